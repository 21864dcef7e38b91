"""Filter metrics over runs × time: RMSE per group, NEES/NIS with χ² bands, best/worst run.

Errors are ``e = x̂ − x`` shaped ``(n_runs, T, n_x)`` in the CA state order ``[r(3), v(3),
a(3)]`` (NED). Consistency (Bar-Shalom, Li & Kirubarajan 2001, §5.4): with ``N`` runs, the
run-averaged NEES ``ε̄_k = (1/N) Σ_i e_{ik}ᵀ P_{ik}⁻¹ e_{ik}`` of a consistent filter is
distributed as ``χ²(N n_x)/N``, so its two-sided ``1 − α`` band is
``[χ²_{α/2}(N n_x), χ²_{1−α/2}(N n_x)]/N``; the same holds for the NIS with ``n_z``.
Best/worst runs (seed 000 §9): the lowest and highest summed absolute error.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .models import STATE_COLUMNS, STATE_GROUPS

F64 = NDArray[np.float64]


def rmse(err: ArrayLike, axis=(0, 1)) -> F64:
    """Root mean square of ``err`` over ``axis`` (default: runs and time → one per component)."""
    e2 = np.square(np.asarray(err, dtype=np.float64))
    return _root_mean(e2, axis)


def _root_mean(e2: F64, axis) -> F64:
    """``sqrt(mean)`` of the finite entries of ``e2`` over ``axis``; NaN where there are none
    (no empty-slice warning: a flight without reference is not an error)."""
    n = np.sum(np.isfinite(e2), axis=axis)
    total = np.nansum(e2, axis=axis)
    return np.sqrt(np.divide(total, n, out=np.full(np.shape(total), np.nan), where=n > 0))


def rmse_groups(err: ArrayLike) -> dict[str, float]:
    """RMSE per state component and per group over runs and time.

    Parameters
    ----------
    err : array_like, shape (n_runs, T, 9) or (T, 9)

    Returns
    -------
    dict
        ``pos_n_m`` … ``acc_d_mps2`` (per axis) and ``pos``, ``vel``, ``acc`` (the 3-D RMSE of
        the group, ``sqrt(mean |e_group|²)``).
    """
    e = np.asarray(err, dtype=np.float64)
    e = e.reshape(-1, e.shape[-1])
    per = rmse(e, axis=0)
    out = {name: float(v) for name, v in zip(STATE_COLUMNS, per)}
    for g, sl in STATE_GROUPS.items():
        out[g] = float(_root_mean(np.sum(e[:, sl] ** 2, axis=1), 0))
    return out


def nees(err: ArrayLike, cov: ArrayLike) -> F64:
    """Normalised estimation error squared ``eᵀ P⁻¹ e``; ``err`` (..., n_x), ``cov`` (..., n_x, n_x)."""
    e = np.asarray(err, dtype=np.float64)
    sol = np.linalg.solve(np.asarray(cov, dtype=np.float64), e[..., None])[..., 0]
    return np.einsum("...i,...i->...", e, sol)


def nis(innovation: ArrayLike, S: ArrayLike) -> F64:
    """Normalised innovation squared ``yᵀ S⁻¹ y`` (same shapes as :func:`nees`)."""
    return nees(innovation, S)


def chi2_band(dof: int, n_runs: int = 1, alpha: float = 0.05) -> tuple[float, float]:
    """Two-sided ``1 − α`` band of a run-averaged NEES/NIS: ``χ²_{α/2, 1−α/2}(N·dof)/N``."""
    from scipy.stats import chi2  # here: scipy.stats costs ~1 s to import, and only the bands need it

    n = dof * n_runs
    lo, hi = chi2.ppf([alpha / 2, 1 - alpha / 2], n)
    return float(lo / n_runs), float(hi / n_runs)


def fraction_in_band(avg: ArrayLike, dof: int, n_runs: int, alpha: float = 0.05) -> float:
    """Fraction of steps whose run-averaged NEES/NIS ``avg`` (T,) lies inside :func:`chi2_band`."""
    lo, hi = chi2_band(dof, n_runs, alpha)
    a = np.asarray(avg, dtype=np.float64)
    return float(np.mean((a >= lo) & (a <= hi)))


def summed_abs_error(err: ArrayLike) -> F64:
    """Per run, the summed absolute error over time and components (seed 000 §9); ``(n_runs,)``."""
    e = np.asarray(err, dtype=np.float64)
    return np.nansum(np.abs(e), axis=tuple(range(1, e.ndim)))


def best_worst(err: ArrayLike) -> tuple[int, int]:
    """Indices of the best (Scenario 1: lowest summed absolute error) and the worst (Scenario 2:
    highest) run of ``err`` (n_runs, T, n_x) (seed 000 §9)."""
    s = summed_abs_error(err)
    return int(np.argmin(s)), int(np.argmax(s))
