"""The named variants of the structures (a structure and its parameters) that ``bench`` times and
``verify --suite`` checks against the oracle: one table, so both tools speak of the same builds."""
from __future__ import annotations

#: name -> (structure, params) of every variant benchmarked and verified; grid cells = factor * N
VARIANTS = {
    "grid": ("grid", {"factor": 4.0}),
    "grid-8N": ("grid", {"factor": 8.0}),
    # M = 2N T_i/T_s (Ize 2007 Eq 4) with T_i/T_s measured on this machine in the same run
    # (costmodel.griddensity.GridDensityFit, on calibration meshes none of which bench reports on)
    "grid-fit": ("grid", {"factor": "fitted"}),
    "grid-bbox": ("grid", {"factor": 4.0, "exact": False}),
    "grid-mailbox": ("grid", {"factor": 4.0, "mailbox": True}),
    "grid-macro": ("grid", {"factor": 4.0, "macro": 4}),
    "nested": ("nested", {}),
    "kdtree": ("kdtree", {}),
    # perfect splits on clipped triangles (Wald & Havran 2006), pbrt's constants 80:1:0.5
    "kdtree-clip": ("kdtree", {"clip": True}),
    "kdtree-clip-d2": ("kdtree", {"clip": True, "extra_depth": 2}),
    # (SAH constants fitted on this machine: build(scene, "kdtree", constants=experiments.core.probes.measure_sah_constants(...))
    # in the same run; no fitted number is typed in here)
    # clipped triangles, leaves of up to four triangles tested together in vector lanes (tracer.accel.simd_tri),
    # pbrt's depth limit lowered by 2: fewer, fuller leaves for the four lanes
    "kdtree-fast": ("kdtree", {"clip": True, "max_prims": 4, "extra_depth": -2}),
    "bvh": ("bvh", {}),
    "bvh-sign": ("bvh", {"order": "sign"}),
    "bvh4": ("bvh4", {}),
    # the SAH's traversal weight measured on this machine in the same run (costmodel.kdcost.BvhSahFit:
    # the binary BVH's time fitted to its counters on small calibration meshes), not pbrt's 1/8
    "bvh4-sah-fit": ("bvh4", {"trav_cost": "fitted"}),
    # 8 children with AVX2 (4 without), leaves of up to 8 triangles tested four at a time, a node priced as
    # 2 leaf blocks (tracer.accel.constants.WIDE_MAX_LEAF / WIDE_TRAV_COST)
    "wbvh": ("wbvh", {}),
    # Embree's choice, the wide BVH's default before: leaves of up to 4 triangles, a node priced as one
    # leaf block; paired beside the default so each run shows what the fitted choice gains on its mesh
    "wbvh-leaf4": ("wbvh", {"max_leaf": 4, "trav_cost": 1.0}),
    # the same tree with child boxes quantised to a byte a plane (128-byte nodes, tracer.accel.wide_quant)
    "wbvh-quant": ("wbvh", {"boxes": "quant"}),
    "cgt": ("cgt", {}),
    "sortedlists": ("sortedlists", {}),
}
