"""Where a grid's time goes beyond the operation counts: probe the memory-free costs of a step and
of a triangle test on a cylinder, and attribute what the measured time has on top of them to the
memory traffic of a structure that outgrows the caches.

Ize 2007's cost model (Eq 1 / Eq 5) charges Ts per cell step and Ti per triangle test, whatever the
grid's size. The probes measure, in this run and side by side (:func:`tracer.measure.timing.time_paired`):

- **T0 and Ts (empty)**: rays inside a cylinder's hollow cross only empty cells; timing them through
  three grids of increasing size gives the per-ray set-up T0 (intercept) and the cost of an empty
  step (slope of time against steps).
- **Ti**: a one-cell grid tests every triangle on every ray that meets the box; (time - T0) / tests.

``excess = measured - (T0 + Ts * steps + Ti * tests)`` is then the time the counts do not explain:
loading the occupied cells' ranges, reference lists and triangles from a structure larger than
the caches.
"""
from __future__ import annotations

import numpy as np

from tracer.accel import build
from tracer.measure.timing import time_paired

#: cells of the three grids the empty-step probe times (spanning 3 decades of M)
PROBE_CELLS = (8_000.0, 125_000.0, 1_000_000.0)


def hollow_rays(scene, n: int, seed: int = 0):
    """Rays inside a z-axis cylinder's hollow: from a random point of the disc of half the radius at
    10 % of the height to one at 90 %, with tmax at the end point, so they meet no triangle (open or
    capped). Returns origins, unit directions (float32) and tmax (float32)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(scene.bounds, np.float64)
    c, r = (lo + hi) / 2, 0.5 * (hi - lo)[:2].min() / 2

    def disc(z):
        a, s = rng.uniform(0, 2 * np.pi, n), r * np.sqrt(rng.uniform(0, 1, n))
        return np.stack([c[0] + s * np.cos(a), c[1] + s * np.sin(a), np.full(n, z)], 1)

    o, e = disc(lo[2] + 0.1 * (hi - lo)[2]), disc(lo[2] + 0.9 * (hi - lo)[2])
    d = e - o
    length = np.linalg.norm(d, axis=1)
    return o.astype(np.float32), (d / length[:, None]).astype(np.float32), length.astype(np.float32)


def memory_free_costs(scene, random_rays, n_hollow: int = 20_000, n_test: int = 1_000, quick: bool = False) -> dict:
    """T0, Ts (empty step) and Ti (ns) of ``scene`` measured in this run (see the module doc)."""
    n_hollow = min(n_hollow, 5_000) if quick else n_hollow
    o, d, tmax = hollow_rays(scene, n_hollow)
    fns, counts = {}, {}
    for cells in PROBE_CELLS:
        g = build(scene, "grid", cells=cells)
        _, cnt = g.intersect(o, d, tmax=tmax)
        assert cnt["tests"].sum() == 0, "hollow rays met a triangle"
        counts[cells] = cnt.mean()["steps"]
        fns[cells] = lambda g=g: g.intersect(o, d, tmax=tmax, counters=False)
    ro, rd = random_rays.origins[:n_test], random_rays.directions[:n_test]
    one = build(scene, "grid", cells=1.0)
    tests_one = one.intersect(ro, rd)[1].mean()["tests"]
    fns["one"] = lambda: one.intersect(ro, rd, counters=False)
    times = time_paired(fns, rounds=3 if quick else 5, repeats=3)
    steps = np.array([counts[c] for c in PROBE_CELLS])
    ns = np.array([np.median(times[c]) / n_hollow * 1e9 for c in PROBE_CELLS])
    ts, t0 = np.polyfit(steps, ns, 1)
    ti = (np.median(times["one"]) / len(ro) * 1e9 - t0) / tests_one
    return {"T0_ns": float(t0), "Ts_empty_ns": float(ts), "Ti_ns": float(ti), "ti_over_ts": float(ti / ts)}


def model_ns(rows, costs: dict) -> np.ndarray:
    """The memory-free count model's ns per ray for sweep rows (a DataFrame with steps, tests)."""
    return np.asarray(costs["T0_ns"] + costs["Ts_empty_ns"] * rows.steps + costs["Ti_ns"] * rows.tests)


def excess(rows, costs: dict) -> np.ndarray:
    """Measured ns per ray minus the memory-free count model."""
    return np.asarray(rows.anchored_ns_per_ray) - model_ns(rows, costs)
