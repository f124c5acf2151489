"""The uniform grid's cell count for this machine: Ize, Shirley & Parker 2007's Eq 4,
M* = 2 N T_i / T_s, with T_i / T_s measured here instead of the paper's.

The paper's ratio makes M* = 8N (``gridcost table2``). What a cell step and a triangle test cost is a
property of the machine and the implementation, not of the method: this tracer tests a cell's
triangles four at a time in vector lanes (:mod:`tracer.accel.simd_tri`), so a test costs less than
a step and the best grid has fewer, fuller cells (``gridcost table2``'s swept best M lies near N
here). Bench's ``grid-fit`` is the grid at this M*:

* :class:`GridDensityFit` — per ray kind, T/ray = c_setup + c_step steps + c_test tests fitted to
  a grid measured at several densities (:data:`GRID_SETTINGS`: steps and tests move in opposite
  directions as the cells shrink, so the two costs separate), T_i / T_s the geometric mean of the
  kinds' c_test / c_step, and ``factor_`` = M* / N from :func:`costmodel.derive.one_level_optimal_M`.
* :func:`fit_grid_density` — the fitted estimator from measured points
  (:func:`experiments.core.probes.measure_grid_density` measures them; nothing here times).
"""
from __future__ import annotations

import numpy as np

from costmodel.derive import PAPER_TI_OVER_TS, one_level_optimal_M
from costmodel.kdcost import BVH_CALIBRATION, kind_costs

#: the densities measured (cells = factor N), in the vector-lane layout the bench meshes' grids use
#: (for small meshes "auto" may take the index layout, whose tests cost more: it would mix two costs)
GRID_SETTINGS = tuple({"factor": f, "layout": "blocks"} for f in (0.5, 2.0, 8.0))
#: calibration meshes: the BVH's (shipped, none of them a bench mesh)
GRID_CALIBRATION = BVH_CALIBRATION
#: the cells per triangle the fit may choose, table2's sweep range (N/8 ... 64N): outside it, a
#: ratio this far from 1 is a fit gone wrong, not a grid anyone should build
FACTOR_RANGE = (0.125, 64.0)
#: cells per triangle when no ray kind separates a step from a test: bench's plain "grid" (4N)
DEFAULT_FACTOR = 4.0


class GridDensityFit:
    """M* / N = 2 T_i / T_s (Ize 2007 Eq 4) with T_i / T_s fitted per ray kind on measured grid points
    (:func:`costmodel.kdcost.kind_costs`, with an intercept: a ray's set-up does not move with the
    density). A kind whose fit leaves a step or a test free is left out (``free_``); when every kind
    is, ``factor_`` is ``default`` and ``fallback_`` True (``strict``: raise instead). Fitted:
    ``c_step_``, ``c_test_``, ``mape_``, ``ratios_`` (dicts by kind, ns and c_test / c_step),
    ``free_``, ``fallback_``, ``ti_over_ts_`` (nan on fallback), ``factor_`` (clipped to
    :data:`FACTOR_RANGE`; ``clipped_`` says whether it was)."""

    def __init__(self, default: float = DEFAULT_FACTOR, strict: bool = False):
        self.default, self.strict = default, strict

    def fit(self, points):
        self.points_ = list(points)
        self.c_step_, self.c_test_, self.mape_, self.free_ = kind_costs(self.points_, "steps", intercept=True)
        self.ratios_ = {k: self.c_test_[k] / self.c_step_[k] for k in self.c_step_}
        self.fallback_ = not self.ratios_
        if self.fallback_ and self.strict:
            from tracer.errors import GridcostError
            raise GridcostError("grid density fit: a step or a test came out free for every ray kind; "
                                "calibrate on more or larger meshes, or on a quieter machine")
        self.clipped_ = False
        if self.fallback_:
            self.ti_over_ts_, self.factor_ = float("nan"), float(self.default)
        else:
            self.ti_over_ts_ = float(np.exp(np.mean(np.log(list(self.ratios_.values())))))
            raw = float(one_level_optimal_M(1.0, 1.0, self.ti_over_ts_))  # M* / N with T_s = 1
            self.factor_ = float(np.clip(raw, *FACTOR_RANGE))
            self.clipped_ = self.factor_ != raw
        return self

    def note(self) -> str:
        """The kinds left out and why, a clipped factor, the fallback ("" when nothing of that)."""
        parts = [f"the {k}-ray fit left out: a {'test' if ct <= cs else 'step'} came out free "
                 f"(c_step {cs:.3g}, c_test {ct:.3g} ns)" for k, (cs, ct) in self.free_.items()]
        if self.clipped_:
            parts.append(f"2 T_i/T_s = {2 * self.ti_over_ts_:.3g} lies outside {FACTOR_RANGE}: clipped to {self.factor_:g}")
        if self.fallback_:
            parts.append(f"NO ray kind fitted, so the grid has the default {self.factor_:g}N cells, not a "
                         "measurement of this host")
        return "; ".join(parts)

    def summary(self) -> dict:
        return {"factor": self.factor_, "ti_over_ts": self.ti_over_ts_, "paper_ti_over_ts": float(PAPER_TI_OVER_TS),
                "points": len(self.points_), "scenes": sorted({p["scene"] for p in self.points_}),
                "kinds_left_out": sorted(self.free_), "fallback": self.fallback_, "clipped": self.clipped_,
                **{f"{k}_{name}": d[k] for k in self.ratios_
                   for name, d in (("c_step_ns", self.c_step_), ("c_test_ns", self.c_test_), ("ratio", self.ratios_),
                                   ("mape", self.mape_))}}


def fit_grid_density(points, strict: bool = False) -> GridDensityFit:
    """Fit :class:`GridDensityFit` to a grid's measured ``points`` (per scene, ray kind and density:
    mean "steps" and "tests" per ray and "s_per_ray")."""
    return GridDensityFit(strict=strict).fit(points)
