"""The measurements cost models are fitted to or decide from; :mod:`costmodel` itself never
builds or times anything, it receives these numbers.

* :func:`single_thread`, :func:`single_pass_time`, :func:`probe_grid` — Hapala's probe of a grid on a
  sample of rays (decision step 2, and the calibration's samples);
* :func:`probe`, :func:`decide` — a :class:`costmodel.select.Selector`'s steps 1-2 measured on a
  scene, and its whole decision;
* :func:`measure_kd_points`, :func:`measure_sah_constants`, :func:`measure_bvh_trav_cost`,
  :func:`measure_grid_density` — a structure's counters and times per build setting, and what is
  fitted to them: the kd-tree's and the BVH's SAH constants (:mod:`costmodel.kdcost`), the grid's
  cells per triangle (:mod:`costmodel.griddensity`).
"""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from costmodel.griddensity import GRID_CALIBRATION, GRID_SETTINGS, GridDensityFit, fit_grid_density
from costmodel.havran import havran_stats
from costmodel.kdcost import (BVH_CALIBRATION, BVH_SETTINGS, DEFAULT_SETTINGS, BvhSahFit, KdCostFit, fit_bvh_trav_cost,
                              fit_sah_constants)
from costmodel.select import DEFAULT_SAMPLE, TIME_STAT
from tracer.accel import build
from tracer.measure.timing import MIN_SAMPLE_SECONDS, build_clock, time_call, time_single_pass
from tracer.scenes.rays import make_rays
from tracer.scenes.scene import Scene, load_scene


def time_stats(runs) -> dict:
    """Median and minimum of repeated timings (interference only ever adds time: the minimum is the
    less noisy estimate on a shared machine, the median the conventional one)."""
    return {"median": float(np.median(runs)), "min": float(np.min(runs))}


@contextmanager
def single_thread():
    """Run the Numba kernels on the calling thread only: the times here are then the calling thread's
    CPU time (:func:`tracer.measure.timing.default_clock`, when its check trusts it), which a shared machine
    does not inflate the way it does wall time."""
    import numba
    n = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(n)


def single_pass_time(accel, o, d, chunks: int = 1, warm: int = 0) -> dict:
    """Per-ray time {median, min over parts} of tracing ``o, d`` once with ``accel``
    (:func:`tracer.measure.timing.time_single_pass`: the way an application traces its first rays)."""
    return time_stats(time_single_pass(lambda po, pd_: accel.intersect(po, pd_, counters=False), o, d, chunks, warm))


def probe_grid(grid, rays, sample: int = DEFAULT_SAMPLE, seed: int = 0, idx: np.ndarray | None = None) -> dict:
    """Decision step 2: the grid's time per ray on ``sample`` of ``rays`` (a random subset, or
    ``idx``), each ray traced once (:func:`single_pass_time`: the first 10 % warm the caches, the
    rest is timed in parts of >= 180 rays, at most 5), and what the grid's counters say about them:
    fraction of rays meeting the scene box (``box_frac``), hit fraction, mean cells stepped and
    triangles tested."""
    if idx is None:
        idx = np.random.default_rng(seed).permutation(rays.n)[:sample]
    o = np.ascontiguousarray(rays.origins[idx])
    d = np.ascontiguousarray(rays.directions[idx])
    with single_thread():
        t = single_pass_time(grid, o, d, chunks=min(5, max(1, len(idx) // 200)), warm=len(idx) // 10)
    hits, cnt = grid.intersect(o, d, counters=True)
    m = cnt.mean()
    return {"t": t[TIME_STAT], "t_median": t["median"], "t_min": t["min"], "box_frac": m["setups"],
            "hit_frac": float((hits.tri_id >= 0).mean()), "steps": m["steps"], "tests": m["tests"],
            "rays": int(len(idx))}


def probe(selector, scene, rays=None) -> tuple[object, dict]:
    """Hapala's decision steps 1-2 for ``selector`` (:class:`costmodel.select.Selector`): build the
    grid (timed) and sample its per-ray time; returns (grid, features)."""
    build(Scene(scene.tris[:1], "warm-up"), "grid")  # load the compiled kernels outside the timing
    with single_thread():
        t0 = build_clock()  # builds on wall time (see tracer.measure.timing.build_clock)
        grid = build(scene, "grid", factor=selector.grid_factor)
        t_build = build_clock() - t0
    if rays is None:
        rays = make_rays(scene, selector.kind, selector.sample_rays, seed=selector.seed)
    p = probe_grid(grid, rays, sample=min(selector.sample_rays, rays.n), seed=selector.seed)
    st = grid.stats()
    feats = {"N": scene.n, "T_BG": t_build, "t_RG_sample": p["t"], "box_frac": p["box_frac"],
             "hit_frac": p["hit_frac"], "steps": p["steps"], "tests": p["tests"],
             "refs_per_tri": st["refs_per_tri"], **havran_stats(grid)}
    return grid, feats

def decide(selector, scene, n_rays: float, rays=None) -> dict:
    """The 8 steps of a fitted ``selector`` for ``scene`` and ``n_rays`` rays: a dict with ``choice`` ("grid" or the
    hierarchy), ``rc_est``, ``t_grid`` (sampled t_R^G), ``t_hier`` (estimated t_R^H),
    ``t_build_hier`` (estimated T_B^H), ``t_build_grid`` (measured T_B^G), all in seconds."""
    _, feats = probe(selector, scene, rays)
    out = selector.decide_features(feats, n_rays)
    out["scene"] = scene.name
    return out


def measure_kd_points(scenes, kinds=("random", "camera"), settings=DEFAULT_SETTINGS, n_rays: int = 50_000,
                      repeats: int = 5, seed: int = 0, clock=None, structure: str = "kdtree",
                      min_sample: float = MIN_SAMPLE_SECONDS) -> list[dict]:
    """One point per (scene, ray kind, build setting of ``structure``, the kd-tree by default):
    per-ray means of the counters ("leaves" and "steps" are both the ``steps`` counter: a kd-tree's
    leaves, a grid's cells) and the median seconds per ray of the non-counting kernel
    (:func:`tracer.measure.timing.time_call`, warm-up first; ``clock`` and ``min_sample`` as
    :func:`tracer.measure.timing.time_call`'s, e.g. ``time.thread_time`` on a loaded machine).
    ``scenes`` are Scene objects or registry names. Run it single-threaded."""
    out = []
    for sc in scenes:
        scene = load_scene(sc) if isinstance(sc, str) else sc
        rays = {k: make_rays(scene, k, n_rays, seed=seed) for k in kinds}
        for params in settings:
            kd = build(scene, structure, **params)
            for kind, r in rays.items():
                _, cnt = kd.intersect(r.origins, r.directions, counters=True)
                tm = time_call(lambda: kd.intersect(r.origins, r.directions, counters=False), repeats=repeats,
                               clock=clock, min_sample=min_sample)
                m = cnt.mean()
                out.append({"scene": scene.name, "kind": kind, "params": dict(params), "rays": r.n,
                            "nodes": m["nodes"], "leaves": m["steps"], "steps": m["steps"], "tests": m["tests"],
                            "s_per_ray": tm.median / r.n, "spread": tm.spread})
    return out


def measure_sah_constants(scenes=("bunny-16k", "dragon-48k", "bunny-69k"), **measure) -> KdCostFit:
    """The kd-tree's SAH constants on this machine: :func:`measure_kd_points` on ``scenes``, then
    :func:`costmodel.kdcost.fit_sah_constants`."""
    return fit_sah_constants(measure_kd_points(scenes, **measure))


def measure_bvh_trav_cost(scenes=BVH_CALIBRATION, settings=BVH_SETTINGS, strict: bool = False, **measure) -> BvhSahFit:
    """The BVH's SAH traversal weight on this machine: the binary BVH at ``settings`` on ``scenes``,
    then :func:`costmodel.kdcost.fit_bvh_trav_cost`."""
    return fit_bvh_trav_cost(measure_kd_points(scenes, settings=settings, structure="bvh", **measure), strict=strict)


def measure_grid_density(scenes=GRID_CALIBRATION, settings=GRID_SETTINGS, strict: bool = False,
                         **measure) -> GridDensityFit:
    """The uniform grid's cells per triangle for this machine: the grid at ``settings`` (densities)
    on ``scenes``, then :func:`costmodel.griddensity.fit_grid_density`."""
    return fit_grid_density(measure_kd_points(scenes, settings=settings, structure="grid", **measure), strict=strict)
