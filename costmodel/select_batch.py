""":class:`costmodel.select.GridcostEstimator` fitted on many calibration splits at once.

The paper's evaluation protocol (:func:`costmodel.select.evaluate`) fits the estimator on thousands of
random splits of the scenes for every calibration size C; each fit is a handful of least-squares
problems of C rows. Done one split at a time the Python overhead of those tiny problems is the whole
cost (minutes per figure). Here the splits of one C are stacked: every form's design matrix is built
once for all scenes, gathered per split, and solved by one batched QR (numpy's stacked ``qr``), with
the same choice rule, the same clipping of features to the calibrated range and the same cap as the
one-split estimator; a split whose stacked system is rank-deficient is solved alone by the one-split
code. The predictions equal the one-split estimator's to rounding (a test checks both on real data).
"""
from __future__ import annotations

import numpy as np

from costmodel.select import (BUILD_FORMS, CAP_FACTOR, GRID_FORMS, RAY_FORMS, _col, _design_log, _log2n, _loo_ols,
                              _pos_log)

#: relative tolerance of the rank test (as :func:`costmodel.select._loo_ols`)
_RANK_TOL = 1e-9


def loo_ols_batch(A, z):
    """:func:`costmodel.select._loo_ols` over a stack: ``A`` (B, n, p), ``z`` (B, n) -> (coefficients
    (B, p), leave-one-out residuals (B, n), nan where n <= p or the split was solved alone)."""
    B, n, p = A.shape
    coef = np.empty((B, p))
    loo = np.full((B, n), np.nan)
    alone = np.ones(B, bool)
    if n >= p:
        Q, R = np.linalg.qr(A)
        d = np.abs(np.diagonal(R, axis1=1, axis2=2))
        ok = d.min(axis=1) > _RANK_TOL * np.maximum(d.max(axis=1), 1e-300)
        if ok.any():
            qz = np.einsum("bnp,bn->bp", Q[ok], z[ok])
            coef[ok] = np.linalg.solve(R[ok], qz[..., None])[..., 0]
            if n > p:
                h = (Q[ok] * Q[ok]).sum(axis=2)
                resid = z[ok] - np.einsum("bnp,bp->bn", A[ok], coef[ok])
                loo[ok] = resid / np.maximum(1.0 - h, 1e-9)
        alone = ~ok
    for b in np.flatnonzero(alone):
        coef[b], loo[b] = _loo_ols(A[b], z[b])
    return coef, loo


class _Quantity:
    """One estimated quantity (T_B^H, t_R^H or t_R^G) over a stack of splits: per split the chosen
    form, its coefficients and the calibrated ranges of its features and offset."""

    def __init__(self, forms, want: str, X: dict, y, cal_idx, tol: float):
        self.forms = forms
        self.designs = {name: _design_log(form, X) for name, form in forms.items()}
        z_all = _pos_log(y)
        B, C = cal_idx.shape
        z = z_all[cal_idx]
        errs, fits = {}, {}
        for name, form in forms.items():
            A_all, off_all = self.designs[name]
            off = off_all[cal_idx]
            if form[1] is None:  # a fixed form: its plain error, no constants
                errs[name] = np.mean(np.abs(np.expm1(np.clip(off - z, -50, 50))), axis=1)
                fits[name] = None
                continue
            A = A_all[cal_idx]
            coef, loo = loo_ols_batch(A, z - off)
            fits[name] = (coef, A.min(axis=1), A.max(axis=1), off.min(axis=1), off.max(axis=1))
            usable = np.isfinite(A).all(axis=(1, 2)) & (C >= max(2, 3 * (A.shape[2] - 1)))
            usable &= np.isfinite(loo).all(axis=1)
            errs[name] = np.where(usable, np.mean(np.abs(np.expm1(np.clip(-loo, -50, 50))), axis=1), np.nan)
        names = list(forms)
        if want != "auto":
            self.choice = np.full(B, names.index(want))
        else:
            E = np.column_stack([errs[n] for n in names])              # (B, forms); nan = not a candidate
            best = np.nanmin(np.where(np.isnan(E), np.inf, E), axis=1)
            within = np.where(np.isnan(E), False, E <= best[:, None] * (1 + tol) + 1e-12)
            self.choice = np.where(within.any(axis=1), within.argmax(axis=1), 0)
        self.names, self.fits = names, fits

    def chosen(self) -> list[str]:
        return [self.names[i] for i in self.choice]

    def predict(self, ev_idx) -> np.ndarray:
        """(B, E) predictions for the rows ``ev_idx`` (B, E) of each split, as ``_LogForm.predict``."""
        out = np.empty(ev_idx.shape)
        for i, name in enumerate(self.names):
            rows = np.flatnonzero(self.choice == i)
            if not len(rows):
                continue
            A_all, off_all = self.designs[name]
            off = off_all[ev_idx[rows]]
            if self.fits[name] is None:
                out[rows] = np.exp(off)
                continue
            coef, lo, hi, _, _ = self.fits[name]
            A = np.clip(A_all[ev_idx[rows]], lo[rows][:, None, :], hi[rows][:, None, :])
            out[rows] = np.exp(off + np.einsum("bep,bp->be", A, coef[rows]))
        return out

    def inside(self, ev_idx, margin: float = np.log(2.0)) -> np.ndarray:
        """(B, E): rows within the calibrated range widened by e^margin, as ``_LogForm.inside``."""
        out = np.ones(ev_idx.shape, bool)
        for i, name in enumerate(self.names):
            rows = np.flatnonzero(self.choice == i)
            if not len(rows) or self.fits[name] is None:
                continue
            A_all, off_all = self.designs[name]
            _, lo, hi, olo, ohi = self.fits[name]
            A, off = A_all[ev_idx[rows]], off_all[ev_idx[rows]]
            ok = ((A >= lo[rows][:, None, :] - margin) & (A <= hi[rows][:, None, :] + margin)).all(axis=2)
            out[rows] = ok & (off >= olo[rows][:, None] - margin) & (off <= ohi[rows][:, None] + margin)
        return out


def fit_predict_splits(est, X: dict, cal_idx, ev_idx):
    """What ``est`` (an unfitted :class:`~costmodel.select.GridcostEstimator`, for its parameters)
    fitted on the rows ``cal_idx`` (B, C) of ``X`` (features precomputed,
    :func:`costmodel.select.add_features`) estimates for the rows ``ev_idx`` (B, E): (T_B^H, t_R^H,
    t_R^G the decision uses), each (B, E), and each split's form string."""
    yb, yr, yg = (_col(X, c) for c in ("T_BH", "t_RH", "t_RG"))
    build = _Quantity(BUILD_FORMS, est.build_form, X, yb, cal_idx, est.tol)
    ray = _Quantity(RAY_FORMS, est.ray_form, X, yr, cal_idx, est.tol)
    grid = _Quantity(GRID_FORMS, est.grid_form, X, yg, cal_idx, est.tol)
    N = _col(X, "N")
    T, t = build.predict(ev_idx), ray.predict(ev_idx)
    if est.cap:
        cap_k = CAP_FACTOR * (yr / _log2n(N))[cal_idx].max(axis=1)
        t = np.minimum(t, cap_k[:, None] * _log2n(N[ev_idx]))
    tg = np.where(grid.inside(ev_idx), grid.predict(ev_idx), _col(X, "t_RG_sample")[ev_idx])
    forms = [f"T_BH = {b}; t_RH = {r}; t_RG = {g}" for b, r, g in zip(build.chosen(), ray.chosen(), grid.chosen())]
    return T, t, tg, forms
