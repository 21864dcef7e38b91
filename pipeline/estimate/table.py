"""The estimator output table (``io.schema`` ``"estimate"``) from filter arrays, and back."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..io import schema
from .models import STATE_COLUMNS

F64 = NDArray[np.float64]

#: ``x_<state column>`` in state order
X_COLUMNS: tuple[str, ...] = tuple(f"x_{c}" for c in STATE_COLUMNS)
#: upper-triangle covariance columns ``P_<i>_<j>`` (i ≤ j), row-major
P_COLUMNS: tuple[str, ...] = tuple(f"P_{i}_{j}" for i in range(9) for j in range(i, 9))


def upper_triangle(cov: ArrayLike, n: int | None = None) -> dict[str, NDArray[np.float64]]:
    """``{P_<i>_<j>: cov[:, i, j]}`` for ``i <= j < n`` (i-major, the tables' column order) of a
    covariance track (T, m, m); ``n`` defaults to ``m``, and entries beyond ``m`` (a filter whose
    state is shorter than its table's) are NaN."""
    P = np.asarray(cov, dtype=np.float64)
    m = P.shape[-1]
    n = m if n is None else n
    nan = np.full(P.shape[0], np.nan)
    return {f"P_{i}_{j}": P[:, i, j] if j < m else nan for i in range(n) for j in range(i, n)}


def estimate_frame(t_ns: ArrayLike, mean: ArrayLike, cov: ArrayLike, nis: ArrayLike | None = None,
                   nees: ArrayLike | None = None):
    """One run's estimates as the canonical ``estimate`` table.

    Parameters
    ----------
    t_ns : array_like of int, shape (T,)
    mean : array_like, shape (T, 9)
    cov : array_like, shape (T, 9, 9)
    nis, nees : array_like, shape (T,), optional
        NaN where not given (``nees``: no truth).

    Returns
    -------
    pandas.DataFrame
        Conformed to ``schema.ESTIMATE``.
    """
    import pandas as pd

    t = np.asarray(t_ns, dtype=np.int64)
    m = np.asarray(mean, dtype=np.float64)
    P = np.asarray(cov, dtype=np.float64)
    n = len(t)
    if m.shape != (n, 9) or P.shape != (n, 9, 9):
        raise ValueError(f"estimate_frame: need mean (T, 9) and cov (T, 9, 9) for T={n}, got {m.shape}, {P.shape}")
    cols = {"t_ns": t, **dict(zip(X_COLUMNS, m.T)), **upper_triangle(P)}
    cols["nis"] = np.full(n, np.nan) if nis is None else np.asarray(nis, dtype=np.float64)
    cols["nees"] = np.full(n, np.nan) if nees is None else np.asarray(nees, dtype=np.float64)
    return schema.conform("estimate", pd.DataFrame(cols))


def frame_arrays(df) -> tuple[NDArray[np.int64], F64, F64]:
    """``(t_ns (T,), mean (T, 9), cov (T, 9, 9))`` back from an ``estimate`` table."""
    m = df[list(X_COLUMNS)].to_numpy(dtype=np.float64)
    up = df[list(P_COLUMNS)].to_numpy(dtype=np.float64)
    P = np.zeros((len(df), 9, 9))
    iu = np.triu_indices(9)
    P[:, iu[0], iu[1]] = up
    P[:, iu[1], iu[0]] = up
    return df["t_ns"].to_numpy(dtype=np.int64), m, P
