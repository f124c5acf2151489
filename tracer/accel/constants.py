"""Cost constants and defaults taken from the papers, each with its source. One place for all of them."""

#: Ize, Shirley & Parker 2007, Sec. 2.2: "Ti/Ts ~ 4" on their machine, hence M = 8N (Eq 4).
IZE_TI_OVER_TS = 4.0
#: Ize 2007 Sec. 4: two-level grid M1 = (8N)^(3/5) (Eq 12 with 2k^2 Ti/Ts folded to 8), M2 = 8 N2.
IZE_M_FACTOR = 8.0
IZE_M1_EXPONENT = 0.6

#: pbrt-v2 GridAccel (Chuang 2006 slides): voxels along the longest axis = 3 N^(1/3), clamped at 64.
PBRT_GRID_VOXELS_PER_CUBE_ROOT = 3.0
PBRT_GRID_MAX_VOXELS = 64

#: pbrt's KdTreeAccel SAH: the constructor defaults ``isectCost = 80, traversalCost = 1,
#: emptyBonus = 0.5, maxPrims = 1`` (pbrt-v3 ``src/accelerators/kdtreeaccel.h``; the same in pbrt-v2's
#: ``accelerators/kdtreeaccel.cpp``) and ``maxDepth = round(8 + 1.3 Log2Int(N))`` when it is not given
#: (``kdtreeaccel.cpp``); Pharr, Jakob & Humphreys, PBR 3rd ed., Sec 4.4.2. Chuang's 2006 slides quote them.
PBRT_KD_ISECT_COST = 80.0
PBRT_KD_TRAVERSAL_COST = 1.0
PBRT_KD_EMPTY_BONUS = 0.5
PBRT_KD_DEPTH_A, PBRT_KD_DEPTH_B = 8.0, 1.3
PBRT_KD_MAX_PRIMS = 1

#: Wald et al. 2006 (coherent grid traversal) Sec. 3: n_x = d_x (lambda N / V)^(1/3), lambda = 5; macrocell 6.
WALD_LAMBDA = 5.0
WALD_MACROCELL = 6

#: Hapala, Karlik & Havran 2011, Sec. 4: R_C = T_B^H / (t_R^G (1 + eps) - t_R^H), eps = 0.01.
HAPALA_EPS = 0.01

#: the wide BVH's SAH weights (tracer.accel.wide_bvh), relative to one test of a block of four triangles.
#: Embree prices a node traversal as one leaf block (Embree 4 ``kernels/bvh/bvh_builder_sah.cpp``:
#: ``travCost = 1``, leaf cost ``Primitive::blocks(n)``, four triangles per ``Triangle4`` block) with
#: leaves of up to 4 triangles. Ours tests a block in float64 lanes (bit-identical to the oracle), so a
#: block costs relatively less against an 8-box node test than Embree's float32 one: leaves of up to 8
#: triangles (two blocks) and a node priced as 2 blocks are our fitted choice, not Embree's. Chosen by
#: paired timing (1 thread, 100k rays, 11 rounds) on
#: dragon-202k, dragon-48k and fandisk-x16 (+16/+5/+11 % random, +9/+1/+8 % camera over 4 / 1.0), and
#: checked on meshes never used for the choice: beetle-alt, teapot-textured-x4, homer-x16 (+2/+7/+8 %
#: random, -1/+4/+8 % camera). With 4-triangle leaves, weights 0.5-3 give the same trees. ``gridcost bench``
#: pairs the variant ``wbvh-leaf4`` (4, 1.0: Embree's choice) beside the default on every mesh it runs.
WIDE_TRAV_COST = 2.0
WIDE_MAX_LEAF = 8
WIDE_BLOCK = 4
#: the wide BVH's child boxes: "float" (float32 planes, 256-byte 8-wide nodes) or "quant" (one byte a
#: plane against the node's origin and step, 128-byte nodes: Embree's compressed nodes, tinybvh's CWBVH;
#: tracer.accel.wide_quant). The box test meets a superset of the float layout's children, so t and id
#: are unchanged and only the visits and the time move. It does not pay here: the nodes are a quarter of
#: the working set (the leaves' float32 blocks are the rest; bunny-69k 3.7 -> 3.2 MiB), visits rise 1-2 %,
#: and the decode costs more than the halved node loads save. ``gridcost bench`` pairs ``wbvh-quant``
#: beside the default on every mesh: on eight meshes (clean c8db68d, 1 thread, paired with Embree) quant
#: is behind on camera rays everywhere (0.96-1.08x Embree against 1.02-1.26x) and on random rays on seven
#: (0.79-0.92x against 0.84-1.00x); only dragon-871k's random rays gain (0.80x against 0.76x).
WIDE_BOXES = "float"
