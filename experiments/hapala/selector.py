"""``selector``: Hapala 2011's decision for one scene and a ray budget — build the uniform grid, sample
its per-ray time, estimate the kd-tree's build and per-ray time from the calibration (table1h's
measurements, or a quick built-in calibration of a few small scenes when they are missing), and keep
the grid (R <= R_C) or build the kd-tree (R > R_C).

    python -m experiments.run selector --scene bunny-948 --rays 1000000 [--json]

Without ``--scene`` (as in ``all``) it evaluates the decision: for each of a few scenes, the
selector is calibrated on table1h's other scenes (leave that scene out), runs its 8 steps on a freshly
built grid for R = 10^4, 10^6, 10^8 rays, and is scored against the scene's measured truth (table1h's
stored calibration of it): the right pick or not, and the time a wrong pick loses.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import pandas as pd

from costmodel.select import DEFAULT_SAMPLE, GRID_FACTOR, GridcostEstimator, HapalaEstimator, Selector, records
from experiments.core.common import emit_json
from experiments.core.probes import decide, probe
from experiments.core.store import atomic_write
from costmodel.papers import hapala2011
from experiments.hapala.lib.calibrate import load_any, measure_all
from tracer.accel.constants import HAPALA_EPS
from tracer.errors import GridcostError

#: the built-in calibration when results/table1h is missing: small scenes, few rays (seconds)
BUILTIN = ["cornell", "boxes-44", "bunny-948", "cylinder-196", "particles-2000", "teapot"]
ESTIMATORS = {"gridcost": GridcostEstimator, "hapala": HapalaEstimator}


#: scenes the decision is evaluated on without --scene (each left out of its own calibration)
EVAL_SCENES = ["bunny-69k", "dragon-48k", "sphere-87k", "cylinder-19996", "teapot-in-stadium", "particles-100k"]
QUICK_EVAL = ["bunny-948", "cylinder-196", "teapot"]
EVAL_RAYS = (1e4, 1e6, 1e8)


def add_arguments(p) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--mesh", help="path of a mesh file (OBJ, PLY, OFF, STL, GLB)")
    g.add_argument("--scene", default=None, help="named scene (without --scene/--mesh: evaluate on several scenes)")
    p.add_argument("--rays", type=float, default=None, help="number of rays R the application will shoot")
    p.add_argument("--kind", choices=("random", "path"), default="random",
                   help="ray kind to sample and calibrate on (default random)")
    p.add_argument("--estimator", choices=tuple(ESTIMATORS), default="gridcost",
                   help="gridcost (ours, default) or hapala (the paper's Eq 7/8)")
    p.add_argument("--sample-rays", type=int, default=DEFAULT_SAMPLE, help="rays sampled on the grid (default 1000)")
    p.add_argument("--eps", type=float, default=HAPALA_EPS)
    p.add_argument("--seed", type=int, default=0)


def calibration(ctx, out, quick: bool, log=print):
    """(records, source): table1h's raw measurements, else the built-in quick calibration (stored
    under ``out``/points, so a second call is instant)."""
    raw_path = Path(out) / "table1h" / "raw.json"
    if raw_path.exists():
        return records(json.loads(raw_path.read_text())), str(raw_path)
    cfg = {"rays": 1000, "repeats": 2, "grid_factor": GRID_FACTOR, "seed": 0, "samples": [100, 300, 1000],
           "hiers": ["kdtree"]}
    raw = measure_all(ctx, BUILTIN, cfg, log=log)
    return records(raw), f"built-in quick calibration ({len(BUILTIN)} small scenes, 1,000 rays per kind)"


def run(ctx, args, log=print) -> dict:
    from tracer.scenes.scene import load_mesh
    from tracer.measure.timing import set_threads
    started = time.time()
    if args.rays < 0:
        raise GridcostError(f"--rays must be >= 0, got {args.rays:g}")
    set_threads(args.threads or 1)
    scene = load_mesh(args.mesh) if args.mesh else load_any(args.scene)
    cal, source = calibration(ctx, args.out, args.quick, log=log)
    sel = Selector(ESTIMATORS[args.estimator](), eps=args.eps, sample_rays=args.sample_rays, kind=args.kind,
                   seed=args.seed).fit(cal)
    out = decide(sel, scene, args.rays)
    out.update({"kind": args.kind, "calibration": source, "calibration_scenes": sel.n_calib_,
                "seconds": round(time.time() - started, 3)})
    return out


def evaluate(ctx, args, log=print) -> pd.DataFrame:
    """The decision on each evaluation scene (left out of its own calibration) against its measured truth."""
    from experiments.hapala.lib.calibrate import settings
    from tracer.measure.timing import set_threads
    started = time.time()
    set_threads(args.threads or 1)
    names = QUICK_EVAL if args.quick else EVAL_SCENES
    cfg = dict(settings(argparse.Namespace(quick=args.quick, rays=None, repeats=None, grid_factor=None, seed=0)))
    truth = records(measure_all(ctx, names, cfg, log=log))
    cal, source = calibration(ctx, args.out, args.quick, log=log)
    rows = []
    for name in names:
        t = truth[(truth.scene == name) & (truth.kind == args.kind)].iloc[0]
        sel = Selector(ESTIMATORS[args.estimator](), eps=args.eps, sample_rays=args.sample_rays, kind=args.kind,
                       seed=args.seed).fit(cal[cal.scene != name])
        _, feats = probe(sel, load_any(name))
        for R in EVAL_RAYS:
            d = sel.decide_features(feats, R)
            grid_total, hier_total = t.T_BG + R * t.t_RG, t.T_BH + R * t.t_RH
            best = "grid" if grid_total <= hier_total else "kdtree"
            picked_total = grid_total if d["choice"] == "grid" else hier_total
            rows.append({"scene": name, "N": int(t.N), "ray_kind": args.kind, "R": R, "pick": d["choice"],
                         "best": best, "correct": d["choice"] == best, "rc_est": d["rc_est"], "rc_true": t.R_C,
                         "time_lost_pct": 100 * (picked_total / min(grid_total, hier_total) - 1),
                         "calibration_scenes": sel.n_calib_, "estimator": d["estimator"]})
    df = pd.DataFrame(rows)
    out_dir = Path(args.out) / "selector"
    ctx.write_csv(out_dir / "selector.csv", df)
    lines = [f"# selector: Hapala 2011's decision, evaluated ({args.kind} rays)", "",
             f"Each scene is left out of its own calibration ({source}); the selector builds the grid, samples "
             f"{args.sample_rays:,} rays and decides for R rays; truth = the scene's measured build and per-ray times "
             "(table1h's calibration of it). Paper: it prints no share of correct picks and no time lost; its "
             f"Figs 1-2 give the R_C estimate's average error: {_paper_error()}.", "",
             "| scene | N | R | pick | best | R_C estimated | R_C measured | time lost (%) |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['N']:,} | {r['R']:.0e} | {r['pick']} | {r['best']} | {r['rc_est']:,.0f} | "
                     f"{r['rc_true']:,.0f} | {r['time_lost_pct']:.1f} |")
    lines += ["", f"Correct picks: {int(df.correct.sum())} of {len(df)}; mean time lost {df.time_lost_pct.mean():.1f} %."]
    atomic_write(out_dir / "summary.md", "\n".join(lines) + "\n")
    ctx.write_meta(out_dir, "selector", started, scenes=names, rays=list(EVAL_RAYS), kind=args.kind)
    log("\n".join(lines))
    return df


def _paper_error() -> str:
    """The paper's own reading of its Figs 1-2, from :mod:`costmodel.papers.hapala2011`."""
    e = hapala2011.ESTIMATE_ERROR
    return (f"about {e['random'].value:g} % for random rays, optimistic about the grid ({e['random'].where}), and around "
            f"{e['path'].value:g} % for path rays ({e['path'].where})")


def main(ctx, args) -> int:
    if not args.scene and not args.mesh:
        if args.rays is not None:
            raise GridcostError("--rays needs --scene or --mesh (without them selector evaluates R = 1e4, 1e6, 1e8)")
        df = evaluate(ctx, args, log=(lambda *a: None) if args.json else print)
        if args.json:
            emit_json({"correct": int(df.correct.sum()), "decisions": len(df),
                       "mean_time_lost_pct": float(df.time_lost_pct.mean())})
        return 0
    if args.rays is None:
        raise GridcostError("--rays R is required with --scene/--mesh")
    res = run(ctx, args, log=(lambda *a: None) if args.json else print)
    if args.json:
        inf = res["rc_est"] == float("inf")
        emit_json({**res, "rc_est": None if inf else res["rc_est"], "rc_est_infinite": inf})
        return 0
    rc = res["rc_est"]
    rc_s = "∞ (the grid is faster per ray)" if rc == float("inf") else f"{rc:,.0f} rays"
    print(f"scene {res['scene']} (N = {res['N']:,}), R = {res['n_rays']:,.0f} {res['kind']} rays")
    print(f"  grid build T_B^G = {res['t_build_grid'] * 1e3:.2f} ms (measured), "
          f"t_R^G = {res['t_grid'] * 1e6:.3f} us/ray (estimated from {args.sample_rays:,} sampled rays, which took "
          f"{res['t_grid_sampled'] * 1e6:.3f} us/ray)")
    print(f"  kd-tree estimate: T_B^H = {res['t_build_hier'] * 1e3:.2f} ms, t_R^H = {res['t_hier'] * 1e6:.3f} us/ray "
          f"[{res['estimator']}; {res['calibration_scenes']} calibration scenes]")
    print(f"  R_C = {rc_s} -> step {res['step']}: use the {'uniform grid' if res['choice'] == 'grid' else res['choice']}")
    return 0
