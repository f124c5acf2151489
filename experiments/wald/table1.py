"""``wald-table1``: Wald et al. 2006 Table 1 — ray-triangle intersection tests of 4 x 4 frustum-grid
packets with neither mailboxing nor frustum culling (n/n), with mailboxing (y/n), and with both
(y/y). The paper: mailboxing alone cuts tests by up to 2x, culling another 4-9x, both together
8.5-14x, to about what a packet kd-tree does.

All three counts come from one counting traversal per scene (mailboxing and culling never change
the hits, so they never change which cells the packet visits): every reference met (n/n), the
first meeting of each triangle per packet (y/n), and those not rejected by the frustum (y/y) — each
times the rays in the packet. Grid as in the paper: lambda = 5, triangles inserted by bounding box.
Beside: the single-ray kd-tree of :mod:`tracer.accel.kdtree` (tests per ray) where the paper lists its
4 x 4 OpenRT kd-tree. Camera rays in 4 x 4 tile order at 1024 x 1024 (the paper's resolution).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from costmodel.papers import wald2006
from experiments.core.common import add_image_args, dash
from experiments.core.figures import subplots
from experiments.core.target import begin, run_quiet
from experiments.wald.lib.views import paper_cell, scene_label, wald_camera
from experiments.wald.lib.packets import count_tests

#: our scene, the paper's scene it stands in for, paper #tris, n/n, y/n, y/y (millions), kd-tree
PAPER = [(r["scene"], r["paper_scene"], r["tris"], r["tests_nn_M"], r["tests_yn_M"], r["tests_yy_M"], r["kdtree_M"])
         for r in wald2006.TABLE1.records()]
QUICK_SCENES = ["bunny-948", "dragon-11k"]
PAPER_RAYS = wald2006.IMAGE_SIDE.value ** 2


def add_arguments(p) -> None:
    add_image_args(p, "comma-separated scenes (default: the four stand-ins)", "image side (default 1024; --quick 128)")
    p.add_argument("--packet", type=int, default=4, help="packet size k (the paper: 4)")
    p.add_argument("--exact", action="store_true", help="exact triangle/cell insertion instead of bounding boxes")
    p.add_argument("--no-kdtree", action="store_true", help="skip the single-ray kd-tree column")


def kdtree_tests(scene, side: int) -> float:
    from tracer.accel.kdtree import KdTree
    rays = wald_camera(scene, side, 1)
    _, cnt = KdTree().build(scene).intersect(rays.origins, rays.directions)
    return float(cnt["tests"].mean())


def run(ctx, args, log=print) -> dict:
    tr = begin(ctx, args, "wald-table1", (QUICK_SCENES, [p[0] for p in PAPER]), threads=args.threads, log=log)
    quick = tr.quick
    side = tr.pick(args.side, 128, 1024)
    paper = {p[0]: p for p in PAPER}
    rows = []
    for name, scene in tr.scenes("wald-table1"):
        row = count_tests(scene, side, args.packet, args.exact)
        if not args.no_kdtree:
            row["kdtree_tests"] = kdtree_tests(scene, min(side, 256 if not quick else side))
        p = paper.get(name)
        if p:
            row.update({"paper_scene": p[1], "paper_N": p[2], "paper_nn": p[3], "paper_yn": p[4], "paper_yy": p[5],
                        "paper_kd": p[6]})
        rows.append(row)
        log(f"  {name}: n/n {row['tests_plain']:.1f}, y/n {row['tests_mb']:.1f}, y/y {row['tests_mb_fc']:.2f} tests/ray")
    df = pd.DataFrame(rows)
    df["mb_factor"] = df.tests_plain / df.tests_mb
    df["fc_factor"] = df.tests_mb / df.tests_mb_fc
    df["total_factor"] = df.tests_plain / df.tests_mb_fc
    if "paper_nn" in df:
        df["paper_mb_factor"] = df.paper_nn / df.paper_yn
        df["paper_fc_factor"] = df.paper_yn / df.paper_yy
        df["paper_total_factor"] = df.paper_nn / df.paper_yy
    tr.finish(_summary(df, side, args.packet, args.exact), {"table1.csv": df}, figure=lambda: _figure(ctx, df),
              side=side, packet=args.packet, exact=args.exact)
    return {"table": df}


def _summary(df, side, k, exact) -> str:
    scale = side * side / 1e6
    lines = [f"# Table 1 (Wald et al. 2006): ray-triangle tests, {k}x{k} packets, mailboxing (MB) and frustum culling (FC)",
             "", f"Camera rays {side}x{side} (the room viewed from inside, the other scenes from outside); grid lambda = 5, "
             f"{'exact' if exact else 'bounding-box'} insertion. The paper's Table 1 gives raw counts: millions of "
             "ray-triangle tests per 1024x1024 frame. Columns 'M/frame' are ours in the same unit (our per-ray count "
             f"x {side}² rays / 1e6) beside the paper's; 'per ray' is ours divided by the rays. Factors are ratios of "
             "counts (unitless). The kd-tree columns: ours is a single-ray SAH kd-tree, the paper's a 4x4 packet "
             "kd-tree (OpenRT).", "",
             "| scene (paper's) | N ours (paper) | n/n M/frame ours | n/n M/frame paper | y/n M/frame ours | "
             "y/n M/frame paper | y/y M/frame ours | y/y M/frame paper | y/y per ray ours | MB factor ours (paper) | "
             "FC factor ours (paper) | n/n over y/y ours (paper) | kd-tree M/frame ours | kd-tree M/frame paper |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for _, r in df.iterrows():
        cells = [f"{r[c] * scale:.2f} | {paper_cell(r, pc)}"
                 for c, pc in (("tests_plain", "paper_nn"), ("tests_mb", "paper_yn"), ("tests_mb_fc", "paper_yy"))]
        lines.append(
            f"| {scene_label(r)} | {r.N:,} ({paper_cell(r, 'paper_N', '{:,.0f}')}) | "
            + " | ".join(cells) + f" | {r.tests_mb_fc:.2f} | "
            f"{r.mb_factor:.2f} ({paper_cell(r, 'paper_mb_factor')}) | {r.fc_factor:.2f} ({paper_cell(r, 'paper_fc_factor')}) | "
            f"{r.total_factor:.1f} ({paper_cell(r, 'paper_total_factor', '{:.1f}')}) | "
            f"{dash(r.get('kdtree_tests', np.nan) * scale, '{:.2f}')} | {paper_cell(r, 'paper_kd')} |")
    lines += ["", "## Reading", "",
              "Paper: MB alone up to 2x, FC on top 4-9x, together 8.5-14x. Ours: MB "
              f"{df.mb_factor.min():.2f}-{df.mb_factor.max():.2f}x, FC on top {df.fc_factor.min():.1f}-{df.fc_factor.max():.1f}x, "
              f"together {df.total_factor.min():.1f}-{df.total_factor.max():.1f}x. "
              "Our culling rejects a triangle when its vertices lie outside one frustum plane (any packet) or when the "
              "four corner rays miss it on one edge (Dmitriev's test, common origin, triangles wider than a cell). "
              + (f"Packets of {k}x{k} at {side}² cover {(1024 / side) ** 2:g}x the scene area of the paper's at 1024², "
                 "which raises n/n and the mailboxing factor. " if side != 1024 else "")
              + "Views differ from the paper's (ours: the models framed from outside; the room from an eye among its "
              "tables, as the paper looks around inside the conference room). Our kd-tree count is per ray of a "
              "single-ray kd-tree traced at min(side, 256)² and scaled to the frame; the paper's counts a 4x4 packet "
              "kd-tree's tests."]
    return "\n".join(lines) + "\n"


def _figure(ctx, df):
    fig, ax = subplots(figsize=(5.5, 3.0))
    x = np.arange(len(df))
    for j, (col, lab) in enumerate((("tests_plain", "n/n"), ("tests_mb", "MB"), ("tests_mb_fc", "MB + FC"))):
        ax.bar(x + (j - 1) * 0.27, df[col], 0.27, label=f"ours {lab}")
    if "paper_nn" in df:
        for j, col in enumerate(("paper_nn", "paper_yn", "paper_yy")):
            ax.plot(x + (j - 1) * 0.27, df[col], "k_", ms=10, label="paper (M per 1024² frame)" if j == 0 else None)
    ax.set_yscale("log")
    ax.set_xticks(x, df.scene, fontsize=7)
    ax.set_ylabel("ray-triangle tests per ray")
    ax.legend(fontsize=6)
    ctx.finish_figure(fig, "wald-table1")


def main(ctx, args) -> int:
    return run_quiet(run, ctx, args)
