"""Havran's scene statistics from a uniform grid (Hapala, Karlik & Havran 2011, Eq 1-6): sparseness,
the maximum, mean, variance, sigma, skewness and kurtosis of the triangle references per cell."""
from __future__ import annotations

import numpy as np


def cell_counts(grid) -> np.ndarray:
    """Per-cell reference counts N_i of a built :class:`tracer.accel.grid.UniformGrid` (or the counts)."""
    if hasattr(grid, "cell_start_"):
        return np.diff(np.asarray(grid.cell_start_, np.int64))
    return np.asarray(grid, np.int64).ravel()


def sparseness_eq1(counts, n_prims: int) -> float:
    """Eq 1 as printed: sparseness = #empty cells / N (N = number of primitives).
    The text says "ratio of empty cells to all cells"; see :func:`sparseness_cells`."""
    return float((np.asarray(counts) == 0).sum()) / max(int(n_prims), 1)


def sparseness_cells(counts) -> float:
    """Eq 1 as the text defines it: sparseness = #empty cells / t (t = number of cells)."""
    counts = np.asarray(counts)
    return float((counts == 0).sum()) / max(counts.size, 1)


def max_refs(counts) -> int:
    """Eq 2: maxRefs = max_i N_i, i in 1..t."""
    return int(np.max(counts, initial=0))


def mean_refs(counts) -> float:
    """Eq 3: mean = (1/t) sum_i N_i."""
    return float(np.mean(np.asarray(counts, float)))


def variance_refs(counts) -> float:
    """Eq 4: variance = 1/(t - 1) sum_i (N_i - mean)^2 (sample variance; nan for t = 1)."""
    c = np.asarray(counts, float)
    return float(((c - c.mean()) ** 2).sum() / (c.size - 1)) if c.size > 1 else float("nan")


def sigma_refs(counts) -> float:
    """sigma = sqrt(variance) with the variance of Eq 4."""
    return float(np.sqrt(variance_refs(counts)))


def skewness_refs(counts) -> float:
    """Eq 5: skewness = (1/t) sum_i ((N_i - mean) / sigma)^3, sigma from Eq 4 (nan when sigma = 0)."""
    c = np.asarray(counts, float)
    s = sigma_refs(c)
    return float(np.mean(((c - c.mean()) / s) ** 3)) if s > 0 else float("nan")


def kurtosis_refs(counts) -> float:
    """Eq 6: kurtosis = (1/t) sum_i ((N_i - mean) / sigma)^4 - 3, sigma from Eq 4 (nan when sigma = 0)."""
    c = np.asarray(counts, float)
    s = sigma_refs(c)
    return float(np.mean(((c - c.mean()) / s) ** 4) - 3.0) if s > 0 else float("nan")


def havran_stats(grid, n_prims: int | None = None) -> dict:
    """Havran's scene statistics (Hapala Eq 1-6) of a built uniform grid (or of per-cell counts
    with ``n_prims``): both readings of sparseness, maxRefs, mean, variance, sigma, skewness, kurtosis."""
    c = cell_counts(grid)
    n = int(n_prims if n_prims is not None else getattr(grid, "n_", c.sum()))
    return {"cells": int(c.size), "empty_cells": int((c == 0).sum()),
            "sparseness_eq1": sparseness_eq1(c, n), "sparseness_cells": sparseness_cells(c),
            "max_refs": max_refs(c), "mean": mean_refs(c), "variance": variance_refs(c),
            "sigma": sigma_refs(c), "skewness": skewness_refs(c), "kurtosis": kurtosis_refs(c)}


