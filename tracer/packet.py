"""Coherent grid traversal (Wald, Ize, Kensler, Knoll & Parker 2006): frustum-bounded packets of
rays walked slice by slice through a uniform grid.

Per packet (k x k = consecutive groups of k^2 rays of the batch):

1. Set-up (Sec 2.2): rays are clipped to the grid box; the major axis K is the dominant component
   of the packet's summed direction in grid space. Rays whose K component has the other sign, or
   whose slopes du/dk, dv/dk exceed ``MAX_SLOPE``, are traced on their own (the uniform grid's
   single-ray kernel :func:`tracer.grid.grid_ray`, set up by :func:`tracer.geometry.dda_setup`);
   when the rest do not form a narrow frustum (slope spread > ``MAX_SPREAD`` or width at the entry
   plane > ``MAX_WIDTH`` cells) the whole packet is.
2. Frustum: in grid coordinates every ray is u_i(k') = a_i + s_i k' with k' the slice distance from
   the packet's entry plane, so the slice overlap box is [min a + min s k', max a + max s k'] —
   B(i+1) = B(i) + dB, evaluated directly (A + S n) so no error accumulates. Truncation gives the
   cells [u0..u1] x [v0..v1] of the slice (with an ``EPS`` cell margin: being generous only costs time).
3. Slices are visited front to back; every cell once per packet; per-packet mailboxing (triangles
   stamped with the packet id, Sec 2.3) and frustum culling: a triangle is rejected when its three
   vertices lie outside one of the four frustum planes, or (common origin) when the four corner
   rays miss it on the same edge (Dmitriev et al.'s shaft culling). Both tests are conservative by
   a relative margin far above rounding, so culling never drops a hit.
4. Ray-triangle tests: one branch-free loop over the packet's rays (vectorised by LLVM) computing
   exactly the float64 expressions of :func:`tracer.geometry.ray_triangle` (hoisting only the
   ray-independent ones), so hits agree bit for bit with the oracle. Rays keep their own closest t.
5. Termination: the packet stops after the last slice any ray still needs (its closest hit's or
   its exit's slice), recomputed whenever a hit improves. Macrocells (Sec 2.4, M x M x M blocks of
   cells, any M): on entering a slab of M slices the frustum's overlap with the whole slab is
   tested against the macrocell occupancy and empty slabs are skipped.

Counters: per ray (:data:`tracer.accel.COUNTER_NAMES`) packet-level counts (set-ups, cells = steps,
slices = nodes, mailbox+culling skips) are spread evenly over the packet's rays (so sums are exact);
``tests`` are the ray-triangle tests each ray did. :meth:`CoherentGrid.packet_counters` returns
per-packet arrays (:data:`PACKET_COUNTERS`) with the tests that would be done without mailboxing,
with mailboxing, and with mailboxing + culling from one traversal (hits, and so the traversal,
do not depend on either).
"""
from __future__ import annotations

import math
import time

import numba
import numpy as np
from numba import prange

from tracer._jit import jit, pjit
from tracer.accel import COUNTER_NAMES, Accel
from tracer.constants import WALD_LAMBDA, WALD_MACROCELL
from tracer.errors import GridcostError
from tracer.geometry import INF, PARALLEL_COS, ray_box
from tracer.grid import grid_assign, grid_params, grid_ray, macro_occupancy, res_wald
from tracer.memory import check_budget

NCOUNT = len(COUNTER_NAMES)
#: per-packet counter columns of :meth:`CoherentGrid.packet_counters`; tests_* are ray-triangle
#: tests (triangles x rays of the packet): no mailboxing/culling, mailboxing, mailboxing + culling,
#: and what the configured variant did
PACKET_COUNTERS = ("rays", "single", "slices", "cells", "considered", "tests_plain", "tests_mb",
                   "tests_mb_fc", "tests", "macro_skips", "culled")
NPC = len(PACKET_COUNTERS)
#: margin in cell units for cell ranges, first/last slices and the culling planes
EPS = 1e-6
#: relative margin of the corner-ray (edge) culling test
CULL_REL = 1e-9
#: rays steeper than this (|du/dk| or |dv/dk|) are traced on their own
MAX_SLOPE = 2.0
#: a packet whose slopes spread more than this (cells per slice) is traced ray by ray
MAX_SPREAD = 1.0
#: ... or whose rays spread more than this many cells at the entry plane
MAX_WIDTH = 8.0
_PAR2 = PARALLEL_COS * PARALLEL_COS
# rows of the per-thread float work array
_OX, _OY, _OZ, _DX, _DY, _DZ, _DD, _BEST, _T1, _KO, _KD = range(11)
_NW = 11


# ---------------------------------------------------------------- kernels
@jit(inline="always")
def _test_tri(n, common, pox, poy, poz, pdx, pdy, pdz, pdd, best, bid, tid,
              ax, ay, az, bx, by, bz, cx, cy, cz, tmin):
    """All n rays against one triangle: ray_triangle's float64 arithmetic, branch-free."""
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
    if common:
        sx = ax - pox[0]
        sy = ay - poy[0]
        sz = az - poz[0]
        sn = sx * nx + sy * ny + sz * nz
        for i in range(n):
            dx = pdx[i]
            dy = pdy[i]
            dz = pdz[i]
            det = dx * nx + dy * ny + dz * nz
            rx = dy * sz - dz * sy
            ry = dz * sx - dx * sz
            rz = dx * sy - dy * sx
            un = -(e2x * rx + e2y * ry + e2z * rz)
            vn = e1x * rx + e1y * ry + e1z * rz
            t = sn / det
            b = best[i]
            ok = (((det > 0.0) & (un >= 0.0) & (vn >= 0.0) & (un + vn <= det))
                  | ((det <= 0.0) & (un <= 0.0) & (vn <= 0.0) & (un + vn >= det)))
            h = (det * det > p2nn * pdd[i]) & ok & (t > tmin) & (t < b)
            best[i] = t if h else b
            bid[i] = tid if h else bid[i]
    else:
        for i in range(n):
            dx = pdx[i]
            dy = pdy[i]
            dz = pdz[i]
            sx = ax - pox[i]
            sy = ay - poy[i]
            sz = az - poz[i]
            det = dx * nx + dy * ny + dz * nz
            rx = dy * sz - dz * sy
            ry = dz * sx - dx * sz
            rz = dx * sy - dy * sx
            un = -(e2x * rx + e2y * ry + e2z * rz)
            vn = e1x * rx + e1y * ry + e1z * rz
            t = (sx * nx + sy * ny + sz * nz) / det
            b = best[i]
            ok = (((det > 0.0) & (un >= 0.0) & (vn >= 0.0) & (un + vn <= det))
                  | ((det <= 0.0) & (un <= 0.0) & (vn <= 0.0) & (un + vn >= det)))
            h = (det * det > p2nn * pdd[i]) & ok & (t > tmin) & (t < b)
            best[i] = t if h else b
            bid[i] = tid if h else bid[i]


@jit(inline="always")
def _plane_cull(gu0, gu1, gu2, k0, k1, k2, alo, slo, ahi, shi):
    """All three vertices below the lower or above the upper frustum plane u = a + s k'."""
    if gu0 - (alo + slo * k0) < -EPS and gu1 - (alo + slo * k1) < -EPS and gu2 - (alo + slo * k2) < -EPS:
        return True
    return gu0 - (ahi + shi * k0) > EPS and gu1 - (ahi + shi * k1) > EPS and gu2 - (ahi + shi * k2) > EPS


@jit(inline="always")
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


@jit(inline="always")
def _spread(counters, n, col, v, slot_of):
    """Spread a packet count v over the rays slot_of[:n] as evenly as integers allow."""
    q = v // n
    r = v - q * n
    for j in range(n):
        counters[slot_of[j], col] += q + (1 if j < r else 0)


@jit
def _packet(b, e, O, D, tmin, tmax, anyhit, gp, res, cell_start, tri_ids, tv, macro, M,
            mailbox, cull, pid, stamps, W, I, out_t, out_id, counters, pc, p):
    nxg = res[0]
    nyg = res[1]
    nzg = res[2]
    # ---- major axis: dominant component of the summed grid-space direction
    sx = 0.0
    sy = 0.0
    sz = 0.0
    for i in range(b, e):
        sx += float(D[i, 0]) * gp[6]
        sy += float(D[i, 1]) * gp[7]
        sz += float(D[i, 2]) * gp[8]
    if abs(sx) >= abs(sy) and abs(sx) >= abs(sz):
        K = 0
        sk = sx
    elif abs(sy) >= abs(sz):
        K = 1
        sk = sy
    else:
        K = 2
        sk = sz
    U = (K + 1) % 3
    V = (K + 2) % 3
    sig = 1.0 if sk >= 0.0 else -1.0
    isig = 1 if sk >= 0.0 else -1
    nK = res[K]
    nU = res[U]
    nV = res[V]
    st0 = 1
    st1 = nxg
    st2 = nxg * nyg
    stK = st0 if K == 0 else (st1 if K == 1 else st2)
    stU = st0 if U == 0 else (st1 if U == 1 else st2)
    stV = st0 if V == 0 else (st1 if V == 1 else st2)
    pox = W[_OX]
    poy = W[_OY]
    poz = W[_OZ]
    pdx = W[_DX]
    pdy = W[_DY]
    pdz = W[_DZ]
    pdd = W[_DD]
    best = W[_BEST]
    pt1 = W[_T1]
    pko = W[_KO]
    pkd = W[_KD]
    bid = I[0]
    idx = I[1]
    single = I[2]
    # ---- clip rays to the box, sort into packet rays and single rays
    n = 0
    ns = 0
    kin_lo = INF
    kin_hi = -INF
    for i in range(b, e):
        ox = float(O[i, 0])
        oy = float(O[i, 1])
        oz = float(O[i, 2])
        dx = float(D[i, 0])
        dy = float(D[i, 1])
        dz = float(D[i, 2])
        t0, t1 = ray_box(ox, oy, oz, dx, dy, dz, gp[0], gp[1], gp[2], gp[9], gp[10], gp[11], tmin, float(tmax[i]))
        out_t[i] = np.float32(INF)
        out_id[i] = -1
        if t0 > t1:
            continue
        o3 = (ox, oy, oz)
        d3 = (dx, dy, dz)
        gdk = d3[K] * gp[6 + K]
        gdu = d3[U] * gp[6 + U]
        gdv = d3[V] * gp[6 + V]
        if sig * gdk > 0.0 and abs(gdu) <= MAX_SLOPE * abs(gdk) and abs(gdv) <= MAX_SLOPE * abs(gdk):
            pox[n] = ox
            poy[n] = oy
            poz[n] = oz
            pdx[n] = dx
            pdy[n] = dy
            pdz[n] = dz
            pdd[n] = dx * dx + dy * dy + dz * dz
            best[n] = float(tmax[i])
            bid[n] = -1
            idx[n] = i
            pt1[n] = t1
            gok = (o3[K] - gp[K]) * gp[6 + K]
            kin = gok + t0 * gdk
            kin_lo = min(kin_lo, kin)
            kin_hi = max(kin_hi, kin)
            pko[n] = gok
            pkd[n] = gdk
            n += 1
        else:
            single[ns] = i
            ns += 1
    slices = 0
    cells = 0
    considered = 0
    uniq = 0
    uniq_nc = 0
    tested = 0
    skips = 0
    mskips = 0
    culled = 0
    if n > 0:
        # ---- frustum: first slice, entry plane P0, u_i(k') = a_i + s_i k'
        if isig > 0:
            jf = int(math.floor(kin_lo - EPS))
            jf = min(max(jf, 0), nK - 1)
            P0 = float(jf)
        else:
            jf = int(math.floor(kin_hi + EPS))
            jf = min(max(jf, 0), nK - 1)
            P0 = float(jf + 1)
        alo_u = INF
        ahi_u = -INF
        slo_u = INF
        shi_u = -INF
        alo_v = INF
        ahi_v = -INF
        slo_v = INF
        shi_v = -INF
        common = True
        for q in range(n):
            o3 = (pox[q], poy[q], poz[q])
            d3 = (pdx[q], pdy[q], pdz[q])
            gdk = pkd[q]
            su = d3[U] * gp[6 + U] / gdk
            sv = d3[V] * gp[6 + V] / gdk
            au = (o3[U] - gp[U]) * gp[6 + U] + (P0 - pko[q]) * su
            av = (o3[V] - gp[V]) * gp[6 + V] + (P0 - pko[q]) * sv
            alo_u = min(alo_u, au)
            ahi_u = max(ahi_u, au)
            alo_v = min(alo_v, av)
            ahi_v = max(ahi_v, av)
            slo_u = min(slo_u, sig * su)
            shi_u = max(shi_u, sig * su)
            slo_v = min(slo_v, sig * sv)
            shi_v = max(shi_v, sig * sv)
            # k'(t) = pko + t pkd from now on
            pko[q] = sig * (pko[q] - P0)
            pkd[q] = sig * gdk
            if pox[q] != pox[0] or poy[q] != poy[0] or poz[q] != poz[0]:
                common = False
        if (shi_u - slo_u > MAX_SPREAD or shi_v - slo_v > MAX_SPREAD
                or ahi_u - alo_u > MAX_WIDTH or ahi_v - alo_v > MAX_WIDTH):
            for q in range(n):  # not a coherent packet: every ray on its own
                single[ns] = idx[q]
                ns += 1
            n = 0
    if n > 0:
        nmax = (nK - 1 - jf) if isig > 0 else jf
        nlast = -1
        for q in range(n):
            nl = int(math.floor(pko[q] + pt1[q] * pkd[q] + EPS))
            nlast = max(nlast, nl)
        nlast = min(nlast, nmax)
        edge = common and cull and tmin >= 0.0
        ox0 = pox[0]
        oy0 = poy[0]
        oz0 = poz[0]
        ru = gp[3 + U] / gp[3 + K]
        rv = gp[3 + V] / gp[3 + K]
        mb1 = (nxg - 1) // M + 1
        mb2 = mb1 * ((nyg - 1) // M + 1)
        mstK = 1 if K == 0 else (mb1 if K == 1 else mb2)
        mstU = 1 if U == 0 else (mb1 if U == 1 else mb2)
        mstV = 1 if V == 0 else (mb1 if V == 1 else mb2)
        counting = pc is not None
        stamping = mailbox or counting
        slab_end = -1
        s = 0
        while s <= nlast:
            j = jf + isig * s
            if macro is not None and s > slab_end:
                J = j // M
                jend = J * M + M - 1 if isig > 0 else J * M
                s_end = min(s + abs(jend - j), nlast)
                ulo = min(alo_u + slo_u * s, alo_u + slo_u * (s_end + 1))
                uhi = max(ahi_u + shi_u * s, ahi_u + shi_u * (s_end + 1))
                vlo = min(alo_v + slo_v * s, alo_v + slo_v * (s_end + 1))
                vhi = max(ahi_v + shi_v * s, ahi_v + shi_v * (s_end + 1))
                u0 = max(int(math.floor(ulo - EPS)), 0)
                u1 = min(int(math.floor(uhi + EPS)), nU - 1)
                v0 = max(int(math.floor(vlo - EPS)), 0)
                v1 = min(int(math.floor(vhi + EPS)), nV - 1)
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
            ulo = min(alo_u + slo_u * s, alo_u + slo_u * (s + 1))
            uhi = max(ahi_u + shi_u * s, ahi_u + shi_u * (s + 1))
            vlo = min(alo_v + slo_v * s, alo_v + slo_v * (s + 1))
            vhi = max(ahi_v + shi_v * s, ahi_v + shi_v * (s + 1))
            u0 = max(int(math.floor(ulo - EPS)), 0)
            u1 = min(int(math.floor(uhi + EPS)), nU - 1)
            v0 = max(int(math.floor(vlo - EPS)), 0)
            v1 = min(int(math.floor(vhi + EPS)), nV - 1)
            changed = False
            sbase = j * stK
            for iv in range(v0, v1 + 1):
                for iu in range(u0, u1 + 1):
                    c = sbase + iu * stU + iv * stV
                    cells += 1
                    for r in range(cell_start[c], cell_start[c + 1]):
                        tid = tri_ids[r]
                        considered += 1
                        first = True
                        if stamping:
                            if stamps[tid] == pid:
                                first = False
                                if mailbox:
                                    skips += 1
                                    continue
                            else:
                                stamps[tid] = pid
                        ax = float(tv[r, 0]); ay = float(tv[r, 1]); az = float(tv[r, 2])
                        bx = float(tv[r, 3]); by = float(tv[r, 4]); bz = float(tv[r, 5])
                        cx = float(tv[r, 6]); cy = float(tv[r, 7]); cz = float(tv[r, 8])
                        out = False
                        if cull or counting:
                            va = (ax, ay, az)
                            vb = (bx, by, bz)
                            vc = (cx, cy, cz)
                            k0 = sig * ((va[K] - gp[K]) * gp[6 + K] - P0)
                            k1 = sig * ((vb[K] - gp[K]) * gp[6 + K] - P0)
                            k2 = sig * ((vc[K] - gp[K]) * gp[6 + K] - P0)
                            out = _plane_cull((va[U] - gp[U]) * gp[6 + U], (vb[U] - gp[U]) * gp[6 + U],
                                              (vc[U] - gp[U]) * gp[6 + U], k0, k1, k2, alo_u, slo_u, ahi_u, shi_u)
                            if not out:
                                out = _plane_cull((va[V] - gp[V]) * gp[6 + V], (vb[V] - gp[V]) * gp[6 + V],
                                                  (vc[V] - gp[V]) * gp[6 + V], k0, k1, k2, alo_v, slo_v, ahi_v, shi_v)
                            if not out and edge:
                                o3 = (ox0, oy0, oz0)
                                w0k = va[K] - o3[K]; w0u = va[U] - o3[U]; w0v = va[V] - o3[V]
                                w1k = vb[K] - o3[K]; w1u = vb[U] - o3[U]; w1v = vb[V] - o3[V]
                                w2k = vc[K] - o3[K]; w2u = vc[U] - o3[U]; w2v = vc[V] - o3[V]
                                # edge normals in the cyclic (K, U, V) frame
                                n0k = w0u * w1v - w0v * w1u; n0u = w0v * w1k - w0k * w1v; n0v = w0k * w1u - w0u * w1k
                                n1k = w1u * w2v - w1v * w2u; n1u = w1v * w2k - w1k * w2v; n1v = w1k * w2u - w1u * w2k
                                n2k = w2u * w0v - w2v * w0u; n2u = w2v * w0k - w2k * w0v; n2v = w2k * w0u - w2u * w0k
                                side = n0k * w2k + n0u * w2u + n0v * w2v
                                mag = ((abs(w0k) + abs(w0u) + abs(w0v)) * (abs(w1k) + abs(w1u) + abs(w1v))
                                       * (abs(w2k) + abs(w2u) + abs(w2v)))
                                if abs(side) > CULL_REL * mag:
                                    out = (_edge_out(n0k, n0u, n0v, sig, ru, rv, slo_u, shi_u, slo_v, shi_v, side)
                                           or _edge_out(n1k, n1u, n1v, sig, ru, rv, slo_u, shi_u, slo_v, shi_v, side)
                                           or _edge_out(n2k, n2u, n2v, sig, ru, rv, slo_u, shi_u, slo_v, shi_v, side))
                            if counting and first:
                                uniq += 1
                                if not out:
                                    uniq_nc += 1
                            if cull and out:
                                skips += 1
                                culled += 1
                                continue
                        tested += 1
                        _test_tri(n, common, pox, poy, poz, pdx, pdy, pdz, pdd, best, bid, tid,
                                  ax, ay, az, bx, by, bz, cx, cy, cz, tmin)
                        changed = True
            if changed:  # the last slice any ray still needs
                nl_max = -1
                for q in range(n):
                    if bid[q] >= 0:
                        if anyhit:
                            continue
                        tl = best[q]
                    else:
                        tl = pt1[q]
                    nl = int(math.floor(pko[q] + tl * pkd[q] + EPS))
                    nl_max = max(nl_max, nl)
                nlast = min(nl_max, nmax)
            s += 1
        for q in range(n):
            i = idx[q]
            if bid[q] >= 0:
                out_t[i] = np.float32(best[q])
                out_id[i] = bid[q]
    # ---- single-ray fallback: the uniform grid's own kernel
    s_steps = 0
    s_tests = 0
    for q in range(ns):
        i = single[q]
        t, tid, su_, st_, te_, sk_, ju_ = grid_ray(
            float(O[i, 0]), float(O[i, 1]), float(O[i, 2]), float(D[i, 0]), float(D[i, 1]), float(D[i, 2]),
            tmin, float(tmax[i]), anyhit, gp, nxg, nyg, nzg, cell_start, tri_ids, tv, None, 0, None, 0)
        out_t[i] = np.float32(t)
        out_id[i] = tid
        s_steps += st_
        s_tests += te_
        if counters is not None:
            counters[i, 0] = su_
            counters[i, 1] = st_
            counters[i, 2] = te_
            counters[i, 3] = 0
            counters[i, 4] = sk_
    if counters is not None and n > 0:
        _spread(counters, n, 0, 1, idx)
        _spread(counters, n, 1, cells, idx)
        _spread(counters, n, 3, slices, idx)
        _spread(counters, n, 4, skips, idx)
        for q in range(n):
            counters[idx[q], 2] = tested
    if pc is not None:
        pc[p, 0] = e - b
        pc[p, 1] = ns
        pc[p, 2] = slices
        pc[p, 3] = cells + s_steps
        pc[p, 4] = considered + s_tests
        pc[p, 5] = considered * n + s_tests
        pc[p, 6] = uniq * n + s_tests
        pc[p, 7] = uniq_nc * n + s_tests
        pc[p, 8] = tested * n + s_tests
        pc[p, 9] = mskips
        pc[p, 10] = culled
    return n


@pjit
def cgt_trace(O, D, tmin, tmax, anyhit, k2, gp, res, cell_start, tri_ids, tv, macro, M,
              mailbox, cull, W, I, stamps, out_t, out_id, counters, pc):
    """Batched coherent grid traversal, ``prange`` over packets of ``k2`` consecutive rays.
    ``W``/``I``/``stamps`` are per-thread work arrays; ``counters``/``pc`` arrays or None (None
    compiles the variant without counting code); ``macro`` the occupancy of M^3 blocks or None."""
    m = O.shape[0]
    npk = (m + k2 - 1) // k2
    for p in prange(npk):
        thr = numba.get_thread_id()
        _packet(p * k2, min(m, (p + 1) * k2), O, D, tmin, tmax, anyhit, gp, res, cell_start, tri_ids, tv,
                macro, M, mailbox, cull, p, stamps[thr], W[thr], I[thr], out_t, out_id, counters, pc, p)


# ---------------------------------------------------------------- structure
class CoherentGrid(Accel):
    """Wald et al. 2006 coherent grid traversal over a uniform grid of n_x = d_x (lam N / V)^(1/3).

    ``packet`` k: packets are k x k = consecutive groups of k^2 rays (order camera rays with
    ``camera_rays(..., tile=k)``). ``macro`` M: macrocells of M^3 cells (0 = off). ``mailbox`` and
    ``frustum_cull`` switch per-packet mailboxing and frustum culling. ``exact`` selects exact
    triangle/cell overlap in the build (the paper inserts by bounding box: False). ``res``
    overrides the resolution (e.g. to share a single-ray grid's).
    """

    name = "cgt"

    def __init__(self, lam=WALD_LAMBDA, packet=8, macro=WALD_MACROCELL, mailbox=True, frustum_cull=True,
                 exact=False, res=None):
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
        ncell = int(np.prod(res))
        check_budget(f"a {res[0]}x{res[1]}x{res[2]} grid ({ncell:,} cells) of {scene.name}",
                     (ncell + 1) * 4 + scene.n * 40 * 2)
        t_start = time.perf_counter()
        gp = grid_params(scene.bounds, res)
        nx, ny, nz = (int(r) for r in res)
        cell_start = np.zeros(ncell + 1, dtype=np.int64)
        refs = grid_assign(scene.tris, gp, nx, ny, nz, self.exact, cell_start, np.zeros(0, np.int32), False)
        check_budget(f"a grid with {refs:,} triangle references over {ncell:,} cells of {scene.name}",
                     (ncell + 1) * 4 + refs * 40)
        if refs >= 2**31:
            raise GridcostError(f"{refs:,} triangle references exceed the int32 index range")
        np.cumsum(cell_start, out=cell_start)
        tri_ids = np.empty(refs, dtype=np.int32)
        grid_assign(scene.tris, gp, nx, ny, nz, self.exact, cell_start, tri_ids, True)
        self.cell_start_ = cell_start.astype(np.int32)
        self.tri_ids_ = tri_ids
        self.tri_verts_ = np.ascontiguousarray(scene.tris.reshape(-1, 9)[tri_ids])
        self.macro_ = macro_occupancy(self.cell_start_, res, self.macro) if self.macro else None
        self.build_seconds_ = time.perf_counter() - t_start
        self.res_, self.gp_, self.n_, self.refs_ = res, gp, scene.n, refs
        self.scene_name_ = scene.name
        return self

    def _run(self, o, d, tmin, tmax, anyhit, counters, pc):
        m = len(o)
        k2 = self.packet * self.packet
        nthr = numba.config.NUMBA_NUM_THREADS
        out_t = np.empty(m, np.float32)
        out_id = np.empty(m, np.int32)
        W = np.empty((nthr, _NW, k2), np.float64)
        I = np.empty((nthr, 3, k2), np.int32)
        stamps = np.full((nthr, max(self.n_, 1)), -1, np.int32)
        cgt_trace(o, d, tmin, tmax, anyhit, k2, self.gp_, self.res_, self.cell_start_, self.tri_ids_,
                  self.tri_verts_, self.macro_, max(self.macro, 1), self.mailbox, self.frustum_cull,
                  W, I, stamps, out_t, out_id, counters, pc)
        return out_t, out_id

    def _trace(self, o, d, tmin, tmax, anyhit, count):
        cnt = np.zeros((len(o), NCOUNT), np.int32) if count else None
        pc = np.zeros(((len(o) + self.packet**2 - 1) // self.packet**2, NPC), np.int64) if count else None
        out_t, out_id = self._run(o, d, tmin, tmax, anyhit, cnt, pc)
        self.last_packet_counters_ = pc
        return out_t, out_id, cnt

    def packet_counters(self, origins, directions, tmin: float = 0.0, tmax=None) -> dict:
        """Per-packet work of one closest-hit trace: a dict of int64 arrays (one entry per packet)
        named by :data:`PACKET_COUNTERS` (tests_* in ray-triangle tests), plus ``hits``."""
        from tracer.accel import Hits, as_rays, tmax_array
        o, d = as_rays(origins, directions)
        t, ids, _ = self._trace(o, d, float(tmin), tmax_array(tmax, len(o)), False, True)
        pc = self.last_packet_counters_
        out = {name: pc[:, k].copy() for k, name in enumerate(PACKET_COUNTERS)}
        out["hits"] = Hits(t, ids)
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
