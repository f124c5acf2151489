"""``fit``: sweep one scene's one-level grid resolution, fit the Ize constants two ways (runtime
against m, Eq 1/Eq 5; runtime against the tracer's counters), print them with bootstrap CIs, R²,
MAPE, the chosen model (cross-validation + AIC), and the predicted optimum M measured against the
swept best.

``fit --timings my.csv --mesh my.obj`` fits the same model to *your own* uniform grid instead: your
trace times at a few resolutions against the work gridcost counts on the same grids
(:mod:`experiments.core.usergrid`): your Tsetup, Ts, Ti with bootstrap CIs, how well the model
explains your times (R², leave-one-resolution-out errors), your predicted best resolution, and a
constants file for ``advise --constants``."""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from costmodel.fit import CounterCostFit, GridCostFit, refine_minimum, select_model
from experiments.core.common import add_scene_args, scene_from_args
from experiments.core.store import atomic_write, write_json
from experiments.core.sweep import (FULL_FACTORS, QUICK_FACTORS, fastest, grid_cells, paired_penalties, penalty_pct,
                               sweep)
from tracer.scenes.rays import make_rays
from tracer.measure.timing import set_threads

#: the folder gathers one scene's files a run: the runner keeps the earlier runs'
#: files (experiments.run drops a whole-folder target's stale ones)
KEEPS_EARLIER_FILES = True


def add_arguments(p) -> None:
    add_scene_args(p)
    p.add_argument("--rays", type=int, default=None, help="random rays per point (default 100000; --quick 10000)")
    p.add_argument("--repeats", type=int, default=None)
    p.add_argument("--seed", type=int, default=0)
    u = p.add_argument_group("your own grid (fit --timings)")
    u.add_argument("--timings", help="CSV of your grid's trace times: cells (or nx, ny, nz), rays, seconds per row")
    u.add_argument("--kind", default="random", choices=["random", "camera", "path"],
                   help="the kind of rays you timed (gridcost counts work on rays of that kind)")
    u.add_argument("--rays-file", help="the very rays you timed: .npz with origins, directions (m x 3)")
    u.add_argument("--grid-param", action="append", default=[],
                   help="gridcost grid parameter that matches your grid, e.g. exact=false for bounding-box "
                        "insertion (repeatable)")


def _ci(c):
    return f"[{c[0]:.3g}, {c[1]:.3g}]"


def main(ctx, args) -> int:
    if args.timings:
        return _fit_timings(ctx, args)
    started = time.time()
    threads = set_threads(args.threads or 1)
    scene = scene_from_args(args)
    n_rays = args.rays or (10_000 if args.quick else 100_000)
    repeats = args.repeats or (3 if args.quick else 5)
    factors = QUICK_FACTORS if args.quick else FULL_FACTORS
    rays = {"random": make_rays(scene, "random", n_rays, seed=args.seed)}
    store = ctx.store()
    rows = sweep(scene, "grid", grid_cells(scene, factors), rays, store, repeats, desc=f"fit {scene.name}")
    df = pd.DataFrame(rows)
    sel = select_model(df.cells.values, df.anchored_ns_per_ray.values, scene.n)
    form, setup = {"eq1": ("compact", True), "eq1-no-setup": ("compact", False),
                   "eq5": ("skinny", True), "eq5-no-setup": ("skinny", False)}[sel["chosen"]]
    g = GridCostFit(form, setup).fit(df.cells, df.anchored_ns_per_ray, scene.n)
    c = CounterCostFit().fit([scene.name] * len(df), df.steps, df.tests, df.anchored_ns_per_ray)
    m_best = refine_minimum(df.cells, df.anchored_ns_per_ray)
    m_pred, m_pred_from = g.optimum(), sel["chosen"]
    if not (np.isfinite(m_pred) and m_pred > 0):  # a fitted Ts at 0 has no finite optimum: say so, use the counters
        m_pred, m_pred_from = 2.0 * scene.n * c.ti_over_ts_, "counter fit (the chosen model's optimum is not finite)"
    m_pred = float(np.clip(m_pred, df.cells.min(), df.cells.max()))
    extra = pd.DataFrame(sweep(scene, "grid", [{"cells": float(round(m_best))}, {"cells": float(round(m_pred))}],
                               rays, store, repeats, desc="fit check"))
    allrows = pd.concat([df, extra], ignore_index=True)
    t_best = allrows.anchored_ns_per_ray.min()
    t_pred = float(extra[extra.param_cells == float(round(m_pred))].anchored_ns_per_ray.iloc[0])
    # the predicted M against the three fastest swept points, timed side by side (paired rounds)
    pp = paired_penalties(scene, "grid", {"pred": {"cells": float(round(m_pred))}},
                          [{"cells": c} for c in fastest(allrows, 3)], rays["random"], store,
                          quick=args.quick)["pred"]
    out = {
        "scene": scene.name, "N": scene.n, "model": sel["chosen"], "why": sel["why"],
        "tsetup": g.tsetup_, "ts": g.ts_, "ti": g.ti_, "ti_over_ts": g.ti_over_ts_,
        "ci": g.ci_, "known": {k: g.known(k) for k in ("tsetup", "ts", "ti")},
        "r2": g.metrics_["r2"], "mape": g.metrics_["mape"], "cond": g.cond_,
        "counter_fit": {"tsetup": c.tsetup_[scene.name], "ts": c.ts_, "ti": c.ti_, "ti_over_ts": c.ti_over_ts_,
                        "ci": c.ci_, "r2": c.metrics_["r2"], "mape": c.metrics_["mape"], "cond": c.cond_},
        "m_pred": m_pred, "m_pred_from": m_pred_from, "m_best": float(allrows.loc[allrows.anchored_ns_per_ray.idxmin()].cells),
        "penalty": pp["penalty_pct"], "penalty_range": [pp["min_pct"], pp["max_pct"]],
        "penalty_swept": penalty_pct(t_pred, t_best), "candidates": sel["candidates"],
        "rays": n_rays, "threads": threads, "units": "ns per ray",
    }
    out_dir = Path(args.out) / "fit"
    ctx.write_csv(out_dir / f"{scene.name}.csv", allrows)
    write_json(out_dir / f"{scene.name}.json", out)
    atomic_write(out_dir / "summary.md", _summary(out, sel, len(df)))
    ctx.write_meta(out_dir, "fit", started, scene=scene.name, rays=n_rays, repeats=repeats, threads=threads)
    if args.json:
        json.dump(out, sys.stdout, default=float)
        print()
        return 0
    print(f"{scene.name}: N = {scene.n:,}, {len(df)} sweep points, {n_rays:,} random rays, {threads} thread(s)")
    print(f"model chosen: {sel['why']}")
    for r in sel["candidates"]:
        print(f"  {r['model']:14s} constants {r['constants']}  CV MAPE {r['cv_mape_pct']:5.1f} %  AIC {r['aic']:8.1f}  R² {r['r2']:.3f}")
    for name in ("tsetup", "ts", "ti") if g.setup else ("ts", "ti"):
        val = getattr(g, f"{name}_")
        flag = "" if g.known(name) else "   (CI spans zero: not a known number)"
        print(f"  {name:7s} = {val:8.3f} ns  95 % CI {_ci(g.ci_[name])}{flag}")
    print(f"  Ti/Ts   = {g.ti_over_ts_:8.3f}     95 % CI {_ci(g.ci_['ti_over_ts'])}   (paper: 4)   "
          f"condition number {g.cond_:.1f}, R² {g.metrics_['r2']:.3f}, MAPE {g.metrics_['mape']:.1f} %")
    print(f"  counters: Ts = {c.ts_:.2f} ns/step, Ti = {c.ti_:.2f} ns/test, Ti/Ts = {c.ti_over_ts_:.2f} "
          f"CI {_ci(c.ci_['ti_over_ts'])}, R² {c.metrics_['r2']:.3f}")
    print(f"  predicted optimum M = {m_pred:,.0f} ({m_pred / scene.n:.1f}N; {m_pred_from}), best swept M = {out['m_best']:,.0f} "
          f"({out['m_best'] / scene.n:.1f}N)")
    print(f"  penalty of the predicted M: {out['penalty']:.1f} % (re-timed side by side with the three fastest "
          f"swept M over {pp['rounds']} rounds: {pp['min_pct']:.1f} .. {pp['max_pct']:.1f} %; "
          f"from the sweep alone {out['penalty_swept']:.1f} %)")
    return 0


def _summary(out: dict, sel: dict, points: int) -> str:
    """summary.md of one fit: the chosen model and why, the constants with CIs, the predicted M and
    its paired penalty, the paper's Ti/Ts = 4 beside ours."""
    ci = out["ci"]
    lines = [f"# Fit of Ize's one-level cost (Eq 1 / Eq 5) on {out['scene']} (N = {out['N']:,})", "",
             f"{points} sweep points, {out['rays']:,} random rays, {out['threads']} thread(s); times in ns per ray "
             "(anchored: ratio to the scene's 8N grid x its stored time).", "",
             f"**Model chosen:** {out['why']}", "",
             "| model | constants | CV MAPE (%) | AIC | R² |", "|---|---|---|---|---|"]
    lines += [f"| {r['model']} | {r['constants']} | {r['cv_mape_pct']:.1f} | {r['aic']:.1f} | {r['r2']:.3f} |"
              for r in sel["candidates"]]
    lines += ["", "| constant | ours (ns) | 95 % CI | paper |", "|---|---|---|---|"]
    for k, paper in (("tsetup", "–"), ("ts", "–"), ("ti", "–"), ("ti_over_ts", "4")):
        lo, hi = ci[k]
        lines.append(f"| {k} | {out[k]:.3f} | {lo:.3f} – {hi:.3f} | {paper} |")
    lines += ["", f"Predicted optimum M = {out['m_pred']:,.0f} ({out['m_pred_from']}); best swept M = "
              f"{out['m_best']:,.0f}; penalty of the predicted M re-timed side by side with the three fastest "
              f"swept M: {out['penalty']:.1f} % (rounds {out['penalty_range'][0]:.1f} – {out['penalty_range'][1]:.1f} %)."]
    return "\n".join(lines) + "\n"


def _fit_timings(ctx, args) -> int:
    """``fit --timings``: your constants, your model error, your predicted best resolution."""
    from experiments.core.common import parse_params
    from experiments.core.usergrid import constants_record, counting_rays, fit_timings, read_timings
    started = time.time()
    timings = read_timings(args.timings)  # bad input fails before anything is built
    scene = scene_from_args(args)
    params = parse_params(args.grid_param)
    rays = counting_rays(scene, args.kind, args.seed, args.rays_file)
    res = fit_timings(timings, scene, rays, params)
    rec = constants_record(res, scene, args.kind if not args.rays_file else f"{args.kind} (your rays)", params,
                           str(args.timings))
    out_dir = Path(args.out) / "fit"
    ctx.write_csv(out_dir / f"{scene.name}-timings.csv", res["work"])
    ctx.write_csv(out_dir / f"{scene.name}-candidates.csv", res["recommendation"]["table"])
    write_json(out_dir / f"{scene.name}-constants.json", rec)
    atomic_write(out_dir / "summary.md", _timings_summary(rec))
    ctx.write_meta(out_dir, "fit", started, scene=scene.name, timings=str(args.timings), counted_rays=rays.n)
    if args.json:
        json.dump(rec, sys.stdout, default=float)
        print()
        return 0
    print(_timings_summary(rec), end="")
    print(f"constants for advise --constants: {out_dir / f'{scene.name}-constants.json'}")
    return 0


def _timings_summary(rec: dict) -> str:
    c, ci, b = rec["constants"], rec["ci"], rec["predicted_best"]
    on = rec["fitted_on"]
    lines = [f"# Your grid's cost model, fitted on {on['mesh']} (N = {on['N']:,}; {on['rows']} resolutions; "
             f"{on['rays']} rays)", "", f"Model: {rec['model']}", "",
             "| constant | fitted (ns per unit of work) | 95 % CI |", "|---|---|---|"]
    lines += [f"| {k} | {c[k] * 1e9:.3f} | {ci[k][0] * 1e9:.3f} – {ci[k][1] * 1e9:.3f} |" for k in c]
    lines += ["", f"How well it explains your times: R² {rec['r2']:.4f}, mean error {rec['mape']:.1f} % (max "
              f"{rec['max_ape']:.1f} %) on the fitted rows; leaving each resolution out in turn, "
              f"{rec['loo_mape']:.1f} % (max {rec['loo_max']:.1f} %).", "",
              "| nx | ny | nz | cells | setups | steps | tests per ray | your s/ray | fitted s/ray | left-out error % |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['nx']} | {r['ny']} | {r['nz']} | {r['cells']:,} | {r['setups']:.3f} | {r['steps']:.2f} | "
              f"{r['tests']:.2f} | {r['seconds_per_ray']:.3e} | {r['fitted_s_per_ray']:.3e} | {r['loo_error_pct']:+.1f} |"
              for r in rec["rows"]]
    rng = rec["predicted_cells_range"]
    lines += ["", f"Predicted best resolution: {b['nx']} x {b['ny']} x {b['nz']} = {b['cells']:,} cells "
              f"({b['cells'] / on['N']:.2f} N), {b['predicted_s_per_ray'] * 1e9:.1f} ns per ray"
              + (f"; the best under 5 %+ of the bootstrap's constants spans {rng[0]:,} – {rng[1]:,} cells." if rng else ".")]
    fr = rec.get("factor_range")
    if fr:
        lines.append(f"Candidates span {fr[0]:.3g} N to {fr[1]:.3g} N: the resolutions you timed, widened 2x either "
                     "way (the model is not carried further from its data).")
    return "\n".join(lines) + "\n"
