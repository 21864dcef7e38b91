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
alone). Where the log has an accelerometer and an attitude (``gps_smoother.imu``), each axis
carries a fourth state, the accelerometer bias ``b`` (a random walk), and the grid times
measure the acceleration: ``z_a = a + b + e_a`` with ``z_a`` the NED component of
``R(q) f + g e₃`` (a loosely coupled GPS/accelerometer fusion; the attitude is taken as
known, so its error times g is part of ``e_a`` and, slowly varying, of ``b``). The numba kernel runs one axis at a time over a run of fixes no more than the position
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
        second): on the simulated M1 flight's ROS bag (fixes without velocity, 0.3 m, 10 Hz,
        without the accelerometer) the velocity RMS against truth is 0.34 / 0.21 / 0.30 / 0.47
        m/s at q = 1 / 10 / 100 / 1000; with the fixes' velocity (DataFlash, tlog) 0.041 m/s at
        every q.
    sigma_h_m, sigma_v_m : float
        Horizontal / vertical position noise of a fix that reports no ``hacc_m`` / ``vacc_m``.
    sigma_vel_mps : float
        Velocity noise of a fix's measured velocity.
    imu : bool
        Fuse the accelerometer (``R(q) f + g e₃`` on the grid) where the log has one and an
        attitude.
    sigma_acc_mps2 : float
        Noise floor of that acceleration, m/s² (preprocessing raises it to the local noise).
        On the simulated M1 bag, velocity N RMS 0.042 / 0.047 / 0.055 / 0.075 / 0.112 m/s at
        0.1 / 0.3 / 0.5 / 1 / 2; 0.5 leaves room for a real airframe's vibration and a degree
        of attitude error (0.17 m/s²).
    acc_bias_psd, acc_bias_sigma_mps2 : float
        Random-walk PSD (m²/s⁵) and prior σ (m/s²) of each axis's bias state.
    """

    enabled: bool = _gs("enabled")
    jerk_psd: float = _gs("jerk_psd")
    sigma_h_m: float = _gs("sigma_h_m")
    sigma_v_m: float = _gs("sigma_v_m")
    sigma_vel_mps: float = _gs("sigma_vel_mps")
    imu: bool = _gs("imu")
    sigma_acc_mps2: float = _gs("sigma_acc_mps2")
    acc_bias_psd: float = _gs("acc_bias_psd")
    acc_bias_sigma_mps2: float = _gs("acc_bias_sigma_mps2")


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
def _inv_spd4(A, out):  # pragma: no cover - compiled
    """``out = A⁻¹`` for a symmetric positive definite 4 × 4 ``A``: Gauss–Jordan with partial
    pivoting in scalar loops (``np.linalg.inv`` would pull numba's LAPACK bindings into the
    kernel's compile)."""
    M = np.empty((4, 8))
    for i in range(4):
        for j in range(4):
            M[i, j] = A[i, j]
            M[i, 4 + j] = 1.0 if i == j else 0.0
    for c in range(4):
        p = c
        for r in range(c + 1, 4):
            if abs(M[r, c]) > abs(M[p, c]):
                p = r
        if p != c:
            for j in range(8):
                M[c, j], M[p, j] = M[p, j], M[c, j]
        d = M[c, c]
        for j in range(8):
            M[c, j] /= d
        for r in range(4):
            if r != c:
                f = M[r, c]
                if f != 0.0:
                    for j in range(8):
                        M[r, j] -= f * M[c, j]
    for i in range(4):
        for j in range(4):
            out[i, j] = M[i, 4 + j]


@numba.njit(cache=True)
def _mm4(A, B, out, b_transposed):  # pragma: no cover - compiled
    """``out = A B`` (``A Bᵀ`` with ``b_transposed``) for 4 × 4 ``A``, ``B``, in scalar loops
    (numba's ``@`` on small matrices costs seconds of compile)."""
    for i in range(4):
        for j in range(4):
            acc = 0.0
            for m in range(4):
                acc += A[i, m] * (B[j, m] if b_transposed else B[m, j])
            out[i, j] = acc


@numba.njit(cache=True)
def _rts_axis(t_s, zp, sp, zv, sv, za, sa, qb, sb0, q, smooth):  # pragma: no cover - compiled
    """One axis: forward Kalman filter over the sorted event times ``t_s`` (NaN ``zp``/``zv``/
    ``za``: no measurement at that event), started at the first position fix ``k0`` (its state
    and variance the prior; earlier events hold that state), then RTS unless ``smooth`` is False.

    The state is ``[p, v, a, b]``: the white-jerk CA model and an accelerometer bias ``b`` (a
    random walk of PSD ``qb``, prior σ ``sb0``) that only the acceleration measurement
    ``z_a = a + b + e_a`` (σ ``sa``, per event) sees; without one, ``b`` stays apart from ``p, v, a``.
    Returns (n, 4); all NaN when the axis has no finite position.

    The 4 × 4 algebra is written as scalar loops: the same operations as ``F @ P @ F.T`` and
    ``np.outer``, but numba compiles the kernel in about a third of the time (it is compiled on
    a fresh checkout's first run, in every test worker that smooths a track)."""
    n = len(t_s)
    xf = np.zeros((n, 4))
    Pf = np.zeros((n, 4, 4))
    xp = np.zeros((n, 4))
    Pp = np.zeros((n, 4, 4))
    F = np.eye(4)
    T = np.zeros((4, 4))
    x = np.zeros(4)
    x2 = np.zeros(4)
    P = np.zeros((4, 4))
    PH = np.zeros(4)
    k0 = 0
    while k0 < n and not np.isfinite(zp[k0]):
        k0 += 1
    if k0 == n:                       # no position on this axis: nothing to say
        return np.full((n, 4), np.nan)
    # start at the first fix: its position, a velocity (if measured) and a loose acceleration;
    # that fix is then in the prior and not applied again
    x[0] = zp[k0]
    P[0, 0] = sp[k0] ** 2
    x[1] = zv[k0] if np.isfinite(zv[k0]) else 0.0
    P[1, 1] = sv ** 2 if np.isfinite(zv[k0]) else 1e4
    P[2, 2] = 1e2
    P[3, 3] = sb0 * sb0
    for k in range(n):
        if k > 0:
            dt = t_s[k] - t_s[k - 1]
            F[0, 1] = dt
            F[0, 2] = 0.5 * dt * dt
            F[1, 2] = dt
            Q1 = white_jerk_q1(dt, q)
            for i in range(4):        # x = F x
                acc = 0.0
                for j in range(4):
                    acc += F[i, j] * x[j]
                x2[i] = acc
            for i in range(4):
                x[i] = x2[i]
            _mm4(F, P, T, False)      # P = F P Fᵀ + Q
            _mm4(T, F, P, True)
            for i in range(3):
                for j in range(3):
                    P[i, j] += Q1[i, j]
            P[3, 3] += qb * dt
        for i in range(4):              # element copies: numba compiles a row assignment
            xp[k, i] = x[i]             # of a 3-D array (Pp[k] = P) in seconds
            for j in range(4):
                Pp[k, i, j] = P[i, j]
        for jm in range(3):             # scalar updates: position, velocity, acceleration
            z = zp[k] if jm == 0 else (zv[k] if jm == 1 else za[k])
            # the first fix is the prior; an acceleration there is new information
            if not np.isfinite(z) or (k <= k0 and jm < 2):
                continue
            r = sp[k] ** 2 if jm == 0 else (sv * sv if jm == 1 else sa[k] ** 2)
            # H = e_jm (+ e_3 for the acceleration, which measures a + b)
            for i in range(4):
                PH[i] = P[i, jm] + (P[i, 3] if jm == 2 else 0.0)
            s = PH[jm] + (PH[3] if jm == 2 else 0.0) + r
            innov = z - x[jm] - (x[3] if jm == 2 else 0.0)
            for i in range(4):
                x[i] += PH[i] / s * innov
            for i in range(4):
                for j in range(4):
                    P[i, j] -= PH[i] / s * PH[j]
            for i in range(4):
                for j in range(i + 1, 4):
                    m = 0.5 * (P[i, j] + P[j, i])
                    P[i, j] = m
                    P[j, i] = m
        for i in range(4):
            xf[k, i] = x[i]
            for j in range(4):
                Pf[k, i, j] = P[i, j]
    if not smooth:
        return xf
    xs = xf.copy()
    Pinv = np.zeros((4, 4))
    C = np.zeros((4, 4))
    d = np.zeros(4)
    for k in range(n - 2, -1, -1):
        dt = t_s[k + 1] - t_s[k]
        F[0, 1] = dt
        F[0, 2] = 0.5 * dt * dt
        F[1, 2] = dt
        _inv_spd4(Pp[k + 1], Pinv)      # Pp[k + 1] is a view: reading it is cheap to compile
        _mm4(Pf[k], F, T, True)         # C = P_k|k Fᵀ P⁻¹_k+1|k
        _mm4(T, Pinv, C, False)
        for i in range(4):
            d[i] = xs[k + 1, i] - xp[k + 1, i]
        for i in range(4):
            acc = 0.0
            for j in range(4):
                acc += C[i, j] * d[j]
            xs[k, i] = xf[k, i] + acc
    return xs


def smooth_track(t_fix_ns: NDArray[np.int64], pos: NDArray, vel: NDArray, sigma_pos: NDArray,
                 t_out_ns: NDArray[np.int64], cfg: GpsSmoother, *, max_gap_ns: float,
                 causal: bool = False, acc: NDArray | None = None, sigma_acc: NDArray | None = None,
                 full: bool = False) -> NDArray:
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
    acc : array (m, 3), optional
        Measured NED acceleration at the grid times (``a = R f + g``, NaN where none), σ
        ``cfg.sigma_acc_mps2``, each axis with its own bias state (``cfg.acc_bias_psd``,
        ``cfg.acc_bias_sigma_mps2``).
    sigma_acc : array (m, 3) or (3,), optional
        That σ per grid time and axis (or per axis) instead of ``cfg.sigma_acc_mps2``.
    full : bool
        Return position, velocity and acceleration, not position alone.

    Returns
    -------
    array (m, 3), or (m, 3, 3) with ``full`` (``[:, axis, (p, v, a)]``)
        At ``t_out_ns``; NaN outside every run of fixes.
    """
    t_fix = np.asarray(t_fix_ns, dtype=np.int64)
    t_out = np.asarray(t_out_ns, dtype=np.int64)
    out = np.full((len(t_out), 3, 3), np.nan)
    sa_out = np.broadcast_to(np.asarray(cfg.sigma_acc_mps2 if sigma_acc is None else sigma_acc, dtype=np.float64),
                             (len(t_out), 3))
    if len(t_fix):
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
                zv, za = zp.copy(), zp.copy()
                sp, sa = np.ones(len(t)), np.ones(len(t))
                zp[i_fix], zv[i_fix], sp[i_fix] = pos[a:b, j], vel[a:b, j], sigma_pos[a:b, j]
                if acc is not None:
                    za[i_out], sa[i_out] = acc[lo:hi, j], sa_out[lo:hi, j]
                xs = _rts_axis(t_s, zp, sp, zv, float(cfg.sigma_vel_mps), za, sa,
                               float(cfg.acc_bias_psd), float(cfg.acc_bias_sigma_mps2), float(cfg.jerk_psd),
                               not causal)
                out[lo:hi, j] = xs[i_out, :3]
    return out if full else out[:, :, 0]
