"""Hapala, Karlik & Havran 2011, Sec 3 ("Analysis and Discussion"): the two summary claims of the selector, computed
from ``table1h``'s rows (ours) and from the paper's own Table 1 beside the paper's printed values,
and the stand-ins matched to the paper's scenes by N and Havran's sigma.

* Build slowdown: the selector always builds the grid first, so a scene that ends with the kd-tree
  pays T_B^G on top of T_B^H. Printed: "4.5 % on average, with a minimum value of 2.1 %
  (1,070,671 triangles) and a maximum value of 15.4 % (528 triangles)".
* Small-budget speed-up: for O(log2 N) rays the selector (grid) against the hierarchy alone,
  (T_B^H + t_R^H log2 N) / (T_B^G + t_R^G log2 N). Printed: "average value of 28.07 with a minimum
  of 6.5 (528 triangles) and a maximum of 46.50 (1,070,671 triangles)".
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from costmodel.papers import hapala2011

#: our stand-in -> (the paper's scene, recipe). Arrays of copies (tracer.scenes.derived.array) with N = k
#: copies of the base mesh near the paper's N, the gap chosen once so that Havran's sigma (grid of N
#: cells, costmodel.havran) is near the paper's; table1h measures and prints the sigma it gets.
STAND_INS = {
    "array-11-53-sphere-2880": ("spheres", "11 UV spheres"),
    "array-8-99-teapot": ("teapots", "8 teapots"),
    "array-10-395-fandisk": ("case", "10 CAD parts (fandisk)"),
    "array-13-2006-dragon-11k": ("hunger", "13 dragons far apart"),
    "array-4-590-dragon-48k": ("sockets", "4 dragons"),
    "array-43-130-spot": ("chess", "43 figures (spot) on a lattice"),
    "array-25-605-fandisk": ("phone-high", "25 CAD parts (fandisk)"),
    "array-53-187-dragon-11k": ("pills-high", "53 dragons"),
    "array-19-1339-knot-56k": ("a10", "19 knots far apart"),
    "array-7-2891-dragon-202k": ("hunger-high", "7 dragons very far apart"),
    "array-125-653-fandisk": ("case-high", "125 CAD parts (fandisk)"),
    "array-24-202-bunny-69k": ("sockets-high", "24 bunnies"),
}
#: Sec 3 (Analysis and Discussion), as printed: (mean, min, max) of the build slowdown (%) and the log2 N speed-up
PAPER_PRINTED = {"slowdown_pct": tuple(c.value for c in hapala2011.BUILD_SLOWDOWN_PCT),
                 "speedup": tuple(c.value for c in hapala2011.LOG_RAYS_SPEEDUP)}


def hapala_sec3_build_slowdown(T_BG, T_BH):
    """Build slowdown of the selector when it ends with the hierarchy (Hapala Sec 3, Analysis): the grid it
    built first and discarded, T_B^G / T_B^H (the paper's bound: 1 + 1 / log2 N)."""
    return np.asarray(T_BG, float) / np.asarray(T_BH, float)


def hapala_sec3_speedup(N, T_BG, T_BH, t_RG, t_RH):
    """Speed-up of the selector (grid) over the hierarchy alone for log2 N rays (Hapala Sec 3, Analysis):
    (T_B^H + t_R^H · log2 N) / (T_B^G + t_R^G · log2 N), times in one unit."""
    lg = np.log2(np.asarray(N, float))
    return (np.asarray(T_BH, float) + np.asarray(t_RH, float) * lg) / (np.asarray(T_BG, float) + np.asarray(t_RG, float) * lg)


def _stats(name, unit, values, N, scenes, printed, paper_values, paper_N):
    v, pv = np.asarray(values, float), np.asarray(paper_values, float)
    i, j = int(np.argmin(v)), int(np.argmax(v))
    pi, pj = int(np.argmin(pv)), int(np.argmax(pv))
    return {"claim": name, "unit": unit, "scenes": len(v), "mean": float(v.mean()), "min": float(v[i]),
            "N_at_min": int(N[i]), "scene_at_min": scenes[i], "max": float(v[j]), "N_at_max": int(N[j]),
            "scene_at_max": scenes[j], "median": float(np.median(v)),
            "paper_printed_mean": printed[0], "paper_printed_min": printed[1], "paper_printed_max": printed[2],
            "paper_table_mean": float(pv.mean()), "paper_table_min": float(pv[pi]), "paper_table_N_at_min": int(paper_N[pi]),
            "paper_table_max": float(pv[pj]), "paper_table_N_at_max": int(paper_N[pj])}


def claims(tab: pd.DataFrame, paper: list, kinds=("random", "path")) -> pd.DataFrame:
    """One row per claim (slowdown; speed-up per ray kind): ours over ``tab`` (table1h's kd-tree
    table: ms and µs), the paper's printed values, and the same formula applied to the paper's
    Table 1 (``paper`` rows as :data:`costmodel.papers.hapala2011.TABLE1`)."""
    N, names = tab.N.to_numpy(), tab.scene.tolist()
    pN = np.array([p[1] for p in paper], float)
    pTG, pTH = np.array([p[3] for p in paper], float), np.array([p[4] for p in paper], float)
    rows = [_stats("build slowdown T_B^G / T_B^H", "%", 100 * hapala_sec3_build_slowdown(tab.T_BG_ms, tab.T_BH_ms), N, names,
                   PAPER_PRINTED["slowdown_pct"], 100 * hapala_sec3_build_slowdown(pTG, pTH), pN)]
    for kind, col in zip(kinds, (5, 8)):
        ours = hapala_sec3_speedup(N, tab.T_BG_ms, tab.T_BH_ms, tab[f"t_RG_us_{kind}"] / 1e3, tab[f"t_RH_us_{kind}"] / 1e3)
        theirs = hapala_sec3_speedup(pN, pTG, pTH, np.array([p[col] for p in paper]) / 1e3,
                                     np.array([p[col + 1] for p in paper]) / 1e3)
        rows.append(_stats(f"speed-up for log2 N {kind} rays", "x", ours, N, names, PAPER_PRINTED["speedup"], theirs, pN))
    return pd.DataFrame(rows)


def _relation(ours: float, paper: float, tol: float = 0.1) -> str:
    """"close to" within ``tol`` (relative), else "above" / "below"."""
    return "close to" if abs(ours - paper) <= tol * abs(paper) else ("above" if ours > paper else "below")


def claims_markdown(c: pd.DataFrame, tab: pd.DataFrame | None = None) -> str:
    lines = ["", "## Sec 3 (Analysis): build slowdown and small-budget speed-up (the paper's two summary claims)", "",
             "Build slowdown = T_B^G / T_B^H (the grid the selector builds first and then discards, when it keeps the "
             "kd-tree); speed-up = (T_B^H + t_R^H log2 N) / (T_B^G + t_R^G log2 N) (only log2 N rays: the grid against "
             "the kd-tree alone). Ours: every table1h scene, T_B minimum over builds, t_R per ray on one thread. "
             "\"Paper, printed\" is the text of Sec 3 (Analysis and Discussion); \"paper, from its Table 1\" is the same formula on the paper's "
             "own Table 1 (28 scenes, rounded ms and µs).", "",
             "| claim | ours: mean | min (N) | max (N) | paper, printed: mean | min | max | paper, from its Table 1: mean | min (N) | max (N) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for _, r in c.iterrows():
        f = (lambda v: f"{v:.1f} %") if r.unit == "%" else (lambda v: f"{v:.2f}")
        lines.append(f"| {r.claim} | {f(r['mean'])} | {f(r['min'])} ({r.N_at_min:,}) | {f(r['max'])} ({r.N_at_max:,}) | "
                     f"{f(r.paper_printed_mean)} | {f(r.paper_printed_min)} | {f(r.paper_printed_max)} | "
                     f"{f(r.paper_table_mean)} | {f(r.paper_table_min)} ({r.paper_table_N_at_min:,}) | "
                     f"{f(r.paper_table_max)} ({r.paper_table_N_at_max:,}) |")
    s, sp = c.iloc[0], c.iloc[1]
    above = []
    if tab is not None:
        slow = 100 * hapala_sec3_build_slowdown(tab.T_BG_ms, tab.T_BH_ms)
        above = [f"{n} ({v:.0f} %)" for n, v in zip(tab.scene, slow) if v > s.paper_printed_max]
    rows = hapala2011.TABLE1.records()
    i = next(j for j, r in enumerate(rows) if r["scene"] == "teapot")
    near = [r["T_BG_ms"] for r in rows[max(i - 2, 0):i] + rows[i + 1:i + 3]]
    lines += ["", f"* The paper's printed values cannot be recomputed exactly from its own Table 1: its slowdown mean is "
              f"{s.paper_table_mean:.1f} % from the table (printed {s.paper_printed_mean:g} %), but the table's teapot row "
              f"(T_B^G = {rows[i]['T_BG_ms']:g} ms against {min(near):g}–{max(near):g} ms for its neighbours) makes its "
              f"maximum {s.paper_table_max:.1f} %, and its speed-up mean is "
              f"{sp.paper_table_mean:.1f} (printed {sp.paper_printed_mean:g}).",
              f"* Ours: the slowdown is {s['mean']:.1f} % on average ({s['min']:.1f} % on {s.scene_at_min}, N = "
              f"{s.N_at_min:,}, to {s['max']:.1f} % on {s.scene_at_max}, N = {s.N_at_max:,}), median {s['median']:.1f} %. "
              f"Above the paper's largest ({s.paper_printed_max:.1f} %): {', '.join(above) or 'none'}; the paper's bound "
              "1 + 1 / log2 N assumes a grid build of O(N) with a small constant, and a long skinny triangle is "
              "referenced by many cells (table3), which makes our grid build of the cylinders cost as much as the kd-tree's.",
              f"* The small-budget speed-up (random rays) is {sp['mean']:.1f} on average ({sp['min']:.2f} on "
              f"{sp.scene_at_min} to {sp['max']:.1f} on {sp.scene_at_max}), {_relation(sp['mean'], sp.paper_printed_mean)} "
              f"the paper's printed {sp.paper_printed_mean:.2f}. For so few rays it is close to T_B^H / T_B^G, the build "
              "times' ratio (the table above gives ours beside the paper's); it falls below 1 only where our grid builds "
              "slower than our kd-tree (the long skinny cylinders)."]
    return "\n".join(lines) + "\n"
#: our scene -> the paper's scene it stands in for (same model or same procedural recipe)
PAPER_MATCH = {"boxes-44": "boxes", "cornell": "cornell", "sphere-2880": "sphere", "teapot": "teapot",
               "knot-56k": "knot", "bunny-69k": "bunny", "sphere-87k": "sphere-high", "conference-room": "conference"}
