"""advise's probes and the advise-check target: camera probes are whole packets of the full frame,
every candidate is measured, a row's goals are computed from the measured totals."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from experiments.tools import advise_check
from experiments.tools.lib import advising as advise
from tracer.errors import GridcostError


class _FixedEstimator:
    """A calibration stand-in: fixed (T_BH, t_RH) whatever the scene."""
    n_calib_ = 0

    def __init__(self, T, t):
        self.T, self.t = T, t

    def predict(self, N, feats):
        return self.T, self.t


def _cal(T):
    rel = {"build": (-0.5, 0.5), "ray": (-0.5, 0.5)}
    return {k: {h: (_FixedEstimator(T, 1e-7), rel) for h in ("kdtree", "bvh")} for k in ("random", "path")}


def test_probe_pool_is_the_full_frame_in_consecutive_pieces(load):
    from tracer.scenes.rays import make_rays
    scene = load("bunny-948")
    full = make_rays(scene, "camera", advise.CHECK_RAYS, seed=0)
    pool = advise.probe_pool(scene, "camera", 0)
    per = advise.PROBE_RAYS // advise.PACKET * advise.PACKET
    assert len(pool) == advise.PROBE_SETS and all(r.n == per and r.kind == "camera" for r in pool)
    # the frame's rays in its own (8x8 packet) order, cut into consecutive whole-packet pieces
    np.testing.assert_array_equal(np.concatenate([r.directions for r in pool]), full.directions[:per * len(pool)])
    assert per * len(pool) > 0.99 * full.n
    rnd = advise.probe_pool(scene, "random", 0)
    assert len(rnd) == advise.PROBE_SETS and all(r.n == advise.PROBE_RAYS for r in rnd)
    every = np.concatenate([r.origins for r in rnd])
    assert len(np.unique(every, axis=0)) == len(every)  # disjoint: no ray traced twice


def test_check_truth_on_camera_rays_is_another_frame_of_the_same_view(load, monkeypatch):
    scene = load("bunny-948")
    seen = {}
    monkeypatch.setattr(advise, "time_structures", lambda sc, st, rays, *a: seen.setdefault("rays", rays))
    advise.measure(scene, "camera", [("grid", {})], 4096, seed=0)
    probe = np.concatenate([r.directions for r in advise.probe_pool(scene, "camera", 0)])
    truth = seen["rays"]
    assert truth.n == 4096 and truth.kind == "camera"
    probe_set = {row.tobytes() for row in probe}
    assert not any(row.tobytes() in probe_set for row in truth.directions)  # jittered: none of the probes' rays
    np.testing.assert_allclose(truth.origins[0], advise.probe_pool(scene, "camera", 0)[0].origins[0])


def test_time_structures_traces_the_next_set_at_each_call(load, monkeypatch):
    """A probe never traces one ray set twice in a row: each call takes the next set of the pool."""
    scene = load("bunny-948")
    pool = advise.probe_pool(scene, "random", 0)[:3]
    seen = []
    from tracer.accel.grid import UniformGrid
    orig = UniformGrid.intersect

    def spy(self, o, d, counters=True):
        seen.append(int(np.flatnonzero([np.array_equal(o, r.origins) for r in pool])[0]))
        return orig(self, o, d, counters=counters)
    monkeypatch.setattr(UniformGrid, "intersect", spy)
    got = advise.time_structures(scene, [("grid", {"factor": 1.0})], pool, repeats=2, build_repeats=1, min_sample=0.0)
    assert seen[:6] == [0, 1, 2, 0, 1, 2][:len(seen[:6])] and len(seen) >= 3
    assert got["grid"]["rays"] == advise.PROBE_RAYS and got["grid"]["ray_s"] > 0
    with pytest.raises(GridcostError, match="unequal sizes"):
        short = pool[1]._replace(origins=pool[1].origins[:10], directions=pool[1].directions[:10])
        advise.time_structures(scene, [("grid", {})], [pool[0], short], repeats=1, build_repeats=1)


@pytest.mark.slow  # CI runs advise-check inside test_all_quick_into_a_fresh_folder; this checks its details
def test_check_scene_measures_every_candidate(load):
    """Cheap hierarchies are probed (not estimated); every candidate has measured parts; each
    budget's row compares the pick with the fastest measured total."""
    scene = load("bunny-948")
    rows, cands = advise_check.check_scene(scene, "camera", _cal(T=1e-3), n_rays=2048, repeats=1, seed=0)
    names = [c["structure"] for c in cands]
    assert set(names) == {"grid", "nested", "cgt", "kdtree", "bvh"}
    assert all(c["how"].startswith("probed") for c in cands)
    assert all(c["meas_build_ms"] > 0 and c["meas_ray_ns"] > 0 and c["pred_ray_ns"] > 0 for c in cands)
    assert [r["R"] for r in rows] == list(advise_check.BUDGETS)
    for r in rows:
        assert r["pick"] in names and r["measured_best"] in names
        assert r["best_measured_s"] <= r["pick_measured_s"] and r["pick_loss_pct"] >= 0
        assert r["pick_ok"] == (r["pick_loss_pct"] <= 10)
        assert np.isclose(r["pred_err_pct"], 100 * (r["predicted_s"] / r["pick_measured_s"] - 1))
    # an expensive estimated build is not probed: the calibration's numbers are used as they are
    _, cands = advise_check.check_scene(scene, "random", _cal(T=10.0), n_rays=1000, repeats=1, seed=0)
    est = [c for c in cands if c["structure"] in ("kdtree", "bvh")]
    assert all(c["how"].startswith("estimated") and np.isclose(c["pred_build_ms"], 1e4) for c in est)
    assert all(np.isclose(c["pred_ray_ns"], 100.0) for c in est)


def test_row_goals_and_summary():
    class S:
        name, n = "x", 10
    pick = {"structure": "bvh", "predicted_s": 1.1, "predicted_lo": 0.9, "predicted_hi": 1.3}
    r = advise_check.summarise_row(S, "random", 1e6, pick, {"bvh": 1.05, "grid": 1.0}, "grid", 1000)
    assert np.isclose(r["pick_loss_pct"], 5.0) and r["pick_ok"]
    assert np.isclose(r["pred_err_pct"], 100 * (1.1 / 1.05 - 1)) and r["pred_ok"] and r["measured_in_interval"]
    r2 = advise_check.summarise_row(S, "random", 1e6, dict(pick, predicted_s=2.0), {"bvh": 1.2, "grid": 1.0}, "grid", 1000)
    assert not r2["pick_ok"] and not r2["pred_ok"]
    cdf = pd.DataFrame([{"scene": "x", "ray_kind": "random", "structure": "grid", "pred_build_ms": 1.0,
                         "meas_build_ms": 2.0, "build_err_pct": -50.0, "pred_ray_ns": 3.0, "meas_ray_ns": 3.0,
                         "ray_err_pct": 0.0, "how": "probed"}])
    cands = [{"structure": "bvh", "pred_build_ms": 100.0, "meas_build_ms": 100.0, "build_err_pct": 0.0,
              "pred_ray_ns": 2000.0, "meas_ray_ns": 1200.0, "ray_err_pct": 66.7},
             {"structure": "grid", "pred_build_ms": 10.0, "meas_build_ms": 500.0, "build_err_pct": -98.0,
              "pred_ray_ns": 1000.0, "meas_ray_ns": 1000.0, "ray_err_pct": 0.0}]
    assert advise_check.diagnose(r2, cands) == "pick: bvh per ray +67 %; prediction: bvh per ray +67 %"
    assert advise_check.diagnose(dict(r2, R=1.0), cands) == "pick: grid build -98 %; prediction: bvh per ray +67 %"
    assert advise_check.diagnose(r, cands) == ""
    r, r2 = dict(r, cause=""), dict(r2, cause="x")
    md = advise_check._summary(pd.DataFrame([r, r2]), cdf, {"x": ("test", "a test")}, 1000, 3)
    assert "pick 1 of 2, prediction 1 of 2" in md and "| x | random | 1e+06 | bvh | grid | 5.0 |" in md
