"""The cost model fitted to *someone else's* uniform grid: their timings in, gridcost's counted work
of the same grids beside them, their constants out (``fit --timings``), and those constants applied
to other meshes (``advise --constants``).

A timings CSV holds one row per resolution of the user's grid:

* ``cells`` (total cells; gridcost picks near-cubic cells in the mesh's box, Ize 2007 Sec 2.2) or
  ``nx, ny, nz`` (the divisions per axis, as most implementations take them);
* ``rays`` (rays traced) and ``seconds`` (their trace time; not the build).

gridcost builds the same grids over the same mesh, traces rays of the same kind (or the very rays,
``--rays-file``, an ``.npz`` with ``origins`` and ``directions``) and counts set-ups, steps and
tests per ray; :class:`costmodel.worktime.WorkTimeFit` prices that work in the user's seconds.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from costmodel.worktime import WORK_TERMS, WorkTimeFit
from tracer.accel import build
from tracer.accel.grid import res_from_cells
from tracer.errors import GridcostError
from tracer.scenes.rays import Rays, make_rays

#: rays gridcost counts each grid's work on (per-ray means settle well below this)
COUNT_RAYS = 20_000
#: the resolutions a best one is chosen among: cells = factor x N, geometric from N/4 to 64N
CANDIDATE_FACTORS = tuple(float(f) for f in np.geomspace(0.25, 64.0, 25))
#: the file format of a fitted constants file (``fit --timings`` writes it, ``advise --constants`` reads it)
CONSTANTS_FORMAT = "gridcost-user-grid-constants/1"


def read_timings(path) -> pd.DataFrame:
    """The user's timings, validated: one clear error naming the file and what is wrong."""
    if isinstance(path, pd.DataFrame):  # the Python API's table: the same checks
        df, path = path.copy(), "table"
    else:
        path = Path(path)
        try:
            df = pd.read_csv(path, comment="#", skipinitialspace=True)
        except (OSError, ValueError, pd.errors.ParserError) as exc:
            raise GridcostError(f"timings {path}: cannot read it as CSV ({exc})") from None
    df.columns = [str(c).strip().lower() for c in df.columns]
    per_axis = bool({"nx", "ny", "nz"} & set(df.columns))  # any of them: the per-axis form, say which is missing
    need = {"rays", "seconds"} | ({"nx", "ny", "nz"} if per_axis else {"cells"})
    if missing := need - set(df.columns):
        raise GridcostError(f"timings {path}: missing column(s) {', '.join(sorted(missing))}; "
                            "need rays, seconds and either cells or nx, ny, nz")
    cols = ["nx", "ny", "nz"] if per_axis else ["cells"]
    try:
        vals = df[cols + ["rays", "seconds"]].astype(float)
    except ValueError as exc:
        raise GridcostError(f"timings {path}: a value is not a number ({exc})") from None
    if not np.isfinite(vals.values).all() or (vals.values <= 0).any():
        raise GridcostError(f"timings {path}: every cells/nx/ny/nz, rays and seconds must be a positive number")
    if per_axis and (vals[cols] != vals[cols].round()).any().any():
        raise GridcostError(f"timings {path}: nx, ny, nz must be whole numbers")
    if len(vals) < len(WORK_TERMS) + 1:
        raise GridcostError(f"timings {path}: {len(vals)} row(s); need at least {len(WORK_TERMS) + 1} resolutions "
                            f"to fit {len(WORK_TERMS)} constants and check them")
    return vals.reset_index(drop=True)


def grid_of(row, scene) -> tuple[int, int, int]:
    """The per-axis divisions of a timings row (its own, or near-cubic cells for a total)."""
    if "nx" in row:
        return int(row["nx"]), int(row["ny"]), int(row["nz"])
    return tuple(int(v) for v in res_from_cells(scene.bounds, float(row["cells"])))


def load_rays(path) -> Rays:
    """The user's own rays from an ``.npz`` with ``origins`` and ``directions`` ((m, 3) each)."""
    try:
        with np.load(path) as z:
            o, d = np.asarray(z["origins"], np.float32), np.asarray(z["directions"], np.float32)
    except (OSError, KeyError, ValueError) as exc:
        raise GridcostError(f"rays file {path}: need an .npz with origins and directions ({exc})") from None
    if o.ndim != 2 or o.shape[1:] != (3,) or d.shape != o.shape or not len(o):
        raise GridcostError(f"rays file {path}: origins and directions must be two (m, 3) arrays, got {o.shape}, {d.shape}")
    return Rays(o, d, "user", 0)


def counting_rays(scene, kind: str, seed: int, rays_file=None, n: int = COUNT_RAYS) -> Rays:
    rays = load_rays(rays_file) if rays_file else make_rays(scene, kind, n, seed=seed)
    if rays.n > n:  # a spread-out subset: per-ray means, not the user's whole frame
        step = rays.n // n
        rays = rays._replace(origins=rays.origins[::step][:n], directions=rays.directions[::step][:n])
    return rays


def count_work(scene, grids, rays: Rays, grid_params: dict | None = None) -> pd.DataFrame:
    """Per-ray means of the fitted counters, and the cells and memory, of gridcost's grid at each
    of ``grids`` (per-axis divisions) on ``rays``."""
    rows = []
    for res in grids:
        acc = build(scene, "grid", res=tuple(int(v) for v in res), **(grid_params or {}))
        _, cnt = acc.intersect(rays.origins, rays.directions, counters=True)
        mean = cnt.mean()
        st = acc.stats()
        rows.append({"nx": int(res[0]), "ny": int(res[1]), "nz": int(res[2]), "cells": int(np.prod(res)),
                     **{k: mean[k] for k in WORK_TERMS}, "memory_bytes": st.get("memory_bytes")})
    return pd.DataFrame(rows)


#: how far beyond the resolutions a user timed (cells / N) a recommendation may reach, either way: a
#: model fitted on a range is not trusted far outside it (a step cost fitted as zero would otherwise
#: send every recommendation to the finest candidate)
EXTRAPOLATION = 2.0


def candidates(scene, factor_range=None) -> list[tuple[int, int, int]]:
    """The per-axis divisions a best resolution is chosen among (:data:`CANDIDATE_FACTORS` x N), within
    ``factor_range`` (lo, hi) of cells / N when given (the timed range widened by :data:`EXTRAPOLATION`)."""
    fs = [f for f in CANDIDATE_FACTORS if factor_range is None or factor_range[0] <= f <= factor_range[1]]
    if factor_range is not None:
        fs = sorted(set(fs) | {factor_range[0], factor_range[1]})
    seen = dict.fromkeys(tuple(int(v) for v in res_from_cells(scene.bounds, f * scene.n)) for f in fs)
    return list(seen)


def timed_factor_range(work: pd.DataFrame, n: int) -> tuple[float, float]:
    """The cells / N of the timed rows, widened by :data:`EXTRAPOLATION` either way."""
    f = work.cells.to_numpy(float) / n
    return float(f.min() / EXTRAPOLATION), float(f.max() * EXTRAPOLATION)


def recommend(fit: WorkTimeFit, scene, rays: Rays, grid_params=None, budget_rays: float | None = None,
              factor_range=None) -> dict:
    """The fitted constants applied to ``scene``: the predicted time per ray at every candidate
    resolution (within ``factor_range`` of cells / N), the best one, and the resolutions within the
    bootstrap's spread of the best."""
    work = count_work(scene, candidates(scene, factor_range), rays, grid_params)
    best = fit.best(work)
    work["predicted_s_per_ray"] = best["predicted"]
    work["best_share"] = best["share"]
    b = work.iloc[best["index"]]
    likely = work[work.best_share >= 0.05]
    out = {"scene": scene.name, "N": scene.n, "best": {k: (int(b[k]) if k in ("nx", "ny", "nz", "cells") else float(b[k]))
                                                     for k in ("nx", "ny", "nz", "cells", "predicted_s_per_ray")},
           "best_factor": float(b.cells / scene.n),
           "cells_range": [int(likely.cells.min()), int(likely.cells.max())] if len(likely) else None,
           "factor_range": list(factor_range) if factor_range is not None else None, "table": work}
    if budget_rays:
        out["best"]["predicted_s"] = float(b.predicted_s_per_ray * budget_rays)
    return out


def fit_timings(timings: pd.DataFrame, scene, rays: Rays, grid_params=None) -> dict:
    """Fit the user's constants: their seconds per ray at each row against gridcost's counted work
    of the same grids; the model's errors; the predicted best resolution among the candidates."""
    grids = [grid_of(row, scene) for _, row in timings.iterrows()]
    work = count_work(scene, grids, rays, grid_params)
    t_ray = (timings.seconds / timings.rays).to_numpy()
    fit = WorkTimeFit().fit(work, t_ray)
    work["seconds_per_ray"] = t_ray
    work["fitted_s_per_ray"] = fit.predict(work)
    work["loo_error_pct"] = fit.loo_
    rec = recommend(fit, scene, rays, grid_params, factor_range=timed_factor_range(work, scene.n))
    return {"fit": fit, "work": work, "recommendation": rec}


def constants_record(res: dict, scene, kind: str, grid_params, source: str) -> dict:
    """The JSON ``fit --timings`` writes and ``advise --constants`` reads."""
    fit = res["fit"]
    return {"format": CONSTANTS_FORMAT, "fitted_on": {"mesh": scene.name, "N": scene.n, "rays": kind,
                                                      "timings": source, "rows": len(res["work"])},
            "model": "T_ray = tsetup * setups + ts * steps + ti * tests (seconds per ray; counters per ray)",
            **fit.summary(), "grid_params": grid_params or {},
            "predicted_best": res["recommendation"]["best"], "predicted_cells_range": res["recommendation"]["cells_range"],
            "factor_range": res["recommendation"]["factor_range"],
            "rows": res["work"].to_dict(orient="records")}


def fit_from_record(rec: dict) -> WorkTimeFit:
    """A :class:`WorkTimeFit` holding the constants of a ``fit --timings`` JSON (bootstrap samples
    are not stored: the intervals come from ``ci``, the stability share is then that of the point fit)."""
    if rec.get("format") != CONSTANTS_FORMAT:
        raise GridcostError(f"constants file: not a {CONSTANTS_FORMAT} file (format {rec.get('format')!r})")
    fit = WorkTimeFit()
    try:
        fit.coef_ = {name: float(rec["constants"][name]) for name in fit.terms.values()}
    except (KeyError, TypeError, ValueError) as exc:
        raise GridcostError(f"constants file: missing or bad constant ({exc})") from None
    fit.boot_ = np.array([list(fit.coef_.values())])
    return fit
