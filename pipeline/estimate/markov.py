"""Markov transition matrices: row-stochastic checks and re-timing (for the IMM and the PF).

A transition matrix ``Π`` given for a reference step ``Δt_ref`` is carried to another step by
the matrix exponential of its generator (continuous-time Markov chain embedding):

.. math::

    \\Pi(\\Delta t) = \\exp\\!\\big(\\log(\\Pi)\\,\\Delta t / \\Delta t_{ref}\\big)

so ``Π(Δt_ref) = Π`` and ``Π(Δt/2)² = Π(Δt)``. The principal logarithm must be real (a Π
with a negative real eigenvalue has no real generator); otherwise a clear error.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import expm, logm

F64 = NDArray[np.float64]


def check_stochastic(Pi: ArrayLike, name: str = "transition matrix", atol: float = 1e-9) -> F64:
    """``Pi`` as a float array, checked to be square and row-stochastic.

    Raises
    ------
    ValueError
        One line naming the matrix and the first offending row (its sum, or a negative or
        non-finite entry).
    """
    P = np.asarray(Pi, dtype=np.float64)
    if P.ndim != 2 or P.shape[0] != P.shape[1] or P.shape[0] == 0:
        raise ValueError(f"{name}: must be a non-empty square matrix, got shape {P.shape}")
    for i, row in enumerate(P):
        if not np.all(np.isfinite(row)):
            raise ValueError(f"{name}: row {i} has a non-finite entry")
        if np.any(row < -atol):
            raise ValueError(f"{name}: row {i} has a negative entry ({row.min():.6g})")
        s = row.sum()
        if abs(s - 1.0) > atol:
            raise ValueError(f"{name}: row {i} sums to {s:.6g}, not 1")
    return P


def retime(Pi: ArrayLike, dt: float, dt_ref: float, name: str = "transition matrix") -> F64:
    """``Π(Δt) = expm(logm(Π)·Δt/Δt_ref)`` (module docstring), row-stochastic.

    Parameters
    ----------
    Pi : array_like, shape (n, n)
        Row-stochastic transition matrix over ``dt_ref``.
    dt, dt_ref : float
        Target and reference steps (s), ``dt ≥ 0``, ``dt_ref > 0``.

    Raises
    ------
    ValueError
        ``Pi`` not row-stochastic (see :func:`check_stochastic`), a bad step, or no real
        generator.
    """
    P = check_stochastic(Pi, name)
    if not (dt_ref > 0) or not (dt >= 0):
        raise ValueError(f"{name}: need dt >= 0 and dt_ref > 0, got dt={dt}, dt_ref={dt_ref}")
    if dt == dt_ref:
        return P.copy()
    if dt == 0:
        return np.eye(len(P))
    L = logm(P)
    if np.iscomplexobj(L):
        if np.max(np.abs(L.imag)) > 1e-9 * max(1.0, np.max(np.abs(L.real))):
            raise ValueError(f"{name}: has no real matrix logarithm (a negative or complex "
                             "eigenvalue), so it cannot be re-timed")
        L = L.real
    out = expm(L * (dt / dt_ref))
    # round-off: clip tiny negatives and renormalise the rows
    out = np.clip(out, 0.0, None)
    return out / out.sum(axis=1, keepdims=True)


def hmm_to_step(transmat: ArrayLike, dt_s: float, dt_hmm_s: float, name: str = "transmat") -> F64:
    """A saved model's ``transmat`` (per HMM sample ``T_hmm``) carried to a filter step ``T``:
    ``Π^{T/T_hmm}`` by :func:`retime` (seed 002 §12 item 3, the IMM's bridge to EKF+HMM)."""
    return retime(transmat, dt_s, dt_hmm_s, name)


def step_to_hmm(Pi_step: ArrayLike, dt_s: float, dt_hmm_s: float, name: str = "step transition") -> F64:
    """The conversion back: a per-step matrix ``Π_T`` to the HMM sample, ``Π_T^{T_hmm/T}``
    (:func:`hmm_to_step` inverted; a converted ``transmat`` converts back)."""
    return retime(Pi_step, dt_hmm_s, dt_s, name)
