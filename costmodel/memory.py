"""A cost model that knows the memory hierarchy: Ize 2007's grid equations with a step cost that
grows with the grid's working set, and the fit used to choose M with it.

Ize's Eq 1 and Eq 5 charge a constant T_step per cell. On a real machine a step loads the cell's
entry from a cell array of B = beta * M bytes; once B outgrows a cache level, a share of the loads
miss it. With a capacity model of the miss rate (a working set of B bytes accessed at random, a
level of C bytes: a share max(0, 1 - C/B) of the accesses miss it) the step cost becomes

    Ts(B) = Ts0 + sum_l Delta_l * max(0, 1 - C_l / B)                      (:func:`memory_eq_ts_of_b`)

with Delta_l the extra latency of the next level. Inside the band of M where the levels
l in S are outgrown this is Ts0 + Lambda - K / M with Lambda = sum_S Delta_l and
K = sum_S Delta_l C_l / beta, and sympy finds the optimum M in closed form
(:func:`memory_eq_one_level_optimum`, :func:`memory_eq_long_skinny_optimum`); as every C_l grows
past B (Lambda, K -> 0) both tend to the paper's Eq 4 and Eq 8 — checked symbolically.

The practical model (:class:`MemoryCostFit`) replaces the capacity formula by the latency curve
the host's pointer-chasing probe measured (:class:`tracer.measure.machine.MachineModel`), and Ize's ideal
counts by the tracer's counters:

    T_ray = Tsetup + Ts0 * steps + Ti * tests
            + kappa * (steps * x(B_cells) + occupied * x(B_data))

where x(B) is the measured load latency at working set B over an L1 hit, B_cells the cell array's
bytes, B_data the reference lists and triangles, ``occupied`` the visited cells holding a
reference, and kappa (one constant) the share of those loads that stall the ray (the rest hide
behind out-of-order execution or hit lines already loaded). With kappa = 0 it is the counter
model of :class:`costmodel.fit.CounterCostFit`.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import sympy as sp
from scipy.optimize import nnls

from costmodel.derive import N, Ti, Ts, M, m, ize_eq4_one_level_optimum, ize_eq8_long_skinny_optimum, same
from costmodel.fit import _metrics

B, beta, Ts0 = sp.symbols("B beta Ts0", positive=True)
C = sp.symbols("C1:4", positive=True)
Delta = sp.symbols("Delta1:4", positive=True)
Lam, K = sp.symbols("Lambda K", nonnegative=True)

#: bytes of one cell's entry in the one-level grid (int32 start offset) and of one occupancy bit
CELL_BYTES = 4.0 + 1.0 / 8.0


# ---------------------------------------------------------------- sympy: the equations
def memory_eq_ts_of_b() -> sp.Expr:
    """Ts(B) = Ts0 + sum_{l=1..3} Delta_l * max(0, 1 - C_l / B)   (capacity miss model, 3 cache levels)."""
    return Ts0 + sum(d * sp.Max(0, 1 - c / B) for d, c in zip(Delta, C))


def memory_eq_ts_in_band() -> sp.Expr:
    """Ts(M) inside a band where the outgrown levels S are fixed: Ts0 + Lambda - K / M, with
    B = beta M, Lambda = sum_S Delta_l and K = sum_S Delta_l C_l / beta."""
    return Ts0 + Lam - K / M


@lru_cache(maxsize=None)
def memory_eq_one_level_cost() -> sp.Expr:
    """Eq 1 with Ts(B):  T = Tsetup + m Ts(beta m^3) + (N / m^2) Ti."""
    from costmodel.derive import ize_eq1_one_level_cost
    return ize_eq1_one_level_cost().subs(Ts, memory_eq_ts_in_band().subs(M, m**3))


@lru_cache(maxsize=None)
def memory_eq_one_level_optimum() -> dict:
    """dT/dm = 0 of :func:`memory_eq_one_level_cost`:  M* = 2 (N Ti - K) / (Ts0 + Lambda).

    Returns {"M": M*, "limit_is_eq4": bool} — with Lambda = K = 0 (everything in cache) M* is Eq 4."""
    T = memory_eq_one_level_cost()
    sols = [s for s in sp.solve(sp.Eq(sp.diff(T, m), 0), m) if s.is_real is not False]
    Ms = sp.simplify(sols[0] ** 3)
    eq4 = ize_eq4_one_level_optimum().optimum
    return {"M": Ms, "limit_is_eq4": same(Ms.subs({Lam: 0, K: 0}), eq4.subs(Ts, Ts0)),
            "as_stated": same(Ms, 2 * (N * Ti - K) / (Ts0 + Lam))}


@lru_cache(maxsize=None)
def memory_eq_long_skinny_cost() -> sp.Expr:
    """Eq 5 with Ts(B):  T = Tsetup + m Ts(beta m^3) + (N / m) Ti."""
    from costmodel.derive import ize_eq5_long_skinny_cost
    return ize_eq5_long_skinny_cost().subs(Ts, memory_eq_ts_in_band().subs(M, m**3))


@lru_cache(maxsize=None)
def memory_eq_long_skinny_optimum() -> dict:
    """dT/dm = 0 of :func:`memory_eq_long_skinny_cost`: the cubic (Ts0 + Lambda) m^3 - N Ti m + 2K = 0.

    Its largest positive root is the optimum (sympy's closed form is Cardano's, kept as the cubic);
    with K = 0 the root is m^2 = N Ti / (Ts0 + Lambda), and with Lambda = 0 too, Eq 8."""
    T = memory_eq_long_skinny_cost()
    cubic = sp.expand(sp.diff(T, m) * m**3)
    stated = (Ts0 + Lam) * m**3 - N * Ti * m + 2 * K
    root0 = sp.solve(sp.Eq(cubic.subs(K, 0), 0), m)
    pos = [r for r in root0 if r.is_positive]
    eq8 = ize_eq8_long_skinny_optimum().optimum
    return {"cubic": cubic, "as_stated": same(cubic, stated),
            "M_K0": sp.simplify(pos[0] ** 3) if pos else None,
            "limit_is_eq8": bool(pos) and same(sp.expand_power_base((pos[0] ** 3).subs(Lam, 0), force=True),
                                               eq8.subs(Ts, Ts0))}


def long_skinny_optimum_numeric(N_, Ti_, Ts0_, Lam_, K_) -> float:  # noqa: N803
    """Largest positive root M = m^3 of the cubic of :func:`memory_eq_long_skinny_optimum`."""
    roots = np.roots([Ts0_ + Lam_, 0.0, -N_ * Ti_, 2.0 * K_])
    real = roots[np.abs(roots.imag) < 1e-9].real
    real = real[real > 0]
    return float(real.max() ** 3) if len(real) else float("nan")


# ---------------------------------------------------------------- the fitted model
def working_sets(cells, memory_bytes) -> tuple[np.ndarray, np.ndarray]:
    """(B_cells, B_data) bytes of one-level grids: the cell array, and the rest (references, triangles)."""
    bc = CELL_BYTES * (np.asarray(cells, float) + 1)
    return bc, np.maximum(np.asarray(memory_bytes, float) - bc, 0.0)


def memory_feature(machine, steps, occupied, cells, memory_bytes) -> np.ndarray:
    """steps * x(B_cells) + occupied * x(B_data) (ns): the loads of a ray priced at the latency their
    working set has over an L1 hit (:meth:`tracer.measure.machine.MachineModel.extra_ns`)."""
    bc, bd = working_sets(cells, memory_bytes)
    return np.asarray(steps, float) * machine.extra_ns(bc) + np.asarray(occupied, float) * machine.extra_ns(bd)


class MemoryCostFit:
    """T_ray = Tsetup[scene] + Ts0 steps + Ti tests + kappa * memory_feature, pooled over scenes
    (nnls on relative residuals). ``memory=False`` drops the kappa term (the counter model).

    Fitted: ``tsetup_`` (per scene), ``ts0_``, ``ti_``, ``kappa_``, ``coef_`` (the work terms'
    constants, in :meth:`_work_columns` order), ``metrics_``, ``n_constants_``."""

    def __init__(self, machine=None, memory: bool = True):
        self.machine, self.memory = machine, memory

    def _work_columns(self, frame) -> list:
        """The per-ray work terms (one column each; each gets one pooled non-negative constant)."""
        cols = [np.asarray(frame["steps"], float), np.asarray(frame["tests"], float)]
        cols.append(memory_feature(self.machine, frame["steps"], frame["occupied"], frame["cells"],
                                   frame["memory_bytes"]) if self.memory else np.zeros(len(cols[0])))
        return cols

    def _design(self, frame):
        cats = list(dict.fromkeys(frame["scene"]))
        work = self._work_columns(frame)
        X = np.zeros((len(work[0]), len(cats) + len(work)))
        sc = np.asarray(frame["scene"])
        for j, c in enumerate(cats):
            X[sc == c, j] = 1.0
        for j, col in enumerate(work):
            X[:, len(cats) + j] = col
        return X, cats

    def fit(self, frame, T):
        T = np.asarray(T, float)
        X, cats = self._design(frame)
        w = 1.0 / T
        coef, _ = nnls(X * w[:, None], T * w)
        self.scenes_ = cats
        self.tsetup_ = dict(zip(cats, (float(c) for c in coef[:len(cats)])))
        self.coef_ = coef[len(cats):].copy()
        self.ts0_, self.ti_, self.kappa_ = (float(v) for v in self.coef_[:3])
        self.n_constants_ = len(cats) + (3 if self.memory else 2)
        self.metrics_ = _metrics(T, X @ coef)
        return self

    def work(self, frame) -> np.ndarray:
        """Predicted time without Tsetup (ns per ray)."""
        return np.column_stack(self._work_columns(frame)) @ self.coef_

    def predict(self, frame, setup: float | None = None) -> np.ndarray:
        """Time per ray; ``setup`` defaults to the mean Tsetup of the training scenes."""
        s = float(np.mean(list(self.tsetup_.values()))) if setup is None else setup
        return s + self.work(frame)


#: where a scene's own calibration points sit: quantiles of log M over its swept range (wide apart,
#: so the steps and tests they count differ enough to separate Ts0 from Ti)
CALIBRATION_QUANTILES = (0.1, 0.5, 0.9)


def calibration_rows(frame, x: str = "cells", quantiles=CALIBRATION_QUANTILES):
    """The rows of one scene's sweep nearest the ``quantiles`` of log ``x`` over its range: the few
    timed points :class:`SceneCalibratedFit` is fitted to (duplicates of ``x`` dropped)."""
    g = frame.sort_values(x).drop_duplicates(x)
    lx = np.log(g[x].to_numpy(float))
    idx = sorted({int(np.argmin(np.abs(lx - (lx.min() + q * (lx.max() - lx.min()))))) for q in quantiles})
    return g.iloc[idx]


class SceneCalibratedFit(MemoryCostFit):
    """A pooled fit's memory term kept, the work constants refitted on a few of the scene's own points:

        T_ray = Tsetup_s + Ts0_s steps + Ti_s tests + kappa * memory_feature     (kappa from ``pooled``)

    A step and a test cost different amounts from scene to scene (table2's AIC asks for per-scene
    constants; room's marginal test costs about 4 ns against 11-13 ns on the scans), and no counter
    or working set of the other scenes has carried that over; three timed points of the scene do
    (:func:`calibration_rows`), a sixth of a sweep. ``kappa`` (the share of a load's
    latency that stalls a ray) stays the one fitted on the other scenes: three points cannot also
    separate it. Needs as many points with distinct counters as constants (3)."""

    def __init__(self, pooled: MemoryCostFit):
        super().__init__(pooled.machine, pooled.memory)
        self.pooled = pooled

    def fit(self, frame, T):
        T = np.asarray(T, float)
        steps, tests, mem = self._work_columns(frame)
        X = np.column_stack([np.ones(len(T)), steps, tests])
        if len(T) < X.shape[1] or np.linalg.matrix_rank(X) < X.shape[1]:
            raise ValueError(f"SceneCalibratedFit needs {X.shape[1]} points with distinct steps and tests, got "
                             f"{len(T)} of rank {np.linalg.matrix_rank(X)}")
        kappa = self.pooled.kappa_ if self.memory else 0.0
        w = 1.0 / T
        coef, _ = nnls(X * w[:, None], (T - kappa * mem) * w)
        self.scenes_ = list(dict.fromkeys(frame["scene"]))
        self.tsetup_ = {s: float(coef[0]) for s in self.scenes_}
        self.coef_ = np.array([coef[1], coef[2], kappa])
        self.ts0_, self.ti_, self.kappa_ = (float(v) for v in self.coef_)
        self.n_constants_ = 3
        self.metrics_ = _metrics(T, coef[0] + np.column_stack([steps, tests, mem]) @ self.coef_)
        return self


def entry_feature(machine, setups, cells, memory_bytes) -> np.ndarray:
    """setups * x(B_cells) (ns): the load of the cell a ray enters the grid by, at a random place in
    the cell array, priced at the latency of the array's working set over an L1 hit. A ray's later
    steps go to neighbouring cells and their loads overlap (the DDA does not wait for them), the
    first one is exposed; it is what makes ``teapot-x16-in-stadium`` twice as slow per ray as its
    grid grows from 4 to 40 MB while its step and test counts stay put."""
    return np.asarray(setups, float) * machine.extra_ns(working_sets(cells, memory_bytes)[0])


def refs_step_feature(steps, refs, n) -> np.ndarray:
    """steps * ln(refs / N): the step cost growing with the mean number of cells a triangle
    overlaps (the cells' size against the triangles'), found by cross-validation over the sweeps
    of ``predict`` (long skinny cylinders: Ts 8-15 ns; compact scans at the same M: 4-6 ns)."""
    return np.asarray(steps, float) * np.log(np.maximum(np.asarray(refs, float) / np.maximum(np.asarray(n, float), 1.0), 1.0))


class EntryRefsCostFit(MemoryCostFit):
    """The counter model with the entry-cell load and the refs-per-triangle step term:

        T_ray = Tsetup + Ts0 steps + Ti tests + kappa_e setups x(B_cells) + Ts_r steps ln(refs / N)

    (:func:`entry_feature`, :func:`refs_step_feature`). Fitted as :class:`MemoryCostFit`;
    ``kappa_`` is kappa_e and ``ts_refs_`` is Ts_r."""

    def __init__(self, machine=None):
        super().__init__(machine, memory=True)

    def _work_columns(self, frame) -> list:
        return [np.asarray(frame["steps"], float), np.asarray(frame["tests"], float),
                entry_feature(self.machine, frame["setups"], frame["cells"], frame["memory_bytes"]),
                refs_step_feature(frame["steps"], frame["refs"], frame["N"])]

    def fit(self, frame, T):
        super().fit(frame, T)
        self.ts_refs_ = float(self.coef_[3])
        self.n_constants_ = len(self.scenes_) + 4
        return self


def aic(T, pred, k: int) -> float:
    """AIC on relative residuals: n log(RSS/n) + 2k."""
    r = (np.asarray(pred, float) - np.asarray(T, float)) / np.asarray(T, float)
    n = len(r)
    return float(n * np.log(max((r**2).sum() / n, 1e-300)) + 2 * k)


def interpolate_counters(frame, x_new, x: str = "cells") -> dict:
    """The counters of a scene's swept grids, interpolated in log x - log counter to ``x_new`` (``x``:
    the swept parameter, "cells" for one-level grids, "param_m1" for nested ones). Counting is cheap
    and smooth in M; this places a model's optimum between swept points."""
    g = frame.sort_values(x).drop_duplicates(x)
    lx = np.log(g[x].to_numpy(float))
    out = {x: np.asarray(x_new, float)}
    for col in ("steps", "tests", "occupied", "memory_bytes", "cells", "refs", "setups"):
        if col != x and col in g:
            v = np.maximum(g[col].to_numpy(float), 1e-9)
            out[col] = np.exp(np.interp(np.log(out[x]), lx, np.log(v)))
    out["scene"] = np.full(len(out[x]), str(g["scene"].iloc[0]))
    if "N" in g:
        out["N"] = np.full(len(out[x]), float(g["N"].iloc[0]))
    return out


def model_optimum(fit, frame, x: str = "cells", points: int = 200) -> float:
    """The ``x`` (M, or M1) minimising ``fit``'s prediction over the swept range of one scene's grids."""
    lo, hi = float(frame[x].min()), float(frame[x].max())
    grid = np.geomspace(lo, hi, points)
    pred = fit.work(interpolate_counters(frame, grid, x))
    return float(grid[int(np.argmin(pred))])


class PaperCountFit(MemoryCostFit):
    """Ize's count model with the paper's ratio fixed: T_ray = Tsetup[scene] + b (steps + 4 tests);
    one shared constant b (the time of a step) besides the set-ups."""

    def __init__(self, ti_over_ts: float = 4.0):
        super().__init__(None, memory=False)
        self.ti_over_ts = ti_over_ts

    def _work_columns(self, frame) -> list:
        steps, tests, zero = super()._work_columns(frame)
        return [steps + self.ti_over_ts * tests, np.zeros_like(zero), zero]

    def fit(self, frame, T):
        super().fit(frame, T)
        self.n_constants_ = len(self.scenes_) + 1
        return self
