"""tracer.accel.simd.slab4: the four-lane slab test equals the scalar float32 code lane by lane, bit for bit,
including the NaN rule (origin on a slab plane with an infinite inverse direction)."""
from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from tracer.accel.geometry import ray_triangle
from tracer.accel.simd import ctz, popc, slab4, slab8
from tracer.accel.simd_tri import ray_tri4


@njit
def _vec8(nf, base, offs, o, j, tlo, thi, tol, t8):
    return slab8(nf, base, offs[0], offs[1], offs[2], offs[3], offs[4], offs[5], o[0], o[1], o[2], j[0], j[1],
                 j[2], tlo, thi, tol, t8)


@njit
def _vec(nf, base, offs, o, j, tlo, thi, tol, t4):
    return slab4(nf, base, offs[0], offs[1], offs[2], offs[3], offs[4], offs[5], o[0], o[1], o[2], j[0], j[1],
                 j[2], tlo, thi, tol, t4)


def _scalar(nf, base, offs, o, j, tlo, thi, tol, w=4):
    gt = lambda t, a: a if a > t else t  # noqa: E731
    lt = lambda t, a: a if a < t else t  # noqa: E731
    f = np.float32
    mask, tn4 = 0, np.empty(w, np.float32)
    for k in range(w):
        d = [f((nf[base + k + offs[i]] - o[i // 2]) * j[i // 2]) for i in range(6)]
        tn = gt(gt(gt(tlo, d[0]), d[2]), d[4])
        tf = lt(lt(lt(thi, d[1]), d[3]), d[5])
        tn4[k] = tn
        mask |= int(tn <= f(tf + tol)) << k
    return mask, tn4


@pytest.mark.parametrize("w", [4, 8])
def test_slab_matches_the_scalar_code(w):
    rng = np.random.default_rng(0)
    offs = np.array([0, 3 * w, w, 4 * w, 2 * w, 5 * w], np.uint64)  # near x, far x, near y, far y, near z, far z
    seen = set()
    for trial in range(3000):
        lo = rng.uniform(-1, 1, (3, w)).astype(np.float32)
        if trial % 7 == 0:  # four copies of one box around the origin: all four met
            lo[:] = np.float32(-2.5)
        hi = (lo + rng.uniform(0.5, 2.5, (3, w)) + (5 if trial % 7 == 0 else 0)).astype(np.float32)
        nf = np.concatenate([lo.ravel(), hi.ravel(), np.zeros(8, np.float32)])
        o = rng.uniform(-2, 2, 3).astype(np.float32)
        d = rng.normal(size=3)
        if trial % 5 == 0:  # a ray parallel to a slab, its origin on one of the planes: inf * 0 = NaN
            ax = trial % 3
            d[ax] = 0.0
            o[ax] = lo[ax, trial % w]
        with np.errstate(divide="ignore"):
            j = (1.0 / d).astype(np.float32)
        tlo, thi, tol = np.float32(0.0), np.float32(rng.uniform(0.5, 5)), np.float32(1e-6)
        t4 = np.empty(w, np.float32)
        mask = (_vec if w == 4 else _vec8)(nf, np.uint64(0), offs, o, j, tlo, thi, tol, t4)
        with np.errstate(invalid="ignore"):
            want_mask, want_t4 = _scalar(nf, 0, offs, o, j, tlo, thi, tol, w)
        assert mask == want_mask, trial
        np.testing.assert_array_equal(t4.view(np.int32), want_t4.view(np.int32))
        seen.add(mask)
    assert 0 in seen and (1 << w) - 1 in seen and len(seen) >= 10  # misses, all hit, and mixed masks


@njit
def _bits(x):
    return ctz(x), popc(x)


def test_ctz_and_popc():
    for x in (1, 2, 3, 8, 0b10110000, 0xFF, 1 << 40):
        assert _bits(np.int64(x)) == ((x & -x).bit_length() - 1, bin(x).count("1"))


@njit
def _tri4(tri, base, ray, tmin, tmax, t4):
    return ray_tri4(tri, base, ray[0], ray[1], ray[2], ray[3], ray[4], ray[5], tmin, tmax, t4)


@njit
def _tri1(v, ray, tmin, tmax):
    return ray_triangle(ray[0], ray[1], ray[2], ray[3], ray[4], ray[5], v[0], v[1], v[2], v[3], v[4], v[5],
                        v[6], v[7], v[8], tmin, tmax)


def _block(verts):
    """(4, 9) float32 triangles [a, b, c] -> the 36-word SoA block of tracer.accel.simd_tri."""
    return np.ascontiguousarray(verts.T).ravel()


def test_ray_tri4_matches_ray_triangle_bit_for_bit():
    """Each lane equals geometry.ray_triangle (t bits and hit/miss), on rays aimed at vertices and
    edges (edge-inclusive ties), back faces, grazing rays, degenerate (padding) triangles and a
    block offset inside a larger array, with finite and infinite limits."""
    rng = np.random.default_rng(1)
    kinds = {"hit": 0, "miss": 0}
    for trial in range(4000):
        v = rng.uniform(-1, 1, (4, 9)).astype(np.float32)
        if trial % 11 == 0:  # padding: a degenerate triangle (three equal vertices)
            v[trial % 4, 3:6] = v[trial % 4, :3]
            v[trial % 4, 6:9] = v[trial % 4, :3]
        o = rng.uniform(-3, 3, 3)
        lane = trial % 4
        w = rng.dirichlet([1, 1, 1])
        if trial % 3 == 0:  # aim at a vertex or an edge midpoint of one lane
            w = [np.array([1.0, 0, 0]), np.array([0.5, 0.5, 0]), np.array([0, 0.5, 0.5])][trial % 9 // 3]
        target = w[0] * v[lane, :3] + w[1] * v[lane, 3:6] + w[2] * v[lane, 6:9]
        d = target.astype(np.float64) - o
        if trial % 13 == 0:  # grazing: along the lane's plane
            e1 = v[lane, 3:6].astype(np.float64) - v[lane, :3]
            d = e1 + 1e-9 * rng.normal(size=3)
        o = o.astype(np.float32).astype(np.float64)
        d = d.astype(np.float32).astype(np.float64)
        ray = np.concatenate([o, d])
        tmin, tmax = 0.0, (np.inf if trial % 2 else float(rng.uniform(0.3, 1.5)))
        pad = trial % 5
        tri = np.concatenate([np.zeros(pad, np.float32), _block(v)])
        t4 = np.empty(4, np.float64)
        mask = _tri4(tri, np.uint64(pad), ray, tmin, tmax, t4)
        for k in range(4):
            want = _tri1(v[k], ray, tmin, tmax)
            hit = bool(mask >> k & 1)
            assert hit == np.isfinite(want), (trial, k)
            assert t4[k].view(np.int64) == np.float64(want).view(np.int64), (trial, k, t4[k], want)
            kinds["hit" if hit else "miss"] += 1
    assert kinds["hit"] > 2000 and kinds["miss"] > 4000, kinds
