"""``wald-fig6``: Wald et al. 2006 Fig 6 — render time of coherent grid traversal (8 x 8 packets,
camera rays, one pinned thread), normalised to each scene's best, against the grid resolution
factor lambda (n_x = d_x (lambda N / V)^(1/3)) from 0.5 to 20. The paper: "nearly all tested scenes
... reach their optimum at approximately lambda = 5".

Beside the measured optimum: the packet cost model (:mod:`costmodel.packet`; T_setup + slices
T_slice + cells T_cell + tests T_test per packet) fitted leave-one-scene-out — the constants come
from the other scenes' sweeps, the scene's own counted work per lambda (a counting traversal, no
timing) gives the predicted curve and the predicted best lambda.

Also holds the measurement helpers the other Wald targets share (one timed point: build, warm-up,
median of >= 5 repeats, and the per-packet work of the same rays).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from costmodel.papers import wald2006
from experiments.core.common import scene_list
from experiments.core.store import atomic_write
from experiments.core.common import progress
from experiments.wald.lib.packets import constants_table, fit_note, loso_predictions, measure_points, pooled_fit
from tracer.scenes.scene import load_scene
from tracer.measure.timing import set_threads

LAMBDAS = (0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0)
QUICK_LAMBDAS = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
SCENES = ["bunny-3851", "bunny-16k", "bunny-69k", "dragon-11k", "dragon-48k", "cornell-sphere"]
QUICK_SCENES = ["bunny-948", "cornell"]
#: the paper's reading of its Fig 6
PAPER_LAMBDA = wald2006.LAMBDA.value
# ---------------------------------------------------------------- the target
def add_arguments(p) -> None:
    p.add_argument("--scenes", default=None, help="comma-separated scenes")
    p.add_argument("--side", type=int, default=None, help="image side in pixels (default 512; --quick 128)")
    p.add_argument("--repeats", type=int, default=None, help="timed rounds per point (default 9; --quick 5)")
    p.add_argument("--packet", type=int, default=8, help="packet size k (k x k rays)")


def run(ctx, args, log=print) -> dict:
    started = time.time()
    threads = set_threads(args.threads or 1)
    quick = args.quick
    names = scene_list(args, QUICK_SCENES, SCENES)
    side = args.side or (128 if quick else 512)
    repeats = args.repeats or (5 if quick else 9)  # the curves are flat: more rounds against load noise
    lams = QUICK_LAMBDAS if quick else LAMBDAS
    out_dir = Path(args.out) / "wald-fig6"
    store = ctx.store(code=("experiments/wald/lib/packets.py",))
    rows = []
    for name in progress(names, "wald-fig6", quiet=getattr(args, "json", False)):
        scene = load_scene(name)
        rows += measure_points(store, "wald-fig6", scene, [{"lam": float(lam), "packet": args.packet} for lam in lams],
                               side, repeats, threads, log)
    df = pd.DataFrame(rows)
    df["normalised"] = df.ns_per_ray / df.groupby("scene").ns_per_ray.transform("min")
    pred, best = loso_predictions(df, "lam")
    df = df.merge(pred[["scene", "lam", "predicted"]], on=["scene", "lam"], how="left")
    fit = pooled_fit(df)
    ctx.write_csv(out_dir / "fig6.csv", df)
    ctx.write_csv(out_dir / "best.csv", best)
    ctx.write_csv(out_dir / "constants.csv", pd.DataFrame([{"name": n, "value": v, "ci_lo": fit.ci_[n][0], "ci_hi": fit.ci_[n][1]}
                                                       for n, v in fit.constants_.items()]))
    md = _summary(df, best, fit, side, repeats, threads, args.packet)
    atomic_write(out_dir / "summary.md", md)
    _figure(ctx, df)
    ctx.write_meta(out_dir, "wald-fig6", started, threads=threads, side=side, repeats=repeats, scenes=names,
               lambdas=list(lams), packet=args.packet, quick=quick)
    log(md)
    return {"table": df, "best": best}


def _summary(df, best, fit, side, repeats, threads, k) -> str:
    lines = [f"# Fig 6 (Wald et al. 2006): render time against lambda, {k}x{k} packets", "",
             f"Camera rays {side}x{side} (tile order), coherent grid traversal with macrocells (M = 6), "
             f"median of {repeats} interleaved rounds, {threads} thread(s); time normalised to each scene's best lambda "
             f"(median spread (max - min) / median of the rounds: {df.spread.median():.0%}).", "",
             "| scene | N | measured best lambda | time at lambda = 5 / best | cost-model best lambda (LOSO) | "
             "its penalty | LOSO MAPE |", "|---|---|---|---|---|---|---|"]
    for _, b in best.iterrows():
        d = df[df.scene == b.scene]
        at5 = d.loc[(d.lam - 5.0).abs().idxmin()]
        lines.append(f"| {b.scene} | {int(d.N.iloc[0]):,} | {b.measured_best_lam:g} | {at5.normalised:.2f} | "
                     f"{b.predicted_best_lam:g} | {b.penalty_of_predicted_pct:.1f}% | {b.loso_mape_pct:.1f}% |")
    lines += ["", "| scene | " + " | ".join(f"λ={lam:g}" for lam in sorted(df.lam.unique())) + " |",
              "|---|" + "---|" * df.lam.nunique()]
    for name, d in df.groupby("scene", sort=False):
        d = d.sort_values("lam")
        lines.append(f"| {name} | " + " | ".join(f"{v:.2f}" for v in d.normalised) + " |")
    med = float(np.median(best.measured_best_lam))
    lines += ["", "Pooled packet cost model (ns; per packet T_setup, per slice, per cell visited, per SIMD lane of a "
              "ray-triangle test, per ray):", "", constants_table(fit), "", fit_note(df),
              "", "## Reading", "",
              f"Paper: the optimum sits near lambda = {PAPER_LAMBDA:g} for nearly all scenes and the curves are flat "
              f"around it. Ours: median measured optimum lambda = {med:g}; the normalised curves above show how flat "
              "the optimum is (values within a few per cent of 1.00 are within timing noise on a shared machine). "
              "Cost-model predictions use constants fitted on the other scenes only. With one packet size, packets per "
              "ray are the same at every point, so T_setup and T_ray cannot be told apart here (wald-fig7 separates them)."]
    return "\n".join(lines) + "\n"


def _figure(ctx, df):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(8, 3.0))
    for name, d in df.groupby("scene", sort=False):
        d = d.sort_values("lam")
        line, = axes[0].plot(d.lam, d.normalised, "o-", ms=3, lw=1, label=name)
        axes[1].plot(d.lam, d.ns_per_ray, "o-", ms=3, lw=1, color=line.get_color())
        axes[1].plot(d.lam, d.predicted, ":", lw=1, color=line.get_color())
    for ax in axes:
        ax.set_xscale("log")
        ax.axvline(PAPER_LAMBDA, color="k", ls="--", lw=0.8)
        ax.set_xlabel("λ (cells per triangle)")
        ax.tick_params(labelsize=7)
    axes[0].set_ylabel("time / best time")
    axes[1].set_ylabel("ns per ray (dotted: cost model, LOSO)")
    axes[0].legend(fontsize=6)
    ctx.finish_figure(fig, "wald-fig6")


def main(ctx, args) -> int:
    run(ctx, args, log=(lambda *a: None) if args.json else print)
    return 0
