"""The kd-tree's SAH constants measured on this machine: the kd-tree's time per ray fitted to its
own counters, and the fitted ratio used as the build's isect:trav constant ("the cost model
calibrating the structure it predicts").

* :func:`kd_time_per_ray` — the model, T/ray = c_node nodes + c_leaf leaves + c_test tests + c_0.
* :class:`KdCostFit` — non-negative least squares of that model (scikit-learn style), with
  ``ti_over_tt_`` = c_test / c_node, the SAH's C_isect / C_trav.
* :func:`fit_sah_constants` — the fitted estimator for ``build(scene, "kdtree", constants=fit)``
  from measured points: per (scene, ray kind, build setting), mean counters per ray and the median
  time per ray (:func:`experiments.core.probes.measure_kd_points` measures them; nothing here times).
* :func:`kind_costs` — per ray kind, a step's and a test's cost fitted apart (the BVH's fit below and
  the grid's density, :mod:`costmodel.griddensity`).
* :class:`BvhSahFit` / :func:`fit_bvh_trav_cost` — the same for the BVH's SAH: the binary BVH's time
  per ray fitted to its counters per ray kind, ``trav_cost_`` = C_trav / C_isect for
  ``build(scene, "bvh" | "bvh4", trav_cost=fit.trav_cost_)`` (pbrt-v2's setting is 1/8).
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from costmodel.fit import _metrics

#: build settings measured by default: trees of different shapes (depth, clipping) so the node,
#: leaf and test counts vary independently enough to separate their costs
DEFAULT_SETTINGS = ({}, {"max_depth": 16}, {"clip": True}, {"clip": True, "max_depth": 40},
                    {"isect_cost": 5.0, "clip": True, "max_depth": 40})
COLUMNS = ("nodes", "leaves", "tests")


def relative_nnls(A, y) -> np.ndarray:
    """Non-negative least squares of ``A @ c = y`` on relative residuals (each row divided by its
    ``y``), so a slow point weighs no more than a fast one: the fit of :class:`BvhSahFit` and
    :class:`WorkCostFit`."""
    return nnls(np.asarray(A, float) / np.asarray(y, float)[:, None], np.ones(len(y)))[0]


def kd_time_per_ray(nodes, leaves, tests, c_node, c_leaf, c_test, c_0=0.0):
    """Kd-tree traversal cost per ray: T = c_node * nodes + c_leaf * leaves + c_test * tests + c_0,
    nodes / leaves / tests the per-ray means of the ``nodes``, ``steps`` and ``tests`` counters."""
    return (c_node * np.asarray(nodes, float) + c_leaf * np.asarray(leaves, float)
            + c_test * np.asarray(tests, float) + c_0)


class KdCostFit:
    """Fit :func:`kd_time_per_ray` (non-negative constants; relative residuals, weights 1/T) to
    points X = (nodes, leaves, tests) per ray, y = seconds (any unit) per ray."""

    def __init__(self, intercept: bool = True):
        self.intercept = intercept

    def _design(self, X):
        X = np.asarray(X, float).reshape(-1, 3)
        return np.column_stack([X, np.ones(len(X)) if self.intercept else np.zeros(len(X))])

    def fit(self, X, y):
        y = np.asarray(y, float)
        A = self._design(X)
        w = 1.0 / y
        coef, _ = nnls(A * w[:, None], y * w)
        self.c_node_, self.c_leaf_, self.c_test_, self.c_0_ = (float(c) for c in coef)
        self.coef_ = coef
        Aw = A[:, :3] * w[:, None]
        self.cond_ = float(np.linalg.cond(Aw / np.linalg.norm(Aw, axis=0)))
        self.metrics_ = _metrics(y, A @ coef)
        self.n_points_ = len(y)
        return self

    @property
    def ti_over_tt_(self) -> float:
        """C_isect / C_trav of the SAH: the fitted cost of a triangle test over that of a node visit."""
        return self.c_test_ / self.c_node_ if self.c_node_ > 0 else float("inf")

    def predict(self, X):
        return self._design(X) @ self.coef_

    def summary(self) -> dict:
        return {"c_node": self.c_node_, "c_leaf": self.c_leaf_, "c_test": self.c_test_, "c_0": self.c_0_,
                "ti_over_tt": self.ti_over_tt_, "cond": self.cond_, "points": self.n_points_, **self.metrics_}


def fit_sah_constants(points) -> KdCostFit:
    """Fit :class:`KdCostFit` to measured ``points`` (:func:`experiments.core.probes.measure_kd_points`);
    the estimator's ``ti_over_tt_`` is the isect:trav constant for ``build(scene, "kdtree",
    constants=...)``. The points are kept in ``points_``."""
    pts = list(points)
    X = np.array([[p[c] for c in COLUMNS] for p in pts])
    y = np.array([p["s_per_ray"] for p in pts]) * 1e9  # ns per ray
    fit = KdCostFit().fit(X, y)
    fit.points_ = pts
    return fit


#: binary-BVH build settings measured by default: trees of different shapes (the SAH's traversal
#: weight, leaf sizes) so node and test counts vary independently
BVH_SETTINGS = ({}, {"trav_cost": 0.5}, {"trav_cost": 2.0}, {"max_leaf": 1}, {"max_leaf": 8, "trav_cost": 1.0})
#: calibration meshes of :func:`fit_bvh_trav_cost`: two small scans and the teapot, all shipped in
#: tracer/data (a fresh clone offline fits on the real meshes, not stand-ins), none of the meshes
#: bench reports on (so its ratios are measured on meshes the fit never saw)
BVH_CALIBRATION = ("bunny-16k", "dragon-11k", "teapot")


def kind_costs(points, step: str, intercept: bool) -> tuple[dict, dict, dict, dict]:
    """Per ray kind, the time per ray fitted as [c_0 +] c_step x ``p[step]`` + c_test x ``p["tests"]``
    (:func:`relative_nnls`) over that kind's ``points`` (dicts with "kind", the two counters and
    "s_per_ray"). Returns ({kind: c_step}, {kind: c_test}, {kind: MAPE %}) of the kinds whose fit
    separated the two costs, in ns, and {kind: (c_step, c_test)} of those it did not: a cost a
    millionth of the other's is none, and a ratio of the two would be 0 or infinite."""
    c_step, c_test, mape, free = {}, {}, {}, {}
    for kind in dict.fromkeys(p["kind"] for p in points):
        pk = [p for p in points if p["kind"] == kind]
        A = np.array([[1.0] * intercept + [p[step], p["tests"]] for p in pk], float)
        y = np.array([p["s_per_ray"] for p in pk]) * 1e9
        coef = relative_nnls(A, y)
        cs, ct = float(coef[-2]), float(coef[-1])
        if not (cs > 1e-6 * ct and ct > 1e-6 * cs):
            free[kind] = (cs, ct)
            continue
        c_step[kind], c_test[kind], mape[kind] = cs, ct, _metrics(y, A @ coef)["mape"]
    return c_step, c_test, mape, free


class BvhSahFit:
    """The BVH's SAH traversal weight measured on this machine. Per ray kind, T/ray = c_node nodes +
    c_test tests (non-negative least squares on relative residuals; no intercept and no leaf term:
    on one or three calibration meshes those made the fit collinear, a node or a test coming out
    free, while the two-term fit stays within 1-8 % MAPE); a coherent kind (camera) pays less per node
    than an incoherent one (random), so the kinds are fitted apart and ``trav_cost_`` = C_trav /
    C_isect is the geometric mean of their c_node / c_test (the SAH needs only the ratio). A kind
    whose fit leaves a node or a test free (noisy timings: seen for camera rays on a busy cloud VM)
    is left out of the mean and named in ``free_`` and :meth:`note`. When every kind does (seen for
    both kinds of ``advise --quick``'s 10,000-ray points on a noisy cloud VM), the timings cannot
    separate the two costs at all: ``trav_cost_`` is then ``default`` (None: the tracer's build
    default, pbrt-v2's 1/8), ``fallback_`` is True and :meth:`note` says so; ``strict=True`` raises
    instead. Fitted: ``c_node_``, ``c_test_``, ``mape_``, ``ratios_`` (dicts by kind), ``free_``
    (kind -> (c_node, c_test) of the kinds left out), ``fallback_``, ``trav_cost_``."""

    def __init__(self, default: float | None = None, strict: bool = False):
        self.default, self.strict = default, strict

    def fit(self, points):
        self.c_node_, self.c_test_, self.mape_, self.free_ = kind_costs(points, "nodes", intercept=False)
        self.ratios_ = {k: self.c_node_[k] / self.c_test_[k] for k in self.c_node_}
        self.fallback_ = not self.ratios_
        if self.fallback_ and self.strict:
            from tracer.errors import GridcostError
            raise GridcostError("BVH cost fit: a node or a test came out free for every ray kind ("
                                + "; ".join(f"{k} rays: c_node {cn:.3g}, c_test {ct:.3g} ns" for k, (cn, ct) in self.free_.items())
                                + "); calibrate on more or larger meshes, or on a quieter machine")
        if self.fallback_:
            from tracer.accel.bvh import BVH_TRAV_COST
            self.trav_cost_ = float(BVH_TRAV_COST if self.default is None else self.default)
        else:
            self.trav_cost_ = float(np.exp(np.mean(np.log(list(self.ratios_.values())))))
        self.points_ = points
        return self

    def note(self) -> str:
        """The kinds left out of the weight and why, and the fallback when every kind was ("" when
        every kind fitted)."""
        parts = [f"the {k}-ray fit left out: a {'test' if ct <= cn else 'node'} came out free "
                 f"(c_node {cn:.3g}, c_test {ct:.3g} ns; timings this noisy cannot separate the two)"
                 for k, (cn, ct) in self.free_.items()]
        if self.fallback_:
            parts.append(f"NO ray kind fitted, so the weight is the tracer's default {self.trav_cost_:.3g} "
                         "(pbrt-v2), not a measurement of this host; calibrate on a quieter machine")
        return "; ".join(parts)

    def summary(self) -> dict:
        return {"trav_cost": self.trav_cost_, "points": len(self.points_),
                "scenes": sorted({p["scene"] for p in self.points_}), "kinds_left_out": sorted(self.free_),
                "fallback": self.fallback_,
                **{f"{k}_{name}": d[k] for k in self.ratios_
                   for name, d in (("c_node_ns", self.c_node_), ("c_test_ns", self.c_test_), ("ratio", self.ratios_),
                                   ("mape", self.mape_))}}


def fit_bvh_trav_cost(points, strict: bool = False) -> BvhSahFit:
    """Fit :class:`BvhSahFit` to the binary BVH's measured ``points``
    (:func:`experiments.core.probes.measure_kd_points` with ``structure="bvh"`` and
    :data:`BVH_SETTINGS` on :data:`BVH_CALIBRATION`); ``strict``: raise rather than fall back to the
    default weight when no ray kind fits."""
    return BvhSahFit(strict=strict).fit(list(points))


class WorkCostFit:
    """Where a structure's time per ray goes: T/ray = c_ray + c_step steps + c_test tests, non-negative
    least squares on relative residuals (weights 1/T), over groups of rays that differ in counted work
    (``experiments.tools.bench`` times them). ``steps`` is the structure's traversal unit: nodes
    visited for a tree, cells for a grid. Fitted: ``c_ray_``, ``c_step_``, ``c_test_`` (in the unit of
    ``y``, ns), ``mape_``, ``r2_``."""

    def fit(self, X, y):
        X = np.asarray(X, float).reshape(-1, 2)
        y = np.asarray(y, float)
        A = np.column_stack([np.ones(len(X)), X])
        coef = relative_nnls(A, y)
        self.c_ray_, self.c_step_, self.c_test_ = (float(c) for c in coef)
        self.coef_ = coef
        m = _metrics(y, A @ coef)
        self.mape_, self.r2_ = m["mape"], m.get("r2", float("nan"))
        return self

    def predict(self, X):
        return np.column_stack([np.ones(len(X)), np.asarray(X, float).reshape(-1, 2)]) @ self.coef_

    def summary(self) -> dict:
        return {"c_ray_ns": self.c_ray_, "c_step_ns": self.c_step_, "c_test_ns": self.c_test_, "mape": self.mape_,
                "r2": self.r2_}
