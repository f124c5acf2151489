"""Sweep points: build a structure at given parameters once, trace every ray set on it, one row per
(point, ray kind). Rows are stored as soon as measured (:class:`experiments.results.PointStore`)."""
from __future__ import annotations

import socket

import numpy as np
from tqdm import tqdm

from experiments.results import PointStore
from tracer.accel import build
from tracer.timing import clock_name, time_call

QUICK_FACTORS = [2.0**k for k in range(-3, 7)]              # N/8 ... 64N, 10 points
FULL_FACTORS = [2.0 ** (k / 2) for k in range(-6, 13)]      # N/8 ... 64N, 19 points


def measure(scene, structure: str, params: dict, rays_by_kind: dict, repeats: int = 5) -> list[dict]:
    """Build once; for each ray kind time ``repeats`` traces (after a warm-up) and count work."""
    import numba
    accel = build(scene, structure, **params)
    st = accel.stats()
    rows = []
    for kind, r in rays_by_kind.items():
        tm = time_call(lambda: accel.intersect(r.origins, r.directions, counters=False), repeats=repeats)
        _, cnt = accel.intersect(r.origins, r.directions, counters=True)
        mean = cnt.mean()
        rows.append({
            "scene": scene.name, "N": scene.n, "structure": structure,
            **{f"param_{k}": v for k, v in params.items()},
            "cells": st.get("cells"), "M1": st.get("M1"), "res": "x".join(str(v) for v in st.get("res", [])) or None,
            "refs": st.get("refs"), "memory_bytes": st.get("memory_bytes"), "build_s": st.get("build_s"),
            "ray_kind": kind, "rays": r.n, "seed": r.seed, "seconds": tm.median, "seconds_min": tm.min,
            "spread": tm.spread, "clock": clock_name(), "ns_per_ray": tm.median / r.n * 1e9,
            **{k: mean[k] for k in ("setups", "steps", "tests", "nodes", "skips")},
            "hits": float((accel.intersect(r.origins[:2000], r.directions[:2000], counters=False)[0].tri_id >= 0).mean()),
            "threads": numba.get_num_threads(), "worker": socket.gethostname(),
        })
    return rows


def sweep(scene, structure: str, param_list: list[dict], rays_by_kind: dict, store: PointStore,
          repeats: int = 5, desc: str | None = None, extra_key: dict | None = None) -> list[dict]:
    """Measure every parameter set not stored yet through the current executor (local or Dask),
    storing each point as soon as it is measured; returns the rows of all points in order."""
    from experiments.executor import get_executor, remember_scene
    remember_scene(scene)
    specs, keys = [], []
    for params in param_list:
        spec = {"scene": scene.name, "N": scene.n, "structure": structure, "params": params,
                "rays": {k: [r.n, r.seed] for k, r in rays_by_kind.items()}, "repeats": repeats,
                **(extra_key or {})}
        keys.append(spec)
        if store.get(spec) is None:
            specs.append(spec)
    if specs:
        bar = tqdm(total=len(specs), desc=desc or f"{scene.name} {structure}", unit="pt", leave=False,
                   disable=None, dynamic_ncols=True)
        for spec, rows in get_executor().map(specs):
            store.put(spec, {"rows": rows})
            bar.update(1)
        bar.close()
    out = []
    for spec in keys:
        out.extend(store.get(spec, ignore_force=True)["rows"])
    return out


def grid_cells(scene, factors) -> list[dict]:
    return [{"cells": float(f * scene.n)} for f in factors]


def best_row(rows: list[dict]) -> dict:
    return min(rows, key=lambda r: r["seconds"])


def as_arrays(rows, *cols):
    return tuple(np.array([r[c] for r in rows], float) for c in cols)


def nearest(rows_df, cells: float):
    """The row of a (one scene, one ray kind) frame measured at the cell count nearest ``cells``."""
    return rows_df.iloc[int(np.argmin(np.abs(np.log(rows_df.param_cells.values / cells))))]


def penalty_pct(t, best) -> float:
    """Extra time of ``t`` over ``best``, in percent."""
    return 100.0 * (t / best - 1.0)
