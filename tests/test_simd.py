"""tracer.accel.simd.slab4: the four-lane slab test equals the scalar float32 code lane by lane, bit for bit,
including the NaN rule (origin on a slab plane with an infinite inverse direction)."""
from __future__ import annotations

import numpy as np
from numba import njit

from tracer.accel.simd import slab4


@njit
def _vec(nf, base, offs, o, j, tlo, thi, tol, t4):
    return slab4(nf, base, offs[0], offs[1], offs[2], offs[3], offs[4], offs[5], o[0], o[1], o[2], j[0], j[1],
                 j[2], tlo, thi, tol, t4)


def _scalar(nf, base, offs, o, j, tlo, thi, tol):
    gt = lambda t, a: a if a > t else t  # noqa: E731
    lt = lambda t, a: a if a < t else t  # noqa: E731
    f = np.float32
    mask, tn4 = 0, np.empty(4, np.float32)
    for k in range(4):
        d = [f((nf[base + k + offs[i]] - o[i // 2]) * j[i // 2]) for i in range(6)]
        tn = gt(gt(gt(tlo, d[0]), d[2]), d[4])
        tf = lt(lt(lt(thi, d[1]), d[3]), d[5])
        tn4[k] = tn
        mask |= int(tn <= f(tf + tol)) << k
    return mask, tn4


def test_slab4_matches_the_scalar_code():
    rng = np.random.default_rng(0)
    offs = np.array([0, 12, 4, 16, 8, 20], np.uint64)  # near x, far x, near y, far y, near z, far z
    seen = set()
    for trial in range(3000):
        lo = rng.uniform(-1, 1, (3, 4)).astype(np.float32)
        if trial % 7 == 0:  # four copies of one box around the origin: all four met
            lo[:] = np.float32(-2.5)
        hi = (lo + rng.uniform(0.5, 2.5, (3, 4)) + (5 if trial % 7 == 0 else 0)).astype(np.float32)
        nf = np.concatenate([lo.ravel(), hi.ravel(), np.zeros(8, np.float32)])
        o = rng.uniform(-2, 2, 3).astype(np.float32)
        d = rng.normal(size=3)
        if trial % 5 == 0:  # a ray parallel to a slab, its origin on one of the planes: inf * 0 = NaN
            ax = trial % 3
            d[ax] = 0.0
            o[ax] = lo[ax, trial % 4]
        with np.errstate(divide="ignore"):
            j = (1.0 / d).astype(np.float32)
        tlo, thi, tol = np.float32(0.0), np.float32(rng.uniform(0.5, 5)), np.float32(1e-6)
        t4 = np.empty(4, np.float32)
        mask = _vec(nf, np.uint64(0), offs, o, j, tlo, thi, tol, t4)
        with np.errstate(invalid="ignore"):
            want_mask, want_t4 = _scalar(nf, 0, offs, o, j, tlo, thi, tol)
        assert mask == want_mask, trial
        np.testing.assert_array_equal(t4.view(np.int32), want_t4.view(np.int32))
        seen.add(mask)
    assert 0 in seen and 15 in seen and len(seen) >= 10  # misses, all four hit, and mixed masks
