"""The stability map's pieces: the derived CAD / teapot-in-stadium scenes, the rules (with the
memory-aware hook), the interpolation, the two-level point and the failure sentence."""
from __future__ import annotations


import numpy as np
import pandas as pd

from experiments.ize import exponents, stability


def test_derived_families_are_named():
    fams = {k: v for k, v in exponents.FAMILIES.items() if k.startswith(("CAD", "teapot"))}
    assert len(fams) == 2 and all(len(v[0]) >= 3 and v[1] == [] for v in fams.values())


def test_rule_cells_and_the_memory_rule(load):
    scene = load("bunny-948")
    rules = stability.rule_cells(scene, 4.0)
    assert rules["8N (Ize Eq 4, Ti/Ts = 4)"] == 8 * 948 == rules["2N·Ti/Ts (Eq 4, Ti/Ts fitted here)"]
    assert stability.MEMORY_AWARE not in rules
    got = stability.rule_cells(scene, 4.0, {stability.MEMORY_AWARE: 1234.0, stability.MEMORY_CALIBRATED: 99})
    assert got[stability.MEMORY_AWARE] == 1234.0 and got[stability.MEMORY_CALIBRATED] == 99.0


def test_time_at_interpolates_in_log_log_and_never_extrapolates():
    cells, t = np.array([100.0, 10_000.0]), np.array([4.0, 1.0])
    assert np.isclose(stability.time_at(cells, t, 1000.0), 2.0)
    assert np.isnan(stability.time_at(cells, t, 50.0)) and np.isnan(stability.time_at(cells, t, 2e4))


def test_two_level_point_is_paired_with_the_sweeps_reference(load, tmp_path):
    from experiments.core.context import RunContext
    from experiments.core.sweep import sweep
    from tracer.scenes.rays import make_rays
    scene = load("bunny-948")
    store = RunContext(out=tmp_path, threads=1, quick=True).store()
    rays = {"random": make_rays(scene, "random", 2000, seed=3)}
    k = pd.DataFrame(sweep(scene, "grid", [{"cells": 8.0 * scene.n}], rays, store, 1))
    pen, row = stability.two_level_penalty(scene, k, store, 1)
    assert row["structure"] == "nested" and row["rays"] == 2000 and row["seed"] == 3
    assert np.isclose(pen, 100 * (row["ratio_to_ref"] / k.ratio_to_ref.iloc[0] - 1)) and pen > -100


def test_where_fails_names_families_and_sizes():
    df = pd.DataFrame({"rule": ["r"] * 3, "family": ["a", "a", "b"], "N": [10, 100, 5],
                       "penalty_pct": [3.0, 25.0, np.nan]})
    assert stability.where_fails(df, "r") == "fails (> 10 %) on a (1 of 2, N = 100; worst 25 %)"
    assert "within 10 %" in stability.where_fails(df.assign(penalty_pct=1.0), "r")
