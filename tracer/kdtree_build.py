"""The SAH kd-tree build (pbrt-v2 KdTreeAccel, Chuang 2006 slides): sorted bounding-box edge events per
axis, the surface area heuristic with pbrt's costs (isect 80, traversal 1, empty bonus 0.5), and the
compaction into the 8-byte node layout :mod:`tracer.kdtree` traverses."""
from __future__ import annotations

import numpy as np

from tracer._jit import jit
from tracer.geometry import INF

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


@jit
def kd_build(ev_t, ev_c, n_prims, root, max_depth, max_prims, isect_cost, trav_cost, empty_bonus):
    """pbrt-v2 KdTreeAccel::buildTree, iterative, on pre-sorted edge lists (see module doc).

    ``ev_t``/``ev_c`` (3, cap) hold the root's sorted edges in [0, 2N); the tail is the work area
    (children's edge lists are written there, stack-like). Returns (node word 0, node word 1,
    split, leaf prim ids, node count, leaf-ref count, leaves, empty leaves, max depth reached,
    SAH sums: interior area, leaf area, leaf area x count; root area)."""
    cap = ev_t.shape[1]
    flag = np.zeros(max(n_prims, 1), np.uint8)
    w0 = np.empty(max(16, 2 * n_prims), np.int32)
    w1 = np.empty(max(16, 2 * n_prims), np.int32)
    spl = np.empty(max(16, 2 * n_prims), np.float32)
    leaf_ids = np.empty(max(16, 2 * n_prims), np.int32)
    nnodes = 0
    nrefs = 0
    nleaves = 0
    nempty = 0
    depth_reached = 0
    s_inner = 0.0
    s_leaf = 0.0
    s_tests = 0.0
    ns = max_depth + 2
    st_base = np.empty(ns, np.int64)
    st_n = np.empty(ns, np.int64)
    st_depth = np.empty(ns, np.int64)
    st_bad = np.empty(ns, np.int64)
    st_parent = np.empty(ns, np.int64)
    st_bounds = np.empty((ns, 6), np.float64)
    sp = 0
    bounds = np.empty(6, np.float64)
    for k in range(6):
        bounds[k] = root[k]
    root_area = _area(bounds)
    base = 0
    n = n_prims
    depth = max_depth
    bad = 0
    parent = -1
    while True:
        node = nnodes
        nnodes += 1
        if nnodes > w0.shape[0]:
            w0 = _grow(w0, nnodes)
            w1 = _grow(w1, nnodes)
            spl = _grow(spl, nnodes)
        if parent >= 0:
            w0[parent] |= node << 2
        depth_reached = max(depth_reached, max_depth - depth)
        area = _area(bounds)
        make_leaf = n <= max_prims or depth == 0
        best_axis = -1
        best_off = -1
        if not make_leaf:
            best_cost = INF
            old_cost = isect_cost * n
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
                lo_a = bounds[axis]
                hi_a = bounds[3 + axis]
                da = bounds[3 + (axis + 1) % 3] - bounds[(axis + 1) % 3]
                db = bounds[3 + (axis + 2) % 3] - bounds[(axis + 2) % 3]
                cap_ab = da * db
                sum_ab = da + db
                n_below = 0
                n_above = n
                for i in range(2 * n):
                    c = ev_c[axis, base + i]
                    if c & 1:
                        n_above -= 1
                    t = float(ev_t[axis, base + i])
                    if t > lo_a and t < hi_a:
                        p_below = 2.0 * (cap_ab + (t - lo_a) * sum_ab) * inv_total
                        p_above = 2.0 * (cap_ab + (hi_a - t) * sum_ab) * inv_total
                        eb = empty_bonus if (n_above == 0 or n_below == 0) else 0.0
                        cost = trav_cost + isect_cost * (1.0 - eb) * (p_below * n_below + p_above * n_above)
                        if cost < best_cost:
                            best_cost = cost
                            best_axis = axis
                            best_off = i
                    if not (c & 1):
                        n_below += 1
                if best_axis != -1:
                    break
                axis = (axis + 1) % 3
            if best_cost > old_cost:
                bad += 1
            if (best_cost > 4.0 * old_cost and n < 16) or best_axis == -1 or bad == 3:
                make_leaf = True
        if make_leaf:
            # leaf: its primitives in the order of their START edges along x
            leaf_ids = _grow(leaf_ids, nrefs + n)
            off = nrefs
            for i in range(2 * n):
                c = ev_c[0, base + i]
                if not (c & 1):
                    leaf_ids[nrefs] = c >> 1
                    nrefs += 1
            w0[node] = LEAF | (n << 2)
            w1[node] = off
            spl[node] = 0.0
            nleaves += 1
            if n == 0:
                nempty += 1
            s_leaf += area
            s_tests += area * n
            if sp == 0:
                break
            sp -= 1
            base = st_base[sp]
            n = st_n[sp]
            depth = st_depth[sp]
            bad = st_bad[sp]
            parent = st_parent[sp]
            for k in range(6):
                bounds[k] = st_bounds[sp, k]
            continue
        # interior: classify primitives against the split edge (pbrt: START before -> below,
        # END after -> above)
        s_inner += area
        ba = best_axis
        tsplit = ev_t[ba, base + best_off]
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
        # below child's edges go on top of the work area (it is built next), the above child's
        # are compacted in place (write index <= read index) and wait on the stack
        need = base + 2 * n + 2 * n_lo
        if need > cap:
            cap2 = max(need, cap * 3 // 2)
            t2 = np.empty((3, cap2), np.float32)
            c2 = np.empty((3, cap2), np.int32)
            t2[:, :base + 2 * n] = ev_t[:, :base + 2 * n]
            c2[:, :base + 2 * n] = ev_c[:, :base + 2 * n]
            ev_t = t2
            ev_c = c2
            cap = cap2
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
        w0[node] = ba
        w1[node] = 0
        spl[node] = tsplit
        # push the above child
        st_base[sp] = base
        st_n[sp] = n_hi
        st_depth[sp] = depth - 1
        st_bad[sp] = bad
        st_parent[sp] = node
        for k in range(6):
            st_bounds[sp, k] = bounds[k]
        st_bounds[sp, ba] = tsplit
        sp += 1
        # continue with the below child
        base = base + 2 * n
        n = n_lo
        depth -= 1
        parent = -1
        bounds[3 + ba] = tsplit
    return (w0[:nnodes].copy(), w1[:nnodes].copy(), spl[:nnodes].copy(), leaf_ids[:nrefs].copy(),
            nleaves, nempty, depth_reached, s_inner, s_leaf, s_tests, root_area)


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


