"""``fournier-table1``, the parts beyond the SPD rows: the teapot counted per object (Newell's
patches, as the paper counts them), the *Around Again* stand-in traced with primary and secondary
rays (lists against the 30³ grid: tests relative to the minimum, events, time), and the figure of
times beside counts."""
from __future__ import annotations

import numpy as np

#: the paper on Around Again: grid tests / minimum, list tests / minimum, list time / grid time
PAPER_AROUND = {"grid_over_min": 618.0, "lists_over_min": 4.5, "list_over_grid_time": 0.35,
                "objects": 25426 + 4610 + 636}
AROUND_STRUCTS = ("grid30", "grid30mb", "sl-hier")
RAY_KINDS = ("primary", "shadow", "reflection")
#: at most this many rays of each kind are checked against the float64 oracle
ORACLE_RAYS = 4096
#: rays x objects elements per chunk of :func:`flat_object_counts` (a few arrays of this many float64)
FLAT_CHUNK_ELEMENTS = 4_000_000
#: bytes one (ray, object) element costs in a chunk of :func:`_flat_counts_chunk` (about twenty
#: float64 (rays, objects) arrays live at once, the six-wide event array included)
FLAT_BYTES_PER_ELEMENT = 256


def flat_chunk_rays(n_objects: int) -> int:
    """Rays per chunk of the (rays, objects) arrays: at most FLAT_CHUNK_ELEMENTS elements and a
    quarter of the memory budget; one ray when even that is over the budget is refused."""
    from tracer.measure.memory import check_budget, memory_budget
    check_budget(f"per-object event counts of one ray over {n_objects:,} objects", n_objects * FLAT_BYTES_PER_ELEMENT)
    per = min(FLAT_CHUNK_ELEMENTS, memory_budget() // (4 * FLAT_BYTES_PER_ELEMENT))
    return max(1, per // max(1, n_objects))


# ---------------------------------------------------------------- flat lists counted per object
def flat_object_counts(boxes, o, d, f) -> dict:
    """Per ray, what the flat sorted lists of the paper's Table 1 do when the objects are the boxes
    ``boxes`` ((M, 6) lo xyz, hi xyz) and the closest hit lies at ``f`` (inf: none), counted as
    :class:`tracer.accel.sortedlists.SortedLists` (``hierarchy=False``) counts them: the root (the box of
    all objects) is opened at the ray's entry into it (t ≥ 0), treating the events before it; the
    walk then treats events in Δt order and stops past ``f`` or at the end of a list (the root's
    exit). An object is tested when entered on all three axes before it is exited on any, at or
    after the opening and before the walk stops. Returns arrays ``tests``, ``events`` (from −∞, as
    our lists count) and ``events_ahead`` (0 ≤ Δt: the paper's, whose camera initialisation treats
    the events behind the eye once per image)."""
    o, d, f = (np.asarray(a, np.float64) for a in (o, d, f))
    # rays in chunks: the arrays below are (rays, objects), 16,384 x 16,384 for tetra-7 at 128²
    step = flat_chunk_rays(len(boxes))
    parts = [_flat_counts_chunk(np.asarray(boxes, np.float64), o[i:i + step], d[i:i + step], f[i:i + step])
             for i in range(0, len(o), step)]
    return {k: np.concatenate([p[k] for p in parts]) for k in ("tests", "events", "events_ahead")}


def _flat_counts_chunk(boxes, o, d, f) -> dict:
    """:func:`flat_object_counts` of one chunk of rays."""
    m = len(o)
    lo, hi = boxes[:, :3], boxes[:, 3:]
    a = np.full((m, len(boxes)), -np.inf)
    b = np.full((m, len(boxes)), np.inf)
    r0, r1 = np.full(m, -np.inf), np.full(m, np.inf)
    ev = []
    static = np.zeros(m)
    for k in range(3):
        dk, ok = d[:, k:k + 1], o[:, k:k + 1]
        mv = dk[:, 0] != 0
        with np.errstate(divide="ignore", invalid="ignore"):
            t_lo, t_hi = (lo[:, k] - ok) / dk, (hi[:, k] - ok) / dk
        t_in, t_out = np.minimum(t_lo, t_hi), np.maximum(t_lo, t_hi)
        inside = (lo[:, k] <= ok) & (ok <= hi[:, k])
        t_in = np.where(mv[:, None], t_in, np.where(inside, -np.inf, np.inf))
        t_out = np.where(mv[:, None], t_out, np.where(inside, np.inf, -np.inf))
        a, b = np.maximum(a, t_in), np.minimum(b, t_out)
        ra, rb = t_in.min(1), t_out.max(1)  # the root's slab on this axis
        r0, r1 = np.maximum(r0, np.where(mv, ra, -np.inf)), np.minimum(r1, np.where(mv, rb, np.inf))
        ev.append(np.where(mv[:, None], np.concatenate([t_lo, t_hi], 1), np.nan))
        # a static axis: its IN events where lo <= o and its OUT events where hi < o lie at -inf
        static += np.where(mv, 0, (lo[:, k] <= ok).sum(1) + (hi[:, k] < ok).sum(1))
    root = (r0 <= r1) & (r1 >= 0)
    tcur = np.maximum(r0, 0.0)
    stop = np.minimum(f, r1)
    ev = np.concatenate(ev, 1)
    events = np.where(root, (ev <= stop[:, None]).sum(1) + static, 0)
    ahead = np.where(root, ((ev >= 0) & (ev <= stop[:, None])).sum(1), 0)
    tests = np.where(root, ((a <= b) & (b >= tcur[:, None]) & (a <= stop[:, None])).sum(1), 0)
    return {"tests": tests, "events": events, "events_ahead": ahead}


def object_boxes(tris, obj) -> np.ndarray:
    """(M, 6) box of each object's triangles (``obj`` = object id per triangle)."""
    v = np.asarray(tris, np.float64)
    n = int(obj.max()) + 1
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    np.minimum.at(lo, obj, v.min(1))
    np.maximum.at(hi, obj, v.max(1))
    return np.concatenate([lo, hi], 1)


# ---------------------------------------------------------------- Around Again
def _trace(acc, o, d, tmax, count=True):
    """Closest hit, or any hit before ``tmax`` (shadow rays), with counters."""
    from tracer.accel import Counters, as_rays, tmax_array
    ro, rd = as_rays(o, d)
    t, ids, cnt = acc._trace(ro, rd, 0.0, tmax_array(tmax, len(ro)), tmax is not None, count)
    return t, ids, (Counters(cnt, acc.counter_fields) if count else None)


def measure_around(res, repeats, leaf_size, branching) -> list[dict]:
    """Trace the Around Again stand-in with primary rays (res x res) and, from their hits, one
    shadow ray (to the point light; any hit) and one mirror reflection ray each, through the 30³
    grid (plain and mailboxed) and the sorted-list hierarchy: counts per ray kind and over all rays,
    hits checked against the float64 oracle, and the time of the whole set (lists vs grid, paired)."""
    from tracer.accel.grid import UniformGrid
    from tracer.accel.oracle import oracle_intersect
    from tracer.accel.sortedlists import SortedLists
    from tracer.measure.timing import build_clock, paired_ratio, time_paired
    from experiments.fournier.lib.scenes import around_again_primary, around_again_scene, secondary_rays
    scene, kind = around_again_scene()
    o, d = around_again_primary(res)
    ref, _ = oracle_intersect(scene, o, d)
    rays = {"primary": (o, d, None), **secondary_rays(scene, o, d, ref.t, ref.tri_id)}
    built = {}
    for s in AROUND_STRUCTS:
        t0 = build_clock()
        acc = (UniformGrid(res=(30, 30, 30), mailbox=(s == "grid30mb")) if s.startswith("grid")
               else SortedLists(hierarchy=True, leaf_size=leaf_size, branching=branching)).build(scene)
        built[s] = (acc, build_clock() - t0)
    refs = {}
    for k, (ro, rd, tm) in rays.items():
        step = max(1, len(ro) // ORACLE_RAYS)
        r, _ = oracle_intersect(scene, ro[::step], rd[::step], tmax=tm[::step] if tm is not None else None)
        refs[k] = (step, r.t, r.tri_id)
    render = lambda acc: [_trace(acc, *rays[k], count=False) for k in RAY_KINDS]  # noqa: E731
    tp = time_paired({s: (lambda a=built[s][0]: render(a)) for s in ("grid30", "sl-hier")}, rounds=repeats, repeats=1)
    rows = []
    for s, (acc, build_s) in built.items():
        tot = {"rays": 0, "hits": 0, "tests": 0, "steps": 0, "nodes": 0, "bad": 0, "checked": 0}
        for k in RAY_KINDS:
            ro, rd, tm = rays[k]
            t, ids, cnt = _trace(acc, ro, rd, tm)
            step, rt, rid = refs[k]
            a, b = ids[::step] >= 0, rid >= 0
            if tm is None:  # closest hit: same t; shadow rays: same verdict
                both = a & b
                ta, tb = np.where(both, t[::step], 0.0), np.where(both, rt, 0.0)
                bad = (a != b) | (both & (np.abs(ta - tb) > 1e-5 * np.maximum(np.abs(tb), 1e-30)))
            else:
                bad = a != b
            c = cnt.total()
            row = {"scene": "around-again", "N": scene.n, "cans_tris": int((kind == 0).sum()),
                   "long_polygons_tris": int((kind == 1).sum()), "structure": s, "ray_kind": k, "rays": len(ro),
                   "hit_frac": float(np.mean(ids >= 0)), "tests_per_ray": c["tests"] / len(ro),
                   "events_per_ray": c["steps"] / len(ro), "nodes_per_ray": c["nodes"] / len(ro),
                   "oracle_checked": int(len(rid)), "disagreements": int(bad.sum()), "build_s": build_s, "res": res}
            rows.append(row)
            for key, v in (("rays", len(ro)), ("hits", int((ids >= 0).sum())), ("tests", c["tests"]),
                           ("steps", c["steps"]), ("nodes", c["nodes"]), ("bad", row["disagreements"]),
                           ("checked", len(rid))):
                tot[key] += v
        n = tot["rays"]
        row = {"scene": "around-again", "N": scene.n, "cans_tris": int((kind == 0).sum()),
               "long_polygons_tris": int((kind == 1).sum()), "structure": s, "ray_kind": "all", "rays": n,
               "hit_frac": tot["hits"] / n, "tests_per_ray": tot["tests"] / n, "events_per_ray": tot["steps"] / n,
               "nodes_per_ray": tot["nodes"] / n, "oracle_checked": tot["checked"], "disagreements": tot["bad"],
               "build_s": build_s, "res": res}
        if s in tp:
            runs = np.asarray(tp[s])
            row.update(ns_per_ray=float(np.median(runs)) / n * 1e9,
                       timing_spread=float((runs.max() - runs.min()) / np.median(runs)))
        if s == "sl-hier":
            row["paired_ratio_to_grid30"] = paired_ratio(tp, "sl-hier", "grid30")[0]
        rows.append(row)
    for r in rows:
        r["tests_over_min"] = r["tests_per_ray"] / max(r["hit_frac"], 1e-12)
    return rows


def around_summary(df) -> list[str]:
    """The Around Again section of summary.md."""
    if df is None or not len(df):
        return []
    g = df.set_index(["structure", "ray_kind"])
    first = df.iloc[0]
    n_p = int(g.loc[("grid30", "primary")].rays)
    lines = [
        "## Around Again: primary and secondary rays, lists vs the 30³ grid", "",
        f"Stand-in for the paper's scene (Fig. 11; {PAPER_AROUND['objects']:,} polygons: 25,426 triangles, 4,610 "
        f"quadrilaterals, 636 larger polygons), built in `experiments/fournier/lib/scenes.py`: 28 drink cans of 1,056 "
        f"small triangles each ({int(first.cans_tris):,}), stacked and lying beside a ground and three walls "
        f"({int(first.long_polygons_tris)} long triangles), N = {int(first.N):,}. Rays: {n_p:,} primary rays "
        f"(a {int(first.res)}² pinhole image from inside the room), then from each primary hit one shadow ray to a "
        "point light (stops at the first occluder) and one mirror reflection ray. *Minimum* = rays that hit (one "
        "test each; for shadow rays, rays occluded). Tests and events per ray are means over the rays of the kind "
        "(grid: cells visited in the events column); *all* = the whole set. Time: the whole set traced single-"
        "threaded, lists against the grid (`UniformGrid(res=(30, 30, 30))`), interleaved rounds, median ratio.", "",
        "| rays | rays traced | minimum (hits/ray) | grid 30³ tests/ray | grid tests / minimum ours (paper) | "
        "grid, mailboxed, tests / minimum | list (hierarchy) tests/ray | list tests / minimum ours (paper) | "
        "list events/ray | grid cells/ray | oracle disagreements (checked) |",
        "|---|---|---|---|---|---|---|---|---|---|---|"]
    for k in RAY_KINDS + ("all",):
        gr, mb, sl = g.loc[("grid30", k)], g.loc[("grid30mb", k)], g.loc[("sl-hier", k)]
        paper = k == "all"
        bad = int(gr.disagreements + mb.disagreements + sl.disagreements)
        lines.append(
            f"| {k} | {int(gr.rays):,} | {gr.hit_frac:.3f} | {gr.tests_per_ray:.1f} | {gr.tests_over_min:.1f}x"
            + (f" ({PAPER_AROUND['grid_over_min']:.0f}x)" if paper else "") + f" | {mb.tests_over_min:.1f}x | "
            f"{sl.tests_per_ray:.2f} | {sl.tests_over_min:.2f}x" + (f" ({PAPER_AROUND['lists_over_min']:.1f}x)" if paper else "")
            + f" | {sl.events_per_ray:.1f} | {gr.events_per_ray:.1f} | {bad} ({int(gr.oracle_checked):,} per structure) |")
    a_sl, a_gr = g.loc[("sl-hier", "all")], g.loc[("grid30", "all")]
    ratio = a_sl.get("paired_ratio_to_grid30", np.nan)
    lines += ["", f"List time / grid time, all rays: ours **{ratio:.0%}** (paper 35 % of the 30³ grid's total "
              f"rendering time); ours per ray {a_gr.ns_per_ray:,.0f} ns (grid) and {a_sl.ns_per_ray:,.0f} ns (lists).", "",
              "Where ours differs: the paper's 618x comes from its scene's polygons (its cans and long polygons in "
              "an unknown layout, its own view and lights); ours counts triangle tests over our stand-in, without "
              "mailboxing in the 618x column (the mailboxed column shows how much of the excess is the same triangle "
              "re-tested in the cells a ray crosses). The paper's time ratio includes shading and its secondary "
              "rays' fast initialisation from the parent's ray list, which our lists do not have (every secondary "
              "ray starts afresh at the root); ours is tracing only, on a CPU where a cell step and a triangle test "
              "cost relatively less against an event than in 1993."]
    return lines


# ---------------------------------------------------------------- figure: times beside counts
def time_figure(ctx, df, around, paper_table1, target) -> None:
    """One column per scene family (and one for Around Again): time per ray, tests and events per
    ray, and time ratios, lists vs the 30³ grid; the paper's numbers where it gives them."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter
    from experiments.core.figures import log_scale, row_legend
    paper = {p[0]: p for p in paper_table1}
    fams = list(dict.fromkeys(df.family))
    ncol = len(fams) + (1 if around is not None and len(around) else 0)
    fig, axes = plt.subplots(3, ncol, figsize=(2.9 * ncol, 7.6), squeeze=False)
    style = {"grid30": ("s-", "C0", "grid 30³"), "sl-hier": ("o-", "C2", "lists, hierarchy"),
             "sl-flat": ("^--", "C1", "lists, flat"), "nogrid": ("x:", "C7", "no grid")}
    for j, fam in enumerate(fams):
        d = df[df.family == fam]
        ax0, ax1, ax2 = axes[0][j], axes[1][j], axes[2][j]
        for kind, (fmt, col, label) in style.items():
            k = d[d.structure == kind].sort_values("N")
            if len(k):
                ax0.plot(k.N, k.ns_per_ray, fmt, color=col, ms=3, lw=1, label=label)
        for kind, key, fmt, col, label in (("grid30", "tests_per_ray", "s-", "C0", "grid tests"),
                                           ("grid30", "events_per_ray", "s:", "C0", "grid cells"),
                                           ("sl-hier", "tests_per_ray", "o-", "C2", "hierarchy tests"),
                                           ("sl-hier", "events_per_ray", "o:", "C2", "hierarchy events")):
            k = d[d.structure == kind].sort_values("N")
            if len(k):
                ax1.plot(k.N, k[key], fmt, color=col, ms=3, lw=1, label=label)
        w = d.pivot_table(index="N", columns="structure", values="ns_per_ray")
        if {"sl-hier", "grid30"} <= set(w.columns):
            ax2.plot(w.index, w["sl-hier"] / w["grid30"], "o-", color="C2", ms=3, lw=1, label="hierarchy / grid (ours)")
        if {"sl-flat", "nogrid"} <= set(w.columns):
            r = (w["sl-flat"] / w["nogrid"]).dropna()
            ax2.plot(r.index, r.values, "^--", color="C1", ms=3, lw=1, label="flat / no grid (ours)")
        pp = [(int(x.N), paper[x.scene]) for _, x in d.drop_duplicates("scene").iterrows() if x.scene in paper]
        if pp:
            ax2.plot([n for n, _ in pp], [p[7] / p[4] for _, p in pp], "r*", ms=7, label="flat / no grid (paper Table 1)")
        ax2.axhline(1.0, color="k", lw=0.6, ls=":")
        for i, ax in enumerate((ax0, ax1, ax2)):
            log_scale(ax, "x", d.N)
            log_scale(ax, "y", [v for ln in ax.get_lines() for v in np.atleast_1d(ln.get_ydata())])
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.yaxis.set_minor_formatter(NullFormatter())
            ax.tick_params(labelsize=7)
            ax.set_xlabel("triangles N (same size factor as the paper's row)" if i == 2 else "triangles N", fontsize=7)
        ax0.set_title(fam, fontsize=9)
    axes[0][0].set_ylabel("time per eye ray (ns, 1 thread)", fontsize=8)
    axes[1][0].set_ylabel("tests / events per eye ray", fontsize=8)
    axes[2][0].set_ylabel("time ratio", fontsize=8)
    if ncol > len(fams):
        _around_panels([axes[i][-1] for i in range(3)], around)
    for i in range(3):
        row_legend(axes[i])
    fig.suptitle("Fournier & Poulin 1993: times beside counts, sorted lists vs a 30³ grid (SPD and teapot: eye rays; "
                 "Around Again: primary + shadow + reflection rays)", fontsize=8)
    ctx.finish_figure(fig, f"{target}-times")


def _around_panels(axes, around):
    g = around.set_index(["structure", "ray_kind"])
    kinds = list(RAY_KINDS) + ["all"]
    x = np.arange(len(kinds))
    ax0, ax1, ax2 = axes
    for s, col, off, lab in (("grid30", "C0", -0.2, "grid 30³ (bars)"), ("sl-hier", "C2", 0.2, "lists, hierarchy (bars)")):
        ax1.bar(x + off, [g.loc[(s, k)].tests_over_min for k in kinds], 0.4, color=col, label=lab)
    ax1.plot([x[-1] - 0.2], [PAPER_AROUND["grid_over_min"]], "r*", ms=8, label="paper (Around Again, all rays)")
    ax1.plot([x[-1] + 0.2], [PAPER_AROUND["lists_over_min"]], "r*", ms=8)
    ax1.set_yscale("log")
    ax1.set_ylabel("tests / minimum", fontsize=7)
    a = [g.loc[(s, "all")] for s in ("grid30", "sl-hier")]
    ax0.bar([0, 1], [r.ns_per_ray for r in a], 0.6, color=["C0", "C2"])
    ax0.set_xticks([0, 1], ["grid 30³", "lists"], fontsize=7)
    ax0.set_ylabel("ns per ray, all rays", fontsize=7)
    ax2.bar([0], [a[1].paired_ratio_to_grid30], 0.5, color="C2", label="lists / grid (ours)")
    ax2.bar([1], [PAPER_AROUND["list_over_grid_time"]], 0.5, color="r", alpha=0.6, label="lists / grid (paper)")
    ax2.axhline(1.0, color="k", lw=0.6, ls=":")
    ax2.set_xticks([0, 1], ["ours", "paper"], fontsize=7)
    ax2.set_ylabel("time ratio, all rays", fontsize=7)
    ax1.set_xticks(x, kinds, fontsize=7)
    ax0.set_title(f"Around Again stand-in (N = {int(around.N.iloc[0]):,})", fontsize=8)
    for ax in axes:
        ax.tick_params(labelsize=7)

