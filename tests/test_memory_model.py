"""The memory-aware cost model: its sympy equations, its fit, the machine model and the occupied counter."""
import numpy as np
import pandas as pd
import pytest

from costmodel import memory as mm
from tracer.accel import build
from tracer.measure.machine import MachineModel, chase_ns
from tracer.scenes.rays import make_rays
from tracer.scenes.scene import load_scene


def test_one_level_optimum_closed_form_and_paper_limit():
    r = mm.memory_eq_one_level_optimum()
    assert r["as_stated"] and r["limit_is_eq4"]
    # numeric: Lambda = K = 0 gives 2 N Ti / Ts0 (= 8N for Ti/Ts0 = 4)
    f = r["M"].subs({mm.Lam: 0, mm.K: 0, mm.Ti: 4, mm.Ts0: 1, mm.N: 1000})
    assert float(f) == pytest.approx(8000)


def test_long_skinny_cubic_and_paper_limit():
    r = mm.memory_eq_long_skinny_optimum()
    assert r["as_stated"] and r["limit_is_eq8"]
    assert mm.long_skinny_optimum_numeric(1000, 4.0, 1.0, 0.0, 0.0) == pytest.approx(8 * 1000**1.5, rel=1e-9)
    # a positive K (memory cost falling with M inside the band) moves the optimum
    assert mm.long_skinny_optimum_numeric(1000, 4.0, 1.0, 1.0, 0.0) == pytest.approx((4000 / 2) ** 1.5)
    assert mm.long_skinny_optimum_numeric(1000, 4.0, 1.0, 1.0, 10_000.0) < 0.99 * (4000 / 2) ** 1.5


def _fake_machine():
    b = [4096 * 2**i for i in range(16)]
    lat = [1.0 if x <= 32 << 10 else (5.0 if x <= 1 << 20 else 80.0) for x in b]
    lat[3] = 0.5  # a dip the model must smooth away (non-decreasing)
    return MachineModel({"bytes": b, "latency_ns": lat, "caches": {"L1": 32 << 10, "L2": 1 << 20, "L3": 8 << 20},
                         "host": "h", "cpu": "c"})


def test_machine_model_is_monotone_and_extra_is_zero_in_l1():
    m = _fake_machine()
    assert np.all(np.diff(m.latency_) >= 0)
    assert m.extra_ns(8192) == 0.0
    assert m.extra_ns(64 << 20) == pytest.approx(79.0)


def test_memory_fit_recovers_constants():
    rng = np.random.default_rng(0)
    mach = _fake_machine()
    rows = []
    for s, n in (("a", 1000), ("b", 5000), ("c", 20000)):
        for cells in np.geomspace(n / 8, 64 * n, 9):
            steps, tests = 2 * cells ** (1 / 3), 4 * n / cells ** (2 / 3) + 1
            rows.append({"scene": s, "cells": cells, "steps": steps, "tests": tests, "occupied": 0.3 * steps,
                         "memory_bytes": 4 * cells + 60 * n})
    f = pd.DataFrame(rows)
    true = 50 + 3.0 * f.steps + 12.0 * f.tests + 0.4 * mm.memory_feature(mach, f.steps, f.occupied, f.cells, f.memory_bytes)
    T = true * (1 + 0.002 * rng.standard_normal(len(f)))
    fit = mm.MemoryCostFit(mach).fit(f, T)
    assert fit.ts0_ == pytest.approx(3.0, rel=0.1) and fit.ti_ == pytest.approx(12.0, rel=0.1)
    assert fit.kappa_ == pytest.approx(0.4, rel=0.1)
    # without the memory term the fit is worse on these data
    assert mm.MemoryCostFit(mach, memory=False).fit(f, T).metrics_["mape"] > fit.metrics_["mape"]
    m_opt = mm.model_optimum(fit, f[f.scene == "c"])
    assert f[f.scene == "c"].cells.min() <= m_opt <= f[f.scene == "c"].cells.max()


def test_scene_calibration_recovers_a_scene_whose_test_is_cheap():
    """Pooled on scenes whose test costs 12 ns, held out on one whose test costs 3 ns: the pooled model
    puts that scene's optimum far too high; three of the scene's own points recover its constants
    exactly (kappa kept from the pool) and its optimum."""
    mach = _fake_machine()

    def frame(s, n):
        cells = np.geomspace(n / 8, 64 * n, 19)
        steps, tests = 2 * cells ** (1 / 3), 4 * n / cells ** (2 / 3) + 1
        return pd.DataFrame({"scene": s, "cells": cells, "steps": steps, "tests": tests, "occupied": 0.3 * steps,
                             "memory_bytes": 4 * cells + 60 * n})

    def time(f, ti):
        return 50 + 3.0 * f.steps + ti * f.tests + 0.4 * mm.memory_feature(mach, f.steps, f.occupied, f.cells, f.memory_bytes)

    train = pd.concat([frame("a", 1000), frame("b", 5000), frame("c", 20000)], ignore_index=True)
    pooled = mm.MemoryCostFit(mach).fit(train, time(train, 12.0))
    room = frame("room", 10000)
    T = time(room, 3.0)
    pts = mm.calibration_rows(room)
    assert len(pts) == 3 and pts.cells.is_monotonic_increasing
    assert pts.cells.iloc[0] < room.cells.median() < pts.cells.iloc[-1]
    cal = mm.SceneCalibratedFit(pooled).fit(pts, T[pts.index])
    assert cal.ts0_ == pytest.approx(3.0, rel=1e-3) and cal.ti_ == pytest.approx(3.0, rel=1e-3)
    assert cal.kappa_ == pooled.kappa_ and cal.tsetup_["room"] == pytest.approx(50.0, rel=1e-3)
    np.testing.assert_allclose(cal.predict(room), T, rtol=1e-3)
    best = float(room.cells[int(np.argmin(T))])
    m_pool, m_cal = mm.model_optimum(pooled, room), mm.model_optimum(cal, room)
    assert m_pool > 2 * best  # the pool's 12 ns test buys cells this scene does not need
    assert best / 1.5 < m_cal < best * 1.5
    with pytest.raises(ValueError, match="needs 3 points"):
        mm.SceneCalibratedFit(pooled).fit(pts.iloc[:2], T[pts.index[:2]])


def test_entry_refs_fit_recovers_constants_and_paper_fit_keeps_its_ratio():
    rng = np.random.default_rng(1)
    mach = _fake_machine()
    rows = []
    for s, n, stretch in (("a", 1000, 1.0), ("b", 5000, 3.0), ("c", 20000, 1.5), ("d", 2000, 8.0)):
        for cells in np.geomspace(n / 8, 64 * n, 9):
            steps, tests = 2 * cells ** (1 / 3), 4 * n / cells ** (2 / 3) + 1
            rows.append({"scene": s, "N": n, "cells": cells, "steps": steps, "tests": tests, "occupied": 0.3 * steps,
                         "setups": 0.6, "refs": n * stretch * (1 + cells / n) ** (1 / 3),
                         "memory_bytes": 4 * cells + 60 * n})
    f = pd.DataFrame(rows)
    true = (50 + 3.0 * f.steps + 12.0 * f.tests + 0.8 * mm.entry_feature(mach, f.setups, f.cells, f.memory_bytes)
            + 2.0 * mm.refs_step_feature(f.steps, f.refs, f.N))
    T = true * (1 + 0.002 * rng.standard_normal(len(f)))
    fit = mm.EntryRefsCostFit(mach).fit(f, T)
    assert fit.ts0_ == pytest.approx(3.0, rel=0.15) and fit.ti_ == pytest.approx(12.0, rel=0.1)
    assert fit.kappa_ == pytest.approx(0.8, rel=0.15) and fit.ts_refs_ == pytest.approx(2.0, rel=0.15)
    assert fit.n_constants_ == 4 + 4
    assert mm.MemoryCostFit(mach, memory=False).fit(f, T).metrics_["mape"] > 3 * fit.metrics_["mape"]
    # the paper's model: one constant b for steps + 4 tests
    paper = mm.PaperCountFit().fit(f, 50 + 2.0 * (f.steps + 4 * f.tests))
    assert paper.ts0_ == pytest.approx(2.0, rel=1e-6) and paper.ti_ == 0.0 and paper.n_constants_ == 4 + 1
    np.testing.assert_allclose(paper.work(f), 2.0 * (f.steps + 4 * f.tests), rtol=1e-6)


def test_chase_probe_runs_and_is_positive():
    assert chase_ns(8192, accesses=20_000, repeats=1) > 0


@pytest.mark.parametrize("structure,params", [("grid", {"factor": 2.0}), ("nested", {})])
def test_occupied_counter(structure, params):
    scene = load_scene("bunny-948")
    r = make_rays(scene, "random", 2000, seed=1)
    _, cnt = build(scene, structure, **params).intersect(r.origins, r.directions)
    occ, steps, tests = cnt["occupied"], cnt["steps"], cnt["tests"]
    assert (occ <= steps).all() and (occ <= tests).all()
    assert ((occ > 0) == (tests > 0)).all()
    assert occ.sum() > 0 and (occ < steps).any()


@pytest.mark.parametrize("structure", ["grid", "nested", "kdtree", "bvh", "bvh4"])
def test_working_set_by_kind_adds_up(structure):
    st = build(load_scene("bunny-948"), structure).stats()
    ws = st["working_set"]
    assert ws["total"] == ws["index"] + ws["refs"] + ws["triangles"] > 0
    assert ws["triangles"] >= 948 * 36  # every triangle's 9 float32 at least once
    assert ws["total"] == st["memory_bytes"]
