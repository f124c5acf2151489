"""advise's probes and the advise-check target: camera probes are whole packets of the full frame,
every candidate is measured, a row's goals are computed from the measured totals."""
from __future__ import annotations

import numpy as np
import pandas as pd

from experiments.tools import advise, advise_check


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


def test_camera_probe_rays_are_whole_packets_of_the_full_frame(load):
    from tracer.rays import make_rays
    scene = load("bunny-948")
    full = make_rays(scene, "camera", advise.CHECK_RAYS, seed=0)
    r = advise.probe_rays(scene, "camera", 0)
    assert r.n == advise.PROBE_RAYS // advise.PACKET * advise.PACKET and r.kind == "camera"
    blocks = r.directions.reshape(-1, advise.PACKET, 3)
    fb = full.directions[: full.n // advise.PACKET * advise.PACKET].reshape(-1, advise.PACKET, 3)
    # each probe packet is one packet of the full frame, packets spread from the first to the last
    where = [int(np.flatnonzero((fb[:, 0] == b[0]).all(axis=1))[0]) for b in blocks[[0, len(blocks) // 2, -1]]]
    for w, b in zip(where, blocks[[0, len(blocks) // 2, -1]]):
        np.testing.assert_array_equal(fb[w], b)
    assert where[0] == 0 and where[-1] == len(fb) - 1 and 0 < where[1] < where[-1]
    # in PROBE_RUNS runs of consecutive packets of the frame, in the frame's order
    per = len(blocks) // advise.PROBE_RUNS
    np.testing.assert_array_equal(blocks[1:per], fb[1:per])
    assert not np.array_equal(blocks[per], fb[per])
    np.testing.assert_array_equal(blocks[-per:], fb[-per:])
    assert advise.probe_rays(scene, "random", 0).n == advise.PROBE_RAYS


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
