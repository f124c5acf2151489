"""Building blocks of the coherent grid traversal's packet loop (:func:`tracer.accel.packet._packets`,
see :mod:`tracer.accel.packet` for the algorithm): the per-thread work-array layout, the branch-free
ray-packet/triangle test on LLVM vectors of LANES rays, the frustum (bounds of the packet and of each group of
LANES slots, cell ranges, which rays still need slices) and frustum culling (planes, then corner
rays against the triangle's edges; then the groups' own frusta).
"""
from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from tracer.accel._jit import jit, ray_jit
from tracer.accel.geometry import INF, PARALLEL_COS
from tracer.accel.simd import prefetch
from tracer.measure.footprint import CGT_ROW_BYTES

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
# rows of the per-thread int work array (_NT: the ray-triangle tests the slot's ray took part in)
_BID, _IDX, _SINGLE, _NL, _NT = range(5)
#: first row of the group frusta (8 rows: :func:`_frustum`) in the float work array
_GB = _NW
_NI = 5
#: references gathered and mailboxed at a time before their tests (:func:`_gather`)
BATCH = 256
# rows of the per-thread reference-list array: references gathered, kept triangle ids, first-visit flags
_RL, _TL, _FL = range(3)
#: the ray loop of a triangle test runs over a multiple of this many rays (SIMD width in doubles);
#: the group frusta (:func:`_frustum`) bound groups of this many slots, one vector each
LANES = 8
#: a packet grid's triangle row (float32, ROW columns = one 64-byte line): the 9 vertex coordinates,
#: then from column BOX the grid-space box (:func:`ref_boxes`), so the box test and the vertex loads
#: that follow it read one line
BOX = 9
ROW = CGT_ROW_BYTES // 4  # the footprint estimate's row size (tracer.measure.footprint), in float32


def _tri8_codegen(common):
    """Codegen of :func:`_tri8c` (``common``: one origin, s = a - o and s.n given) or :func:`_tri8o`
    (each lane's own origin): the rays in slots [lo, lo + LANES) of the work arrays against one
    triangle on ``<LANES x double>`` LLVM vectors, ray_triangle's float64 expressions in its order
    without branches (no fast-math or ``contract`` flags, so no fused multiply-add: a hit lane's t is
    bit-identical to ray_triangle's); its early returns become lane masks with the scalar
    comparisons' NaN rule (ordered compares). Hit lanes get t in W[_BEST] and the triangle id in
    I[_BID] (a blend: the other lanes keep theirs); returns the number of hit lanes."""
    vd = ir.VectorType(ir.DoubleType(), LANES)
    vi = ir.VectorType(ir.IntType(32), LANES)
    i32 = ir.IntType(32)

    def codegen(context, builder, signature, args):
        b = builder
        aW, aI, alo, atri, atid = args
        W = context.make_array(signature.args[0])(context, b, aW)
        I = context.make_array(signature.args[1])(context, b, aI)

        def row(arr, r, vt):  # arr[r, lo:lo + LANES] as a pointer to a vector
            p = cgutils.get_item_pointer2(context, b, arr.data, cgutils.unpack_tuple(b, arr.shape),
                                          cgutils.unpack_tuple(b, arr.strides), "C",
                                          [ir.Constant(alo.type, r), alo])
            return b.bitcast(p, vt.as_pointer())

        def splat(x, vt=vd):
            v = b.insert_element(ir.Constant(vt, ir.Undefined), x, i32(0))
            return b.shuffle_vector(v, ir.Constant(vt, ir.Undefined), ir.Constant(vi, [0] * LANES))

        mul, sub, add, cmp = b.fmul, b.fsub, b.fadd, b.fcmp_ordered
        ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, p2nn, tmin = (
            splat(b.extract_value(atri, k)) for k in range(14))
        dx, dy, dz, dd = (b.load(row(W, r, vd), align=8) for r in (_DX, _DY, _DZ, _DD))
        pbest = row(W, _BEST, vd)
        best = b.load(pbest, align=8)
        if common:  # the first three are s = a - o, the 15th s.n
            sx, sy, sz = ax, ay, az
            sn = splat(b.extract_value(atri, 14))
        else:
            sx, sy, sz = (sub(a, b.load(row(W, r, vd), align=8)) for a, r in ((ax, _OX), (ay, _OY), (az, _OZ)))
            sn = add(add(mul(sx, nx), mul(sy, ny)), mul(sz, nz))
        det = add(add(mul(dx, nx), mul(dy, ny)), mul(dz, nz))
        rx = sub(mul(dy, sz), mul(dz, sy))
        ry = sub(mul(dz, sx), mul(dx, sz))
        rz = sub(mul(dx, sy), mul(dy, sx))
        un = b.fneg(add(add(mul(e2x, rx), mul(e2y, ry)), mul(e2z, rz)))
        vn = add(add(mul(e1x, rx), mul(e1y, ry)), mul(e1z, rz))
        t = b.fdiv(sn, det)
        zero = ir.Constant(vd, [0.0] * LANES)
        uv = add(un, vn)
        pos = b.and_(b.and_(b.and_(cmp(">", det, zero), cmp(">=", un, zero)), cmp(">=", vn, zero)), cmp("<=", uv, det))
        neg = b.and_(b.and_(b.and_(cmp("<=", det, zero), cmp("<=", un, zero)), cmp("<=", vn, zero)), cmp(">=", uv, det))
        hit = b.and_(b.and_(b.and_(cmp(">", mul(det, det), mul(p2nn, dd)), b.or_(pos, neg)), cmp(">", t, tmin)),
                     cmp("<", t, best))
        b.store(b.select(hit, t, best), pbest, align=8)
        pid = row(I, _BID, vi)
        b.store(b.select(hit, splat(atid, vi), b.load(pid, align=4)), pid, align=4)
        m = b.bitcast(hit, ir.IntType(LANES))
        cnt = b.call(b.module.declare_intrinsic("llvm.ctpop", [ir.IntType(LANES)]), [m])
        return b.zext(cnt, ir.IntType(64))

    return codegen


@intrinsic
def _tri8c(typingctx, W, I, lo, tri, tid):
    """``_tri8c(W, I, lo, tri, tid)``: rays with a common origin in slots [lo, lo + LANES) against one
    triangle; ``tri`` = (s, e1, e2, n, p2nn, tmin, s.n) as 15 float64 (s = a - o; p2nn =
    PARALLEL_COS^2 n.n); ``tid`` int32."""
    return types.int64(W, I, lo, tri, tid), _tri8_codegen(True)


@intrinsic
def _tri8o(typingctx, W, I, lo, tri, tid):
    """``_tri8o(W, I, lo, tri, tid)``: as :func:`_tri8c`, each ray with its own origin;
    ``tri`` = (a, e1, e2, n, p2nn, tmin) as 14 float64."""
    return types.int64(W, I, lo, tri, tid), _tri8_codegen(False)


@intrinsic
def _ctz(typingctx, m):
    """``_ctz(m)``: the index of the lowest set bit of the int64 ``m`` (m != 0)."""
    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        f = builder.module.declare_intrinsic("llvm.cttz", [i64], ir.FunctionType(i64, [i64, ir.IntType(1)]))
        return builder.call(f, [args[0], ir.Constant(ir.IntType(1), 1)])
    return types.int64(types.int64), codegen


@ray_jit
def _test_tri(n, cull, GB, box, groups, common, W, I, tid, ax, ay, az, bx, by, bz, cx, cy, cz, tmin, counting):
    """Rays [0, n) of the packet against one triangle (float64 vertices; ``box`` its grid-space box,
    :func:`_ref_box`), a group of LANES slots at a time (:func:`_tri8c`, :func:`_tri8o`);
    with ``cull`` only the groups :func:`_groups` leaves (``groups``: the caller's mask of the first
    64, so that a triangle no group meets is dropped before its vertices are loaded). The
    ray-independent terms are hoisted (with a common origin also s = a - o and s.n). Returns (lanes
    that hit, lanes tested, real rays tested); ``counting`` adds a test to each real ray's I[_NT].
    Slots past n hold retired or unused rays, whose results are never read. Why explicit vectors:
    LLVM vectorises a plain loop over the lanes only when it runs over a whole packet, not over the
    few groups the group frusta leave (it unrolled or kept those scalar: 5-8 ns per lane instead of 3)."""
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
    tid = np.int32(tid)
    sx = ax - W[_OX, 0]
    sy = ay - W[_OY, 0]
    sz = az - W[_OZ, 0]
    tric = (sx, sy, sz, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, p2nn, tmin, sx * nx + sy * ny + sz * nz)
    trio = (ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z, nx, ny, nz, p2nn, tmin)
    nh = 0
    lanes = 0
    real = 0
    for b0 in range(0, (n + LANES - 1) // LANES, 64):  # blocks of 64 groups (one bitmask each)
        if b0 > 0:
            groups = _groups(n, cull, GB, box, b0)
        while groups != 0:
            i = (b0 + _ctz(groups)) * LANES
            groups &= groups - 1
            if common:
                nh += _tri8c(W, I, i, tric, tid)
            else:
                nh += _tri8o(W, I, i, trio, tid)
            lanes += LANES
            real += min(n, i + LANES) - i
            if counting:
                for q in range(i, min(n, i + LANES)):
                    I[_NT, q] += 1
    return nh, lanes, real


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
def _frustum(n, W, GB):
    """The frustum of rays [0, n): u in [alo_u + slo_u k', ahi_u + shi_u k'], same for v; and the
    same eight bounds of each group of LANES slots in GB[:, g] (rows in that order). ``_min(x, acc)``
    keeps the builtin ``min(acc, x)``'s rule (a NaN x is passed over) as a select LLVM vectorises."""
    for g in range((n + LANES - 1) // LANES):
        alo_u = slo_u = alo_v = slo_v = INF
        ahi_u = shi_u = ahi_v = shi_v = -INF
        for q in range(g * LANES, min(n, g * LANES + LANES)):
            alo_u = _min(W[_AU, q], alo_u); ahi_u = _max(W[_AU, q], ahi_u)
            alo_v = _min(W[_AV, q], alo_v); ahi_v = _max(W[_AV, q], ahi_v)
            slo_u = _min(W[_SU, q], slo_u); shi_u = _max(W[_SU, q], shi_u)
            slo_v = _min(W[_SV, q], slo_v); shi_v = _max(W[_SV, q], shi_v)
        GB[0, g] = alo_u; GB[1, g] = ahi_u; GB[2, g] = slo_u; GB[3, g] = shi_u
        GB[4, g] = alo_v; GB[5, g] = ahi_v; GB[6, g] = slo_v; GB[7, g] = shi_v
    alo_u = slo_u = alo_v = slo_v = INF
    ahi_u = shi_u = ahi_v = shi_v = -INF
    for g in range((n + LANES - 1) // LANES):
        alo_u = _min(GB[0, g], alo_u); ahi_u = _max(GB[1, g], ahi_u)
        slo_u = _min(GB[2, g], slo_u); shi_u = _max(GB[3, g], shi_u)
        alo_v = _min(GB[4, g], alo_v); ahi_v = _max(GB[5, g], ahi_v)
        slo_v = _min(GB[6, g], slo_v); shi_v = _max(GB[7, g], shi_v)
    return alo_u, ahi_u, slo_u, shi_u, alo_v, ahi_v, slo_v, shi_v


@ray_jit
def _frame(ax, ay, az, bx, by, bz, cx, cy, cz, K, U, V, gp, sig, P0):
    """The triangle's vertices in the packet's grid frame: k' (slices from the entry plane P0 along
    the major axis K, in the packet's direction) and u, v (cells along U, V) of each vertex."""
    va, vb, vc = (ax, ay, az), (bx, by, bz), (cx, cy, cz)
    return (sig * ((va[K] - gp[K]) * gp[6 + K] - P0), sig * ((vb[K] - gp[K]) * gp[6 + K] - P0),
            sig * ((vc[K] - gp[K]) * gp[6 + K] - P0),
            (va[U] - gp[U]) * gp[6 + U], (vb[U] - gp[U]) * gp[6 + U], (vc[U] - gp[U]) * gp[6 + U],
            (va[V] - gp[V]) * gp[6 + V], (vb[V] - gp[V]) * gp[6 + V], (vc[V] - gp[V]) * gp[6 + V])


@intrinsic
def _gmask(typingctx, GB, g0, box):
    """``_gmask(GB, g0, box)``: bitmask (int64, bit j for group g0 + j) of the groups g0 .. g0 + LANES
    - 1 whose frustum (GB[:, g], rows as :func:`_frustum` fills them) the triangle's grid-space box
    ``box`` = (u_lo, u_hi, v_lo, v_hi, k'_lo, k'_hi) does not lie outside: for each of u and v, beyond
    the lower plane u = a_lo + s_lo k' (hi - (a_lo + min(s_lo k'_lo, s_lo k'_hi)) < -EPS) or the upper
    one (lo - (a_hi + max(s_hi k'_lo, s_hi k'_hi)) > EPS). A box beyond a plane has every vertex
    beyond it, the per-vertex test of :func:`_plane_cull`, whose margin keeps every hit. One
    ``<LANES x double>`` vector per frustum row, ordered compares (a NaN keeps the group); the caller
    clears bits of groups past the packet's last."""
    vd = ir.VectorType(ir.DoubleType(), LANES)
    vi = ir.VectorType(ir.IntType(32), LANES)
    i32 = ir.IntType(32)

    def codegen(context, builder, signature, args):
        b = builder
        aG, ag0, abox = args
        G = context.make_array(signature.args[0])(context, b, aG)

        def row(r):
            p = cgutils.get_item_pointer2(context, b, G.data, cgutils.unpack_tuple(b, G.shape),
                                          cgutils.unpack_tuple(b, G.strides), "A", [ir.Constant(ag0.type, r), ag0])
            return b.load(b.bitcast(p, vd.as_pointer()), align=8)

        def splat(x):
            v = b.insert_element(ir.Constant(vd, ir.Undefined), x, i32(0))
            return b.shuffle_vector(v, ir.Constant(vd, ir.Undefined), ir.Constant(vi, [0] * LANES))

        ul, uh, vl, vh, kl, kh = (splat(b.extract_value(abox, k)) for k in range(6))
        mul, add, sub, cmp = b.fmul, b.fadd, b.fsub, b.fcmp_ordered

        def vmin(x, y):
            return b.select(cmp("<", x, y), x, y)

        def vmax(x, y):
            return b.select(cmp(">", x, y), x, y)

        eps = ir.Constant(vd, [EPS] * LANES)
        neps = ir.Constant(vd, [-EPS] * LANES)
        out = None
        for r0, lo, hi in ((0, ul, uh), (4, vl, vh)):
            alo, ahi, slo, shi = row(r0), row(r0 + 1), row(r0 + 2), row(r0 + 3)
            below = cmp("<", sub(hi, add(alo, vmin(mul(slo, kl), mul(slo, kh)))), neps)
            above = cmp(">", sub(lo, add(ahi, vmax(mul(shi, kl), mul(shi, kh)))), eps)
            o = b.or_(below, above)
            out = o if out is None else b.or_(out, o)
        keep = b.xor(out, ir.Constant(ir.VectorType(ir.IntType(1), LANES), [1] * LANES))
        return b.zext(b.bitcast(keep, ir.IntType(LANES)), ir.IntType(64))

    return types.int64(GB, g0, box), codegen


@ray_jit
def _verts(tv, r):
    """Triangle r's vertex row as nine float64 (ax, ay, az, bx, ...)."""
    return (np.float64(tv[r, 0]), np.float64(tv[r, 1]), np.float64(tv[r, 2]), np.float64(tv[r, 3]),
            np.float64(tv[r, 4]), np.float64(tv[r, 5]), np.float64(tv[r, 6]), np.float64(tv[r, 7]),
            np.float64(tv[r, 8]))


@ray_jit
def _ref_box(tv, r, K, U, V, sig, P0):
    """The grid-space box (u_lo, u_hi, v_lo, v_hi, k'_lo, k'_hi) of triangle r in the packet's frame
    (k' slices from the entry plane P0 in the packet's direction ``sig``, as :func:`_frame`), from
    its stored box ``tv[r, BOX:BOX + 6]`` (:func:`ref_boxes`). Rounding is monotone, so this box holds the one
    :func:`_frame`'s vertices span: the tests that use it stay conservative."""
    ka = sig * (np.float64(tv[r, BOX + 2 * K]) - P0)
    kb = sig * (np.float64(tv[r, BOX + 2 * K + 1]) - P0)
    return (np.float64(tv[r, BOX + 2 * U]), np.float64(tv[r, BOX + 2 * U + 1]), np.float64(tv[r, BOX + 2 * V]),
            np.float64(tv[r, BOX + 2 * V + 1]), min(ka, kb), max(ka, kb))


@jit
def ref_boxes(tv, gp, out):
    """Each triangle's grid-space box into ``out[r, BOX:BOX + 6]`` = (x_lo, x_hi, y_lo, y_hi, z_lo,
    z_hi) in cells (``tv``: the vertex rows, ``gp``: :func:`tracer.accel.grid.grid_params`),
    float32 rounded outward from the float64 (v - lo) * cells/extent that :func:`_frame` computes,
    so a packet tests a triangle's box against its group frusta before it reads the vertices (half or
    more of the distinct triangles a camera packet meets are culled: dragon-202k 50 % at 512², 59 %
    at 1024²)."""
    for r in range(tv.shape[0]):
        for a in range(3):
            x0 = (np.float64(tv[r, a]) - gp[a]) * gp[6 + a]
            x1 = (np.float64(tv[r, 3 + a]) - gp[a]) * gp[6 + a]
            x2 = (np.float64(tv[r, 6 + a]) - gp[a]) * gp[6 + a]
            lo = min(x0, x1, x2)
            hi = max(x0, x1, x2)
            flo = np.float32(lo)
            if np.float64(flo) > lo:
                flo = np.nextafter(flo, np.float32(-np.inf))
            fhi = np.float32(hi)
            if np.float64(fhi) < hi:
                fhi = np.nextafter(fhi, np.float32(np.inf))
            out[r, BOX + 2 * a] = flo
            out[r, BOX + 2 * a + 1] = fhi
    return out


@ray_jit
def _groups(n, cull, GB, box, b0):
    """Bitmask (bit j: group b0 + j) of the packet's groups of LANES slots among b0 .. b0 + 63 (rays
    [0, n)) the triangle whose grid-space box (:func:`_ref_box`) is ``box`` may meet: with ``cull`` the
    groups whose frustum the box does not lie outside (:func:`_gmask`), else every group. A set
    rather than one range: a triangle meets one or two blocks of an 8x8 packet, not always adjacent
    slots once retired rays are replaced."""
    ng = min((n + LANES - 1) // LANES, b0 + 64)
    if not cull:
        return -1 if ng - b0 == 64 else (1 << (ng - b0)) - 1
    m = 0
    for g0 in range(b0, ng, LANES):
        mg = _gmask(GB, g0, box)
        if ng - g0 < LANES:
            mg &= (1 << (ng - g0)) - 1
        m |= mg << (g0 - b0)
    return m


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
def _retire(q, i, W, I, out_t, out_id, counters):
    """Packet slot q (ray i) is done: write its hit, if any, and the triangle tests it took part in."""
    if I[_BID, q] >= 0:
        out_t[i] = np.float32(W[_BEST, q])
        out_id[i] = I[_BID, q]
    if counters is not None:
        counters[i, 2] = I[_NT, q]


@ray_jit
def _needs(n, anyhit, W, I):
    """After hits: a ray with a hit needs no slice past its hit's (closest hit), or none at all
    (any hit: I[_NL] = -1)."""
    for q in range(n):
        if I[_BID, q] >= 0:
            I[_NL, q] = -1 if anyhit else min(I[_NL, q], int(math.floor(W[_KO, q] + W[_BEST, q] * W[_KD, q] + EPS)))


@ray_jit
def _compact(n, s, W, I, out_t, out_id, counters):
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
        _retire(q, i, W, I, out_t, out_id, counters)
        n -= 1
        if q < n:
            for row in range(_NW):
                W[row, q] = W[row, n]
            I[_BID, q] = I[_BID, n]
            I[_IDX, q] = I[_IDX, n]
            I[_NL, q] = I[_NL, n]
            I[_NT, q] = I[_NT, n]
            I[_IDX, n] = i
    return n, retired


@ray_jit
def _shrink(n, s, W, I, GB, fr, out_t, out_id, counters):
    """Retire the rays of slots [0, n) that need no slice past ``s`` (:func:`_compact`) and return
    what the rest need: (rays left, their frustum (``fr`` when none retired), slot 0's origin (the
    common origin of the edge culling), their slice span (:func:`_span`))."""
    n, retired = _compact(n, s, W, I, out_t, out_id, counters)
    if retired and n > 0:
        fr = _frustum(n, W, GB)
    nlast, nfirst = _span(n, I)
    return n, fr, W[_OX, 0], W[_OY, 0], W[_OZ, 0], nlast, nfirst


@ray_jit
def _cells(alo, ahi, slo, shi, s0, s1, n):
    """Cells [c0, c1] (clipped to [0, n)) the frustum covers along one axis for k' in [s0, s1]."""
    lo = min(alo + slo * s0, alo + slo * s1)
    hi = max(ahi + shi * s0, ahi + shi * s1)
    return max(int(math.floor(lo - EPS)), 0), min(int(math.floor(hi + EPS)), n - 1)


@ray_jit
def _culled(ax, ay, az, bx, by, bz, cx, cy, cz, fv, K, U, V, sig, fr, edge, ox, oy, oz, ru, rv):
    """Is the triangle outside the frustum ``fr``? Planes first (``fv``: its vertices in the grid
    frame, :func:`_frame`); then, with ``edge`` (the caller's: a common origin and the triangle wider
    than EDGE_MIN cells), corner rays against the edges (common origin ``o``)."""
    alo_u, ahi_u, slo_u, shi_u, alo_v, ahi_v, slo_v, shi_v = fr
    va, vb, vc = (ax, ay, az), (bx, by, bz), (cx, cy, cz)
    k0, k1, k2, gu0, gu1, gu2, gv0, gv1, gv2 = fv
    if _plane_cull(gu0, gu1, gu2, k0, k1, k2, alo_u, slo_u, ahi_u, shi_u):
        return True
    if _plane_cull(gv0, gv1, gv2, k0, k1, k2, alo_v, slo_v, ahi_v, shi_v):
        return True
    if not edge:
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


@ray_jit
def _slice_cells(u0, u1, v0, v1, sbase, stU, stV, occb, cell_start, CL):
    """The slice's occupied cells in traversal order (v outer, u inner) into CL[:nc], with no branch
    per cell (an empty cell's entry is overwritten by the next one); each one's start entry is
    prefetched so that :func:`_gather`'s loads overlap. Returns nc."""
    nc = 0
    for iv in range(v0, v1 + 1):
        for iu in range(u0, u1 + 1):
            c = sbase + iu * stU + iv * stV
            CL[nc] = c
            nc += (occb[c >> 3] >> (c & 7)) & 1
    for k in range(nc):
        prefetch(cell_start, np.uintp(CL[k]))
    return nc


@ray_jit
def _gather(kc, rcur, rend, nc, CL, cell_start, tri_ids, tv, L, pid, stamping, mailbox, stamps):
    """The next batch of up to BATCH references of the occupied cells CL[:nc], in traversal order
    (cursor: cell CL[kc] next, references [rcur, rend) of the current cell left), then the packet's
    mailbox over the batch (``stamping``: stamp each triangle with the packet id ``pid``; a triangle
    stamped before is dropped with ``mailbox``, else kept with L[_FL] = 0). The batch's references go
    to L[_RL]; the kept ones' triangle ids and first-visit flags to L[_TL], L[_FL]. Gathering first keeps each
    phase's loads independent of the tests, so they overlap (a cell at a time, they waited on each
    other); each reference's triangle row ``tv[tid]`` (:data:`ROW`) is prefetched here, a batch ahead
    of its use, also for repeats (their line is cached: a branch costs more).
    Returns (kept, gathered, kc, rcur, rend)."""
    nr = 0
    while nr < BATCH:
        if rcur >= rend:
            if kc >= nc:
                break
            c = CL[kc]
            kc += 1
            rcur = cell_start[c]
            rend = cell_start[c + 1]
            continue
        take = min(rend - rcur, BATCH - nr)
        for k in range(take):
            L[_RL, nr + k] = rcur + k
        for k in range(0, take, 16):  # one prefetch per 64-byte line of ids
            prefetch(tri_ids, np.uintp(rcur + k))
        prefetch(tri_ids, np.uintp(rcur + take - 1))
        nr += take
        rcur += take
    nk = 0
    for k in range(nr):
        r = L[_RL, k]
        tid = tri_ids[r]
        prefetch(tv, np.uintp(tid * ROW))
        first = True
        if stamping:
            first = stamps[tid] != pid
            stamps[tid] = pid
        L[_TL, nk] = tid
        L[_FL, nk] = first
        nk += first or not mailbox
    return nk, nr, kc, rcur, rend
