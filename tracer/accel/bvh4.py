"""4-wide BVH collapsed from the binned-SAH binary BVH (:mod:`tracer.accel.bvh`), traced by testing the four
child boxes of a node together and visiting the hit children nearest first.

Build: the binary BVH of :class:`tracer.accel.bvh.BVH` (same parameters), then collapsed top-down (Wald,
Benthin & Boulos 2008; Embree's BVH4): a 4-wide node starts from the two children of a binary
interior node and repeatedly replaces its interior child of largest surface area by that child's two
children until it holds four children or only leaves. The binary leaves (and the triangle order)
are kept as they are.

Layout: ``nodes_`` (nodes, 32) int32 records of 128 bytes: the four child boxes in SoA float32
``[lo x0..x3, lo y0..y3, lo z0..z3, hi x0..x3, hi y0..y3, hi z0..z3]`` (24 words, float32 bits),
then ``ref[4]`` and ``count[4]``: count 0 = interior child (ref = its node), count > 0 = leaf (ref =
offset into ``tri_verts_``/``tri_ids_``), count -1 = empty slot (box lo = +inf, hi = -inf, never hit).
``nodes_f_`` is the float32 view.

Traversal: the rules of :mod:`tracer.accel.bvh` (the root box tested in float64, comparisons widened by
``tol`` = T_EPS of the ray's t scale, float32 vertices passed to :func:`tracer.accel.geometry.ray_triangle`
as the oracle passes them, so a hit's t and triangle are bit-identical to the oracle's), except that
the four child boxes of a node are tested together in float32 (one 4-lane vector operation,
:func:`tracer.accel.simd.slab4`): origin (float32 already), inverse direction
rounded to float32, ``(plane - o) * inv`` per plane, NaN products (origin on a slab plane, zero
direction) ignored. Each float32 distance that decides a hit (the entry max and exit min, both
within [tmin, the root exit] for a ray meeting the box) is within about 3 float32 roundings (2e-7
relative) of the exact value, an order of magnitude inside ``tol`` (2e-6 of the t scale), so the
widened test never drops a box the ray meets (a box met only within the widening is just visited).
The four hits form a 4-bit mask: one hit child is visited directly; several are pushed on one stack
with their entry distances, sorted so the nearest is on top, and it is visited; an entry whose
distance lies beyond the closest hit (+ tol) is dropped when popped. Counters: ``setups`` 1 per ray meeting the root box, ``nodes``
entries visited (4-wide nodes and leaves), ``steps`` leaves visited, ``tests`` triangle tests.
"""
from __future__ import annotations

import time

import numpy as np
from numba import prange

from tracer.accel._jit import BLOCK, jit, nblocks, pjit, pop_within, store_ray
from tracer.accel import Accel, TreeTraceMixin
from tracer.accel.bvh import BVH, BVH_TRAV_COST, ray_start
from tracer.accel.geometry import INF, ray_triangle, t_tolerance
from tracer.accel.pages import traversal_array
from tracer.measure.memory import working_set
from tracer.accel.simd import slab4

#: int32 words per 4-wide node: 24 box words (SoA float32), 4 refs, 4 counts
WORDS = 32
REF = 24
CNT = 28


# ---------------------------------------------------------------- build (collapse)
@jit(inline="always")
def _barea(nb, c):
    ex0 = np.float64(nb[c, 3]) - nb[c, 0]
    ex1 = np.float64(nb[c, 4]) - nb[c, 1]
    ex2 = np.float64(nb[c, 5]) - nb[c, 2]
    return 2.0 * (ex0 * ex1 + ex1 * ex2 + ex2 * ex0)


@jit
def collapse4(nb, info):
    """Collapse a binary BVH (``nb`` (nodes, 6) float32 boxes; ``info`` (nodes, 2) int32: interior
    ``[right, <= 0]`` with the left child at i + 1, leaf ``[offset, count >= 1]``) into 4-wide node
    records (see the module docstring). Returns (records (n4, 32) int32, 4-wide depth)."""
    nbin = nb.shape[0]
    cap = max(1, nbin)
    rec = np.zeros((cap, WORDS), np.int32)
    rf = rec.view(np.float32)
    st_b = np.empty(64, np.int64)
    st_n = np.empty(64, np.int64)
    st_d = np.empty(64, np.int64)
    ch = np.empty(4, np.int64)
    n4 = 1
    max_depth = 0
    sp = 0
    if info[0, 1] > 0:  # a single leaf: the root holds it as its only child
        ch[0] = 0
        m = 1
        cur = 0
        depth = 0
    else:
        ch[0] = 1
        ch[1] = info[0, 0]
        m = 2
        cur = 0
        depth = 0
    while True:
        while m < 4:  # open the interior child of largest area
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
        for k in range(4):
            if k < m:
                c = ch[k]
                for j in range(6):
                    rf[cur, 4 * j + k] = nb[c, j]
                if info[c, 1] > 0:
                    rec[cur, REF + k] = info[c, 0]
                    rec[cur, CNT + k] = info[c, 1]
                else:
                    rec[cur, REF + k] = n4
                    rec[cur, CNT + k] = 0
                    if sp == st_b.shape[0]:
                        st_b = np.concatenate((st_b, st_b))
                        st_n = np.concatenate((st_n, st_n))
                        st_d = np.concatenate((st_d, st_d))
                    st_b[sp] = c
                    st_n[sp] = n4
                    st_d[sp] = depth + 1
                    sp += 1
                    n4 += 1
            else:
                for j in range(3):
                    rf[cur, 4 * j + k] = INF
                    rf[cur, 12 + 4 * j + k] = -INF
                rec[cur, REF + k] = 0
                rec[cur, CNT + k] = -1
        if sp == 0:
            break
        sp -= 1
        b = st_b[sp]
        cur = st_n[sp]
        depth = st_d[sp]
        ch[0] = b + 1
        ch[1] = info[b, 0]
        m = 2
    return rec[:n4].copy(), max_depth


# ---------------------------------------------------------------- traversal
#: set bits and lowest set bit of a 4-bit hit mask
_NBITS = (0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4)
_LOWBIT = (0, 0, 1, 0, 2, 0, 1, 0, 3, 0, 1, 0, 2, 0, 1, 0)


@jit
def bvh4_chunk(lo, hi, O, D, tmin, tmax, anyhit, box, diag, ni, nf, tv, ids, stack_size,
               out_t, out_id, counters):
    """Trace rays lo..hi-1 with one stack. ``ni``/``nf``: flat int32 / float32 views of the
    (nodes, 32) records."""
    sn = np.empty(stack_size, np.int64)
    sc = np.empty(stack_size, np.int64)
    st = np.empty(stack_size, np.float64)
    t4 = np.empty(4, np.float32)
    tmin32 = np.float32(tmin)
    for i in range(lo, hi):
        px, py, pz, dx, dy, dz, ix, iy, iz, sx, sy, sz, best, t0, t1 = ray_start(O, D, i, box, tmin, tmax)
        best_id = -1
        nvis = 0
        leaves = 0
        tests = 0
        in_box = t0 <= t1
        if in_box:
            tol = t_tolerance(t0, t1, diag, ix, iy, iz)
            # float32 copies of the ray for the box tests (see the module docstring)
            ox = O[i, 0]
            oy = O[i, 1]
            oz = O[i, 2]
            jx = np.float32(ix)
            jy = np.float32(iy)
            jz = np.float32(iz)
            tol32 = np.float32(tol)
            # word offsets of the near / far planes of the four boxes on each axis
            nxo = np.uintp(4) * sx
            fxo = np.uintp(12) - nxo
            nyo = np.uintp(4) + np.uintp(4) * sy
            fyo = np.uintp(16) - np.uintp(4) * sy
            nzo = np.uintp(8) + np.uintp(4) * sz
            fzo = np.uintp(20) - np.uintp(4) * sz
            sp = 0
            ref = 0
            cnt = 0
            while True:
                nvis += 1
                if cnt > 0:
                    leaves += 1
                    done = False
                    for rr in range(ref, ref + cnt):
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
                    ref = -1
                else:
                    base = np.uintp(WORDS) * np.uintp(ref)
                    lim = np.float32(best + tol)
                    # the four slab tests as one 4-lane float32 operation (tracer.accel.simd)
                    mask = slab4(nf, base, nxo, fxo, nyo, fyo, nzo, fzo, ox, oy, oz, jx, jy, jz, tmin32, lim,
                                 tol32, t4)
                    if mask == 0:
                        ref = -1
                    elif _NBITS[mask] == 1:  # one child hit: visit it, no stack
                        ku = base + np.uintp(_LOWBIT[mask])
                        ref = ni[ku + np.uintp(REF)]
                        cnt = ni[ku + np.uintp(CNT)]
                    else:  # push the hit children, kept sorted far .. near, and visit the nearest
                        sp0 = sp
                        while mask != 0:
                            k = _LOWBIT[mask]
                            mask &= mask - 1
                            ku = base + np.uintp(k)
                            tn = np.float64(t4[k])
                            j = sp
                            while j > sp0 and st[np.uintp(j - 1)] < tn:
                                ju = np.uintp(j)
                                st[ju] = st[ju - np.uintp(1)]
                                sn[ju] = sn[ju - np.uintp(1)]
                                sc[ju] = sc[ju - np.uintp(1)]
                                j -= 1
                            ju = np.uintp(j)
                            st[ju] = tn
                            sn[ju] = ni[ku + np.uintp(REF)]
                            sc[ju] = ni[ku + np.uintp(CNT)]
                            sp += 1
                        sp -= 1
                        spu = np.uintp(sp)
                        ref = sn[spu]
                        cnt = sc[spu]
                if ref < 0:  # pop the nearest pending entry that may still hold a closer hit
                    sp = pop_within(st, sp, best + tol)
                    if sp < 0:
                        break
                    spu = np.uintp(sp)
                    ref = sn[spu]
                    cnt = sc[spu]
        store_ray(out_t, out_id, counters, i, best if best_id >= 0 else INF, best_id, 1 if in_box else 0,
                  leaves, tests, nvis, 0)


@pjit
def bvh4_trace(O, D, tmin, tmax, anyhit, box, diag, ni, nf, tv, ids, stack_size, out_t, out_id,
               counters, nt):
    """Batched 4-wide BVH traversal, ``prange`` over the ``nt`` threads, each taking every nt-th block
    of BLOCK rays (:data:`tracer.accel._jit.BLOCK`), one stack per block; ``counters`` (m, 5) int32 or None
    (the variant without counting)."""
    m = O.shape[0]
    for th in prange(nt):
        for b in range(th, nblocks(m), nt):
            bvh4_chunk(b * BLOCK, min(m, (b + 1) * BLOCK), O, D, tmin, tmax, anyhit, box, diag, ni, nf,
                       tv, ids, stack_size, out_t, out_id, counters)


class BVH4(TreeTraceMixin, Accel):
    """4-wide BVH collapsed from :class:`tracer.accel.bvh.BVH`; parameters as the binary BVH's: ``bins``
    (32), ``max_leaf`` triangles per leaf (4), ``trav_cost`` (pbrt-v2: 1/8)."""

    _kernel = staticmethod(bvh4_trace)

    name = "bvh4"
    counter_fields = {"setups": "1 if the ray enters the root box", "steps": "leaves visited",
                      "tests": "ray/triangle tests", "nodes": "nodes visited (leaves included)"}

    def __init__(self, bins=32, max_leaf=4, trav_cost=BVH_TRAV_COST):
        self.bins, self.max_leaf, self.trav_cost = bins, max_leaf, trav_cost

    def build(self, scene):
        t_start = time.perf_counter()
        b = BVH(self.bins, self.max_leaf, self.trav_cost).build(scene)
        self.n_ = b.n_
        self.binary_ = b.stats()
        self.tri_ids_, self.tri_verts_, self.diag_ = b.tri_ids_, b.tri_verts_, b.diag_
        self.scene_name_ = scene.name
        if b.n_ == 0:
            self.nodes_ = np.zeros((0, WORDS), np.int32)
            self.nodes_f_ = self.nodes_.view(np.float32)
            self.depth_, self.build_seconds_ = 0, time.perf_counter() - t_start
            return self
        self.box_ = b.box_
        rec, depth = collapse4(b.nodes_f_[:, :6], b.nodes_[:, 6:8])
        self.nodes_ = traversal_array(rec)
        self.nodes_f_ = self.nodes_.view(np.float32)
        self.depth_ = int(depth)
        self.build_seconds_ = time.perf_counter() - t_start
        return self

    def _stack_size(self) -> int:
        """Up to three pushed children per level (four hit, the nearest visited), and a margin."""
        return 3 * self.depth_ + 8

    def stats(self) -> dict:
        nn = len(self.nodes_)
        cnt = self.nodes_[:, CNT:]
        bs = self.binary_
        return {
            "structure": "bvh4", "nodes": nn, "interior": nn, "leaves": bs["leaves"],
            "depth": self.depth_, "binary_depth": bs["depth"], "refs": len(self.tri_ids_),
            "mean_children": float((cnt >= 0).sum() / max(nn, 1)),
            "mean_leaf_refs": bs["mean_leaf_refs"],
            "memory_bytes": int(self.nodes_.nbytes + self.tri_ids_.nbytes + self.tri_verts_.nbytes),
            "working_set": working_set(self.nodes_.nbytes, self.tri_ids_.nbytes, self.tri_verts_.nbytes),
            "build_s": self.build_seconds_,
            "params": {"bins": self.bins, "max_leaf": self.max_leaf, "trav_cost": self.trav_cost},
        }
