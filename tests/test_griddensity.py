"""The grid's machine-fitted density (costmodel.griddensity): Ize 2007 Eq 4 at a measured T_i/T_s."""
import numpy as np
import pytest

from costmodel.derive import PAPER_TI_OVER_TS
from costmodel.griddensity import FACTOR_RANGE, GridDensityFit, fit_grid_density
from tracer.accel.grid import UniformGrid
from tracer.errors import GridcostError


def _points(costs, n=9, seed=3):
    """Synthetic grid points: per kind (c_setup, c_step, c_test) in ns, steps and tests drawn apart."""
    rng = np.random.default_rng(seed)
    pts = []
    for kind, (c0, cs, ct) in costs.items():
        for _ in range(n):
            steps, tests = rng.uniform(3, 40), rng.uniform(2, 20)
            pts.append({"scene": "s", "kind": kind, "steps": steps, "tests": tests,
                        "s_per_ray": (c0 + cs * steps + ct * tests) * 1e-9})
    return pts


def test_fit_recovers_each_kinds_ratio_and_eq4():
    """c_test / c_step = 0.5 (random) and 2 (camera): each comes back, T_i/T_s is their geometric
    mean (1) and the grid has M* / N = 2 T_i/T_s = 2 cells per triangle, whatever the set-up costs."""
    fit = fit_grid_density(_points({"random": (30.0, 10.0, 5.0), "camera": (7.0, 4.0, 8.0)}))
    assert fit.ratios_["random"] == pytest.approx(0.5, rel=1e-6) and fit.ratios_["camera"] == pytest.approx(2.0, rel=1e-6)
    assert fit.ti_over_ts_ == pytest.approx(1.0, rel=1e-6) and fit.factor_ == pytest.approx(2.0, rel=1e-6)
    assert not fit.fallback_ and not fit.clipped_ and fit.note() == ""
    s = fit.summary()
    assert s["random_c_step_ns"] == pytest.approx(10.0, rel=1e-6) and s["camera_c_test_ns"] == pytest.approx(8.0, rel=1e-6)
    assert s["paper_ti_over_ts"] == float(PAPER_TI_OVER_TS) and s["scenes"] == ["s"]
    # the paper's own ratio gives its 8N
    assert fit_grid_density(_points({"random": (0.0, 1.0, float(PAPER_TI_OVER_TS))})).factor_ == pytest.approx(8.0, rel=1e-6)


def test_free_kind_is_left_out_and_all_free_falls_back():
    """Times that do not grow with the tests leave that kind out (named in the note); with no kind
    left, strict raises and the default keeps bench's 4N grid, saying so."""
    free = [{"scene": "s", "kind": "camera", "steps": st, "tests": te, "s_per_ray": (20 + 5 * st) * 1e-9}
            for st, te in ((10, 3), (20, 1), (30, 4), (40, 2))]
    mixed = GridDensityFit().fit(free + _points({"random": (10.0, 8.0, 2.0)}))
    assert mixed.free_.keys() == {"camera"} and mixed.factor_ == pytest.approx(0.5, rel=1e-6)
    assert "camera-ray fit left out: a test came out free" in mixed.note()
    with pytest.raises(GridcostError, match="came out free for every ray kind"):
        GridDensityFit(strict=True).fit(free)
    fb = GridDensityFit().fit(free)
    assert fb.fallback_ and fb.factor_ == 4.0 and np.isnan(fb.ti_over_ts_) and "NO ray kind fitted" in fb.note()


def test_factor_is_clipped_to_the_swept_range():
    """A ratio far outside what a grid can use (tests 1000x a step) gives the range's end, said."""
    fit = fit_grid_density(_points({"random": (5.0, 0.01, 10.0)}))
    assert fit.factor_ == FACTOR_RANGE[1] and fit.clipped_ and "clipped" in fit.note()


def test_unresolved_factor_is_a_clear_error():
    """bench resolves "fitted" before building; anything else non-numeric is refused at once."""
    for bad in ("fitted", True, [4.0]):
        with pytest.raises(GridcostError, match="must be a number"):
            UniformGrid(factor=bad)
    with pytest.raises(GridcostError, match="cell count must be a number"):
        UniformGrid(cells="many")
