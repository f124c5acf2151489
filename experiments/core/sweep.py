"""Sweep points: build a structure at given parameters once, trace every ray set on it, one row per
(point, ray kind). Rows are stored as soon as measured (:class:`experiments.core.store.PointStore`)."""
from __future__ import annotations

import numpy as np
from tqdm import tqdm

from experiments.core.executor import LocalExecutor
from experiments.core.point import QUICK_MIN_SAMPLE, REFERENCE
from experiments.core.store import PointStore
from tracer.accel import build

QUICK_FACTORS = [2.0**k for k in range(-3, 7)]              # N/8 ... 64N, 10 points
FULL_FACTORS = [2.0 ** (k / 2) for k in range(-6, 13)]      # N/8 ... 64N, 19 points


def _anchor(store: PointStore, scene, rays_by_kind: dict, rows: list[dict]) -> dict:
    """Per (worker, ray kind): the reference's seconds that ratios are turned back into seconds with.
    Fixed the first time a scene's points are measured (the median reference time of that sweep) and
    stored, so later sweeps of the same scene (refinement points, other targets) share it."""
    out = {}
    for worker in sorted({r["worker"] for r in rows}):
        spec = {"reference": list(REFERENCE), "scene": scene.name, "N": scene.n, "worker": worker,
                "rays": {k: [r.n, r.seed] for k, r in rays_by_kind.items()}}
        with store.claim(spec):  # the first target to sweep the scene fixes it, also under `all --jobs`
            got = store.get(spec)
            if got is None:
                got = store.put(spec, {k: float(np.median([r["ref_seconds"] for r in rows
                                                            if r["worker"] == worker and r["ray_kind"] == k]))
                                       for k in rays_by_kind})
        out[worker] = got
    return out


def sweep(scene, structure: str, param_list: list[dict], rays_by_kind: dict, store: PointStore,
          repeats: int = 5, desc: str | None = None, extra_key: dict | None = None) -> list[dict]:
    """Measure every parameter set not stored yet through the run's executor (local or Dask:
    ``store.ctx.executor``), storing each point as soon as it is measured; returns the rows of all
    points in order."""
    ctx = store.ctx
    quick = bool(ctx and ctx.quick)
    specs, keys = [], []
    for params in param_list:
        spec = {"scene": scene.name, "N": scene.n, "structure": structure, "params": params,
                "rays": {k: [r.n, r.seed] for k, r in rays_by_kind.items()}, "repeats": repeats,
                "timing": "beside-reference", **({"min_sample": QUICK_MIN_SAMPLE} if quick else {}),
                **(extra_key or {})}
        keys.append(spec)
        if store.get(spec) is None:
            specs.append(dict(spec, code=list(store.code), threads=store.measurement_key["threads"]))
    if specs:
        bar = tqdm(total=len(specs), desc=desc or f"{scene.name} {structure}", unit="pt", leave=False,
                   disable=None, dynamic_ncols=True)
        executor = ctx.executor if ctx is not None else LocalExecutor()
        mine = store.measurement_key  # this run's, read before any task runs (an in-process worker sets its own)
        if isinstance(executor, LocalExecutor):  # one point at a time, held while measured (`all --jobs`)
            for spec in specs:
                key = _stored_spec(spec)
                with store.claim(key):
                    if store.get(key) is None:
                        for got in executor.map([spec], scenes={scene.name: scene}):
                            _put_rows(store, mine, *got)
                bar.update(1)
        else:  # Dask: every point at once, stored as it completes
            for got in executor.map(specs, scenes={scene.name: scene}):
                _put_rows(store, mine, *got)
                bar.update(1)
        bar.close()
    out = []
    for spec in keys:
        prov = store.provenance(spec)
        out.extend(dict(r, **prov) for r in store.get(spec, ignore_force=True)["rows"])
    anchor = _anchor(store, scene, rays_by_kind, out)
    for r in out:  # drift-free time: ratio to the reference x the reference's anchored time
        r["anchored_seconds"] = r["ratio_to_ref"] * anchor[r["worker"]][r["ray_kind"]]
        r["anchored_ns_per_ray"] = r["anchored_seconds"] / r["rays"] * 1e9
    return out


def _stored_spec(spec: dict) -> dict:
    """A point's spec as stored (without what the task carries to the worker)."""
    return {k: v for k, v in spec.items() if k not in ("code", "threads")}


def _put_rows(store: PointStore, mine: dict, spec: dict, rows: list[dict]) -> None:
    """Store a measured point's rows, refusing rows measured under another measurement key than
    ``mine`` (the run's)."""
    theirs = rows[0].pop("key") if rows else mine
    for r in rows[1:]:
        r.pop("key", None)
    if theirs != mine:
        from tracer.errors import GridcostError
        raise GridcostError(f"worker {rows[0]['worker']} measured with another measurement key "
                            f"({theirs}) than this run ({mine}): same code, threads, clock and CPU needed")
    store.put(_stored_spec(spec), {"rows": rows},
              provenance={"host": rows[0]["worker"], "clock": rows[0]["clock"]} if rows else None)


def grid_cells(scene, factors) -> list[dict]:
    return [{"cells": float(f * scene.n)} for f in factors]


def as_arrays(rows, *cols):
    return tuple(np.array([r[c] for r in rows], float) for c in cols)


def nearest(rows_df, cells: float):
    """The row of a (one scene, one ray kind) frame measured at the cell count nearest ``cells``."""
    return rows_df.iloc[int(np.argmin(np.abs(np.log(rows_df.param_cells.values / cells))))]


def penalty_range(pp: dict) -> str:
    """A paired penalty's 95 % interval (:func:`penalty_ci`; the rounds' min..max for points stored
    before it was kept) and the rounds it took, as text; for the fastest point, "fastest" and its
    interval against the next fastest (negative: how much faster) instead of a point divided by itself."""
    lo, hi = pp.get("ci_pct") or (pp["min_pct"], pp["max_pct"])
    n = f", {pp['rounds']} rounds" if "ci_pct" in pp else ""
    if pp.get("fastest"):
        return f"fastest ({lo:.1f}..{hi:.1f} vs next{n})"
    return f"{lo:.1f}..{hi:.1f}{n}"


def penalty_pct(t, best) -> float:
    """Extra time of ``t`` over ``best``, in percent."""
    return 100.0 * (t / best - 1.0)


#: paired re-timing: rounds x repeats per round (a round times every point once, as a median of
#: ``repeats`` samples); quick runs use fewer
PAIRED_ROUNDS, PAIRED_REPEATS = 11, 5
QUICK_PAIRED_ROUNDS, QUICK_PAIRED_REPEATS = 3, 3
#: noise-aware paired penalties (full runs): after PAIRED_ROUNDS, rounds are added one at a time until
#: the 95 % interval of every target's median per-round ratio to the best is at most
#: PAIRED_HALF_WIDTH_PCT wide each side (or PAIRED_MAX_ROUNDS are timed); on a noisy host 11 rounds
#: cannot tell a 5 % penalty from none
PAIRED_MAX_ROUNDS, PAIRED_HALF_WIDTH_PCT = 41, 2.0
#: rounds before an interval's width is trusted enough to give up on it (:func:`_unsettled`): with
#: fewer, the binomial interval of a median spans most of the rounds' range and overstates the noise
FUTILE_AFTER = 21


def paired_rule() -> str:
    """The stop rule of full-run paired penalties in words, for the summaries that show them."""
    return (f"after {PAIRED_ROUNDS} rounds, rounds are added until every interval is within "
            f"±{PAIRED_HALF_WIDTH_PCT:g} points or {PAIRED_MAX_ROUNDS} are timed; a settled target is no longer "
            f"timed, and one that {PAIRED_MAX_ROUNDS} rounds would still leave wider (judged from "
            f"{FUTILE_AFTER} rounds on) is given up with its wider interval")


def _paired_budget(quick: bool) -> tuple[int, int, dict]:
    """(rounds, repeats per round, the key's extra timing settings) of side-by-side timing; --quick
    also takes shorter samples (QUICK_MIN_SAMPLE) and never adds rounds."""
    if quick:
        return QUICK_PAIRED_ROUNDS, QUICK_PAIRED_REPEATS, {"min_sample": QUICK_MIN_SAMPLE}
    return PAIRED_ROUNDS, PAIRED_REPEATS, {"max_rounds": PAIRED_MAX_ROUNDS, "half_width_pct": PAIRED_HALF_WIDTH_PCT}


def penalty_ci(times: dict, target, best) -> tuple[float, float]:
    """95 % interval (%, :func:`tracer.measure.timing.median_ci`) of the median per-round ratio of ``target``
    to ``best`` (lists of per-round seconds in ``times``), as a penalty."""
    from tracer.measure.timing import common_ratio, median_ci
    lo, hi = median_ci(common_ratio(times, target, best))
    return penalty_pct(lo, 1.0), penalty_pct(hi, 1.0)


def _unsettled(targets, half_width_pct: float, max_rounds: int | None = None):
    """``more`` of :func:`tracer.measure.timing.time_paired`: while the interval of some target's
    penalty against the current best (fastest by median among the points still timed; against the
    next fastest for the best itself) is wider than ``half_width_pct`` on either side, the names to
    time in one more round: the unsettled targets, the two fastest and every non-point (``others``).
    A settled target or a candidate that is none of these drops out, as its rounds no longer narrow
    any unsettled interval; its penalty stays the one of the rounds it was timed in (empty: all
    settled).

    Futility: from FUTILE_AFTER rounds on, a target whose interval would still be too wide after
    ``max_rounds`` rounds, were it to shrink as 1/sqrt(rounds), is given up rather than timed to the
    cap; its wider interval is what is reported."""
    def more(times: dict) -> set:
        n = max(len(v) for v in times.values())
        med = {i: float(np.median(v)) for i, v in times.items() if isinstance(i, int) and len(v) == n}
        order = sorted(med, key=med.get)
        wide = set()
        for i in (t for t in targets if t in med):  # a target that dropped out was settled
            lo, hi = penalty_ci(times, i, order[1] if i == order[0] and len(order) > 1 else order[0])
            hw = (hi - lo) / 2.0
            hopeless = max_rounds is not None and n >= FUTILE_AFTER and hw * np.sqrt(n / max_rounds) > half_width_pct
            if hw > half_width_pct and not hopeless:
                wide.add(i)
        return wide | set(order[:2]) | {k for k in times if not isinstance(k, int)} if wide else set()
    return more


def paired_penalties(scene, structure: str, targets: dict, candidates: list[dict], rays, store: PointStore,
                     quick: bool = False, others: dict | None = None) -> dict:
    """Penalty of each of ``targets`` (name -> parameters, e.g. the theory's M) against the best of
    them and ``candidates`` (e.g. the three fastest swept points), re-measured side by side in
    interleaved rounds (:func:`tracer.measure.timing.time_paired`) on one ray set, so the slow drifts of a
    shared machine cancel, and the points are compared directly rather than through the reference
    each sweep point was timed beside. The best is the fastest point by median time; a target's penalty is
    the median over rounds of its per-round ratio to the best (0 for the best itself). Returns name
    -> {penalty_pct, min_pct, max_pct, target_ns, best_ns, best_params, speedup}; stored in ``store``
    like a sweep point (resumable). ``others`` (name -> (structure, parameters), e.g. the best
    one-level grid) are timed in the same rounds but are not candidates for the best; ``speedup``
    holds each target's median per-round speed-up over each of them."""
    rounds, repeats, timing = _paired_budget(quick)
    points = []
    for p in list(targets.values()) + list(candidates):
        if p not in points:
            points.append(p)
    spec = {"paired": 2, "scene": scene.name, "N": scene.n, "structure": structure, "targets": targets,
            "points": points, "rays": [rays.n, rays.seed, rays.kind], "rounds": rounds, "repeats": repeats,
            **timing, **({"others": others} if others else {})}
    with store.claim(spec):
        done = store.get(spec)
        return done if done is not None else _paired_penalties(scene, structure, targets, points, rays, store, spec,
                                                               rounds, repeats, timing, others)


def _paired_penalties(scene, structure, targets, points, rays, store, spec, rounds, repeats, timing, others):
    """:func:`paired_penalties` measured now and stored."""
    from tracer.measure.timing import paired_ratio
    adapt = ([points.index(p) for p in targets.values()], timing["max_rounds"], timing["half_width_pct"]) \
        if "max_rounds" in timing else None
    tp, prov = _run(store, _time_side_by_side, scene, structure, points, rays, rounds, repeats, others,
                    timing.get("min_sample"), adapt)
    med = {i: float(np.median(v)) for i, v in tp.items() if isinstance(i, int)}
    # the best among the points timed to the end, as :func:`_unsettled` chose it: a point that dropped
    # out has fewer rounds, and a median over fewer rounds is not compared with one over more
    n = max(len(tp[i]) for i in med)
    best = min((i for i in med if len(tp[i]) == n), key=med.get)
    out = {}
    for name, p in targets.items():
        i = points.index(p)
        fastest_ = i == best and len(med) > 1
        # the fastest point against itself says nothing: its range is against the next fastest
        other = min((j for j in med if j != i and len(tp[j]) == n), key=med.get) if fastest_ else best
        ratio, lo, hi = paired_ratio(tp, i, other)
        out[name] = {"penalty_pct": 0.0 if fastest_ else penalty_pct(ratio, 1.0), "min_pct": penalty_pct(lo, 1.0),
                     "max_pct": penalty_pct(hi, 1.0), "fastest": bool(fastest_), "ci_pct": list(penalty_ci(tp, i, other)),
                     "vs_next_pct": penalty_pct(ratio, 1.0) if fastest_ else None, "target_ns": med[i] / rays.n * 1e9,
                     "best_ns": med[best] / rays.n * 1e9, "best_params": points[best], "rounds": len(tp[i]),
                     "speedup": {o: paired_ratio(tp, o, i)[0] for o in (others or {})}}
    store.put(spec, out, provenance=prov)
    return out


def _run(store: PointStore, fn, *args):
    """``fn(*args)`` as one task of the store's run (local, or one Dask worker): (result, provenance)."""
    if store.ctx is None:
        return fn(*args), None
    return store.ctx.run_task(store, fn, *args)


def _time_side_by_side(scene, structure, points, rays, rounds, repeats, others=None, min_sample=None,
                       adapt=None) -> dict:
    """Build every point (index -> structure) and each of ``others`` (name -> (structure, params)),
    then time them all in interleaved rounds: index or name -> per-round seconds (samples of at
    least ``min_sample`` seconds; None: the default). ``adapt`` = (target indices, max rounds,
    half-width %) adds rounds until the targets' penalties are known that well (:func:`_unsettled`)."""
    from tracer.measure.timing import MIN_SAMPLE_SECONDS, time_paired
    accels = {i: build(scene, structure, **p) for i, p in enumerate(points)}
    for name, (st, p) in (others or {}).items():
        accels[name] = build(scene, st, **p)
    more = dict(more=_unsettled(adapt[0], adapt[2], adapt[1]), max_rounds=adapt[1]) if adapt else {}
    return time_paired({i: (lambda a=a: a.intersect(rays.origins, rays.directions, counters=False))
                        for i, a in accels.items()}, rounds=rounds, repeats=repeats,
                       min_sample=MIN_SAMPLE_SECONDS if min_sample is None else min_sample, **more)


def paired_plane(scene, structure: str, points: list[dict], rays, store: PointStore, quick: bool = False) -> np.ndarray:
    """% time over the best of every point of a parameter plane (e.g. Fig 5's (m1, m2) factors),
    all timed side by side in interleaved rounds: per round each point's time over the same round's
    time of the plane's fastest point (by median time), then the median over rounds (:func:`plane_pct`).
    Drift between rounds cancels, and the points are compared directly rather than through the
    reference each sweep point is timed beside. Stored in ``store`` (resumable)."""
    rounds, repeats, timing = _paired_budget(quick)
    timing = {k: v for k, v in timing.items() if k == "min_sample"}  # a plane is timed in fixed rounds
    spec = {"paired_plane": 2, "scene": scene.name, "N": scene.n, "structure": structure, "points": points,
            "rays": [rays.n, rays.seed, rays.kind], "rounds": rounds, "repeats": repeats, **timing}
    with store.claim(spec):
        done = store.get(spec)
        if done is None:
            tp, prov = _run(store, _time_side_by_side, scene, structure, points, rays, rounds, repeats, None,
                            timing.get("min_sample"))
            done = store.put(spec, {"pct_over_best": plane_pct(np.array([tp[i] for i in range(len(points))])).tolist()},
                             provenance=prov)
    return np.asarray(done["pct_over_best"])


def plane_pct(t: np.ndarray) -> np.ndarray:
    """% over the best from per-round times ``t`` (points, rounds): the median over rounds of each
    point's time over the fastest point's (by median) in the same round, over the smallest such
    median. One fixed point as the yardstick, not each round's fastest: the minimum of several
    points' noisy times in a round is biased low, which inflates every % by a common factor (no
    matter within one plane, but it compounds when planes are chained, fig5's chain_ring)."""
    ref = int(np.argmin(np.median(t, axis=1)))
    r = np.median(t / t[ref], axis=1)
    return 100 * (r / r.min() - 1)


def fastest(rows_df, k: int = 3) -> list[float]:
    """Cell counts of the k fastest rows of a (one scene, one ray kind) frame."""
    return [float(c) for c in rows_df.nsmallest(k, "anchored_ns_per_ray").param_cells]


def cells_sweep(n: int, points: int) -> list[dict]:
    """From N/2 to 4 x 8 N^1.5 on a log grid, always including 8N and 8N^1.5."""
    grid = np.geomspace(0.5 * n, 32.0 * n**1.5, points)
    return [{"cells": float(round(m))} for m in sorted(set(np.round(grid).tolist()) | {8.0 * n, round(8.0 * n**1.5)})]
