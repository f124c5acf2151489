"""Bounding volume hierarchy: binned SAH build (Wald 2007) and ordered stack traversal.

Build (Numba, O(N log N)): top-down over a primitive index array partitioned in place. Per node:
bounds and centroid bounds of its triangles; ``bins`` (32) equal-width bins of the centroids on
each of the three axes; the split between bins with the least SAH cost
``trav_cost + (A_L N_L + A_R N_R) / A`` (pbrt-v2's BVHAccel weights: traversal 1/8, intersection
1). A node of at most ``max_leaf`` (4) triangles becomes a leaf when that is no dearer than the
best split (cost N); larger nodes are always split (by index halves when all centroids coincide).

Layout (depth-first, left child implicit at ``i + 1``): ``nodes_`` (nodes, 8) int32 records of
32 bytes, ``[lo xyz, hi xyz (float32 bits), a, b]`` — interior ``a`` = right child, ``b`` <= 0 (below);
leaf ``a`` = offset, ``b`` = count >= 1 — and ``nodes_f_`` their float32 view. ``tri_ids_`` and
``tri_verts_`` (N, 9) float32 hold the triangles in leaf order.

Traversal: at an interior node both child boxes are tested (float64 slab test that treats an
origin on a slab plane with a zero direction as inside); the nearer hit child is visited first
and the other pushed with its entry distance on a fixed-size stack (one per chunk of rays), and
popped entries beyond the closest hit are dropped. With ``order="sign"`` the near child is picked
instead by the sign of the ray direction on the node's split axis (left = lower centroids first);
interior ``b`` then holds ``-1 - axis`` (``b`` = 0: by entry distance, the default; sign ordering
measured no faster on random rays). Box/hit comparisons are widened by ``tol``
(T_EPS = 2e-6 of the ray's t scale) so rounding never loses a hit, also not the hits
:func:`tracer.accel.geometry.ray_triangle` accepts on a triangle's very edge. The ray is widened to
float64 with ``np.float64`` and passed to ray_triangle exactly as the grid and the oracle pass it
(float32 vertices), so a hit's t is bit-identical to the oracle's.
Counters: ``setups`` 1 per ray meeting the root box, ``nodes`` nodes visited (entered), ``steps``
leaves visited, ``tests`` triangle tests.
"""
from __future__ import annotations

import time

import numpy as np
from numba import prange

from tracer.accel._jit import BLOCK, jit, nblocks, pjit, pop_within, store_ray
from tracer.accel import TreeTraceMixin, COUNTER_NAMES, Accel
from tracer.errors import GridcostError
from tracer.accel.geometry import INF, load_ray, padded_bounds, ray_triangle, t_tolerance
from tracer.accel.kdtree import root_box
from tracer.accel.pages import traversal_array, traversal_rows
from tracer.measure.memory import check_budget, working_set

NCOUNT = len(COUNTER_NAMES)
#: pbrt-v2 BVHAccel SAH weights: traversal 1/8 of a triangle test
BVH_TRAV_COST = 0.125


# ---------------------------------------------------------------- build
@jit
def _bin_of(c, cmin, scale, nbins):
    b = int((c - cmin) * scale)
    if b < 0:
        return 0
    if b >= nbins:
        return nbins - 1
    return b


@jit(inline="always")
def _area(x0, x1, x2, X0, X1, X2):
    return 2.0 * ((X0 - x0) * (X1 - x1) + (X1 - x1) * (X2 - x2) + (X2 - x2) * (X0 - x0))


@jit
def bvh_build(pb, pc, nbins, max_leaf, trav_cost, block=1):
    """Binned-SAH BVH over primitive bounds ``pb`` (N, 6) float32 and centroids ``pc`` (N, 3)
    float64. ``block``: triangles one intersection test handles together (1; 4 for leaves tested
    four at a time, :mod:`tracer.accel.simd_tri`): a leaf of n costs ceil(n / block) tests in the SAH.
    Returns (bounds (nodes, 6) float32, info (nodes, 2) int32, primitive order, leaves,
    max depth, SAH sums: interior area, leaf area x count; root area)."""
    n = pb.shape[0]
    idx = np.arange(n).astype(np.int32)
    cap = max(1, 2 * n - 1)
    nb = np.empty((cap, 6), np.float32)
    info = np.zeros((cap, 2), np.int32)
    bin_n = np.zeros((3, nbins), np.int64)
    bin_b = np.empty((3, nbins, 6), np.float64)
    r_area = np.empty(nbins, np.float64)
    r_n = np.empty(nbins, np.int64)
    ss = 64
    st_s = np.empty(ss, np.int64)
    st_e = np.empty(ss, np.int64)
    st_p = np.empty(ss, np.int64)
    st_d = np.empty(ss, np.int64)
    sp = 0
    s = 0
    e = n
    parent = -1
    depth = 0
    nnodes = 0
    nleaves = 0
    max_depth = 0
    s_inner = 0.0
    s_tests = 0.0
    root_area = 0.0
    while True:
        node = nnodes
        nnodes += 1
        if parent >= 0:
            info[parent, 0] = node
        max_depth = max(max_depth, depth)
        lo0 = INF; lo1 = INF; lo2 = INF; hi0 = -INF; hi1 = -INF; hi2 = -INF
        c0 = INF; c1 = INF; c2 = INF; C0 = -INF; C1 = -INF; C2 = -INF
        for i in range(s, e):
            p = idx[i]
            lo0 = min(lo0, pb[p, 0]); lo1 = min(lo1, pb[p, 1]); lo2 = min(lo2, pb[p, 2])
            hi0 = max(hi0, pb[p, 3]); hi1 = max(hi1, pb[p, 4]); hi2 = max(hi2, pb[p, 5])
            c0 = min(c0, pc[p, 0]); c1 = min(c1, pc[p, 1]); c2 = min(c2, pc[p, 2])
            C0 = max(C0, pc[p, 0]); C1 = max(C1, pc[p, 1]); C2 = max(C2, pc[p, 2])
        nb[node, 0] = lo0; nb[node, 1] = lo1; nb[node, 2] = lo2
        nb[node, 3] = hi0; nb[node, 4] = hi1; nb[node, 5] = hi2
        ex0 = hi0 - lo0; ex1 = hi1 - lo1; ex2 = hi2 - lo2
        area = 2.0 * (ex0 * ex1 + ex1 * ex2 + ex2 * ex0)
        if node == 0:
            root_area = area
        cnt = e - s
        best_cost = INF
        best_axis = -1
        best_bin = -1
        if cnt > 1:
            for a in range(3):
                cmin = c0 if a == 0 else (c1 if a == 1 else c2)
                cmax = C0 if a == 0 else (C1 if a == 1 else C2)
                if not cmax > cmin:
                    continue
                scale = nbins / (cmax - cmin)
                for b in range(nbins):
                    bin_n[a, b] = 0
                    for k in range(3):
                        bin_b[a, b, k] = INF
                        bin_b[a, b, 3 + k] = -INF
                for i in range(s, e):
                    p = idx[i]
                    b = _bin_of(pc[p, a], cmin, scale, nbins)
                    bin_n[a, b] += 1
                    for k in range(3):
                        bin_b[a, b, k] = min(bin_b[a, b, k], pb[p, k])
                        bin_b[a, b, 3 + k] = max(bin_b[a, b, 3 + k], pb[p, 3 + k])
                # sweep from the right: area and count of bins b..nbins-1
                x0 = INF; x1 = INF; x2 = INF; X0 = -INF; X1 = -INF; X2 = -INF
                acc = 0
                for b in range(nbins - 1, 0, -1):
                    x0 = min(x0, bin_b[a, b, 0]); x1 = min(x1, bin_b[a, b, 1]); x2 = min(x2, bin_b[a, b, 2])
                    X0 = max(X0, bin_b[a, b, 3]); X1 = max(X1, bin_b[a, b, 4]); X2 = max(X2, bin_b[a, b, 5])
                    acc += bin_n[a, b]
                    r_n[b] = (acc + block - 1) // block
                    r_area[b] = _area(x0, x1, x2, X0, X1, X2) if acc else 0.0
                x0 = INF; x1 = INF; x2 = INF; X0 = -INF; X1 = -INF; X2 = -INF
                acc = 0
                for b in range(nbins - 1):  # split between bin b and b + 1
                    x0 = min(x0, bin_b[a, b, 0]); x1 = min(x1, bin_b[a, b, 1]); x2 = min(x2, bin_b[a, b, 2])
                    X0 = max(X0, bin_b[a, b, 3]); X1 = max(X1, bin_b[a, b, 4]); X2 = max(X2, bin_b[a, b, 5])
                    acc += bin_n[a, b]
                    if acc == 0 or r_n[b + 1] == 0:
                        continue
                    cost = _area(x0, x1, x2, X0, X1, X2) * ((acc + block - 1) // block) + r_area[b + 1] * r_n[b + 1]
                    if cost < best_cost:
                        best_cost = cost
                        best_axis = a
                        best_bin = b
        split_cost = trav_cost + best_cost / area if area > 0 else INF
        if cnt == 1 or (cnt <= max_leaf and (best_axis < 0 or (cnt + block - 1) // block <= split_cost)):
            info[node, 0] = s
            info[node, 1] = cnt
            nleaves += 1
            s_tests += area * cnt
            if sp == 0:
                break
            sp -= 1
            s = st_s[sp]; e = st_e[sp]; parent = st_p[sp]; depth = st_d[sp]
            continue
        s_inner += area
        mid = (s + e) // 2
        if best_axis >= 0:
            a = best_axis
            cmin = c0 if a == 0 else (c1 if a == 1 else c2)
            cmax = C0 if a == 0 else (C1 if a == 1 else C2)
            scale = nbins / (cmax - cmin)
            i = s
            j = e - 1
            while i <= j:
                if _bin_of(pc[idx[i], a], cmin, scale, nbins) <= best_bin:
                    i += 1
                else:
                    tmp = idx[i]
                    idx[i] = idx[j]
                    idx[j] = tmp
                    j -= 1
            if i > s and i < e:
                mid = i
        info[node, 1] = -1 - (best_axis if best_axis >= 0 else 0)  # interior: -1 - split axis
        if sp == st_s.shape[0]:
            st_s = np.concatenate((st_s, st_s))
            st_e = np.concatenate((st_e, st_e))
            st_p = np.concatenate((st_p, st_p))
            st_d = np.concatenate((st_d, st_d))
        st_s[sp] = mid; st_e[sp] = e; st_p[sp] = node; st_d[sp] = depth + 1
        sp += 1
        e = mid
        parent = -1
        depth += 1
    return nb[:nnodes].copy(), info[:nnodes].copy(), idx, nleaves, max_depth, s_inner, s_tests, root_area


# ---------------------------------------------------------------- traversal
@jit(inline="always")
def _slab_narrow(nf, near, far, o, inv, tn, tf):
    """[tn, tf] narrowed to the slab between the planes ``nf[near]`` and ``nf[far]`` of one axis
    (float64); a NaN product is ignored."""
    a = (np.float64(nf[near]) - o) * inv
    if a > tn:
        tn = a
    a = (np.float64(nf[far]) - o) * inv
    if a < tf:
        tf = a
    return tn, tf


@jit(inline="always")
def _box(nf, base, ox, oy, oz, ix, iy, iz, sx, sy, sz, tmin, tlim):
    """Slab test of the node box at ``nf[base:base + 6]`` in float64 (``s*``: 0 or 3, which face is
    near on each axis). NaN products (origin on a slab plane, zero direction) are ignored, i.e.
    count as inside. Returns (t_enter, t_leave)."""
    tn, tf = _slab_narrow(nf, base + sx, base + (np.uintp(3) - sx), ox, ix, tmin, tlim)
    tn, tf = _slab_narrow(nf, base + np.uintp(1) + sy, base + (np.uintp(4) - sy), oy, iy, tn, tf)
    return _slab_narrow(nf, base + np.uintp(2) + sz, base + (np.uintp(5) - sz), oz, iz, tn, tf)


@jit(inline="always")
def ray_start(O, D, i, box, tmin, tmax):
    """Ray ``i`` (:func:`tracer.accel.geometry.load_ray`), the near face of each axis (``s*``: 0 or 3,
    :func:`_box`), its limit ``tmax[i]`` as float64 and [t0, t1] in the padded root box ``box``
    (a miss when t0 > t1; the finite range sets ``tol``): (ox, oy, oz, dx, dy, dz, ix, iy, iz,
    sx, sy, sz, tmax, t0, t1)."""
    ox, oy, oz, dx, dy, dz, ix, iy, iz = load_ray(O, D, i)
    sx = np.uintp(0) if ix >= 0.0 else np.uintp(3)
    sy = np.uintp(0) if iy >= 0.0 else np.uintp(3)
    sz = np.uintp(0) if iz >= 0.0 else np.uintp(3)
    tlim = np.float64(tmax[i])
    t0, t1 = _box(box, np.uintp(0), ox, oy, oz, ix, iy, iz, sx, sy, sz, tmin, tlim)
    return ox, oy, oz, dx, dy, dz, ix, iy, iz, sx, sy, sz, tlim, t0, t1


@jit
def bvh_chunk(lo, hi, O, D, tmin, tmax, anyhit, box, diag, ni, nf, tv, ids, stack_size,
              out_t, out_id, counters):
    """Trace rays lo..hi-1 with one stack. ``ni``/``nf``: flat int32 / float32 views of the
    (nodes, 8) node records [lo xyz, hi xyz, a, b]."""
    sn = np.empty(stack_size, np.int64)
    st = np.empty(stack_size, np.float64)
    six = np.uintp(6)
    seven = np.uintp(7)
    for i in range(lo, hi):
        px, py, pz, dx, dy, dz, ix, iy, iz, sx, sy, sz, best, t0, t1 = ray_start(O, D, i, box, tmin, tmax)
        best_id = -1
        nvis = 0
        leaves = 0
        tests = 0
        in_box = t0 <= t1
        if in_box:
            tol = t_tolerance(t0, t1, diag, ix, iy, iz)
            sp = 0
            node = 0
            while True:
                nvis += 1
                base = np.uintp(8 * node)
                cnt = ni[base + seven]
                if cnt > 0:
                    leaves += 1
                    off = ni[base + six]
                    # written out here and in bvh4_chunk: as an inline helper returning (best,
                    # best_id, tests, done) this kernel measured 2-3 % slower (bunny-69k, 1 thread)
                    done = False
                    for rr in range(off, off + cnt):
                        r = np.uintp(rr)
                        tests += 1
                        t = ray_triangle(px, py, pz, dx, dy, dz, tv[r, 0], tv[r, 1], tv[r, 2],
                                         tv[r, 3], tv[r, 4], tv[r, 5], tv[r, 6], tv[r, 7], tv[r, 8],
                                         tmin, best)
                        if t < best:
                            best = t
                            best_id = ids[r]
                            if anyhit:
                                done = True
                                break
                    if done:
                        break
                    node = -1
                else:
                    left = node + 1
                    right = ni[base + six]
                    lim = best + tol
                    ln, lf = _box(nf, base + np.uintp(8), px, py, pz, ix, iy, iz, sx, sy, sz, tmin, lim)
                    rn, rf = _box(nf, np.uintp(8 * right), px, py, pz, ix, iy, iz, sx, sy, sz, tmin, lim)
                    hl = ln <= lf + tol
                    hr = rn <= rf + tol
                    if hl and hr:
                        spu = np.uintp(sp)
                        if cnt == 0:  # order by entry distance
                            near_left = ln <= rn
                        else:  # order by the sign of the direction on the split axis -1 - cnt
                            near_left = (sx if cnt == -1 else (sy if cnt == -2 else sz)) == 0
                        sn[spu] = right if near_left else left
                        st[spu] = rn if near_left else ln
                        sp += 1
                        node = left if near_left else right
                    elif hl:
                        node = left
                    elif hr:
                        node = right
                    else:
                        node = -1
                if node < 0:  # pop the nearest pending node that may still hold a closer hit
                    sp = pop_within(st, sp, best + tol)
                    if sp < 0:
                        break
                    node = sn[np.uintp(sp)]
        store_ray(out_t, out_id, counters, i, best if best_id >= 0 else INF, best_id, 1 if in_box else 0,
                  leaves, tests, nvis, 0)


@pjit
def bvh_trace(O, D, tmin, tmax, anyhit, box, diag, ni, nf, tv, ids, stack_size, out_t, out_id,
              counters, nt):
    """Batched BVH traversal, ``prange`` over the ``nt`` threads, each taking every nt-th block of BLOCK rays (:data:`tracer.accel._jit.BLOCK`), one stack per block;
    ``counters`` (m, 5) int32 or None (the variant without counting)."""
    m = O.shape[0]
    for th in prange(nt):
        for b in range(th, nblocks(m), nt):
            bvh_chunk(b * BLOCK, min(m, (b + 1) * BLOCK), O, D, tmin, tmax, anyhit, box, diag, ni, nf,
                      tv, ids, stack_size, out_t, out_id, counters)


class BVH(TreeTraceMixin, Accel):
    """Binned-SAH BVH. Parameters: ``bins`` (32), ``max_leaf`` triangles per leaf (4),
    ``trav_cost`` relative to one triangle test (pbrt-v2: 1/8), ``order`` of the two children
    ("distance": nearer entry first; "sign": by the direction's sign on the split axis)."""

    _kernel = staticmethod(bvh_trace)

    name = "bvh"
    counter_fields = {"setups": "1 if the ray enters the root box", "steps": "leaves visited",
                      "tests": "ray/triangle tests", "nodes": "nodes visited (leaves included)"}

    def __init__(self, bins=32, max_leaf=4, trav_cost=BVH_TRAV_COST, order="distance"):
        self.bins, self.max_leaf, self.trav_cost, self.order = bins, max_leaf, trav_cost, order

    def build(self, scene):
        n = scene.n
        if not 2 <= int(self.bins) <= 1024:
            raise GridcostError(f"BVH bins must be in [2, 1024], got {self.bins}")
        if int(self.max_leaf) < 1:
            raise GridcostError(f"BVH max_leaf must be >= 1, got {self.max_leaf}")
        if n >= 2**30:
            raise GridcostError(f"{n:,} triangles exceed the BVH's int32 index range")
        if self.order not in ("sign", "distance"):
            raise GridcostError(f"BVH order must be 'sign' or 'distance', got {self.order!r}")
        check_budget(f"a BVH over {n:,} triangles of {scene.name}", n * (2 * 32 + 24 + 24 + 40 + 8))
        t_start = time.perf_counter()
        tris = scene.tris
        self.n_ = n
        if n == 0:
            self.nodes_ = np.zeros((1, 8), np.int32)
            self.nodes_f_ = self.nodes_.view(np.float32)
            self.tri_ids_ = np.zeros(0, np.int32)
            self.tri_verts_ = np.zeros((0, 9), np.float32)
            self.leaves_, self.depth_, self.sah_ = 0, 0, {"exp_inner": 0.0, "exp_tests": 0.0}
            self.diag_, self.build_seconds_ = 0.0, time.perf_counter() - t_start
            return self
        # centroids from the exact bounds (the tree's splits), node boxes from the padded ones
        pc = 0.5 * (tris.min(axis=1).astype(np.float64) + tris.max(axis=1).astype(np.float64))
        self.box_ = root_box(scene)
        pb = np.concatenate(padded_bounds(tris, self.box_), axis=1)
        B, info, order, nleaves, depth, s_inner, s_tests, root_area = bvh_build(
            pb, pc, int(self.bins), int(self.max_leaf), float(self.trav_cost))
        nodes = np.empty((len(B), 8), np.int32)
        nodes[:, :6] = B.view(np.int32)
        nodes[:, 6:] = info
        if self.order == "distance":  # interior b = 0: the kernel orders children by entry distance
            nodes[nodes[:, 7] < 0, 7] = 0
        self.nodes_ = traversal_array(nodes)
        self.nodes_f_ = self.nodes_.view(np.float32)
        self.tri_ids_ = order
        self.tri_verts_ = traversal_rows(tris.reshape(-1, 9), order)
        self.build_seconds_ = time.perf_counter() - t_start
        self.diag_ = float(np.linalg.norm(self.box_[3:] - self.box_[:3]))
        self.leaves_, self.depth_ = int(nleaves), int(depth)
        ra = root_area if root_area > 0 else np.nan
        self.sah_ = {"exp_inner": s_inner / ra, "exp_tests": s_tests / ra}
        self.scene_name_ = scene.name
        return self

    def stats(self) -> dict:
        nn = len(self.nodes_)
        e = self.sah_
        return {
            "structure": "bvh", "nodes": nn, "interior": nn - self.leaves_, "leaves": self.leaves_,
            "depth": self.depth_, "refs": len(self.tri_ids_),
            "mean_leaf_refs": len(self.tri_ids_) / max(self.leaves_, 1),
            # expected interior nodes / triangle tests per ray meeting the root box (area ratios)
            "exp_inner": e["exp_inner"], "exp_tests": e["exp_tests"],
            "sah_cost": self.trav_cost * e["exp_inner"] + e["exp_tests"],
            "memory_bytes": int(self.nodes_.nbytes + self.tri_ids_.nbytes
                                + self.tri_verts_.nbytes),
            "working_set": working_set(self.nodes_.nbytes, self.tri_ids_.nbytes, self.tri_verts_.nbytes),
            "build_s": self.build_seconds_,
            "params": {"bins": self.bins, "max_leaf": self.max_leaf, "trav_cost": self.trav_cost,
                       "order": self.order},
        }
