"""``vtk-timings``: a uniform grid gridcost did not write (VTK's ``vtkStaticCellLocator``), timed the
way a user would time their own, to validate ``fit --timings`` on it.

    gridcost vtk-timings --scene bunny-69k                       # the user's CSV: a few resolutions
    gridcost fit --timings results/vtk-timings/bunny-69k.csv --scene bunny-69k \\
        --rays-file results/vtk-timings/bunny-69k-rays.npz --grid-param exact=false
    gridcost vtk-timings --scene bunny-69k --check results/fit/bunny-69k-constants.json

Without ``--check`` it times VTK at ``--factors`` x N cells (near-cubic bins, the divisions per
axis written out) on one ray set and writes the CSV ``fit --timings`` reads, and the rays. With
``--check`` it times VTK at a dense sweep of resolutions *and* at the resolution the fitted
constants predict, in interleaved rounds (median of ``--repeats``); the fastest swept resolutions
and the predicted one are then timed again in fresh interleaved rounds, and the predicted
resolution's penalty is the median over those rounds of its time over the fastest contender's.
The fresh rounds matter: the minimum of sixteen noisy medians is biased low (it picks the
resolution whose rounds happened to run fast), so a penalty read off the sweep itself overstates
what the prediction loses. VTK's hits are checked against the float64
oracle on a sample of the rays first: a timing of wrong answers would validate nothing.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

from experiments.core.common import add_scene_args, emit_json, scene_from_args
from experiments.core.store import atomic_write, write_json
from experiments.core.usergrid import load_rays
from tracer.accel.grid import res_from_cells
from tracer.accel.oracle import compare, oracle_intersect
from tracer.accel.reference import VtkGridLocator
from tracer.errors import GridcostError
from tracer.scenes.rays import make_rays

#: the folder gathers one scene's timings (and its --check) a run: the runner keeps the earlier runs'
#: files (experiments.run drops a whole-folder target's stale ones)
KEEPS_EARLIER_FILES = True

#: the resolutions of the "user's" CSV: few, spread over two and a half decades of cells (x N)
FIT_FACTORS = "0.02,0.1,0.5,2,8"
#: the dense sweep ``--check`` finds VTK's own best in (x N)
CHECK_FACTORS = tuple(float(f) for f in np.geomspace(1 / 64, 16.0, 16))
ORACLE_SAMPLE = 2000
#: timed rounds per resolution (medians): VTK's per-ray cost waits on loads, whose round-to-round
#: spread on a shared 2-core host is several %, so three rounds could not tell 5 % apart
REPEATS = 11
#: the swept resolutions re-timed beside the predicted one in the held-out rounds of ``--check``
CONTENDERS = 3


def add_arguments(p) -> None:
    add_scene_args(p)
    p.add_argument("--rays", type=int, default=None, help="rays timed per resolution (default 20000; --quick 4000)")
    p.add_argument("--kind", default="random", choices=["random", "camera", "path"])
    p.add_argument("--factors", default=FIT_FACTORS, help=f"cells = factor x N of each timed row (default {FIT_FACTORS})")
    p.add_argument("--repeats", type=int, default=REPEATS, help=f"timed rounds (median; default {REPEATS})")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--check", help="constants JSON of fit --timings: time its predicted resolution against a dense sweep")


def _round_times(accs, rays, repeats: int) -> np.ndarray:
    """(rounds, grids) seconds: every built grid timed once per round, interleaved, so a busy phase
    of the machine hits all alike."""
    for a in accs:  # warm-up: first-touch of the bins
        a.intersect(rays.origins[:200], rays.directions[:200], counters=False)
    times = np.empty((repeats, len(accs)))
    for r in range(repeats):
        for j, a in enumerate(accs):
            t0 = time.perf_counter()
            a.intersect(rays.origins, rays.directions, counters=False)
            times[r, j] = time.perf_counter() - t0
    return times


def _time_rounds(scene, grids, rays, repeats: int) -> tuple[pd.DataFrame, list]:
    """Build each grid once and time them in interleaved rounds: median seconds per resolution
    (and the built grids, for more rounds)."""
    accs = [VtkGridLocator(g).build(scene) for g in grids]
    times = _round_times(accs, rays, repeats)
    return pd.DataFrame({"nx": [g[0] for g in grids], "ny": [g[1] for g in grids], "nz": [g[2] for g in grids],
                         "cells": [int(np.prod(g)) for g in grids], "rays": rays.n,
                         "seconds": np.median(times, axis=0), "spread": (times.max(0) - times.min(0)) / np.median(times, axis=0),
                         "build_s": [a.build_seconds_ for a in accs]}), accs


def _held_out_penalty(df, accs, rays, repeats: int) -> dict:
    """The predicted resolution against the :data:`CONTENDERS` fastest swept ones, timed again in
    fresh interleaved rounds: its penalty is its median per-round time ratio to the contender it
    trails most (0 when it trails none: then how far it is ahead of the closest), and the spread over
    rounds. Best and penalty are read from the same per-round ratios, so the penalty is never below
    0 (a best chosen by median time could give a tie a penalty of -0.1 %)."""
    pred = int(np.flatnonzero(df.predicted.to_numpy())[0])
    swept = [int(j) for j in df.assign(j=range(len(df)))[~df.predicted].nsmallest(CONTENDERS, "seconds").j]
    idx = [pred] + swept
    t = _round_times([accs[j] for j in idx], rays, repeats)
    ratios = t[:, [0]] / t  # per round: the prediction's time over each contender's (1 for itself)
    med = np.median(ratios, axis=0)
    best = int(np.argmax(med))
    ratio = ratios[:, best]
    out = {"held_out_rounds": repeats, "contenders": [int(df.cells.iloc[j]) for j in idx],
           "held_out_best_cells": int(df.cells.iloc[idx[best]]),
           "penalty_pct": 100.0 * (float(np.median(ratio)) - 1.0),
           "penalty_range_pct": [100.0 * (float(ratio.min()) - 1.0), 100.0 * (float(ratio.max()) - 1.0)]}
    if best == 0:  # the prediction is the fastest: by how much, against the closest contender
        nxt = 1 + int(np.argmax(med[1:]))
        ahead = t[:, nxt] / t[:, 0]
        out["ahead_pct"] = 100.0 * (float(np.median(ahead)) - 1.0)
        out["ahead_range_pct"] = [100.0 * (float(ahead.min()) - 1.0), 100.0 * (float(ahead.max()) - 1.0)]
    return out


def _check_oracle(scene, rays, grid) -> dict:
    k = min(ORACLE_SAMPLE, rays.n)
    o, d = rays.origins[:k], rays.directions[:k]
    hits, _ = VtkGridLocator(grid).build(scene).intersect(o, d, counters=False)
    ref, ties = oracle_intersect(scene, o, d)
    res = compare(hits, ref, ties, rtol=1e-4)  # VTK intersects in its own float64 arithmetic
    if res["hit_miss"] or res["id_mismatch"]:
        raise GridcostError(f"vtk-timings: VTK disagrees with the oracle on {res['disagreements']} of {k} rays; "
                            "its timings would validate nothing")
    return res


def main(ctx, args) -> int:
    if not VtkGridLocator.available():
        raise GridcostError("vtk-timings needs VTK: pip install 'gridcost[vtk]'")
    started = time.time()
    scene = scene_from_args(args)
    n_rays = args.rays or (4000 if args.quick else 20_000)
    out_dir = Path(args.out) / "vtk-timings"
    rays_path = out_dir / f"{scene.name}-rays.npz"
    if args.check:
        try:
            rec = json.loads(Path(args.check).read_text())
            b = rec["predicted_best"]
            pred = (int(b["nx"]), int(b["ny"]), int(b["nz"]))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise GridcostError(f"vtk-timings --check {args.check}: not a fit --timings constants file ({exc})") from None
        rays = load_rays(rays_path) if rays_path.exists() else make_rays(scene, args.kind, n_rays, seed=args.seed)
        grids = list(dict.fromkeys([tuple(int(v) for v in res_from_cells(scene.bounds, f * scene.n))
                                    for f in CHECK_FACTORS] + [pred]))
        agree = _check_oracle(scene, rays, pred)
        df, accs = _time_rounds(scene, grids, rays, max(1, args.repeats))
        df["predicted"] = [g == pred for g in grids]
        best = df[~df.predicted].nsmallest(1, "seconds").iloc[0]
        t_pred = float(df[df.predicted].seconds.iloc[0])
        held = _held_out_penalty(df, accs, rays, max(1, args.repeats))
        out = {"scene": scene.name, "N": scene.n, "rays": rays.n, "predicted": list(pred),
               "predicted_cells": int(np.prod(pred)), "best": [int(best.nx), int(best.ny), int(best.nz)],
               "best_cells": int(best.cells), "t_predicted_s": t_pred, "t_best_s": float(best.seconds),
               "sweep_penalty_pct": 100.0 * (t_pred / float(best.seconds) - 1.0), **held,
               "swept": len(df) - 1, "constants": rec.get("constants"), "oracle": agree}
        lo, hi = held["penalty_range_pct"]
        verdict = (f"{held['penalty_pct']:.1f} % (per-round {lo:.1f} – {hi:.1f} %)" if "ahead_pct" not in held else
                   f"0 %: the predicted resolution is the fastest, {held['ahead_pct']:.1f} % ahead of the next "
                   f"(per-round {held['ahead_range_pct'][0]:.1f} – {held['ahead_range_pct'][1]:.1f} %)")
        ctx.write_csv(out_dir / f"{scene.name}-check.csv", df)
        write_json(out_dir / f"{scene.name}-check.json", out)
        text = (f"# fit --timings validated on VTK's vtkStaticCellLocator: {scene.name} (N = {scene.n:,})\n\n"
                f"Predicted by the fitted constants: {pred[0]} x {pred[1]} x {pred[2]} = {out['predicted_cells']:,} bins, "
                f"{t_pred / rays.n * 1e9:.0f} ns per ray. VTK's own best of {out['swept']} swept resolutions: "
                f"{out['best'][0]} x {out['best'][1]} x {out['best'][2]} = {out['best_cells']:,} bins, "
                f"{out['t_best_s'] / rays.n * 1e9:.0f} ns per ray (medians of {args.repeats} interleaved rounds, "
                f"{rays.n:,} rays; read off the sweep, the predicted one is {out['sweep_penalty_pct']:+.1f} %).\n\n"
                f"Penalty of the predicted resolution, re-timed beside the {len(held['contenders']) - 1} fastest swept "
                f"resolutions in {args.repeats} fresh interleaved rounds (the sweep's own minimum is biased low): "
                f"{verdict}. VTK agrees with the oracle on {agree['rays']:,} rays.\n")
    else:
        factors = [float(f) for f in args.factors.split(",") if f.strip()]
        if not factors or min(factors) <= 0:
            raise GridcostError(f"vtk-timings: --factors must be positive numbers, got {args.factors!r}")
        rays = make_rays(scene, args.kind, n_rays, seed=args.seed)
        grids = list(dict.fromkeys(tuple(int(v) for v in res_from_cells(scene.bounds, f * scene.n)) for f in factors))
        agree = _check_oracle(scene, rays, grids[len(grids) // 2])
        df, _ = _time_rounds(scene, grids, rays, max(1, args.repeats))
        ctx.write_csv(out_dir / f"{scene.name}.csv", df[["nx", "ny", "nz", "rays", "seconds"]])
        tmp = rays_path.with_suffix(".tmp.npz")
        out_dir.mkdir(parents=True, exist_ok=True)
        np.savez(tmp, origins=rays.origins, directions=rays.directions)
        tmp.replace(rays_path)
        out = {"scene": scene.name, "N": scene.n, "rays": rays.n, "rows": df.to_dict(orient="records"), "oracle": agree}
        text = (f"# VTK vtkStaticCellLocator timings on {scene.name} (N = {scene.n:,})\n\n"
                + "| nx | ny | nz | cells | seconds | spread | build s |\n|---|---|---|---|---|---|---|\n"
                + "".join(f"| {r.nx} | {r.ny} | {r.nz} | {r.cells:,} | {r.seconds:.4g} | {r.spread:.3f} | {r.build_s:.3g} |\n"
                          for r in df.itertuples()) + "\n"
                f"{rays.n:,} {args.kind} rays (saved: {rays_path.name}), medians of {args.repeats} interleaved rounds; "
                f"VTK agrees with the oracle on {agree['rays']:,} rays.\n")
    atomic_write(out_dir / "summary.md", text)
    ctx.write_meta(out_dir, "vtk-timings", started, scene=scene.name, rays=rays.n, check=bool(args.check))
    if args.json:
        emit_json(out)
        return 0
    print(text, end="")
    return 0
