"""Hapala, Karlik & Havran 2011, "When it makes sense to use uniform grids for ray tracing": the
critical number of rays R_C, the paper's calibration and 8-step decision algorithm, its estimator
(Eq 7, Eq 8), an improved estimator built on what gridcost knows, Havran's scene statistics (Eq 1-6)
and the paper's evaluation protocol (random calibration/evaluation splits, Err = 100 (R_est - R_C) / R_C).

Units: every time is in seconds (build times T_B, per-ray times t_R); R_C is a number of rays.
scikit-learn conventions: parameters in ``__init__``, ``fit`` returns self, fitted attributes end in ``_``.

Calibration records are a :class:`pandas.DataFrame` with one row per (scene, ray kind) and the
columns ``scene``, ``kind``, ``N``, ``T_BG``, ``t_RG`` (all rays), ``t_RG_sample`` (the
sampled rays, what the decision algorithm sees), ``T_BH``, ``t_RH``, the grid's sampled counters and
Havran statistics (:mod:`costmodel.havran`). ``experiments.hapala.lib.calibrate.calibrate_scene`` measures them
(calibration steps 1-4, with :func:`experiments.core.probes.probe_grid` for the decision's sample);
:func:`records` flattens its output. Nothing here builds or times: :mod:`experiments.core.probes` does.
"""
from __future__ import annotations


import numpy as np
import pandas as pd

# Havran statistics (Hapala Eq 1-6) live in costmodel/havran.py; re-exported for the selector's users
from costmodel.havran import (cell_counts, havran_stats, kurtosis_refs, max_refs, mean_refs,  # noqa: F401
                              sigma_refs, skewness_refs, sparseness_cells, sparseness_eq1, variance_refs)
from tracer.accel.constants import HAPALA_EPS

#: grid resolution of the calibration and the decision (Hapala Sec 3: "number of cells proportional
#: to N"; the constant is not given, we use cells = N, the classic choice of Cleary & Wyvill / Havran)
GRID_FACTOR = 1.0
#: sample sizes for the grid's per-ray time (the paper: "100 to 1000 rays")
SAMPLE_SIZES = (100, 300, 1000, 3000)
DEFAULT_SAMPLE = 1000
#: which statistic of repeated timings the records use ("min": interference only adds time)
TIME_STAT = "min"
#: version of the calibration protocol (stored measurements of another protocol are redone)
PROTOCOL = "thread-cpu-time/single-pass-probe/4"
#: Err of an estimate that says "grid always" (R_est = inf) while the true R_C is finite, in percent
ERR_CAP = 1000.0


# ============================================================ the critical point
def exact_rc(T_BH, t_RG, t_RH, eps: float = HAPALA_EPS):
    """Hapala Sec 3 step 6: R_C = T_B^H / (t_R^G (1 + eps) - t_R^H), the number of rays above which
    building the hierarchy pays off; inf ("grid always", step 5) when t_R^H >= t_R^G. Arrays broadcast."""
    T_BH, t_RG, t_RH = np.broadcast_arrays(*(np.asarray(v, float) for v in (T_BH, t_RG, t_RH)))
    den = t_RG * (1.0 + eps) - t_RH
    grid_always = (t_RH >= t_RG) | ~(den > 0)
    out = np.where(grid_always, np.inf, T_BH / np.where(grid_always, 1.0, den))
    return float(out) if out.ndim == 0 else out


def rc_error(r_est, r_true, cap: float = ERR_CAP):
    """Err = 100 (R_est - R_C) / R_C in percent (Hapala Sec 4), for finite R_C; an estimate of inf
    ("grid always") scores ``cap``, and Err is clipped to [-100, cap]. Rows with R_C = inf give nan."""
    r_est, r_true = np.asarray(r_est, float), np.asarray(r_true, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        err = 100.0 * (r_est - r_true) / r_true
    err = np.where(np.isinf(r_est), cap, np.clip(err, -100.0, cap))
    return np.where(np.isfinite(r_true), err, np.nan)


def _pick(v, stat):
    return v[stat] if isinstance(v, dict) else v


def records(raw, hier: str = "kdtree", sample: int = DEFAULT_SAMPLE, eps: float = HAPALA_EPS,
            stat: str | None = None) -> pd.DataFrame:
    """Flatten ``calibrate_scene`` outputs to one calibration record per (scene, ray kind):
    the grid features come from the ``sample`` sampled rays (what the decision algorithm sees);
    ``t_RG`` (all rays), ``T_BH`` and ``t_RH`` are the measured truth; ``t_RG_s<k>`` every sample
    size; ``stat`` = "min" (default, :data:`TIME_STAT`) or "median" of the repeated timings."""
    stat = stat or TIME_STAT
    rows = []
    for r in raw:
        if hier not in r["hier"]:
            continue
        for kind, k in r["kinds"].items():
            s = k["samples"].get(str(sample)) or k["samples"][max(k["samples"], key=int)]
            row = {"scene": r["scene"], "kind": kind, "N": r["N"], "T_BG": _pick(r["T_BG"], stat),
                   "t_RG": _pick(k["t_RG"], stat), "t_RG_sample": s.get(f"t_{stat}", s["t"]),
                   "T_BH": _pick(r["hier"][hier]["T_BH"], stat), "t_RH": _pick(k["hier"][hier]["t_RH"], stat),
                   "box_frac": s["box_frac"], "hit_frac": s["hit_frac"], "steps": s["steps"], "tests": s["tests"],
                   "refs_per_tri": r["refs_per_tri"], "rays": k["rays"], "hier": hier,
                   "calib_seconds": r.get("seconds", np.nan)}
            row.update({c: r[c] for c in ("sigma", "mean", "sparseness_cells", "sparseness_eq1", "max_refs",
                                          "skewness", "kurtosis")})
            row.update({f"t_RG_s{n}": v.get(f"t_{stat}", v["t"]) for n, v in k["samples"].items()})
            row["R_C"] = exact_rc(row["T_BH"], row["t_RG"], row["t_RH"], eps)
            rows.append(row)
    return pd.DataFrame(rows)


# ============================================================ estimators
def _log2n(N):
    return np.log2(np.maximum(np.asarray(N, float), 2.0))


def _col(X, name, default=np.nan):
    """Column ``name`` of a DataFrame / mapping of arrays / scalars, as a float array."""
    if isinstance(X, pd.DataFrame):
        return X[name].to_numpy(float) if name in X else np.full(len(X), default)
    if X is None or name not in X:
        return np.full(np.size(X.get("N", 0)) if X is not None else 1, default, dtype=float)
    return np.atleast_1d(np.asarray(X[name], float))


def as_arrays(frame) -> dict:
    """A calibration frame as a dict of numpy columns (fast row subsets in the evaluation loops)."""
    return {c: frame[c].to_numpy() for c in frame.columns} if isinstance(frame, pd.DataFrame) else dict(frame)


def subset(X: dict, idx) -> dict:
    return {k: v[idx] for k, v in X.items()}


def _vector(features) -> bool:
    """True for a table of rows (DataFrame or dict of arrays), False for one scene's mapping."""
    return isinstance(features, pd.DataFrame) or (features is not None and np.ndim(features.get("N", 0)) >= 1)


class HapalaEstimator:
    """Hapala Eq 7 and Eq 8: T_B^H = N log2 N (1/s) sum T_B^H(i) / (N(i) log2 N(i)) and
    t_R^H = log2 N (1/s) sum t_R^H(i) / log2 N(i), averaged over the s calibration scenes."""

    form_ = "hapala"

    def fit(self, cal):
        N = _col(cal, "N")
        L = _log2n(N)
        self.k_build_ = float(np.mean(_col(cal, "T_BH") / (N * L)))
        self.k_ray_ = float(np.mean(_col(cal, "t_RH") / L))
        self.n_calib_ = len(N)
        return self

    def predict(self, N, features=None):
        """(T_BH_est, t_RH_est) for N primitives (``features`` unused)."""
        N = np.asarray(N, float)
        L = _log2n(N)
        T, t = self.k_build_ * N * L, self.k_ray_ * L
        return (float(T), float(t)) if N.ndim == 0 else (T, t)


def _pos_log(v, floor: float = 1e-12):
    return np.log(np.maximum(np.nan_to_num(np.asarray(v, float), nan=floor), floor))


#: log-space features the improved estimator may use; all are known once the grid is built and probed
FEATURES = {
    "log N": lambda X: np.log(_col(X, "N")),
    "log log2 N": lambda X: np.log(_log2n(_col(X, "N"))),
    "log N log2 N": lambda X: np.log(_col(X, "N") * _log2n(_col(X, "N"))),
    "log t_G": lambda X: _pos_log(_col(X, "t_RG_sample")),
    "log tests": lambda X: _pos_log(_col(X, "tests") + 0.1),
    "log steps": lambda X: _pos_log(_col(X, "steps") + 0.1),
    "log sigma": lambda X: _pos_log(_col(X, "sigma")),
    "sparseness": lambda X: np.nan_to_num(_col(X, "sparseness_cells"), nan=0.0),
}
#: candidate forms, simplest first: name -> (offset with coefficient 1 or None, fitted features);
#: every form has a fitted constant and is fitted by least squares on logs (relative errors);
#: features None = a fixed form without constants
BUILD_FORMS = {
    "c N log N": ("log N log2 N", []),
    "a N^b": (None, ["log N"]),
    "a N^b sigma^c e^(d sparseness)": (None, ["log N", "log sigma", "sparseness"]),
    "a N^b steps^c t_G^d": (None, ["log N", "log steps", "log t_G"]),
}
RAY_FORMS = {
    "c log N": ("log log2 N", []),
    "c t_G": ("log t_G", []),
    "a t_G^b": (None, ["log t_G"]),
    "a t_G^b tests^c steps^d": (None, ["log t_G", "log tests", "log steps"]),
    "a t_G^b tests^c steps^d (log N)^e": (None, ["log t_G", "log tests", "log steps", "log log2 N"]),
    "a t_G^b tests^c steps^d sigma^e e^(f sparseness)": (None, ["log t_G", "log tests", "log steps", "log sigma",
                                                                 "sparseness"]),
}
#: the grid's own per-ray time from the sample: as sampled (the paper) or corrected for the
#: sample's cold start, t_G = a t_sample^b
GRID_FORMS = {"sampled": ("log t_G", None), "a t_sample^b": (None, ["log t_G"]),
              "a t_sample^b steps^c tests^d": (None, ["log t_G", "log steps", "log tests"])}


def _feature(X, name):
    """Feature ``name`` of X: precomputed (:func:`add_features`) or computed now."""
    key = "f:" + name
    return X[key] if isinstance(X, dict) and key in X else FEATURES[name](X)


def add_features(X) -> dict:
    """X as a dict of arrays with every feature precomputed (the evaluation loops fit thousands of times)."""
    X = as_arrays(X)
    X.update({"f:" + k: fn(X) for k, fn in FEATURES.items()})
    return X


def _design_log(form, X):
    off_name, feats = form
    n = len(_col(X, "N"))
    off = _feature(X, off_name) if off_name else np.zeros(n)
    A = np.column_stack([np.ones(n)] + [_feature(X, f) for f in (feats or [])])
    return A, off


def _loo_ols(A, z):
    """OLS of z on A: (coefficients, leave-one-out residuals r_i / (1 - h_ii); nan if n <= p)."""
    n, p = A.shape
    if n >= p:
        Q, Rm = np.linalg.qr(A)
        d = np.abs(np.diag(Rm))
        if d.min() > 1e-9 * max(d.max(), 1e-300):
            b = np.linalg.solve(Rm, Q.T @ z)
            if n == p:
                return b, np.full(n, np.nan)
            h = (Q * Q).sum(axis=1)
            return b, (z - A @ b) / np.maximum(1.0 - h, 1e-9)
    b, *_ = np.linalg.lstsq(A, z, rcond=None)  # rank-deficient: minimum-norm fit, no LOO
    return b, np.full(n, np.nan)


def select_form(forms, X, y, tol: float = 0.10):
    """Pick the form of ``forms`` (name -> (offset, features), simplest first) for target ``y``:
    the leave-one-out mean |relative error| of each form (exact, hat matrix, on logs) and the first
    (simplest) form within ``tol`` (relative) of the best. A form with k fitted exponents needs
    3k calibration scenes (and the constant-only forms two); with too few for any, the first form.
    Returns (name, {name: LOO error})."""
    z = _pos_log(y)
    table = {}
    for name, form in forms.items():
        if form[1] is None:  # a fixed form (no constants): its plain error
            _, off = _design_log(form, X)
            table[name] = float(np.mean(np.abs(np.expm1(np.clip(off - z, -50, 50)))))
            continue
        A, off = _design_log(form, X)
        if len(z) < max(2, 3 * (A.shape[1] - 1)) or not np.isfinite(A).all():
            continue  # as simple as the data allow: >= 3 calibration scenes per fitted exponent
        _, loo = _loo_ols(A, z - off)
        if np.isfinite(loo).all():
            table[name] = float(np.mean(np.abs(np.expm1(np.clip(-loo, -50, 50)))))  # estimate / truth - 1
    if not table:
        return next(iter(forms)), table
    best = min(table.values())
    return next(n for n in forms if n in table and table[n] <= best * (1 + tol) + 1e-12), table


class _LogForm:
    """One fitted log-linear form: log y = offset + A b. Predictions do not extrapolate the fitted
    part: each log-feature is clipped to the range the calibration scenes spanned (a scene far
    outside it, e.g. a grid ray testing 4,000 triangles where the calibration saw at most 30, gets
    the estimate at the edge of the calibrated range instead of a power law carried 100x beyond its
    data); the fixed offset (e.g. log2 N, log t_G) is kept as is."""

    def __init__(self, forms, name):
        self.forms, self.name = forms, name

    def fit(self, X, y):
        form = self.forms[self.name]
        if form[1] is None:
            self.coef_ = np.zeros(0)
            return self
        A, off = _design_log(form, X)
        self.coef_, _ = _loo_ols(A, _pos_log(y) - off)
        self.lo_, self.hi_ = A.min(axis=0), A.max(axis=0)
        self.off_lo_, self.off_hi_ = float(off.min()), float(off.max())
        return self

    def inside(self, X, margin: float = np.log(2.0)) -> np.ndarray:
        """Rows of X whose features (and offset) lie within the calibrated range, widened by a
        factor e^margin (2x) either side; a fixed form is inside everywhere."""
        A, off = _design_log(self.forms[self.name], X)
        if not len(self.coef_):
            return np.ones(len(off), bool)
        ok = ((A >= self.lo_ - margin) & (A <= self.hi_ + margin)).all(axis=1)
        return ok & (off >= self.off_lo_ - margin) & (off <= self.off_hi_ + margin)

    def predict(self, X):
        A, off = _design_log(self.forms[self.name], X)
        if not len(self.coef_):
            return np.exp(off)
        return np.exp(off + np.clip(A, self.lo_, self.hi_) @ self.coef_)


#: t_R^H estimates are capped at this multiple of Eq 8 with the slowest calibration scene's constant:
#: an order of magnitude above any hierarchy the calibration saw, so only a runaway extrapolation hits it
CAP_FACTOR = 10.0


class GridcostEstimator:
    """T_B^H, t_R^H (and the grid's own t_R^G) from what gridcost knows once the grid is built and
    probed: N, the sampled per-ray grid time, the sampled counters (cells stepped, triangles tested)
    and Havran's statistics. Each quantity has a few candidate log-linear forms (:data:`BUILD_FORMS`,
    :data:`RAY_FORMS`, :data:`GRID_FORMS`), fitted by least squares on logs over the calibration
    scenes; with form "auto" the form is chosen by exact leave-one-out cross-validation over the
    calibration scenes, keeping the simplest form within ``tol`` of the best (:func:`select_form`)."""

    def __init__(self, build_form: str = "auto", ray_form: str = "auto", grid_form: str = "auto",
                 tol: float = 0.10, cap: bool = True):
        self.build_form, self.ray_form, self.grid_form, self.tol = build_form, ray_form, grid_form, tol
        self.cap = cap

    def _choose(self, forms, want, X, y):
        if want != "auto":
            return want, {}
        return select_form(forms, X, y, self.tol)

    def fit(self, cal):
        cal = as_arrays(cal)
        yb, yr, yg = (_col(cal, c) for c in ("T_BH", "t_RH", "t_RG"))
        self.build_form_, self.build_cv_ = self._choose(BUILD_FORMS, self.build_form, cal, yb)
        self.ray_form_, self.ray_cv_ = self._choose(RAY_FORMS, self.ray_form, cal, yr)
        self.grid_form_, self.grid_cv_ = self._choose(GRID_FORMS, self.grid_form, cal, yg)
        self.build_ = _LogForm(BUILD_FORMS, self.build_form_).fit(cal, yb)
        self.ray_ = _LogForm(RAY_FORMS, self.ray_form_).fit(cal, yr)
        self.grid_ = _LogForm(GRID_FORMS, self.grid_form_).fit(cal, yg)
        self.form_ = f"T_BH = {self.build_form_}; t_RH = {self.ray_form_}; t_RG = {self.grid_form_}"
        self.n_calib_ = len(yb)
        # the hierarchy's per-ray time does not follow the grid's down a pathological grid (teapot in a
        # stadium: the grid slows 300x, the kd-tree does not): cap t_RH at CAP_FACTOR times the paper's
        # Eq 8 with the slowest calibration scene's constant (max t_RH / log2 N)
        self.cap_k_ = CAP_FACTOR * float(np.max(yr / _log2n(_col(cal, "N")))) if self.cap else np.inf
        return self

    @staticmethod
    def _frame(N, features):
        if _vector(features):
            return features, False
        return {**(features or {}), "N": N}, np.ndim(N) == 0

    def predict(self, N, features=None):
        """(T_BH_est, t_RH_est) for N primitives and the grid ``features`` (mapping or DataFrame)."""
        X, scalar = self._frame(N, features)
        T, t = self.build_.predict(X), self.ray_.predict(X)
        t = np.minimum(t, self.cap_k_ * _log2n(np.asarray(_col(X, "N"), float)))
        return (float(T[0]), float(t[0])) if scalar else (T, t)

    def predict_grid(self, features):
        """t_R^G estimated from the sampled per-ray time (corrected when the calibration says so;
        a scene outside the calibrated range keeps its sample: a measurement is not extrapolated)."""
        t = np.where(self.grid_.inside(features), self.grid_.predict(features),
                     np.asarray(_col(features, "t_RG_sample"), float))
        return t if _vector(features) else float(t[0])


def grid_time(estimator, features):
    """t_R^G the decision uses: the estimator's correction of the sample, else the sample itself."""
    if hasattr(estimator, "predict_grid"):
        return estimator.predict_grid(features)
    t = _col(features, "t_RG_sample")
    return t if _vector(features) else float(t[0])


def estimate_rc(estimator, frame, eps: float = HAPALA_EPS):
    """R_est for every row of ``frame`` as the decision algorithm sees it (sampled t_R^G)."""
    T, t = estimator.predict(_col(frame, "N"), frame)
    return exact_rc(T, grid_time(estimator, frame), t, eps)


# ============================================================ the decision algorithm (Sec 3)
def decide_rule(t_RG, T_BH, t_RH, n_rays, eps: float = HAPALA_EPS) -> tuple[str, float, int]:
    """Steps 5-8 on (estimated) times: ("grid" | "hier", R_C, the step that decided).

    Step 5: t_R^H >= t_R^G -> grid. Step 6: R_C = T_B^H / (t_R^G (1 + eps) - t_R^H). Step 7 as
    printed reads "If R_C <= R use uniform grids", which contradicts the paper's own analysis ("for
    the number of rays ... between 0 and R_C it does not pay off to build up a hierarchical data
    structure"); the logically correct rule is implemented: R <= R_C -> keep the grid (step 7),
    otherwise build the hierarchy (step 8)."""
    if t_RH >= t_RG:
        return "grid", float("inf"), 5
    rc = exact_rc(T_BH, t_RG, t_RH, eps)
    return ("grid", rc, 7) if n_rays <= rc else ("hier", rc, 8)


class Selector:
    """Hapala's decision algorithm: calibrate once (``fit`` on calibration records of one ray kind),
    then for a new scene build the grid, sample t_R^G on ``sample_rays`` rays, estimate T_B^H and
    t_R^H with ``estimator`` (default :class:`HapalaEstimator`) and keep the grid or build the
    hierarchy (``hier``, default the kd-tree) for ``n_rays`` rays (:func:`decide_rule`)."""

    def __init__(self, estimator=None, eps: float = HAPALA_EPS, sample_rays: int = DEFAULT_SAMPLE,
                 kind: str = "random", grid_factor: float = GRID_FACTOR, hier: str = "kdtree", seed: int = 0):
        self.estimator, self.eps, self.sample_rays, self.kind = estimator, eps, sample_rays, kind
        self.grid_factor, self.hier, self.seed = grid_factor, hier, seed

    def fit(self, calibration: pd.DataFrame):
        cal = calibration
        if "kind" in cal and (cal["kind"] == self.kind).any():
            cal = cal[cal["kind"] == self.kind]
        if "hier" in cal and (cal["hier"] == self.hier).any():
            cal = cal[cal["hier"] == self.hier]
        import copy
        self.estimator_ = copy.deepcopy(self.estimator) if self.estimator is not None else HapalaEstimator()
        self.estimator_.fit(cal.reset_index(drop=True))
        self.n_calib_ = len(cal)
        return self

    def decide_features(self, features: dict, n_rays: float) -> dict:
        """Steps 3-8 for a grid already built and probed: ``features`` holds N, T_BG, t_RG_sample and
        the sampled counters (box_frac, hit_frac, steps, tests, refs_per_tri, Havran statistics)."""
        T_BH, t_RH = self.estimator_.predict(features["N"], features)
        t_RG = float(grid_time(self.estimator_, features))
        choice, rc, step = decide_rule(t_RG, T_BH, t_RH, n_rays, self.eps)
        return {"choice": "grid" if choice == "grid" else self.hier, "rc_est": rc, "t_grid": t_RG,
                "t_grid_sampled": float(features["t_RG_sample"]),
                "t_hier": float(t_RH), "t_build_hier": float(T_BH), "t_build_grid": float(features.get("T_BG", np.nan)),
                "step": step, "n_rays": n_rays, "N": int(features["N"]), "estimator": getattr(self.estimator_, "form_", "")}


# ============================================================ evaluation (Sec 4)
#: ray budgets of the decision-quality evaluation: 10^3 ... 10^9, 4 per decade
R_VALUES = np.logspace(3, 9, 25)


def total_times(frame, R):
    """True total time (s) of keeping the grid and of building the hierarchy for R rays (rows x R):
    T_B^G + R t_R^G, and T_B^G + T_B^H + R t_R^H (the grid is built either way)."""
    R = np.asarray(R, float)[None, :]
    c = {k: _col(frame, k)[:, None] for k in ("T_BG", "t_RG", "T_BH", "t_RH")}
    return c["T_BG"] + R * c["t_RG"], c["T_BG"] + c["T_BH"] + R * c["t_RH"]


def decision_quality(frame: pd.DataFrame, r_est, R=R_VALUES) -> dict:
    """Picks of "grid iff R <= R_est" against the oracle (the faster of the two true totals):
    correct-pick fraction and time lost (mean of per-pair % and total % over all pairs)."""
    tg, th = total_times(frame, R)
    pick_grid = np.asarray(R)[None, :] <= np.asarray(r_est, float)[:, None]
    chosen = np.where(pick_grid, tg, th)
    best = np.minimum(tg, th)
    lost = chosen / best - 1.0
    return {"correct": float(np.mean(lost <= 1e-12)), "lost_mean_pct": 100 * float(lost.mean()),
            "lost_total_pct": 100 * float(chosen.sum() / best.sum() - 1), "lost_max_pct": 100 * float(lost.max()),
            "pairs": int(lost.size), "correct_n": int((lost <= 1e-12).sum())}


def evaluate(cal: pd.DataFrame, make_estimator, C_values=None, n_splits: int = 200, seed: int = 0,
             eps: float = HAPALA_EPS, R=R_VALUES, keep_errors: bool = False) -> pd.DataFrame:
    """The paper's protocol for one ray kind: for each C, ``n_splits`` random splits of the S scenes
    into C calibration and S - C evaluation scenes; fit ``make_estimator()`` on the calibration
    scenes, estimate R_est for the others (decision algorithm: sampled t_R^G), Err against the exact
    R_C (evaluation scenes with finite R_C), and the picks over the ray budgets ``R``.
    One row per C: mean Err, mean |Err|, median |Err|, capped fraction, correct picks, time lost."""
    cal = add_features(cal)
    S = len(cal["N"])
    C_values = list(C_values or range(1, S))
    rng = np.random.default_rng(seed)
    rc_true = _col(cal, "R_C")
    tg, th = total_times(cal, R)
    best = np.minimum(tg, th)
    rows = []
    batched = type(make_estimator()) is GridcostEstimator  # many splits in one stacked fit (select_batch)
    for C in C_values:
        perms = np.array([rng.permutation(S) for _ in range(n_splits)])
        cal_idx, ev_idx = perms[:, :C], perms[:, C:]
        if batched:
            from costmodel.select_batch import fit_predict_splits
            T, t, g, form_list = fit_predict_splits(make_estimator(), cal, cal_idx, ev_idx)
            r_est = exact_rc(T, g, t, eps)
        else:
            r_est, form_list = np.empty(ev_idx.shape), []
            for b in range(n_splits):
                est = make_estimator().fit(subset(cal, cal_idx[b]))
                form_list.append(getattr(est, "form_", ""))
                r_est[b] = estimate_rc(est, subset(cal, ev_idx[b]), eps)
        forms = {}
        for f in form_list:
            forms[f] = forms.get(f, 0) + 1
        e = rc_error(r_est, rc_true[ev_idx]).ravel()
        e = e[np.isfinite(e)]
        ch = np.where(np.asarray(R)[None, None, :] <= r_est[..., None], tg[ev_idx], th[ev_idx])
        lo = (ch / best[ev_idx] - 1.0).ravel()
        chosen_sum, best_sum = ch.sum(), best[ev_idx].sum()
        row = {"C": C, "splits": n_splits, "n_err": int(e.size),
               "mean_err": float(e.mean()) if e.size else np.nan, "mean_abs_err": float(np.abs(e).mean()) if e.size else np.nan,
               "median_abs_err": float(np.median(np.abs(e))) if e.size else np.nan,
               "capped_frac": float((e >= ERR_CAP).mean()) if e.size else np.nan,
               "correct": float((lo <= 1e-12).mean()), "lost_mean_pct": 100 * float(lo.mean()),
               "lost_total_pct": 100 * (chosen_sum / best_sum - 1), "top_form": max(forms, key=forms.get)}
        if keep_errors:
            row["errors"] = e
        rows.append(row)
    return pd.DataFrame(rows)


def loo_errors(cal: pd.DataFrame, make_estimator, eps: float = HAPALA_EPS) -> pd.DataFrame:
    """Leave-one-scene-out (C = S - 1): each scene's R_est from an estimator fitted on all others."""
    from costmodel.fit import leave_one_scene_out
    out = []
    for _, train, held in leave_one_scene_out(cal.reset_index(drop=True)):
        est = make_estimator().fit(train)
        for j in range(len(held)):  # one row per scene for one ray kind; each row of the scene alike
            row = held.iloc[[j]]
            T, t = est.predict(row["N"].to_numpy(float), row)
            g = grid_time(est, row)
            r = exact_rc(T, g, t, eps)
            out.append({"scene": row["scene"].iloc[0], "N": int(row["N"].iloc[0]), "R_C": float(row["R_C"].iloc[0]),
                        "R_est": float(np.asarray(r).ravel()[0]), "T_BH": float(row["T_BH"].iloc[0]),
                        "T_BH_est": float(np.ravel(T)[0]), "t_RH": float(row["t_RH"].iloc[0]),
                        "t_RH_est": float(np.ravel(t)[0]), "t_RG": float(row["t_RG"].iloc[0]),
                        "t_RG_sample": float(row["t_RG_sample"].iloc[0]), "t_RG_est": float(np.ravel(g)[0]),
                        "form": getattr(est, "form_", "")})
    df = pd.DataFrame(out)
    df["err"] = rc_error(df["R_est"], df["R_C"])
    return df


# ============================================================ the decision against its baselines
#: ray budgets of the selector's evaluation: 10^4 ... 10^9, two per decade, so that both answers occur
EVAL_R = np.logspace(4, 9, 11)
#: the policies a decision is scored against: the selector, the two fixed answers and the oracle
POLICIES = ("selector", "always grid", "always hierarchy", "oracle")


def loo_decisions(cal: pd.DataFrame, make_estimator, R=EVAL_R, eps: float = HAPALA_EPS) -> pd.DataFrame:
    """Every scene of ``cal`` (one ray kind, one hierarchy) left out of its own calibration and decided
    at every budget R: the selector keeps the grid iff R <= R_est (steps 5-8 on the estimated times,
    :func:`loo_errors`); "always grid", "always hierarchy" and the oracle (the faster true total,
    :func:`total_times`) beside it. One row per (scene, R) with each policy's pick and time lost in %
    over the oracle's total."""
    cal = cal.reset_index(drop=True)
    loo = loo_errors(cal, make_estimator, eps).set_index("scene")
    R = np.asarray(R, float)
    tg, th = total_times(cal, R)
    rows = []
    for i, r in cal.iterrows():
        est = loo.loc[r["scene"]]
        for j, n in enumerate(R):
            best = min(tg[i, j], th[i, j])
            picks = {"selector": n <= est["R_est"], "always grid": True, "always hierarchy": False,
                     "oracle": tg[i, j] <= th[i, j]}
            row = {"scene": r["scene"], "N": int(r["N"]), "R": n, "R_C": float(r["R_C"]), "R_est": float(est["R_est"]),
                   "t_RG_sample": float(r["t_RG_sample"]), "t_RH_est": float(est["t_RH_est"]),
                   "t_RG_est": float(est["t_RG_est"]), "t_RH": float(r["t_RH"]), "t_RG": float(r["t_RG"])}
            for p, grid in picks.items():
                row[f"pick {p}"] = "grid" if grid else "hierarchy"
                row[f"lost {p}"] = 100.0 * ((tg[i, j] if grid else th[i, j]) / best - 1.0)
            rows.append(row)
    return pd.DataFrame(rows)


def policy_scores(decisions: pd.DataFrame) -> pd.DataFrame:
    """Per policy of :data:`POLICIES`: correct picks (the oracle's answer, or a tie), their share, and
    the time lost over the oracle's total (mean and worst of the per-decision %)."""
    out = []
    for p in POLICIES:
        lost = decisions[f"lost {p}"].to_numpy(float)
        out.append({"policy": p, "decisions": int(lost.size), "correct": int((lost <= 1e-9).sum()),
                    "correct_pct": 100.0 * float((lost <= 1e-9).mean()) if lost.size else np.nan,
                    "lost_mean_pct": float(lost.mean()) if lost.size else np.nan,
                    "lost_max_pct": float(lost.max()) if lost.size else np.nan})
    return pd.DataFrame(out)


def step5_diagnosis(cal: pd.DataFrame, make_estimator, eps: float = HAPALA_EPS) -> dict:
    """Why step 5 ("t_R^H >= t_R^G: keep the grid") fires: the share of scenes whose held-out t_R^H
    estimate is at least the grid time the decision sees, the measured per-ray margin (median
    t_R^G / t_R^H: how small an estimation error flips step 5), and how the Eq 8 constant
    (t_R^H / log2 N) spreads over the calibration scenes (its mean against its median: a few scenes
    where the hierarchy is slow pull the mean, and with it every estimate, up)."""
    loo = loo_errors(cal.reset_index(drop=True), make_estimator, eps)
    k = _col(cal, "t_RH") / _log2n(_col(cal, "N"))
    ratio = _col(cal, "t_RG") / _col(cal, "t_RH")
    return {"scenes": int(len(loo)), "step5_share": float((loo["t_RH_est"] >= loo["t_RG_est"]).mean()),
            "median_tG_over_tH": float(np.median(ratio)), "hier_slower_share": float((ratio < 1).mean()),
            "eq8_k_mean": float(np.mean(k)), "eq8_k_median": float(np.median(k)),
            "median_est_over_true_tH": float(np.median(loo["t_RH_est"] / loo["t_RH"])),
            "median_est_over_true_tG": float(np.median(loo["t_RG_est"] / loo["t_RG"]))}
