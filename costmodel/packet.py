"""Packet cost model of coherent grid traversal (Wald et al. 2006, Sec 4.1: "the cost of a traversal
step is constant, but the cost for intersecting the cells in a slice increases with the number of
cells that the frustum overlaps ... a natural crossover point").

One packet of k^2 rays costs

    T_packet = T_setup + slices * T_slice + cells * T_cell + tests * T_test

(``tests`` = ray-triangle tests, i.e. triangles tested x rays tested with them), so the time per ray
is that amortised over the k^2 rays:

    T_ray = T_setup * (packets / ray) + T_slice * (slices / ray) + T_cell * (cells / ray)
            + T_test * (tests / ray)   [+ T_ray0 with ``ray_term=True``: clipping each ray]

— linear in the constants, fitted by non-negative least squares (scipy.optimize.nnls) to measured
times over a sweep of packet sizes and lambda. Relative least squares (rows weighted by 1 / T) so
fast and slow points count alike; bootstrap 95 % intervals. scikit-learn style: parameters in
``__init__``, ``fit`` returns self, fitted attributes end with ``_``.

:func:`best_config` turns fitted constants and the *counted* work of candidate (k, lambda)
configurations (a counting traversal, no timing) into predicted times and the predicted best.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from costmodel.fit import _metrics

#: per-ray work columns the model takes, in order (``ray`` is the optional constant per-ray term)
COLUMNS = ("packets", "slices", "cells", "tests")
CONSTANTS = ("t_setup", "t_slice", "t_cell", "t_test")
N_BOOT = 200


def design(X, ray_term: bool = False) -> np.ndarray:
    """The design matrix: ``X`` an (n, 4) array of per-ray packets, slices, cells, tests, or a
    mapping/DataFrame with those columns; with ``ray_term`` a column of ones is appended."""
    if hasattr(X, "columns") or isinstance(X, dict):
        A = np.column_stack([np.asarray(X[c], float) for c in COLUMNS])
    else:
        A = np.asarray(X, float)
        if A.ndim == 1:
            A = A[None, :]
    if A.shape[1] != len(COLUMNS):
        raise ValueError(f"need {len(COLUMNS)} columns {COLUMNS}, got shape {A.shape}")
    if ray_term:
        A = np.column_stack([A, np.ones(len(A))])
    return A


class PacketCostFit:
    """Fit T_setup, T_slice, T_cell, T_test (and T_ray0 with ``ray_term``) of the packet model to
    per-ray counts ``X`` and times ``y`` (any unit; we use ns per ray)."""

    def __init__(self, ray_term: bool = False, relative: bool = True, n_boot: int = N_BOOT, seed: int = 0):
        self.ray_term, self.relative, self.n_boot, self.seed = ray_term, relative, n_boot, seed

    @property
    def names(self) -> tuple:
        return CONSTANTS + (("t_ray",) if self.ray_term else ())

    def fit(self, X, y):
        A = design(X, self.ray_term)
        y = np.asarray(y, float)
        if len(y) != len(A):
            raise ValueError(f"{len(A)} rows of counts but {len(y)} times")
        w = 1.0 / y if self.relative else np.ones_like(y)
        coef, _ = nnls(A * w[:, None], y * w)
        self.coef_ = coef
        self.constants_ = dict(zip(self.names, (float(c) for c in coef)))
        self.t_setup_, self.t_slice_, self.t_cell_, self.t_test_ = (float(c) for c in coef[:4])
        self.t_ray_ = float(coef[4]) if self.ray_term else 0.0
        Aw = A * w[:, None]
        norms = np.linalg.norm(Aw, axis=0)
        self.cond_ = float(np.linalg.cond(Aw / np.where(norms > 0, norms, 1)))
        self.metrics_ = _metrics(y, A @ coef)
        rng = np.random.default_rng(self.seed)
        boots = []
        for _ in range(self.n_boot):
            idx = rng.integers(0, len(y), len(y))
            if len(np.unique(idx)) < A.shape[1]:
                continue
            c, _ = nnls(A[idx] * w[idx, None], y[idx] * w[idx])
            boots.append(c)
        boots = np.array(boots) if boots else np.full((1, A.shape[1]), np.nan)
        lo, hi = np.nanpercentile(boots, [2.5, 97.5], axis=0)
        self.ci_ = {n: (float(a), float(b)) for n, a, b in zip(self.names, lo, hi)}
        self.n_samples_ = len(y)
        return self

    def predict(self, X) -> np.ndarray:
        """Predicted time per ray for per-ray counts ``X``."""
        return design(X, self.ray_term) @ self.coef_

    def packet_time(self, slices, cells, tests, rays=None):
        """Predicted time of one packet (``rays`` adds the per-ray term for that many rays)."""
        t = self.t_setup_ + np.asarray(slices, float) * self.t_slice_ + np.asarray(cells, float) * self.t_cell_ \
            + np.asarray(tests, float) * self.t_test_
        return t + (0.0 if rays is None else np.asarray(rays, float) * self.t_ray_)

    def shares(self, X) -> dict:
        """Mean fraction of the predicted time spent in each term (set-up, slices, cells, tests[, ray])."""
        A = design(X, self.ray_term) * self.coef_
        tot = A.sum(axis=1, keepdims=True)
        frac = (A / np.where(tot > 0, tot, 1)).mean(axis=0)
        return {n: float(f) for n, f in zip(self.names, frac)}


def best_config(model: PacketCostFit, counts, keys=("packet", "lam")):
    """Predict the time per ray of every candidate configuration from its counted work and the
    fitted constants. ``counts``: a DataFrame with the ``keys`` columns and the per-ray
    :data:`COLUMNS`. Returns (the best row as a dict, the DataFrame with a ``predicted`` column)."""
    df = counts.copy()
    df["predicted"] = model.predict(df)
    best = df.loc[df["predicted"].idxmin()]
    return {k: best[k] for k in list(keys) + ["predicted"] if k in best}, df
