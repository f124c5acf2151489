"""``predict``: the held-out scores and the model choice held out too (nested leave-one-scene-out),
on sweeps made by a known cost model."""
import numpy as np
import pandas as pd
import pytest

from costmodel import memory as mm
from experiments.ize import predict
from tracer.measure.machine import MachineModel


def _machine():
    b = [4096 * 2**i for i in range(16)]
    lat = [1.0 if x <= 32 << 10 else (5.0 if x <= 1 << 20 else 80.0) for x in b]
    return MachineModel({"bytes": b, "latency_ns": lat, "caches": {"L1": 32 << 10, "L2": 1 << 20, "L3": 8 << 20},
                         "host": "h", "cpu": "c"})


def _sweeps(mach, kappa_e: float, ts_r: float, seed: int = 0) -> pd.DataFrame:
    """Six scenes x 9 grids; T = Tsetup + 3 steps + 12 tests + kappa_e entry + Ts_r steps ln(refs/N)."""
    rng = np.random.default_rng(seed)
    rows = []
    for k, (n, stretch, setups) in enumerate(((1000, 1.0, 0.6), (5000, 3.0, 0.3), (20000, 1.5, 0.6),
                                              (2000, 8.0, 0.5), (40000, 1.2, 0.4), (8000, 20.0, 0.6))):
        for cells in np.geomspace(n / 8, 64 * n, 9):
            steps, tests = 2 * cells ** (1 / 3), 4 * n / cells ** (2 / 3) + 1
            rows.append({"scene": f"s{k}", "sweep": f"x:s{k}", "N": n, "cells": cells, "steps": steps, "tests": tests,
                         "occupied": 0.3 * steps, "setups": setups, "refs": n * stretch * (1 + cells / n) ** (1 / 3),
                         "memory_bytes": 4 * cells + 60 * n, "point_seconds": 0.1, "setup": 40.0 + 25 * k})
    f = pd.DataFrame(rows)
    T = (f.setup + 3.0 * f.steps + 12.0 * f.tests
         + kappa_e * mm.entry_feature(mach, f.setups, f.cells, f.memory_bytes)
         + ts_r * mm.refs_step_feature(f.steps, f.refs, f.N))
    return f.assign(anchored_ns_per_ray=T * (1 + 0.003 * rng.standard_normal(len(f))))


def test_nested_selection_picks_the_model_that_made_the_data():
    mach = _machine()
    scenes = [f"s{k}" for k in range(6)]
    rich = predict.nested_selection(_sweeps(mach, 0.8, 2.0), scenes, mach)
    assert list(rich.scene) == scenes and (rich.picked == "entry-refs").all()
    assert rich.mape_pct.max() < 2.0
    # the counter model's data: the extra terms buy nothing, so a simpler model is picked
    plain = predict.nested_selection(_sweeps(mach, 0.0, 0.0), scenes, mach)
    assert set(plain.picked) <= {"paper", "counter"}
    assert plain.mape_pct.max() < 2.0
    # scored like holdout(): the outer scene never enters its own choice
    s0 = predict.holdout(_sweeps(mach, 0.8, 2.0), "s0", scenes[1:], "entry-refs", mach)
    assert rich.mape_pct.iloc[0] == pytest.approx(s0["mape_pct"])


def test_pick_is_the_simplest_within_tolerance():
    assert predict._pick({"paper": 5.0, "counter": 4.5, "memory-aware": 4.4, "entry-refs": 4.2}) == "paper"
    assert predict._pick({"paper": 9.0, "counter": 8.0, "memory-aware": 7.5, "entry-refs": 6.0}) == "entry-refs"
    assert predict._pick({"paper": 9.0, "counter": 6.9, "memory-aware": 7.5, "entry-refs": 6.0}) == "counter"


def test_three_scene_points_recover_a_scene_unlike_the_others():
    """A held-out scene whose test costs 3 ns (the others: 12 ns): the pooled model misses it; with
    Ts0 and Ti refitted on three of its points the error is the noise's, and the cost counts them."""
    mach = _machine()
    f = _sweeps(mach, 0.0, 0.0)
    odd = f.scene == "s5"
    f.loc[odd, "anchored_ns_per_ray"] -= 9.0 * f.loc[odd, "tests"]
    others = [f"s{k}" for k in range(5)]
    pooled = predict.holdout(f, "s5", others, "memory-aware", mach)
    cal = predict.holdout(f, "s5", others, "memory-aware", mach, calibrate=True)
    assert cal["model"] == predict.CALIBRATED
    assert pooled["mape_pct"] > 10.0 and cal["mape_pct"] < 1.0
    assert cal["penalty_pct"] < 1.0 < pooled["penalty_pct"]
    assert cal["calibration_s"] == pytest.approx(len(others) * 9 * 0.1 + 3 * 0.1)
