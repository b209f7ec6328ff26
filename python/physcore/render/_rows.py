"""Row-wise numpy helpers on (N, d) arrays of points, written column by column: numpy reductions
along a short last axis (N, 2) are several times slower than whole-column operations."""
from __future__ import annotations

import numpy as np


def _rows_finite(x: np.ndarray) -> np.ndarray:
    """(N, d) -> (N,) bool, True where the whole row is finite."""
    ok = np.isfinite(x[:, 0])
    for c in range(1, x.shape[1]):
        ok &= np.isfinite(x[:, c])
    return ok


def _row_norms(v: np.ndarray) -> np.ndarray:
    """(N, d) -> (N,) Euclidean norms."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _finite_mean(x: np.ndarray) -> np.ndarray:
    """(N, d) -> (d,) mean of the finite rows; zeros if there are none."""
    if np.isfinite(x).all():
        return np.array([x[:, c].mean() for c in range(x.shape[1])]) if len(x) else np.zeros(x.shape[1])
    ok = _rows_finite(x)
    return np.array([x[ok, c].mean() for c in range(x.shape[1])]) if ok.any() else np.zeros(x.shape[1])
