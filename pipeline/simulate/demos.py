"""Simulated demonstrations with a known intent, for the trajectory learner (issue 15, Build
item 4; seed 004 §10 item 2).

Seed 004 §10 item 2: "run the §4 model with a known reference trajectory to produce M demos.
Time-warp each with τ steps drawn from d and add N(0,Σ^(y)) noise. Check that learned-vs-truth
error is below demo-vs-truth error; this makes 'straighter than any demo' quantitative."

Here the intent is a kinematic reference (speed, heading and flight-path angle profiles, so no
airframe model is needed) on the hidden time grid ``dt/2`` (T ≈ 2N, seed §2 "T = 2 × mean
N^k"); each demo follows the generative model of seed §2 (eqs. 3.2–3.3):

* its sample j sits at the hidden index ``τ_j``, ``τ_0 = 0`` and steps ``τ_{j+1} − τ_j ∈ {1,2,3}``
  with probabilities ``d`` ("P(τ_{j+1}^k|τ_j^k)=d_i^k if the jump is i∈{1,2,3}, else 0", 3.3);
* ``y_j = z_{τ_j} + ω^(y)``, where ω^(y) "covers both sensor error and pilot error": white
  sensor noise plus a pilot deviation, a band-limited first-order Gauss–Markov process
  (:func:`~pipeline.simulate.quadcopter.gauss_markov`, time constant ≥ 1 s) in position, whose
  derivatives enter the velocity and acceleration.

References (seed §7: "straight level flight and vertical hover"; the issue adds a loop):

* ``level_turns``: level flight at constant altitude with two 180° turns (a racetrack);
* ``pull_up``: level flight, a pull-up to the vertical and a hover-like vertical deceleration
  (the seed's hover: "pitch ≈90° for ≥4 s");
* ``loop``: level flight into a full inside loop and out.

The attitude follows the flight path: body x along the velocity, body z against the
specific force's component across it (so a banked turn rolls and a loop's top is inverted);
where that component vanishes (the vertical hover) the previous body z is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..frames.rotations import dcm_to_quat, quat_continuity
from .quadcopter import gauss_markov

F64 = NDArray[np.float64]

#: the simulated references
REFERENCES: tuple[str, ...] = ("level_turns", "pull_up", "loop")
#: the demos' 13 columns (those of :data:`pipeline.align.trajectory.COLUMNS`)
COLUMNS: tuple[str, ...] = (
    "pos_n_m", "pos_e_m", "pos_d_m", "vel_n_mps", "vel_e_mps", "vel_d_mps",
    "acc_n_mps2", "acc_e_mps2", "acc_d_mps2", "q_w", "q_x", "q_y", "q_z",
)
G = 9.80665


@dataclass(frozen=True)
class DemoSimSettings:
    """Settings of the simulated demos (config ``align.simulate``).

    Attributes
    ----------
    dt_s : float
        Demo sample interval (s); seed §5: "SD card ... at ≈10 Hz". The hidden grid is dt/2.
    duration_s : float
        Length of each intended reference (s); demos last about as long.
    speed_mps : float
        Flight speed of the references (m/s).
    altitude_m : float
        Height of the level parts (m above the origin; NED down = −altitude).
    step_probs : tuple of 3 floats
        d = (d_1, d_2, d_3), the τ step probabilities (mean step 2: demos at the reference's pace).
    sensor_sigma : tuple of 4 floats
        White sensor noise std of position (m), velocity (m/s), acceleration (m/s²) and each
        quaternion component (renormalised after).
    pilot_sigma_m : float
        Std of the Gauss–Markov pilot deviation in position (m, per axis).
    pilot_tau_s : float
        Its time constant (s, ≥ 1).
    pilot_knot_s : float
        Knot spacing of the band-limited process (s; :func:`~pipeline.simulate.quadcopter.gauss_markov`).
    yak54_speed_mps : float
        Trimmed airspeed of the Yak54 references (m/s).
    yak54_sensor_sigma : tuple of 3 floats
        The Yak54 demos' extra white noise std: body rates (rad/s), control surfaces (rad) and
        thrust (N); position, velocity and quaternion take ``sensor_sigma``'s.
    yak54_elevator_rad : float
        Peak elevator of the Yak54 pull-up (rad). The model has no pitch stiffness (pitch is
        neutrally stable), so (4.1)'s moment, 0.009 N m at 0.002 rad and 12 m/s, against (4.2)'s
        damping alone pitches the 12 s reference up to ~75° and over the top (50 → 100 m).
    """

    dt_s: float = 0.1
    duration_s: float = 30.0
    speed_mps: float = 15.0
    altitude_m: float = 50.0
    step_probs: tuple[float, float, float] = (0.2, 0.6, 0.2)
    sensor_sigma: tuple[float, float, float, float] = (0.5, 0.3, 0.5, 0.01)
    pilot_sigma_m: float = 1.0
    pilot_tau_s: float = 2.0
    pilot_knot_s: float = 0.5
    yak54_speed_mps: float = 12.0
    yak54_sensor_sigma: tuple[float, float, float] = (0.05, 0.002, 0.05)
    yak54_elevator_rad: float = 0.002

    def __post_init__(self):
        p = np.asarray(self.step_probs, dtype=float)
        if p.shape != (3,) or np.any(p < 0) or not abs(p.sum() - 1.0) < 1e-9:
            raise ValueError(f"align.simulate.step_probs: must be 3 non-negative numbers summing to 1, got {self.step_probs}")
        if not self.pilot_tau_s >= 1.0:
            raise ValueError(f"align.simulate.pilot_tau_s: the pilot deviation's time constant must be >= 1 s, got {self.pilot_tau_s}")
        if len(self.yak54_sensor_sigma) != 3 or min(self.yak54_sensor_sigma) < 0:
            raise ValueError("align.simulate.yak54_sensor_sigma: 3 non-negative stds (rates, surfaces, thrust)")
        for name in ("dt_s", "duration_s", "speed_mps", "pilot_knot_s", "yak54_speed_mps"):
            if not getattr(self, name) > 0:
                raise ValueError(f"align.simulate.{name}: must be > 0, got {getattr(self, name)}")
        if len(self.sensor_sigma) != 4 or min(self.sensor_sigma) < 0 or self.pilot_sigma_m < 0:
            raise ValueError("align.simulate.sensor_sigma: 4 non-negative stds (pos, vel, acc, quaternion); "
                             "pilot_sigma_m >= 0")


@dataclass(frozen=True)
class DemoSet:
    """Simulated demos of one reference with their truth.

    Attributes
    ----------
    intended : ndarray (L, 13)
        The intended trajectory on the hidden grid (``dt_hidden``).
    demos : list of ndarray (N_k, 13)
        The demos, sampled at ``dt``.
    tau_true : list of int ndarray (N_k,)
        Hidden index of each demo sample (the true time warp).
    dt : float
    dt_hidden : float
    reference : str
    columns : tuple of str
    """

    intended: F64
    demos: list
    tau_true: list
    dt: float
    dt_hidden: float
    reference: str
    columns: tuple[str, ...] = COLUMNS


def _smooth(x: F64) -> F64:
    """Quintic smoothstep 0 -> 1 on [0, 1] (clipped)."""
    s = np.clip(x, 0.0, 1.0)
    return s ** 3 * (10 - 15 * s + 6 * s * s)


def _profiles(reference: str, t: F64, duration: float, speed: float) -> tuple[F64, F64, F64]:
    """(speed, heading ψ, flight-path angle γ) profiles of a reference on times ``t``."""
    u = t / duration
    V = np.full_like(t, speed)
    psi = np.zeros_like(t)
    gam = np.zeros_like(t)
    if reference == "level_turns":
        # straight, 180° right turn, straight, 180° right turn, straight (a racetrack)
        psi = np.pi * (_smooth((u - 0.15) / 0.2) + _smooth((u - 0.6) / 0.2))
    elif reference == "pull_up":
        # level, pull up to the vertical (γ → 90°) while slowing to a near hover, hold
        gam = 0.5 * np.pi * _smooth((u - 0.25) / 0.25)
        V = speed * (1.0 - 0.9 * _smooth((u - 0.3) / 0.35))
    elif reference == "loop":
        # level, one full inside loop (γ through 360°), level
        gam = 2.0 * np.pi * _smooth((u - 0.2) / 0.6)
    else:
        raise ValueError(f"simulate_demos: unknown reference {reference!r}; known: {', '.join(REFERENCES)}")
    return V, psi, gam


def _attitude(vel: F64, acc: F64) -> F64:
    """Quaternions (scalar first, body -> NED) with body x along the velocity and body z against
    the specific force across it (the previous body z where that vanishes)."""
    n = len(vel)
    R = np.empty((n, 3, 3))
    zprev = np.array([0.0, 0.0, 1.0])
    g = np.array([0.0, 0.0, G])
    for i in range(n):
        x = vel[i] / np.linalg.norm(vel[i])
        f = acc[i] - g  # specific force (what lift and thrust supply)
        fp = f - (f @ x) * x
        nf = np.linalg.norm(fp)
        z = -fp / nf if nf > 0.5 else zprev - (zprev @ x) * x
        z /= np.linalg.norm(z)
        y = np.cross(z, x)
        R[i] = np.stack([x, y, z], axis=1)
        zprev = z
    return quat_continuity(dcm_to_quat(R))


def intended_trajectory(reference: str, settings: DemoSimSettings = DemoSimSettings()) -> tuple[F64, float]:
    """The intended (L, 13) trajectory of ``reference`` on the hidden grid and its step (s)."""
    dth = settings.dt_s / 2.0
    L = int(round(settings.duration_s / dth)) + 1
    t = np.arange(L) * dth
    V, psi, gam = _profiles(reference, t, settings.duration_s, settings.speed_mps)
    vel = V[:, None] * np.stack([np.cos(gam) * np.cos(psi), np.cos(gam) * np.sin(psi), -np.sin(gam)], axis=1)
    pos = np.zeros((L, 3))
    pos[1:] = np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dth, axis=0)
    pos[:, 2] -= settings.altitude_m
    acc = np.gradient(vel, dth, axis=0, edge_order=2)
    return np.hstack([pos, vel, acc, _attitude(vel, acc)]), dth


def _warp_and_pilot(L: int, p: F64, rng: np.random.Generator, settings: DemoSimSettings) -> tuple[F64, F64]:
    """One demo's time warp over ``L`` hidden steps (τ₀ = 0, steps 1–3 drawn with probabilities
    ``p``, eq. 3.3) and its Gauss–Markov pilot deviation in position (N, 3) on the demo's own
    clock."""
    steps = rng.choice(np.array([1, 2, 3]), size=L, p=p)
    tau = np.concatenate([[0], np.cumsum(steps)])
    tau = tau[tau <= L - 1]
    dev = gauss_markov(1, len(tau), settings.dt_s, settings.pilot_tau_s, settings.pilot_sigma_m, rng,
                       knot_s=settings.pilot_knot_s)[0]
    return tau, dev


def simulate_demos(reference: str, *, n_demos: int = 5, rng: np.random.Generator,
                   settings: DemoSimSettings = DemoSimSettings()) -> DemoSet:
    """Simulate ``n_demos`` demos of ``reference`` (see the module docstring).

    Parameters
    ----------
    reference : {"level_turns", "pull_up", "loop"}
    n_demos : int
        M (seed §2: "M=5, following [2], which calls 5 'sufficient'").
    rng : numpy.random.Generator
        The only source of randomness.
    settings : DemoSimSettings

    Returns
    -------
    DemoSet
    """
    if int(n_demos) < 1:
        raise ValueError(f"simulate_demos: n_demos must be >= 1, got {n_demos}")
    z, dth = intended_trajectory(reference, settings)
    L = len(z)
    p = np.asarray(settings.step_probs, dtype=float)
    sp, sv, sa, sq = settings.sensor_sigma
    demos, taus = [], []
    for _ in range(int(n_demos)):
        tau, dev = _warp_and_pilot(L, p, rng, settings)
        N = len(tau)
        dvel = np.gradient(dev, settings.dt_s, axis=0)
        dacc = np.gradient(dvel, settings.dt_s, axis=0)
        y = z[tau].copy()
        y[:, 0:3] += dev + sp * rng.standard_normal((N, 3))
        y[:, 3:6] += dvel + sv * rng.standard_normal((N, 3))
        y[:, 6:9] += dacc + sa * rng.standard_normal((N, 3))
        q = y[:, 9:13] + sq * rng.standard_normal((N, 4))
        y[:, 9:13] = quat_continuity(q / np.linalg.norm(q, axis=1, keepdims=True))
        demos.append(y)
        taus.append(tau.astype(np.int64))
    return DemoSet(z, demos, taus, float(settings.dt_s), dth, reference)


# -- the seed's airframe: references flown by the Yak54 model ---------------------------------------

#: references flown by the Yak54 model of seed 004 §4 (lift on, :mod:`pipeline.estimate.aircraft`)
#: from a control schedule, for the learner's ``dynamics="yak54"``: the thesis's "straight level
#: flight" (§7) and a pull-up into a climb
YAK54_REFERENCES: tuple[str, ...] = ("yak54_level", "yak54_pull_up")
#: integration substeps per hidden step of the Yak54 references (Euler at dt/20 = 5 ms)
YAK54_SUBSTEPS = 10


def _yak54_controls(reference: str, t: F64, duration: float, trim: F64, settings: DemoSimSettings) -> F64:
    """The control schedule (L, 4): aileron, elevator, rudder (rad), thrust (N) about the trim."""
    u = np.tile(trim[13:17], (len(t), 1))
    if reference == "yak54_level":
        return u
    if reference == "yak54_pull_up":
        # an elevator pulse (up, positive by the (4.1) polynomial) over 0.25–0.45 of the run, the
        # thrust raised smoothly for the climb that follows
        x = t / duration
        u[:, 1] += settings.yak54_elevator_rad * (_smooth((x - 0.25) / 0.1) - _smooth((x - 0.35) / 0.1))
        u[:, 3] *= 1.0 + 0.8 * _smooth((x - 0.25) / 0.2)
        return u
    raise ValueError(f"simulate_demos: unknown reference {reference!r}; known: "
                     f"{', '.join(REFERENCES + YAK54_REFERENCES)}")


def yak54_intended(reference: str, settings: DemoSimSettings = DemoSimSettings()) -> tuple[F64, float]:
    """The intended (L, 17) Yak54 trajectory of ``reference`` on the hidden grid and its step (s).

    From straight-and-level trim at ``yak54_speed_mps`` (:func:`~pipeline.estimate.aircraft.yak54_trim`,
    heading north at ``altitude_m``), the model of seed §4 *with* our lift term is Euler-integrated
    at ``dt/2/YAK54_SUBSTEPS`` under the reference's control schedule; row i holds the state and
    the controls applied over the next hidden step.
    """
    from ..estimate.aircraft import Yak54Params, yak54_step, yak54_trim

    params = Yak54Params()
    dth = settings.dt_s / 2.0
    L = int(round(settings.duration_s / dth)) + 1
    t = np.arange(L) * dth
    x = yak54_trim(settings.yak54_speed_mps, params, altitude_m=settings.altitude_m)
    ctrl = _yak54_controls(reference, t, settings.duration_s, x, settings)
    out = np.empty((L, len(x)))
    h = dth / YAK54_SUBSTEPS
    for i in range(L):
        x = x.copy()
        x[13:17] = ctrl[i]
        out[i] = x
        for _ in range(YAK54_SUBSTEPS):
            x = yak54_step(x, h, params, lift=True)
    if not np.all(np.isfinite(out)):
        raise ValueError(f"simulate_demos: the Yak54 reference {reference!r} diverged (check yak54_elevator_rad)")
    out[:, 6:10] = quat_continuity(out[:, 6:10])
    return out, dth


def simulate_yak54_demos(reference: str, *, n_demos: int = 5, rng: np.random.Generator,
                         settings: DemoSimSettings = DemoSimSettings()) -> DemoSet:
    """``n_demos`` demos of a Yak54 reference (17 columns,
    :data:`~pipeline.estimate.aircraft.YAK54_COLUMNS`), by the generative model of
    :func:`simulate_demos`: time warp by τ steps drawn from ``step_probs``, the Gauss–Markov
    pilot deviation in position (its derivative in velocity) and white sensor noise
    (``sensor_sigma`` for position, velocity and quaternion; ``yak54_sensor_sigma`` for the body
    rates, surfaces and thrust)."""
    from ..estimate.aircraft import YAK54_COLUMNS

    if int(n_demos) < 1:
        raise ValueError(f"simulate_yak54_demos: n_demos must be >= 1, got {n_demos}")
    z, dth = yak54_intended(reference, settings)
    L = len(z)
    p = np.asarray(settings.step_probs, dtype=float)
    sp, sv, _, sq = settings.sensor_sigma
    sr, ss, sf = settings.yak54_sensor_sigma
    demos, taus = [], []
    for _ in range(int(n_demos)):
        tau, dev = _warp_and_pilot(L, p, rng, settings)
        N = len(tau)
        y = z[tau].copy()
        y[:, 0:3] += dev + sp * rng.standard_normal((N, 3))
        y[:, 3:6] += np.gradient(dev, settings.dt_s, axis=0) + sv * rng.standard_normal((N, 3))
        q = y[:, 6:10] + sq * rng.standard_normal((N, 4))
        y[:, 6:10] = quat_continuity(q / np.linalg.norm(q, axis=1, keepdims=True))
        y[:, 10:13] += sr * rng.standard_normal((N, 3))
        y[:, 13:16] += ss * rng.standard_normal((N, 3))
        y[:, 16] += sf * rng.standard_normal(N)
        demos.append(y)
        taus.append(tau.astype(np.int64))
    return DemoSet(z, demos, taus, float(settings.dt_s), dth, reference, tuple(YAK54_COLUMNS))
