"""``stability``: where each resolution rule fails — the penalty of every rule (Ize's 8N and
2N·Ti/Ts, the long-skinny 8N^1.5, pbrt's 3N^(1/3) voxels along the longest axis clamped at 64, Wald's
lambda = 5, Ize's two-level grid M1 = (8N)^0.6, M2 = 8 N2, and the memory-aware model's M with
constants held out, and with Ts0 and Ti from three of the scene's own swept points) against the best swept one-level M, for every scene family of
``exponents`` (compact scans, CAD, long skinny cylinders, scattered particles, teapot in a stadium)
from about 200 to 871k triangles.

The curves are the ``exponents`` sweeps (random rays, one thread, every point timed beside the
scene's 8N grid): a rule's time is read off its scene's curve by linear interpolation in
log M – log t between the two swept points around it (a rule outside the swept range, N/8 … 64N, is
marked, not extrapolated), and its penalty is that time over the curve's minimum. Ti/Ts for
2N·Ti/Ts is the counter model's, pooled over all points (steps and tests against time, nnls).

The two-level grid is another structure, so it is not read off the one-level curve: it is one more
point of the same sweep (:func:`experiments.core.sweep.sweep`, structure ``nested``), timed beside the
scene's reference grid (8N) on the same rays like every one-level point, and its penalty is its ratio
to that reference over the best one-level point's ratio (:func:`two_level_penalty`; a negative
penalty: the two-level grid beats every one-level M).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd

from costmodel.fit import CounterCostFit
from costmodel.papers import ize2007
from experiments.ize.lib import memmodel
from experiments.core.store import atomic_write, read_csv
from experiments.core.target import ensure_input
from tracer.accel.constants import IZE_M_FACTOR, PBRT_GRID_MAX_VOXELS, WALD_LAMBDA


def add_arguments(p) -> None:
    pass


#: the two-level rule (a measured point of the nested grid, not a cell count on the one-level curve)
TWO_LEVEL = "(8N)^0.6 two-level (Ize Eq 12-13, M2 = 8 N2)"
TWO_LEVEL_PARAMS = {"levels": 2}
#: the memory-aware rule (experiments.ize.lib.memmodel: costmodel.memory's model, constants from the other scenes)
MEMORY_AWARE = "memory-aware (held-out constants)"
#: ... with Tsetup, Ts0 and Ti refitted on three of the scene's swept points (costmodel.memory.SceneCalibratedFit)
MEMORY_CALIBRATED = "memory-aware, 3 scene points"


def rule_cells(scene, ti_over_ts: float, memory: dict | None = None) -> dict:
    """Cell count of every one-level rule for ``scene`` (rule name -> M), and the model rules of
    ``memory`` (name -> M, e.g. :data:`MEMORY_AWARE` -> the M of
    :func:`experiments.ize.lib.memmodel.memory_aware_cells`), when given."""
    from tracer.accel.grid import res_pbrt, res_wald
    n = scene.n
    out = {"8N (Ize Eq 4, Ti/Ts = 4)": IZE_M_FACTOR * n,
           "2N·Ti/Ts (Eq 4, Ti/Ts fitted here)": 2 * n * ti_over_ts,
           "8N^1.5 (Ize Eq 8, long skinny)": IZE_M_FACTOR * n**1.5,
           f"pbrt 3N^(1/3), <= {PBRT_GRID_MAX_VOXELS}": float(np.prod(res_pbrt(scene.bounds, n))),
           f"Wald lambda = {WALD_LAMBDA:g}": float(np.prod(res_wald(scene.bounds, n)))}
    out.update({k: float(v) for k, v in (memory or {}).items()})
    return out


def two_level_penalty(scene, k: pd.DataFrame, store, repeats: int) -> tuple[float, dict]:
    """Penalty (%) of the two-level grid (:data:`TWO_LEVEL_PARAMS`) against the best point of the
    scene's one-level sweep ``k``, and its sweep row. The two-level point is measured on the sweep's
    rays (same count and seed) beside the same reference grid (8N), so its time over the reference's
    in the same rounds (``ratio_to_ref``) is compared with the one-level points' ratios: paired,
    drift-free, and independent of when (and on which clock) the one-level curve was measured."""
    from experiments.core.sweep import sweep
    from tracer.scenes.rays import make_rays
    rays = {"random": make_rays(scene, "random", int(k.rays.iloc[0]), seed=int(k.seed.iloc[0]))}
    row = sweep(scene, "nested", [TWO_LEVEL_PARAMS], rays, store, repeats, desc=f"stability {scene.name} two-level")[0]
    return 100 * (float(row["ratio_to_ref"]) / float(k.ratio_to_ref.min()) - 1), row


def time_at(cells: np.ndarray, ns: np.ndarray, m: float) -> float:
    """Time at ``m`` cells interpolated in log-log between the swept points around it; NaN outside."""
    order = np.argsort(cells)
    lc, lt = np.log(np.asarray(cells, float)[order]), np.log(np.asarray(ns, float)[order])
    lm = np.log(m)
    if lm < lc[0] - 1e-9 or lm > lc[-1] + 1e-9:
        return float("nan")
    return float(np.exp(np.interp(lm, lc, lt)))


def _points(ctx, args) -> pd.DataFrame:
    path = Path(args.out) / "exponents" / "points.csv"
    # --force on a derived target re-derives; it does not re-measure its inputs
    ensure_input(ctx, args, "exponents", path, log=lambda *a: None, families=None, rays=None, repeats=None, seed=0)
    return read_csv(path)


def main(ctx, args) -> int:
    from tracer.scenes.scene import load_scene
    from tracer.measure.timing import set_threads
    started = time.time()
    threads = set_threads(args.threads or 1)
    pts = _points(ctx, args)
    pts = pts[(pts.ray_kind == "random") & (pts.structure == "grid")]
    ratio = CounterCostFit(n_boot=0).fit(pts.scene.tolist(), pts.steps, pts.tests, pts.anchored_ns_per_ray).ti_over_ts_
    store, repeats = ctx.store(), 3 if ctx.quick else 5
    mach = memmodel.machine(ctx.quick)
    rows = []
    for (family, name), k in pts.groupby(["family", "scene"], sort=False):
        k = k.drop_duplicates("cells")
        best = float(k.anchored_ns_per_ray.min())
        scene = load_scene(name)
        best_M = float(k.loc[k.anchored_ns_per_ray.idxmin()].cells)
        base = {"family": family, "scene": name, "N": scene.n, "best_M": best_M, "rays": int(k.rays.iloc[0]),
                "sweep_spread_pct": 100 * float(k.spread.median())}
        mem = {rule: memmodel.memory_aware_cells(pts, name, "random", mach, calibrate=cal)[0]
               for rule, cal in ((MEMORY_AWARE, False), (MEMORY_CALIBRATED, True))}
        for rule, m in rule_cells(scene, ratio, mem).items():
            t = time_at(k.cells.values, k.anchored_ns_per_ray.values, m)
            rows.append({**base, "rule": rule, "M": m, "M_over_N": m / scene.n,
                         "penalty_pct": 100 * (t / best - 1) if np.isfinite(t) else np.nan,
                         "outside_sweep": not np.isfinite(t), "measured": False})
        p2, r2 = two_level_penalty(scene, k, store, repeats)
        rows.append({**base, "rule": TWO_LEVEL, "M": float(r2["cells"]), "M_over_N": float(r2["cells"]) / scene.n,
                     "penalty_pct": p2, "outside_sweep": False, "measured": True})
    df = pd.DataFrame(rows)
    out_dir = Path(args.out) / "stability"
    ctx.write_csv(out_dir / "stability.csv", df)
    atomic_write(out_dir / "summary.md", _summary(df, ratio))
    _figure(ctx, df)
    ctx.write_meta(out_dir, "stability", started, ti_over_ts=ratio, threads=threads, machine=mach.data)
    if not getattr(args, "json", False):
        print(_summary(df, ratio))
    return 0


def _cell(v, outside) -> str:
    return "outside sweep" if outside else f"{v:.1f}"


def where_fails(df: pd.DataFrame, rule: str, tol: float = 10.0) -> str:
    """One sentence: the families where ``rule`` costs more than ``tol`` % and from which N."""
    g = df[(df.rule == rule)].dropna(subset=["penalty_pct"])
    if g.empty:
        return "no scene inside its sweep"
    parts = []
    for fam, f in g.groupby("family", sort=False):
        bad = f[f.penalty_pct > tol]
        if len(bad):
            parts.append(f"{fam} ({len(bad)} of {len(f)}, N = {', '.join(f'{n:,}' for n in bad.N)}; worst "
                         f"{bad.penalty_pct.max():.0f} %)")
    return ("fails (> 10 %) on " + "; ".join(parts)) if parts else "within 10 % on every scene it was measured on"


def _summary(df: pd.DataFrame, ratio: float) -> str:
    rules = list(dict.fromkeys(df.rule))
    rays = ", ".join(f"{fam}: {int(g.rays.iloc[0]):,}" for fam, g in df.groupby("family", sort=False))
    lines = ["# Stability map: where each resolution rule fails", "",
             "Penalty (%) of each rule against the best swept one-level M, per scene: random rays (two uniform points "
             f"on the bounding sphere; per family {rays} rays), one thread. One-level rules: time read off the "
             "scene's `exponents` sweep (M from N/8 to 64N in 19 points, 14 up to 32 N^1.5 for skinny, each timed "
             "beside the scene's 8N reference grid, medians of 5 interleaved rounds), interpolated in log M – log t; "
             "a rule outside the swept range is marked, not extrapolated. Two-level rule: a measured point of the "
             "nested grid on the same rays, timed beside the same 8N reference; its penalty is its ratio to the reference over the best one-level point's ratio (negative: faster than every one-level M). "
             f"Ti/Ts of 2N·Ti/Ts = {ratio:.2f} (counter model, pooled over every point). Memory-aware: the M "
             "minimising costmodel.memory's model (counters + the host's load latency at the grid's working set), "
             "its constants fitted on every other scene of the map (held out); with 3 scene points: Tsetup, Ts0 "
             "and Ti refitted on the scene's swept points nearest the 10/50/90 % quantiles of log M (kappa still held "
             "out; those points are also on the curve its penalty is read from).", "",
             "Sweep spread: the median over the scene's swept points of (slowest - fastest) / median of a point's "
             "repeats (its timing noise); penalties below it are not resolved.", "",
             "| family | scene | N | sweep spread % | " + " | ".join(rules) + " |", "|---|---|---|---|" + "---|" * len(rules)]
    for (family, scene), g in df.groupby(["family", "scene"], sort=False):
        by = {r.rule: r for r in g.itertuples()}
        lines.append(f"| {family} | {scene} | {g.N.iloc[0]:,} | {g.sweep_spread_pct.iloc[0]:.0f} | "
                     + " | ".join(_cell(by[r].penalty_pct, by[r].outside_sweep) for r in rules) + " |")
    stats = df.dropna(subset=["penalty_pct"]).groupby("rule").penalty_pct.agg(["median", "max"])
    lines += ["", "## Where each rule fails", ""]
    for rule in rules:
        if rule in stats.index:
            r = stats.loc[rule]
            lines.append(f"- **{rule}**: median {r['median']:.1f} %, worst {r['max']:.1f} %; {where_fails(df, rule)}.")
    p2 = [r["penalty_pct"] for r in ize2007.TABLE2.records()]
    p3 = [r["penalty_pct"] for r in ize2007.TABLE3.records()]
    gb, gc = ize2007.TWO_LEVEL_GAIN["dragon-871k"], ize2007.TWO_LEVEL_GAIN["conference-room"]
    lines.append(f"- Paper (Ize 2007): 8N within {min(p2):g}-{max(p2):g} % of the best on its compact scenes "
                 f"({ize2007.TABLE2.where}), 8N^1.5 within {min(p3):g}-{max(p3):g} % on its capped cylinders "
                 f"({ize2007.TABLE3.where}), the two-level grid {gb.text}x faster than the best one-level grid on "
                 f"Buddha and {gc.text}x on the conference room ({gb.where}; penalty {100 * (1 / gb.value - 1):.0f} % and "
                 f"{100 * (1 / gc.value - 1):.0f} % in this table's unit, recomputed). "
                 "\"Outside sweep\": 8N^1.5 above 64N on compact scenes, where the sweep stops (that rule is not meant "
                 "for them).")
    return "\n".join(lines) + "\n"


def _figure(ctx, df: pd.DataFrame) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rules = list(dict.fromkeys(df.rule))
    scenes = list(dict.fromkeys(zip(df.family, df.scene, df.N)))
    Z = np.full((len(rules), len(scenes)), np.nan)
    for r in df.itertuples():
        Z[rules.index(r.rule), scenes.index((r.family, r.scene, r.N))] = r.penalty_pct
    fig, ax = plt.subplots(figsize=(1.0 + 0.55 * len(scenes), 0.9 + 0.45 * len(rules)))
    im = ax.imshow(np.clip(Z, 0, 100), cmap="RdYlGn_r", vmin=0, vmax=100, aspect="auto")
    for i in range(len(rules)):
        for j in range(len(scenes)):
            ax.text(j, i, "out" if np.isnan(Z[i, j]) else f"{Z[i, j]:.0f}", ha="center", va="center", fontsize=6)
    ax.set_yticks(range(len(rules)), rules, fontsize=7)
    ax.set_xticks(range(len(scenes)), [f"{s}\n{n:,}" for _, s, n in scenes], fontsize=6, rotation=60, ha="right")
    ax.set_title("penalty (%) of each rule's M over the best swept M (random rays)", fontsize=8)
    fig.colorbar(im, ax=ax, fraction=0.03, label="% over best (clipped at 100)")
    ctx.finish_figure(fig, "stability")
