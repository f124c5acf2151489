"""``wald-table3``: Wald et al. 2006 Table 3 — single-ray grid against 8 x 8 (and 4 x 4) frustum
packets, frames per second at 1024 x 1024 camera rays on one thread, beside the paper's speed-ups
(:data:`costmodel.papers.wald2006.TABLE3`). Beside it: macrocells on/off for the packets (Sec 2.4,
:data:`costmodel.papers.wald2006.MACROCELL_GAIN_PCT`) with their
effect on visited cells, and Sec 4.7's shadow packets (rays from a point light to the primary hits,
any-hit packets against the single-ray grid's any-hit query).

All times of one scene come from one run of interleaved rounds (:func:`tracer.measure.timing.time_paired`),
ratios are medians of per-round ratios. Single ray: :class:`tracer.accel.grid.UniformGrid` at the packet
grid's resolution (lambda = 5), with 2^k macrocells when they are faster on this scene (the paper's
"using a macrocell hierarchy if advantageous"). Packets: :class:`tracer.accel.packet.CoherentGrid`,
lambda = 5, macrocells M = 6 (the paper's default) unless said otherwise. Only ray traversal is
timed (no shading: the paper's fps include simple shading).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from experiments.core.common import add_image_args
from experiments.core.figures import subplots
from experiments.core.target import begin, run_quiet
from costmodel.papers import wald2006
from experiments.wald.lib.packets import packet_work
from experiments.wald.lib.views import paper_cell as _p
from experiments.wald.lib.views import light_position, paired, scene_label, shadow_rays, wald_camera
from tracer.accel.grid import UniformGrid
from tracer.accel.packet import CoherentGrid
from tracer.measure.machine import doubles_per_vector
from tracer.measure.timing import clock_name

#: the paper's Table 3 (frames per second at 1024², 1 thread): paper scene -> (single-ray, 8x8 packets, ratio)
PAPER = {r["paper_scene"]: (r["single_fps"], r["packet8_fps"], r["ratio"]) for r in wald2006.TABLE3.records()}
#: our stand-in -> the paper's scene (wald-table4's list)
STAND_IN = {r["scene"]: r["paper_scene"] for r in wald2006.TABLE4.records()}
QUICK_SCENES = ["bunny-948", "cornell"]
#: the paper's macrocell gain ("around 30%") and shadow-packet claim (Sec 4.7)
PAPER_MACRO_GAIN = 1 + wald2006.MACROCELL_GAIN_PCT.value / 100


def add_arguments(p) -> None:
    add_image_args(p, "comma-separated scenes (default: the five Table 1/4 stand-ins)",
                   "image side (default 1024, the paper's; --quick 128)", "interleaved rounds (default 5)")


def measure(scene, side: int, rounds: int) -> dict:
    """One scene: build everything, count the work, then time all variants in interleaved rounds."""
    r8, r4 = wald_camera(scene, side, 8), wald_camera(scene, side, 4)
    c8 = CoherentGrid(packet=8).build(scene)
    c8n = CoherentGrid(packet=8, macro=0, res=c8.res_).build(scene)
    c4 = CoherentGrid(packet=4, res=c8.res_).build(scene)
    g = UniformGrid(res=c8.res_).build(scene)
    gm = UniformGrid(res=c8.res_, macro=4).build(scene)
    hits, _ = c8.intersect(r8.origins, r8.directions, counters=False)
    so, sd, stmax = shadow_rays(r8, hits.t, light_position(scene))
    fns = {"grid": lambda: g.intersect(r8.origins, r8.directions, counters=False),
           "grid_macro": lambda: gm.intersect(r8.origins, r8.directions, counters=False),
           "p8": lambda: c8.intersect(r8.origins, r8.directions, counters=False),
           "p8_nomacro": lambda: c8n.intersect(r8.origins, r8.directions, counters=False),
           "p4": lambda: c4.intersect(r4.origins, r4.directions, counters=False)}
    if len(so):
        fns["shadow_grid"] = lambda: g.occluded(so, sd, stmax)
        fns["shadow_grid_macro"] = lambda: gm.occluded(so, sd, stmax)
        fns["shadow_p8"] = lambda: c8.occluded(so, sd, stmax)
    sec, up = paired(fns, rounds, "p8")
    single = "grid_macro" if sec["grid_macro"] < sec["grid"] else "grid"
    n = r8.n
    w8, w8n = packet_work(c8, r8), packet_work(c8n, r8)
    _, cg = g.intersect(r8.origins, r8.directions)
    row = {"scene": scene.name, "N": scene.n, "res": "x".join(str(v) for v in c8.res_), "side": side, "rays": n,
           "hit_frac": float(np.isfinite(hits.t).mean()), "single_variant": single,
           "single_fps": 1 / sec[single], "p8_fps": 1 / sec["p8"], "p4_fps": 1 / sec["p4"],
           "p8_nomacro_fps": 1 / sec["p8_nomacro"],
           "single_mrays": n / sec[single] / 1e6, "p8_mrays": n / sec["p8"] / 1e6, "p4_mrays": n / sec["p4"] / 1e6,
           # per-round ratios: p8 over single = time[single] / time[p8]
           "ratio_p8": 1 / up[single][0], "ratio_p8_min": 1 / up[single][2], "ratio_p8_max": 1 / up[single][1],
           "ratio_p4": up["p4"][0] / up[single][0],
           "macro_gain": 1 / up["p8_nomacro"][0],  # time without / time with macrocells
           "cells_single": float(cg["steps"].mean()), "cells_p8": w8["cells"], "cells_p8_nomacro": w8n["cells"],
           "macro_skips_p8": w8["macro_skips"], "grid_macro_gain": sec["grid"] / sec["grid_macro"]}
    if len(so):
        ssingle = "shadow_grid_macro" if sec["shadow_grid_macro"] < sec["shadow_grid"] else "shadow_grid"
        occ = c8.occluded(so, sd, stmax)
        row.update({"shadow_rays": len(so), "shadow_occluded": float(occ.mean()),
                    "shadow_single_mrays": len(so) / sec[ssingle] / 1e6, "shadow_p8_mrays": len(so) / sec["shadow_p8"] / 1e6,
                    "shadow_ratio": up["shadow_p8"][0] / up[ssingle][0],  # time[single] / time[p8]
                    "shadow_single_frac": _single_frac(c8, so, sd, stmax)})
    p = PAPER.get(STAND_IN.get(scene.name, ""))
    if p:
        row.update({"paper_scene": STAND_IN[scene.name], "paper_single_fps": p[0], "paper_p8_fps": p[1], "paper_ratio": p[2]})
    return row


def _single_frac(cgt, o, d, tmax) -> float:
    """Share of the shadow rays meeting the grid that left their packet (too wide a frustum, e.g. at
    a silhouette) and were traced on their own (the paper splits such packets instead)."""
    pc = cgt.packet_counters(o, d, tmax=tmax)
    s, p = pc["single"].sum(), pc["packet_rays"].sum()
    return float(s / max(s + p, 1))


def run(ctx, args, log=print) -> dict:
    tr = begin(ctx, args, "wald-table3", (QUICK_SCENES, list(STAND_IN)), threads=1, log=log)
    side = tr.pick(args.side, 128, 1024)
    rounds = args.repeats or 5
    rows = []
    for name, scene in tr.scenes("wald-table3"):
        row = measure(scene, side, rounds)
        rows.append(row)
        log(f"  {name}: single {row['single_mrays']:.2f}, 8x8 {row['p8_mrays']:.2f} Mrays/s ({row['ratio_p8']:.2f}x)")
    df = pd.DataFrame(rows)
    tr.finish(_summary(df, side, rounds), {"table3.csv": df}, figure=lambda: _figure(ctx, df), side=side, rounds=rounds)
    return {"table": df}


def _macro_paper(quote: bool = True) -> str:
    """The paper's macrocell gain as a time ratio, recomputed from its Sec 2 percentage."""
    g = wald2006.MACROCELL_GAIN_PCT
    return f"about {1 + g.value / 100:.2f}x, recomputed from {g.where}" + (f"'s \"{g.quote}\"" if quote else "")


def _summary(df, side, rounds) -> str:
    lines = [f"# Table 3 (Wald et al. 2006): single-ray grid vs frustum packets, {side}x{side} camera rays, 1 thread", "",
             f"Primary camera rays {side}x{side} (the room viewed from inside, the others from outside), lambda = 5, "
             f"{clock_name()}, {rounds} interleaved rounds; fps = frames of {side}² rays per second, ray traversal only "
             "(the paper's fps include simple shading, on a 3.2 GHz Pentium IV). Speed-ups are medians of per-round "
             "time ratios (min-max over rounds in brackets).", "",
             "| scene (paper's) | N | single-ray fps ours (paper) | 8x8 fps ours (paper) | 4x4 fps ours | "
             "8x8 / single ours [rounds] (paper) | 4x4 / single ours | single Mrays/s | 8x8 Mrays/s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for _, r in df.iterrows():
        lines.append(
            f"| {scene_label(r)} | {r.N:,} | {r.single_fps:.2f} ({_p(r, 'paper_single_fps')}) | "
            f"{r.p8_fps:.2f} ({_p(r, 'paper_p8_fps', '{:.1f}')}) | {r.p4_fps:.2f} | {r.ratio_p8:.2f} "
            f"[{r.ratio_p8_min:.2f}-{r.ratio_p8_max:.2f}] ({_p(r, 'paper_ratio')}) | {r.ratio_p4:.2f} | "
            f"{r.single_mrays:.2f} | {r.p8_mrays:.2f} |")
    lines += ["", "Single ray: uniform grid at the packet grid's resolution"
              + "; with macrocells where faster (" + ", ".join(f"{r.scene}: {'yes' if r.single_variant == 'grid_macro' else 'no'}"
                                                          for _, r in df.iterrows()) + ").", "",
              "## Macrocells (8x8 packets, M = 6)", "",
              f"| scene | time without / with macrocells ours (paper: {_macro_paper(False)}) | cells per ray with | without | "
              "macrocell slab skips per ray | single-ray cells per ray |", "|---|---|---|---|---|---|"]
    for _, r in df.iterrows():
        lines.append(f"| {r.scene} | {r.macro_gain:.2f} | {r.cells_p8:.3f} | {r.cells_p8_nomacro:.3f} | "
                     f"{r.macro_skips_p8:.3f} | {r.cells_single:.1f} |")
    if "shadow_ratio" in df:
        lines += ["", "## Shadow packets (Sec 4.7)", "",
                  "Shadow rays from one point light (common origin) to every primary hit, in the primary 8x8 tiles; "
                  "any-hit queries (a ray that hits is retired at once). The paper gives no shadow timing of its own "
                  "beyond \"shadow rays in practice work just as well as primary rays\" (with packet splitting).", "",
                  "| scene | shadow rays | occluded | single-ray any-hit Mrays/s | 8x8 any-hit Mrays/s | 8x8 / single | "
                  "8x8 / single on primary rays | rays traced on their own |", "|---|---|---|---|---|---|---|---|"]
        for _, r in df.iterrows():
            lines.append(f"| {r.scene} | {int(r.shadow_rays):,} | {100 * r.shadow_occluded:.1f}% | {r.shadow_single_mrays:.2f} | "
                         f"{r.shadow_p8_mrays:.2f} | {r.shadow_ratio:.2f} | {r.ratio_p8:.2f} | {100 * r.shadow_single_frac:.1f}% |")
    paper = [r["ratio"] for r in wald2006.TABLE3.records()]
    lanes = doubles_per_vector()
    lines += ["", "## Reading", "",
              f"Paper ({wald2006.TABLE3.where}, its ratio row): 8x8 packets {min(paper):g}-{max(paper):g}x faster "
              f"than its single-ray grid. Ours: {df.ratio_p8.min():.2f}-"
              f"{df.ratio_p8.max():.2f}x (4x4: {df.ratio_p4.min():.2f}-{df.ratio_p4.max():.2f}x). Ours is smaller "
              "because our single-ray grid is a tight compiled 3D-DDA over flat arrays while the packet kernel is "
              f"float64 ({lanes} doubles per vector register on this CPU, where the paper's SSE test took 4 floats), "
              "and the paper's single-ray grid was multi-level. Packets do cut the visited cells as in the paper's "
              "Table 4: single-ray "
              f"cells per ray over 8x8-packet cells per ray here {(df.cells_single / df.cells_p8).min():.0f}-"
              f"{(df.cells_single / df.cells_p8).max():.0f}x. Macrocells: ours {df.macro_gain.min():.2f}-"
              f"{df.macro_gain.max():.2f}x (paper: {_macro_paper()}); "
              "a camera framing a single model from outside spends little of its walk in empty space inside the "
              "grid, so there is less to skip than in the paper's scenes. Absolute fps are not comparable (other "
              "CPU, no shading); this machine is shared, so read the paired ratios, not the fps."]
    return "\n".join(lines) + "\n"


def _figure(ctx, df):
    fig, ax = subplots(figsize=(5.5, 3.0))
    x = np.arange(len(df))
    ax.bar(x - 0.2, df.ratio_p8, 0.4, label="ours 8x8 / single")
    ax.bar(x + 0.2, df.ratio_p4, 0.4, label="ours 4x4 / single")
    if "paper_ratio" in df:
        ax.plot(x - 0.2, df.paper_ratio, "k_", ms=12, label="paper 8x8 / single")
    ax.set_xticks(x, df.scene, fontsize=7)
    ax.set_ylabel("speed-up over single-ray grid")
    ax.legend(fontsize=6)
    ctx.finish_figure(fig, "wald-table3")


def main(ctx, args) -> int:
    return run_quiet(run, ctx, args)
