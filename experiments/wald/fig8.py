"""``wald-fig8``: Wald et al. 2006 Fig 8 / Sec 4.4 and 4.6 — rebuilding the grid every frame against
tracing it, and trace time as the model resolution grows at fixed lambda.

1. Rebuild against trace (Fig 8): the largest mesh available (the dragon, 871K triangles; the paper's
   Thai Statue has 10M) at lambda = 1 and 5, 4 x 4 packets (the paper's choice for large models),
   1024² camera rays, one thread: build time per frame (wall clock, median of 3 after a warm-up)
   beside trace time per frame (the two lambdas timed in interleaved rounds). The paper: at
   lambda = 5 the Thai Statue's rebuild takes 3x its trace, the aggregate optimum is near lambda = 1.
2. Model resolution (Sec 4.4 / Fig 7's model axis): the bunny (948 .. 69K) and dragon (11K .. 871K)
   families at lambda = 5, 8 x 8 packets, 1024² camera rays: trace and build time per frame and the
   counted work per ray, against N.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from costmodel.papers import wald2006
from experiments.core.figures import subplots
from experiments.core.target import begin, run_quiet
from experiments.wald.lib.packets import packet_work
from experiments.wald.lib.views import paired, wald_camera
from tracer.accel.packet import CoherentGrid
from tracer.scenes.scene import load_scene
from tracer.measure.timing import build_clock, clock_name, time_call

LARGEST = "dragon-871k"
FAMILY = ["bunny-948", "bunny-3851", "bunny-16k", "bunny-69k", "dragon-11k", "dragon-48k", "dragon-202k", "dragon-871k"]
QUICK_LARGEST = "bunny-16k"
QUICK_FAMILY = ["bunny-948", "bunny-3851"]
LAMBDAS = (1.0, 5.0)
#: the paper's Fig 8 reading (Thai Statue, 10M triangles): build / trace at lambda = 5
PAPER_BUILD_OVER_TRACE = wald2006.BUILD_OVER_TRACE.value


def add_arguments(p) -> None:
    p.add_argument("--scenes", default=None, help="comma-separated model-resolution scenes (default: bunny and dragon families)")
    p.add_argument("--largest", default=None, help=f"scene of the rebuild/trace trade-off (default {LARGEST})")
    p.add_argument("--side", type=int, default=None, help="image side (default 1024; --quick 128)")
    p.add_argument("--repeats", type=int, default=None, help="interleaved rounds (default 5)")


def build_seconds(scene, **params) -> float:
    return time_call(lambda: CoherentGrid(**params).build(scene), repeats=3, warmup=1, clock=build_clock).median


def rebuild_vs_trace(scene, side: int, rounds: int) -> pd.DataFrame:
    rays = wald_camera(scene, side, 4)
    built = {lam: CoherentGrid(lam=lam, packet=4).build(scene) for lam in LAMBDAS}
    sec, _ = paired({lam: (lambda c=c: c.intersect(rays.origins, rays.directions, counters=False))
                     for lam, c in built.items()}, rounds, LAMBDAS[-1])
    rows = []
    for lam, c in built.items():
        b = build_seconds(scene, lam=lam, packet=4)
        rows.append({"scene": scene.name, "N": scene.n, "lam": lam, "packet": 4, "side": side, "rays": rays.n,
                     "res": "x".join(str(v) for v in c.res_), "build_s": b, "trace_s": sec[lam],
                     "total_s": b + sec[lam], "fps_with_rebuild": 1 / (b + sec[lam]), "build_over_trace": b / sec[lam]})
    return pd.DataFrame(rows)


def model_resolution(scene, side: int, rounds: int) -> dict:
    rays = wald_camera(scene, side, 8)
    c = CoherentGrid(packet=8).build(scene)
    t = time_call(lambda: c.intersect(rays.origins, rays.directions, counters=False), repeats=rounds)
    return {"scene": scene.name, "N": scene.n, "side": side, "res": "x".join(str(v) for v in c.res_),
            "trace_s": t.median, "spread": t.spread, "build_s": build_seconds(scene, packet=8),
            "ns_per_ray": t.median / rays.n * 1e9, **packet_work(c, rays)}


def run(ctx, args, log=print) -> dict:
    tr = begin(ctx, args, "wald-fig8", (QUICK_FAMILY, FAMILY), threads=1, log=log)
    side = tr.pick(args.side, 128, 1024)
    rounds = args.repeats or 5
    largest = tr.pick(args.largest, QUICK_LARGEST, LARGEST)
    scenes = dict(tr.scenes("wald-fig8"))
    big = scenes.get(largest) or load_scene(largest)
    rb = rebuild_vs_trace(big, side, rounds)
    log(rb.to_string())
    mr = pd.DataFrame([model_resolution(scenes[n], side, rounds) for n in tr.names])
    tr.finish(_summary(rb, mr, side, rounds), {"rebuild.csv": rb, "model_resolution.csv": mr},
              figure=lambda: _figure(ctx, rb, mr), side=side, rounds=rounds, largest=largest)
    return {"rebuild": rb, "model_resolution": mr}


def _summary(rb, mr, side, rounds) -> str:
    r5 = rb[rb.lam == 5.0].iloc[0]
    best = rb.loc[rb.total_s.idxmin()]
    lines = [f"# Fig 8 / Sec 4.4, 4.6 (Wald et al. 2006): rebuild against trace, and model resolution, {side}² rays",
             "", f"One thread. Build: wall clock, median of 3 after a warm-up (a full rebuild from the triangles). "
             f"Trace: camera rays {side}x{side}, {clock_name()}, {rounds} rounds (the two lambdas interleaved). "
             "Seconds per frame.", "",
             f"## Rebuild against trace: {r5.scene} ({int(r5.N):,} triangles; the paper's Thai Statue has 10M), 4x4 packets", "",
             "| lambda | grid | build s/frame | trace s/frame | build / trace ours | (paper, Thai Statue) | frames/s with rebuild |",
             "|---|---|---|---|---|---|---|"]
    for _, r in rb.iterrows():
        paper = f"{PAPER_BUILD_OVER_TRACE:g}" if r.lam == 5.0 else "– (not given; best total)"
        lines.append(f"| {r.lam:g} | {r.res} | {r.build_s:.3f} | {r.trace_s:.3f} | {r.build_over_trace:.2f} | {paper} | "
                     f"{r.fps_with_rebuild:.2f} |")
    lines += ["", f"## Model resolution at lambda = 5, 8x8 packets, {side}² camera rays", "",
              "| scene | N | grid | trace s/frame | ns per ray | build s | cells per ray | tests per ray |",
              "|---|---|---|---|---|---|---|---|"]
    for _, r in mr.sort_values(["scene", "N"], key=lambda c: c.str.split("-").str[0] if c.name == "scene" else c).iterrows():
        lines.append(f"| {r.scene} | {int(r.N):,} | {r.res} | {r.trace_s:.4f} | {r.ns_per_ray:.1f} | {r.build_s:.4f} | "
                     f"{r.cells:.3f} | {r.tests:.2f} |")
    fams = []
    for fam, d in mr.groupby(mr.scene.str.split("-").str[0], sort=False):
        d = d.sort_values("N")
        if len(d) > 1:
            a, b = d.iloc[0], d.iloc[-1]
            fams.append(f"{fam}: N x{b.N / a.N:.0f} -> trace x{b.trace_s / a.trace_s:.2f}, build x{b.build_s / a.build_s:.1f}")
    lines += ["", "## Reading", "",
              f"Paper: the Thai Statue's rebuild at lambda = 5 takes 3x its trace; lambda = 1 gives the best total. Ours "
              f"({r5.scene}): build / trace {r5.build_over_trace:.2f} at lambda = 5; the best total per frame is at lambda = "
              f"{best.lam:g} ({best.total_s:.3f} s). Our mesh is {10e6 / r5.N:.0f}x smaller than the statue; the rebuild "
              f"weighs {'less' if r5.build_over_trace < PAPER_BUILD_OVER_TRACE else 'as much or more'} here than in the "
              "paper (one thread for both, float64 packet tests). Trace time grows "
              "slowly with N at fixed lambda (the frustum walk scales with the visible surface, not N): "
              + "; ".join(fams) + "."]
    return "\n".join(lines) + "\n"


def _figure(ctx, rb, mr):
    fig, axes = subplots(1, 2, figsize=(8, 3.0))
    x = np.arange(len(rb))
    axes[0].bar(x, rb.build_s, 0.5, label="build")
    axes[0].bar(x, rb.trace_s, 0.5, bottom=rb.build_s, label="trace")
    axes[0].set_xticks(x, [f"lambda {v:g}" for v in rb.lam])
    axes[0].set_ylabel(f"s per frame ({rb.scene.iloc[0]})")
    axes[0].legend(fontsize=6)
    for fam, d in mr.groupby(mr.scene.str.split("-").str[0], sort=False):
        d = d.sort_values("N")
        axes[1].plot(d.N, d.trace_s, "o-", ms=3, label=f"{fam} trace")
        axes[1].plot(d.N, d.build_s, "s--", ms=3, label=f"{fam} build")
    axes[1].set_xscale("log")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("triangles N")
    axes[1].set_ylabel("s per frame")
    axes[1].legend(fontsize=6)
    ctx.finish_figure(fig, "wald-fig8")


def main(ctx, args) -> int:
    return run_quiet(run, ctx, args)
