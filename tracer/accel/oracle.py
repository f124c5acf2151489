"""Float64 brute-force oracle: every ray against every triangle, closest hit.

Uses the same :func:`tracer.accel.geometry.ray_triangle` as every structure, so any disagreement is a
traversal/assignment error of the structure, never a difference of triangle-test arithmetic.
"""
from __future__ import annotations

import numpy as np
from numba import prange

from tracer.accel._jit import pjit
from tracer.accel import Hits, as_rays, tmax_array
from tracer.accel.geometry import INF, ray_triangle


@pjit
def _oracle(O, D, tmin, tmax, V, out_t, out_id, out_ties):
    n = V.shape[0]
    for i in prange(O.shape[0]):
        ox = np.float64(O[i, 0]); oy = np.float64(O[i, 1]); oz = np.float64(O[i, 2])
        dx = np.float64(D[i, 0]); dy = np.float64(D[i, 1]); dz = np.float64(D[i, 2])
        best = np.float64(tmax[i])
        best_id = -1
        for k in range(n):
            t = ray_triangle(ox, oy, oz, dx, dy, dz, V[k, 0], V[k, 1], V[k, 2], V[k, 3], V[k, 4],
                             V[k, 5], V[k, 6], V[k, 7], V[k, 8], tmin, best)
            if t < best:
                best = t
                best_id = k
        ties = 0
        if best_id >= 0:  # other triangles hit at the same t (duplicates, shared edges/vertices)
            for k in range(n):
                if k != best_id:
                    t = ray_triangle(ox, oy, oz, dx, dy, dz, V[k, 0], V[k, 1], V[k, 2], V[k, 3],
                                     V[k, 4], V[k, 5], V[k, 6], V[k, 7], V[k, 8], tmin,
                                     best * (1 + 1e-9) + 1e-300)
                    if t <= best * (1 + 1e-9):
                        ties += 1
        out_t[i] = best if best_id >= 0 else INF
        out_id[i] = best_id
        out_ties[i] = ties


def oracle_intersect(scene, origins, directions, tmin: float = 0.0, tmax=None):
    """Closest hits by brute force. Returns (Hits with float64 t, ties per ray)."""
    o, d = as_rays(origins, directions)
    m = len(o)
    out_t = np.empty(m, np.float64)
    out_id = np.empty(m, np.int32)
    ties = np.empty(m, np.int32)
    _oracle(o, d, float(tmin), tmax_array(tmax, m), np.ascontiguousarray(scene.tris.reshape(-1, 9)),
            out_t, out_id, ties)
    return Hits(out_t, out_id), ties


def oracle_cached(scene, origins, directions, tmin: float = 0.0, tmax=None):
    """:func:`oracle_intersect` with its answer kept in the mesh cache ($GRIDCOST_CACHE), keyed by
    the triangles, the rays, the ray range and the kernel digest (an answer computed by other
    code is never reused), so verifying several structures pays once."""
    import hashlib

    import numpy as np

    from tracer.measure.provenance import kernel_digest
    from tracer.storage import atomic_savez, cache_root, load_cached_npz
    o, d = as_rays(origins, directions)
    h = hashlib.sha1(kernel_digest().encode())
    for a in (scene.tris, o, d, tmax_array(tmax, len(o)), np.float64(tmin)):
        h.update(np.ascontiguousarray(a).tobytes())
    path = cache_root() / "oracle" / f"{h.hexdigest()}.npz"
    z = load_cached_npz(path, ("t", "tri_id", "ties"), "oracle answer")
    if z is not None:
        return Hits(z["t"], z["tri_id"]), z["ties"]
    hits, ties = oracle_intersect(scene, o, d, tmin, tmax)
    atomic_savez(path, t=hits.t, tri_id=hits.tri_id, ties=ties)
    return hits, ties


def compare(hits: Hits, ref: Hits, ref_ties: np.ndarray, rtol: float = 1e-5) -> dict:
    """Count disagreements of ``hits`` with the oracle's ``ref``.

    A ray disagrees on hit/miss, on t beyond ``rtol`` relative, or on the triangle id — except that a
    different id at the same t where the oracle saw other triangles at that t is a *tie* (duplicate
    faces, shared edges), reported separately and not a disagreement.

    The oracle's float64 t is compared as the structures return it, rounded to float32: a hit
    beyond float32's range (a subnormal direction component) is a hit at t = inf for both.
    """
    hit_a = hits.tri_id >= 0
    hit_b = ref.tri_id >= 0
    hitmiss = hit_a != hit_b
    both = hit_a & hit_b
    ta = np.where(both, hits.t.astype(np.float64), 0.0)
    with np.errstate(over="ignore"):
        tb = np.where(both, ref.t.astype(np.float32).astype(np.float64), 0.0)
    with np.errstate(invalid="ignore"):  # inf - inf: the same out-of-range hit
        t_bad = both & (np.abs(ta - tb) > rtol * np.maximum(np.abs(tb), 1e-30))
    id_diff = both & ~t_bad & (hits.tri_id != ref.tri_id)
    tie = id_diff & (ref_ties > 0)
    id_bad = id_diff & ~tie
    bad = hitmiss | t_bad | id_bad
    return {
        "rays": int(len(ta)), "hits": int(hit_b.sum()), "disagreements": int(bad.sum()),
        "hit_miss": int(hitmiss.sum()), "t_mismatch": int(t_bad.sum()), "id_mismatch": int(id_bad.sum()),
        "ties": int(tie.sum()), "bad_index": np.flatnonzero(bad)[:20].tolist(),
    }
