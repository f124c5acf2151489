"""Fournier & Poulin (1993): a ray tracing accelerator based on a hierarchy of 1D sorted lists.

Every object (triangle) and every bounding volume (BV) is an axis-aligned box; for each BV the
lo/hi coordinates of its children's boxes are *events*, pre-sorted once per axis. A ray walks
the events in ray order on all three axes at once (the smallest next Delta-t first); an event
is IN or OUT depending on the sign of the direction. A child becomes *active* when it has been
entered on all three axes before it is exited on any (per-child counts 0..3, -1 = processed):
a triangle is then tested, a BV *opened*. The walk stops when the next event lies past the
closest hit (or at the first hit for shadow rays), or at the end of one of the lists (every
object has then been exited on that axis).

Hierarchy (Sec. "Building a hierarchy"): top down, a node holding more than ``leaf_size``
objects lays a regular ``branching`` grid over its objects' box centroids and groups the objects
by the cell of their centroid; each non-empty cell of two or more objects becomes a child BV
bounded by its objects (BVs may overlap, objects are never split or duplicated), a lone object
stays a direct child. Up to ``leaf_size`` objects larger than ``big`` times the node's extent are
kept as direct children of the node (the paper's "special grid element"). ``hierarchy=False``
gives the flat method of the paper's Table 1 (one node, all triangles its children).

Hierarchical traversal (Sec. "Traversing a hierarchy"): opening a BV at Delta-t ``t`` walks its
three lists up to ``t`` (events before it are treated without intersecting anything; children
found IN on all axes are activated at ``t``) and puts the three next events of the BV in the
*list of next events*: here one binary heap keyed by (Delta-t, IN before OUT) holding one cursor
per (open BV, axis). Closing a BV (its OUT event, or the end of one of its lists) drops its
cursors lazily, when they surface.

Layout (flat arrays): nodes in breadth-first order, node 0 the root; node ``p``'s children are
the *slots* ``child_start_[p] .. child_start_[p+1]``, a slot being a triangle (``slot_tri_ >= 0``,
vertices in ``tri_verts_[slot]``) or a BV (``slot_node_``). Node ``p``'s events on axis ``k`` are
``ev_val_[6 a + 2 m k : 6 a + 2 m (k + 1)]`` with a = cs[p], m = cs[p+1] - a (node-major, so
one node's events are contiguous; float32, sorted, lo before hi at equal values) and ``ev_code_``
(2 slot + is_hi). Per-chunk scratch: child states (int8 per slot), cursors, heap.

Robustness: object boxes are padded outwards (``PAD_REL`` of the scene extent plus a few float32
ulps) so that a hit found by :func:`tracer.accel.geometry.ray_triangle` lies strictly inside its box
even after rounding of Delta-t; boxes are inclusive (IN events before OUT events at equal
Delta-t); a zero direction component makes that axis static (IN where the slab holds the origin).

Counters: ``setups`` 1 per ray, ``steps`` events treated (also those walked while opening a BV),
``tests`` ray-triangle tests, ``nodes`` BVs opened (the root included), ``skips`` events of
children already processed (a subset of ``steps``).
"""
from __future__ import annotations

import time

import numba
import numpy as np
from numba import prange

from tracer.accel._jit import BLOCK, jit, nblocks, pjit, store_ray
from tracer.accel import COUNTER_NAMES, Accel
from tracer.errors import GridcostError
from tracer.accel.geometry import INF, ray_triangle
from tracer.measure.memory import check_budget

#: object boxes are padded by this fraction of the largest scene extent ...
PAD_REL = 1e-6
#: ... plus this fraction of the coordinate's magnitude (a few float32 ulps)
PAD_ULP = 4.0e-7
NCOUNT = len(COUNTER_NAMES)


# ---------------------------------------------------------------- build
@jit
def _node_bounds(tb, perm, s, e):
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    clo = np.full(3, np.inf)
    chi = np.full(3, -np.inf)
    for i in range(s, e):
        t = perm[i]
        for k in range(3):
            a = float(tb[t, k])
            b = float(tb[t, 3 + k])
            lo[k] = min(lo[k], a)
            hi[k] = max(hi[k], b)
            c = 0.5 * (a + b)
            clo[k] = min(clo[k], c)
            chi[k] = max(chi[k], c)
    return lo, hi, clo, chi


@jit
def _new_bv(q_s, q_e, slot_node, node_slot, depth, p, q, slot, s, e):
    """Make slot ``slot`` of node ``p`` the new BV ``q`` over objects perm[s:e] (queued)."""
    slot_node[slot] = q
    node_slot[q] = slot
    depth[q] = depth[p] + 1
    q_s[q] = s
    q_e[q] = e


@jit
def build_hierarchy(tb, leaf_size, bx, by, bz, big, flat):
    """Top-down grid-of-centroids hierarchy over object boxes ``tb`` (N, 6) float32.

    Returns (child_start (B + 1), slot_tri (S), slot_node (S), node_slot (B), node_depth (B)),
    nodes in breadth-first order (a node's children have larger ids), S = N + B - 1 slots."""
    n = tb.shape[0]
    cap_b = max(1, n)
    cs = np.zeros(cap_b + 1, np.int64)
    slot_tri = np.full(n + cap_b, -1, np.int32)
    slot_node = np.full(n + cap_b, -1, np.int32)
    node_slot = np.full(cap_b, -1, np.int32)
    depth = np.zeros(cap_b, np.int32)
    q_s = np.empty(cap_b, np.int64)
    q_e = np.empty(cap_b, np.int64)
    perm = np.arange(n).astype(np.int64)
    tmp = np.empty(n, np.int64)
    cell = np.empty(n, np.int64)
    ncell_max = bx * by * bz
    cnt = np.zeros(ncell_max + 1, np.int64)
    q_s[0] = 0
    q_e[0] = n
    nn = 1
    nslot = 0
    p = 0
    while p < nn:
        s = q_s[p]
        e = q_e[p]
        cs[p] = nslot
        m = e - s
        if flat or m <= leaf_size:
            for i in range(s, e):
                slot_tri[nslot] = perm[i]
                nslot += 1
            p += 1
            continue
        lo, hi, clo, chi = _node_bounds(tb, perm, s, e)
        # the "special grid element": up to leaf_size objects spanning more than `big` of the node
        r = s
        if big > 0.0:
            lim = big * max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2])
            nb = 0
            for i in range(s, e):
                t = perm[i]
                cell[i] = 1 if max(tb[t, 3] - tb[t, 0], tb[t, 4] - tb[t, 1], tb[t, 5] - tb[t, 2]) > lim else 0
                nb += cell[i]
            if 0 < nb <= leaf_size and nb < m:
                w = 0
                u = nb
                for i in range(s, e):  # stable partition, the big objects first
                    if cell[i] == 1:
                        tmp[w] = perm[i]
                        w += 1
                    else:
                        tmp[u] = perm[i]
                        u += 1
                for i in range(m):
                    perm[s + i] = tmp[i]
                for i in range(s, s + nb):
                    slot_tri[nslot] = perm[i]
                    nslot += 1
                r = s + nb
                lo, hi, clo, chi = _node_bounds(tb, perm, r, e)
        rest = e - r
        nx = bx if chi[0] > clo[0] else 1
        ny = by if chi[1] > clo[1] else 1
        nz = bz if chi[2] > clo[2] else 1
        if rest <= 1 or nx * ny * nz == 1 or (r > s and rest <= leaf_size):
            if rest >= 2 and r > s:  # the small rest: one child BV beside the big objects
                _new_bv(q_s, q_e, slot_node, node_slot, depth, p, nn, nslot, r, e)
                nn += 1
                nslot += 1
            else:
                for i in range(r, e):
                    slot_tri[nslot] = perm[i]
                    nslot += 1
            p += 1
            continue
        # counting sort of the rest by the grid cell of their centroid
        nc = nx * ny * nz
        for c in range(nc + 1):
            cnt[c] = 0
        for i in range(r, e):
            t = perm[i]
            ci = 0
            mul = 1
            for k in range(3):
                nk = nx if k == 0 else (ny if k == 1 else nz)
                if nk > 1:
                    c = 0.5 * (float(tb[t, k]) + float(tb[t, 3 + k]))
                    j = int((c - clo[k]) / (chi[k] - clo[k]) * nk)
                    j = min(max(j, 0), nk - 1)
                    ci += j * mul
                mul *= nk
            cell[i] = ci
            cnt[ci + 1] += 1
        for c in range(nc):
            cnt[c + 1] += cnt[c]
        for i in range(r, e):
            ci = cell[i]
            tmp[cnt[ci]] = perm[i]
            cnt[ci] += 1
        # cnt[c] is now the end of cell c (relative to r)
        start = 0
        for c in range(nc):
            end = cnt[c]
            for i in range(start, end):
                perm[r + i] = tmp[i]
            k = end - start
            if k == 1:
                slot_tri[nslot] = perm[r + start]
                nslot += 1
            elif k >= 2:
                _new_bv(q_s, q_e, slot_node, node_slot, depth, p, nn, nslot, r + start, r + end)
                nn += 1
                nslot += 1
            start = end
        p += 1
    cs[nn] = nslot
    return cs[:nn + 1].copy(), slot_tri[:nslot].copy(), slot_node[:nslot].copy(), node_slot[:nn].copy(), depth[:nn].copy()


@jit
def build_events(cs, slot_tri, slot_node, tb):
    """Node boxes (bottom up) and the sorted per-axis event lists of every node's children."""
    nb = cs.shape[0] - 1
    ns = slot_tri.shape[0]
    nbox = np.empty((nb, 6), np.float32)
    for p in range(nb - 1, -1, -1):
        for k in range(3):
            nbox[p, k] = np.inf
            nbox[p, 3 + k] = -np.inf
        for s in range(cs[p], cs[p + 1]):
            t = slot_tri[s]
            for k in range(6):
                v = tb[t, k] if t >= 0 else nbox[slot_node[s], k]
                if k < 3:
                    nbox[p, k] = min(nbox[p, k], v)
                else:
                    nbox[p, k] = max(nbox[p, k], v)
    ev_val = np.empty(6 * ns, np.float32)
    ev_code = np.empty(6 * ns, np.int32)
    for p in range(nb):
        a = cs[p]
        m = cs[p + 1] - a
        vals = np.empty(2 * m, np.float32)
        for k in range(3):
            for i in range(m):
                s = a + i
                t = slot_tri[s]
                if t >= 0:
                    vals[i] = tb[t, k]
                    vals[m + i] = tb[t, 3 + k]
                else:
                    vals[i] = nbox[slot_node[s], k]
                    vals[m + i] = nbox[slot_node[s], 3 + k]
            order = np.argsort(vals, kind="mergesort")  # stable: lo before hi at equal values
            for j in range(2 * m):
                o = order[j]
                ev_val[6 * a + 2 * m * k + j] = vals[o]
                ev_code[6 * a + 2 * m * k + j] = 2 * (a + (o % m)) + (1 if o >= m else 0)
    return nbox, ev_val, ev_code


def padded_boxes(tris: np.ndarray) -> np.ndarray:
    """(N, 6) float32 [lo xyz, hi xyz] triangle boxes padded outwards (see module docstring)."""
    v = tris.astype(np.float64)
    lo = v.min(axis=1)
    hi = v.max(axis=1)
    ext = float((hi.max(axis=0) - lo.min(axis=0)).max()) if len(v) else 1.0
    pad_lo = PAD_REL * max(ext, 1e-30) + PAD_ULP * np.abs(lo)
    pad_hi = PAD_REL * max(ext, 1e-30) + PAD_ULP * np.abs(hi)
    return np.concatenate([lo - pad_lo, hi + pad_hi], axis=1).astype(np.float32)


# ---------------------------------------------------------------- traversal
@jit(inline="always")
def _ev_t(val, hi, o, inv, mode):
    """Delta-t and IN-ness of an event. mode 0: d > 0 (lo = IN), 1: d < 0 (hi = IN), 2: d == 0:
    a static axis, where IN (lo <= o) and OUT (hi < o) events are all at -inf, the others at +inf."""
    if mode == 2:
        if hi == 0:
            return (-INF if float(val) <= o else INF), True
        return (-INF if float(val) < o else INF), False
    return (float(val) - o) * inv, hi == mode


@jit(inline="always")
def _treat(st, s, isin, pend, npend):
    """Treat an event of child slot ``s``: IN counts up (and queues the child in ``pend`` when it
    reaches 3), OUT marks it processed (-1); a processed child is skipped. Written without
    branches (events are the inner loop, and their outcome is unpredictable).
    Returns (npend, 1 if skipped else 0)."""
    v = st[s]
    nv = v + 1 if isin else -1
    if v < 0:
        nv = v
    st[s] = nv
    pend[npend] = s
    return npend + (nv == 3), v < 0


@jit(inline="always")
def _heap_before(t, isin, t2, isin2):
    """The heap order of keys (t, isin): smaller t first, IN before OUT at equal t."""
    return (t < t2) | ((t == t2) & (isin > isin2))


@jit(inline="always")
def _heap_put(hp, h_t, h_in, i, c, t, isin):
    """Store cursor ``c`` with key (t, isin) in heap slot ``i``."""
    hp[i] = c
    h_t[i] = t
    h_in[i] = isin


@jit(inline="always")
def _heap_push(hp, h_t, h_in, n, c, t, isin):
    """Insert cursor ``c`` with key (t, IN first) into the heap hp[0:n] (keys h_t, h_in kept in
    heap order beside it). Returns the new size."""
    i = n
    while i > 0:
        p = (i - 1) >> 1
        tp = h_t[p]
        if _heap_before(t, isin, tp, h_in[p]):
            _heap_put(hp, h_t, h_in, i, hp[p], tp, h_in[p])
            i = p
        else:
            break
    _heap_put(hp, h_t, h_in, i, c, t, isin)
    return n + 1


@jit(inline="always")
def _heap_down(hp, h_t, h_in, n, c, t, isin):
    """Put cursor ``c`` with key (t, isin) at the top of the heap hp[0:n] and sift it down."""
    i = 0
    while True:
        m = 2 * i + 1
        if m >= n:
            break
        tm = h_t[m]
        im = h_in[m]
        if m + 1 < n:
            t2 = h_t[m + 1]
            i2 = h_in[m + 1]
            if _heap_before(t2, i2, tm, im):
                m += 1
                tm = t2
                im = i2
        if _heap_before(tm, im, t, isin):
            _heap_put(hp, h_t, h_in, i, hp[m], tm, im)
            i = m
        else:
            break
    _heap_put(hp, h_t, h_in, i, c, t, isin)


@jit(inline="always")
def sl_ray(ox, oy, oz, dx, dy, dz, tmin, tmax, anyhit, cs, slot_tri, slot_node, nbox, tv, ev_val, ev_code,
           st, pend, hp, h_t, h_in, c_pos, c_end, c_slot, c_ax, org, inv, mode):
    """Trace one ray; returns (t, tri_id, setups, steps, tests, nodes, skips).

    One loop: open the BV pending (the root first) at the current Delta-t ``tcur``; activate the
    children queued in ``pend`` (test a triangle, or leave a BV to be opened next); else treat the
    next event, the top of the heap of cursors, unless it lies past the closest hit."""
    org[0] = ox
    org[1] = oy
    org[2] = oz
    t0 = -INF
    t1 = INF
    for k in range(3):
        d = dx if k == 0 else (dy if k == 1 else dz)
        md = 0 if d > 0.0 else (1 if d < 0.0 else 2)
        mode[k] = md
        inv[k] = 1.0 / d if md < 2 else 0.0
        up = 1 if md == 1 else 0  # the root box's IN and OUT events on this axis
        ta, _ = _ev_t(nbox[0, k + 3 * up], up, org[k], inv[k], md)
        tb, _ = _ev_t(nbox[0, k + 3 - 3 * up], 1 - up, org[k], inv[k], md)
        t0 = max(t0, ta)
        t1 = min(t1, tb)
    if t0 > t1 or t1 < tmin or t0 > tmax:
        return INF, -1, 1, 0, 0, 0, 0
    best = np.float64(tmax)
    best_id = -1
    tcur = max(t0, tmin)
    steps = 0
    skips = 0
    tests = 0
    nodes = 0
    hn = 0
    nc = 0
    npend = 0
    q_open = 0  # the BV to open now (node id; -1 none) and its slot in its parent (-1: root)
    s_open = -1
    while True:
        if q_open >= 0:
            # open BV q_open at tcur: reset its children, treat its events up to tcur, push cursors
            nodes += 1
            a = cs[q_open]
            b = cs[q_open + 1]
            for j in range(a, b):
                st[j] = 0
            m2 = 2 * (b - a)
            for k in range(3):
                md = mode[k]
                lo = 6 * a + m2 * k
                step = -1 if md == 1 else 1  # walk the list backwards for a negative direction
                pos = lo + m2 - 1 if md == 1 else lo
                end = lo - 1 if md == 1 else lo + m2
                o = org[k]
                iv = inv[k]
                t = INF
                isin = False
                while pos != end:
                    code = ev_code[pos]
                    t, isin = _ev_t(ev_val[pos], code & 1, o, iv, md)
                    if (t < tcur) | ((t == tcur) & isin):
                        steps += 1
                        npend, sk = _treat(st, code >> 1, isin, pend, npend)
                        skips += sk
                        pos += step
                    else:
                        break
                if pos != end and t < INF:
                    c_pos[nc] = pos
                    c_end[nc] = end
                    c_slot[nc] = s_open
                    c_ax[nc] = k
                    hn = _heap_push(hp, h_t, h_in, hn, nc, t, np.int8(1 if isin else 0))
                    nc += 1
            q_open = -1
        # activate the children that became IN on all axes at tcur
        while npend > 0:
            npend -= 1
            s = pend[npend]
            if st[s] != 3:
                continue
            q = slot_node[s]
            if q >= 0:
                q_open = q
                s_open = s
                break
            tests += 1
            t = ray_triangle(ox, oy, oz, dx, dy, dz, tv[s, 0], tv[s, 1], tv[s, 2], tv[s, 3], tv[s, 4],
                             tv[s, 5], tv[s, 6], tv[s, 7], tv[s, 8], tmin, best)
            if t < best:
                best = t
                best_id = slot_tri[s]
                if anyhit:
                    return best, best_id, 1, steps, tests, nodes, skips
        if q_open >= 0:
            continue
        if hn == 0:
            break
        c = hp[0]
        t = h_t[0]
        if t > best:
            break
        ps = c_slot[c]
        nk = t
        ni = h_in[0]
        if ps < 0 or st[ps] >= 0:  # a cursor of the root or of a BV still open: treat its event
            k = c_ax[c]
            md = mode[k]
            pos = c_pos[c]
            steps += 1
            npend, sk = _treat(st, ev_code[pos] >> 1, ni == 1, pend, npend)
            skips += sk
            tcur = t
            pos += -1 if md == 1 else 1
            if pos != c_end[c]:
                code = ev_code[pos]
                t2, in2 = _ev_t(ev_val[pos], code & 1, org[k], inv[k], md)
                c_pos[c] = pos
                nk = t2
                ni = np.int8(1 if in2 else 0)
            else:
                # the end of one of the node's lists: every child has been exited on this axis, so
                # none can become active any more (the paper's termination, per BV): close the node
                if ps < 0:
                    break
                st[ps] = -1
                c = -1
        else:
            c = -1
        if c < 0:  # cursor exhausted, or its BV closed: drop it
            hn -= 1
            if hn == 0:
                continue
            c = hp[hn]
            nk = h_t[hn]
            ni = h_in[hn]
        _heap_down(hp, h_t, h_in, hn, c, nk, ni)
    if best_id < 0:
        best = INF
    return best, best_id, 1, steps, tests, nodes, skips


@jit
def sl_chunk(lo, hi, O, D, tmin, tmax, anyhit, cs, slot_tri, slot_node, nbox, tv, ev_val, ev_code,
             out_t, out_id, counters, st, pend, hp, h_t, h_in, c_pos, c_end, c_slot, c_ax, org, inv, mode):
    """Trace rays lo..hi with one set of scratch buffers (arrays are passed once per chunk)."""
    for i in range(lo, hi):
        t, tid, su, stp, te, nv, sk = sl_ray(
            # widened as the grid and the oracle widen the ray (Numba's float() keeps a float32 a
            # float32), so ray_triangle runs on the same float64 inputs and t is bit-identical
            np.float64(O[i, 0]), np.float64(O[i, 1]), np.float64(O[i, 2]),
            np.float64(D[i, 0]), np.float64(D[i, 1]), np.float64(D[i, 2]),
            tmin, np.float64(tmax[i]), anyhit, cs, slot_tri, slot_node, nbox, tv, ev_val, ev_code,
            st, pend, hp, h_t, h_in, c_pos, c_end, c_slot, c_ax, org, inv, mode)
        store_ray(out_t, out_id, counters, i, t, tid, su, stp, te, nv, sk)


@pjit
def sl_trace(O, D, tmin, tmax, anyhit, cs, slot_tri, slot_node, nbox, tv, ev_val, ev_code,
             out_t, out_id, counters, nt):
    """Batched traversal, ``prange`` over the ``nt`` threads, each taking every nt-th block of BLOCK rays (:data:`tracer.accel._jit.BLOCK`), one set of scratch buffers per thread;
    ``counters`` (m, 5) int32 or None (the variant without counting)."""
    m = O.shape[0]
    ns = slot_tri.shape[0]
    ncur = 3 * (cs.shape[0] - 1)
    for th in prange(nt):
        st = np.empty(ns, np.int8)
        pend = np.empty(ns + 1, np.int32)
        hp = np.empty(ncur, np.int32)
        h_t = np.empty(ncur, np.float64)
        h_in = np.empty(ncur, np.int8)
        c_pos = np.empty(ncur, np.int64)
        c_end = np.empty(ncur, np.int64)
        c_slot = np.empty(ncur, np.int32)
        c_ax = np.empty(ncur, np.int8)
        org = np.empty(3, np.float64)
        inv = np.empty(3, np.float64)
        mode = np.empty(3, np.int8)
        for b in range(th, nblocks(m), nt):
            sl_chunk(b * BLOCK, min(m, (b + 1) * BLOCK), O, D, tmin, tmax, anyhit, cs, slot_tri, slot_node,
                     nbox, tv, ev_val, ev_code, out_t, out_id, counters, st, pend, hp, h_t, h_in, c_pos, c_end,
                     c_slot, c_ax, org, inv, mode)


class SortedLists(Accel):
    """Fournier & Poulin 1993 sorted event lists. ``hierarchy`` (True) builds the BV hierarchy;
    ``leaf_size`` (8) objects at most per leaf BV; ``branching`` cells per axis of the grid laid
    over each node's centroids (int or 3 ints; 2 = up to 8 children); ``big`` (0.5): objects larger
    than this fraction of their node stay its direct children (0 turns this off)."""

    name = "sortedlists"
    counter_fields = {"setups": "1 per ray", "steps": "events treated", "tests": "ray/triangle tests",
                      "nodes": "bounding volumes opened (the root included)",
                      "skips": "events of children already processed (a subset of steps)"}

    def __init__(self, hierarchy=True, leaf_size=8, branching=2, big=0.5):
        self.hierarchy, self.leaf_size, self.branching, self.big = hierarchy, leaf_size, branching, big

    def build(self, scene):
        br = np.broadcast_to(np.asarray(self.branching, np.int64), (3,))
        if (br < 1).any() or (br > 16).any() or br.prod() < 2:
            raise GridcostError(f"sorted-lists branching must be 1..16 per axis with at least 2 cells, got {self.branching}")
        if int(self.leaf_size) < 1:
            raise GridcostError(f"sorted-lists leaf_size must be >= 1, got {self.leaf_size}")
        n = scene.n
        if n >= 2**29:
            raise GridcostError(f"{n:,} triangles exceed the sorted lists' int32 slot range")
        check_budget(f"sorted lists over {n:,} triangles of {scene.name}", n * (24 + 2 * 48 + 36 + 64))
        t_start = time.perf_counter()
        self.n_ = n
        tb = padded_boxes(scene.tris)
        if n == 0:
            tb = np.zeros((0, 6), np.float32)
        cs, slot_tri, slot_node, node_slot, depth = build_hierarchy(
            tb, int(self.leaf_size), int(br[0]), int(br[1]), int(br[2]), float(self.big or 0.0),
            not self.hierarchy)
        nbox, ev_val, ev_code = build_events(cs, slot_tri, slot_node, tb)
        tv = np.zeros((len(slot_tri), 9), np.float32)
        is_tri = slot_tri >= 0
        tv[is_tri] = scene.tris.reshape(-1, 9)[slot_tri[is_tri]]
        self.child_start_, self.slot_tri_, self.slot_node_, self.node_slot_ = cs, slot_tri, slot_node, node_slot
        self.node_box_, self.ev_val_, self.ev_code_, self.tri_verts_ = nbox, ev_val, ev_code, tv
        self.depth_ = depth
        self.build_seconds_ = time.perf_counter() - t_start
        self.scene_name_ = scene.name
        return self

    def _trace(self, o, d, tmin, tmax, anyhit, count):
        m = len(o)
        out_t = np.empty(m, np.float32)
        out_id = np.empty(m, np.int32)
        cnt = np.zeros((m, NCOUNT), np.int32) if count else None
        if self.n_ == 0:
            out_t[:] = np.inf
            out_id[:] = -1
            if cnt is not None:
                cnt[:, 0] = 1
            return out_t, out_id, cnt
        if not tmax.flags.writeable:  # a read-only array would compile another variant
            tmax = tmax.copy()
        sl_trace(o, d, tmin, tmax, anyhit, self.child_start_, self.slot_tri_, self.slot_node_, self.node_box_, self.tri_verts_, self.ev_val_, self.ev_code_, out_t, out_id, cnt, numba.get_num_threads())
        return out_t, out_id, cnt

    def stats(self) -> dict:
        cs = self.child_start_
        nb = len(cs) - 1
        kids = np.diff(cs)
        leaf = np.array([not (self.slot_node_[cs[p]:cs[p + 1]] >= 0).any() for p in range(nb)], bool) if nb else np.zeros(0, bool)
        mem = sum(a.nbytes for a in (cs, self.slot_tri_, self.slot_node_, self.node_slot_, self.node_box_,
                                     self.ev_val_, self.ev_code_, self.tri_verts_))
        return {
            "structure": "sortedlists", "nodes": nb, "leaves": int(leaf.sum()), "slots": int(len(self.slot_tri_)),
            "events": int(self.ev_val_.shape[0]), "depth": int(self.depth_.max(initial=0)) + 1,
            "max_children": int(kids.max(initial=0)), "mean_children": float(kids.mean()) if nb else 0.0,
            "root_children": int(kids[0]) if nb else 0,
            "memory_bytes": int(mem), "build_s": self.build_seconds_,
            "params": {"hierarchy": bool(self.hierarchy), "leaf_size": int(self.leaf_size),
                       "branching": np.broadcast_to(np.asarray(self.branching), (3,)).tolist(), "big": self.big},
        }
