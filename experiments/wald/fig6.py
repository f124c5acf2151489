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

from costmodel.packet import PacketCostFit, best_config
from experiments.core.common import scene_list
from experiments.core.store import atomic_write
from experiments.core.common import progress
from tracer.accel.packet import CoherentGrid
from tracer.scenes.rays import camera_rays
from tracer.scenes.scene import load_scene
from tracer.measure.timing import set_threads, time_paired

LAMBDAS = (0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0)
QUICK_LAMBDAS = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
SCENES = ["bunny-3851", "bunny-16k", "bunny-69k", "dragon-11k", "dragon-48k", "cornell-sphere"]
QUICK_SCENES = ["bunny-948", "cornell"]
#: the paper's reading of its Fig 6
PAPER_LAMBDA = 5.0
#: points with more than this fraction of the rays meeting the grid traced on their own are not
#: packet traversals (left out of cost-model fits)
MAX_SINGLE = 0.5
#: fit the packet cost model with a per-ray constant besides the four per-packet ones
RAY_TERM = True


# ---------------------------------------------------------------- shared measurement helpers
def camera(scene, side: int, k: int, eye_dir=(0.55, 0.45, 0.7)):
    """Camera rays of a side x side image ordered in k x k tiles (one packet per tile)."""
    return camera_rays(scene, side, side, tile=k, eye_dir=eye_dir)


def packet_work(cgt, rays) -> dict:
    """Per-ray work of one counting traversal: the cost model's columns plus the other counters."""
    pc = cgt.packet_counters(rays.origins, rays.directions)
    n = rays.n
    single, packed = pc["single"].sum(), pc["packet_rays"].sum()
    out = {"packets": len(pc["rays"]) / n, "hits": float((pc["hits"].tri_id >= 0).mean()),
           "single_frac": single / max(single + packed, 1)}  # of the rays meeting the grid
    for k in ("slices", "cells", "considered", "tests_plain", "tests_mb", "tests_mb_fc", "tests", "test_lanes",
              "macro_skips"):
        out[k] = pc[k].sum() / n
    return out


def model_X(df: pd.DataFrame) -> pd.DataFrame:
    """The cost model's per-ray columns; its ``tests`` are the SIMD lanes the tests occupied (a
    packet's ray loop runs over whole vectors, so small packets pay for idle lanes)."""
    return pd.DataFrame({"packets": df.packets, "slices": df.slices, "cells": df.cells, "tests": df.test_lanes},
                        index=df.index)


def _row(scene, params: dict, cgt, rays, seconds: list, spread: float) -> dict:
    import numba
    st = cgt.stats()
    med = float(np.median(seconds))
    return {"scene": scene.name, "N": scene.n, **{f"param_{a}": v for a, v in params.items()},
            "packet": params.get("packet", 8), "lam": params.get("lam", 5.0), "side": int(np.sqrt(rays.n)),
            "rays": rays.n, "res": "x".join(str(v) for v in st["res"]), "cells_total": st["cells"], "refs": st["refs"],
            "build_s": st["build_s"], "seconds": med, "seconds_min": float(np.min(seconds)), "spread": spread,
            "samples": len(seconds), "ns_per_ray": med / rays.n * 1e9, "mrays_s": rays.n / med / 1e6,
            **packet_work(cgt, rays), "threads": numba.get_num_threads()}


def measure_points(store, target: str, scene, param_list, side, repeats, threads, log) -> list[dict]:
    """Time every parameter set on one scene not in the point store yet: build all, then
    ``repeats`` interleaved rounds (:func:`tracer.measure.timing.time_paired`: a warm-up call
    first), so a burst of load on a shared machine hits every point alike; per point the median
    of the rounds. Camera rays in k x k tile order; the counted work of the same rays."""
    keys = [{"target": target, "scene": scene.name, "params": p, "side": side, "repeats": repeats,
             "threads": threads} for p in param_list]
    todo = [(k, p) for k, p in zip(keys, param_list) if store.get(k) is None]
    if todo:
        rows, prov = store.ctx.run_task(store, time_points, scene, [p for _, p in todo], side, repeats)
        for (key, params), row in zip(todo, rows):
            store.put(key, row, provenance=prov)
            log(f"  {scene.name} {params}: {row['ns_per_ray']:.1f} ns/ray")
    return [dict(store.get(k, ignore_force=True), **store.provenance(k)) for k in keys]


def time_points(scene, param_list, side, repeats) -> list[dict]:
    """Build every parameter set and time them all in interleaved rounds (one task of the run)."""
    built = [(CoherentGrid(**p).build(scene), camera(scene, side, p.get("packet", 8))) for p in param_list]
    tp = time_paired({j: (lambda c=c, r=r: c.intersect(r.origins, r.directions, counters=False))
                      for j, (c, r) in enumerate(built)}, rounds=repeats, repeats=1)
    return [_row(scene, params, cgt, rays, tp[j], (max(tp[j]) - min(tp[j])) / float(np.median(tp[j])))
            for j, (params, (cgt, rays)) in enumerate(zip(param_list, built))]


def loso_predictions(df: pd.DataFrame, key: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Leave-one-scene-out: for each scene fit PacketCostFit on the other scenes' points, predict
    this scene's times from its counted work; returns (df with ``predicted``, per-scene best).
    Points traced mostly ray by ray (incoherent packets fall back) are left out of fits and
    candidates: the packet model does not describe them."""
    out, best = [], []
    ok = df[df.single_frac <= MAX_SINGLE]
    scenes = list(dict.fromkeys(df.scene))
    for name in scenes:
        train = ok[ok.scene != name] if ok.scene.nunique() > 1 else ok
        fit = PacketCostFit(ray_term=RAY_TERM).fit(model_X(train), train.ns_per_ray)
        mine = df[df.scene == name]
        pred = mine.assign(predicted=fit.predict(model_X(mine)))
        cand = ok[ok.scene == name]
        b, _ = best_config(fit, pd.concat([cand[["packet", "lam"]], model_X(cand)], axis=1), keys=("packet", "lam"))
        out.append(pred)
        meas = mine.loc[mine.ns_per_ray.idxmin()]
        best.append({"scene": name, f"measured_best_{key}": meas[key], f"predicted_best_{key}": b[key],
                     "penalty_of_predicted_pct": 100 * (float(mine[mine[key] == b[key]].ns_per_ray.min()) / meas.ns_per_ray - 1),
                     "loso_mape_pct": _mape(pred[pred.single_frac <= MAX_SINGLE])})
    return pd.concat(out), pd.DataFrame(best)


def _mape(d: pd.DataFrame) -> float:
    return float(np.mean(np.abs(d.predicted - d.ns_per_ray) / d.ns_per_ray) * 100) if len(d) else float("nan")


def pooled_fit(df: pd.DataFrame, ray_term: bool = True) -> PacketCostFit:
    ok = df[df.single_frac <= MAX_SINGLE]
    return PacketCostFit(ray_term=ray_term).fit(model_X(ok), ok.ns_per_ray)


def fit_note(df: pd.DataFrame) -> str:
    """The four-constant model of the brief against the one with a per-ray term, on the same points."""
    f4, f5 = pooled_fit(df, False), pooled_fit(df, True)
    return (f"Four constants (per packet, slice, cell, test lane): R² {f4.metrics_['r2']:.3f}, MAPE "
            f"{f4.metrics_['mape']:.1f} %; with a fifth, per-ray constant T_ray (clipping and sorting each ray, "
            f"writing its hit — work that does not shrink with the packet size): R² {f5.metrics_['r2']:.3f}, MAPE "
            f"{f5.metrics_['mape']:.1f} %. Predictions use the five-constant model. Points where over "
            f"{100 * MAX_SINGLE:.0f} % of the rays fell back to single-ray traversal are left out of fits.")


def constants_table(fit: PacketCostFit) -> str:
    lines = ["| constant | fitted (ns) | 95 % CI |", "|---|---|---|"]
    for name, v in fit.constants_.items():
        lo, hi = fit.ci_[name]
        lines.append(f"| {name} | {v:.3g} | {lo:.3g}–{hi:.3g} |")
    return "\n".join(lines)


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
    store = ctx.store(code=("experiments/wald/fig6.py",))
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
