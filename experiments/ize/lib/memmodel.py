"""The memory-aware cost model in the Ize tables: its M for a held-out scene, and the model chosen per
scene (:mod:`costmodel.memory`).

For a scene of a table, the model's constants are fitted on the *other* scenes swept in the same run
(same ray kind; Tsetup per scene, Ts0, Ti and kappa pooled) with the host's load-latency curve
(:class:`tracer.measure.machine.MachineModel`); its M is the minimum of the prediction over the scene's
counters (counted at the swept M, interpolated between them). With a single scene in the run the fit
is the scene's own (marked ``in-sample``). ``calibrate=True`` then refits Tsetup, Ts0 and Ti on three
of the scene's own swept points (:class:`costmodel.memory.SceneCalibratedFit`), keeping kappa.
"""
from __future__ import annotations

import pandas as pd

from costmodel.memory import MemoryCostFit, SceneCalibratedFit, calibration_rows, model_optimum

def machine(quick: bool = False, log=None):
    """The host's machine model, read from the probe's file (probed the first time on a host)."""
    from tracer.measure.machine import MachineModel
    return MachineModel.load(quick=quick, log=log)


def memory_aware_table(df: pd.DataFrame, scenes, kinds, quick: bool = False, log=None, calibrate: bool = False) -> dict:
    """(scene, kind) -> :func:`memory_aware_cells` of every scene of ``scenes`` and kind of ``kinds``
    (one-level grids), the host's :func:`machine` model loaded first."""
    mach = machine(quick, log=log)
    return {(name, kind): memory_aware_cells(df, name, kind, mach, calibrate=calibrate)
            for name in scenes for kind in kinds}


def grid_rows(df: pd.DataFrame, kind: str, structure: str = "grid", x: str = "cells") -> pd.DataFrame:
    d = df[(df.ray_kind == kind) & (df.structure == structure)]
    return d.drop_duplicates(["scene", x])


def memory_aware_cells(df: pd.DataFrame, scene: str, kind: str, mach, structure: str = "grid",
                       x: str = "cells", calibrate: bool = False) -> tuple[float, str]:
    """(M, how): the memory-aware model's M (``x`` = "cells"), or M1 of a nested grid (``structure`` =
    "nested", ``x`` = "param_m1"), for ``scene`` from the other scenes' sweeps of ``df`` (with
    ``calibrate``, Ts0 and Ti from three of the scene's own swept points)."""
    d = grid_rows(df, kind, structure, x)
    test = d[d.scene == scene]
    train = d[d.scene != scene]
    how = "held-out"
    if train.scene.nunique() == 0:
        train, how = test, "in-sample"
    fit = MemoryCostFit(mach).fit(train, train.anchored_ns_per_ray)
    if calibrate:
        pts = calibration_rows(test, x)
        fit = SceneCalibratedFit(fit).fit(pts, pts.anchored_ns_per_ray)
        how = f"kappa {how}, Ts0 and Ti from {len(pts)} of the scene's swept points"
    return model_optimum(fit, test, x), how
