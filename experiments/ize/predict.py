"""``predict``: cross-scene prediction with the counter cost model. For each scene of the table2
sweeps held out in turn, fit T = Tsetup + Ts·steps + Ti·tests on the other scenes (one pooled Ts, Ti),
predict the held-out runtime curve from its counters (Tsetup: mean of the training scenes, or
calibrated on one measured point), report MAPE per held-out scene and the penalty of the predicted
optimum M; then chart prediction error against calibration cost (scenes and sweep points used)."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from costmodel.fit import CounterCostFit
from experiments.core.store import atomic_write


def add_arguments(p) -> None:
    p.add_argument("--seed", type=int, default=0)


def _rows(ctx, args) -> pd.DataFrame:
    path = Path(args.out) / "table2" / "table2.csv"
    if not path.exists():
        from experiments.ize import table2 as ize_table2
        ize_table2.run(ctx, argparse.Namespace(**{**vars(args), "scenes": None, "rays": None, "repeats": None}),
                       log=lambda *a: None)
    return pd.read_csv(path)


def holdout(df: pd.DataFrame, test: str, train: list[str], points: int | None = None, seed: int = 0,
            calibrate_setup: bool = True) -> dict:
    rng = np.random.default_rng(seed)
    tr = df[df.scene.isin(train)]
    if points:
        keep = []
        for _, g in tr.groupby("scene"):
            keep += list(g.index[np.sort(rng.choice(len(g), min(points, len(g)), replace=False))])
        tr = tr.loc[keep]
    fit = CounterCostFit(n_boot=0).fit(tr.scene.tolist(), tr.steps, tr.tests, tr.anchored_ns_per_ray)
    te = df[df.scene == test].sort_values("cells")
    work = fit.ts_ * te.steps.values + fit.ti_ * te.tests.values
    if calibrate_setup:  # one measured point of the new scene (its median-M point) fixes Tsetup
        j = len(te) // 2
        setup = te.anchored_ns_per_ray.values[j] - work[j]
    else:
        setup = float(np.mean(list(fit.tsetup_.values())))
    pred = setup + work
    ape = np.abs(pred - te.anchored_ns_per_ray.values) / te.anchored_ns_per_ray.values
    i_pred = int(np.argmin(pred))
    return {"scene": test, "train": ",".join(train), "points": points or "all", "mape_pct": float(ape.mean() * 100),
            "m_pred": float(te.cells.values[i_pred]), "m_best": float(te.cells.values[np.argmin(te.anchored_ns_per_ray.values)]),
            "penalty_pct": float(100 * (te.anchored_ns_per_ray.values[i_pred] / te.anchored_ns_per_ray.min() - 1)),
            "ts": fit.ts_, "ti": fit.ti_, "calibrated_setup": calibrate_setup}


def main(ctx, args) -> int:
    started = time.time()
    df = _rows(ctx, args)
    df = df[(df.ray_kind == "random") & (df.structure == "grid")]
    scenes = list(dict.fromkeys(df.scene))
    if len(scenes) < 2:
        from tracer.errors import GridcostError
        raise GridcostError("cross-scene prediction needs table2 sweeps of at least two scenes")
    loo = [holdout(df, s, [t for t in scenes if t != s], calibrate_setup=c) for s in scenes for c in (True, False)]
    loo = pd.DataFrame(loo)
    # calibration cost: number of training scenes x sweep points per scene
    rng = np.random.default_rng(args.seed)
    cost = []
    for c in range(1, len(scenes)):
        for pts in (3, 5, 8, None):
            for rep in range(10):
                test = scenes[rep % len(scenes)]
                others = [t for t in scenes if t != test]
                train = list(rng.choice(others, c, replace=False))
                r = holdout(df, test, train, pts, seed=rep)
                cost.append({**r, "n_train": c, "rep": rep})
    cost = pd.DataFrame(cost)
    out_dir = Path(args.out) / "predict"
    ctx.write_csv(out_dir / "loo.csv", loo)
    ctx.write_csv(out_dir / "calibration_cost.csv", cost)
    cal = loo[loo.calibrated_setup]
    lines = ["# Cross-scene prediction with the counter cost model", "",
             "Leave one scene out: Ts and Ti fitted on the other scenes' sweeps (random rays), the held-out runtime "
             "curve predicted from its counters. 'one point' = Tsetup of the new scene from one measured point; "
             "'none' = mean Tsetup of the training scenes.", "",
             "| held-out scene | MAPE (one point) | MAPE (none) | predicted M | best M | penalty of predicted M |",
             "|---|---|---|---|---|---|"]
    for s in scenes:
        a = loo[(loo.scene == s) & loo.calibrated_setup].iloc[0]
        b = loo[(loo.scene == s) & ~loo.calibrated_setup].iloc[0]
        lines.append(f"| {s} | {a.mape_pct:.1f}% | {b.mape_pct:.1f}% | {a.m_pred:,.0f} | {a.m_best:,.0f} | {a.penalty_pct:.1f}% |")
    lines += ["", f"Mean MAPE over held-out scenes: {cal.mape_pct.mean():.1f} % (one calibration point), "
              f"{loo[~loo.calibrated_setup].mape_pct.mean():.1f} % (none). Worst penalty of the predicted M: "
              f"{cal.penalty_pct.max():.1f} %.", "",
              "Speed vs accuracy: `paper_figs/predict.png` plots the held-out MAPE against the number of calibration "
              "scenes and sweep points per scene (mean of 10 random choices)."]
    md = "\n".join(lines) + "\n"
    atomic_write(out_dir / "summary.md", md)
    _figure(ctx, cost)
    ctx.write_meta(out_dir, "predict", started, scenes=scenes, seed=args.seed)
    if args.json:
        json.dump({"loo": loo.to_dict(orient="records"), "mean_mape_pct": float(cal.mape_pct.mean())}, sys.stdout,
                  default=float)
        print()
    else:
        print(md)
    return 0


def _figure(ctx, cost):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(4, 3))
    for pts, g in cost.groupby(cost.points.astype(str)):
        m = g.groupby("n_train").mape_pct.mean()
        ax.plot(m.index, m.values, "o-", ms=3, label=f"{pts} points/scene")
    ax.set_xlabel("calibration scenes")
    ax.set_ylabel("held-out MAPE (%)")
    ax.legend(fontsize=7)
    ctx.finish_figure(fig, "predict")
