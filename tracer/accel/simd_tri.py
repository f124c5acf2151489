"""One ray against four triangles at once: :func:`tracer.accel.geometry.ray_triangle` on ``<4 x double>``
LLVM vectors (:func:`numba.extending.intrinsic`), for leaves whose triangles are stored four at a time.

Numba does not vectorise the scalar test across the triangles of a leaf (each test ends in data-dependent
branches). :func:`ray_tri4` does, lane by lane, exactly the float64 operations of ``ray_triangle`` in
the same order (float32 vertices widened with ``fpext``, exact like ``np.float64``; no fused
multiply-add: the IR carries no fast-math or ``contract`` flags; the parallel test's constant is
``geometry._PAR2`` itself), so each lane's t is bit-identical to the scalar test's and the oracle's.
The scalar test's early returns become lane masks, each with the scalar comparison's NaN rule: the
grazing test rejects on ``det*det <= ...`` (ordered), the edge tests reject on ordered ``<`` / ``>``,
the range test accepts on ordered ``t > tmin and t < tmax``.

Leaf layout (SoA, one block of four triangles = 36 float32 words): ``[ax0..3, ay0..3, az0..3, bx0..3,
by0..3, bz0..3, cx0..3, cy0..3, cz0..3]``. A leaf of fewer than four triangles is padded with
degenerate ones (all three vertices equal): their edges and normal are exactly 0, so ``det*det <=
0`` rejects them in every case, as ``ray_triangle`` rejects a degenerate triangle.

Closest hit of a block, as the scalar loop ``for r in leaf: t = ray_triangle(..., tmin, best); if t
< best: best = t`` finds it: the lanes hit within (tmin, tmax), the smallest t, ties to the lowest
lane (the scalar loop keeps the first of equal t, since a later equal t is not < best).
"""
from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from tracer.accel.geometry import _PAR2

_F32 = ir.FloatType()
_F64 = ir.DoubleType()
_I32 = ir.IntType(32)
_V4F = ir.VectorType(_F32, 4)
_V4D = ir.VectorType(_F64, 4)

#: float32 words of one block of four triangles
TRI4_WORDS = 36


def _splat(builder, x):
    v = builder.insert_element(ir.Constant(_V4D, ir.Undefined), x, _I32(0))
    return builder.shuffle_vector(v, ir.Constant(_V4D, ir.Undefined), ir.Constant(ir.VectorType(_I32, 4), [0, 0, 0, 0]))


@intrinsic
def ray_tri4(typingctx, tri, base, ox, oy, oz, dx, dy, dz, tmin, tmax, t4):
    """``ray_tri4(tri, base, ox, oy, oz, dx, dy, dz, tmin, tmax, t4)`` -> int64 hit mask (bit k: lane k
    hit in (tmin, tmax)) of the block of four triangles at float32 words ``tri[base:base + 36]``
    (layout in the module docstring; ``base`` unsigned). Ray and limits float64. Each lane's t (inf
    where the lane misses) is stored into ``t4`` (float64[4]); a hit lane's t equals
    ``ray_triangle``'s bit for bit."""
    sig = types.int64(tri, base, ox, oy, oz, dx, dy, dz, tmin, tmax, t4)

    def codegen(context, builder, signature, args):
        atri, abase, aox, aoy, aoz, adx, ady, adz, atmin, atmax, at4 = args
        ary = context.make_array(signature.args[0])(context, builder, atri)
        out = context.make_array(signature.args[10])(context, builder, at4)
        b = builder

        def vert(k):  # word group k (0..8) of the block, widened exactly to float64
            p = b.gep(ary.data, [b.add(abase, ir.Constant(abase.type, 4 * k))])
            return b.fpext(b.load(b.bitcast(p, _V4F.as_pointer()), align=4), _V4D)

        ax, ay, az, bx, by, bz, cx, cy, cz = (vert(k) for k in range(9))
        ox, oy, oz, dx, dy, dz = (_splat(b, x) for x in (aox, aoy, aoz, adx, ady, adz))
        mul, sub, add = b.fmul, b.fsub, b.fadd
        e1x, e1y, e1z = sub(bx, ax), sub(by, ay), sub(bz, az)
        e2x, e2y, e2z = sub(cx, ax), sub(cy, ay), sub(cz, az)
        nx = sub(mul(e1y, e2z), mul(e1z, e2y))
        ny = sub(mul(e1z, e2x), mul(e1x, e2z))
        nz = sub(mul(e1x, e2y), mul(e1y, e2x))
        det = add(add(mul(dx, nx), mul(dy, ny)), mul(dz, nz))
        nn = add(add(mul(nx, nx), mul(ny, ny)), mul(nz, nz))
        dd = add(add(mul(dx, dx), mul(dy, dy)), mul(dz, dz))
        par2 = _splat(b, ir.Constant(_F64, _PAR2))
        grazing = b.fcmp_ordered("<=", mul(det, det), mul(mul(par2, nn), dd))
        sx, sy, sz = sub(ax, ox), sub(ay, oy), sub(az, oz)
        rx = sub(mul(dy, sz), mul(dz, sy))
        ry = sub(mul(dz, sx), mul(dx, sz))
        rz = sub(mul(dx, sy), mul(dy, sx))
        un = b.fneg(add(add(mul(e2x, rx), mul(e2y, ry)), mul(e2z, rz)))
        vn = add(add(mul(e1x, rx), mul(e1y, ry)), mul(e1z, rz))
        zero = ir.Constant(_V4D, [0.0] * 4)
        uv = add(un, vn)
        out_pos = b.or_(b.or_(b.fcmp_ordered("<", un, zero), b.fcmp_ordered("<", vn, zero)),
                        b.fcmp_ordered(">", uv, det))
        out_neg = b.or_(b.or_(b.fcmp_ordered(">", un, zero), b.fcmp_ordered(">", vn, zero)),
                        b.fcmp_ordered("<", uv, det))
        outside = b.select(b.fcmp_ordered(">", det, zero), out_pos, out_neg)
        t = b.fdiv(add(add(mul(sx, nx), mul(sy, ny)), mul(sz, nz)), det)
        inside = b.and_(b.fcmp_ordered(">", t, _splat(b, atmin)), b.fcmp_ordered("<", t, _splat(b, atmax)))
        hit = b.and_(b.and_(b.not_(grazing), b.not_(outside)), inside)
        inf = ir.Constant(_V4D, [float("inf")] * 4)
        b.store(b.select(hit, t, inf), b.bitcast(out.data, _V4D.as_pointer()), align=8)
        return b.zext(b.bitcast(hit, ir.IntType(4)), ir.IntType(64))

    return sig, codegen
