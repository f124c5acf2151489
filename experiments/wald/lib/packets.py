"""Packet measurements and the packet cost model's fits shared by the Wald targets (fig6, fig7, fig8,
lowres, table1, table3, table4): camera rays in k x k tiles, one counting traversal's per-ray work,
interleaved timing of parameter sets into the point store, and the leave-one-scene-out fits of
:class:`costmodel.packet.PacketCostFit`."""
from __future__ import annotations

import numpy as np
import pandas as pd

from costmodel.fit import leave_one_scene_out
from costmodel.packet import PacketCostFit, best_config
from experiments.wald.lib.views import wald_camera
from tracer.accel.packet import CoherentGrid
from tracer.measure.timing import time_paired
from tracer.scenes.rays import camera_rays

#: points with more than this fraction of the rays meeting the grid traced on their own are not
#: packet traversals (left out of cost-model fits)
MAX_SINGLE = 0.5
#: fit the packet cost model with a per-ray constant besides the four per-packet ones
RAY_TERM = True


# ---------------------------------------------------------------- shared measurement helpers
def camera(scene, side: int, k: int, eye_dir=(0.55, 0.45, 0.7)):
    """Camera rays of a side x side image ordered in k x k tiles (one packet per tile)."""
    return camera_rays(scene, side, side, tile=k, eye_dir=eye_dir)


def packet_work(cgt, rays) -> dict:
    """Per-ray work of one counting traversal: the cost model's columns plus the other counters."""
    pc = cgt.packet_counters(rays.origins, rays.directions)
    n = rays.n
    single, packed = pc["single"].sum(), pc["packet_rays"].sum()
    out = {"packets": len(pc["rays"]) / n, "hits": float((pc["hits"].tri_id >= 0).mean()),
           "single_frac": single / max(single + packed, 1)}  # of the rays meeting the grid
    for k in ("slices", "cells", "considered", "tests_plain", "tests_mb", "tests_mb_fc", "tests", "test_lanes",
              "macro_skips"):
        out[k] = pc[k].sum() / n
    return out


def model_X(df: pd.DataFrame) -> pd.DataFrame:
    """The cost model's per-ray columns; its ``tests`` are the SIMD lanes the tests occupied (a
    packet's ray loop runs over whole vectors, so small packets pay for idle lanes)."""
    return pd.DataFrame({"packets": df.packets, "slices": df.slices, "cells": df.cells, "tests": df.test_lanes},
                        index=df.index)


def _row(scene, params: dict, cgt, rays, seconds: list, spread: float) -> dict:
    import numba
    st = cgt.stats()
    med = float(np.median(seconds))
    return {"scene": scene.name, "N": scene.n, **{f"param_{a}": v for a, v in params.items()},
            "packet": params.get("packet", 8), "lam": params.get("lam", 5.0), "side": int(np.sqrt(rays.n)),
            "rays": rays.n, "res": "x".join(str(v) for v in st["res"]), "cells_total": st["cells"], "refs": st["refs"],
            "build_s": st["build_s"], "seconds": med, "seconds_min": float(np.min(seconds)), "spread": spread,
            "samples": len(seconds), "ns_per_ray": med / rays.n * 1e9, "mrays_s": rays.n / med / 1e6,
            **packet_work(cgt, rays), "threads": numba.get_num_threads()}


def measure_points(store, target: str, scene, param_list, side, repeats, threads, log) -> list[dict]:
    """Time every parameter set on one scene not in the point store yet: build all, then
    ``repeats`` interleaved rounds (:func:`tracer.measure.timing.time_paired`: a warm-up call
    first), so a burst of load on a shared machine hits every point alike; per point the median
    of the rounds. Camera rays in k x k tile order; the counted work of the same rays."""
    keys = [{"target": target, "scene": scene.name, "params": p, "side": side, "repeats": repeats,
             "threads": threads} for p in param_list]
    todo = [(k, p) for k, p in zip(keys, param_list) if store.get(k) is None]
    if todo:
        rows, prov = store.ctx.run_task(store, time_points, scene, [p for _, p in todo], side, repeats)
        for (key, params), row in zip(todo, rows):
            store.put(key, row, provenance=prov)
            log(f"  {scene.name} {params}: {row['ns_per_ray']:.1f} ns/ray")
    return [dict(store.get(k, ignore_force=True), **store.provenance(k)) for k in keys]


def time_points(scene, param_list, side, repeats) -> list[dict]:
    """Build every parameter set and time them all in interleaved rounds (one task of the run)."""
    built = [(CoherentGrid(**p).build(scene), camera(scene, side, p.get("packet", 8))) for p in param_list]
    tp = time_paired({j: (lambda c=c, r=r: c.intersect(r.origins, r.directions, counters=False))
                      for j, (c, r) in enumerate(built)}, rounds=repeats, repeats=1)
    return [_row(scene, params, cgt, rays, tp[j], (max(tp[j]) - min(tp[j])) / float(np.median(tp[j])))
            for j, (params, (cgt, rays)) in enumerate(zip(param_list, built))]


def loso_predictions(df: pd.DataFrame, key: str) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Leave-one-scene-out: for each scene fit PacketCostFit on the other scenes' points, predict
    this scene's times from its counted work; returns (df with ``predicted``, per-scene best).
    Points traced mostly ray by ray (incoherent packets fall back) are left out of fits and
    candidates: the packet model does not describe them."""
    out, best = [], []
    ok = df[df.single_frac <= MAX_SINGLE]
    for name, _, mine in leave_one_scene_out(df):
        train = ok[ok.scene != name] if ok.scene.nunique() > 1 else ok  # one scene: fitted on itself
        fit = PacketCostFit(ray_term=RAY_TERM).fit(model_X(train), train.ns_per_ray)
        pred = mine.assign(predicted=fit.predict(model_X(mine)))
        cand = ok[ok.scene == name]
        b, _ = best_config(fit, pd.concat([cand[["packet", "lam"]], model_X(cand)], axis=1), keys=("packet", "lam"))
        out.append(pred)
        meas = mine.loc[mine.ns_per_ray.idxmin()]
        best.append({"scene": name, f"measured_best_{key}": meas[key], f"predicted_best_{key}": b[key],
                     "penalty_of_predicted_pct": 100 * (float(mine[mine[key] == b[key]].ns_per_ray.min()) / meas.ns_per_ray - 1),
                     "loso_mape_pct": _mape(pred[pred.single_frac <= MAX_SINGLE])})
    return pd.concat(out), pd.DataFrame(best)


def _mape(d: pd.DataFrame) -> float:
    return float(np.mean(np.abs(d.predicted - d.ns_per_ray) / d.ns_per_ray) * 100) if len(d) else float("nan")


def pooled_fit(df: pd.DataFrame, ray_term: bool = True) -> PacketCostFit:
    ok = df[df.single_frac <= MAX_SINGLE]
    return PacketCostFit(ray_term=ray_term).fit(model_X(ok), ok.ns_per_ray)


def fit_note(df: pd.DataFrame) -> str:
    """The four-constant model of the brief against the one with a per-ray term, on the same points."""
    f4, f5 = pooled_fit(df, False), pooled_fit(df, True)
    return (f"Four constants (per packet, slice, cell, test lane): R² {f4.metrics_['r2']:.3f}, MAPE "
            f"{f4.metrics_['mape']:.1f} %; with a fifth, per-ray constant T_ray (clipping and sorting each ray, "
            f"writing its hit — work that does not shrink with the packet size): R² {f5.metrics_['r2']:.3f}, MAPE "
            f"{f5.metrics_['mape']:.1f} %. Predictions use the five-constant model. Points where over "
            f"{100 * MAX_SINGLE:.0f} % of the rays fell back to single-ray traversal are left out of fits.")


def constants_table(fit: PacketCostFit) -> str:
    lines = ["| constant | fitted (ns) | 95 % CI |", "|---|---|---|"]
    for name, v in fit.constants_.items():
        lo, hi = fit.ci_[name]
        lines.append(f"| {name} | {v:.3g} | {lo:.3g}–{hi:.3g} |")
    return "\n".join(lines)


def count_tests(scene, side: int, k: int, exact: bool, lam: float = 5.0, macro: int = 6) -> dict:
    """Per-ray work of one counting traversal with k x k packets (wald-table1, wald-table4)."""
    rays = wald_camera(scene, side, k)
    cgt = CoherentGrid(packet=k, lam=lam, exact=exact, macro=macro).build(scene)
    pc = cgt.packet_counters(rays.origins, rays.directions)
    n = rays.n
    row = {"scene": scene.name, "N": scene.n, "packet": k, "side": side, "rays": n, "exact": exact,
           "res": "x".join(str(v) for v in cgt.res_), "refs_per_tri": cgt.refs_ / scene.n,
           "hits": float((pc["hits"].tri_id >= 0).mean()), "single_frac": pc["single"].sum() / n}
    for c in ("slices", "cells", "considered", "tests_plain", "tests_mb", "tests_mb_fc", "culled"):
        row[c] = pc[c].sum() / n
    return row
