"""``advise``: which structure to build for *your* scene and ray budget, with predicted times.

    gridcost advise --mesh my.obj --rays 1e7 [--kind random|camera|path] [--check] [--json]

For each candidate — the uniform grid at Ize's Eq 4, M = 2N T_i/T_s, with T_i/T_s fitted on this host
(:class:`costmodel.griddensity.GridDensityFit`; the paper's 4, M = 8N, when the fit cannot separate a
step from a test), the two-level grid at M1 = (8N)^0.6, M2 = 8 N2,
the kd-tree, the BVH, the 4-wide BVH built with the SAH weight fitted on this host
(:class:`costmodel.kdcost.BvhSahFit`; probed whenever the BVH is) and, for camera rays, coherent grid
packets — it predicts the total time for R rays, build plus trace, with an interval, and picks the
fastest:

* **Grids** are probed, as Hapala 2011's decision algorithm does: built (wall clock, the median of
  3 builds when cheap) and samples of 20,000 rays traced (median of 5 interleaved rounds of every
  probed candidate after a warm-up: the steady state of a long run, and a busy phase of a shared
  machine cannot reorder them; each call traces the next of 10 disjoint sets, never a ray twice;
  camera rays are the 200,000-pixel frame a long run traces, in consecutive pieces of whole 8x8
  packets, in the frame's order: :func:`probe_pool`); the interval is the spread of the repeats, at
  least ±10 %.
* **Hierarchies** (kd-tree, BVH) are probed with them when cheap: when the calibration's estimate
  of their build is at most 2 s. Above that they are predicted without building them, from a
  calibration on this host: table1h's measurements of a few small built-in scenes (stored like every
  point, so the first call measures and later calls reuse it) fit the estimator of
  :class:`costmodel.select.GridcostEstimator` (build time and per-ray time from N and the probed
  grid's counters); the interval is the 10-90 % range of its leave-one-scene-out relative errors.
  (``advise-check`` found the estimator off by -57 to +85 % in build and -70 to +129 % per ray on
  meshes 1-50x larger than its calibration scenes, on a loaded machine: it ranks close structures
  wrongly, so it is only the fallback for builds too dear to probe.)

``--check`` builds and times the three best candidates on R rays (at most 200,000 traced; the rest
scaled) and prints measured beside predicted.
"""
from __future__ import annotations

import time

import pandas as pd

from experiments.core.common import emit_json
from experiments.core.store import atomic_write
from experiments.tools.lib.advising import CHECK_RAYS, calibration, measure, predict, with_totals
from tracer.errors import GridcostError

#: the folder gathers one scene and ray kind a run: the runner keeps the earlier runs'
#: files (experiments.run drops a whole-folder target's stale ones)
KEEPS_EARLIER_FILES = True


def add_arguments(p) -> None:
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--mesh", help="path of your mesh (OBJ, PLY, OFF, STL, GLB)")
    g.add_argument("--scene", help="a named scene")
    p.add_argument("--rays", type=float, default=None,
                   help="rays R the application will trace; without it, the budget ranges where each candidate "
                        "is fastest (1e3..1e10 rays), with a crossover chart (PNG) and JSON")
    p.add_argument("--image", type=int, default=None, help="camera rays: the side of your square frame in pixels")
    p.add_argument("--kind", choices=("random", "camera", "path"), default="random")
    p.add_argument("--check", action="store_true", help="build and time the best candidates; measured beside predicted")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--constants", help="constants JSON of `fit --timings` (your own grid): recommend your grid's "
                                       "resolution for this mesh, in your units")


def _check(scene, kind, R, cands, seed) -> None:
    """Build and time the three best candidates: measured_s = build + R x per-ray time."""
    n = int(min(max(R, 1000), CHECK_RAYS))
    truth = measure(scene, kind, [(c["structure"], c["params"]) for c in cands[:3]], n, seed=seed)
    for c in cands[:3]:
        m = truth[c["structure"]]
        c["measured_s"] = m["build_s"] + R * m["ray_s"]
        c["measured_build_s"], c["measured_ray_s"] = m["build_s"], m["ray_s"]


def main(ctx, args) -> int:
    from tracer.scenes.scene import load_mesh, load_scene
    from tracer.measure.timing import set_threads
    started = time.time()
    if args.rays is not None and not args.rays >= 1:
        raise GridcostError(f"--rays must be >= 1, got {args.rays:g}")
    if args.image is not None and not 8 <= args.image <= 8192:
        raise GridcostError(f"--image must be 8..8192 pixels, got {args.image}")
    if args.constants:
        return _your_grid(ctx, args, started)
    if args.rays is None:
        return _budgets(ctx, args, started)
    log = (lambda *a: None) if args.json else print
    set_threads(args.threads or 1)
    scene = load_mesh(args.mesh) if args.mesh else load_scene(args.scene)
    cal = calibration(ctx, log)
    cands = with_totals(predict(scene, args.kind, cal, args.seed, log), args.rays)
    if args.check:
        _check(scene, args.kind, args.rays, cands, args.seed)
    pick = cands[0]
    runner = cands[1] if len(cands) > 1 else None
    why = (f"{pick['structure']}: predicted {pick['predicted_s']:.3g} s for {args.rays:.3g} {args.kind} rays "
           f"(build {pick['build_s'] * 1e3:.1f} ms + {pick['ray_s'] * 1e9:.0f} ns per ray)"
           + (f", {runner['predicted_s'] / pick['predicted_s']:.2f}x faster than {runner['structure']}" if runner else "")
           + (" — the intervals overlap: a close call" if runner and runner["predicted_lo"] < pick["predicted_hi"] else ""))
    res = {"scene": scene.name, "N": scene.n, "rays": args.rays, "kind": args.kind, "pick": pick["structure"],
           "why": why, "threads": 1,
           "candidates": [{k: c[k] for k in ("structure", "params", "predicted_s", "predicted_lo", "predicted_hi", "how",
                                             "build_s", "ray_s") + (("measured_s",) if "measured_s" in c else ())}
                          for c in cands]}
    out_dir = ctx.out / "advise"
    df = pd.DataFrame([dict(c, scene=scene.name, N=scene.n, rays=args.rays, ray_kind=args.kind) for c in res["candidates"]])
    df["params"] = df["params"].astype(str)
    ctx.write_csv(out_dir / f"{scene.name}.csv", df)
    lines = [f"# advise: {scene.name} (N = {scene.n:,}), {args.rays:.3g} {args.kind} rays, one thread", "",
             f"**Pick: {why}**", "", "| structure | predicted (s) | interval (s) | build (ms) | per ray (ns) | measured (s) | how |",
             "|---|---|---|---|---|---|---|"]
    for c in cands:
        meas = f"{c['measured_s']:.3g}" if "measured_s" in c else "–"
        lines.append(f"| {c['structure']} | {c['predicted_s']:.3g} | {c['predicted_lo']:.3g} – {c['predicted_hi']:.3g} | "
                     f"{c['build_s'] * 1e3:.1f} | {c['ray_s'] * 1e9:.0f} | {meas} | {c['how']} |")
    atomic_write(out_dir / "summary.md", "\n".join(lines) + "\n")
    ctx.write_meta(out_dir, "advise", started, scene=scene.name, rays=args.rays, kind=args.kind, check=args.check)
    if args.json:
        emit_json(res)
    else:
        print("\n".join(lines))
    return 0


def _budgets(ctx, args, started) -> int:
    """advise with no --rays: the budget ranges where each candidate is fastest, the crossovers
    with their intervals and each candidate's memory; chart, JSON, CSV; --check measures a factor 3
    on both sides of each crossover."""
    import json
    from experiments.tools.lib.advising import advice_for
    from experiments.tools.lib.budgets import R_RANGE, check_budgets, describe
    from tracer.measure.timing import set_threads
    from tracer.scenes.scene import load_mesh, load_scene
    log = (lambda *a: None) if args.json else print
    set_threads(args.threads or 1)
    scene = load_mesh(args.mesh) if args.mesh else load_scene(args.scene)
    adv = advice_for(ctx, scene, args.kind, args.seed, args.image, log)
    ranges = adv.ranges()
    memory = {c.label(): c.memory_bytes for c in adv.candidates}
    res = adv.to_dict()
    res["summary"] = describe(ranges, memory)
    checks = []
    if args.check:
        n = int(CHECK_RAYS)
        truth = measure(scene, args.kind, [(c.structure, c.params) for c in adv.candidates], n, seed=args.seed,
                        image=args.image)
        for R in check_budgets(ranges):
            meas = {c.label(): truth[c.structure]["build_s"] + R * truth[c.structure]["ray_s"] for c in adv.candidates}
            checks.append({"rays": R, "predicted_pick": adv.pick(R).label(), "measured_pick": min(meas, key=meas.get),
                           "measured_s": meas})
        res["check"] = checks
    out_dir = ctx.out / "advise"
    stem = f"{scene.name}-{args.kind}-budgets"
    atomic_write(out_dir / f"{stem}.json", json.dumps(res, indent=1, default=float) + "\n")
    _chart(ctx, adv, checks, stem)
    lines = [f"# advise: {scene.name} (N = {scene.n:,}), {args.kind} rays at every budget, one thread", "",
             f"**{res['summary']}**", "", "| structure | build (ms) | per ray (ns) | memory (MiB) | how |", "|---|---|---|---|---|"]
    for c in adv.candidates:
        mem = f"{c.memory_bytes / 2 ** 20:.1f}" if c.memory_bytes else "not built"
        lines.append(f"| {c.label()} | {c.build_s * 1e3:.1f} | {c.ray_s * 1e9:.0f} | {mem} | {c.how} |")
    for ch in checks:
        lines.append(f"\n--check at {ch['rays']:.3g} rays: predicted {ch['predicted_pick']}, measured {ch['measured_pick']}")
    atomic_write(out_dir / "summary.md", "\n".join(lines) + "\n")
    ctx.write_meta(out_dir, "advise", started, scene=scene.name, kind=args.kind, budgets=list(R_RANGE), check=args.check)
    if args.json:
        emit_json(res)
    else:
        print("\n".join(lines))
    return 0


def _chart(ctx, adv, checks, stem) -> None:
    """Predicted build + trace seconds against R, a band per candidate, the measured points of --check."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from experiments.tools.lib.budgets import R_RANGE
    R = np.logspace(np.log10(R_RANGE[0]), np.log10(R_RANGE[1]), 200)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for c in adv.candidates:
        lo, hi = c.band(R)
        line, = ax.plot(R, c.total_s(R), label=c.label())
        ax.fill_between(R, lo, hi, color=line.get_color(), alpha=0.2)
        pts = [(ch["rays"], ch["measured_s"][c.label()]) for ch in checks]
        if pts:
            ax.plot(*zip(*pts), "o", color=line.get_color())
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("rays R")
    ax.set_ylabel("build + trace (s), one thread")
    ax.set_title(f"{adv.scene}: {adv.kind} rays")
    ax.legend(fontsize=7)
    ctx.finish_figure(fig, stem)



def _your_grid(ctx, args, started) -> int:
    """advise --constants: your grid's best resolution on this mesh, from the constants ``fit
    --timings`` fitted to your timings, applied to the work gridcost counts here."""
    import json
    from pathlib import Path

    from experiments.core.usergrid import counting_rays, fit_from_record, recommend
    from tracer.scenes.scene import load_mesh, load_scene
    try:
        rec = json.loads(Path(args.constants).read_text())
    except (OSError, ValueError) as exc:
        raise GridcostError(f"--constants {args.constants}: cannot read it as JSON ({exc})") from None
    fit = fit_from_record(rec)
    scene = load_mesh(args.mesh) if args.mesh else load_scene(args.scene)
    rays = counting_rays(scene, args.kind, args.seed)
    out = recommend(fit, scene, rays, rec.get("grid_params") or {}, budget_rays=args.rays,
                    factor_range=rec.get("factor_range"))
    table = out.pop("table")
    top = table.sort_values("predicted_s_per_ray").head(5)
    b = out["best"]
    text = (f"# Your grid on {scene.name} (N = {scene.n:,}), {args.kind} rays, constants fitted on "
            f"{rec['fitted_on']['mesh']} ({args.constants})\n\n"
            f"Best resolution: {b['nx']} x {b['ny']} x {b['nz']} = {b['cells']:,} cells ({out['best_factor']:.2f} N), "
            f"predicted {b['predicted_s_per_ray'] * 1e9:.1f} ns per ray in your units"
            + (f", {b['predicted_s']:.3g} s for {args.rays:.3g} rays" if args.rays else "") + ".\n\n"
            "| nx | ny | nz | cells | predicted ns/ray | memory (MB, gridcost's layout) |\n|---|---|---|---|---|---|\n"
            + "".join(f"| {r.nx} | {r.ny} | {r.nz} | {r.cells:,} | {r.predicted_s_per_ray * 1e9:.1f} | "
                      f"{(r.memory_bytes or 0) / 1e6:.1f} |\n" for r in top.itertuples()))
    out_dir = ctx.out / "advise"
    ctx.write_csv(out_dir / f"{scene.name}-your-grid.csv", table)
    atomic_write(out_dir / "summary.md", text)
    ctx.write_meta(out_dir, "advise", started, scene=scene.name, constants=str(args.constants))
    if args.json:
        emit_json(out)
        return 0
    print(text, end="")
    return 0
