"""Four-lane float32 operations that Numba does not vectorise by itself, as LLVM vector IR
(:func:`numba.extending.intrinsic`): the slab test of the four (eight) child boxes of a 4-wide (8-wide)
BVH node, the bit counts of its hit mask, and a cache-line prefetch.

Numba compiles the four box tests of :func:`tracer.accel.bvh4.bvh4_chunk` written as a loop to 48 scalar
subtractions and multiplications and 24 scalar min/max (``vsubss``/``vmulss``/``vmaxss``: LLVM's
SLP vectoriser does not combine them across the loop's stores). :func:`slab4` does the same
arithmetic on ``<4 x float>`` vectors: the same float32 operations in the same order, per lane, so
each lane's distances and hit bit are bit-identical to the scalar code (fastmath stays off: no
reassociation, no fused multiply-add), including its NaN rule (a NaN plane distance, 0 x inf, is
ignored: ``select(a > t, a, t)`` keeps ``t``).
"""
from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

_F32 = ir.FloatType()
_I32 = ir.IntType(32)


def _slab_codegen(width, quant=False):
    """Codegen of the ``width``-lane slab test (see :func:`slab4`); ``quant``: the planes are bytes
    decoded as ``g + q s`` per axis (see :func:`slabq8`)."""
    vt = ir.VectorType(_F32, width)

    def splat(builder, x):
        v = builder.insert_element(ir.Constant(vt, ir.Undefined), x, _I32(0))
        return builder.shuffle_vector(v, ir.Constant(vt, ir.Undefined), ir.Constant(ir.VectorType(_I32, width), [0] * width))

    def codegen(context, builder, signature, args):
        if quant:
            (anf, abase, anxo, afxo, anyo, afyo, anzo, afzo, agx, agy, agz, asx, asy, asz, aox, aoy, aoz,
             ajx, ajy, ajz, atlo, athi, atol, at4) = args
        else:
            (anf, abase, anxo, afxo, anyo, afyo, anzo, afzo, aox, aoy, aoz, ajx, ajy, ajz, atlo, athi, atol,
             at4) = args
            agx = agy = agz = asx = asy = asz = None
        ary = context.make_array(signature.args[0])(context, builder, anf)
        out = context.make_array(signature.args[-1])(context, builder, at4)
        vptr = vt.as_pointer()

        def planes(off, g, sc):
            p = builder.gep(ary.data, [builder.add(abase, off)])
            if not quant:
                return builder.load(builder.bitcast(p, vptr), align=4)
            # W bytes -> float32 lanes, then g + q * s: float32 multiply, then add (no fused
            # multiply-add: the build checks the same two roundings, wide_quant.quantize)
            q = builder.load(builder.bitcast(p, ir.VectorType(ir.IntType(8), width).as_pointer()), align=1)
            return builder.fadd(splat(builder, g), builder.fmul(builder.uitofp(q, vt), splat(builder, sc)))

        def dist(off, o, j, g, sc):
            return builder.fmul(builder.fsub(planes(off, g, sc), splat(builder, o)), splat(builder, j))

        def gt(t, a):  # a if a > t else t
            return builder.select(builder.fcmp_ordered(">", a, t), a, t)

        def lt(t, a):  # a if a < t else t
            return builder.select(builder.fcmp_ordered("<", a, t), a, t)

        tn = gt(gt(gt(splat(builder, atlo), dist(anxo, aox, ajx, agx, asx)), dist(anyo, aoy, ajy, agy, asy)),
                dist(anzo, aoz, ajz, agz, asz))
        tf = lt(lt(lt(splat(builder, athi), dist(afxo, aox, ajx, agx, asx)), dist(afyo, aoy, ajy, agy, asy)),
                dist(afzo, aoz, ajz, agz, asz))
        hit = builder.fcmp_ordered("<=", tn, builder.fadd(tf, splat(builder, atol)))
        builder.store(tn, builder.bitcast(out.data, vptr), align=4)
        bits = builder.bitcast(hit, ir.IntType(width))
        return builder.zext(bits, ir.IntType(64))

    return codegen


@intrinsic
def slab4(typingctx, nf, base, nxo, fxo, nyo, fyo, nzo, fzo, ox, oy, oz, jx, jy, jz, tlo, thi, tol, t4):
    """``slab4(nf, base, nxo, fxo, nyo, fyo, nzo, fzo, ox, oy, oz, jx, jy, jz, tlo, thi, tol, t4)``
    -> int64 hit mask (bit k: box k met) of the four boxes whose planes are the float32 words
    ``nf[base + off + 0..3]`` (``off``: the near / far plane offsets on x, y, z); all scalars
    float32. Per lane: entry = max(tlo, (near_x - ox) jx, (near_y - oy) jy, (near_z - oz) jz),
    exit = min(thi, (far_x - ox) jx, …), each max/min ``select(a > t, a, t)`` in that order; hit =
    entry <= exit + tol. The four entries are stored into ``t4`` (float32[4])."""
    sig = types.int64(nf, base, nxo, fxo, nyo, fyo, nzo, fzo, ox, oy, oz, jx, jy, jz, tlo, thi, tol, t4)
    return sig, _slab_codegen(4)


@intrinsic
def slab8(typingctx, nf, base, nxo, fxo, nyo, fyo, nzo, fzo, ox, oy, oz, jx, jy, jz, tlo, thi, tol, t8):
    """:func:`slab4` on eight boxes (``<8 x float>``, one AVX2 register): planes ``nf[base + off + 0..7]``,
    entries into ``t8`` (float32[8]), an 8-bit mask."""
    sig = types.int64(nf, base, nxo, fxo, nyo, fyo, nzo, fzo, ox, oy, oz, jx, jy, jz, tlo, thi, tol, t8)
    return sig, _slab_codegen(8)


@intrinsic
def slabq4(typingctx, nb, base, nxo, fxo, nyo, fyo, nzo, fzo, gx, gy, gz, sx, sy, sz, ox, oy, oz, jx, jy, jz,
           tlo, thi, tol, t4):
    """:func:`slab4` on quantised boxes: plane ``off`` of box k is the byte ``q = nb[base + off + k]``
    (uint8) decoded as ``g + float32(q) * s`` with the axis' origin ``g`` and step ``s`` (float32
    multiply, then add), then tested exactly as :func:`slab4` tests float32 planes."""
    sig = types.int64(nb, base, nxo, fxo, nyo, fyo, nzo, fzo, gx, gy, gz, sx, sy, sz, ox, oy, oz, jx, jy, jz,
                      tlo, thi, tol, t4)
    return sig, _slab_codegen(4, quant=True)


@intrinsic
def slabq8(typingctx, nb, base, nxo, fxo, nyo, fyo, nzo, fzo, gx, gy, gz, sx, sy, sz, ox, oy, oz, jx, jy, jz,
           tlo, thi, tol, t8):
    """:func:`slabq4` on eight boxes."""
    sig = types.int64(nb, base, nxo, fxo, nyo, fyo, nzo, fzo, gx, gy, gz, sx, sy, sz, ox, oy, oz, jx, jy, jz,
                      tlo, thi, tol, t8)
    return sig, _slab_codegen(8, quant=True)


@intrinsic
def ctz(typingctx, x):
    """Index of the lowest set bit of the int64 ``x`` (``x`` != 0): LLVM's ``cttz`` (one ``tzcnt``)."""
    sig = types.int64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.cttz(args[0], ir.Constant(ir.IntType(1), 1))

    return sig, codegen


@intrinsic
def popc(typingctx, x):
    """Set bits of the int64 ``x``: LLVM's ``ctpop`` (one ``popcnt``)."""
    sig = types.int64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.ctpop(args[0])

    return sig, codegen


@intrinsic
def prefetch(typingctx, arr, idx):
    """``prefetch(a, i)``: hint the CPU to load the cache line of ``a.ravel()[i]`` (LLVM's
    ``llvm.prefetch``, read, high locality). Never faults, also for an index past the end."""
    sig = types.void(arr, idx)

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        ptr = builder.bitcast(builder.gep(ary.data, [args[1]]), ir.IntType(8).as_pointer())
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [ptr.type, i32, i32, i32]), "llvm.prefetch.p0")
        builder.call(fn, [ptr, i32(0), i32(3), i32(1)])
        return context.get_dummy_value()
    return sig, codegen
