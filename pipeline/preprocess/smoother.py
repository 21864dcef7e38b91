"""GPS track smoothing: the fixes and their measured velocity fused by a Kalman (RTS) smoother.

A log without the autopilot's own navigation solution (a ROS ``NavSatFix`` bag, a MAVLink
``GPS_RAW_INT`` stream) gives positions only as raw fixes, with white noise of a few tenths of
a metre at 5–10 Hz. Interpolated onto the grid and differenced at the maneuver models' 5 Hz
(seed 000 (3.7): the HMMs see position *increments*), 0.3 m of fix noise is ~0.4 m per step
against true increments of centimetres: on the simulated M3 flight the truth-trained models
read M1 on every sample of the raw track and M3 on 96 % of the smoothed one. An autopilot
fuses the same fixes with their Doppler velocity, which is ~10× more precise; this module does
the same offline, per NED axis, with the white-jerk constant-acceleration model of seed 000
§3 (the estimators' model, written here without them: preprocessing sits below ``estimate``
in the import graph):

.. math:: x = [p, v, a]^T,\\quad x_{k+1} = F(\\Delta t)\\,x_k + w_k,\\quad
          F = \\begin{bmatrix}1 & \\Delta t & \\Delta t^2/2\\\\ 0 & 1 & \\Delta t\\\\ 0 & 0 & 1\\end{bmatrix},

.. math:: Q = q\\begin{bmatrix}\\Delta t^5/20 & \\Delta t^4/8 & \\Delta t^3/6\\\\
          \\Delta t^4/8 & \\Delta t^3/3 & \\Delta t^2/2\\\\ \\Delta t^3/6 & \\Delta t^2/2 & \\Delta t\\end{bmatrix},

measured position ``z_p = p + e_p`` (σ from the fix's ``hacc_m``/``vacc_m``, else the
config's) and, where the fix has it, velocity ``z_v = v + e_v``; the forward Kalman filter over
the merged fix and grid times, then the Rauch–Tung–Striebel pass

.. math:: C_k = P_{k|k} F_{k+1}^T P_{k+1|k}^{-1},\\quad
          \\hat x_{k|N} = \\hat x_{k|k} + C_k(\\hat x_{k+1|N} - \\hat x_{k+1|k})

(zero-phase, like the Butterworth default; ``preprocess.causal`` keeps the forward filter
alone). The numba kernel runs one axis at a time over a run of fixes no more than the position
gap limit apart; the grid points between two runs stay gaps, as before.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from ..config import cfield

_gs = functools.partial(cfield, "preprocess.gps_smoother")


@dataclass(frozen=True, kw_only=True)
class GpsSmoother:
    """``preprocess.gps_smoother``: the GPS position source fused with its velocity.

    Parameters
    ----------
    enabled : bool
        Off: the fixes are interpolated onto the grid as they are.
    jerk_psd : float
        White-jerk power spectral density ``q``, m²/s⁵. Default 10 (a jerk of ~3 m/s³ per
        second): on the simulated M1 flight's ROS bag (fixes without velocity, 0.3 m, 10 Hz)
        the velocity RMS against truth is 0.34 / 0.21 / 0.30 / 0.47 m/s at q = 1 / 10 / 100 /
        1000; with the fixes' velocity (DataFlash, tlog) 0.041 m/s at every q.
    sigma_h_m, sigma_v_m : float
        Horizontal / vertical position noise of a fix that reports no ``hacc_m`` / ``vacc_m``.
    sigma_vel_mps : float
        Velocity noise of a fix's measured velocity.
    """

    enabled: bool = _gs("enabled")
    jerk_psd: float = _gs("jerk_psd")
    sigma_h_m: float = _gs("sigma_h_m")
    sigma_v_m: float = _gs("sigma_v_m")
    sigma_vel_mps: float = _gs("sigma_vel_mps")


@numba.njit(cache=True)
def white_jerk_q1(dt, q):  # pragma: no cover - compiled (its py_func is tested and used by estimate)
    """One axis of the white-jerk CA process noise (seed 000 §3 eq. 2.16, §13.7):
    ``Q₁ = q [[dt⁵/20, dt⁴/8, dt³/6], [dt⁴/8, dt³/3, dt²/2], [dt³/6, dt²/2, dt]]``.

    The one copy of the formula: the smoother's kernel calls it compiled, and
    ``pipeline.estimate.models.white_jerk_q`` calls its ``py_func`` (the estimators sit above
    preprocessing in the import graph, so the formula lives here).
    """
    d2 = dt * dt
    d3 = d2 * dt
    Q = np.empty((3, 3))
    Q[0, 0] = q * d3 * d2 / 20.0
    Q[0, 1] = Q[1, 0] = q * d2 * d2 / 8.0
    Q[0, 2] = Q[2, 0] = q * d3 / 6.0
    Q[1, 1] = q * d3 / 3.0
    Q[1, 2] = Q[2, 1] = q * d2 / 2.0
    Q[2, 2] = q * dt
    return Q


@numba.njit(cache=True)
def _rts_axis(t_s, zp, sp, zv, sv, q, smooth):  # pragma: no cover - compiled
    """One axis: forward Kalman filter over the sorted event times ``t_s`` (NaN ``zp``/``zv``:
    no measurement at that event), started at the first position fix ``k0`` (its state and
    variance the prior; earlier events hold that state), then RTS unless ``smooth`` is False.
    Returns (n, 3); all NaN when the axis has no finite position."""
    n = len(t_s)
    xf = np.zeros((n, 3))
    Pf = np.zeros((n, 3, 3))
    xp = np.zeros((n, 3))
    Pp = np.zeros((n, 3, 3))
    F = np.eye(3)
    x = np.zeros(3)
    P = np.zeros((3, 3))
    k0 = 0
    while k0 < n and not np.isfinite(zp[k0]):
        k0 += 1
    if k0 == n:                       # no position on this axis: nothing to say
        return np.full((n, 3), np.nan)
    # start at the first fix: its position, a velocity (if measured) and a loose acceleration;
    # that fix is then in the prior and not applied again
    x[0] = zp[k0]
    P[0, 0] = sp[k0] ** 2
    x[1] = zv[k0] if np.isfinite(zv[k0]) else 0.0
    P[1, 1] = sv ** 2 if np.isfinite(zv[k0]) else 1e4
    P[2, 2] = 1e2
    for k in range(n):
        dt = t_s[k] - t_s[k - 1] if k > 0 else 0.0
        if k > 0:
            F[0, 1] = dt
            F[0, 2] = 0.5 * dt * dt
            F[1, 2] = dt
            x = F @ x
            P = F @ P @ F.T + white_jerk_q1(dt, q)
        xp[k] = x
        Pp[k] = P
        if k > k0:
            for j in range(2):          # scalar updates: position, then velocity
                z = zp[k] if j == 0 else zv[k]
                if not np.isfinite(z):
                    continue
                r = sp[k] ** 2 if j == 0 else sv * sv
                s = P[j, j] + r
                K = P[:, j] / s
                x = x + K * (z - x[j])
                P = P - np.outer(K, P[j, :])
                P = 0.5 * (P + P.T)
        xf[k] = x
        Pf[k] = P
    if not smooth:
        return xf
    xs = xf.copy()
    for k in range(n - 2, -1, -1):
        dt = t_s[k + 1] - t_s[k]
        F[0, 1] = dt
        F[0, 2] = 0.5 * dt * dt
        F[1, 2] = dt
        C = Pf[k] @ F.T @ np.linalg.inv(Pp[k + 1])
        xs[k] = xf[k] + C @ (xs[k + 1] - xp[k + 1])
    return xs


def smooth_track(t_fix_ns: NDArray[np.int64], pos: NDArray, vel: NDArray, sigma_pos: NDArray,
                 t_out_ns: NDArray[np.int64], cfg: GpsSmoother, *, max_gap_ns: float,
                 causal: bool = False) -> NDArray:
    """Smoothed NED position of GPS fixes at the grid times, per axis (module docstring).

    Parameters
    ----------
    t_fix_ns : int64 array (n,)
        Fix times, increasing.
    pos : array (n, 3)
        Fix positions, NED, m.
    vel : array (n, 3)
        Measured velocities, m/s; NaN where a fix has none (per axis).
    sigma_pos : array (n, 3)
        Position noise of each fix and axis, m.
    t_out_ns : int64 array (m,)
        Grid times.
    cfg : GpsSmoother
    max_gap_ns : float
        Fixes further apart than this start a new run (the grid between stays a gap: NaN).
    causal : bool
        Forward filter only (no RTS pass).

    Returns
    -------
    array (m, 3)
        Positions at ``t_out_ns``; NaN outside every run of fixes.
    """
    t_fix = np.asarray(t_fix_ns, dtype=np.int64)
    t_out = np.asarray(t_out_ns, dtype=np.int64)
    out = np.full((len(t_out), 3), np.nan)
    if not len(t_fix):
        return out
    cuts = np.flatnonzero(np.diff(t_fix) > max_gap_ns) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(t_fix)]):
        lo, hi = np.searchsorted(t_out, t_fix[a], "left"), np.searchsorted(t_out, t_fix[b - 1], "right")
        grid = t_out[lo:hi]
        t = np.union1d(t_fix[a:b], grid)
        i_fix = np.searchsorted(t, t_fix[a:b])
        i_out = np.searchsorted(t, grid)
        t_s = (t - t[0]) * 1e-9
        for j in range(3):
            zp = np.full(len(t), np.nan)
            zv = zp.copy()
            sp = np.ones(len(t))
            zp[i_fix], zv[i_fix], sp[i_fix] = pos[a:b, j], vel[a:b, j], sigma_pos[a:b, j]
            xs = _rts_axis(t_s, zp, sp, zv, float(cfg.sigma_vel_mps), float(cfg.jerk_psd), not causal)
            out[lo:hi, j] = xs[i_out, 0]
    return out
