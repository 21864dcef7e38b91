"""Point-mass quadcopter of seed 000 §1 driven by thrust and Euler-angle commands.

Model (Strong 2021, eqs. 2.9–2.13, thrust sign fixed for NED, seed 000 §13.5):

.. math::

    m \\ddot{\\mathbf r} = -\\operatorname{diag}(A_x, A_y, A_z)\\,\\dot{\\mathbf r}
        + m g\\,\\mathbf e_3 - U_1 R_{321}(\\phi, \\theta, \\psi)\\,\\mathbf e_3 + m\\,\\mathbf d(t)

in NED, with :math:`R_{321} = R_z(\\psi) R_y(\\theta) R_x(\\phi)` (body FRD -> NED, the ZYX
sequence of :mod:`pipeline.frames.rotations`) and thrust along −z_B. The controller is
*perfect*: attitude and thrust equal their commands at every instant, so the attitude never
needs integrating and the body rates follow from the (analytic) Euler-angle rates

.. math::

    p = \\dot\\phi - \\dot\\psi \\sin\\theta,\\quad
    q = \\dot\\theta\\cos\\phi + \\dot\\psi \\sin\\phi\\cos\\theta,\\quad
    r = -\\dot\\theta\\sin\\phi + \\dot\\psi\\cos\\phi\\cos\\theta .

``d(t)`` is the band-limited acceleration disturbance (wind, blade flapping; seed 000 §2),
a first-order Gauss–Markov process per NED axis drawn at knots ``knot_s`` apart and joined
smoothly (:func:`gauss_markov`), its norm softly saturated at ``clip_mps2`` so the
|a| ≤ 10 m/s² limit of seed 000 §2 holds on every run.

Integration. The right-hand side is linear in the velocity, so each axis is integrated
*exactly* under a first-order hold of the forcing ``f = (mg e3 − U1 R e3)/m + d`` between grid
points (rate ``rate_hz`` ≥ 100 Hz): with :math:`k = A/m`, step :math:`h`,
:math:`v_{n+1} = e^{-kh} v_n + (\\varphi_1 - \\psi) f_n + \\psi f_{n+1}`, where
:math:`\\varphi_1 = (1-e^{-kh})/k` and :math:`\\psi = \\varphi_1 - (1 - e^{-kh}(1+kh))/(k^2 h)`,
and :math:`r_{n+1} = r_n + [h (f_n + f_{n+1})/2 - (v_{n+1} - v_n)]/k` (because
:math:`v = (f - \\dot v)/k`). The recursion runs as one :func:`scipy.signal.lfilter` call over
all runs of a batch. Truth acceleration is the model's :math:`\\dot v = f - k v` at the grid
points (exact for the integrated trajectory), jerk its central difference.

Parameters (``simulate.vehicle`` in ``datasets/config.yaml``): the thesis defers them to its
references, so the defaults are Luukkonen's quadcopter — ``mass_kg`` 0.468,
``drag_kgps`` [0.25, 0.25, 0.25] (A_x, A_y, A_z), ``inertia_kgm2`` [4.856e-3, 4.856e-3,
8.801e-3], ``arm_m`` 0.225, ``yaw_coeff_m`` 0.0383 (b/k, rotor drag over lift constant:
1.14e-7/2.98e-6), ``max_motor_thrust_N`` (per motor, for PWM scaling; default 2·m·g/4),
``g_mps2`` 9.80665.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import lfilter

from ..config import ConfigError, cfield
from ..frames.rotations import euler_to_quat

F64 = NDArray[np.float64]


_veh = functools.partial(cfield, "simulate.vehicle")


def _triple(v: Any) -> tuple[float, float, float]:
    """One number for all three axes, or three numbers."""
    return tuple(float(x) for x in ([v] * 3 if np.isscalar(v) else v))  # type: ignore[return-value]


@dataclass(frozen=True, kw_only=True)
class QuadParams:
    """Vehicle parameters (SI), ``simulate.vehicle``; defaults from the config schema (see the
    module docstring for their source). Build from a section with
    ``pipeline.config.build(QuadParams, sec)``."""

    mass_kg: float = _veh("mass_kg")
    drag_kgps: tuple[float, float, float] = _veh("drag_kgps", convert=_triple)
    inertia_kgm2: tuple[float, float, float] = _veh("inertia_kgm2", convert=_triple)
    arm_m: float = _veh("arm_m")
    yaw_coeff_m: float = _veh("yaw_coeff_m")
    max_motor_thrust_N: float | None = _veh("max_motor_thrust_N")
    g_mps2: float = _veh("g_mps2")

    def __post_init__(self):
        if self.mass_kg <= 0 or min(self.drag_kgps) < 0:
            raise ConfigError("simulate.vehicle: mass_kg must be > 0 and drag_kgps >= 0")

    @property
    def k(self) -> F64:
        """Drag over mass per NED axis (1/s)."""
        return np.asarray(self.drag_kgps, dtype=float) / self.mass_kg

    @property
    def motor_max_N(self) -> float:
        return self.max_motor_thrust_N or 2.0 * self.mass_kg * self.g_mps2 / 4.0


@dataclass(frozen=True)
class CommandSample:
    """Commands on a time grid: thrust over weight (n_t,), Euler ZYX angles and their rates
    (n_t, 3) rad and rad/s, yaw *relative to the run's heading*."""

    thr: F64
    euler: F64
    euler_rate: F64


@dataclass
class Truth:
    """Integrated batch. Arrays are (n_runs, n_t, ...) except ``t_s`` (n_t,).

    ``pos``/``vel``/``acc``/``jerk`` NED (m, m/s, m/s², m/s³); ``euler`` (roll, pitch, yaw) rad;
    ``quat`` FRD->NED scalar first; ``rates`` body p, q, r (rad/s); ``thrust_N`` (n_runs, n_t);
    ``dist`` the disturbance acceleration (NED); ``label`` (n_t,) maneuver label per sample;
    ``cmd`` the commands (relative yaw); ``yaw0`` (n_runs,) heading (rad).
    """

    t_s: F64
    pos: F64
    vel: F64
    acc: F64
    jerk: F64
    euler: F64
    quat: F64
    rates: F64
    thrust_N: F64
    dist: F64
    yaw0: F64
    label: NDArray[np.object_]
    cmd: CommandSample
    meta: dict = field(default_factory=dict)

    @property
    def n_runs(self) -> int:
        return self.pos.shape[0]

    def acc_heading(self) -> F64:
        """Acceleration in each run's heading frame (forward, right, down)."""
        return rotate_to_heading(self.acc, self.yaw0)

    def subsample(self, step: int) -> "Truth":
        """Every ``step``-th sample (e.g. the 5 Hz dataset truth)."""
        s = slice(None, None, step)
        return Truth(self.t_s[s], self.pos[:, s], self.vel[:, s], self.acc[:, s], self.jerk[:, s],
                     self.euler[:, s], self.quat[:, s], self.rates[:, s], self.thrust_N[:, s],
                     self.dist[:, s], self.yaw0, self.label[s],
                     CommandSample(self.cmd.thr[s], self.cmd.euler[s], self.cmd.euler_rate[s]),
                     dict(self.meta))

    def run(self, i: int) -> "Truth":
        """One run as a batch of one."""
        s = slice(i, i + 1)
        return Truth(self.t_s, self.pos[s], self.vel[s], self.acc[s], self.jerk[s], self.euler[s],
                     self.quat[s], self.rates[s], self.thrust_N[s], self.dist[s], self.yaw0[s],
                     self.label, self.cmd, dict(self.meta))


def rotate_to_heading(v: F64, yaw0: F64) -> F64:
    """NED vectors (n_runs, n_t, 3) -> (forward, right, down) of each run's heading ``yaw0``."""
    c, s = np.cos(yaw0)[:, None], np.sin(yaw0)[:, None]
    out = np.empty_like(v)
    out[..., 0] = c * v[..., 0] + s * v[..., 1]
    out[..., 1] = -s * v[..., 0] + c * v[..., 1]
    out[..., 2] = v[..., 2]
    return out


def gauss_markov(n_runs: int, n_t: int, dt: float, tau_s: float, sigma_mps2: float,
                 rng: np.random.Generator, clip_mps2: float | None = None, knot_s: float = 0.1) -> F64:
    r"""Band-limited first-order Gauss–Markov acceleration disturbance, (n_runs, n_t, 3) NED.

    The process is drawn exactly at knots ``knot_s`` apart (stationary start),

    .. math:: d_{j+1} = \beta d_j + \sigma\sqrt{1-\beta^2}\, w_j,\quad \beta = e^{-\Delta_k/\tau},

    and joined by the quintic smoothstep, so it is band-limited (about 1/(2·knot_s) Hz) and twice
    differentiable: truth jerk stays finite and finite differences of the truth velocity match
    its acceleration. ``clip_mps2`` bounds the norm with the smooth saturation
    :math:`d/(1 + (|d|/c)^8)^{1/8}` (≈ identity below c/2; ≤ c always).
    """
    if sigma_mps2 <= 0:
        return np.zeros((n_runs, n_t, 3))
    t_end = (n_t - 1) * dt
    n_k = int(np.ceil(t_end / knot_s)) + 2
    w = rng.standard_normal((n_runs, n_k, 3))
    beta = float(np.exp(-knot_s / tau_s))
    w[:, 1:] *= sigma_mps2 * np.sqrt(1.0 - beta * beta)
    w[:, 0] *= sigma_mps2
    dk = lfilter([1.0], [1.0, -beta], w, axis=1)
    t = np.arange(n_t) * dt
    j = np.minimum((t / knot_s).astype(np.int64), n_k - 2)
    s = np.clip(t / knot_s - j, 0.0, 1.0)
    sm = (s ** 3 * (10 - 15 * s + 6 * s * s))[None, :, None]
    d = dk[:, j] + (dk[:, j + 1] - dk[:, j]) * sm
    if clip_mps2:
        n = np.linalg.norm(d, axis=-1, keepdims=True) / clip_mps2
        d = d / (1.0 + n ** 8) ** 0.125
    return d


def thrust_direction(euler: F64) -> F64:
    """``R_321(φ, θ, ψ) e3`` (the body z axis in NED), shape (..., 3)."""
    phi, th, psi = euler[..., 0], euler[..., 1], euler[..., 2]
    cphi, sphi, cth, sth, cpsi, spsi = np.cos(phi), np.sin(phi), np.cos(th), np.sin(th), np.cos(psi), np.sin(psi)
    return np.stack([sphi * spsi + cphi * cpsi * sth, cphi * spsi * sth - cpsi * sphi, cphi * cth], axis=-1)


def body_rates(euler: F64, euler_rate: F64) -> F64:
    """Body rates (p, q, r) from ZYX Euler angles and their time derivatives (rad, rad/s)."""
    phi, th = euler[..., 0], euler[..., 1]
    dphi, dth, dpsi = euler_rate[..., 0], euler_rate[..., 1], euler_rate[..., 2]
    return np.stack([
        dphi - dpsi * np.sin(th),
        dth * np.cos(phi) + dpsi * np.sin(phi) * np.cos(th),
        -dth * np.sin(phi) + dpsi * np.cos(phi) * np.cos(th),
    ], axis=-1)


def specific_force_ned(cmd_thr: F64, euler: F64, params: QuadParams) -> F64:
    """Thrust plus gravity per unit mass in NED: ``g e3 − (U1/m) R e3`` with U1 = thr·m·g."""
    g = params.g_mps2
    f = -(cmd_thr * g)[..., None] * thrust_direction(euler)
    f[..., 2] += g
    return f


def equilibrium_velocity(thr: float, euler: F64, params: QuadParams) -> F64:
    """Velocity at which drag balances thrust+gravity for constant commands (zero on a drag-free
    axis). Used as the initial velocity so a run starts without an artificial transient."""
    f = specific_force_ned(np.asarray(thr), np.asarray(euler, dtype=float), params)
    k = params.k
    return np.where(k > 0, f / np.where(k > 0, k, 1.0), 0.0)


def _foh_coefficients(k: float, h: float) -> tuple[float, float, float]:
    """Exact first-order-hold step of ``v' = -k v + f``: (e^{-kh}, weight of f_n, of f_{n+1})."""
    kh = k * h
    if kh < 1e-9:  # drag-free (or negligible) axis: the k -> 0 limit
        return 1.0, h / 2.0, h / 2.0
    e = np.exp(-kh)
    phi1 = -np.expm1(-kh) / k
    psi = phi1 - (1.0 - e * (1.0 + kh)) / (k * k * h)
    return e, phi1 - psi, psi


def integrate(f: F64, v0: F64, r0: F64, dt: float, params: QuadParams) -> tuple[F64, F64, F64]:
    """Integrate ``v' = f − k v``, ``r' = v`` exactly under a first-order hold of ``f``.

    Parameters
    ----------
    f : array, shape (n_runs, n_t, 3)
        Forcing per unit mass (NED, m/s²) on the grid.
    v0, r0 : array, shape (n_runs, 3)
        Initial velocity and position.
    dt : float
        Grid step (s).

    Returns
    -------
    pos, vel, acc : arrays (n_runs, n_t, 3)
    """
    n_runs, n_t, _ = f.shape
    vel = np.empty_like(f)
    pos = np.empty_like(f)
    for ax, k in enumerate(params.k):
        e, b0, b1 = _foh_coefficients(float(k), dt)
        fa = f[..., ax]
        # v_{n+1} - e v_n = b0 f_n + b1 f_{n+1}: an IIR filter over the time axis
        u = np.zeros_like(fa)
        u[:, 1:] = b0 * fa[:, :-1] + b1 * fa[:, 1:]
        u[:, 0] = v0[:, ax]
        vel[..., ax] = lfilter([1.0], [1.0, -e], u, axis=1)
        dv = np.diff(vel[..., ax], axis=1)
        if k * dt < 1e-9:
            dr = dt * vel[:, :-1, ax] + dt * dt * (fa[:, :-1] / 3.0 + fa[:, 1:] / 6.0)
        else:
            dr = (dt * 0.5 * (fa[:, :-1] + fa[:, 1:]) - dv) / k
        pos[:, 0, ax] = r0[:, ax]
        pos[:, 1:, ax] = r0[:, ax, None] + np.cumsum(dr, axis=1)
    acc = f - params.k * vel
    return pos, vel, acc


def uniform_step(t_s: ArrayLike) -> float:
    """The step of a uniform time grid ``t_s`` (s), or one ValueError.

    The FOH integrator and the jerk's finite differences assume one step throughout: a grid
    with fewer than 2 samples, a non-finite time, a non-positive step, or a step that differs
    from the first by more than round-off (``1e-9·dt`` plus a few ulps of the largest |t|, the
    error of ``np.arange(n) / rate``) is refused, naming the first bad row.
    """
    t = np.asarray(t_s, dtype=np.float64)
    if t.ndim != 1 or len(t) < 2:
        raise ValueError(f"simulate: t_s must be a 1-D grid of at least 2 samples, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"simulate: t_s row {int(np.argmax(~np.isfinite(t)))} is not finite")
    dt = float(t[1] - t[0])
    if not dt > 0:
        raise ValueError(f"simulate: t_s must increase; its first step is {dt!r} s")
    tol = 1e-9 * dt + 16 * np.finfo(np.float64).eps * float(np.max(np.abs(t)))
    off = np.abs(np.diff(t) - dt) > tol
    if off.any():
        k = int(np.argmax(off)) + 1
        raise ValueError(f"simulate: t_s must be a uniform grid; the step into row {k} is "
                         f"{float(t[k] - t[k - 1])!r} s, the first {dt!r} s")
    return dt


def simulate(cmd: CommandSample, t_s: F64, params: QuadParams, *, yaw0: F64, pos0: F64,
             dist: F64 | None = None, vel0: F64 | None = None,
             label: NDArray[np.object_] | None = None) -> Truth:
    """Fly a batch of runs through one command profile.

    Parameters
    ----------
    cmd : CommandSample
        Commands on ``t_s`` (yaw relative to the heading).
    t_s : array (n_t,)
        Uniform time grid (s), step = 1/rate, at least 2 samples (:func:`uniform_step`).
    params : QuadParams
    yaw0 : array (n_runs,)
        Heading of each run (rad); the whole command profile is rotated with it.
    pos0 : array (n_runs, 3)
        Start position NED (m).
    dist : array (n_runs, n_t, 3), optional
        Disturbance acceleration (NED); zero when omitted.
    vel0 : array (n_runs, 3), optional
        Initial velocity; default the equilibrium velocity of the first command.
    label : array (n_t,), optional
        Maneuver label per sample.
    """
    n_runs = len(yaw0)
    dt = uniform_step(t_s)
    n_t = len(t_s)
    euler = np.broadcast_to(cmd.euler, (n_runs, n_t, 3)).copy()
    euler[..., 2] += yaw0[:, None]
    euler[..., 2] = np.angle(np.exp(1j * euler[..., 2]))  # wrap to (-pi, pi]
    erate = np.broadcast_to(cmd.euler_rate, (n_runs, n_t, 3))
    thr = np.broadcast_to(cmd.thr, (n_runs, n_t))
    f = specific_force_ned(thr, euler, params)
    if dist is None:
        dist = np.zeros((n_runs, n_t, 3))
    f = f + dist
    if vel0 is None:
        vel0 = np.stack([equilibrium_velocity(cmd.thr[0], euler[i, 0], params) for i in range(n_runs)])
    pos, vel, acc = integrate(f, vel0, np.asarray(pos0, dtype=float), dt, params)
    jerk = np.gradient(acc, dt, axis=1)
    rates = body_rates(euler, erate)
    quat = euler_to_quat(euler[..., 0], euler[..., 1], euler[..., 2])
    if label is None:
        label = np.full(n_t, "", dtype=object)
    return Truth(t_s=t_s, pos=pos, vel=vel, acc=acc, jerk=jerk, euler=euler, quat=quat, rates=rates,
                 thrust_N=thr * params.mass_kg * params.g_mps2, dist=dist, yaw0=np.asarray(yaw0, float),
                 label=np.asarray(label, dtype=object), cmd=cmd)


def motor_thrusts(truth: Truth, params: QuadParams) -> F64:
    """Per-motor thrust (N), (n_runs, n_t, 4), of an X quad that realises the truth's thrust and
    the torques ``τ = I ω̇ + ω × I ω`` of its body rates (perfect control).

    Motor order ArduPilot quad-X: 1 front-right (CCW), 2 rear-left (CCW), 3 front-left (CW),
    4 rear-right (CW). Roll torque τx = l/√2 (−F1 + F2 + F3 − F4); pitch τy = l/√2 (F1 − F2 + F3 − F4);
    yaw τz = c (F1 + F2 − F3 − F4) with c = ``yaw_coeff_m``.
    """
    dt = float(truth.t_s[1] - truth.t_s[0])
    w = truth.rates
    inertia = np.asarray(params.inertia_kgm2)
    wdot = np.gradient(w, dt, axis=1)
    iw = w * inertia
    tau = wdot * inertia + np.cross(w, iw)
    a = params.arm_m / np.sqrt(2.0)
    c = params.yaw_coeff_m
    mix = np.array([[1, 1, 1, 1], [-a, a, a, -a], [a, -a, a, -a], [c, c, -c, -c]], dtype=float)
    rhs = np.concatenate([truth.thrust_N[..., None], tau], axis=-1)
    return rhs @ np.linalg.inv(mix).T
