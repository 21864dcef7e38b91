"""Cramér–Rao lower bound of bearing-only tracking on a known trajectory (seed 002 §7, App. D).

Following Ristic & Arulampalam, with no process noise the Fisher information obeys

.. math::

    J_0 = P_0^{-1},\\qquad
    J_{k+1} = F_k^{-T} J_k F_k^{-1} + H_{k+1}^T R^{-1} H_{k+1}

(⚠ the printed ``[HᵀRH]⁻¹`` fixed: R⁻¹, and no inverse of a rank-1 matrix), with ``F_k`` the
CPPV Jacobian (:func:`~pipeline.estimate.models.cppv_jacobian`) and ``H`` the bearing Jacobian
taken on the **true** trajectory. The bound is ``E[(x̂−x)(x̂−x)ᵀ] ≥ J⁻¹``; the range bound
(unstated in the thesis) is ``gᵀ (J⁻¹)_{pos} g`` with ``g = [r_N, r_E]/r``. The acceptance
check of issue 16 takes ``J₀`` = the inverse of the bank's combined initial covariance.

Public API: ``crlb(x_true (…, T, 5), t_s (T,), P0 (…, 5, 5), sigma_rad, *, update_first=False,
process_noise=None) -> Crlb(bound (…, T, 5, 5), std (…, T, 5), range_std (…, T))`` and
``q_floor(x_true, t_s, P0, sigma_rad, process_noise) -> Crlb`` (the error covariance of the best
filter that carries a process noise Q on the noise-free truth).

With the thesis's Q in the filter and a noise-free truth, the filter cannot approach the
noise-free bound once its Q dominates (σ_ω̇² = 5e-6 rad²/s³ alone lets ω wander 0.13°/s in
1 s, against a bound of ~0.001°/s at 120 s); ``process_noise`` gives the bound of a filter
that assumes Q.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .models import BearingMeasurement, cppv_jacobian

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Crlb:
    """``bound`` = J⁻¹ (…, T, 5, 5); ``std`` its square-root diagonal (…, T, 5) in CPPV order
    (r_N, r_E, v, θ, ω); ``range_std`` = √(gᵀ J⁻¹_pos g) (…, T)."""

    bound: F64
    std: F64
    range_std: F64


def crlb(x_true: ArrayLike, t_s: ArrayLike, P0: ArrayLike, sigma_rad: float, *,
         update_first: bool = False, process_noise=None) -> Crlb:
    """The bound along ``x_true`` (module docstring).

    Parameters
    ----------
    x_true : array_like, shape (..., T, 5)
        True relative CPPV states at the steps ``t_s``.
    t_s : array_like, shape (T,)
    P0 : array_like, shape (5, 5) or (..., 5, 5)
        Initial covariance (``J₀ = P₀⁻¹``).
    sigma_rad : float
        Bearing noise std.
    update_first : bool
        Add the information of a bearing at ``t_s[0]`` (off: the bank does not update at its
        initialising step).
    process_noise : callable ``dt -> Q (5, 5)``, optional
        Not the thesis's bound: the posterior CRLB with additive process noise (Tichavský et
        al. 1998), ``J_{k+1} = (Q + F J⁻¹ Fᵀ)⁻¹ + HᵀR⁻¹H``: the best a filter that *assumes*
        this Q can do (e.g. :func:`~pipeline.estimate.models.cppv_process_noise` with the
        bank's σ_v², σ_ω̇²), a diagnostic beside the noise-free bound.
    """
    x, t = _track(x_true, t_s, "crlb")
    b = x.shape[:-2]
    J = np.linalg.inv(np.broadcast_to(np.asarray(P0, dtype=np.float64), b + (5, 5)))
    meas = BearingMeasurement(float(sigma_rad))
    rinv = 1.0 / float(sigma_rad) ** 2

    def info(xk):
        h = meas.jacobian(xk)[..., 0, :]
        return rinv * h[..., :, None] * h[..., None, :]

    if update_first:
        J = J + info(x[..., 0, :])
    T = len(t)
    bound = np.empty(b + (T, 5, 5))
    bound[..., 0, :, :] = np.linalg.inv(J)
    for k in range(1, T):
        F = cppv_jacobian(x[..., k - 1, :], t[k] - t[k - 1])
        if process_noise is None:
            Fi = np.linalg.inv(F)
            J = np.swapaxes(Fi, -1, -2) @ J @ Fi + info(x[..., k, :])
        else:
            Pp = F @ np.linalg.inv(J) @ np.swapaxes(F, -1, -2) + np.asarray(process_noise(t[k] - t[k - 1]))
            J = np.linalg.inv(Pp) + info(x[..., k, :])
        J = 0.5 * (J + np.swapaxes(J, -1, -2))
        bound[..., k, :, :] = np.linalg.inv(J)
    return _result(x, bound)


def _track(x_true: ArrayLike, t_s: ArrayLike, who: str) -> tuple[F64, F64]:
    """``x_true`` (…, T, 5) and ``t_s`` (T,) as float arrays, or one error naming ``who``."""
    x = np.asarray(x_true, dtype=np.float64)
    t = np.asarray(t_s, dtype=np.float64)
    if x.shape[-1] != 5 or x.shape[-2] != len(t):
        raise ValueError(f"{who}: x_true shaped {x.shape}, expected (..., {len(t)}, 5)")
    return x, t


def _result(x: F64, cov: F64) -> Crlb:
    """:class:`Crlb` of covariances ``cov`` (…, T, 5, 5) along ``x``: the std and the range std
    ``√(gᵀ cov_pos g)``, ``g = [r_N, r_E]/r``."""
    std = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    g = x[..., :2] / np.hypot(x[..., 0], x[..., 1])[..., None]
    rvar = np.einsum("...i,...ij,...j->...", g, cov[..., :2, :2], g)
    return Crlb(cov, std, np.sqrt(rvar))


def q_floor(x_true: ArrayLike, t_s: ArrayLike, P0: ArrayLike, sigma_rad: float, process_noise, *,
            update_first: bool = False) -> Crlb:
    r"""The actual error covariance of a Kalman filter that assumes ``Q`` on a noise-free truth.

    The filter is linearised on the **true** trajectory (the best case of any EKF that carries
    ``Q``) and starts with error covariance ``P₀``. Its gain follows its own covariance,

    .. math::

        P^-_{k} = F P_{k-1} F^T + Q,\quad K_k = P^-_k H^T (H P^-_k H^T + R)^{-1},\quad
        P_k = (I - K_k H) P^-_k,

    while the error it actually makes, with no process noise in the truth, has the covariance

    .. math::

        C^-_k = F C_{k-1} F^T,\quad C_k = (I - K_k H) C^-_k (I - K_k H)^T + K_k R K_k^T .

    With ``Q = 0`` the gain is the optimal one and ``C`` equals :func:`crlb` exactly; with
    ``Q > 0`` ``C ≥ J⁻¹`` (the bound holds for every estimator) and ``C ≤ P`` (the filter believes
    in noise the truth has not got). ``C``'s std over √CRLB is what the ideal (truth-linearised,
    unbiased) filter carrying the thesis's Table 4.1 Q reaches in the issue-16 CRLB check (seed
    002 §7, §9): a bank with that Q meets the band only by doing better than this ideal. (A
    biased estimator's spread is bounded by neither: on few realisations, or with a shared bias,
    a bank's sample std can fall below both.)

    Parameters are those of :func:`crlb`; ``process_noise`` (``dt -> Q``) is required.
    Returns a :class:`Crlb` whose ``bound`` is ``C``.
    """
    x, t = _track(x_true, t_s, "q_floor")
    b = x.shape[:-2]
    P = np.array(np.broadcast_to(np.asarray(P0, dtype=np.float64), b + (5, 5)))
    C = P.copy()
    meas = BearingMeasurement(float(sigma_rad))
    R = float(sigma_rad) ** 2
    eye = np.eye(5)

    def update(P, C, xk):
        h = meas.jacobian(xk)[..., 0, :]                           # (..., 5)
        ph = np.einsum("...ij,...j->...i", P, h)
        K = ph / (np.einsum("...i,...i->...", h, ph) + R)[..., None]
        A = eye - K[..., :, None] * h[..., None, :]
        P = A @ P
        C = A @ C @ np.swapaxes(A, -1, -2) + R * K[..., :, None] * K[..., None, :]
        return 0.5 * (P + np.swapaxes(P, -1, -2)), 0.5 * (C + np.swapaxes(C, -1, -2))

    if update_first:
        P, C = update(P, C, x[..., 0, :])
    T = len(t)
    out = np.empty(b + (T, 5, 5))
    out[..., 0, :, :] = C
    for k in range(1, T):
        F = cppv_jacobian(x[..., k - 1, :], t[k] - t[k - 1])
        Ft = np.swapaxes(F, -1, -2)
        P = F @ P @ Ft + np.asarray(process_noise(t[k] - t[k - 1]))
        C = F @ C @ Ft
        P, C = update(P, C, x[..., k, :])
        out[..., k, :, :] = C
    return _result(x, out)
