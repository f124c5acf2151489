"""``bench``: build time and Mrays/s of every structure and build/trace variant on random and camera
rays, beside Embree (embreex) and trimesh's ray_triangle, as ratios, in one run.

Warm-up call first, median of ``--repeats`` (>= 5) runs; Numba threads pinned with ``--threads``.
Embree through embreex traces on one thread (its ``run`` loops ``rtcIntersect1``). At one thread
the Embree ratios compare one thread with one thread; with ``--threads T`` > 1 they are reported per
thread (our Mrays/s / T against Embree's one-thread Mrays/s) and labelled so. trimesh is timed on a
small sample of rays. Builds are timed with wall time. A structure that fails to build or trace
fails the run (no "skipped"); Embree and trimesh are optional references and are reported as
unavailable when their packages are missing.
"""
from __future__ import annotations

import sys
import time


from experiments.core.common import add_scene_args, emit_json, scene_from_args
from experiments.core.store import atomic_write, write_json
from experiments.core.common import progress
from experiments.tools.lib.variants import VARIANTS
from tracer.accel import build, plugin_structures
from tracer.measure.memory import memory_budget
from tracer.scenes.rays import make_rays
from tracer.measure.timing import build_clock, host_info, set_threads, time_call

#: the folder gathers one JSON per scene and thread count a run: the runner keeps the earlier runs'
#: files (experiments.run drops a whole-folder target's stale ones)
KEEPS_EARLIER_FILES = True


def default_names() -> list[str]:
    """What bench runs by default: every variant, every registered structure, Embree and trimesh."""
    return [*VARIANTS, *plugin_structures(), "embree", "trimesh"]


#: the structures whose Embree ratio is also measured in interleaved rounds (the headline ratios)
PAIRED = ("grid", "grid-fit", "kdtree-fast", "bvh4", "bvh4-sah-fit", "wbvh", "wbvh-leaf4", "wbvh-quant", "cgt")


#: bytes trimesh's tracer holds per (ray, face) pair: its rtree returns a ray's candidate faces,
#: about all of them for a ray across the mesh (2,000 rays on dragon-871k reached 24 GB and were
#: killed); the rays given to it are cut to the memory budget (:func:`trimesh_ray_count`)
TRIMESH_BYTES_PER_PAIR = 16
TRIMESH_MIN_RAYS = 100


def trimesh_ray_count(wanted: int, n_faces: int) -> int:
    """Rays for trimesh's tracer: ``wanted``, fewer when TRIMESH_BYTES_PER_PAIR x rays x faces would
    exceed the memory budget (:func:`tracer.measure.memory.memory_budget`)."""
    return int(min(wanted, memory_budget() // (TRIMESH_BYTES_PER_PAIR * max(n_faces, 1))))


def add_arguments(p) -> None:
    add_scene_args(p, default_scene="bunny-69k")
    p.add_argument("--rays", type=int, default=200_000, help="rays per kind (default 200000)")
    p.add_argument("--repeats", type=int, default=5, help="timed repeats after warm-up (default 5)")
    p.add_argument("--structures", default=None,
                   help="comma-separated variants to run (default: every variant below, the structures other "
                        "packages register by entry point, embree, trimesh)")
    p.add_argument("--trimesh-rays", type=int, default=2000, help="rays for trimesh's tracer")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sah-scenes", default=None,
                   help="meshes bvh4-sah-fit calibrates the BVH's SAH weight on, and grid-fit the grid's "
                        "density (default: costmodel.kdcost.BVH_CALIBRATION, none of them a bench mesh)")


def _bench_one(accel_fn, rays_by_kind, repeats, counters=True) -> tuple[dict, object]:
    """(row of build time, Mrays/s and counters per ray kind, the built structure)."""
    t_build = time_call(accel_fn, repeats=3 if repeats > 1 else 1, warmup=0, clock=build_clock)
    accel = accel_fn()
    row = {"build_s": t_build.median}
    for kind, r in rays_by_kind.items():
        tm = time_call(lambda: accel.intersect(r.origins, r.directions, counters=False), repeats=repeats)
        row[f"{kind}_mrays"] = r.n / tm.median / 1e6
        row[f"{kind}_spread"] = tm.spread
        if counters:
            _, cnt = accel.intersect(r.origins, r.directions, counters=True)
            row[f"{kind}_per_ray"] = {k: round(v, 3) for k, v in cnt.mean().items()}
    st = accel.stats()
    row["stats"] = {k: v for k, v in st.items() if isinstance(v, (int, float, bool, str))}
    return row, accel


#: the settings bench measures in its own run when a variant asks for "fitted": setting -> (where
#: the fit's summary goes in the output, the probe in experiments.core.probes that measures and fits
#: it on the calibration meshes, what the log says of the fit)
FITTED = {
    "trav_cost": ("bvh_sah_fit", "measure_bvh_trav_cost",
                  lambda f: f"BVH SAH weight C_trav/C_isect {f.trav_cost_:.3f} (pbrt-v2: 0.125)"),
    "factor": ("grid_density_fit", "measure_grid_density",
               lambda f: f"grid density T_i/T_s {f.ti_over_ts_:.3f}, {f.factor_:.2f}N cells (Ize Eq 4)"),
}


def _fitted_params(params: dict, out: dict, sah_scenes, log) -> dict:
    """``params`` with a "fitted" setting (:data:`FITTED`) replaced by what this run measures on
    ``sah_scenes`` (or the probe's default calibration meshes), once per run: its summary and
    seconds go to ``out``."""
    for key, (slot, probe, say) in FITTED.items():
        if params.get(key) != "fitted":
            continue
        if slot not in out:
            from experiments.core import probes
            t0 = time.perf_counter()
            fit = getattr(probes, probe)(*([tuple(sah_scenes)] if sah_scenes else []))
            out[slot] = {**fit.summary(), "seconds": time.perf_counter() - t0}
            note = fit.note()
            log(f"  {say(fit)}, fitted on {', '.join(out[slot]['scenes'])} ({out[slot]['seconds']:.0f} s)"
                + (f"; {note}" if note else ""))
        params = {**params, key: out[slot][key]}
    return params


def run_bench(scene, names, n_rays, repeats, threads, trimesh_rays=2000, seed=0, log=print,
              sah_scenes=None) -> dict:
    from tracer.accel.reference import EmbreeAccel, TrimeshAccel
    threads = set_threads(threads)
    rays = {"random": make_rays(scene, "random", n_rays, seed=seed),
            "camera": make_rays(scene, "camera", n_rays, seed=seed)}
    from experiments.core.store import git_commit
    out = {"scene": scene.name, "faces": scene.n, "threads": threads, "rays": n_rays, "repeats": repeats,
           "git_commit": git_commit(), "host": host_info(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
           "structures": {}, "unavailable": {}}
    kept = {}  # the structures the paired rounds time again (PAIRED and Embree), as built above
    for name in progress(names, f"bench {scene.name}", quiet=log is not print, unit="structure"):
        t0 = time.perf_counter()
        if name == "embree":
            if not EmbreeAccel.available():
                out["unavailable"][name] = "embreex not installed (pip install 'gridcost[embree]')"
                continue
            row, kept[name] = _bench_one(lambda: EmbreeAccel().build(scene), rays, repeats, counters=False)
            row["robust"] = False
            row["threads"] = 1
        elif name == "trimesh":
            if not TrimeshAccel.available():
                out["unavailable"][name] = "trimesh's ray tracer needs rtree (pip install rtree)"
                continue
            k_rays = trimesh_ray_count(trimesh_rays, scene.n)
            if k_rays < TRIMESH_MIN_RAYS:
                out["unavailable"][name] = (f"trimesh's tracer would need about {TRIMESH_BYTES_PER_PAIR * TRIMESH_MIN_RAYS * scene.n / 2**30:.1f} GiB "
                                            f"for {TRIMESH_MIN_RAYS} rays on {scene.n:,} faces (budget {memory_budget() / 2**30:.1f} GiB)")
                continue
            step = {k: max(1, r.n // k_rays) for k, r in rays.items()}  # spread over the image
            small = {k: r._replace(origins=r.origins[::step[k]][:k_rays], directions=r.directions[::step[k]][:k_rays])
                     for k, r in rays.items()}
            row, _ = _bench_one(lambda: TrimeshAccel().build(scene), small, 1, counters=False)
            row["rays"] = k_rays
        elif name in VARIANTS or name in plugin_structures():
            struct, params = VARIANTS.get(name, (name, {}))
            params = _fitted_params(params, out, sah_scenes, log)
            row, accel = _bench_one(lambda: build(scene, struct, **params), rays, repeats)
            if name in PAIRED:
                kept[name] = accel
            row["params"] = params
        else:
            from tracer.errors import GridcostError
            raise GridcostError(f"bench: unknown structure {name!r}; known: {', '.join(default_names())}")
        out["structures"][name] = row
        log(f"  {name:13s} build {row['build_s'] * 1e3:9.1f} ms   random {row.get('random_mrays', 0):7.3f} "
            f"Mrays/s   camera {row.get('camera_mrays', 0):7.3f} Mrays/s   ({time.perf_counter() - t0:.0f} s)")
    s = out["structures"]
    ratios = {}
    if "embree" in s:
        e = s["embree"]
        # Embree traces on one thread: at T > 1 threads compare per thread (ours / T), and say so
        label = "/embree" if threads == 1 else f"/embree per thread (ours / {threads} threads vs embree 1 thread)"
        out["embree_ratio_basis"] = "1 thread vs 1 thread" if threads == 1 else f"per thread: ours / {threads}"
        for name, row in s.items():
            if name not in ("embree", "trimesh"):
                ratios[f"{name}{label}"] = {k: row[f"{k}_mrays"] / threads / e[f"{k}_mrays"] for k in rays}
                ratios[f"{name}{label}"]["build"] = row["build_s"] / e["build_s"]
    if "trimesh" in s and "grid" in s:
        ratios["grid/trimesh"] = {k: s["grid"][f"{k}_mrays"] / s["trimesh"][f"{k}_mrays"] for k in rays}
    out["ratios"] = ratios
    out["paired"] = _paired(rays, kept, threads, log)
    for key, v in out["paired"].items():  # the work behind each paired time: nodes and tests per ray
        row = s.get(key.split("/")[0], {})
        for kind, p in v.items():
            if isinstance(p, dict) and f"{kind}_per_ray" in row:
                p["nodes_per_ray"] = row[f"{kind}_per_ray"]["nodes"]
                p["tests_per_ray"] = row[f"{kind}_per_ray"]["tests"]
    if threads == 1:
        out["work_costs"] = _where_time_goes(rays, {k: v for k, v in kept.items() if _structure(k) not in NO_PER_RAY_WORK},
                                             log)
    out["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    return out


#: ray groups of different counted work that a structure's time per ray is fitted over
WORK_GROUPS = 8
#: left out of the split of time per ray: Embree (no counters) and the packet grid, whose camera rays'
#: cells are walked per packet, not per ray (its fit there is off by 30-40 %)
NO_PER_RAY_WORK = ("embree", "cgt")
#: structures whose traversal step is a cell (``steps``), not a node (``nodes``)
GRID_LIKE = ("grid", "nested", "cgt", "sortedlists")


def _structure(name: str) -> str:
    """The structure a bench name builds (a variant's, or the name itself)."""
    return VARIANTS.get(name, (name, {}))[0]


def _where_time_goes(rays, accels, log, rounds: int = 5) -> dict:
    """Per structure and ray kind: its time per ray split into a cost per ray, per traversal step
    (node for a tree, cell for a grid) and per triangle test (:class:`costmodel.kdcost.WorkCostFit`),
    fitted over :data:`WORK_GROUPS` groups of the rays sorted by their counted work (steps + tests), the
    groups timed in interleaved rounds; and the structure's working set (its arrays, ``memory_bytes``)
    beside this host's L2 and L3 (:func:`tracer.measure.memory.cache_bytes`): a gap to Embree paid per step
    or per test with the working set in L2 is arithmetic, with it beyond L3 it is memory."""
    import numpy as np

    from costmodel.kdcost import WorkCostFit
    from tracer.measure.memory import cache_bytes
    from tracer.measure.timing import time_paired
    out = {}
    for name, a in accels.items():
        ws = int(a.stats().get("memory_bytes") or 0)
        rec = {"working_set_bytes": ws, "l2_bytes": cache_bytes(2), "l3_bytes": cache_bytes(3)}
        for kind, r in rays.items():
            _, cnt = a.intersect(r.origins, r.directions, counters=True)
            unit = "steps" if _structure(name) in GRID_LIKE else "nodes"
            steps, tests = np.asarray(cnt[unit], float), np.asarray(cnt["tests"], float)
            groups = np.array_split(np.argsort(steps + tests, kind="stable"), WORK_GROUPS)
            sub = [(np.ascontiguousarray(r.origins[g]), np.ascontiguousarray(r.directions[g])) for g in groups]
            tp = time_paired({i: (lambda o=o, d=d: a.intersect(o, d, counters=False)) for i, (o, d) in enumerate(sub)},
                             rounds=rounds, repeats=1)
            y = [float(np.median(tp[i])) / len(g) * 1e9 for i, g in enumerate(groups)]
            X = [(steps[g].mean(), tests[g].mean()) for g in groups]
            fit = WorkCostFit().fit(X, y)
            rec[kind] = {"unit": unit, **fit.summary(), "groups": WORK_GROUPS, "rounds": rounds}
            log(f"  {name:13s} {kind:7s} {fit.c_ray_:6.1f} ns/ray + {fit.c_step_:5.2f} ns/{unit[:-1]} + "
                f"{fit.c_test_:5.2f} ns/test (MAPE {fit.mape_:.1f} %)")
        out[name] = rec
    return out


def _paired(rays, kept, threads, log, rounds: int = 7) -> dict:
    """The headline ratios measured in interleaved rounds (:func:`tracer.measure.timing.time_paired`): each of
    :data:`PAIRED` that ran against Embree (all one thread, in the same rounds), and the grid's scaling
    from 1 to ``threads`` threads (wall time for both). Median, min and max of the per-round ratios."""
    import numba
    import numpy as np

    from tracer.measure.timing import paired_ratio, time_paired
    out = {}
    if "grid" not in kept:
        return out
    accels = {name: kept[name] for name in PAIRED if name in kept}
    grid = accels["grid"]
    if "embree" in kept and threads == 1:
        emb = kept["embree"]
        for kind, r in rays.items():
            fns = {name: (lambda a=a: a.intersect(r.origins, r.directions, counters=False)) for name, a in accels.items()}
            fns["embree"] = lambda: emb.intersect(r.origins, r.directions, counters=False)
            tp = time_paired(fns, rounds)
            for name in accels:
                med, lo, hi = paired_ratio(tp, "embree", name)  # throughput ratio = time ratio inverted
                ns, ens = (1e9 * float(np.median(tp[k])) / r.n for k in (name, "embree"))
                out.setdefault(f"{name}/embree", {})[kind] = {"ratio": med, "min": lo, "max": hi, "rounds": rounds,
                                                              "ns_per_ray": ns, "embree_ns_per_ray": ens}
                log(f"  paired {name}/embree {kind:7s} {med:6.3f}x  (rounds {lo:.3f}-{hi:.3f}; "
                    f"{ns:.0f} ns/ray vs Embree {ens:.0f})")
    if threads > 1:
        out["grid_scaling"] = {}
        def on(n, r):
            numba.set_num_threads(n)
            grid.intersect(r.origins, r.directions, counters=False)
        for kind, r in rays.items():
            tp = time_paired({"1": lambda: on(1, r), "n": lambda: on(threads, r)}, rounds, clock=time.perf_counter)
            med, lo, hi = paired_ratio(tp, "1", "n")
            out["grid_scaling"][kind] = {"threads": threads, "speedup": med, "min": lo, "max": hi, "rounds": rounds}
            log(f"  paired grid scaling 1 -> {threads} threads {kind:7s} {med:5.2f}x  (rounds {lo:.2f}-{hi:.2f})")
        numba.set_num_threads(threads)
    return out


def main(ctx, args) -> int:
    scene = scene_from_args(args)
    names = ([n.strip() for n in args.structures.split(",") if n.strip()] if args.structures
             else default_names())
    log = (lambda *a, **k: None) if args.json else print
    log(f"bench {scene.name}: {scene.n:,} faces, {args.rays:,} rays per kind, threads={args.threads or 'all'}")
    sah = [n.strip() for n in args.sah_scenes.split(",") if n.strip()] if args.sah_scenes else None
    out = run_bench(scene, names, args.rays, max(1, args.repeats), args.threads, args.trimesh_rays, args.seed, log, sah)
    write_json(f"{args.out}/bench/{scene.name}-t{out['threads']}.json", out)
    atomic_write(f"{args.out}/bench/summary.md", _summary_all(f"{args.out}/bench"))
    if args.json:
        emit_json(out)
    else:
        for k, v in out["ratios"].items():
            print(f"  {k:22s} " + "  ".join(f"{kk} {vv:7.3f}x" for kk, vv in v.items()))
        for k, v in out["unavailable"].items():
            print(f"  unavailable {k}: {v}", file=sys.stderr)
    return 0


def _summary_all(folder) -> str:
    """summary.md of every bench file in ``folder`` (one section per scene and thread count), each
    naming the commit, host and time that measured it."""
    import json
    from pathlib import Path
    parts = ["# bench: every scene benched into this folder", "",
             "Each section is one `gridcost bench` run; its commit, host and finish time are under its title."]
    for f in sorted(Path(folder).glob("*-t*.json")):
        out = json.loads(f.read_text())
        sec = _summary(out).replace("# bench:", "## bench:", 1).split("\n")
        host = out.get("host") or {}
        sec.insert(1, f"\nMeasured by commit {out.get('git_commit', 'unknown (before bench recorded it)')} on "
                      f"{host.get('host', '?')} ({host.get('cpu', '?')}), "
                      + (f"{out['started']} – {out['finished']}." if "started" in out
                         else f"started {out.get('finished', '?')} (files before the fix record the start as 'finished')."))
        parts += [""] + sec
    return "\n".join(parts).rstrip("\n") + "\n"


def _summary(out: dict) -> str:
    """summary.md: Mrays/s and build time of every structure, and the ratios to Embree (labelled
    per thread when more than one thread ran) and the paired headline ratios."""
    lines = [f"# bench: {out['scene']} ({out['faces']:,} faces), {out['rays']:,} rays per kind, "
             f"{out['threads']} thread(s), median of {out['repeats']} after a warm-up", "",
             "| structure | build (ms) | random Mrays/s | camera Mrays/s |", "|---|---|---|---|"]
    for name, r in out["structures"].items():
        lines.append(f"| {name} | {r['build_s'] * 1e3:.1f} | {r.get('random_mrays', float('nan')):.3f} | "
                     f"{r.get('camera_mrays', float('nan')):.3f} |")
    if out["ratios"]:
        lines += ["", f"Ratios of throughput (build: of build time); Embree basis: {out.get('embree_ratio_basis', '–')}.", "",
                  "| ratio | random | camera | build |", "|---|---|---|---|"]
        for k, v in out["ratios"].items():
            lines.append(f"| {k} | {v.get('random', float('nan')):.3f} | {v.get('camera', float('nan')):.3f} | "
                         f"{v.get('build', float('nan')):.3f} |")
    paired = {k: v for k, v in (out.get("paired") or {}).items() if k.endswith("/embree")}
    if paired:
        n_rounds = next(iter(next(iter(paired.values())).values()))["rounds"]
        lines += ["", f"Paired with Embree (interleaved rounds, one thread each, {n_rounds} rounds; median "
                      "[min – max] of the per-round throughput ratios):", "",
                  "| ratio | random | camera |", "|---|---|---|"]
        for k, v in paired.items():
            lines.append(f"| {k} | " + " | ".join(
                f"{v[kind]['ratio']:.3f} [{v[kind]['min']:.3f} – {v[kind]['max']:.3f}]" if kind in v else "–"
                for kind in ("random", "camera")) + " |")
        work = [(k, kind, v[kind]) for k, v in paired.items() for kind in ("random", "camera")
                if "ns_per_ray" in v.get(kind, {})]
        if work:
            lines += ["", "Time per ray in those rounds (medians) beside the work behind it:", "",
                      "| structure | rays | ns/ray | Embree ns/ray | nodes/ray | tests/ray |", "|---|---|---|---|---|---|"]
            for k, kind, p in work:
                lines.append(f"| {k.split('/')[0]} | {kind} | {p['ns_per_ray']:.0f} | {p['embree_ns_per_ray']:.0f} | "
                             f"{p.get('nodes_per_ray', float('nan')):.2f} | {p.get('tests_per_ray', float('nan')):.2f} |")
    costs = out.get("work_costs")
    if costs:
        l2, l3 = (next(iter(costs.values()))[k] for k in ("l2_bytes", "l3_bytes"))
        lines += ["", f"Where the time goes: each structure's time per ray fitted as c_ray + c_step x steps + c_test x tests "
                      f"(non-negative least squares) over {WORK_GROUPS} groups of the rays sorted by counted work, timed in "
                      f"interleaved rounds (steps: nodes for a tree, cells for a grid); working set = the structure's "
                      f"arrays against this host's L2 ({l2 / 2**20:.1f} MiB) and L3 ({l3 / 2**20:.0f} MiB). Where steps and tests "
                      "rise together across the groups (the BVH4 tests under one triangle per ray) the split between the two is "
                      "loose; ns/ray (a ray's set-up, paid alone by rays that miss the box) and the MAPE stay meaningful. The "
                      "packet grid is left out: its camera rays walk cells per packet, not per ray.", "",
                  "| structure | rays | ns/ray | ns/step | ns/test | MAPE % | working set (MiB) | fits in |",
                  "|---|---|---|---|---|---|---|---|"]
        for name, rec in ((k, v) for k, v in costs.items() if _structure(k) not in NO_PER_RAY_WORK):
            ws = rec["working_set_bytes"]
            where = "L2" if ws <= l2 else ("L3" if ws <= l3 else "memory")
            for kind in ("random", "camera"):
                if kind in rec:
                    c = rec[kind]
                    lines.append(f"| {name} | {kind} | {c['c_ray_ns']:.1f} | {c['c_step_ns']:.2f} ({c['unit']}) | "
                                 f"{c['c_test_ns']:.2f} | {c['mape']:.1f} | {ws / 2**20:.1f} | {where} |")
    fit = out.get("bvh_sah_fit")
    if fit:
        lines += ["", f"bvh4-sah-fit: the BVH4 built with the SAH traversal weight C_trav/C_isect = {fit['trav_cost']:.3f} "
                      f"(pbrt-v2: 0.125), fitted in this run on {', '.join(fit['scenes'])}: the binary BVH's time per ray "
                      "against its node visits and triangle tests, per ray kind (c_node / c_test: "
                      + ", ".join(f"{k} {fit[f'{k}_ratio']:.2f} (MAPE {fit[f'{k}_mape']:.1f} %)"
                                  for k in ("random", "camera") if f"{k}_ratio" in fit)
                      + f"), geometric mean; {fit['seconds']:.0f} s."]
    gfit = out.get("grid_density_fit")
    if gfit:
        from costmodel.derive import one_level_optimal_M
        how = ("; ".join(f"{k} {gfit[f'{k}_ratio']:.2f} (MAPE {gfit[f'{k}_mape']:.1f} %)"
                         for k in ("random", "camera") if f"{k}_ratio" in gfit) or "no kind separated the two")
        lines += ["", f"grid-fit: the grid with M = 2N T_i/T_s cells (Ize 2007 Eq 4), {gfit['factor']:.2f}N: T_i/T_s fitted "
                      f"in this run on {', '.join(gfit['scenes'])} (the grid at several densities, time per ray against "
                      f"its cell steps and triangle tests per ray kind, c_test / c_step: {how}, geometric mean "
                      f"{gfit['ti_over_ts']:.3f}; the paper's T_i/T_s is {gfit['paper_ti_over_ts']:g}, which gives "
                      f"{float(one_level_optimal_M(1.0, 1.0, gfit['paper_ti_over_ts'])):g}N); {gfit['seconds']:.0f} s"
                      + (" (fallback: the timings did not separate a step from a test)" if gfit["fallback"] else "")
                      + (" (clipped to the swept range)" if gfit["clipped"] else "") + "."]
    for k, v in out["unavailable"].items():
        lines.append(f"\nUnavailable: {k}: {v}")
    return "\n".join(lines) + "\n"
