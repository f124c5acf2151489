"""SAH kd-tree as pbrt-v2's ``KdTreeAccel`` builds it, and pbrt's front-to-back traversal.

Build (Numba, O(N log N)): pbrt-v2's sorted-edge sweep, with the sort done once. The 2N bound
edges of every axis are sorted once at the root (key: t, then START before END, as pbrt's
``BoundEdge::operator<``); a node's three edge lists are stable-filtered into its children, so
every node sees its edges already sorted and the per-node work is linear (pbrt re-sorts at every
node: O(N log^2 N), same trees). Per node, exactly as pbrt-v2:

* leaf when ``n <= max_prims`` or the depth budget is spent (max depth
  ``round(8 + 1.3 * floor(log2 N))`` — pbrt's ``Log2Int`` is the floor);
* SAH sweep over the edges strictly inside the node along the axis of largest extent; the other
  two axes are tried (``retries``) only when that axis has no candidate plane;
  cost = traversal + isect * (1 - bonus) * (pB nB + pA nA), bonus = ``empty_bonus`` when a side is
  empty (80 / 1 / 0.5 by default, :mod:`tracer.accel.constants`);
* ``bad_refines`` counts splits costlier than the leaf (isect * n); leaf when the best cost is
  > 4 x leaf cost with n < 16, or no plane, or the third bad refine;
* primitives with a START edge before the split edge go below, those with an END edge after it
  go above (straddlers, and triangles lying in the plane, go to one or both sides so that every
  triangle is on each side it touches). Triangles are not clipped: edges are their full bounds.

``clip=True`` builds with perfect splits on triangles clipped to each node instead
(:mod:`tracer.accel.kdtree_clip`, Wald & Havran 2006); same node layout and traversal.

Layout: pbrt's depth-first order with the below child at ``i + 1``, minus the empty leaves (a
third of pbrt's leaves; they are counted as visited, not stored). ``nodes_`` (stored nodes, 2)
int32: interior ``[axis | flag << 2 | child << 4, split (float32 bits)]`` with flag 0: below at
``i + 1``, above at ``child``; 1: below is an empty leaf, above at ``i + 1``; 2: above is an empty
leaf, below at ``i + 1``. Leaf ``[3 | count << 2, x]``: x is the triangle's index itself in a
one-triangle leaf (most leaves: max_prims = 1), else the leaf's first block of four in ``blocks_``.
A leaf of two or more triangles is stored as ceil(count / 4) blocks of four triangles (the SoA
layout of :mod:`tracer.accel.simd_tri`, padded with degenerate triangles) with their indices in
``block_ids_`` (-1 padding), and tested four at a time in vector lanes by
:func:`tracer.accel.simd_tri.ray_tri4`, whose lanes' t are ``ray_triangle``'s bit for bit.
``nodes_f_`` is the float32 view of the same memory. ``tri_ids_`` (refs) holds the triangle indices
in leaf order (the blocks are made from it) and ``tri_verts_`` (N, 9) float32 the triangles in scene order, not copied per
ref (9+ refs per triangle at max_prims = 1 would not fit in L2 where the scene's triangles do).
By default (``leaf_order=True``; False keeps scene order) the triangles are stored in the order the leaves first reference them
(:func:`leaf_first_order`), so the triangles of neighbouring leaves share cache lines; the kernel
then returns stored indices and ``_trace`` maps them back to the scene's through ``tri_order_``
(8-16 % less time per random ray on bunny-69k / dragon-202k, paired, one thread).

Traversal: pbrt-v2 ``KdTreeAccel::Intersect`` — front-to-back with a fixed-size todo stack. Each
block of BLOCK rays is traced two rays at a time, one node of each in turn (:func:`kd_chunk`), so
the two node-to-node dependency chains overlap; each ray's visits, counters and result are those
of tracing it alone. A popped node whose t-range starts after the closest hit is skipped
(pbrt stops there, but the stack is not ordered by entry t: a ray lying in a split plane pushes
the above child with the parent's whole t-range, beneath entries of the below subtree that start
later — stopping lost nearer hits there, e.g. on meshes far from the origin, where float32 rays
often lie exactly in split planes); the any-hit variant (``IntersectP``) stops at the first hit.
The near/far choice is branch-free (cmov: branches mispredict on random rays), the ray's
origin / direction / inverse direction (and its band, below) are read from a 16-entry per-block
array indexed by the split axis, and each interior node prefetches its far (above) child, whose
dependent load otherwise misses L2 on large trees. Without counters, an empty child is never pushed (visiting it only
counts). The ray is widened to float64 with ``np.float64`` (Numba's
``float()`` keeps a float32 a float32) and passed to :func:`tracer.accel.geometry.ray_triangle` exactly
as the grid and the oracle pass it, so a hit's t is bit-identical to the oracle's.
Plane distances are float64 and every comparison of a plane or a hit with a node's t-range is
widened by ``tol`` = T_EPS (2e-6) of the ray's t scale (the range is kept widened, so a plane's
distance is compared as computed, with no add on the node-to-node dependency chain), so rounding can only add node visits,
never lose a hit — including hits that ray_triangle accepts on a triangle's very edge.
A ray nearly parallel to a split plane needs more: ray_triangle's rounding can report a hit just
across the plane from the exact ray (a ray leaving the plane at d_y = -1e-30 meets a vertex on it),
and one float32 step in space there is far beyond any widening in t. So a ray within
:func:`tracer.accel.geometry.box_pad` of a plane in space visits both children (its band, w =
box_pad / |d| in t, added to the node's range so the node-to-node chain is unchanged; for
ordinary rays w is below tol and the visits are those of the widening alone, within 0.3 %).
Counters: ``setups`` 1 per ray meeting the root box, ``steps`` leaves visited (empty ones too),
``tests`` triangle tests, ``nodes`` nodes visited (interior + leaf) — pbrt's visits exactly.
"""
from __future__ import annotations

import math
import time

import numpy as np
from numba import prange

from tracer.accel._jit import BLOCK, jit, nblocks, pjit, pop_within, ray_jit, store_ray
from tracer.accel import TreeTraceMixin, COUNTER_NAMES, Accel
from tracer.accel.constants import (PBRT_KD_DEPTH_A, PBRT_KD_DEPTH_B, PBRT_KD_EMPTY_BONUS,
                              PBRT_KD_ISECT_COST, PBRT_KD_MAX_PRIMS, PBRT_KD_TRAVERSAL_COST)
from tracer.errors import GridcostError
from tracer.accel.geometry import INF, box_pad, load_ray, ray_triangle, t_tolerance
from tracer.accel.kdtree_build import LEAF, kd_build, kd_compact, sorted_edges  # noqa: F401 - the SAH build
from tracer.accel.kdtree_clip import kd_build_clip
from tracer.accel.simd import prefetch
from tracer.accel.pages import traversal_array, traversal_rows
from tracer.accel.simd_tri import TRI4_WORDS, ray_tri4
from tracer.measure.memory import check_budget, fmt_bytes, memory_budget, working_set

NCOUNT = len(COUNTER_NAMES)


def pbrt_max_depth(n: int) -> int:
    """pbrt-v2: ``Round2Int(8 + 1.3f * Log2Int(float(N)))`` with Log2Int = floor(log2)."""
    lg = math.floor(math.log2(n)) if n >= 1 else 0
    return int(math.floor(PBRT_KD_DEPTH_A + PBRT_KD_DEPTH_B * lg + 0.5))


# ---------------------------------------------------------------- traversal
@jit(inline="always")
def _slab_clip(lo, hi, o, inv, t0, t1):
    """Clip [t0, t1] to one slab of the root box (float64; a NaN product is ignored)."""
    a = (lo - o) * inv
    b = (hi - o) * inv
    if a > b:
        a, b = b, a
    if a > t0:
        t0 = a
    if b < t1:
        t1 = b
    return t0, t1


@ray_jit
def _kd_next(nxt, hi, O, D, tmin, tmax, box, diag, rs, out_t, out_id, counters):
    """Load the next ray from ``nxt`` on that meets the root box into ``rs`` (origin, direction,
    inverse direction, indexed by axis; then the band of each axis, see below); the rays before it
    that miss the box get their result here. Returns (its index, or -1 when none is left; the next
    ``nxt``; best; the widened t-range ntmin, ntmax). The root slab test ignores NaN products
    (origin on a slab plane, zero direction)."""
    while nxt < hi:
        i = nxt
        nxt += 1
        ox, oy, oz, dx, dy, dz, ix, iy, iz = load_ray(O, D, i)
        best = np.float64(tmax[i])
        t0, t1 = _slab_clip(box[0], box[3], ox, ix, tmin, best)
        t0, t1 = _slab_clip(box[1], box[4], oy, iy, t0, t1)
        t0, t1 = _slab_clip(box[2], box[5], oz, iz, t0, t1)
        if t0 <= t1:
            tol = t_tolerance(t0, t1, diag, ix, iy, iz)
            rs[0] = ox
            rs[1] = oy
            rs[2] = oz
            rs[3] = dx
            rs[4] = dy
            rs[5] = dz
            rs[6] = ix
            rs[7] = iy
            rs[8] = iz
            # the band around a split plane where a hit may lie on either side (box_pad): its
            # half-width in t on each axis (w; wide for a nearly axis-parallel ray), the same
            # plus 2 tol (the children's ranges end that far beyond the plane), and its
            # half-width in space (rays parallel to the plane: box_pad, set once by kd_chunk)
            u = rs[15]
            rs[9] = abs(u * ix)
            rs[10] = abs(u * iy)
            rs[11] = abs(u * iz)
            rs[12] = rs[9] + (tol + tol)
            rs[13] = rs[10] + (tol + tol)
            rs[14] = rs[11] + (tol + tol)
            # the node's t-range is kept widened by tol on both sides (ntmin - tol, ntmax + tol),
            # so a plane distance is compared as computed, with no add on the node-to-node chain
            return i, nxt, best, t0 - tol, t1 + tol
        store_ray(out_t, out_id, counters, i, INF, -1, 0, 0, 0, 0, 0)
    return -1, nxt, 0.0, 0.0, 0.0


@ray_jit
def _kd_visit(node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests, rs, sn, s0, s1,
              nodes, nodes_f, tv, blk, bids, t4, tmin, anyhit, counters):
    """One node of one ray's traversal (pbrt-v2 KdTreeAccel::Intersect, or IntersectP when
    ``anyhit``): an interior node descends one level, front to back; a leaf (``node`` < 0: an empty
    one) is tested, then the next pending node is popped. Returns the ray's new state (node, ntmin,
    ntmax, sp, best, best_id, nvis, leaves, tests, done)."""
    one = np.uintp(1)
    nvis += 1
    if node >= 0:
        nu = np.uintp(2 * node)
        w = nodes[nu]
        axis = w & 3
        if axis != LEAF:
            # the above child is far away in memory: start loading it now (w >> 4 is 0 when a
            # child is an empty leaf, a harmless hint)
            prefetch(nodes, np.uintp(2 * (w >> 4)))
            split = np.float64(nodes_f[nu + one])
            fl = (w >> 2) & 3  # 1: below child empty, 2: above child empty
            below = -1 if fl == 1 else node + 1
            above = node + 1 if fl == 1 else (-1 if fl == 2 else w >> 4)
            au = np.uintp(axis)
            o = rs[au]
            d = rs[au + np.uintp(3)]
            inv = rs[au + np.uintp(6)]
            if d == 0.0:  # parallel to the plane: the origin's side (both when within the band)
                u = rs[np.uintp(15)]
                if o < split - u:
                    node = below
                elif o > split + u:
                    node = above
                else:
                    spu = np.uintp(sp)
                    sn[spu] = above
                    s0[spu] = ntmin
                    s1[spu] = ntmax
                    sp += 1
                    node = below
                return node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests, False
            tp = (split - o) * inv
            neg = d < 0.0
            first = above if neg else below
            second = below if neg else above
            # the children's widened ranges end 2 tol and the band's w beyond the plane; the
            # band is added to the node's range, not to tp, so the node-to-node chain (tp, a
            # compare, a select) is as long as without it (paired against the kernel without a
            # band: a branch for the rare nearly axis-parallel ray took 17-39 % more time, w
            # subtracted from tp -1..+4 %, this 1 % less to 1 % more)
            w = rs[au + np.uintp(9)]
            e = rs[au + np.uintp(12)]
            lo_tp = tp - e
            hi_tp = tp + e
            only_first = tp > ntmax + w
            only_second = tp < ntmin - w
            both = not (only_first or only_second)
            # branch-free: always write the todo entry, keep it only when both (and, without
            # counters, only when it is not an empty leaf: visiting one only counts)
            spu = np.uintp(sp)
            sn[spu] = second
            s0[spu] = max(ntmin, lo_tp)
            s1[spu] = ntmax
            keep = both and (counters is not None or second >= 0)
            sp += 1 if keep else 0
            node = second if only_second else first
            ntmax = min(ntmax, hi_tp) if both else ntmax
            return node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests, False
        leaves += 1
        cnt = w >> 2
        x = nodes[nu + one]
        ox = rs[0]
        oy = rs[1]
        oz = rs[2]
        dx = rs[3]
        dy = rs[4]
        dz = rs[5]
        if cnt == 1:  # single-triangle leaf: the triangle's index inline
            r = np.uintp(x)
            tests += 1
            t = ray_triangle(ox, oy, oz, dx, dy, dz, tv[r, 0], tv[r, 1], tv[r, 2], tv[r, 3], tv[r, 4],
                             tv[r, 5], tv[r, 6], tv[r, 7], tv[r, 8], tmin, best)
            if t < best:
                best = t
                best_id = x
                if anyhit:
                    return node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests, True
        else:  # blocks of four from block x on, four triangles tested in vector lanes
            tests += cnt
            for bk in range(x, x + ((cnt + 3) >> 2)):
                hit = ray_tri4(blk, np.uintp(bk * TRI4_WORDS), ox, oy, oz, dx, dy, dz, tmin, best, t4)
                if hit != 0:
                    # the smallest t, ties to the first lane: the scalar loop's choice
                    for k in range(4):
                        if (hit >> k) & 1 and t4[k] < best:
                            best = t4[k]
                            best_id = bids[np.uintp(4 * bk + k)]
                    if anyhit:
                        return node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests, True
    else:
        leaves += 1  # an empty leaf: visited as pbrt does, but not stored
    # pop the next pending node; one that starts after the closest hit is skipped, not a stop:
    # the todo stack is not ordered by entry t. A ray in a split plane (d == 0, o == split) pushes
    # the above child with the parent's whole range, under the entries the below child's subtree
    # pushes later with larger entry t; and tol lets a child's entry t exceed its sibling's.
    sp = pop_within(s0, sp, best)
    if sp < 0:
        return node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests, True
    spu = np.uintp(sp)
    return sn[spu], s0[spu], s1[spu], sp, best, best_id, nvis, leaves, tests, False


@ray_jit
def _kd_turn(i, nxt, hi, node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests, rs, sn, s0,
             s1, O, D, tmin, tmax, anyhit, box, diag, nodes, nodes_f, tv, blk, bids, t4, out_t, out_id,
             counters):
    """One turn of one of :func:`kd_chunk`'s two rays: visit its next node; when its traversal is
    done, write its result and start the next ray in its place. Returns the slot's new state (i,
    nxt, node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests)."""
    node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests, done = _kd_visit(
        node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests, rs, sn, s0, s1, nodes,
        nodes_f, tv, blk, bids, t4, tmin, anyhit, counters)
    if done:
        store_ray(out_t, out_id, counters, i, best if best_id >= 0 else INF, best_id, 1, leaves, tests,
                  nvis, 0)
        i, nxt, best, ntmin, ntmax = _kd_next(nxt, hi, O, D, tmin, tmax, box, diag, rs, out_t, out_id,
                                              counters)
        return i, nxt, 0, ntmin, ntmax, 0, best, -1, 0, 0, 0
    return i, nxt, node, ntmin, ntmax, sp, best, best_id, nvis, leaves, tests


@jit
def kd_chunk(lo, hi, O, D, tmin, tmax, anyhit, box, diag, nodes, nodes_f, tv, blk, bids, stack_size,
             out_t, out_id, counters):
    """Trace rays lo..hi-1, two at a time, each with its own todo stack: every turn visits one
    node of each (:func:`_kd_turn`), so the two rays' node-to-node chains (a load, a float32 to
    float64 conversion, a subtract, a multiply, a compare, a select, then the next load) overlap
    in the core instead of running one after the other (1.20-1.34x the one-ray loop's speed on
    eight meshes, random and camera rays, paired, one thread; three or four rays at a time gained
    nothing more).
    ``nodes``/``nodes_f``: the flat int32 / float32 views of the node array; ``tv`` the triangles
    (one-triangle leaves); ``blk``/``bids`` the blocks of four of the larger leaves (flat float32,
    :data:`tracer.accel.simd_tri.TRI4_WORDS` a block) and their triangle indices (flat, four a
    block, -1 padding)."""
    t4 = np.empty(4, np.float64)  # the lanes' t of a block test
    ra = np.empty(16, np.float64)
    sna = np.empty(stack_size, np.int32)
    s0a = np.empty(stack_size, np.float64)
    s1a = np.empty(stack_size, np.float64)
    rb = np.empty(16, np.float64)
    ra[15] = rb[15] = box_pad(box)  # the band's half-width in space: one per structure (see _kd_next)
    snb = np.empty(stack_size, np.int32)
    s0b = np.empty(stack_size, np.float64)
    s1b = np.empty(stack_size, np.float64)
    ia, nxt, besta, ntmina, ntmaxa = _kd_next(lo, hi, O, D, tmin, tmax, box, diag, ra, out_t,
                                              out_id, counters)
    ib, nxt, bestb, ntminb, ntmaxb = _kd_next(nxt, hi, O, D, tmin, tmax, box, diag, rb, out_t,
                                              out_id, counters)
    nodea, spa, ida, nva, lfa, tsa = 0, 0, -1, 0, 0, 0
    nodeb, spb, idb, nvb, lfb, tsb = 0, 0, -1, 0, 0, 0
    while ia >= 0 or ib >= 0:
        if ia >= 0:
            ia, nxt, nodea, ntmina, ntmaxa, spa, besta, ida, nva, lfa, tsa = _kd_turn(
                ia, nxt, hi, nodea, ntmina, ntmaxa, spa, besta, ida, nva, lfa, tsa, ra, sna, s0a,
                s1a, O, D, tmin, tmax, anyhit, box, diag, nodes, nodes_f, tv, blk, bids, t4, out_t,
                out_id, counters)
        if ib >= 0:
            ib, nxt, nodeb, ntminb, ntmaxb, spb, bestb, idb, nvb, lfb, tsb = _kd_turn(
                ib, nxt, hi, nodeb, ntminb, ntmaxb, spb, bestb, idb, nvb, lfb, tsb, rb, snb, s0b,
                s1b, O, D, tmin, tmax, anyhit, box, diag, nodes, nodes_f, tv, blk, bids, t4, out_t,
                out_id, counters)


@pjit
def kd_trace(O, D, tmin, tmax, anyhit, box, diag, nodes, nodes_f, tv, blk, bids, stack_size,
             out_t, out_id, counters, nt):
    """Batched kd-tree traversal, ``prange`` over the ``nt`` threads, each taking every nt-th block of BLOCK rays (:data:`tracer.accel._jit.BLOCK`), two rays at a time, each with its own todo stack (:func:`kd_chunk`).
    ``counters`` is an (m, 5) int32 array or None (None compiles the variant without counting)."""
    m = O.shape[0]
    for th in prange(nt):
        for b in range(th, nblocks(m), nt):
            kd_chunk(b * BLOCK, min(m, (b + 1) * BLOCK), O, D, tmin, tmax, anyhit, box, diag, nodes,
                     nodes_f, tv, blk, bids, stack_size, out_t, out_id, counters)


def root_box(scene) -> np.ndarray:
    """The traversal's root box: the scene bounds joined with the triangles' bounds, padded by
    1e-5 of the largest extent so rays through boundary vertices meet it despite rounding."""
    v = scene.tris.reshape(-1, 3).astype(np.float64)
    lo = np.minimum(v.min(axis=0), scene.bounds[0].astype(np.float64))
    hi = np.maximum(v.max(axis=0), scene.bounds[1].astype(np.float64))
    pad = 1e-5 * max(float((hi - lo).max()), 1e-6)
    return np.concatenate([lo - pad, hi + pad])


def leaf_first_order(nodes: np.ndarray, tri_ids: np.ndarray, n: int) -> np.ndarray:
    """The scene's triangle indices in the order the stored leaves (depth-first) first reference
    them, then any never referenced: ``perm[new] = old``."""
    w = nodes[:, 0]
    lf = np.flatnonzero((w & 3) == LEAF)
    cnt = (w[lf] >> 2).astype(np.int64)
    x = nodes[lf, 1].astype(np.int64)
    rep = np.repeat(np.arange(len(lf)), cnt)
    off = np.arange(len(rep)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    xr = x[rep]
    multi = cnt[rep] > 1
    seq = xr.copy()
    if len(tri_ids):
        seq[multi] = tri_ids[xr[multi] + off[multi]]
    _, first = np.unique(seq, return_index=True)
    seen = seq[np.sort(first)]
    rest = np.setdiff1d(np.arange(n), seen, assume_unique=True)
    return np.concatenate([seen, rest]).astype(np.int64)


def leaf_blocks(nodes: np.ndarray, tri_ids: np.ndarray, tv: np.ndarray):
    """The leaves of more than one triangle as blocks of four (the SoA layout of
    :mod:`tracer.accel.simd_tri`, padded with degenerate triangles, index -1): (blocks (B, 36)
    float32, their indices (B, 4) int32). Rewrites such a leaf's second word from its offset in
    ``tri_ids`` to its first block; one-triangle leaves keep their inline index."""
    w = nodes[:, 0]
    multi = np.flatnonzero(((w & 3) == LEAF) & ((w >> 2) > 1))
    cnt = (w[multi] >> 2).astype(np.int64)
    nb = (cnt + 3) // 4
    first = np.cumsum(nb) - nb
    ids = np.full((int(nb.sum()), 4), -1, np.int32)
    # slot of each ref: block first + j // 4, lane j % 4
    rep = np.repeat(np.arange(len(multi)), cnt)
    j = np.arange(len(rep)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    ids[first[rep] + j // 4, j % 4] = tri_ids[nodes[multi, 1].astype(np.int64)[rep] + j]
    v = tv[np.maximum(ids, 0)].astype(np.float32)  # (B, 4 lanes, 9 coordinates)
    v[ids < 0] = 0.0  # padding: a degenerate triangle, which never hits
    nodes[multi, 1] = first.astype(np.int32)
    return np.ascontiguousarray(v.transpose(0, 2, 1).reshape(-1, TRI4_WORDS)), ids


class KdTree(TreeTraceMixin, Accel):
    """pbrt-v2 SAH kd-tree (KdTreeAccel). Parameters: ``isect_cost`` (80), ``trav_cost`` (1),
    ``empty_bonus`` (0.5), ``max_prims`` per leaf (1), ``max_depth`` (None: pbrt's
    round(8 + 1.3 floor(log2 N))), ``extra_depth`` (0: added to pbrt's max depth; the clip build spends
    levels on empty cut-offs around re-clipped triangles, 2 more levels pay there), ``clip`` (False: pbrt's build on whole-triangle bounds; True:
    perfect splits on triangles clipped to the node, :mod:`tracer.accel.kdtree_clip`), ``constants``
    (None, or a fitted estimator with ``ti_over_tt_``, e.g. :func:`experiments.core.probes.measure_sah_constants`:
    sets ``isect_cost`` to it with ``trav_cost`` 1)."""

    _kernel = staticmethod(kd_trace)

    name = "kdtree"
    counter_fields = {"setups": "1 if the ray enters the root box", "steps": "leaves visited",
                      "tests": "ray/triangle tests", "nodes": "nodes visited (leaves included)"}

    def __init__(self, isect_cost=PBRT_KD_ISECT_COST, trav_cost=PBRT_KD_TRAVERSAL_COST,
                 empty_bonus=PBRT_KD_EMPTY_BONUS, max_prims=PBRT_KD_MAX_PRIMS, max_depth=None,
                 extra_depth=0, clip=False, constants=None, leaf_order=True):
        if constants is not None:
            isect_cost, trav_cost = float(constants.ti_over_tt_), 1.0
        self.isect_cost, self.trav_cost, self.empty_bonus = isect_cost, trav_cost, empty_bonus
        self.max_prims, self.max_depth, self.clip = max_prims, max_depth, bool(clip)
        self.extra_depth, self.leaf_order = int(extra_depth), bool(leaf_order)

    def build(self, scene):
        n = scene.n
        if n >= 2**29:
            raise GridcostError(f"{n:,} triangles exceed the kd-tree's 29-bit index range")
        if int(self.max_prims) < 0:
            raise GridcostError(f"kd-tree max_prims must be >= 0, got {self.max_prims}")
        depth = (pbrt_max_depth(n) + self.extra_depth) if self.max_depth is None else int(self.max_depth)
        if depth < 0 or depth > 200:
            raise GridcostError(f"kd-tree max_depth must be in [0, 200], got {depth}")
        # edges (3 x 2N x 8 B) x ~4 for the work area, plus about 3 refs per triangle
        check_budget(f"a kd-tree over {n:,} triangles of {scene.name}", n * (3 * 2 * 8 * 4 + 3 * 40 + 16))
        t_start = time.perf_counter()
        tris = scene.tris
        lo = tris.min(axis=1)
        hi = tris.max(axis=1)
        rootb = (np.concatenate([lo.min(axis=0), hi.max(axis=0)]).astype(np.float64) if n
                 else np.zeros(6))
        costs = (int(self.max_prims), float(self.isect_cost), float(self.trav_cost), float(self.empty_bonus))
        if self.clip:
            built = kd_build_clip(np.ascontiguousarray(tris.reshape(-1, 9)), n, rootb, depth, *costs)
        else:
            ev_t, ev_c = sorted_edges(lo, hi)
            cap = max(16, 8 * n)
            wt = np.empty((3, cap), np.float32)
            wc = np.empty((3, cap), np.int32)
            wt[:, :2 * n] = ev_t
            wc[:, :2 * n] = ev_c
            del ev_t, ev_c
            budget = memory_budget()
            built = kd_build(wt, wc, n, rootb, depth, *costs, budget)
            del wt, wc
            if built[4] < 0:
                raise GridcostError(
                    f"a kd-tree over {n:,} triangles of {scene.name} outgrew the memory budget of "
                    f"{fmt_bytes(budget)} while building (its triangles are duplicated into many leaves); "
                    f"raise it with GRIDCOST_MEMORY_BUDGET, or use clip=True or a smaller max_depth")
        (w0, w1, spl, leaf_ids, nleaves, nempty, depth_reached, s_inner, s_leaf, s_tests, root_area) = built
        inner = (w0 & 3) != LEAF
        w1 = np.where(inner, spl.view(np.int32), w1).astype(np.int32)
        # single-triangle leaves hold the triangle's index itself (no refs-array indirection)
        one_tri = ~inner & ((w0 >> 2) == 1)
        w1[one_tri] = leaf_ids[w1[one_tri]]
        nodes = kd_compact(w0, w1, depth)
        if len(nodes) >= 2**27:
            raise GridcostError(f"a kd-tree of {len(nodes):,} nodes exceeds the 27-bit child index")
        self.logical_nodes_ = len(w0)
        # vertices not copied per reference (9 refs per triangle would not fit L2): in scene order,
        # or in leaf order with the map back to the scene's indices (-1 stays -1)
        self.tri_order_ = None
        if self.leaf_order and n:
            perm = leaf_first_order(nodes, leaf_ids, n)
            inv = np.empty(n, np.int32)
            inv[perm] = np.arange(n, dtype=np.int32)
            one = ((nodes[:, 0] & 3) == LEAF) & ((nodes[:, 0] >> 2) == 1)
            nodes[one, 1] = inv[nodes[one, 1]]
            leaf_ids = inv[leaf_ids]
            self.tri_order_ = np.append(perm, -1).astype(np.int32)
        self.tri_ids_ = leaf_ids
        tv = tris.reshape(-1, 9)  # one copy into traversal memory, in leaf order when there is one
        self.tri_verts_ = traversal_array(tv) if self.tri_order_ is None else traversal_rows(tv, perm)
        blocks, block_ids = leaf_blocks(nodes, leaf_ids, self.tri_verts_)  # (writes the leaves' block words)
        self.blocks_, self.block_ids_ = traversal_array(blocks), traversal_array(block_ids)
        self.nodes_ = traversal_array(nodes)
        self.nodes_f_ = self.nodes_.view(np.float32)
        self.box_ = root_box(scene) if n else np.zeros(6)
        self.build_seconds_ = time.perf_counter() - t_start
        self.diag_ = float(np.linalg.norm(self.box_[3:] - self.box_[:3]))
        self.n_, self.max_depth_, self.depth_ = n, depth, int(depth_reached)
        self.leaves_, self.empty_leaves_ = int(nleaves), int(nempty)
        ra = root_area if root_area > 0 else np.nan
        self.sah_ = {"exp_inner": s_inner / ra, "exp_leaves": s_leaf / ra, "exp_tests": s_tests / ra}
        self.scene_name_ = scene.name
        return self

    def _tree_arrays(self) -> tuple:
        return (self.nodes_.reshape(-1), self.nodes_f_.reshape(-1), self.tri_verts_, self.blocks_.reshape(-1),
                self.block_ids_.reshape(-1))

    def _scene_ids(self, out_id):
        """Stored (leaf-order) indices -> the scene's; -1 -> -1."""
        return out_id if self.tri_order_ is None else self.tri_order_[out_id]

    def stats(self) -> dict:
        nn = self.logical_nodes_
        refs = len(self.tri_ids_)
        e = self.sah_
        return {
            "structure": "kdtree", "nodes": nn, "interior": nn - self.leaves_, "leaves": self.leaves_,
            "empty_leaves": self.empty_leaves_, "stored_nodes": len(self.nodes_),
            "depth": self.depth_, "max_depth": self.max_depth_,
            "refs": refs, "refs_per_tri": refs / max(self.n_, 1),
            "mean_leaf_refs": refs / max(self.leaves_ - self.empty_leaves_, 1),
            # Havran-style expectations for a ray meeting the root box (surface-area ratios)
            "exp_inner": e["exp_inner"], "exp_leaves": e["exp_leaves"], "exp_tests": e["exp_tests"],
            "sah_cost": self.trav_cost * e["exp_inner"] + self.isect_cost * e["exp_tests"],
            "memory_bytes": int(self.nodes_.nbytes + self.tri_ids_.nbytes + self.tri_verts_.nbytes
                                + self.blocks_.nbytes + self.block_ids_.nbytes
                                + (0 if self.tri_order_ is None else self.tri_order_.nbytes)),
            "working_set": working_set(self.nodes_.nbytes, self.tri_ids_.nbytes + self.block_ids_.nbytes
                                       + (0 if self.tri_order_ is None else self.tri_order_.nbytes),
                                       self.tri_verts_.nbytes + self.blocks_.nbytes),
            "build_s": self.build_seconds_,
            "params": {"isect_cost": self.isect_cost, "trav_cost": self.trav_cost,
                       "empty_bonus": self.empty_bonus, "max_prims": self.max_prims},
            "clip": self.clip, "extra_depth": self.extra_depth, "leaf_order": self.leaf_order,
        }
