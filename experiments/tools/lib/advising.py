"""What ``advise`` and ``advise-check`` share: the per-host calibration of the hierarchies (table1h's
points on small built-in scenes), the probes of the candidates (build, then timed samples of disjoint
ray sets), the prediction of each candidate's build + trace time for R rays with an interval, and the
interleaved measurement ``--check`` compares it with. The rationale of each knob is where it is set."""
from __future__ import annotations

import itertools
import time

from experiments.hapala.lib.calibrate import HIERARCHIES
from tracer.errors import GridcostError

#: the per-host calibration of the hierarchies: small scenes that travel with the package
CALIBRATION = ["cornell", "boxes-44", "bunny-948", "bunny-3851", "cylinder-196", "particles-2000", "teapot",
               "dragon-11k", "sphere-2880", "cylinder-3996", "bunny-16k"]
#: every hierarchy table1h calibrates (kd-tree, BVH, wide BVH; the wide BVH is the fastest we have),
#: so table1h --quick and advise --quick share their points
CAL_CFG = {"rays": 3000, "repeats": 3, "grid_factor": 1.0, "seed": 0, "samples": [300, 1000, 3000],
           "hiers": list(HIERARCHIES)}
#: --quick: the six smallest, fewer rays (a first look, the tests)
QUICK_CALIBRATION = ["cornell", "boxes-44", "bunny-948", "cylinder-196", "particles-2000", "teapot"]
QUICK_CAL_CFG = dict(CAL_CFG, rays=2000, samples=[100, 300, 1000])  # = table1h --quick: `all --quick` reuses its points
#: rays traced by the probes and by --check
PROBE_RAYS, CHECK_RAYS = 20_000, 200_000
#: relative half-width floor of a probed interval (single-pass timings of a shared machine)
PROBE_FLOOR = 0.10
#: a probe's build is timed 3 times (median) when one build takes less than this
PROBE_REBUILD_S = 0.5
#: a hierarchy whose estimated build takes at most this is built and probed like the grids
PROBE_BUILD_MAX_S = 2.0
#: a timed trace sample repeats the rays until it lasts this long: longer than the time slices a
#: loaded machine hands out, so one preemption does not make a sample (camera rays: 20,000 rays
#: can take 4 ms)
MIN_SAMPLE_S = 0.05
#: what advise fits on this host before it probes, from points measured by the first call (a few
#: seconds) and stored like every point: the BVH4 candidate's SAH weight
#: (:class:`costmodel.kdcost.BvhSahFit`) and the uniform grid candidate's cells per triangle, Ize's
#: Eq 4 with this host's T_i/T_s (:class:`costmodel.griddensity.GridDensityFit`: a step and a test
#: cost what this machine and this tracer make them cost, not the paper's 4:1). structure ->
#: (point-store target, the files beside tracer/ that shape the points: their measurement key)
HOST_FITS = {"bvh": ("advise-bvh-sah", ("costmodel/kdcost.py",)),
             "grid": ("advise-grid-density", ("costmodel/griddensity.py", "costmodel/kdcost.py"))}
#: --quick: the same meshes with fewer rays (two tiny scenes fitted well too, but three meshes leave
#: more margin against a term coming out free on a loaded machine), each timed sample MIN_SAMPLE_S
#: long (with 0.02 s samples a noisy cloud VM left both terms' split free: costmodel.kdcost.BvhSahFit)
HOST_FIT_QUICK = {"n_rays": 10_000, "repeats": 3, "min_sample": MIN_SAMPLE_S}
#: rays per packet of the coherent grid (8x8 tiles of camera rays)
PACKET = 64
#: disjoint probe sets of PROBE_RAYS each, traced in turn (:func:`probe_pool`)
PROBE_SETS = 10


def calibration(ctx, log) -> dict:
    """kind -> {hier: (fitted estimator, (lo, hi) relative error quantiles of T_BH and t_RH)};
    ``bvh4_trav_cost``, the 4-wide BVH's SAH weight, and ``grid_factor``, the uniform grid's cells
    per triangle (with ``grid_ti_over_ts``), both fitted on this host (:data:`HOST_FITS`), and their
    notes (what a fit left out, a fallback)."""
    from costmodel.select import GridcostEstimator, loo_errors, records
    from experiments.hapala.lib.calibrate import measure_all
    names, cfg = (QUICK_CALIBRATION, QUICK_CAL_CFG) if ctx.quick else (CALIBRATION, CAL_CFG)
    t0 = time.time()
    raw = measure_all(ctx, names, cfg, log=lambda *a: None)
    if time.time() - t0 > 5:
        log(f"advise: calibrated this host on {len(names)} small scenes in {time.time() - t0:.0f} s "
            f"(stored: later calls reuse it)")
    from costmodel.griddensity import GridDensityFit
    from costmodel.kdcost import fit_bvh_trav_cost
    from tracer.accel.constants import IZE_M_FACTOR
    pts, how = {}, {}
    for structure, (target, code) in HOST_FITS.items():
        t0 = time.time()
        scenes, settings = host_fit_inputs(structure)
        key = {"target": target, "scenes": list(scenes), "settings": list(settings),
               "quick": bool(ctx.quick), **(HOST_FIT_QUICK if ctx.quick else {})}
        pts[structure], cached = ctx.store(code=code).measure(key, host_fit_points, structure, bool(ctx.quick))
        how[structure] = (f"on {', '.join(scenes)} "
                          + ("(stored points of this host)" if cached else f"(measured in {time.time() - t0:.0f} s, stored)"))
    sah = fit_bvh_trav_cost(pts["bvh"])
    # no ray kind separating a step from a test: the paper's 8N, what advise probed before this fit
    dens = GridDensityFit(default=IZE_M_FACTOR).fit(pts["grid"])
    out = {"bvh4_trav_cost": sah.trav_cost_, "bvh4_sah_note": sah.note(), "grid_factor": dens.factor_,
           "grid_ti_over_ts": dens.ti_over_ts_, "grid_fallback": dens.fallback_, "grid_density_note": dens.note()}
    log(f"advise: the BVH4's SAH weight C_trav/C_isect {sah.trav_cost_:.2f}, fitted {how['bvh']}"
        + (f"; {sah.note()}" if sah.free_ else ""))
    ratio = "the paper's T_i/T_s" if dens.fallback_ else f"T_i/T_s {dens.ti_over_ts_:.2f}"
    log(f"advise: the grid's cells {dens.factor_:.2f}N (Ize Eq 4, {ratio}), fitted {how['grid']}"
        + (f"; {dens.note()}" if dens.note() else ""))
    for kind in ("random", "path"):
        out[kind] = {}
        for hier in cfg["hiers"]:
            cal = records(raw, hier=hier)
            cal = cal[cal.kind == kind].reset_index(drop=True)
            est = GridcostEstimator().fit(cal)
            loo = loo_errors(cal, GridcostEstimator)
            rel_b = loo.T_BH_est / loo.T_BH - 1
            rel_r = loo.t_RH_est / loo.t_RH - 1
            out[kind][hier] = (est, {"build": (float(rel_b.quantile(0.1)), float(rel_b.quantile(0.9))),
                                     "ray": (float(rel_r.quantile(0.1)), float(rel_r.quantile(0.9)))})
    return out


def host_fit_inputs(structure: str) -> tuple:
    """(calibration meshes, build settings) of the :data:`HOST_FITS` fit of ``structure``."""
    from costmodel.griddensity import GRID_CALIBRATION, GRID_SETTINGS
    from costmodel.kdcost import BVH_CALIBRATION, BVH_SETTINGS
    return {"bvh": (BVH_CALIBRATION, BVH_SETTINGS), "grid": (GRID_CALIBRATION, GRID_SETTINGS)}[structure]


def host_fit_points(structure: str, quick: bool) -> list[dict]:
    """The points of ``structure``'s :data:`HOST_FITS` fit (fewer rays with ``quick``): measured once
    per host and code, stored like every point (:func:`calibration`)."""
    from experiments.core.probes import measure_kd_points
    scenes, settings = host_fit_inputs(structure)
    return measure_kd_points(scenes, settings=settings, structure=structure, **(HOST_FIT_QUICK if quick else {}))


def probe_pool(scene, kind: str, seed: int, image: int | None = None) -> list:
    """The probes' rays: PROBE_SETS disjoint sets of PROBE_RAYS rays of ``kind``; a timed probe
    traces the next set at each call (:func:`time_structures`), so it never traces a ray twice, as a
    long run does not: repeating one set of 20,000 rays until a sample lasted MIN_SAMPLE_S let
    their cells, nodes and triangles stay in the caches, and the probes of large scenes came out
    13-20 % faster per ray than a long run (dragon-202k, room).

    Camera rays are the frame of CHECK_RAYS pixels (the frame --check and a long run trace, not a
    smaller one: a packet's coherence depends on the resolution) cut into PROBE_SETS consecutive
    pieces of whole 8x8 packets, traced in turn: the frame in its own order, so each packet finds
    what its neighbours loaded in the caches, as in a long run. Per-ray time of the probe over the
    whole frame's, measured on particles-100k and dragon-202k (grid at 8N, BVH, packets): consecutive
    pieces 0.98-1.08; one set of 39 runs of 8 packets spread over the frame and repeated 0.81-1.05
    (repeated rays stay in the caches); 10 such sets in turn 1.07-1.26 (a run's neighbours were
    evicted since); the whole frame with its packets shuffled 1.27 (particles-100k, grid).
    ``image``: the side of the user's square frame in pixels instead (its coherence is theirs)."""
    import numpy as np
    from tracer.scenes.rays import Rays, make_rays
    if kind != "camera":
        r = make_rays(scene, kind, PROBE_SETS * PROBE_RAYS, seed=seed)
        return [Rays(np.ascontiguousarray(r.origins[k::PROBE_SETS]), np.ascontiguousarray(r.directions[k::PROBE_SETS]),
                     kind, seed) for k in range(PROBE_SETS)]
    full = make_rays(scene, kind, image * image if image else CHECK_RAYS, seed=seed)
    per = max(1, min(PROBE_RAYS // PACKET, full.n // PACKET // PROBE_SETS)) * PACKET
    return [Rays(np.ascontiguousarray(full.origins[k * per:(k + 1) * per]),
                 np.ascontiguousarray(full.directions[k * per:(k + 1) * per]), kind, seed) for k in range(PROBE_SETS)]


def predict(scene, kind, cal, seed, log=lambda *a: None, min_sample: float = MIN_SAMPLE_S,
            image: int | None = None) -> list[dict]:
    """Every candidate's predicted build seconds and per-ray seconds with their relative intervals
    (independent of R: :func:`with_totals` adds the totals). The grids, and each hierarchy whose
    build the calibration estimates at most PROBE_BUILD_MAX_S (cheap next to any budget worth
    advice), are probed together (:func:`time_structures` on the probe rays: builds timed, traces
    timed in interleaved rounds, so a busy phase of a shared machine hits all of them alike and
    cannot reorder them); the other hierarchies are estimated from the calibration."""
    from costmodel.select import Selector
    from tracer.accel import plugin_structures
    pool = probe_pool(scene, kind, seed, image)
    rays = pool[0]
    f = cal["grid_factor"]
    grid_how = (f"probed (M = {f:.2f}N, Ize Eq 4 with T_i/T_s {cal['grid_ti_over_ts']:.2f} fitted on this host)"
                if not cal["grid_fallback"] else
                f"probed (M = {f:g}N, Ize Eq 4 with the paper's T_i/T_s: {cal['grid_density_note']})")
    probed = [("grid", {"factor": f}, grid_how),
              ("nested", {"levels": 2}, "probed (M1 = (8N)^0.6, M2 = 8 N2, Ize Eq 12-13)")]
    if kind == "camera":
        probed.append(("cgt", {}, "probed (Wald 2006, lambda = 5, 8x8 packets)"))
    # structures other packages register (entry points, tracer.accel.base.structures) are probed like the grids
    probed += [(name, {}, "probed (registered by an entry point)") for name in plugin_structures()]
    ckind = kind if kind in cal else "random"
    # the decision algorithm's probe (a grid of N cells, 1000 sampled rays): the estimators' features
    from experiments.core.probes import probe as probe_selector
    _, feats = probe_selector(Selector(kind=ckind, sample_rays=1000, seed=seed), scene, rays if kind == ckind else None)
    out = []
    for hier, (est, rel) in cal[ckind].items():
        T_BH, t_RH = est.predict(feats["N"], feats)
        if T_BH <= PROBE_BUILD_MAX_S:
            probed.append((hier, {}, f"probed (its estimated build, {T_BH * 1e3:.0f} ms, is cheap)"))
            if hier == "bvh" and "bvh4_trav_cost" in cal:  # the BVH4 builds from the same binary BVH
                w = cal["bvh4_trav_cost"]
                probed.append(("bvh4", {"trav_cost": w}, f"probed (4-wide BVH, SAH weight {w:.2f} fitted on this host)"))
            continue
        how = f"estimated from this host's calibration ({est.n_calib_} scenes, {ckind} rays)"
        out.append({"structure": hier, "params": {}, "how": how, "build_s": float(T_BH), "ray_s": float(t_RH),
                    "rel_build": rel["build"], "rel_ray": rel["ray"], "memory_bytes": None})
    got = time_structures(scene, [(s_, p_) for s_, p_, _ in probed], pool, repeats=5, build_repeats=None,
                          min_sample=min_sample)
    for structure, params, how in probed:
        g = got[structure]
        hb, hr = max(PROBE_FLOOR, g["build_spread"] / 2), max(PROBE_FLOOR, g["ray_spread"] / 2)
        out.append({"structure": structure, "params": params, "how": how, "build_s": g["build_s"],
                    "ray_s": g["ray_s"], "rel_build": (-hb, hb), "rel_ray": (-hr, hr),
                    "memory_bytes": g.get("memory_bytes")})
    return out


def with_totals(cands: list[dict], R: float) -> list[dict]:
    """Copies of ``cands`` with the predicted total for R rays (build + R x per ray) and its
    interval (each part's relative interval applied to it), fastest first."""
    out = []
    for c in cands:
        c = dict(c)
        c["predicted_s"] = c["build_s"] + R * c["ray_s"]
        c["predicted_lo"] = c["build_s"] * (1 + c["rel_build"][0]) + R * c["ray_s"] * (1 + c["rel_ray"][0])
        c["predicted_hi"] = c["build_s"] * (1 + c["rel_build"][1]) + R * c["ray_s"] * (1 + c["rel_ray"][1])
        out.append(c)
    return sorted(out, key=lambda c: c["predicted_s"])


def _cycling(accel, pool):
    """A trace of the next ray set of ``pool`` at each call (so repeated calls trace fresh rays)."""
    sets = itertools.cycle(pool)

    def trace():
        r = next(sets)
        accel.intersect(r.origins, r.directions, counters=False)
    return trace


def time_structures(scene, structures, rays, repeats: int = 5, build_repeats: int | None = 5,
                    min_sample: float = MIN_SAMPLE_S) -> dict:
    """Build and time ``structures`` [(structure, params), …] on ``rays`` (one ray set, or a list of
    equal-sized sets traced in turn, one per call: :func:`probe_pool`): build seconds = median of
    ``build_repeats`` builds after a warm-up (wall clock; None: 3 builds when one takes under
    PROBE_REBUILD_S, else 1), per-ray seconds = median over ``repeats`` interleaved rounds of tracing
    a ray set with every structure (:func:`tracer.measure.timing.time_paired`, default clock), so a busy
    phase of the shared machine hits every structure alike. Returns structure -> {build_s, ray_s,
    build_spread, ray_spread (relative: (max - min) / median), rays}."""
    import numpy as np
    from tracer.accel import build
    from tracer.measure.timing import build_clock, time_paired
    pool = list(rays) if isinstance(rays, list) else [rays]  # (a Rays is a NamedTuple)
    n_rays = pool[0].n
    if any(r.n != n_rays for r in pool):
        raise GridcostError(f"time_structures: ray sets of unequal sizes {sorted({r.n for r in pool})}")
    accs, builds = {}, {}
    for structure, params in structures:
        t0 = build_clock()
        accs[structure] = build(scene, structure, **params)  # warm-up (JIT, caches); kept for tracing
        first = build_clock() - t0
        n = build_repeats or (3 if first < PROBE_REBUILD_S else 1)
        ts = []
        for _ in range(max(1, n)):
            t0 = build_clock()
            build(scene, structure, **params)
            ts.append(build_clock() - t0)
        builds[structure] = np.asarray(ts)
    tm = time_paired({k: _cycling(a, pool) for k, a in accs.items()},
                     rounds=max(1, repeats), repeats=1, min_sample=min_sample)
    out = {}
    for k in accs:
        b, t = builds[k], np.asarray(tm[k])
        out[k] = {"build_s": float(np.median(b)), "ray_s": float(np.median(t)) / n_rays,
                  "build_spread": float(np.ptp(b) / np.median(b)), "ray_spread": float(np.ptp(t) / np.median(t)),
                  "rays": n_rays, "memory_bytes": accs[k].stats().get("memory_bytes")}
    return out


def measure(scene, kind, structures, n_rays: int, repeats: int = 5, seed: int = 0,
            min_sample: float = MIN_SAMPLE_S, image: int | None = None) -> dict:
    """The measured truth of ``structures`` on ``n_rays`` fresh rays of ``kind`` (seed + 1: other
    rays than the probes'; camera rays: the probes' view and resolution with every pixel's ray
    jittered inside the pixel, as a renderer's next frame, since the unjittered frame is the
    probes'), :func:`time_structures` with ``repeats`` builds and rounds."""
    import numpy as np
    from tracer.scenes.rays import camera_rays, make_rays
    if kind == "camera":
        side = image or max(1, int(round(np.sqrt(n_rays))))
        rows = image or max(1, int(n_rays) // side)
        rays = camera_rays(scene, side, rows, seed=seed + 1, jitter=True)
    else:
        rays = make_rays(scene, kind, int(n_rays), seed=seed + 1)
    return time_structures(scene, structures, rays, repeats, repeats, min_sample)


def advice_for(ctx, scene, kind: str, seed: int = 0, image: int | None = None, log=lambda *a: None):
    """Every candidate's prediction for ``scene`` and ``kind`` (independent of the budget) as an
    :class:`~experiments.tools.lib.budgets.Advice`: the host's calibration (stored in ``ctx``'s
    point store), then :func:`predict`."""
    from experiments.tools.lib.budgets import Advice, Candidate
    cal = calibration(ctx, log)
    cands = predict(scene, kind, cal, seed, log, image=image)
    return Advice(scene.name, scene.n, kind, [Candidate.from_dict(c) for c in cands], image)

