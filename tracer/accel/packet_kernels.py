"""Building blocks of the coherent grid traversal's packet loop (:func:`tracer.accel.packet._packets`,
see :mod:`tracer.accel.packet` for the algorithm): the per-thread work-array layout, the branch-free
ray-packet/triangle test LLVM vectorises, the frustum (bounds, cell ranges, which rays still need
slices) and frustum culling (planes, then corner rays against the triangle's edges).
"""
from __future__ import annotations

import math

import numpy as np

from tracer.accel._jit import jit, ray_jit
from tracer.accel.geometry import INF, PARALLEL_COS

#: margin in cell units for cell ranges, first/last slices and the culling planes
EPS = 1e-6
#: relative margin of the corner-ray (edge) culling test
CULL_REL = 1e-9
#: the corner-ray (edge) culling test is tried only on triangles wider than this many cells in u or v
EDGE_MIN = 1.0
_PAR2 = PARALLEL_COS * PARALLEL_COS
# rows of the per-thread float work array
_OX, _OY, _OZ, _DX, _DY, _DZ, _DD, _BEST, _T1, _KO, _KD, _AU, _AV, _SU, _SV, _C0, _C1 = range(17)
_NW = 17
# rows of the per-thread int work array
_BID, _IDX, _SINGLE, _NL = range(4)


@ray_jit
def _lane(dx, dy, dz, dd, sx, sy, sz, sn, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, p2nn, tmin, best):
    """One ray of a packet test: ray_triangle's float64 expressions without branches -> (hit, t)."""
    det = dx * nx + dy * ny + dz * nz
    rx = dy * sz - dz * sy
    ry = dz * sx - dx * sz
    rz = dx * sy - dy * sx
    un = -(e2x * rx + e2y * ry + e2z * rz)
    vn = e1x * rx + e1y * ry + e1z * rz
    t = sn / det
    ok = (((det > 0.0) & (un >= 0.0) & (vn >= 0.0) & (un + vn <= det))
          | ((det <= 0.0) & (un <= 0.0) & (vn <= 0.0) & (un + vn >= det)))
    return (det * det > p2nn * dd) & ok & (t > tmin) & (t < best), t


@ray_jit
def _test_tri(n, common, W, I, tid, ax, ay, az, bx, by, bz, cx, cy, cz, tmin):
    """Rays [0, n) of the packet against one triangle (float64 vertices): a loop LLVM vectorises,
    with masked stores of the hits. With a common origin s = a - o and s.n are hoisted. Returns
    how many of the n lanes hit (the any-hit kernel retires those rays at once)."""
    e1x = bx - ax
    e1y = by - ay
    e1z = bz - az
    e2x = cx - ax
    e2y = cy - ay
    e2z = cz - az
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    p2nn = _PAR2 * (nx * nx + ny * ny + nz * nz)
    nh = 0
    if common:
        sx = ax - W[_OX, 0]
        sy = ay - W[_OY, 0]
        sz = az - W[_OZ, 0]
        sn = sx * nx + sy * ny + sz * nz
        for i in range(n):
            h, t = _lane(W[_DX, i], W[_DY, i], W[_DZ, i], W[_DD, i], sx, sy, sz, sn,
                         e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, p2nn, tmin, W[_BEST, i])
            nh += h
            if h:
                W[_BEST, i] = t
                I[_BID, i] = tid
    else:
        for i in range(n):
            sx = ax - W[_OX, i]
            sy = ay - W[_OY, i]
            sz = az - W[_OZ, i]
            h, t = _lane(W[_DX, i], W[_DY, i], W[_DZ, i], W[_DD, i], sx, sy, sz, sx * nx + sy * ny + sz * nz,
                         e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, p2nn, tmin, W[_BEST, i])
            nh += h
            if h:
                W[_BEST, i] = t
                I[_BID, i] = tid
    return nh


@ray_jit
def _min(a, b):
    return a if a < b else b  # a select LLVM vectorises (the builtin min is not)


@ray_jit
def _max(a, b):
    return a if a > b else b


@ray_jit
def _plane_cull(gu0, gu1, gu2, k0, k1, k2, alo, slo, ahi, shi):
    """All three vertices below the lower or above the upper frustum plane u = a + s k'."""
    if gu0 - (alo + slo * k0) < -EPS and gu1 - (alo + slo * k1) < -EPS and gu2 - (alo + slo * k2) < -EPS:
        return True
    return gu0 - (ahi + shi * k0) > EPS and gu1 - (ahi + shi * k1) > EPS and gu2 - (ahi + shi * k2) > EPS


@jit
def _edge_out(nk, nu, nv, sig, ru, rv, slo_u, shi_u, slo_v, shi_v, side):
    """Do all four corner directions (sig, S_u ru, S_v rv) lie strictly outside the edge plane with
    normal (nk, nu, nv), whose inside is the sign ``side``?"""
    a = nu * ru
    b = nv * rv
    hi = sig * nk + max(a * slo_u, a * shi_u) + max(b * slo_v, b * shi_v)
    lo = sig * nk + min(a * slo_u, a * shi_u) + min(b * slo_v, b * shi_v)
    marg = CULL_REL * (abs(nk) + abs(a) * (abs(slo_u) + abs(shi_u)) + abs(b) * (abs(slo_v) + abs(shi_v)))
    if side > 0.0:
        return hi < -marg
    return lo > marg


@jit
def _spread(counters, n, col, v, I):
    """Spread a packet count v over the rays I[_IDX, :n] as evenly as integers allow."""
    q = v // n
    r = v - q * n
    for j in range(n):
        counters[I[_IDX, j], col] += q + (1 if j < r else 0)


@jit
def _bounds(n, W):
    """The frustum of rays [0, n): u in [alo_u + slo_u k', ahi_u + shi_u k'], same for v."""
    alo_u = slo_u = alo_v = slo_v = INF
    ahi_u = shi_u = ahi_v = shi_v = -INF
    for q in range(n):
        alo_u = min(alo_u, W[_AU, q]); ahi_u = max(ahi_u, W[_AU, q])
        alo_v = min(alo_v, W[_AV, q]); ahi_v = max(ahi_v, W[_AV, q])
        slo_u = min(slo_u, W[_SU, q]); shi_u = max(shi_u, W[_SU, q])
        slo_v = min(slo_v, W[_SV, q]); shi_v = max(shi_v, W[_SV, q])
    return alo_u, ahi_u, slo_u, shi_u, alo_v, ahi_v, slo_v, shi_v


@ray_jit
def _span(n, I):
    """The last slice any of rays [0, n) needs, and the first slice after which one needs no more."""
    hi = -1
    lo = 1 << 30
    for q in range(n):
        hi = max(hi, I[_NL, q])
        lo = min(lo, I[_NL, q])
    return hi, lo


@ray_jit
def _retire(q, i, W, I, out_t, out_id, counters, tested):
    """Packet slot q (ray i) is done: write its hit, if any, and the packet's triangle tests."""
    if I[_BID, q] >= 0:
        out_t[i] = np.float32(W[_BEST, q])
        out_id[i] = I[_BID, q]
    if counters is not None:
        counters[i, 2] = tested


@ray_jit
def _needs(n, anyhit, W, I):
    """After hits: a ray with a hit needs no slice past its hit's (closest hit), or none at all
    (any hit: I[_NL] = -1)."""
    for q in range(n):
        if I[_BID, q] >= 0:
            I[_NL, q] = -1 if anyhit else min(I[_NL, q], int(math.floor(W[_KO, q] + W[_BEST, q] * W[_KD, q] + EPS)))


@ray_jit
def _compact(n, s, W, I, out_t, out_id, counters, tested):
    """Retire the rays of slots [0, n) that need no slice past ``s`` (I[_NL] <= s): write their
    results, move the last active ray into each freed slot (the retired ray's id stays at the end of
    I[_IDX] for the counters). Returns (rays left, whether any was retired)."""
    q = 0
    retired = False
    while q < n:
        if I[_NL, q] > s:
            q += 1
            continue
        retired = True
        i = I[_IDX, q]
        _retire(q, i, W, I, out_t, out_id, counters, tested)
        n -= 1
        if q < n:
            for row in range(_NW):
                W[row, q] = W[row, n]
            I[_BID, q] = I[_BID, n]
            I[_IDX, q] = I[_IDX, n]
            I[_NL, q] = I[_NL, n]
            I[_IDX, n] = i
    return n, retired


@ray_jit
def _cells(alo, ahi, slo, shi, s0, s1, n):
    """Cells [c0, c1] (clipped to [0, n)) the frustum covers along one axis for k' in [s0, s1]."""
    lo = min(alo + slo * s0, alo + slo * s1)
    hi = max(ahi + shi * s0, ahi + shi * s1)
    return max(int(math.floor(lo - EPS)), 0), min(int(math.floor(hi + EPS)), n - 1)


@ray_jit
def _culled(ax, ay, az, bx, by, bz, cx, cy, cz, K, U, V, gp, sig, P0, fr, edge, ox, oy, oz, ru, rv):
    """Is the triangle outside the frustum ``fr``? Planes first; corner rays against the edges
    (common origin ``o``) for triangles wider than EDGE_MIN cells."""
    alo_u, ahi_u, slo_u, shi_u, alo_v, ahi_v, slo_v, shi_v = fr
    va, vb, vc = (ax, ay, az), (bx, by, bz), (cx, cy, cz)
    k0 = sig * ((va[K] - gp[K]) * gp[6 + K] - P0)
    k1 = sig * ((vb[K] - gp[K]) * gp[6 + K] - P0)
    k2 = sig * ((vc[K] - gp[K]) * gp[6 + K] - P0)
    gu0 = (va[U] - gp[U]) * gp[6 + U]
    gu1 = (vb[U] - gp[U]) * gp[6 + U]
    gu2 = (vc[U] - gp[U]) * gp[6 + U]
    if _plane_cull(gu0, gu1, gu2, k0, k1, k2, alo_u, slo_u, ahi_u, shi_u):
        return True
    gv0 = (va[V] - gp[V]) * gp[6 + V]
    gv1 = (vb[V] - gp[V]) * gp[6 + V]
    gv2 = (vc[V] - gp[V]) * gp[6 + V]
    if _plane_cull(gv0, gv1, gv2, k0, k1, k2, alo_v, slo_v, ahi_v, shi_v):
        return True
    if not edge or (max(gu0, gu1, gu2) - min(gu0, gu1, gu2) <= EDGE_MIN
                    and max(gv0, gv1, gv2) - min(gv0, gv1, gv2) <= EDGE_MIN):
        return False
    o3 = (ox, oy, oz)
    w0k = va[K] - o3[K]; w0u = va[U] - o3[U]; w0v = va[V] - o3[V]
    w1k = vb[K] - o3[K]; w1u = vb[U] - o3[U]; w1v = vb[V] - o3[V]
    w2k = vc[K] - o3[K]; w2u = vc[U] - o3[U]; w2v = vc[V] - o3[V]
    # edge-plane normals through the origin, in the cyclic (K, U, V) frame
    n0k = w0u * w1v - w0v * w1u; n0u = w0v * w1k - w0k * w1v; n0v = w0k * w1u - w0u * w1k
    n1k = w1u * w2v - w1v * w2u; n1u = w1v * w2k - w1k * w2v; n1v = w1k * w2u - w1u * w2k
    n2k = w2u * w0v - w2v * w0u; n2u = w2v * w0k - w2k * w0v; n2v = w2k * w0u - w2u * w0k
    side = n0k * w2k + n0u * w2u + n0v * w2v
    mag = ((abs(w0k) + abs(w0u) + abs(w0v)) * (abs(w1k) + abs(w1u) + abs(w1v))
           * (abs(w2k) + abs(w2u) + abs(w2v)))
    if abs(side) <= CULL_REL * mag:  # the origin is (nearly) in the triangle's plane
        return False
    return (_edge_out(n0k, n0u, n0v, sig, ru, rv, slo_u, shi_u, slo_v, shi_v, side)
            or _edge_out(n1k, n1u, n1v, sig, ru, rv, slo_u, shi_u, slo_v, shi_v, side)
            or _edge_out(n2k, n2u, n2v, sig, ru, rv, slo_u, shi_u, slo_v, shi_v, side))
