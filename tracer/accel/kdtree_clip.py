"""SAH kd-tree build with exact ("perfect") split candidates from clipped triangle bounds
(Wald & Havran 2006, "On building fast kd-trees for ray tracing, and on doing that in
O(N log N)", Sec. 4 split clipping and the O(N log^2 N) sort-per-node variant of Sec. 5.1).

Every reference (triangle in a node) carries the bounds of the triangle clipped to the node's box;
the SAH candidates are those bounds, on all three axes; the classification uses them too. So a
triangle whose bounding box overlaps a child's box but whose surface does not is not put in that
child, and planes at the clipped extent cut the empty space around a slanted triangle exactly.

Per node (cost terms as :mod:`tracer.accel.kdtree_build`, pbrt-v2 with its empty bonus):

* events per axis: a planar event at ``lo`` when the clipped extent is flat (``lo == hi``), else an
  end event at ``hi`` and a start event at ``lo``; sorted by (position, end < planar < start);
* sweep (Wald & Havran Alg. 1): at each position p with pE ends, pP planar, pS starts,
  ``N_R -= pP + pE``; planes strictly inside the node are scored with the planar triangles on the
  left and on the right (:func:`sah_split_cost`), then ``N_L += pS + pP``;
* leaf rules of pbrt-v2: ``n <= max_prims``, depth budget spent, no candidate, best cost > 4 x the
  leaf cost with n < 16, or the third split costlier than the leaf;
* classification (Wald & Havran Sec. 4.3): ``hi <= s`` left, ``lo >= s`` right, flat at ``s`` to
  the side the SAH chose; straddlers go to both, each side's bounds re-clipped to the child box.

Robustness: clipping is Sutherland-Hodgman in float64 on the float32 vertices against the child
box (inclusive planes); the result is rounded outward to float32 (candidate planes are stored as
float32, after a pad of :data:`CLIP_PAD_REL` of the triangle's magnitude) and clamped to the child box, so a reference's bounds always contain the part of its
triangle inside the node. A straddler whose clip comes out empty through rounding keeps its old
bounds cut at the plane (a spare reference, never a lost one). The traversal of
:mod:`tracer.accel.kdtree` is unchanged and its t-range widening covers the rest, so hits stay
bit-identical to the oracle.
"""
from __future__ import annotations

import numpy as np

from tracer.accel._jit import jit
from tracer.accel.geometry import INF
from tracer.accel.kdtree_build import (_area, _grow, axis_extent, child_probs, close_leaf, leaf_verdict, open_node,
                                 sah_split_cost, split_node, tree_arrays, tree_result)

#: event types, in their sort order at equal positions (Wald & Havran: end < planar < start)
EV_END, EV_PLANAR, EV_START = 0, 1, 2
#: outward pad of a clipped extent, relative to the triangle's largest coordinate magnitude, before
#: it is rounded outward to float32: the float64 clip of a sliver (edge points interpolated through up
#: to six planes) can land a few float64 ulps inside the true extent, and when that point is itself a
#: float32 the outward rounding keeps it and the reference's bounds miss the triangle's tip. 2^-32
#: is ~2^20 float64 ulps, far above that error and far below one float32 ulp (2^-23).
CLIP_PAD_REL = 2.0 ** -32
_LOW30 = (1 << 30) - 1


@jit(inline="always")
def _mono(bits):
    """The bits of a float32 -> uint64 key that orders like the float (-0.0 taken as +0.0)."""
    b = np.uint64(bits)
    if b == np.uint64(0x80000000):
        return np.uint64(0x80000000)
    if b >> np.uint64(31):
        return b ^ np.uint64(0xFFFFFFFF)
    return b | np.uint64(0x80000000)


@jit
def _clip_bounds(tv, tri, box, poly, out):
    """Bounds of triangle ``tri`` clipped to ``box`` (6 float64: lo, hi) into ``out`` (float64);
    returns False when nothing is left. ``poly`` is a (2, 10, 3) float64 scratch array."""
    cnt = 3
    for k in range(3):
        for c in range(3):
            poly[0, k, c] = np.float64(tv[tri, 3 * k + c])
    src = 0
    for plane in range(6):
        a = plane % 3
        side_lo = plane < 3
        bnd = box[plane]
        dst = 1 - src
        m = 0
        for k in range(cnt):
            kn = k + 1 if k + 1 < cnt else 0
            pa = poly[src, k, a]
            pb = poly[src, kn, a]
            ina = pa >= bnd if side_lo else pa <= bnd
            inb = pb >= bnd if side_lo else pb <= bnd
            if ina:
                for c in range(3):
                    poly[dst, m, c] = poly[src, k, c]
                m += 1
            if ina != inb:
                s = (bnd - pa) / (pb - pa)
                for c in range(3):
                    poly[dst, m, c] = poly[src, k, c] + s * (poly[src, kn, c] - poly[src, k, c])
                poly[dst, m, a] = bnd
                m += 1
        cnt = m
        src = dst
        if cnt == 0:
            return False
    for c in range(3):
        lo = INF
        hi = -INF
        for k in range(cnt):
            v = poly[src, k, c]
            lo = min(lo, v)
            hi = max(hi, v)
        out[c] = lo
        out[3 + c] = hi
    return True


@jit(inline="always")
def _down32(x):
    """The largest float32 <= x (x float64)."""
    f = np.float32(x)
    if np.float64(f) > x:
        f = np.nextafter(f, np.float32(-np.inf))
    return f


@jit(inline="always")
def _up32(x):
    """The smallest float32 >= x (x float64)."""
    f = np.float32(x)
    if np.float64(f) < x:
        f = np.nextafter(f, np.float32(np.inf))
    return f


@jit
def _child_bounds(tv, tri, ob, box, poly, cb, dst, k):
    """Write into ``dst[6k:6k+6]`` the parent bounds ``ob`` (6 float32) of triangle ``tri``
    re-clipped to the child ``box``: outward-rounded float32, clamped to the box and to the
    parent bounds; the parent bounds cut to the box when the clip is empty through rounding."""
    ok = _clip_bounds(tv, tri, box, poly, cb)
    mag = 0.0
    for j in range(9):
        mag = max(mag, abs(np.float64(tv[tri, j])))
    pad = CLIP_PAD_REL * mag
    for c in range(6):
        old = ob[c]
        if c < 3:
            v = max(_down32(cb[c] - pad), old) if ok else old
            v = max(v, np.float32(box[c]))
        else:
            v = min(_up32(cb[c] + pad), old) if ok else old
            v = min(v, np.float32(box[c]))
        dst[6 * k + c] = v
    for c in range(3):  # a degenerate clip (rounding) must not leave lo > hi
        if dst[6 * k + c] > dst[6 * k + 3 + c]:
            dst[6 * k + c] = max(ob[c], np.float32(box[c]))
            dst[6 * k + 3 + c] = min(ob[3 + c], np.float32(box[3 + c]))


@jit
def _best_split(rb, base, n, bounds, keys, isect_cost, trav_cost, empty_bonus):
    """Wald & Havran's event sweep over the three axes of a node's references (``rb`` bounds of
    refs base..base+n-1). Returns (cost, axis, position, planar_left)."""
    rbu = rb.view(np.uint32)
    area = _area(bounds)
    inv_total = 1.0 / area
    best_cost = INF
    best_axis = -1
    best_pos = np.float32(0.0)
    best_pl = True
    for axis in range(3):
        lo_a, hi_a, cap_ab, sum_ab = axis_extent(bounds, axis)
        if not hi_a > lo_a:
            continue
        ne = 0
        for j in range(n):
            q = 6 * (base + j) + axis
            if rb[q] == rb[q + 3]:
                keys[ne] = (_mono(rbu[q]) << np.uint64(32)) | np.uint64(EV_PLANAR << 30 | j)
                ne += 1
            else:
                keys[ne] = (_mono(rbu[q + 3]) << np.uint64(32)) | np.uint64(EV_END << 30 | j)
                keys[ne + 1] = (_mono(rbu[q]) << np.uint64(32)) | np.uint64(EV_START << 30 | j)
                ne += 2
        ev = np.sort(keys[:ne])
        n_l = 0
        n_r = n
        i = 0
        while i < ne:
            hi32 = ev[i] >> np.uint64(32)
            j0 = np.int64(ev[i] & np.uint64(_LOW30))
            ty0 = np.int64((ev[i] >> np.uint64(30)) & np.uint64(3))
            p = rb[6 * (base + j0) + (3 + axis if ty0 == EV_END else axis)]
            p_e = 0
            p_p = 0
            p_s = 0
            while i < ne and (ev[i] >> np.uint64(32)) == hi32:
                ty = (ev[i] >> np.uint64(30)) & np.uint64(3)
                if ty == EV_END:
                    p_e += 1
                elif ty == EV_PLANAR:
                    p_p += 1
                else:
                    p_s += 1
                i += 1
            n_r -= p_p + p_e
            t = np.float64(p)
            if t > lo_a and t < hi_a:
                p_below, p_above = child_probs(t, lo_a, hi_a, cap_ab, sum_ab, inv_total)
                c_l = sah_split_cost(trav_cost, isect_cost, empty_bonus, p_below, p_above, n_l + p_p, n_r)
                c_r = sah_split_cost(trav_cost, isect_cost, empty_bonus, p_below, p_above, n_l, n_r + p_p)
                if c_l < best_cost:
                    best_cost, best_axis, best_pos, best_pl = c_l, axis, p, True
                if c_r < best_cost:
                    best_cost, best_axis, best_pos, best_pl = c_r, axis, p, False
            n_l += p_s + p_p
    return best_cost, best_axis, best_pos, best_pl


@jit
def _clip_partition(tv, rid, rb, base, n, ba, tsplit, planar_left, bounds, poly, cb, cbox, ob):
    """Classify a node's refs against ``tsplit`` on ``ba`` (see module doc), straddlers re-clipped
    to each child box. The above child's refs end up compacted at ``base``, the below child's right
    after them. Returns (rid, rb (grown when full), n below, n above)."""
    # below child's refs go on top of the work area, the above child's are compacted in place
    # (write index <= read index)
    need = base + 2 * n
    if need > rid.shape[0] or 6 * need > rb.shape[0]:
        cap = max(need, rid.shape[0] * 3 // 2)
        rid = _grow(rid, cap)
        rb = _grow(rb, 6 * cap)
    wl = base + n
    wr = base
    for j in range(base, base + n):
        lo = rb[6 * j + ba]
        hi = rb[6 * j + 3 + ba]
        tri = rid[j]
        if lo == hi and lo == tsplit:
            left = planar_left
            right = not planar_left
        else:
            left = lo < tsplit
            right = hi > tsplit
        if left and right:  # straddler: re-clip to each child box
            for c in range(6):
                cbox[c] = bounds[c]
                ob[c] = rb[6 * j + c]
            cbox[3 + ba] = tsplit
            rid[wl] = tri
            _child_bounds(tv, tri, ob, cbox, poly, cb, rb, wl)
            wl += 1
            cbox[3 + ba] = bounds[3 + ba]
            cbox[ba] = tsplit
            _child_bounds(tv, tri, ob, cbox, poly, cb, rb, wr)
            rid[wr] = tri
            wr += 1
        elif left:
            rid[wl] = tri
            for c in range(6):
                rb[6 * wl + c] = rb[6 * j + c]
            wl += 1
        else:
            rid[wr] = tri
            for c in range(6):
                rb[6 * wr + c] = rb[6 * j + c]
            wr += 1
    n_lo = wl - (base + n)
    n_hi = wr - base
    # the below child's refs move down to base + n_hi.. so the work area stays compact
    for j in range(n_lo):
        rid[base + n_hi + j] = rid[base + n + j]
        for c in range(6):
            rb[6 * (base + n_hi + j) + c] = rb[6 * (base + n + j) + c]
    return rid, rb, n_lo, n_hi


@jit
def kd_build_clip(tv, n_prims, root, max_depth, max_prims, isect_cost, trav_cost, empty_bonus):
    """Iterative perfect-split SAH build (see module doc) over triangles ``tv`` (N, 9) float32 in
    the root box ``root``. Returns what :func:`tracer.accel.kdtree_build.kd_build` returns: node word 0,
    node word 1, split, leaf prim ids, leaves, empty leaves, max depth reached, SAH area sums
    (interior, leaf, leaf x count), root area."""
    cap = max(16, 4 * n_prims)
    rid = np.empty(cap, np.int32)
    rb = np.empty(6 * cap, np.float32)
    for j in range(n_prims):
        rid[j] = j
        for c in range(3):
            lo = min(tv[j, c], tv[j, 3 + c], tv[j, 6 + c])
            hi = max(tv[j, c], tv[j, 3 + c], tv[j, 6 + c])
            rb[6 * j + c] = lo
            rb[6 * j + 3 + c] = hi
    keys = np.empty(max(16, 2 * n_prims), np.uint64)
    poly = np.empty((2, 10, 3), np.float64)
    cb = np.empty(6, np.float64)
    cbox = np.empty(6, np.float64)
    ob = np.empty(6, np.float32)
    w0, w1, spl, leaf_ids, ic, fs, st, st_bounds, bounds, root_area = tree_arrays(n_prims, max_depth, root)
    sp = 1
    while sp > 0:
        w0, w1, spl, sp, node, base, n, depth, bad, area, make_leaf = open_node(
            w0, w1, spl, ic, st, st_bounds, sp, bounds, max_depth, max_prims)
        ba = -1
        tsplit = np.float32(0.0)
        planar_left = True
        if not make_leaf:
            if 2 * n > keys.shape[0]:
                keys = np.empty(2 * n, np.uint64)
            best_cost, ba, tsplit, planar_left = _best_split(rb, base, n, bounds, keys, isect_cost,
                                                             trav_cost, empty_bonus)
            bad, make_leaf = leaf_verdict(best_cost, ba, n, bad, isect_cost)
        if make_leaf:
            leaf_ids, off = close_leaf(w0, w1, spl, leaf_ids, ic, fs, node, n, area)
            leaf_ids[off:off + n] = rid[base:base + n]
            continue
        rid, rb, n_lo, n_hi = _clip_partition(tv, rid, rb, base, n, ba, tsplit, planar_left, bounds,
                                              poly, cb, cbox, ob)
        sp = split_node(w0, w1, spl, fs, st, st_bounds, sp, node, ba, tsplit, bounds, area, base + n_hi,
                        n_lo, base, n_hi, depth, bad)
    return tree_result(w0, w1, spl, leaf_ids, ic, fs, root_area)
