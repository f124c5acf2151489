"""Quantised node layout of the wide BVH (:mod:`tracer.accel.wide_bvh`, ``boxes="quant"``): the same
tree with each child box stored as one byte per plane, as Embree's compressed nodes and tinybvh's
CWBVH do, so an 8-wide node takes 128 bytes (two cache lines) instead of 256.

Record (int32 words, W children): words 0-2 the node's origin ``g`` (float32 x, y, z), words 3-5 its
step ``s`` per axis (float32); then 6 W bytes of planes, ``[lo x, lo y, lo z, hi x, hi y, hi z]`` W
bytes each (the float layout's SoA order, a byte where it has a float); then the W child words
(an empty slot is an empty leaf, -1); then NORD orders of 3 bytes each (the float layout's order
words, 24 bits little-endian). W = 8: 32 words; W = 4: 22 words.

A plane byte q stands for ``g + float32(q) * s`` (a float32 multiply, then an add, as
:func:`tracer.accel.simd.slabq8` computes it). Lower planes are rounded down and upper planes up,
checked with those same two roundings, so each decoded box holds its float32 box: the box test
meets every child the float layout meets (and a few more), and the triangle tests, which decide t
and id, are the same. An empty slot decodes to an inverted box (lo = g + 255 s, hi = g) and its
child word is an empty leaf, so meeting it by round-off costs a visit and finds nothing.
"""
from __future__ import annotations

import numpy as np

from tracer.accel._jit import jit

#: plane bytes per axis step: q in 0..QMAX
QMAX = 255
#: header words (origin and step per axis) and bytes of one octant's order
HEADER = 6
ORDER_BYTES = 3


@jit(inline="always")
def qnode_words(width: int, nord: int) -> int:
    """int32 words of a quantised record (jitted: the kernel computes its offsets with these too)."""
    return HEADER + 6 * width // 4 + width + (nord * ORDER_BYTES + 3) // 4


@jit(inline="always")
def child_word(width: int) -> int:
    """Word offset of the child words in a quantised record."""
    return HEADER + 6 * width // 4


@jit(inline="always")
def order_byte(width: int) -> int:
    """Byte offset of the first octant's order in a quantised record."""
    return 4 * (child_word(width) + width)


def _decode(g, q, s):
    """float32 g + float32(q) * s, two roundings (never fused)."""
    return (g + q.astype(np.float32) * s).astype(np.float32)


def _steps(g, top):
    """Per node and axis a float32 step s with g + 255 s >= top after float32 rounding (0 on a flat
    axis): (top - g) / 255, widened by a margin that doubles from one float32 spacing of top until
    the rounded decode reaches top (far from the origin a step is far below that spacing)."""
    d = top.astype(np.float64) - g.astype(np.float64)
    s = (d / QMAX).astype(np.float32)
    margin = np.spacing(np.abs(top)).astype(np.float64)
    for _ in range(64):
        short = _decode(g, np.full(s.shape, QMAX, np.float32), s) < top
        if not short.any():
            return s
        s = np.where(short, np.nextafter(((d + margin) / QMAX).astype(np.float32), np.float32(np.inf)), s)
        margin = margin * 2.0
    raise AssertionError("quantisation step did not converge")


def _round(g, s, x, down: bool):
    """Per plane the byte whose decoded value is the nearest one at or below (``down``) / above x."""
    with np.errstate(divide="ignore", invalid="ignore"):
        q = (x.astype(np.float64) - g.astype(np.float64)) / s.astype(np.float64)
    q = np.where(s > 0, np.floor(q) if down else np.ceil(q), 0.0)
    q = np.clip(q, 0, QMAX).astype(np.int64)
    for _ in range(QMAX + 1):  # float32 round-off: at most a step or two
        v = _decode(g, q, s)
        bad = (v > x) & (q > 0) if down else (v < x) & (q < QMAX)
        if not bad.any():
            break
        q = np.where(bad, q - 1 if down else q + 1, q)
    v = _decode(g, q, s)
    assert (v <= x).all() if down else (v >= x).all(), "a quantised plane does not hold its box"
    return q


def quantize(nodes: np.ndarray, width: int, nord: int) -> np.ndarray:
    """The quantised records (module docstring) of the float records ``nodes`` (nodes, 7 W + nord)
    of :func:`tracer.accel.wide_bvh.collapse`."""
    W = width
    nn = len(nodes)
    rf = nodes.view(np.float32)
    lo = rf[:, :3 * W].reshape(nn, 3, W)
    hi = rf[:, 3 * W:6 * W].reshape(nn, 3, W)
    valid = np.isfinite(lo[:, 0, :])                                  # empty slots: lo = +inf
    g = np.where(valid[:, None, :], lo, np.inf).min(axis=2)           # (nn, 3)
    top = np.where(valid[:, None, :], hi, -np.inf).max(axis=2)
    s = _steps(g, top)
    gb, sb = g[:, :, None], s[:, :, None]
    lo_f = np.where(valid[:, None, :], lo, gb)                        # empty slots: any value, replaced below
    hi_f = np.where(valid[:, None, :], hi, gb)
    qlo = np.where(valid[:, None, :], _round(gb, sb, lo_f, True), QMAX)
    qhi = np.where(valid[:, None, :], _round(gb, sb, hi_f, False), 0)
    out = np.zeros((nn, qnode_words(W, nord)), np.int32)
    of = out.view(np.float32)
    of[:, 0:3] = g
    of[:, 3:6] = s
    ob = out.view(np.uint8)
    ob[:, 4 * HEADER:4 * HEADER + 6 * W] = np.concatenate([qlo, qhi], axis=1).reshape(nn, 6 * W).astype(np.uint8)
    cw = child_word(W)
    out[:, cw:cw + W] = np.where(valid, nodes[:, 6 * W:7 * W], -1)
    orders = nodes[:, 7 * W:7 * W + nord].astype(np.uint32)
    o0 = order_byte(W)
    for b in range(ORDER_BYTES):
        ob[:, o0 + b:o0 + nord * ORDER_BYTES:ORDER_BYTES] = ((orders >> np.uint32(8 * b)) & np.uint32(0xFF)).astype(np.uint8)
    return out
