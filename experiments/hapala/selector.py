"""``selector``: Hapala 2011's decision for one scene and a ray budget — build the uniform grid, sample
its per-ray time, estimate the kd-tree's build and per-ray time from the calibration (table1h's
measurements, or a quick built-in calibration of a few small scenes when they are missing), and keep
the grid (R <= R_C) or build the kd-tree (R > R_C).

    python -m experiments.run selector --scene bunny-948 --rays 1000000 [--json]

Without ``--scene`` (as in ``all``) it evaluates the decision on every scene table1h calibrated: each
scene is left out of its own calibration, decided from its sampled grid time at ray budgets from 10^4
to 10^9 for each hierarchy (kd-tree, BVH, wide BVH) and estimator (gridcost's, the paper's), and scored
against "always grid", "always hierarchy" and the oracle: correct picks and the time a wrong pick
loses. Its truth and R_C are table1h's records, so the two agree.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import pandas as pd

from costmodel.select import (DEFAULT_SAMPLE, EVAL_R, GRID_FACTOR, GridcostEstimator, HapalaEstimator, Selector,
                              loo_decisions, policy_scores, records, step5_diagnosis)
from experiments.core.common import emit_json
from experiments.core.probes import decide
from experiments.core.store import atomic_write
from costmodel.papers import hapala2011
from experiments.hapala.lib.calibrate import HIERARCHIES, load_any, measure_all
from tracer.accel.constants import HAPALA_EPS
from tracer.errors import GridcostError

#: the built-in calibration when results/table1h is missing: small scenes, few rays (seconds)
BUILTIN = ["cornell", "boxes-44", "bunny-948", "cylinder-196", "particles-2000", "teapot"]
ESTIMATORS = {"gridcost": GridcostEstimator, "hapala": HapalaEstimator}




def add_arguments(p) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--mesh", help="path of a mesh file (OBJ, PLY, OFF, STL, GLB)")
    g.add_argument("--scene", default=None, help="named scene (without --scene/--mesh: evaluate on several scenes)")
    p.add_argument("--rays", type=float, default=None, help="number of rays R the application will shoot")
    p.add_argument("--kind", choices=("random", "path"), default="random",
                   help="ray kind to sample and calibrate on (default random)")
    p.add_argument("--hierarchy", choices=HIERARCHIES, default="wbvh",
                   help="the hierarchy the selector may build instead of the grid (default wbvh, gridcost's fastest)")
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
        raw = json.loads(raw_path.read_text())
        return pd.concat([records(raw, hier=h) for h in HIERARCHIES], ignore_index=True), str(raw_path)
    cfg = {"rays": 1000, "repeats": 2, "grid_factor": GRID_FACTOR, "seed": 0, "samples": [100, 300, 1000],
           "hiers": list(HIERARCHIES)}
    raw = measure_all(ctx, BUILTIN, cfg, log=log)
    return pd.concat([records(raw, hier=h) for h in HIERARCHIES], ignore_index=True), f"built-in quick calibration ({len(BUILTIN)} small scenes, 1,000 rays per kind)"


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
                   hier=args.hierarchy, seed=args.seed).fit(cal)
    out = decide(sel, scene, args.rays)
    out.update({"kind": args.kind, "calibration": source, "calibration_scenes": sel.n_calib_,
                "seconds": round(time.time() - started, 3)})
    return out


def evaluate(ctx, args, log=print) -> pd.DataFrame:
    """The decision on every calibrated scene, each left out of its own calibration, at ray budgets from
    10^4 to 10^9, for each hierarchy and estimator, against "always grid", "always hierarchy" and the
    oracle (plan: table1h's records; analysis: :func:`costmodel.select.loo_decisions`)."""
    started = time.time()
    cal, source = calibration(ctx, args.out, args.quick, log=log)
    frames, scores, diag = [], [], []
    for (hier, kind), c in cal.groupby(["hier", "kind"], sort=False):
        for name, est in ESTIMATORS.items():
            d = loo_decisions(c, est)
            d.insert(0, "hierarchy", hier), d.insert(1, "ray_kind", kind), d.insert(2, "estimator", name)
            frames.append(d)
            s = policy_scores(d)
            s.insert(0, "hierarchy", hier), s.insert(1, "ray_kind", kind), s.insert(2, "estimator", name)
            scores.append(s)
            diag.append({"hierarchy": hier, "ray_kind": kind, "estimator": name, **step5_diagnosis(c, est)})
    df, sc, dg = pd.concat(frames, ignore_index=True), pd.concat(scores, ignore_index=True), pd.DataFrame(diag)
    out_dir = Path(args.out) / "selector"
    ctx.write_csv(out_dir / "selector.csv", df)
    ctx.write_csv(out_dir / "scores.csv", sc)
    ctx.write_csv(out_dir / "step5.csv", dg)
    text = report(sc, dg, source, int(cal.scene.nunique()))
    atomic_write(out_dir / "summary.md", text)
    ctx.write_meta(out_dir, "selector", started, scenes=sorted(cal.scene.unique()), rays=list(EVAL_R),
                   calibration=source)
    log(text)
    return sc


def best_estimator(scores: pd.DataFrame) -> str:
    """The estimator whose held-out decisions lose the least time, over every hierarchy and ray kind."""
    sel = scores[scores.policy == "selector"]
    return str(sel.groupby("estimator")["lost_mean_pct"].mean().idxmin())


def report(scores: pd.DataFrame, diag: pd.DataFrame, source: str, n_scenes: int) -> str:
    """summary.md from the analysis' frames (no number typed: paper values from costmodel.papers)."""
    lines = ["# selector: Hapala 2011's decision against its baselines", "",
             f"Every one of the {n_scenes} calibrated scenes ({source}) is left out of its own calibration; the "
             "selector decides from the grid's sampled per-ray time and the estimated hierarchy times, at "
             f"{len(EVAL_R)} ray budgets from {EVAL_R[0]:.0e} to {EVAL_R[-1]:.0e}. Truth: the scene's measured build "
             "and per-ray times, the same records as table1h, so every R_C here is table1h's. Paper: it prints no "
             f"share of correct picks and no time lost; its Figs 1-2 give the R_C estimate's average error: {_paper_error()}.",
             "", f"Best held-out estimator (least mean time lost): **{best_estimator(scores)}** (the default).", "",
             "| hierarchy | rays | estimator | selector: correct / mean lost / worst | always grid | always hierarchy |",
             "|---|---|---|---|---|---|"]
    for (h, k, e), g in scores.groupby(["hierarchy", "ray_kind", "estimator"], sort=False):
        p = g.set_index("policy")
        cell = lambda q: (f"{p.loc[q, 'correct_pct']:.0f} % / {p.loc[q, 'lost_mean_pct']:.1f} % / "
                          f"{p.loc[q, 'lost_max_pct']:.0f} %")
        lines.append(f"| {h} | {k} | {e} | {cell('selector')} | {cell('always grid')} | {cell('always hierarchy')} |")
    lines += ["", "## Why step 5 fired everywhere with the paper's estimator", "",
              "Step 5 keeps the grid when the estimated t_R^H is at least t_R^G. Two things make it fire: the margin "
              "is small here (median measured t_R^G / t_R^H below), so an estimate a little high flips it; and Eq 8's "
              "constant is a mean of t_R^H / log2 N over the calibration scenes, which the few scenes where the "
              "hierarchy is much slower than the grid (long skinny cylinders, scattered particles) pull far above its "
              "median, so the paper's estimate of t_R^H is high for every typical scene.", "",
              "| hierarchy | rays | estimator | step 5 fires | median t_R^G / t_R^H | hierarchy slower per ray | "
              "Eq 8 constant mean / median (ns) | est / true t_R^H (median) |", "|---|---|---|---|---|---|---|---|"]
    for r in diag.itertuples():
        lines.append(f"| {r.hierarchy} | {r.ray_kind} | {r.estimator} | {r.step5_share:.0%} of {r.scenes} | "
                     f"{r.median_tG_over_tH:.2f} | {r.hier_slower_share:.0%} | {r.eq8_k_mean * 1e9:.1f} / "
                     f"{r.eq8_k_median * 1e9:.1f} | {r.median_est_over_true_tH:.2f} |")
    return "\n".join(lines) + "\n"


def _paper_error() -> str:
    """The paper's own reading of its Figs 1-2, from :mod:`costmodel.papers.hapala2011`."""
    e = hapala2011.ESTIMATE_ERROR
    return (f"about {e['random'].value:g} % for random rays, optimistic about the grid ({e['random'].where}), and around "
            f"{e['path'].value:g} % for path rays ({e['path'].where})")


def main(ctx, args) -> int:
    if not args.scene and not args.mesh:
        if args.rays is not None:
            raise GridcostError("--rays needs --scene or --mesh (without them selector evaluates R = 1e4, 1e6, 1e8)")
        sc = evaluate(ctx, args, log=(lambda *a: None) if args.json else print)
        if args.json:
            emit_json({"best_estimator": best_estimator(sc), "scores": sc.to_dict(orient="records")})
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
    print(f"  {args.hierarchy} estimate: T_B^H = {res['t_build_hier'] * 1e3:.2f} ms, t_R^H = {res['t_hier'] * 1e6:.3f} us/ray "
          f"[{res['estimator']}; {res['calibration_scenes']} calibration scenes]")
    print(f"  R_C = {rc_s} -> step {res['step']}: use the {'uniform grid' if res['choice'] == 'grid' else res['choice']}")
    return 0
