"""Wide BVH: 8 children per node on CPUs with AVX2 (one ``<8 x float>`` slab test, :func:`tracer.accel.simd.slab8`),
4 elsewhere (:func:`~tracer.accel.simd.slab4`), leaves of up to eight triangles tested in blocks of four
in ``<4 x double>`` lanes (:func:`tracer.accel.simd_tri.ray_tri4`).

Build: one canonical binned-SAH binary BVH (:func:`tracer.accel.bvh.bvh_build`, leaves priced in blocks of
four triangles, as Embree prices Triangle4 leaves; the leaf size and node weight are
:data:`~tracer.accel.constants.WIDE_MAX_LEAF` and ``WIDE_TRAV_COST``, fitted by paired timing), then collapsed top-down to ``width`` children per
node (the collapse of :mod:`tracer.accel.bvh4`: open the interior child of largest surface area until
the node is full or holds only leaves), the layout conversion tinybvh makes from its one binary build.

Layout: ``nodes_`` (nodes, 7 W + 8) int32 records (W = width; 256 bytes at W = 8): the W child boxes
in SoA float32 ``[lo x, lo y, lo z, hi x, hi y, hi z]`` (6 W words), W child words, 8 order words.
A child word c >= 0 is an interior node; c < 0 a leaf, ``-1 - c = first_block << 4 | triangles``;
an empty slot has the box lo = +inf, hi = -inf (never met). Order word o (o = the octant of the
ray's direction signs, bit k set when the direction is negative on axis k) packs the W slots in
near-to-far order, 3 bits each (slot at position p: ``(order >> 3 p) & 7``): the order the binary
splits inside the node give (at a split on axis a the lower child first when the direction is
positive on a). ``tri4_`` (blocks, 36) float32 holds the leaves' triangles four at a time in
SoA (:mod:`tracer.accel.simd_tri`; a leaf's last block padded with degenerate triangles), ``ids4_``
(blocks, 4) their triangle ids (-1 for padding).

Traversal: the rules of :mod:`tracer.accel.bvh4` (root box in float64, box tests in float32 widened by
``tol``, popped entries beyond the closest hit + tol dropped, float32 vertices passed to the float64
triangle test exactly as the oracle passes them, so t and id are bit-identical to the oracle's),
except that the hit children are pushed in the node's order for the ray's octant, nearest on top,
with no sort, and the entry to be popped next has its cache lines prefetched (``_prefetch_entry``).
Each block of rays is traced two rays at a time, one entry of each in turn (:func:`wide_chunk`), so
one ray's cache misses overlap the other's work; each ray's visits, counters and result are those of
tracing it alone.
Counters: ``setups`` 1 per ray meeting the root box, ``nodes`` entries visited (wide nodes and leaves), ``steps`` leaves visited, ``tests`` triangles in the leaves visited (padding
lanes not counted).
"""
from __future__ import annotations

import time

import numpy as np
from numba import prange

from tracer.accel import Accel, TreeTraceMixin
from tracer.accel._jit import BLOCK, jit, nblocks, pjit, pop_within, ray_jit, store_ray
from tracer.accel.bvh import bvh_build, ray_start
from tracer.accel.geometry import INF, padded_bounds, t_tolerance
from tracer.accel.kdtree import root_box
from tracer.accel.pages import traversal_array
from tracer.accel.simd import ctz, popc, prefetch, slab4, slab8, slabq4, slabq8
from tracer.accel.wide_quant import HEADER, ORDER_BYTES, child_word, order_byte, qnode_words, quantize
from tracer.accel.simd_tri import TRI4_WORDS, ray_tri4
from tracer.errors import GridcostError
from tracer.measure.memory import check_budget, working_set
from tracer.measure.provenance import bvh_width
from tracer.accel.constants import WIDE_BLOCK, WIDE_BOXES, WIDE_MAX_LEAF, WIDE_TRAV_COST

#: order words per node (one per octant of direction signs)
NORD = 8


def host_width() -> int:
    """Children per node for this CPU (:func:`tracer.measure.provenance.bvh_width`, recorded in the
    measurement key): 8 with AVX2, else 4."""
    return bvh_width()


def node_words(width: int) -> int:
    return 7 * width + NORD


# ---------------------------------------------------------------- build (collapse)
@jit(inline="always")
def _barea(nb, c):
    ex0 = np.float64(nb[c, 3]) - nb[c, 0]
    ex1 = np.float64(nb[c, 4]) - nb[c, 1]
    ex2 = np.float64(nb[c, 5]) - nb[c, 2]
    return 2.0 * (ex0 * ex1 + ex1 * ex2 + ex2 * ex0)


@jit
def _orders(info, top, ch, m, W, rec, cur, ordw):
    """The NORD order words of node ``cur`` whose slots ``ch[:m]`` were opened from binary node ``top``."""
    st = np.empty(2 * W + 2, np.int64)
    for o in range(NORD):
        word = 0
        pos = 0
        used = 0
        sp = 1
        st[0] = top
        while sp > 0:
            sp -= 1
            c = st[sp]
            slot = -1
            for k in range(m):
                if ch[k] == c:
                    slot = k
            if slot >= 0:
                word |= slot << (3 * pos)
                used |= 1 << slot
                pos += 1
            else:  # an opened interior node: push far first so near comes out first
                axis = -1 - info[c, 1]
                if (o >> axis) & 1:  # negative direction on the split axis: right (upper) first
                    st[sp] = c + 1
                    st[sp + 1] = info[c, 0]
                else:
                    st[sp] = info[c, 0]
                    st[sp + 1] = c + 1
                sp += 2
        for k in range(W):  # empty slots last (never met)
            if not (used >> k) & 1:
                word |= k << (3 * pos)
                pos += 1
        rec[cur, ordw + o] = word


@jit
def collapse(nb, info, W, leaf_word):
    """Collapse a binary BVH (``nb`` (nodes, 6) float32 boxes; ``info`` (nodes, 2) int32: interior
    ``[right, -1 - axis]`` with the left child at i + 1, leaf ``[offset, count >= 1]``) into W-wide
    records (module docstring); ``leaf_word[c]`` is the child word of binary leaf c. Returns
    (records, depth)."""
    nbin = nb.shape[0]
    words = 7 * W + NORD
    rec = np.zeros((max(1, nbin), words), np.int32)
    rf = rec.view(np.float32)
    st_b = np.empty(64, np.int64)
    st_n = np.empty(64, np.int64)
    st_d = np.empty(64, np.int64)
    ch = np.empty(W, np.int64)
    n = 1
    max_depth = 0
    sp = 0
    cur = 0
    depth = 0
    top = 0
    ch[0] = 0
    m = 1
    if info[0, 1] <= 0:  # the root is interior: its node opens it
        ch[0] = 1
        ch[1] = info[0, 0]
        m = 2
    while True:
        while m < W:  # open the interior child of largest area
            best = -1
            best_a = -1.0
            for k in range(m):
                c = ch[k]
                if info[c, 1] <= 0:
                    a = _barea(nb, c)
                    if a > best_a:
                        best_a = a
                        best = k
            if best < 0:
                break
            c = ch[best]
            ch[best] = c + 1
            ch[m] = info[c, 0]
            m += 1
        max_depth = max(max_depth, depth)
        _orders(info, top, ch, m, W, rec, cur, 7 * W)
        for k in range(W):
            if k < m:
                c = ch[k]
                for j in range(6):
                    rf[cur, W * j + k] = nb[c, j]
                if info[c, 1] > 0:
                    rec[cur, 6 * W + k] = leaf_word[c]
                else:
                    rec[cur, 6 * W + k] = n
                    if sp == st_b.shape[0]:
                        st_b = np.concatenate((st_b, st_b))
                        st_n = np.concatenate((st_n, st_n))
                        st_d = np.concatenate((st_d, st_d))
                    st_b[sp] = c
                    st_n[sp] = n
                    st_d[sp] = depth + 1
                    sp += 1
                    n += 1
            else:
                for j in range(3):
                    rf[cur, W * j + k] = INF
                    rf[cur, W * (3 + j) + k] = -INF
                rec[cur, 6 * W + k] = 0
        if sp == 0:
            break
        sp -= 1
        top = st_b[sp]
        cur = st_n[sp]
        depth = st_d[sp]
        ch[0] = top + 1
        ch[1] = info[top, 0]
        m = 2
    return rec[:n].copy(), max_depth


@jit
def leaf_blocks(info, tv, order):
    """The leaves' triangles in blocks of four (SoA, :mod:`tracer.accel.simd_tri`): (tri4 (blocks, 36)
    float32, ids4 (blocks, 4) int32, the child word of every binary leaf). ``tv`` (N, 9) float32
    triangles in leaf order, ``order`` their ids."""
    nbin = info.shape[0]
    nblk = 0
    for c in range(nbin):
        if info[c, 1] > 0:
            nblk += (info[c, 1] + 3) // 4
    tri4 = np.empty((max(nblk, 1), TRI4_WORDS), np.float32)
    ids4 = np.full((max(nblk, 1), 4), -1, np.int32)
    word = np.zeros(nbin, np.int32)
    b = 0
    for c in range(nbin):
        cnt = info[c, 1]
        if cnt <= 0:
            continue
        off = info[c, 0]
        word[c] = -1 - ((b << 4) | cnt)
        for j in range((cnt + 3) // 4):
            for lane in range(4):
                q = 4 * j + lane
                r = off + (q if q < cnt else 4 * j)  # padding: the block's first triangle, collapsed
                for v in range(3):
                    for a in range(3):
                        x = tv[r, 3 * v + a] if q < cnt else tv[r, a]
                        tri4[b, 12 * v + 4 * a + lane] = x
                if q < cnt:
                    ids4[b, lane] = order[r]
            b += 1
    return tri4, ids4, word


# ---------------------------------------------------------------- traversal
@jit(inline="always")
def _prefetch_entry(ni, tri, words, c, nq):
    """Start the loads of a pending stack entry, so they overlap the work done before it is popped:
    a node's cache lines, or the first block of a leaf (144 bytes, up to three lines).
    Paired against no prefetch, 1 thread: 0.92-0.99x the time on seven meshes (dragon-871k random
    0.92), none slower."""
    if c >= 0:  # four lines (float records, 256 bytes at W = 8), two for the quantised ones (``nq``)
        b = words * np.uintp(c)
        prefetch(ni, b)
        prefetch(ni, b + np.uintp(16))
        if nq is None:
            prefetch(ni, b + np.uintp(32))
            prefetch(ni, b + np.uintp(48))
    else:
        b = np.uintp(TRI4_WORDS) * np.uintp((-1 - c) >> 4)
        prefetch(tri, b)
        prefetch(tri, b + np.uintp(16))
        prefetch(tri, b + np.uintp(32))


@ray_jit
def _wide_next(nxt, hi, O, D, tmin, tmax, box, diag, W, ow, nq, rf, rq, ru, out_t, out_id, counters):
    """Load the next ray from ``nxt`` on that meets the root box into ``rf`` (float64: the origin and
    direction passed to the triangle test, tol), ``rq`` (float32: the origin, inverse direction and
    tol of the box tests) and ``ru`` (word offsets of the near / far planes of the W boxes on each
    axis, and of the ray's order word); the rays before it that miss the box get their result here.
    Returns (its index, or -1 when none is left; the next ``nxt``; best)."""
    Wu = np.uintp(W)
    while nxt < hi:
        i = nxt
        nxt += 1
        px, py, pz, dx, dy, dz, ix, iy, iz, sx, sy, sz, best, t0, t1 = ray_start(O, D, i, box, tmin, tmax)
        if t0 <= t1:
            tol = t_tolerance(t0, t1, diag, ix, iy, iz)
            rf[0] = px
            rf[1] = py
            rf[2] = pz
            rf[3] = dx
            rf[4] = dy
            rf[5] = dz
            rf[6] = tol
            rq[0] = O[i, 0]
            rq[1] = O[i, 1]
            rq[2] = O[i, 2]
            rq[3] = np.float32(ix)
            rq[4] = np.float32(iy)
            rq[5] = np.float32(iz)
            rq[6] = np.float32(tol)
            # s*: 0 or 3, the near plane's word group on each axis
            ru[0] = Wu * sx
            ru[1] = np.uintp(3) * Wu - Wu * sx
            ru[2] = Wu + Wu * sy
            ru[3] = np.uintp(4) * Wu - Wu * sy
            ru[4] = np.uintp(2) * Wu + Wu * sz
            ru[5] = np.uintp(5) * Wu - Wu * sz
            octant = (np.uintp(1) if sx else np.uintp(0)) + (np.uintp(2) if sy else np.uintp(0)) \
                + (np.uintp(4) if sz else np.uintp(0))
            # where the ray's order lives: a word of the float records, three bytes of the quantised ones
            ru[6] = ow + octant if nq is None else ow + np.uintp(ORDER_BYTES) * octant
            return i, nxt, best
        store_ray(out_t, out_id, counters, i, INF, -1, 0, 0, 0, 0, 0)
    return -1, nxt, 0.0


@ray_jit
def _wide_visit(c, sp, best, best_id, nvis, leaves, tests, rf, rq, ru, sc, st, W, words, cw, ni, nf, nq,
                tri, ids4, tb, t4, tmin, anyhit):
    """One entry of one ray's traversal: a leaf's blocks are tested, or a node's W boxes, whose met
    children are pushed near to far (the nearest is visited next, without the stack); after a leaf,
    or a node with no child met, the next pending entry is popped. Returns the ray's new state (c,
    sp, best, best_id, nvis, leaves, tests, done)."""
    one, two, three, four, five = np.uintp(1), np.uintp(2), np.uintp(3), np.uintp(4), np.uintp(5)
    nvis += 1
    found = False
    if c < 0:  # a leaf: its blocks of four triangles
        v = -1 - c
        cnt = v & 15
        leaves += 1
        tests += cnt
        b0 = v >> 4
        for bb in range(b0, b0 + ((cnt + 3) >> 2)):
            hm = ray_tri4(tri, np.uintp(TRI4_WORDS) * np.uintp(bb), rf[0], rf[1], rf[2], rf[3], rf[4], rf[5],
                          tmin, best, t4)
            while hm != 0:  # lanes in order, strict <: the first of equal t, as the scalar loop
                k = ctz(hm)
                hm &= hm - 1
                if t4[k] < best:
                    best = t4[k]
                    best_id = ids4[np.uintp(4 * bb + k)]
            if anyhit and best_id >= 0:
                return c, sp, best, best_id, nvis, leaves, tests, True
    else:
        base = words * np.uintp(c)
        lim = np.float32(best + rf[6])
        tmin32 = np.float32(tmin)
        if nq is not None:
            qb = np.uintp(4) * base + np.uintp(4 * HEADER)
            if W == 8:
                mask = slabq8(nq, qb, ru[0], ru[1], ru[2], ru[3], ru[4], ru[5], nf[base], nf[base + one],
                              nf[base + two], nf[base + three], nf[base + four], nf[base + five],
                              rq[0], rq[1], rq[2], rq[3], rq[4], rq[5], tmin32, lim, rq[6], tb)
            else:
                mask = slabq4(nq, qb, ru[0], ru[1], ru[2], ru[3], ru[4], ru[5], nf[base], nf[base + one],
                              nf[base + two], nf[base + three], nf[base + four], nf[base + five],
                              rq[0], rq[1], rq[2], rq[3], rq[4], rq[5], tmin32, lim, rq[6], tb)
        elif W == 8:
            mask = slab8(nf, base, ru[0], ru[1], ru[2], ru[3], ru[4], ru[5], rq[0], rq[1], rq[2], rq[3], rq[4],
                         rq[5], tmin32, lim, rq[6], tb)
        else:
            mask = slab4(nf, base, ru[0], ru[1], ru[2], ru[3], ru[4], ru[5], rq[0], rq[1], rq[2], rq[3], rq[4],
                         rq[5], tmin32, lim, rq[6], tb)
        found = mask != 0
        if found:
            nh = popc(mask)
            if nh == 1:  # one child met: visit it, no stack
                c = ni[base + cw + np.uintp(ctz(mask))]
            else:  # the met children near to far from the order word; nearest on top
                octant = ru[6]
                if nq is None:
                    perm = ni[base + octant]
                else:
                    ob = np.uintp(4) * base + octant
                    perm = np.int32(nq[ob]) | (np.int32(nq[ob + one]) << 8) | (np.int32(nq[ob + two]) << 16)
                top = sp + nh - 1
                j = top
                # every child in order is written at j, which moves down only past a met one: a
                # child not met is overwritten by the next met one, and the loop ends after the
                # farthest met child. No branch on each child's hit bit, which random rays
                # mispredict (paired new/old, 1 thread, 15 rounds, t and id identical: random rays
                # 0.93-0.96x the time on 5 meshes, camera 0.97-1.01x)
                while True:
                    k = perm & 7
                    perm >>= 3
                    ju = np.uintp(j)
                    sc[ju] = ni[base + cw + np.uintp(k)]
                    st[ju] = np.float64(tb[k])
                    j -= (mask >> k) & 1
                    if j < sp:
                        break
                c = sc[np.uintp(top)]
                sp = top
                # the second nearest is visited after c's subtree
                _prefetch_entry(ni, tri, words, sc[np.uintp(top - 1)], nq)
    if not found:  # pop the nearest pending entry that may still hold a closer hit
        sp = pop_within(st, sp, best + rf[6])
        if sp < 0:
            return c, sp, best, best_id, nvis, leaves, tests, True
        c = sc[np.uintp(sp)]
        if sp > 0:
            _prefetch_entry(ni, tri, words, sc[np.uintp(sp - 1)], nq)
    return c, sp, best, best_id, nvis, leaves, tests, False


@ray_jit
def _wide_turn(i, nxt, hi, c, sp, best, best_id, nvis, leaves, tests, rf, rq, ru, sc, st, O, D, tmin, tmax,
               anyhit, box, diag, W, words, cw, ow, ni, nf, nq, tri, ids4, tb, t4, out_t, out_id, counters):
    """One turn of one of :func:`wide_chunk`'s two rays: visit its next entry; when its traversal is
    done, write its result and start the next ray in its place. Returns the slot's new state (i,
    nxt, c, sp, best, best_id, nvis, leaves, tests)."""
    c, sp, best, best_id, nvis, leaves, tests, done = _wide_visit(
        c, sp, best, best_id, nvis, leaves, tests, rf, rq, ru, sc, st, W, words, cw, ni, nf, nq, tri, ids4,
        tb, t4, tmin, anyhit)
    if done:
        store_ray(out_t, out_id, counters, i, best if best_id >= 0 else INF, best_id, 1, leaves, tests, nvis, 0)
        i, nxt, best = _wide_next(nxt, hi, O, D, tmin, tmax, box, diag, W, ow, nq, rf, rq, ru, out_t, out_id,
                                  counters)
        return i, nxt, 0, 0, best, -1, 0, 0, 0
    return i, nxt, c, sp, best, best_id, nvis, leaves, tests


@jit
def wide_chunk(lo, hi, O, D, tmin, tmax, anyhit, box, diag, W, ni, nf, nq, tri, ids4, stack_size,
               out_t, out_id, counters):
    """Trace rays lo..hi-1, two at a time, each with its own stack: every turn visits one entry of
    each (:func:`_wide_turn`), so the two rays' memory loads and dependency chains overlap in the
    core (paired against one ray at a time, 1 thread, eight meshes: random rays 0.90-0.98x the
    time, camera rays 0.96-1.06x, as each entry loads the ray's constants from its arrays).
    ``ni``/``nf``: flat int32 / float32 views of the node records; ``nq`` their uint8 view
    for the quantised records (:mod:`tracer.accel.wide_quant`), None for the float ones (Numba
    compiles each layout on its own); ``tri``: flat float32 blocks of four triangles; ``ids4``
    flat."""
    tb = np.empty(8, np.float32)
    t4 = np.empty(4, np.float64)
    if nq is None:  # words per record, offset of the child words, of the order words
        words = np.uintp(7 * W + NORD)
        cw = np.uintp(6 * W)
        ow = np.uintp(7 * W)
    else:  # ... of the child words, and the byte offset of the orders
        words = np.uintp(qnode_words(W, NORD))
        cw = np.uintp(child_word(W))
        ow = np.uintp(order_byte(W))
    rfa = np.empty(8, np.float64)
    rqa = np.empty(8, np.float32)
    rua = np.empty(8, np.uintp)
    sca = np.empty(stack_size, np.int64)
    sta = np.empty(stack_size, np.float64)
    rfb = np.empty(8, np.float64)
    rqb = np.empty(8, np.float32)
    rub = np.empty(8, np.uintp)
    scb = np.empty(stack_size, np.int64)
    stb = np.empty(stack_size, np.float64)
    ia, nxt, besta = _wide_next(lo, hi, O, D, tmin, tmax, box, diag, W, ow, nq, rfa, rqa, rua, out_t, out_id,
                                counters)
    ib, nxt, bestb = _wide_next(nxt, hi, O, D, tmin, tmax, box, diag, W, ow, nq, rfb, rqb, rub, out_t, out_id,
                                counters)
    ca, spa, ida, nva, lfa, tsa = 0, 0, -1, 0, 0, 0
    cb, spb, idb, nvb, lfb, tsb = 0, 0, -1, 0, 0, 0
    while ia >= 0 or ib >= 0:
        if ia >= 0:
            ia, nxt, ca, spa, besta, ida, nva, lfa, tsa = _wide_turn(
                ia, nxt, hi, ca, spa, besta, ida, nva, lfa, tsa, rfa, rqa, rua, sca, sta, O, D, tmin, tmax,
                anyhit, box, diag, W, words, cw, ow, ni, nf, nq, tri, ids4, tb, t4, out_t, out_id, counters)
        if ib >= 0:
            ib, nxt, cb, spb, bestb, idb, nvb, lfb, tsb = _wide_turn(
                ib, nxt, hi, cb, spb, bestb, idb, nvb, lfb, tsb, rfb, rqb, rub, scb, stb, O, D, tmin, tmax,
                anyhit, box, diag, W, words, cw, ow, ni, nf, nq, tri, ids4, tb, t4, out_t, out_id, counters)


@pjit
def wide_trace(O, D, tmin, tmax, anyhit, box, diag, W, ni, nf, nq, tri, ids4, stack_size, out_t, out_id,
               counters, nt):
    """Batched wide-BVH traversal, ``prange`` over the ``nt`` threads, each taking every nt-th block of
    BLOCK rays (:data:`tracer.accel._jit.BLOCK`), two rays at a time, each with its own stack
    (:func:`wide_chunk`); ``counters`` or None (the variant without counting)."""
    m = O.shape[0]
    for th in prange(nt):
        for b in range(th, nblocks(m), nt):
            wide_chunk(b * BLOCK, min(m, (b + 1) * BLOCK), O, D, tmin, tmax, anyhit, box, diag, W, ni, nf, nq,
                       tri, ids4, stack_size, out_t, out_id, counters)


class WideBVH(TreeTraceMixin, Accel):
    """8-wide BVH on AVX2 CPUs, 4-wide elsewhere (``width``: None = :func:`host_width`, or 4 / 8), with
    leaves of up to ``max_leaf`` (:data:`WIDE_MAX_LEAF`, 8) triangles tested four at a time; ``bins`` (32) and
    ``trav_cost`` (relative to one block test, :data:`WIDE_TRAV_COST`, 2) of the binary SAH build it collapses."""

    name = "wbvh"
    _kernel = staticmethod(wide_trace)
    counter_fields = {"setups": "1 if the ray enters the root box", "steps": "leaves visited",
                      "tests": "ray/triangle tests (triangles of the leaves visited)",
                      "nodes": "nodes visited (leaves included)"}

    def __init__(self, width=None, bins=32, max_leaf=WIDE_MAX_LEAF, trav_cost=WIDE_TRAV_COST, boxes=WIDE_BOXES):
        if boxes not in ("float", "quant"):
            raise GridcostError(f"wide BVH boxes must be 'float' or 'quant', got {boxes!r}")
        self.width, self.bins, self.max_leaf, self.trav_cost = width, bins, max_leaf, trav_cost
        self.boxes = boxes

    def build(self, scene):
        n = scene.n
        w = host_width() if self.width is None else self.width
        if w not in (4, 8):
            raise GridcostError(f"wide BVH width must be 4 or 8, got {self.width}")
        if not 2 <= int(self.bins) <= 1024:
            raise GridcostError(f"wide BVH bins must be in [2, 1024], got {self.bins}")
        if not 1 <= int(self.max_leaf) <= 15:
            raise GridcostError(f"wide BVH max_leaf must be in [1, 15], got {self.max_leaf}")
        if n >= 2**26:
            raise GridcostError(f"{n:,} triangles exceed the wide BVH's leaf word range")
        check_budget(f"a wide BVH over {n:,} triangles of {scene.name}", n * (2 * 32 + 24 + 24 + 40 + 8 + 64))
        t_start = time.perf_counter()
        self.width_, self.n_ = w, n
        self.scene_name_ = scene.name
        if n == 0:
            self.nodes_ = np.zeros((0, node_words(w)), np.int32)
            self.qnodes_ = None
            self.tri4_, self.ids4_ = np.zeros((0, TRI4_WORDS), np.float32), np.zeros((0, 4), np.int32)
            self.depth_, self.leaves_, self.diag_ = 0, 0, 0.0
            self.build_seconds_ = time.perf_counter() - t_start
            return self
        tris = scene.tris
        # centroids from the exact bounds (the tree's splits), node boxes from the padded ones
        pc = 0.5 * (tris.min(axis=1).astype(np.float64) + tris.max(axis=1).astype(np.float64))
        self.box_ = root_box(scene)
        pb = np.concatenate(padded_bounds(tris, self.box_), axis=1)
        nb, info, order, nleaves, _, _, _, _ = bvh_build(pb, pc, int(self.bins), int(self.max_leaf),
                                                         float(self.trav_cost), WIDE_BLOCK)
        tv = np.ascontiguousarray(tris.reshape(-1, 9)[order])
        tri4, ids4, leaf_word = leaf_blocks(info, tv, order)
        self.ids4_ = traversal_array(ids4)
        self.tri4_ = traversal_array(tri4)
        nodes, depth = collapse(nb, info, w, leaf_word)
        self.nodes_ = traversal_array(nodes)
        # the layout traced: the float records, or the same tree quantised (one byte a plane)
        self.qnodes_ = traversal_array(quantize(nodes, w, NORD)) if self.boxes == "quant" else None
        self.depth_, self.leaves_ = int(depth), int(nleaves)
        self.diag_ = float(np.linalg.norm(self.box_[3:] - self.box_[:3]))
        self.build_seconds_ = time.perf_counter() - t_start
        return self

    def _stack_size(self) -> int:
        """Up to W - 1 pushed children per level, and a margin."""
        return (self.width_ - 1) * (self.depth_ + 1) + 8

    def _traced(self) -> np.ndarray:
        """The node records the kernel walks."""
        return self.nodes_ if self.qnodes_ is None else self.qnodes_

    def _tree_arrays(self) -> tuple:
        rec = self._traced()
        return (self.width_, rec.reshape(-1), rec.view(np.float32).reshape(-1),
                None if self.qnodes_ is None else rec.view(np.uint8).reshape(-1),
                self.tri4_.reshape(-1), self.ids4_.reshape(-1))

    def stats(self) -> dict:
        nn = len(self.nodes_)
        w = self.width_
        child = self.nodes_[:, 6 * w:7 * w] if nn else np.zeros((0, w), np.int32)
        lo = self.nodes_.view(np.float32)[:, :w] if nn else np.zeros((0, w), np.float32)
        mem = self._traced().nbytes + self.tri4_.nbytes + self.ids4_.nbytes
        return {
            "structure": "wbvh", "width": w, "nodes": nn, "interior": nn, "leaves": self.leaves_,
            "blocks": len(self.tri4_) if self.n_ else 0, "depth": self.depth_, "refs": self.n_,
            "mean_children": float(np.isfinite(lo).sum() / max(nn, 1)),
            "interior_children": int((child > 0).sum()),
            "mean_leaf_refs": self.n_ / max(self.leaves_, 1),
            "memory_bytes": int(mem),
            "working_set": working_set(self._traced().nbytes, self.ids4_.nbytes, self.tri4_.nbytes),
            "boxes": self.boxes,
            "build_s": self.build_seconds_,
            "params": {"width": self.width, "bins": self.bins, "max_leaf": self.max_leaf,
                       "trav_cost": self.trav_cost, "boxes": self.boxes},
        }
