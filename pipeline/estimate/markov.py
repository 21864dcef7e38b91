"""Markov transition matrices: row-stochastic checks and re-timing (for the IMM and the PF).

A transition matrix ``Π`` given for a reference step ``Δt_ref`` is carried to another step by
the matrix exponential of its generator (continuous-time Markov chain embedding):

.. math::

    \\Pi(\\Delta t) = \\exp\\!\\big(\\log(\\Pi)\\,\\Delta t / \\Delta t_{ref}\\big)

so ``Π(Δt_ref) = Π`` and ``Π(Δt/2)² = Π(Δt)``. The principal logarithm must be real (a Π
with a negative real eigenvalue has none). It need not be a valid generator (the embedding
problem: a cyclic Π, or one with a zero entry that two steps can reach, has a negative
off-diagonal rate), and then ``Π(Δt)`` has negative entries, which are clipped and the rows
renormalised — an approximation that breaks ``Π(Δt/2)² = Π(Δt)``. It is allowed only up to
``max_clip`` of probability clipped from any row (default :data:`MAX_CLIP`: the paper's Π_d/Π_p
of seed 001 at 20 Hz clip 2e-5), else a clear error with the amount; a caller that accepts more
says so with ``max_clip`` (the trained maneuver HMMs' transmats clip 2e-4 to 2e-2 at a quarter
of their step).
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


#: default bound on the probability mass clipped from one row of Π(Δt) (module docstring)
MAX_CLIP = 1e-4


def retime(Pi: ArrayLike, dt: float, dt_ref: float, name: str = "transition matrix", *,
           max_clip: float = MAX_CLIP) -> F64:
    """``Π(Δt) = expm(logm(Π)·Δt/Δt_ref)`` (module docstring), row-stochastic.

    Parameters
    ----------
    Pi : array_like, shape (n, n)
        Row-stochastic transition matrix over ``dt_ref``.
    dt, dt_ref : float
        Target and reference steps (s), ``dt ≥ 0``, ``dt_ref > 0``.
    max_clip : float
        Largest probability mass that may be clipped from one row (no valid generator).

    Raises
    ------
    ValueError
        ``Pi`` not row-stochastic (see :func:`check_stochastic`), a bad (negative, NaN or
        infinite) step, no real logarithm, or more than ``max_clip`` to clip from a row.
    """
    P = check_stochastic(Pi, name)
    if not (np.isfinite(dt) and np.isfinite(dt_ref) and dt_ref > 0 and dt >= 0):
        raise ValueError(f"{name}: need finite dt >= 0 and dt_ref > 0, got dt={dt}, dt_ref={dt_ref}")
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
    # a valid generator leaves round-off only; without one (negative off-diagonal rates) the
    # clipped mass measures the approximation and is bounded, never silently large
    clipped = np.where(out < 0.0, -out, 0.0).sum(axis=1)
    if clipped.max() > max_clip:
        i = int(np.argmax(clipped))
        raise ValueError(f"{name}: has no valid generator, so Pi(dt) at dt/dt_ref = {dt / dt_ref:.4g} has negative "
                         f"entries: {clipped[i]:.3g} of row {i}'s probability would be clipped (max_clip "
                         f"{max_clip:g}); it cannot be re-timed exactly")
    out = np.clip(out, 0.0, None)
    return out / out.sum(axis=1, keepdims=True)


def hmm_to_step(transmat: ArrayLike, dt_s: float, dt_hmm_s: float, name: str = "transmat", *,
                max_clip: float = MAX_CLIP) -> F64:
    """A saved model's ``transmat`` (per HMM sample ``T_hmm``) carried to a filter step ``T``:
    ``Π^{T/T_hmm}`` by :func:`retime` (seed 002 §12 item 3, the IMM's bridge to EKF+HMM). A
    left-to-right maneuver HMM has no valid generator: pass the ``max_clip`` you accept."""
    return retime(transmat, dt_s, dt_hmm_s, name, max_clip=max_clip)


def step_to_hmm(Pi_step: ArrayLike, dt_s: float, dt_hmm_s: float, name: str = "step transition", *,
                max_clip: float = MAX_CLIP) -> F64:
    """The conversion back: a per-step matrix ``Π_T`` to the HMM sample, ``Π_T^{T_hmm/T}``
    (:func:`hmm_to_step` inverted; a converted ``transmat`` converts back)."""
    return retime(Pi_step, dt_hmm_s, dt_s, name, max_clip=max_clip)
