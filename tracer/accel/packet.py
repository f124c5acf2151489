"""Coherent grid traversal (Wald, Ize, Kensler, Knoll & Parker 2006): frustum-bounded packets of
rays walked slice by slice through a uniform grid of n_x = d_x (lambda N / V)^(1/3) cells.

Per packet (k x k = consecutive groups of k^2 rays of the batch; ``prange`` over chunks of CHUNK
packets, each thread with its own work arrays):

1. Set-up (Sec 2.2): every ray is clipped to the grid box (one vectorised loop); the major axis K
   is the dominant grid-space component of the first, middle and last rays' directions. Rays whose
   K component has the other sign, or whose slopes du/dk, dv/dk exceed ``MAX_SLOPE``, are traced on
   their own by the uniform grid's single-ray kernel (:func:`tracer.accel.grid.grid_ray`, set up by
   :func:`tracer.accel.geometry.dda_setup`); when the rest do not form a narrow frustum (slope spread >
   ``MAX_SPREAD`` or width > ``MAX_WIDTH`` cells at the entry plane) the whole packet is.
2. Frustum: in grid coordinates every ray is u_i(k') = a_i + s_i k' (k' = slices from the packet's
   entry plane), so the slice overlap box is [min a + min s k', max a + max s k'] — Wald's
   B(i+1) = B(i) + dB, evaluated as A + S k' so no error accumulates. Truncation gives the cells
   [u0..u1] x [v0..v1] of the slice, with an ``EPS`` cell margin (generosity only costs time).
3. Slices front to back; every cell once per packet (a bitmask skips empty cells without touching
   the cell table); per-packet mailboxing (triangles stamped with the packet id, Sec 2.3) and
   frustum culling: a triangle is rejected when its vertices lie outside one of the four frustum
   planes or, with a common origin, when the four corner rays miss it on one edge (Dmitriev's shaft
   culling; only tried on triangles wider than ``EDGE_MIN`` cells, where it pays; smaller ones skip
   the packet's planes, which the group frusta bound tighter, and go straight there). Then the group
   frusta: the packet's slots form groups of LANES rays (a 4 x 2 block of the tile,
   :func:`slot_order`, until retired rays are replaced), each with its own frustum bounds, and a
   triangle is tested only on the groups whose frustum its grid-space box may meet (a small
   triangle meets one or two blocks of an 8x8 packet): one vector compare per bound gives the
   bitmask of those groups. The box is stored in float32, rounded outward, in the same 64-byte row
   as the triangle's vertices (:func:`tracer.accel.packet_kernels.ref_boxes`), so a small triangle
   no group meets is dropped before its vertices are read. Every test keeps a margin far above
   rounding, so culling never drops a hit. A slice runs in phases (``_slice_cells``, ``_gather``):
   its occupied cells are listed without a branch per cell, their references gathered in batches
   of BATCH and mailboxed (their triangles' rows prefetched), and only then culled, loaded and tested; the
   order of the tests is the cell-by-cell order, so the hits are the same, and the loads of one
   phase do not wait on the tests of the last. For closest hits the small triangles' group masks
   are a pass of their own, which keeps the survivors in order with no branch per triangle.
4. Ray-triangle tests: LANES rays at a time on LLVM vectors (``<8 x double>``, Numba intrinsics),
   computing exactly the float64 expressions of :func:`tracer.accel.geometry.ray_triangle` in its
   order, without branches (only ray-independent ones hoisted), so hits agree bit for bit with the
   oracle. All inputs are widened with ``np.float64(...)``: Numba's ``float()`` keeps a float32 a
   float32.
5. Termination: each ray needs slices up to its closest hit's (or its exit's); rays that need no
   more are retired (their result written, the last active ray moved into their slot) and the
   frustum shrinks to the rest; the packet ends when none is left. Any-hit queries (``occluded``,
   e.g. shadow packets from a point light, Sec 4.7) share this loop: a ray is retired right after
   the triangle test that gave it a hit, not at the end of the slice. Macrocells (Sec 2.4, M x M x M
   blocks, any M): on entering a slab of M slices the frustum's overlap with the whole slab is
   tested against the macrocell occupancy and empty slabs are skipped.

Counters: per ray (:data:`tracer.accel.COUNTER_NAMES`) packet-level counts (set-ups, cells = steps,
slices = nodes, mailbox + culling skips) are spread evenly over the packet's rays (sums are exact);
``tests`` are the ray-triangle tests each ray took part in. :meth:`CoherentGrid.packet_counters`
returns per-packet arrays (:data:`PACKET_COUNTERS`), among them the tests without mailboxing, with
mailboxing and with mailboxing + culling of the whole packet, all from one traversal (hits, and so
the traversal, do not depend on either technique), and the tests the variant did (with culling on,
fewer: the group frusta). Mailbox skips count whole batches: an any-hit packet that ends within a
batch has already gathered and stamped the rest of it.

Files: this module has the packet loop (:func:`_packets`), the batched kernel and the structure;
the loop's building blocks (work-array rows, the SIMD triangle test of step 4, the frustum and the
culling tests of steps 2-3) are in :mod:`tracer.accel.packet_kernels`.
"""
from __future__ import annotations

import math
import time

import numba
import numpy as np
from numba import prange

from tracer.accel._jit import jit, pjit, ray_jit, store_ray
from tracer.accel import COUNTER_NAMES, Accel, Counters, Hits, as_rays, tmax_array
from tracer.accel.constants import WALD_LAMBDA, WALD_MACROCELL
from tracer.errors import GridcostError
from tracer.accel.geometry import INF, ray_box
from tracer.accel.pages import traversal_empty
from tracer.measure.footprint import CGT_ROW_BYTES
from tracer.measure.memory import check_budget
from tracer.accel.grid import fill_cells, grid_params, grid_ray, macro_occupancy, res_wald
from tracer.accel.packet_kernels import CULL_REL, EDGE_MIN  # noqa: F401 (tuning constants, importable from here)
from tracer.accel.packet_kernels import (  # the packet loop's building blocks (work arrays, SIMD test, frustum)
    EPS, _AU, _AV, _BEST, _BID, _C0, _C1, _DD, _DX, _DY, _DZ, _IDX, _KD, _KO, _NL, _NW,
    _GB, _NI, _NT, _OX, _OY, _OZ, _SINGLE, _SU, _SV, _T1, BATCH, LANES, _FL, _RL, _TL, _cells,
    _culled, _frame, _frustum, _gather, _groups, _max, _min, _needs, _ref_box, _retire, _shrink, _slice_cells, _span,
    _spread, _test_tri, _verts, ref_boxes, BOX, ROW,
)
from tracer.accel.simd import prefetch

NCOUNT = len(COUNTER_NAMES)
#: per-packet counter columns of :meth:`CoherentGrid.packet_counters`; tests_* are ray-triangle
#: tests (triangles x rays of the packet): no mailboxing/culling, mailboxing, mailboxing + culling
#: of the whole packet, and what the configured variant did (with culling: only the groups of
#: LANES rays the group frusta leave); test_lanes the SIMD lanes those tests occupied (the ray
#: loop runs over whole vectors of LANES rays, so a 1-ray packet pays for LANES); packet_rays the
#: rays traced as a packet (the rest of the rays meeting the grid are in ``single``)
PACKET_COUNTERS = ("rays", "single", "slices", "cells", "considered", "tests_plain", "tests_mb",
                   "tests_mb_fc", "tests", "macro_skips", "culled", "test_lanes", "packet_rays")
NPC = len(PACKET_COUNTERS)
#: rays steeper than this (|du/dk| or |dv/dk|) are traced on their own
MAX_SLOPE = 2.0
#: a packet whose slopes spread more than this (cells per slice) is traced ray by ray
MAX_SPREAD = 1.0
#: ... or whose rays spread more than this many cells at the entry plane
MAX_WIDTH = 64.0
#: frustum culling is skipped while a packet has this many rays or fewer (one SIMD vector)
CULL_MIN_RAYS = 8
#: packets per parallel work item
CHUNK = 16


# ---------------------------------------------------------------- the packet's set-up
def slot_order(k: int) -> np.ndarray:
    """Slot q of a whole k x k packet holds the tile's pixel order[q] (pixels row-major in the tile,
    as :func:`tracer.scenes.rays.camera_rays` orders them): for k a multiple of 4, LANES = 8
    consecutive slots are a 4 x 2 block, not a row of 8, so each group's frustum (:func:`_groups`)
    is about square and meets fewer small triangles (dragon-202k, 512²: 7.4 tests per camera ray
    instead of 11.2). Any order gives the same hits; others stay row-major."""
    q = np.arange(k * k)
    if k % 4 or LANES != 8:
        return q.astype(np.int32)
    blk, w = q // 8, q % 8  # block-row-major blocks of 4 x 2 pixels, row-major inside
    by, bx = blk // (k // 4), blk % (k // 4)
    return ((by * 2 + w // 4) * k + bx * 4 + w % 4).astype(np.int32)


@ray_jit
def _load_clip(b, cnt, order, O, D, tmin, tmax, gp, W, I, out_t, out_id):
    """Rays [b, b + cnt) into slots [0, cnt) of the work arrays (float64 origin, direction, tmax as
    W[_BEST]; a whole packet's rays in the slot ``order`` of :func:`slot_order`, ray ids in
    I[_IDX]), their results reset to a miss, and each clipped to the grid box: W[_C0] (NaN when a
    zero direction lies on a slab plane: the careful test is :func:`_sort`'s), W[_C1]. Returns how
    many may meet the box. Three loops, so that the clipping (the divisions) runs on the work array
    alone and LLVM vectorises it without alias checks against the ray arrays."""
    full = cnt == len(order)
    for q in range(cnt):
        i = np.uintp(b + (order[q] if full else q))  # unsigned: no negative-index wraparound
        I[_IDX, q] = i
        W[_OX, q] = np.float64(O[i, 0]); W[_OY, q] = np.float64(O[i, 1]); W[_OZ, q] = np.float64(O[i, 2])
        W[_DX, q] = np.float64(D[i, 0]); W[_DY, q] = np.float64(D[i, 1]); W[_DZ, q] = np.float64(D[i, 2])
        W[_BEST, q] = np.float64(tmax[i])
    for q in range(cnt):
        i = np.uintp(b + q)
        out_t[i] = np.float32(INF)
        out_id[i] = -1
    inbox = 0
    x0, y0, z0, x1, y1, z1 = gp[0], gp[1], gp[2], gp[9], gp[10], gp[11]
    for q in range(cnt):
        ox = W[_OX, q]; oy = W[_OY, q]; oz = W[_OZ, q]
        ix, iy, iz = 1.0 / W[_DX, q], 1.0 / W[_DY, q], 1.0 / W[_DZ, q]
        xa = (x0 - ox) * ix; xb = (x1 - ox) * ix
        ya = (y0 - oy) * iy; yb = (y1 - oy) * iy
        za = (z0 - oz) * iz; zb = (z1 - oz) * iz
        t0 = _max(_max(tmin, _min(xa, xb)), _max(_min(ya, yb), _min(za, zb)))
        t1 = _min(_min(W[_BEST, q], _max(xa, xb)), _min(_max(ya, yb), _max(za, zb)))
        nan = (xa != xa) | (xb != xb) | (ya != ya) | (yb != yb) | (za != za) | (zb != zb)
        W[_C0, q] = np.nan if nan else t0
        W[_C1, q] = t1
        inbox += nan or not (t0 > t1)  # NaN (a zero direction on a slab plane) counts as inside
    return inbox


@ray_jit
def _sort(b, cnt, any_in, tmin, tmax, gp, K, U, V, sig, W, I):
    """Sort the loaded rays (slots [0, cnt), :func:`_load_clip`) into packet rays, moved down to
    slots [0, n) (grid-space k of the origin W[_KO], dk/dt W[_KD], slopes du/dk, dv/dk in W[_AU],
    W[_AV] for now, exit W[_T1]), and single rays (their ray ids in I[_SINGLE, :ns]): a packet ray
    meets the box, runs along +K (sig > 0) or -K, and is no steeper than MAX_SLOPE. Returns (n, ns,
    lowest and highest grid-space k at the rays' box entries). A first loop computes every slot in
    place (vectorised: the K, U, V components are rows _OX + K ...); slots move only when a ray is
    not a packet ray or needs the careful slab test (NaN entry)."""
    gpk, gsk, gsu, gsv = gp[K], gp[6 + K], gp[6 + U], gp[6 + V]
    nok = 0
    kin_lo = INF
    kin_hi = -INF
    for q in range(cnt if any_in else 0):
        t0 = W[_C0, q]
        t1 = W[_C1, q]
        gdk = W[_DX + K, q] * gsk
        gdu = W[_DX + U, q] * gsu
        gdv = W[_DX + V, q] * gsv
        gok = (W[_OX + K, q] - gpk) * gsk
        ok = (t0 <= t1) & (sig * gdk > 0.0) & (abs(gdu) <= MAX_SLOPE * abs(gdk)) & (abs(gdv) <= MAX_SLOPE * abs(gdk))
        kin = gok + t0 * gdk
        kin_lo = _min(kin_lo, kin if ok else INF)
        kin_hi = _max(kin_hi, kin if ok else -INF)
        W[_DD, q] = W[_DX, q] * W[_DX, q] + W[_DY, q] * W[_DY, q] + W[_DZ, q] * W[_DZ, q]
        W[_T1, q] = t1
        W[_KO, q] = gok
        W[_KD, q] = gdk
        W[_AU, q] = gdu / gdk
        W[_AV, q] = gdv / gdk
        I[_BID, q] = -1
        I[_NT, q] = 0
        nok += ok
    if nok == cnt:
        return cnt, 0, kin_lo, kin_hi
    n = 0
    ns = 0
    for q in range(cnt if any_in else 0):
        t0 = W[_C0, q]
        t1 = W[_C1, q]
        if t0 > t1:
            continue
        if not (t0 <= t1):  # NaN from a zero direction: the careful slab test
            i = I[_IDX, q]
            t0, t1 = ray_box(W[_OX, q], W[_OY, q], W[_OZ, q], W[_DX, q], W[_DY, q], W[_DZ, q], gp[0], gp[1], gp[2],
                             gp[9], gp[10], gp[11], tmin, np.float64(tmax[i]))
            if t0 > t1:
                continue
            W[_T1, q] = t1
        gdk = W[_KD, q]
        gdu = W[_DX + U, q] * gsu
        gdv = W[_DX + V, q] * gsv
        if sig * gdk > 0.0 and abs(gdu) <= MAX_SLOPE * abs(gdk) and abs(gdv) <= MAX_SLOPE * abs(gdk):
            kin = W[_KO, q] + t0 * gdk
            kin_lo = min(kin_lo, kin)
            kin_hi = max(kin_hi, kin)
            if n != q:
                for row in (_OX, _OY, _OZ, _DX, _DY, _DZ, _DD, _BEST, _T1, _KO, _KD, _AU, _AV):
                    W[row, n] = W[row, q]
                I[_IDX, n] = I[_IDX, q]
            n += 1
        else:
            I[_SINGLE, ns] = I[_IDX, q]
            ns += 1
    return n, ns, kin_lo, kin_hi


# ---------------------------------------------------------------- the packet loop
@jit
def _packets(p0, p1, k2, order, O, D, tmin, tmax, anyhit, gp, res, cell_start, occb, tri_ids, tv, macro, M,
             mailbox, cull, stamps, W, I, CL, L, out_t, out_id, counters, pc):
    """Trace packets [p0, p1) one after the other on this thread's work arrays (one call per chunk
    of packets: a call per packet costs as much as tracing a packet that misses the grid; ``CL``
    holds a slice's occupied cells, ``L`` a batch of references, :func:`_gather`). A packet is the
    rays [p k2, (p + 1) k2); rays that cannot join it are traced on their own."""
    m = O.shape[0]
    nxg, nyg, nzg = res[0], res[1], res[2]
    GB = W[_GB:_GB + 8]  # the group frusta (tracer.accel.packet_kernels._frustum)
    for p in range(p0, p1):
        b = p * k2
        e = min(m, b + k2)
        pid = np.int32(p)
        cnt = e - b
        inbox = _load_clip(b, cnt, order, O, D, tmin, tmax, gp, W, I, out_t, out_id)
        if inbox == 0 and pc is None:
            continue
        # ---- major axis: dominant component of the first, middle and last rays' summed grid-space
        # directions (Wald takes the first ray's; three guard against one odd ray)
        h = (cnt - 1) // 2
        sx = (W[_DX, 0] + W[_DX, h] + W[_DX, cnt - 1]) * gp[6]
        sy = (W[_DY, 0] + W[_DY, h] + W[_DY, cnt - 1]) * gp[7]
        sz = (W[_DZ, 0] + W[_DZ, h] + W[_DZ, cnt - 1]) * gp[8]
        K, sk = (0, sx) if abs(sx) >= abs(sy) and abs(sx) >= abs(sz) else ((1, sy) if abs(sy) >= abs(sz) else (2, sz))
        U, V = (K + 1) % 3, (K + 2) % 3
        sig, isig = (1.0, 1) if sk >= 0.0 else (-1.0, -1)
        nK, nU, nV = res[K], res[U], res[V]
        st3 = (1, nxg, nxg * nyg)  # cell strides along x, y, z
        stK, stU, stV = st3[K], st3[U], st3[V]
        # ---- sort the rays meeting the box into packet rays (slots [0, n)) and single rays
        n, ns, kin_lo, kin_hi = _sort(b, cnt, inbox > 0, tmin, tmax, gp, K, U, V, sig, W, I)
        slices = cells = considered = uniq = skips = mskips = culled = 0
        acc_plain = acc_mb = acc_fc = acc_tests = acc_lanes = 0  # ray-triangle tests: no MB, MB, MB + FC, done
        n_in = n
        if n > 0:
            # ---- frustum: first slice jf, entry plane P0, u_i(k') = a_i + s_i k' for k' >= 0
            if isig > 0:
                jf = min(max(int(math.floor(kin_lo - EPS)), 0), nK - 1)
                P0 = np.float64(jf)
            else:
                jf = min(max(int(math.floor(kin_hi + EPS)), 0), nK - 1)
                P0 = np.float64(jf + 1)
            nmax = (nK - 1 - jf) if isig > 0 else jf
            gpu, gsu, gpv, gsv = gp[U], gp[6 + U], gp[V], gp[6 + V]
            ox0 = W[_OX, 0]; oy0 = W[_OY, 0]; oz0 = W[_OZ, 0]
            other = 0  # rays whose origin is not ray 0's (a branch-free count, so the loop vectorises)
            for q in range(n):
                su = W[_AU, q]
                sv = W[_AV, q]
                W[_AU, q] = (W[_OX + U, q] - gpu) * gsu + (P0 - W[_KO, q]) * su
                W[_AV, q] = (W[_OX + V, q] - gpv) * gsv + (P0 - W[_KO, q]) * sv
                W[_SU, q] = sig * su
                W[_SV, q] = sig * sv
                W[_KO, q] = sig * (W[_KO, q] - P0)  # k'(t) = pko + t pkd from now on
                W[_KD, q] = sig * W[_KD, q]
                I[_NL, q] = min(int(math.floor(W[_KO, q] + W[_T1, q] * W[_KD, q] + EPS)), nmax)  # last slice it needs
                other += (W[_OX, q] != ox0) | (W[_OY, q] != oy0) | (W[_OZ, q] != oz0)
            common = other == 0
            fr = _frustum(n, W, GB)
            if (fr[3] - fr[2] > MAX_SPREAD or fr[7] - fr[6] > MAX_SPREAD
                    or fr[1] - fr[0] > MAX_WIDTH or fr[5] - fr[4] > MAX_WIDTH):
                for q in range(n):  # not a coherent packet: every ray on its own
                    I[_SINGLE, ns] = I[_IDX, q]
                    ns += 1
                n = 0
                n_in = 0
        if n > 0:
            nlast, nfirst = _span(n, I)
            edge = common and cull and tmin >= 0.0
            ox0 = W[_OX, 0]; oy0 = W[_OY, 0]; oz0 = W[_OZ, 0]
            ru, rv = gp[3 + U] / gp[3 + K], gp[3 + V] / gp[3 + K]
            mst3 = (1, (nxg - 1) // M + 1, ((nxg - 1) // M + 1) * ((nyg - 1) // M + 1))  # macrocell strides
            mstK, mstU, mstV = mst3[K], mst3[U], mst3[V]
            counting = pc is not None
            stamping = mailbox or counting
            slab_end = -1
            s = 0
            while s <= nlast:
                j = jf + isig * s
                if macro is not None and s > slab_end:  # entering a slab of macrocells
                    J = j // M
                    s_end = min(s + abs((J * M + M - 1 if isig > 0 else J * M) - j), nlast)
                    u0, u1 = _cells(fr[0], fr[1], fr[2], fr[3], s, s_end + 1, nU)
                    v0, v1 = _cells(fr[4], fr[5], fr[6], fr[7], s, s_end + 1, nV)
                    empty = True
                    if u0 <= u1 and v0 <= v1:
                        for bv in range(v0 // M, v1 // M + 1):
                            for bu in range(u0 // M, u1 // M + 1):
                                if macro[J * mstK + bu * mstU + bv * mstV] != 0:
                                    empty = False
                                    break
                            if not empty:
                                break
                    if empty:
                        mskips += 1
                        s = s_end + 1
                        continue
                    slab_end = s_end
                slices += 1
                u0, u1 = _cells(fr[0], fr[1], fr[2], fr[3], s, s + 1, nU)
                v0, v1 = _cells(fr[4], fr[5], fr[6], fr[7], s, s + 1, nV)
                changed = False
                sbase = j * stK
                cull_now = cull and n > CULL_MIN_RAYS  # a test of a few rays costs less than culling
                nc = _slice_cells(u0, u1, v0, v1, sbase, stU, stV, occb, cell_start, CL)
                cells += max(u1 - u0 + 1, 0) * max(v1 - v0 + 1, 0)
                kc = rcur = rend = 0
                while n > 0:  # batches of references: gathered, mailboxed, then culled and tested
                    nk, nr, kc, rcur, rend = _gather(kc, rcur, rend, nc, CL, cell_start, tri_ids, tv, L, pid, stamping,
                                                     mailbox, stamps)
                    if nr == 0:
                        break
                    considered += nr
                    acc_plain += n * nr
                    skips += nr - nk
                    # closest hit, culling, up to 32 groups: a first pass drops the small triangles no
                    # group frustum meets without a branch per triangle (about half the references a
                    # camera packet keeps; a branch on each was mispredicted) and leaves each survivor's
                    # group mask in L[_RL] (0: the loop below decides, as for large triangles)
                    fast = cull_now and LANES < n <= 32 * LANES and not counting and not anyhit
                    if fast:
                        j = 0
                        for k in range(nk):
                            tid = L[_TL, k]
                            box = _ref_box(tv, tid, K, U, V, sig, P0)
                            small = box[1] - box[0] <= EDGE_MIN and box[3] - box[2] <= EDGE_MIN
                            g = _groups(n, True, GB, box, 0)
                            L[_TL, j] = tid
                            L[_RL, j] = np.int32(g if small else 0)  # g < 2^32: up to 32 groups
                            j += (g != 0) | (not small)
                        skips += nk - j
                        culled += nk - j
                        nk = j
                    for k in range(nk):
                        tid = L[_TL, k]
                        groups = (np.int64(L[_RL, k]) & 0xFFFFFFFF) if fast else 0
                        gcull = cull_now and n > LANES
                        if groups != 0:  # kept by the first pass: straight to the test
                            ax, ay, az, bx, by, bz, cx, cy, cz = _verts(tv, tid)
                            nh, lanes, real = _test_tri(n, gcull, GB, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0), groups, common,
                                                        W, I, tid, ax, ay, az, bx, by, bz, cx, cy, cz, tmin, False)
                            acc_lanes += lanes
                            acc_tests += real
                            changed = True
                            continue
                        box = _ref_box(tv, tid, K, U, V, sig, P0)
                        # a triangle within EDGE_MIN cells gets no edge test, and the group frusta
                        # (_groups) bound it tighter than the packet's planes: it goes straight there
                        small = box[1] - box[0] <= EDGE_MIN and box[3] - box[2] <= EDGE_MIN
                        if (cull_now and not small) or counting:
                            ax, ay, az, bx, by, bz, cx, cy, cz = _verts(tv, tid)
                            fv = _frame(ax, ay, az, bx, by, bz, cx, cy, cz, K, U, V, gp, sig, P0)
                            out = _culled(ax, ay, az, bx, by, bz, cx, cy, cz, fv, K, U, V, sig, fr,
                                          edge and not small, ox0, oy0, oz0, ru, rv)
                            if counting and L[_FL, k] != 0:
                                uniq += 1
                                acc_mb += n
                                if not out:
                                    acc_fc += n
                            if cull_now and not small and out:
                                skips += 1
                                culled += 1
                                continue
                        # whole vectors of LANES rays; with culling, only the groups whose frusta it may
                        # meet: a triangle none meets is dropped before its vertices are loaded
                        groups = _groups(n, gcull, GB, box, 0)
                        if groups == 0 and n <= 64 * LANES:
                            skips += 1
                            culled += 1
                            continue
                        ax, ay, az, bx, by, bz, cx, cy, cz = _verts(tv, tid)
                        nh, lanes, real = _test_tri(n, gcull, GB, box, groups, common, W, I, tid,
                                                    ax, ay, az, bx, by, bz, cx, cy, cz, tmin, counters is not None)
                        acc_lanes += lanes
                        acc_tests += real
                        changed = True
                        if anyhit and nh > 0:  # any hit: a ray that hit is done now, not at the slice's end
                            _needs(n, True, W, I)
                            n, fr, ox0, oy0, oz0, nlast, nfirst = _shrink(n, -1, W, I, GB, fr, out_t, out_id,
                                                                          counters)
                            if n == 0:
                                break
                            cull_now = cull and n > CULL_MIN_RAYS
                if n == 0:
                    break
                if changed:  # a ray with a hit needs no slice past its hit's
                    _needs(n, anyhit, W, I)
                # ---- retire rays that need no further slice (checked when a hit came or the earliest
                # last slice is reached); the frustum shrinks to the rest
                if changed or s >= nfirst:
                    n, fr, ox0, oy0, oz0, nlast, nfirst = _shrink(n, s, W, I, GB, fr, out_t, out_id, counters)
                    if n == 0:
                        break
                s += 1
            for q in range(n):
                _retire(q, I[_IDX, q], W, I, out_t, out_id, counters)
        # ---- single-ray fallback: the uniform grid's own kernel
        s_steps = 0
        s_tests = 0
        for q in range(ns):
            i = I[_SINGLE, q]
            t, tid, su_, st_, te_, sk_, ju_, oc_ = grid_ray(
                np.float64(O[i, 0]), np.float64(O[i, 1]), np.float64(O[i, 2]), np.float64(D[i, 0]),
                np.float64(D[i, 1]), np.float64(D[i, 2]), tmin, np.float64(tmax[i]), anyhit, gp,
                nxg, nyg, nzg, cell_start, tri_ids, tv, None, 0, None, 0, None, tri_ids)
            store_ray(out_t, out_id, counters, i, np.float32(t), tid, su_, st_, te_, 0, sk_)
            s_steps += st_
            s_tests += te_
        if counters is not None and n_in > 0:  # I[_IDX, :n_in] holds every packet ray (retired ones at the end)
            _spread(counters, n_in, 0, 1, I)
            _spread(counters, n_in, 1, cells, I)
            _spread(counters, n_in, 3, slices, I)
            _spread(counters, n_in, 4, skips, I)
        if pc is not None:  # columns: PACKET_COUNTERS (single rays: no mailboxing, no culling)
            pc[p, 0], pc[p, 1], pc[p, 2], pc[p, 3], pc[p, 4] = e - b, ns, slices, cells + s_steps, considered + s_tests
            pc[p, 5], pc[p, 6], pc[p, 7] = acc_plain + s_tests, acc_mb + s_tests, acc_fc + s_tests
            pc[p, 8], pc[p, 9], pc[p, 10], pc[p, 11] = acc_tests + s_tests, mskips, culled, acc_lanes + s_tests
            pc[p, 12] = n_in


@pjit
def cgt_trace(O, D, tmin, tmax, anyhit, k2, order, gp, res, cell_start, occb, tri_ids, tv, macro, M,
              mailbox, cull, W, I, CL, L, stamps, out_t, out_id, counters, pc):
    """Batched coherent grid traversal, ``prange`` over chunks of CHUNK packets of ``k2``
    consecutive rays. ``W``/``I``/``CL``/``L``/``stamps`` are per-thread work arrays; ``counters``/``pc`` arrays
    or None (None compiles the variant without counting code); ``macro`` the occupancy of M^3
    blocks or None."""
    npk = (O.shape[0] + k2 - 1) // k2
    nch = (npk + CHUNK - 1) // CHUNK
    for c in prange(nch):
        thr = numba.get_thread_id()
        _packets(c * CHUNK, min(npk, (c + 1) * CHUNK), k2, order, O, D, tmin, tmax, anyhit, gp, res, cell_start, occb,
               tri_ids, tv, macro, M, mailbox, cull, stamps[thr], W[thr], I[thr], CL[thr], L[thr], out_t, out_id,
               counters, pc)


# ---------------------------------------------------------------- structure
class CoherentGrid(Accel):
    """Wald et al. 2006 coherent grid traversal over a uniform grid of n_x = d_x (lam N / V)^(1/3).

    ``packet`` k: packets are k x k = consecutive groups of k^2 rays (order camera rays with
    ``camera_rays(..., tile=k)``). ``macro`` M: macrocells of M^3 cells (0 = off). ``mailbox`` and
    ``frustum_cull`` switch per-packet mailboxing and frustum culling. ``exact`` selects exact
    triangle/cell overlap in the build (default: about 5 % faster here); the paper inserts by
    bounding box (``exact=False``; Sec 3). ``res`` overrides the resolution (e.g. to share a
    single-ray grid's).
    """

    name = "cgt"
    counter_fields = {"setups": "3D-DDA set-ups (single-ray fallback)", "steps": "cells stepped",
                      "tests": "ray/triangle tests", "nodes": "grid slices traversed by the ray's packet",
                      "skips": "tests skipped by the mailbox"}

    def __init__(self, lam=WALD_LAMBDA, packet=8, macro=WALD_MACROCELL, mailbox=True, frustum_cull=True,
                 exact=True, res=None):
        if int(packet) < 1 or int(packet) != packet:
            raise GridcostError(f"packet size must be a positive integer, got {packet}")
        if macro is None or int(macro) < 0:
            raise GridcostError(f"macrocell size must be >= 0, got {macro}")
        if not (np.isfinite(lam) and lam > 0):
            raise GridcostError(f"lambda must be a positive number, got {lam}")
        self.lam, self.packet, self.macro = float(lam), int(packet), int(macro)
        self.mailbox, self.frustum_cull, self.exact, self.res = bool(mailbox), bool(frustum_cull), bool(exact), res

    def build(self, scene):
        res = np.asarray(self.res, np.int64) if self.res is not None else res_wald(scene.bounds, scene.n, self.lam)
        if res.shape != (3,) or (res < 1).any():
            raise GridcostError(f"grid resolution must be three positive integers, got {res}")
        t_start = time.perf_counter()
        gp = grid_params(scene.bounds, res)
        #: occupied_: one bit per cell, set when the cell holds a triangle (little-endian bit order)
        self.cell_start_, self.tri_ids_, self.tri_verts_, self.occupied_, _ = fill_cells(
            scene, res, gp, self.exact, "index", self.macro)
        refs = len(self.tri_ids_)
        # one 64-byte row per triangle (not per reference, as the single-ray grid's blocks: the mailbox
        # drops a packet's repeats, and a third of the bytes on dragon-202k, 2.8 references per
        # triangle, was 4 % faster there and 0-1 % on three other meshes, paired): its vertices,
        # then its grid-space box (packet_kernels.ref_boxes)
        check_budget(f"the packet grid's {scene.n:,} triangle rows", scene.n * CGT_ROW_BYTES)
        rows = traversal_empty((scene.n, ROW), np.float32)
        rows[:, :BOX] = self.tri_verts_
        self.tri_verts_ = ref_boxes(self.tri_verts_, gp, rows)
        self.macro_ = macro_occupancy(self.cell_start_, res, self.macro) if self.macro else None
        self.build_seconds_ = time.perf_counter() - t_start
        self.res_, self.gp_, self.n_, self.refs_ = res, gp, scene.n, refs
        self.slot_order_ = slot_order(self.packet)
        self.scene_name_ = scene.name
        return self

    def _run(self, o, d, tmin, tmax, anyhit, counters, pc):
        m = len(o)
        k2 = self.packet * self.packet
        nthr = numba.config.NUMBA_NUM_THREADS
        out_t = np.empty(m, np.float32)
        out_id = np.empty(m, np.int32)
        width = (k2 + LANES - 1) // LANES * LANES
        W = np.zeros((nthr, _GB + 8, width), np.float64)  # rows _GB.. hold the group frusta
        I = np.zeros((nthr, _NI, width), np.int32)
        stamps = np.full((nthr, max(self.n_, 1)), -1, np.int32)
        # a slice's cells: at most the product of the grid's two largest sides
        CL = np.empty((nthr, int(np.sort(self.res_)[1:].prod())), np.int32)
        L = np.empty((nthr, 3, BATCH), np.int32)
        cgt_trace(o, d, tmin, tmax, anyhit, k2, self.slot_order_, self.gp_, self.res_, self.cell_start_,
                  self.occupied_, self.tri_ids_, self.tri_verts_, self.macro_, max(self.macro, 1),
                  self.mailbox, self.frustum_cull, W, I, CL, L, stamps, out_t, out_id, counters, pc)
        return out_t, out_id

    def _trace(self, o, d, tmin, tmax, anyhit, count):
        cnt = np.zeros((len(o), NCOUNT), np.int32) if count else None
        pc = np.zeros(((len(o) + self.packet**2 - 1) // self.packet**2, NPC), np.int64) if count else None
        out_t, out_id = self._run(o, d, tmin, tmax, anyhit, cnt, pc)
        return out_t, out_id, cnt

    def packet_counters(self, origins, directions, tmin: float = 0.0, tmax=None) -> dict:
        """Per-packet work of one closest-hit trace: a dict of int64 arrays (one entry per packet)
        named by :data:`PACKET_COUNTERS` (tests_* in ray-triangle tests), plus ``hits`` and the
        per-ray ``counters``."""
        o, d = as_rays(origins, directions)
        cnt = np.zeros((len(o), NCOUNT), np.int32)
        pc = np.zeros(((len(o) + self.packet**2 - 1) // self.packet**2, NPC), np.int64)
        t, ids = self._run(o, d, float(tmin), tmax_array(tmax, len(o)), False, cnt, pc)
        out = {name: pc[:, k].copy() for k, name in enumerate(PACKET_COUNTERS)}
        out["hits"] = Hits(t, ids)
        out["counters"] = Counters(cnt, self.counter_fields)
        return out

    def stats(self) -> dict:
        ncell = int(np.prod(self.res_))
        occ = np.diff(self.cell_start_)
        return {
            "structure": "cgt", "res": [int(r) for r in self.res_], "cells": ncell, "lam": self.lam,
            "refs": int(self.refs_), "refs_per_tri": self.refs_ / max(self.n_, 1),
            "empty_cells": int((occ == 0).sum()), "max_refs": int(occ.max(initial=0)),
            "memory_bytes": int(self.cell_start_.nbytes + self.tri_ids_.nbytes + self.tri_verts_.nbytes
                                + (self.macro_.nbytes if self.macro_ is not None else 0)),
            "build_s": self.build_seconds_, "packet": self.packet, "macro": self.macro,
            "mailbox": self.mailbox, "frustum_cull": self.frustum_cull, "exact": self.exact,
        }
