"""The SAH kd-tree build (pbrt-v2 KdTreeAccel, Chuang 2006 slides): sorted bounding-box edge events per
axis, the surface area heuristic with pbrt's costs (isect 80, traversal 1, empty bonus 0.5), and the
compaction into the 8-byte node layout :mod:`tracer.accel.kdtree` traverses."""
from __future__ import annotations

import numpy as np

from tracer.accel._jit import jit
from tracer.accel.geometry import INF

#: leaf flag in the low two bits of a node's first word (0, 1, 2: interior split axis)
LEAF = 3


def sorted_edges(lo: np.ndarray, hi: np.ndarray):
    """Per axis, the 2N bound edges sorted by (t, START before END, primitive): t (3, 2N) float32
    and code (3, 2N) int32 = prim << 1 | is_end."""
    n = lo.shape[0]
    t_out = np.empty((3, 2 * n), np.float32)
    c_out = np.empty((3, 2 * n), np.int32)
    prim = np.arange(n, dtype=np.int64)
    code = np.concatenate([prim << 1, (prim << 1) | 1])
    for a in range(3):
        t = np.concatenate([lo[:, a], hi[:, a]]).astype(np.float32)
        t[t == 0] = 0.0  # -0.0 -> +0.0 so the bit key orders like the float compare
        b = t.view(np.uint32).astype(np.uint64)
        b = np.where(b >> 31, b ^ 0xFFFFFFFF, b | 0x80000000)  # monotone float -> uint key
        key = (b << 32) | code.astype(np.uint64)  # t, then type (low bit), then prim
        order = np.argsort(key, kind="stable")
        t_out[a] = t[order]
        c_out[a] = code[order]
    return t_out, c_out


@jit
def _grow(a, need):
    """``a`` itself, or a 1.5x larger copy when it holds fewer than ``need`` entries."""
    if need <= a.shape[0]:
        return a
    b = np.empty(max(need, a.shape[0] * 3 // 2 + 16), a.dtype)
    b[:a.shape[0]] = a
    return b


@jit
def _area(b):
    dx = b[3] - b[0]
    dy = b[4] - b[1]
    dz = b[5] - b[2]
    return 2.0 * (dx * dy + dy * dz + dz * dx)


@jit(inline="always")
def sah_split_cost(trav_cost, isect_cost, empty_bonus, p_left, p_right, n_left, n_right):
    """pbrt-v2's SAH of a split: C = C_trav + C_isect (1 - b) (P_L N_L + P_R N_R), with
    b = ``empty_bonus`` when one side is empty, P = area(child) / area(node)."""
    eb = empty_bonus if (n_left == 0 or n_right == 0) else 0.0
    return trav_cost + isect_cost * (1.0 - eb) * (p_left * n_left + p_right * n_right)


@jit(inline="always")
def axis_extent(bounds, axis):
    """The node box ``bounds`` seen from ``axis``: (lo, hi, product and sum of the other two
    extents), what the child areas of a plane on ``axis`` are made of."""
    da = bounds[3 + (axis + 1) % 3] - bounds[(axis + 1) % 3]
    db = bounds[3 + (axis + 2) % 3] - bounds[(axis + 2) % 3]
    return bounds[axis], bounds[3 + axis], da * db, da + db


@jit(inline="always")
def child_probs(t, lo_a, hi_a, cap_ab, sum_ab, inv_total):
    """Areas of the children below and above a plane at ``t`` over the node's (``inv_total`` = 1 /
    its area; ``lo_a``.. from :func:`axis_extent`)."""
    p_below = 2.0 * (cap_ab + (t - lo_a) * sum_ab) * inv_total
    p_above = 2.0 * (cap_ab + (hi_a - t) * sum_ab) * inv_total
    return p_below, p_above


@jit(inline="always")
def leaf_verdict(best_cost, best_axis, n, bad, isect_cost):
    """pbrt-v2's leaf rules after the split search: ``bad`` counts the splits costlier than a leaf
    on the way down; returns (bad, make a leaf after all)."""
    old_cost = isect_cost * n
    if best_cost > old_cost:
        bad += 1
    return bad, (best_cost > 4.0 * old_cost and n < 16) or best_axis == -1 or bad == 3


# --------------------------------------------------- tree bookkeeping shared by both builds
@jit
def tree_arrays(n_prims, max_depth, root):
    """The arrays of a build: node word 0, word 1, split and leaf prim ids (grown as needed); int
    counters ``ic`` [nodes, leaf refs, leaves, empty leaves, depth reached]; float sums ``fs``
    [interior area, leaf area, leaf area x count]; the stack of pending nodes ``st`` (base, n,
    depth budget, bad, parent) with their boxes ``st_bounds``, holding the root (prims 0..n-1 in
    ``root``); the current box ``bounds``; the root's area."""
    m = max(16, 2 * n_prims)
    ns = max_depth + 3
    st = np.empty((ns, 5), np.int64)
    st_bounds = np.empty((ns, 6), np.float64)
    st[0, 0] = 0
    st[0, 1] = n_prims
    st[0, 2] = max_depth
    st[0, 3] = 0
    st[0, 4] = -1
    for k in range(6):
        st_bounds[0, k] = root[k]
    bounds = st_bounds[0].copy()
    return (np.empty(m, np.int32), np.empty(m, np.int32), np.empty(m, np.float32), np.empty(m, np.int32),
            np.zeros(5, np.int64), np.zeros(3, np.float64), st, st_bounds, bounds, _area(bounds))


@jit
def open_node(w0, w1, spl, ic, st, st_bounds, sp, bounds, max_depth, max_prims):
    """Pop the last pending node into ``bounds`` and give it the next index (the node arrays grown
    when full), linked as its parent's above child when it has a parent entry. Returns (w0, w1, spl,
    sp, node, base, n, depth budget, bad, area of ``bounds``, a leaf by pbrt's first rules: few
    prims or no depth left)."""
    sp -= 1
    for k in range(6):
        bounds[k] = st_bounds[sp, k]
    node = ic[0]
    ic[0] += 1
    if ic[0] > w0.shape[0]:
        w0 = _grow(w0, ic[0])
        w1 = _grow(w1, ic[0])
        spl = _grow(spl, ic[0])
    parent = st[sp, 4]
    if parent >= 0:
        w0[parent] |= node << 2
    depth = st[sp, 2]
    ic[4] = max(ic[4], max_depth - depth)
    n = st[sp, 1]
    return w0, w1, spl, sp, node, st[sp, 0], n, depth, st[sp, 3], _area(bounds), n <= max_prims or depth == 0


@jit
def close_leaf(w0, w1, spl, leaf_ids, ic, fs, node, n, area):
    """Make ``node`` a leaf of ``n`` prims: reserves their ``n`` slots in ``leaf_ids`` (grown),
    which the caller fills from the returned offset on."""
    leaf_ids = _grow(leaf_ids, ic[1] + n)
    off = ic[1]
    ic[1] += n
    w0[node] = LEAF | (n << 2)
    w1[node] = off
    spl[node] = 0.0
    ic[2] += 1
    if n == 0:
        ic[3] += 1
    fs[1] += area
    fs[2] += area * n
    return leaf_ids, off


@jit
def _push(st, st_bounds, sp, base, n, depth, bad, parent, bounds, k, v):
    """Push a pending node whose box is ``bounds`` with entry ``k`` set to ``v``."""
    st[sp, 0] = base
    st[sp, 1] = n
    st[sp, 2] = depth
    st[sp, 3] = bad
    st[sp, 4] = parent
    for c in range(6):
        st_bounds[sp, c] = bounds[c]
    st_bounds[sp, k] = v
    return sp + 1


@jit
def split_node(w0, w1, spl, fs, st, st_bounds, sp, node, axis, tsplit, bounds, area, base_lo, n_lo,
               base_hi, n_hi, depth, bad):
    """Make ``node`` an interior node (``tsplit`` on ``axis``) and push its children: above
    (``n_hi`` prims at ``base_hi``, linked later), then below (built next, at ``node + 1``).
    Returns the stack size."""
    w0[node] = axis
    w1[node] = 0
    spl[node] = tsplit
    fs[0] += area
    sp = _push(st, st_bounds, sp, base_hi, n_hi, depth - 1, bad, node, bounds, axis, tsplit)
    return _push(st, st_bounds, sp, base_lo, n_lo, depth - 1, bad, -1, bounds, 3 + axis, tsplit)


@jit
def tree_result(w0, w1, spl, leaf_ids, ic, fs, root_area):
    """What a build returns (see :func:`kd_build`)."""
    return (w0[:ic[0]].copy(), w1[:ic[0]].copy(), spl[:ic[0]].copy(), leaf_ids[:ic[1]].copy(),
            ic[2], ic[3], ic[4], fs[0], fs[1], fs[2], root_area)


# ---------------------------------------------------------------- pbrt-v2's build on edges
@jit
def _edge_split(ev_t, ev_c, base, n, bounds, area, isect_cost, trav_cost, empty_bonus):
    """pbrt-v2's sweep over a node's sorted edges, the longest axis first, the next ones only when
    it offers no plane inside the node. Returns (cost, axis, edge offset)."""
    best_cost = INF
    best_axis = -1
    best_off = -1
    inv_total = 1.0 / area
    dx = bounds[3] - bounds[0]
    dy = bounds[4] - bounds[1]
    dz = bounds[5] - bounds[2]
    if dx > dy and dx > dz:
        axis = 0
    elif dy > dz:
        axis = 1
    else:
        axis = 2
    for retries in range(3):
        lo_a, hi_a, cap_ab, sum_ab = axis_extent(bounds, axis)
        n_below = 0
        n_above = n
        for i in range(2 * n):
            c = ev_c[axis, base + i]
            if c & 1:
                n_above -= 1
            t = float(ev_t[axis, base + i])
            if t > lo_a and t < hi_a:
                p_below, p_above = child_probs(t, lo_a, hi_a, cap_ab, sum_ab, inv_total)
                cost = sah_split_cost(trav_cost, isect_cost, empty_bonus, p_below, p_above, n_below, n_above)
                if cost < best_cost:
                    best_cost = cost
                    best_axis = axis
                    best_off = i
            if not (c & 1):
                n_below += 1
        if best_axis != -1:
            break
        axis = (axis + 1) % 3
    return best_cost, best_axis, best_off


@jit
def _edge_partition(ev_t, ev_c, flag, base, n, ba, best_off):
    """Classify a node's prims against the split edge ``best_off`` on ``ba`` (pbrt: START before ->
    below, END after -> above). The below child's edges go on top of the work area (it is built
    next), the above child's are compacted in place (write index <= read index). Returns
    (ev_t, ev_c (grown when full), n below, n above)."""
    for i in range(2 * n):
        flag[ev_c[ba, base + i] >> 1] = 0
    n_lo = 0
    n_hi = 0
    for i in range(best_off):
        c = ev_c[ba, base + i]
        if not (c & 1):
            flag[c >> 1] |= 1
            n_lo += 1
    for i in range(best_off + 1, 2 * n):
        c = ev_c[ba, base + i]
        if c & 1:
            flag[c >> 1] |= 2
            n_hi += 1
    cap = ev_t.shape[1]
    need = base + 2 * n + 2 * n_lo
    if need > cap:
        cap2 = max(need, cap * 3 // 2)
        t2 = np.empty((3, cap2), np.float32)
        c2 = np.empty((3, cap2), np.int32)
        t2[:, :base + 2 * n] = ev_t[:, :base + 2 * n]
        c2[:, :base + 2 * n] = ev_c[:, :base + 2 * n]
        ev_t = t2
        ev_c = c2
    for a in range(3):
        wl = base + 2 * n
        wr = base
        for i in range(base, base + 2 * n):
            c = ev_c[a, i]
            t = ev_t[a, i]
            f = flag[c >> 1]
            if f & 1:
                ev_c[a, wl] = c
                ev_t[a, wl] = t
                wl += 1
            if f & 2:
                ev_c[a, wr] = c
                ev_t[a, wr] = t
                wr += 1
    return ev_t, ev_c, n_lo, n_hi


@jit
def held_bytes(ev_t, w0, leaf_ids):
    """Bytes the edge build holds: edge lists (float32 t + int32 code, 3 axes), node words (two
    int32 and a float32 split) and leaf references (int32)."""
    return ev_t.shape[1] * 24 + w0.shape[0] * 12 + leaf_ids.shape[0] * 4


@jit
def kd_build(ev_t, ev_c, n_prims, root, max_depth, max_prims, isect_cost, trav_cost, empty_bonus, max_bytes):
    """pbrt-v2 KdTreeAccel::buildTree, iterative, on pre-sorted edge lists (see module doc).

    ``ev_t``/``ev_c`` (3, cap) hold the root's sorted edges in [0, 2N); the tail is the work area
    (children's edge lists are written there, stack-like). Returns (node word 0, node word 1,
    split, leaf prim ids, leaves, empty leaves, max depth reached, SAH sums: interior area, leaf
    area, leaf area x count; root area).

    SAH duplication (1 to 19 references per triangle on the meshes measured) is not known before
    the build, so the build checks what it holds (:func:`held_bytes`) each time an array grows and
    stops when that exceeds ``max_bytes``: it then returns the empty result with leaves = -1."""
    flag = np.zeros(max(n_prims, 1), np.uint8)
    w0, w1, spl, leaf_ids, ic, fs, st, st_bounds, bounds, root_area = tree_arrays(n_prims, max_depth, root)
    sp = 1
    while sp > 0:
        w0, w1, spl, sp, node, base, n, depth, bad, area, make_leaf = open_node(
            w0, w1, spl, ic, st, st_bounds, sp, bounds, max_depth, max_prims)
        ba = -1
        best_off = -1
        if not make_leaf:
            best_cost, ba, best_off = _edge_split(ev_t, ev_c, base, n, bounds, area, isect_cost,
                                                  trav_cost, empty_bonus)
            bad, make_leaf = leaf_verdict(best_cost, ba, n, bad, isect_cost)
        if make_leaf:
            # leaf: its primitives in the order of their START edges along x
            leaf_ids, off = close_leaf(w0, w1, spl, leaf_ids, ic, fs, node, n, area)
            for i in range(2 * n):
                c = ev_c[0, base + i]
                if not (c & 1):
                    leaf_ids[off] = c >> 1
                    off += 1
            continue
        tsplit = ev_t[ba, base + best_off]
        ev_t, ev_c, n_lo, n_hi = _edge_partition(ev_t, ev_c, flag, base, n, ba, best_off)
        if held_bytes(ev_t, w0, leaf_ids) > max_bytes:
            ic[0] = 0
            ic[1] = 0
            ic[2] = -1
            break
        # the below child's edges were written on top of the work area
        sp = split_node(w0, w1, spl, fs, st, st_bounds, sp, node, ba, tsplit, bounds, area, base + 2 * n,
                        n_lo, base, n_hi, depth, bad)
    return tree_result(w0, w1, spl, leaf_ids, ic, fs, root_area)


@jit
def kd_compact(w0, w1, max_depth):
    """Re-lay the pbrt tree (``w0``/``w1`` from :func:`kd_build`, split bits in ``w1`` of interior
    nodes) depth-first without its empty leaves: an interior node with an empty child stores its
    other child at ``i + 1`` and says which child is empty in two flag bits (see module doc)."""
    n = w0.shape[0]
    out = np.empty((n, 2), np.int32)
    st_old = np.empty(max_depth + 2, np.int64)
    st_par = np.empty(max_depth + 2, np.int64)
    sp = 0
    cur = 0
    k = 0
    while True:
        w = w0[cur]
        if (w & 3) == LEAF:
            out[k, 0] = w
            out[k, 1] = w1[cur]
            k += 1
            if sp == 0:
                break
            sp -= 1
            cur = st_old[sp]
            out[st_par[sp], 0] |= k << 4
            continue
        b = cur + 1
        a = w >> 2
        out[k, 1] = w1[cur]
        if w0[b] == LEAF:  # below child is an empty leaf (3 | 0 << 2)
            out[k, 0] = (w & 3) | (1 << 2)
            cur = a
        elif w0[a] == LEAF:
            out[k, 0] = (w & 3) | (2 << 2)
            cur = b
        else:
            out[k, 0] = w & 3
            st_old[sp] = a
            st_par[sp] = k
            sp += 1
            cur = b
        k += 1
    return out[:k].copy()


