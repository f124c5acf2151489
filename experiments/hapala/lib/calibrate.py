"""Hapala 2011's calibration phase (Sec 3, steps 1-4), measured: per scene the grid's and each
hierarchy's build time and per-ray times on random and path rays, and the decision algorithm's probe
on ray samples. One stored point per scene and settings; table1h, fig1h, fig2h, selector, havran and
advise read them."""
from __future__ import annotations

import time

import numpy as np
import pandas as pd

from costmodel.select import GRID_FACTOR, PROTOCOL, SAMPLE_SIZES, havran_stats, records
from experiments.core.probes import probe_grid, single_thread, time_stats
from experiments.core.common import progress
from experiments.hapala.lib.claims import STAND_INS
KINDS = ("random", "path")
#: the hierarchies calibrated beside the grid: the paper's kd-tree, the binary BVH and gridcost's fastest
#: hierarchy (the wide BVH, 8 children with AVX2, SIMD leaves); the paper's kd-tree was the best
#: hierarchy of its day, so the selector is offered today's best as well
HIERARCHIES = ("kdtree", "bvh", "wbvh")
PROCEDURAL = ["boxes-44", "cylinder-196", "particles-2000", "sphere-2880", "cylinder-3996", "teapot-in-stadium",
              "boxes-2000", "cylinder-19996", "surfpoints-20k", "knot-56k", "sphere-87k", "particles-100k", "room",
              "conference-room"]
SPD = ["tetra-6", "sphereflake-2", "gears-3", "tree-8", "sphereflake-3"]
QUICK = ["cornell", "boxes-44", "bunny-948", "suzanne", "cylinder-196", "particles-2000", "teapot",
         "teapot-in-stadium"]


def _timed_build(scene, structure, params, repeats):
    """(structure, build seconds {median, min} of ``repeats`` builds after a warm-up, the structure's
    own build_s). Builds are timed with wall time (:data:`tracer.measure.timing.build_clock`): a library may
    build on threads the calling thread's CPU time does not see."""
    from tracer.accel import build
    from tracer.measure.timing import build_clock
    acc = build(scene, structure, **params)  # warm-up (JIT, caches); kept for tracing
    cpu, wall = [], []
    for _ in range(max(repeats, 1)):
        t0 = build_clock()
        a = build(scene, structure, **params)
        cpu.append(build_clock() - t0)
        wall.append(a.stats()["build_s"])
    return acc, time_stats(cpu), float(np.median(wall))


def build_repeats(n: int, repeats: int) -> int:
    """Timed builds per structure after the warm-up: ``repeats`` up to 100k triangles, half as many
    up to 500k, 2 above. A build of seconds varies by a few % between builds (dragon-871k's kd-tree:
    median 6.6 s, min 6.2 s of 3), while the four structures' builds of the million-triangle scenes
    take most of the calibration's time."""
    return repeats if n <= 100_000 else max(2, repeats // 2) if n <= 500_000 else min(repeats, 2)


def paired_times(fns: dict, repeats: int) -> dict:
    """Per-call time {median, min} of each function over ``repeats`` interleaved rounds
    (:func:`tracer.measure.timing.time_paired`, one sample per function per round, on the default clock), so
    that busy phases of a shared machine hit every structure alike."""
    from tracer.measure.timing import time_paired
    return {k: time_stats(v) for k, v in time_paired(fns, rounds=repeats, repeats=1).items()}


def calibrate_scene(scene, kinds=("random", "path"), n_rays: int = 10_000, samples=SAMPLE_SIZES,
                    repeats: int = 5, grid_factor: float = GRID_FACTOR, hiers=("kdtree",),
                    seed: int = 0) -> dict:
    """Calibration steps 1-4 for one scene: grid build time T_B^G (cells = grid_factor N), the
    grid's per-ray time on ``n_rays`` rays of each kind, each hierarchy's build time T_B^H and
    per-ray time t_R^H on the same rays, and the decision algorithm's probe (:func:`probe_grid`) on
    random subsets of ``samples`` rays. All times are the calling thread's CPU seconds, kept as
    median and minimum: builds over :func:`build_repeats` builds after a warm-up, ray times over
    ``repeats`` interleaved grid / hierarchy rounds over all rays."""
    with single_thread():
        return _calibrate(scene, kinds, n_rays, samples, repeats, grid_factor, hiers, seed)


def _calibrate(scene, kinds, n_rays, samples, repeats, grid_factor, hiers, seed) -> dict:
    from tracer.scenes.rays import make_rays
    t0 = time.perf_counter()
    brep = build_repeats(scene.n, repeats)
    grid, T_BG, T_BG_wall = _timed_build(scene, "grid", {"factor": grid_factor}, brep)
    gs = grid.stats()
    out = {"scene": scene.name, "N": scene.n, "grid_factor": grid_factor, "T_BG": T_BG, "T_BG_wall": T_BG_wall,
           "refs_per_tri": gs["refs_per_tri"], "grid_res": gs["res"], **havran_stats(grid), "hier": {}, "kinds": {}}
    accs = {}
    for h in hiers:
        acc, T_BH, T_BH_wall = _timed_build(scene, h, {}, brep)
        accs[h] = acc
        st = acc.stats()
        out["hier"][h] = {"T_BH": T_BH, "T_BH_wall": T_BH_wall, "nodes": st.get("nodes"), "depth": st.get("depth"),
                          "refs_per_tri": st.get("refs", 0) / max(scene.n, 1)}
    for kind in kinds:
        rays = make_rays(scene, kind, n_rays, seed=seed)
        o, d = rays.origins, rays.directions
        fns = {"grid": lambda: grid.intersect(o, d, counters=False)}
        fns.update({h: (lambda a=a: a.intersect(o, d, counters=False)) for h, a in accs.items()})
        tm = paired_times(fns, repeats)
        hits, cnt = grid.intersect(o, d, counters=True)
        m = cnt.mean()
        rec = {"rays": rays.n, "t_RG": {k: v / rays.n for k, v in tm["grid"].items()}, "box_frac_all": m["setups"],
               "hit_frac_all": float((hits.tri_id >= 0).mean()), "steps_all": m["steps"], "tests_all": m["tests"],
               "hier": {}, "samples": {}}
        for h, a in accs.items():
            _, c = a.intersect(o, d, counters=True)
            hm = c.mean()
            rec["hier"][h] = {"t_RH": {k: v / rays.n for k, v in tm[h].items()}, "nodes": hm["nodes"],
                              "leaves": hm["steps"], "tests": hm["tests"]}
        for j, s in enumerate(samples):
            if s <= rays.n:
                idx = np.random.default_rng(seed + 1 + j).permutation(rays.n)[:s]
                rec["samples"][str(s)] = probe_grid(grid, rays, idx=idx)
        out["kinds"][kind] = rec
    out["seconds"] = time.perf_counter() - t0
    return out


def load_any(name: str):
    """A named scene (mesh, procedural or SPD: one registry, :func:`tracer.scenes.scene.load_scene`) or a path."""
    from tracer.scenes.scene import load_scene
    return load_scene(name)


def default_scenes(quick: bool) -> list[str]:
    """--quick: :data:`QUICK`; else every named mesh, the procedural and SPD scenes and the stand-ins
    matched to the paper's scenes (:data:`experiments.hapala.lib.claims.STAND_INS`)."""
    if quick:
        return list(QUICK)
    from tracer.scenes.scene import manifest
    return sorted(manifest()) + PROCEDURAL + SPD + list(STAND_INS)


def settings(args) -> dict:
    quick = bool(getattr(args, "quick", False))
    return {"rays": getattr(args, "rays", None) or (2_000 if quick else 10_000),
            "repeats": getattr(args, "repeats", None) or (3 if quick else 7),
            "grid_factor": float(getattr(args, "grid_factor", None) or GRID_FACTOR),
            "seed": int(getattr(args, "seed", 0) or 0),
            "samples": [s for s in SAMPLE_SIZES if s <= (getattr(args, "rays", None) or (2_000 if quick else 10_000))],
            "hiers": list(HIERARCHIES)}
#: the code (beside tracer/) that shapes a stored calibration point: the measuring, the probe and Havran's
#: statistics; the selector's constants that shape it (grid factor, sample sizes, protocol) are in the key
MEASURE_CODE = ("experiments/hapala/lib/calibrate.py", "experiments/core/probes.py", "costmodel/havran.py")


def calibrate_named(name: str, cfg: dict) -> dict:
    """:func:`calibrate_scene` of a named scene with the settings ``cfg`` (one task of the run)."""
    scene = load_any(name)
    return calibrate_scene(scene, KINDS, cfg["rays"], cfg["samples"], cfg["repeats"], cfg["grid_factor"],
                           tuple(cfg["hiers"]), cfg["seed"])


def measure_all(ctx, names, cfg: dict, log=print, repeat_pass: int = 1) -> list[dict]:
    """Calibrate every scene (resumable: one stored point per scene and settings, keyed by the
    measurement key of :class:`experiments.core.store.PointStore`); ``repeat_pass`` > 1 measures the
    same again as an independent retest."""
    store = ctx.store(code=MEASURE_CODE)
    raw = []
    for i, name in enumerate(progress(names, "table1h calibration", quiet=log is not print)):
        key = {"target": "table1h", "scene": name, "kinds": list(KINDS), "protocol": PROTOCOL, **cfg}
        if repeat_pass > 1:
            key["pass"] = repeat_pass
        t0 = time.perf_counter()
        row, cached = store.measure(key, calibrate_named, name, cfg)
        log(f"[{i + 1}/{len(names)}] {name}: N={row['N']:,} {'(stored)' if cached else f'{time.perf_counter() - t0:.1f} s'}")
        raw.append(dict(row, provenance=store.provenance(key)))
    return raw


def retest(raw, raw2) -> pd.DataFrame:
    """Test-retest of two independent calibrations: per hierarchy and ray kind, the median |log ratio|
    of each time, the share of scenes whose outcome (R_C finite or not) agrees, and Err of the second
    R_C against the first (the floor any estimator is judged against)."""
    from costmodel.select import rc_error
    rows = []
    for h in ("kdtree", "bvh"):
        a, b = records(raw, hier=h), records(raw2, hier=h)
        m = a.merge(b, on=["scene", "kind"], suffixes=("_a", "_b"))
        for kind in KINDS:
            k = m[m.kind == kind]
            if not len(k):
                continue
            e = rc_error(k.R_C_b, k.R_C_a)
            e = e[np.isfinite(e)]
            row = {"hier": h, "kind": kind, "scenes": len(k),
                   "outcome_agree": float((np.isfinite(k.R_C_a) == np.isfinite(k.R_C_b)).mean()),
                   "n_err": int(e.size), "mean_abs_err": float(np.abs(e).mean()) if e.size else np.nan,
                   "median_abs_err": float(np.median(np.abs(e))) if e.size else np.nan}
            for q in ("T_BG", "T_BH", "t_RG", "t_RH", "t_RG_sample"):
                row[f"{q}_pct"] = 100 * float(np.median(np.abs(np.log(k[f"{q}_b"] / k[f"{q}_a"]))))
            rows.append(row)
    return pd.DataFrame(rows)
