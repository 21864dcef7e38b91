"""Rauch–Tung–Striebel smoother over a :class:`~pipeline.estimate.ekf.FilterTrack`, vectorised
across runs (a backward loop over time only).

With ``F_{k+1}`` mapping step k to k+1 and the filter's predicted ``x⁻_{k+1}, P⁻_{k+1}``
(Rauch, Tung & Striebel 1965; Särkkä 2013, eq. 8.6):

.. math::

    C_k = P^+_k F_{k+1}^T (P^-_{k+1})^{-1},\\quad
    x^s_k = x^+_k + C_k (x^s_{k+1} - x^-_{k+1}),\\quad
    P^s_k = P^+_k + C_k (P^s_{k+1} - P^-_{k+1}) C_k^T

starting from ``x^s_{T−1} = x^+_{T−1}``. For the EKF, ``F`` is the (linear) CA transition, so
this is the exact RTS step on the linearised model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .ekf import FilterTrack

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class SmoothedTrack:
    """Smoothed estimates (runs, time, state) and the smoother gains."""

    t_ns: NDArray[np.int64]
    mean: F64
    cov: F64
    gain: F64


def rts_smooth(track: FilterTrack) -> SmoothedTrack:
    """Smooth a filter run (``run_filter(..., store="all")``).

    Parameters
    ----------
    track : FilterTrack
        With ``mean``, ``cov``, ``pred_mean``, ``pred_cov`` and ``F`` (shape ``(T, n_x, n_x)``,
        shared by the runs, or ``(R, T, n_x, n_x)`` per run).

    Returns
    -------
    SmoothedTrack
        ``mean`` (R, T, n_x), ``cov`` (R, T, n_x, n_x), ``gain`` ``C_k`` (R, T, n_x, n_x), the
        last step's gain zero.
    """
    if track.pred_cov is None or track.cov is None or track.F is None:
        raise ValueError("rts_smooth: the track holds no predicted covariances; run the filter "
                         "with store='all'")
    xf, Pf, xp, Pp, F = track.mean, track.cov, track.pred_mean, track.pred_cov, track.F
    T = xf.shape[1]
    xs, Ps = xf.copy(), Pf.copy()
    C = np.zeros_like(Pf)
    for k in range(T - 2, -1, -1):
        Fk = F[k + 1] if F.ndim == 3 else F[:, k + 1]
        # C = Pf Fᵀ Pp⁻¹  <=>  Cᵀ = Pp⁻¹ F Pf (both covariances symmetric)
        Ck = np.swapaxes(np.linalg.solve(Pp[:, k + 1], Fk @ Pf[:, k]), -1, -2)
        xs[:, k] = xf[:, k] + np.matmul(Ck, (xs[:, k + 1] - xp[:, k + 1])[..., None])[..., 0]
        Ps[:, k] = Pf[:, k] + Ck @ (Ps[:, k + 1] - Pp[:, k + 1]) @ np.swapaxes(Ck, -1, -2)
        C[:, k] = Ck
    return SmoothedTrack(track.t_ns, xs, Ps, C)
