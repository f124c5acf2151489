"""Someone else's tracer priced by gridcost's counted work (``fit --timings``, ``advise --constants``).

The work a uniform grid does on a ray set is a property of the method and the grid's resolution:
gridcost counts it on the same grids (traversal set-ups, cells stepped, ray/triangle tests). What
one unit of that work costs is a property of the user's implementation and machine, so their time
per ray is fitted as

    T_ray = Tsetup * setups + Ts * steps + Ti * tests                       (Ize 2007, Eq 1's terms)

with the counters measured rather than modelled from M (Eq 1 assumes m^3 = M cubic cells and
N/m^2 tests; counted work holds for any mesh and any per-axis division). The fit is non-negative
least squares on relative errors (every resolution weighs alike, whatever its time), with bootstrap
95 % intervals of each constant, and leave-one-resolution-out errors that say how well the model
explains times it was not fitted on. No measuring here: the work and the times come in as data.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from costmodel.fit import N_BOOT, _ci, _metrics

#: the counters a grid's time per ray is fitted to, with the name of each one's unit cost
WORK_TERMS = {"setups": "tsetup", "steps": "ts", "tests": "ti"}


class WorkTimeFit:
    """T_ray = Σ_k c_k · work_k (non-negative c_k), fitted to measured times per ray.

    Parameters: ``terms`` (counter name -> constant name, :data:`WORK_TERMS`), ``n_boot`` bootstrap
    resamples, ``seed``. Fitted: ``coef_`` (constant name -> value, in the unit of ``T`` per unit of
    work), ``ci_`` (95 % bootstrap intervals), ``metrics_`` (R², MAPE on the fitted rows),
    ``loo_`` (leave-one-row-out relative errors, %), ``boot_`` (the bootstrap coefficient samples).
    """

    def __init__(self, terms: dict | None = None, n_boot: int = N_BOOT, seed: int = 0):
        self.terms = dict(terms or WORK_TERMS)
        self.n_boot, self.seed = n_boot, seed

    def _design(self, work) -> np.ndarray:
        return np.column_stack([np.asarray(work[k], float) for k in self.terms])

    @staticmethod
    def _solve(X, T):
        w = 1.0 / T
        coef, _ = nnls(X * w[:, None], T * w)
        return coef

    def fit(self, work, T):
        """``work``: counter name -> per-ray means, one per measured row; ``T``: time per ray of each row."""
        T = np.asarray(T, float)
        if len(T) < len(self.terms) or not (np.isfinite(T).all() and (T > 0).all()):
            raise ValueError(f"need at least {len(self.terms)} positive, finite times to fit "
                             f"{len(self.terms)} constants, got {len(T)}")
        X = self._design(work)
        c = self._solve(X, T)
        self.coef_ = dict(zip(self.terms.values(), (float(v) for v in c)))
        self.metrics_ = _metrics(T, X @ c)
        Xw = X / T[:, None]
        self.cond_ = float(np.linalg.cond(Xw / np.maximum(np.linalg.norm(Xw, axis=0), 1e-300)))
        loo = []
        for i in range(len(T)):
            keep = np.arange(len(T)) != i
            ci = self._solve(X[keep], T[keep])
            loo.append(100.0 * (X[i] @ ci - T[i]) / T[i])
        self.loo_ = np.asarray(loo)
        rng = np.random.default_rng(self.seed)
        boots = [self._solve(X[idx], T[idx]) for idx in (rng.integers(0, len(T), len(T)) for _ in range(self.n_boot))]
        self.boot_ = np.asarray(boots) if boots else c[None, :]
        self.ci_ = {name: tuple(float(v) for v in _ci(self.boot_[:, j])) for j, name in enumerate(self.terms.values())}
        return self

    def predict(self, work) -> np.ndarray:
        """Time per ray of each row of ``work`` (counter name -> per-ray means)."""
        return self._design(work) @ np.array(list(self.coef_.values()))

    def best(self, work) -> dict:
        """The row of ``work`` with the least predicted time, and how often each row is the best
        under the bootstrap samples of the constants (its stability): ``index``, ``predicted``
        (per row), ``share`` (per row, the fraction of resamples in which it is the fastest)."""
        X = self._design(work)
        pred = X @ np.array(list(self.coef_.values()))
        wins = np.bincount(np.argmin(X @ self.boot_.T, axis=0), minlength=len(X))
        return {"index": int(np.argmin(pred)), "predicted": pred, "share": wins / max(1, wins.sum())}

    def summary(self) -> dict:
        return {"constants": self.coef_, "ci": self.ci_, "r2": self.metrics_["r2"], "mape": self.metrics_["mape"],
                "max_ape": self.metrics_["max_ape"], "loo_mape": float(np.mean(np.abs(self.loo_))),
                "loo_max": float(np.max(np.abs(self.loo_))), "cond": self.cond_}
