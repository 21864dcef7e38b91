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

Public API: ``crlb(x_true (…, T, 5), t_s (T,), P0 (…, 5, 5), sigma_rad, *, update_first=False)
-> Crlb(bound (…, T, 5, 5), std (…, T, 5), range_std (…, T))``.
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
         update_first: bool = False) -> Crlb:
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
    """
    x = np.asarray(x_true, dtype=np.float64)
    t = np.asarray(t_s, dtype=np.float64)
    if x.shape[-1] != 5 or x.shape[-2] != len(t):
        raise ValueError(f"crlb: x_true shaped {x.shape}, expected (..., {len(t)}, 5)")
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
        Fi = np.linalg.inv(F)
        J = np.swapaxes(Fi, -1, -2) @ J @ Fi + info(x[..., k, :])
        J = 0.5 * (J + np.swapaxes(J, -1, -2))
        bound[..., k, :, :] = np.linalg.inv(J)
    std = np.sqrt(np.diagonal(bound, axis1=-2, axis2=-1))
    g = x[..., :2] / np.hypot(x[..., 0], x[..., 1])[..., None]
    rvar = np.einsum("...i,...ij,...j->...", g, bound[..., :2, :2], g)
    return Crlb(bound, std, np.sqrt(rvar))
