"""Least-squares fits of the Ize 2007 cost constants to tracer measurements (scikit-learn style:
parameters in ``__init__``, ``fit`` returns self, fitted attributes end with ``_``).

* :class:`GridCostFit` — one scene's resolution sweep: T(M) = Tsetup + m Ts + (N/m^2) Ti (Eq 1,
  ``form='compact'``) or T = Tsetup + m Ts + (N/m) Ti (Eq 5, ``form='skinny'``), non-negative least
  squares (scipy.optimize.nnls), R^2, MAPE, bootstrap 95 % intervals, condition number, and the
  predicted optimum M.
* :class:`CounterCostFit` — time per ray against the tracer's counters,
  T = Tsetup_s + Ts steps + Ti tests, pooled over scenes (one Ts, Ti; one Tsetup per scene).
* :class:`ExponentFit` — M_best ∝ N^alpha by log-log regression with a bootstrap CI.
* :func:`refine_minimum` — the best M of a sweep: the measured minimum refined by a parabola in log M.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar, nnls

from costmodel.derive import long_skinny_time, one_level_time
from tracer.accel.constants import IZE_TI_OVER_TS

N_BOOT = 400


def _design_one_level(M, N, form, setup=True):
    m = np.cbrt(np.asarray(M, float))
    N = np.broadcast_to(np.asarray(N, float), m.shape)
    term = N / m**2 if form == "compact" else N / m
    cols = [np.ones_like(m), m, term] if setup else [np.zeros_like(m), m, term]
    return np.column_stack(cols)


def leave_one_out(names):
    """``(name, the other names)`` for each of ``names`` (in order, duplicates once)."""
    names = list(dict.fromkeys(names))
    for name in names:
        yield name, [n for n in names if n != name]


def leave_one_scene_out(df, column: str = "scene", scenes=None):
    """The one leave-one-scene-out split of gridcost (predict, the selector's errors, the packet
    model's scores): ``(scene, train, test)`` for each scene of ``df[column]`` (in order of first
    appearance, or those of ``scenes``): ``test`` is that scene's rows, ``train`` every other scene's
    (empty when ``df`` holds one scene only)."""
    for name, _ in leave_one_out(df[column] if scenes is None else scenes):
        held = df[column] == name
        yield name, df[~held], df[held]


def _metrics(y, yhat) -> dict:
    """R², mean and maximum absolute percentage error of ``yhat`` against ``y`` (shared by every fit)."""
    y, yhat = np.asarray(y, float), np.asarray(yhat, float)
    ss_res = float(((y - yhat) ** 2).sum())
    ss_tot = float(((y - y.mean()) ** 2).sum())
    ape = np.abs(yhat - y) / np.abs(y)
    return {"r2": 1 - ss_res / ss_tot if ss_tot > 0 else float("nan"),
            "mape": float(np.mean(ape)) * 100, "max_ape": float(np.max(ape)) * 100}


def _ci(samples, level=0.95):
    samples = np.asarray(samples, float)
    if samples.size == 0 or np.isnan(samples).all():
        return np.nan, np.nan
    lo, hi = np.nanpercentile(samples, [50 * (1 - level), 50 * (1 + level)], axis=0)
    return lo, hi


class GridCostFit:
    """Fit Tsetup, Ts, Ti of Eq 1 (``form='compact'``) or Eq 5 (``form='skinny'``) to (M, T) of one
    scene with N primitives. T is any time unit (we use ns per ray)."""

    def __init__(self, form: str = "compact", setup: bool = True, n_boot: int = N_BOOT, seed: int = 0):
        self.form, self.setup, self.n_boot, self.seed = form, setup, n_boot, seed

    @property
    def n_constants(self) -> int:
        return 3 if self.setup else 2

    def fit(self, M, T, N):
        M, T = np.asarray(M, float), np.asarray(T, float)
        X = _design_one_level(M, N, self.form, self.setup)
        # relative least squares: weight rows by 1/T so every point of the log-spaced sweep counts
        w = 1.0 / T
        coef, _ = nnls(X * w[:, None], T * w)
        self.N_ = float(N)
        self.coef_ = coef
        self.tsetup_, self.ts_, self.ti_ = (float(c) for c in coef)
        Xw = (X * w[:, None])[:, 0 if self.setup else 1:]
        self.cond_ = float(np.linalg.cond(Xw / np.linalg.norm(Xw, axis=0)))
        resid = (T - X @ coef) / T
        self.rss_ = float((resid**2).sum())
        self.aic_ = len(T) * np.log(max(self.rss_, 1e-300) / len(T)) + 2 * self.n_constants
        self.metrics_ = _metrics(T, X @ coef)
        rng = np.random.default_rng(self.seed)
        boots = []
        for _ in range(self.n_boot):
            idx = rng.integers(0, len(T), len(T))
            if len(np.unique(idx)) < 3:
                continue
            c, _ = nnls(X[idx] * w[idx, None], T[idx] * w[idx])
            boots.append(c)
        boots = np.array(boots) if boots else np.full((1, 3), np.nan)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = boots[:, 2] / boots[:, 1]
        self.ci_ = {name: tuple(float(v) for v in _ci(boots[:, i]))
                    for i, name in enumerate(("tsetup", "ts", "ti"))}
        self.ci_["ti_over_ts"] = tuple(float(v) for v in _ci(ratio[np.isfinite(ratio)] if np.isfinite(ratio).any() else ratio))
        return self

    @property
    def ti_over_ts_(self) -> float:
        return self.ti_ / self.ts_ if self.ts_ > 0 else float("inf")

    def predict(self, M):
        fn = one_level_time if self.form == "compact" else long_skinny_time
        return fn(np.asarray(M, float), self.N_, self.tsetup_, self.ts_, self.ti_)

    def optimum(self) -> float:
        """The M minimising the fitted curve: 2 N Ti/Ts (Eq 4) or (N Ti/Ts)^1.5 (Eq 8)."""
        r = self.ti_over_ts_
        return 2 * self.N_ * r if self.form == "compact" else (self.N_ * r) ** 1.5

    def known(self, name: str) -> bool:
        """A constant is 'known' only when its bootstrap CI excludes zero."""
        lo, hi = self.ci_[name]
        return bool(lo > 0 or hi < 0)


class CounterCostFit:
    """T_ray = Tsetup[scene] + Ts * steps + Ti * tests, pooled over scenes (nnls, bootstrap CIs)."""

    def __init__(self, n_boot: int = N_BOOT, seed: int = 0):
        self.n_boot, self.seed = n_boot, seed

    def _design(self, scenes, steps, tests):
        cats = list(dict.fromkeys(scenes))
        X = np.zeros((len(scenes), len(cats) + 2))
        for j, c in enumerate(cats):
            X[np.asarray(scenes) == c, j] = 1.0
        X[:, -2] = steps
        X[:, -1] = tests
        return X, cats

    def fit(self, scenes, steps, tests, T):
        T = np.asarray(T, float)
        X, cats = self._design(scenes, np.asarray(steps, float), np.asarray(tests, float))
        w = 1.0 / T
        coef, _ = nnls(X * w[:, None], T * w)
        self.scenes_ = cats
        self.tsetup_ = dict(zip(cats, (float(c) for c in coef[:-2])))
        self.ts_, self.ti_ = float(coef[-2]), float(coef[-1])
        self.coef_ = coef
        Xw = X * w[:, None]
        self.cond_ = float(np.linalg.cond(Xw / np.linalg.norm(Xw, axis=0)))
        self.metrics_ = _metrics(T, X @ coef)
        rng = np.random.default_rng(self.seed)
        boots = []
        for _ in range(self.n_boot):
            idx = rng.integers(0, len(T), len(T))
            c, _ = nnls(X[idx] * w[idx, None], T[idx] * w[idx])
            boots.append(c[-2:])
        boots = np.array(boots) if boots else np.full((1, 2), np.nan)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = boots[:, 1] / boots[:, 0]
        self.ci_ = {"ts": tuple(float(v) for v in _ci(boots[:, 0])),
                    "ti": tuple(float(v) for v in _ci(boots[:, 1])),
                    "ti_over_ts": tuple(float(v) for v in _ci(ratio[np.isfinite(ratio)]))}
        return self

    @property
    def ti_over_ts_(self) -> float:
        return self.ti_ / self.ts_ if self.ts_ > 0 else float("inf")

    def predict(self, scenes, steps, tests):
        X, _ = self._design(scenes, np.asarray(steps, float), np.asarray(tests, float))
        coef = np.concatenate([[self.tsetup_.get(c, np.mean(list(self.tsetup_.values()))) for c in dict.fromkeys(scenes)],
                               [self.ts_, self.ti_]])
        return X @ coef


#: an exponent's CI is reported only from this many distinct scenes spanning this many decades of N: a
#: bootstrap over 3-4 points resamples the same few scenes and gives intervals of zero width
EXPONENT_MIN_SCENES = 6
EXPONENT_MIN_DECADES = 2.0


class ExponentFit:
    """y ∝ x^alpha by least squares on logs; bootstrap 95 % CI of alpha. ``determined_`` is False
    (and every report prints "not determined" instead of the CI) when the points are fewer than
    :data:`EXPONENT_MIN_SCENES` distinct x, span less than :data:`EXPONENT_MIN_DECADES` decades, or
    the bootstrap interval is degenerate (not finite or of zero width)."""

    def __init__(self, n_boot: int = 2000, seed: int = 0):
        self.n_boot, self.seed = n_boot, seed

    def fit(self, x, y):
        lx, ly = np.log(np.asarray(x, float)), np.log(np.asarray(y, float))
        self.alpha_, self.log_c_ = (float(v) for v in np.polyfit(lx, ly, 1))
        rng = np.random.default_rng(self.seed)
        boots = []
        for _ in range(self.n_boot):
            idx = rng.integers(0, len(lx), len(lx))
            if np.ptp(lx[idx]) == 0:
                continue
            boots.append(np.polyfit(lx[idx], ly[idx], 1)[0])
        self.ci_ = tuple(float(v) for v in _ci(np.array(boots))) if boots else (float("nan"),) * 2
        resid = ly - (self.alpha_ * lx + self.log_c_)
        dof = max(len(lx) - 2, 1)
        se = np.sqrt((resid**2).sum() / dof / max(((lx - lx.mean()) ** 2).sum(), 1e-300))
        self.se_ = float(se)
        self.n_points_ = int(len(np.unique(lx)))
        self.decades_ = float(np.ptp(lx) / np.log(10.0)) if len(lx) else 0.0
        lo, hi = self.ci_
        self.determined_ = bool(self.n_points_ >= EXPONENT_MIN_SCENES and self.decades_ >= EXPONENT_MIN_DECADES
                                and np.isfinite(lo) and np.isfinite(hi) and hi - lo > 1e-6)
        return self

    def ci_text(self, fmt: str = "{:.2f}") -> str:
        """The CI as printed: "lo–hi", or why it is not determined."""
        if self.determined_:
            return f"{fmt.format(self.ci_[0])}–{fmt.format(self.ci_[1])}"
        return f"not determined ({self.n_points_} scenes over {self.decades_:.1f} decades of N)"

    def predict(self, x):
        return np.exp(self.log_c_) * np.asarray(x, float) ** self.alpha_


def work_cost(steps, tests, ti_over_ts: float = IZE_TI_OVER_TS):
    """Ize's cost in units of Ts from the tracer's counters: steps + (Ti/Ts) tests. Deterministic
    (no timing noise), so exponents of its optimum test the theory's counting argument alone."""
    return np.asarray(steps, float) + ti_over_ts * np.asarray(tests, float)


def refine_minimum(M, T) -> float:
    """Best M of a sweep: the measured minimum, refined by a parabola in (log M, log T) through it
    and its neighbours (kept inside the bracket)."""
    M, T = np.asarray(M, float), np.asarray(T, float)
    order = np.argsort(M)
    M, T = M[order], T[order]
    i = int(np.argmin(T))
    lo, hi = max(0, i - 2), min(len(M), i + 3)
    if hi - lo < 3:
        return float(M[i])
    x, y = np.log(M[lo:hi]), np.log(T[lo:hi])
    a, b, c = np.polyfit(x, y, 2)
    if a <= 0:
        return float(M[i])
    res = minimize_scalar(lambda z: a * z * z + b * z + c, bounds=(x[max(0, i - lo - 1)], x[min(hi - lo - 1, i - lo + 1)]),
                          method="bounded")
    return float(np.exp(res.x))


#: candidate one-level models for selection: (form, with Tsetup)
CANDIDATES = {"eq1": ("compact", True), "eq1-no-setup": ("compact", False),
              "eq5": ("skinny", True), "eq5-no-setup": ("skinny", False)}


def cv_mape(form, setup, M, T, N, k: int = 5, seed: int = 0) -> float:
    """k-fold cross-validated MAPE (%) of a one-level model on one sweep."""
    M, T = np.asarray(M, float), np.asarray(T, float)
    idx = np.random.default_rng(seed).permutation(len(T))
    errs = []
    for fold in np.array_split(idx, min(k, len(T))):
        train = np.setdiff1d(idx, fold)
        if len(train) < 3:
            continue
        g = GridCostFit(form, setup, n_boot=0).fit(M[train], T[train], N)
        errs.append(np.abs(g.predict(M[fold]) - T[fold]) / T[fold])
    return float(np.mean(np.concatenate(errs))) * 100 if errs else float("nan")


def select_model(M, T, N, candidates=CANDIDATES, tolerance_pct: float = 1.0) -> dict:
    """Fit every candidate, score by 5-fold CV MAPE and AIC, and choose the simplest (fewest
    constants, then lowest AIC) whose CV error is within ``tolerance_pct`` points of the best."""
    rows = []
    for name, (form, setup) in candidates.items():
        g = GridCostFit(form, setup, n_boot=0).fit(M, T, N)
        rows.append({"model": name, "form": form, "constants": g.n_constants, "aic": g.aic_,
                     "mape_pct": g.metrics_["mape"], "cv_mape_pct": cv_mape(form, setup, M, T, N),
                     "r2": g.metrics_["r2"], "m_pred": g.optimum()})
    best = min(r["cv_mape_pct"] for r in rows)
    ok = [r for r in rows if r["cv_mape_pct"] <= best + tolerance_pct]
    chosen = min(ok, key=lambda r: (r["constants"], r["aic"]))
    why = (f"{chosen['model']}: CV MAPE {chosen['cv_mape_pct']:.1f} % within {tolerance_pct} points of the best "
           f"({best:.1f} %) with the fewest constants ({chosen['constants']})")
    return {"chosen": chosen["model"], "why": why, "candidates": rows}


def pooling_evidence(scenes, steps, tests, T) -> dict:
    """Does one (Ts, Ti) pair serve every scene, or does each scene need its own? Fits both
    (pooled: per-scene Tsetup + one Ts, Ti; per-scene: Tsetup, Ts, Ti for each scene) by the same
    relative least squares and compares AIC = n log(RSS/n) + 2k on the relative residuals (lower
    is better; per-scene constants only on strong evidence, an AIC lower by more than 10). Returns
    the AICs, parameter counts, the per-scene fits (name -> CounterCostFit) and the verdict
    ``per_scene`` (bool)."""
    scenes = np.asarray(scenes)
    steps, tests, T = (np.asarray(v, float) for v in (steps, tests, T))
    pooled = CounterCostFit(n_boot=0).fit(scenes.tolist(), steps, tests, T)
    rel_p = (pooled.predict(scenes.tolist(), steps, tests) - T) / T
    per, rel_s = {}, np.empty_like(T)
    for s in dict.fromkeys(scenes.tolist()):
        m = scenes == s
        per[s] = CounterCostFit().fit([s] * int(m.sum()), steps[m], tests[m], T[m])
        rel_s[m] = (per[s].predict([s] * int(m.sum()), steps[m], tests[m]) - T[m]) / T[m]
    n, S = len(T), len(per)
    aic = lambda rss, k: float(n * np.log(max(rss, 1e-300) / n) + 2 * k)  # noqa: E731
    a_p, a_s = aic(float(rel_p @ rel_p), S + 2), aic(float(rel_s @ rel_s), 3 * S)
    return {"aic_pooled": a_p, "aic_per_scene": a_s, "k_pooled": S + 2, "k_per_scene": 3 * S,
            "per_scene": a_s < a_p - 10.0, "fits": per}


def counter_fits(df) -> tuple:
    """(pooled :class:`CounterCostFit`, :func:`pooling_evidence`, scene -> its own Ti/Ts) of the
    random-ray rows of a one-level sweep (table2, table3)."""
    rnd = df[df.ray_kind == "random"]
    cfit = CounterCostFit().fit(rnd.scene.tolist(), rnd.steps, rnd.tests, rnd.anchored_ns_per_ray)
    pool = pooling_evidence(rnd.scene.tolist(), rnd.steps, rnd.tests, rnd.anchored_ns_per_ray)
    return cfit, pool, {s: f.ti_over_ts_ for s, f in pool["fits"].items()}
