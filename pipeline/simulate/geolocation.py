"""Seed-001 target and observer simulator and the geo-location scenarios (digest 001 §7, §9–§11).

Target (digest §7)
------------------
A ground car (D = 0) in one of the five driving modes :data:`~pipeline.estimate.models.DRIVING_MODES`
= STOP, ACCEL, DECEL, COAST, TURN, switching per step by the thesis's derived matrix Π_d
(Table 3.2, :data:`PI_D`, rows renormalised: the printed rows 2, 3 and 5 sum to 0.999). State:
position, heading ψ (from N toward E), speed s. On entering ACCEL or DECEL ``|a| ~ U(accel_mps2)``
along the heading; on entering TURN ``|Ω| ~ U(omega_radps)`` with a random sign (Ω > 0 right),
``|Ω| ≤ s/min_turn_radius_m``. The simulator is not strictly Markov (digest §7): DECEL reaching
s = 0 is forced to STOP, ACCEL at the 80 km/h cap to COAST; a Markov draw of STOP while the car still
moves is not taken (thesis §3.6: "Stopping may only be reached after decelerating to a stop").

Observers (digest §9)
---------------------
Stationary (thesis §6.1: ``[U(±box), U(±box), h]`` ENU → NED) or **mobile**: point masses at a
fixed height with acceleration limit ``a_m`` that orbit the *estimated* target at radius ζ𝓡,
the reference point advancing by ``Δθ = 2 asin(d/(2ζ𝓡))`` with ``d`` = orbit speed × 1 s
(4.50–4.53). The reference rides on the target, whose velocity the thesis takes as estimated
(§4.4.2), so the commanded velocity is the filter's estimated target velocity plus an approach
toward the reference at ``√(2 a_m r)``, the speed that can still brake to it (4.54's braking
distance ``r_d = ‖v‖²/(2a_m)``); no speed limit (the thesis sets none). Thesis Fig. 6.11: "the
UAVs maintain a distance to the target between 60-80 meters"; without the target's velocity in
the command they trail a fast target by ~80 m more. Orbit direction alternates with the
observer index (thesis §6.3), heights stacked in 10 m steps from ``mobile_heights_m``. Yaw
follows the velocity, roll = pitch = 0 (point mass); the gimbal aims at the filter's previous
estimate (4.44–4.46), at the first step at the true target (acquisition assumed).

Detections: the noise-free projection must fall inside the image; the detection is that plus
``N(0, σ_px²)`` per axis, ``σ_px = f tan σ_ψ``.

Initialisation (seed 001 §2.1, "a rough distribution built from the first measurement(s)"):
every particle is the least-squares ray intersection of the first detections re-noised by σ_px
(:func:`~pipeline.estimate.camera.sample_fixes`, digest §3), so the cloud has the spread of a
fix from those detections; the first step then only takes the estimate.

Randomness: each run splits its generator into target, observer-start, per-observer pixel-noise
and filter streams, so the truth and the detections do not depend on N or on the observer count.

Filter: :class:`~pipeline.estimate.pf.ParticleFilter` with the D4 mode models
(:func:`~pipeline.estimate.models.driving_mode_models`), the PF matrix Π_p (Table 6.1,
:data:`PI_P`), systematic resampling at N_eff < N/3, and the multi-observer
:class:`~pipeline.estimate.camera.CameraLikelihood`; §6.1 runs CV (COAST) only. After each
resampling the copies are moved by the regularised PF's Gaussian kernel (digest §13 item 7 asks
for roughening; ``jitter``, :func:`move_after_resampling`). Optionally (``init.collapse_window_s``,
off by default) the cloud is re-initialised from the step's rays when the best particle's
residuals over a window reject it (:class:`~pipeline.estimate.camera.CollapseWindow`).

Metrics (digest §11, D11): ``ε_k = ‖p_k − p̄_k‖`` (3-D), ``η_k = ε_k / mean_u ‖p_k − p^U_{u,k}‖``;
the summaries drop the first second (the thesis's near-zero-error artifact) and pool time and runs.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..config import build, cfield, validate_section
from ..estimate.camera import CameraLikelihood, CollapseWindow, PinholeCamera, camera_to_world, look_at_angles, pack_detections, rot_zyx
from ..estimate.markov import retime
from ..estimate.models import (DRIVING_MODES, GEO_IX_DOWN, GEO_IX_HEADING, GEO_STATE, PfBlocked, PfConstantVelocity, PfDownRandomWalk,
                               driving_mode_models, wrap_angle)
from ..estimate.pf import ParticleFilter
from ..estimate.resample import regularise, roughen

F64 = NDArray[np.float64]

_g = functools.partial(cfield, "estimate.pf.geolocation")

#: Π_d, the target's mode matrix as printed (Table 3.2; rows 2, 3, 5 sum to 0.999)
PI_D_PRINTED: F64 = np.array([[0.995, 0.005, 0.000, 0.000, 0.000],
                              [0.000, 0.992, 0.002, 0.004, 0.001],
                              [0.003, 0.001, 0.991, 0.002, 0.002],
                              [0.000, 0.002, 0.002, 0.995, 0.001],
                              [0.000, 0.003, 0.001, 0.002, 0.993]])
#: Π_p, the filter's matrix (Table 6.1: off-diagonals ×2, rows sum to 1)
PI_P: F64 = np.array([[0.990, 0.010, 0.000, 0.000, 0.000],
                      [0.000, 0.986, 0.004, 0.008, 0.002],
                      [0.006, 0.002, 0.984, 0.004, 0.004],
                      [0.000, 0.004, 0.004, 0.990, 0.002],
                      [0.000, 0.006, 0.002, 0.004, 0.988]])
#: both matrices are per step at this rate (digest §7)
PI_RATE_HZ = 40.0
STOP, ACCEL, DECEL, COAST, TURN = range(5)
#: scenario names (thesis §6.1–§6.5, digest §10)
SCENARIOS = ("base", "maneuvering", "mobile")
#: mobile observers start this far from the target's first position (thesis §6.3: "~200 m")
MOBILE_START_RANGE_M = (150.0, 250.0)


def renormalise_rows(P: Any) -> F64:
    """Rows divided by their sums (Π_d's printed rows miss an "internal change" column)."""
    P = np.asarray(P, dtype=np.float64)
    return P / P.sum(axis=1, keepdims=True)


#: Π_d with rows renormalised, the matrix the target simulator uses
PI_D: F64 = renormalise_rows(PI_D_PRINTED)

#: the filter's move after each resampling (``estimate.pf.geolocation.jitter``): the regularised
#: PF's kernel, Gordon's roughening, or none
JITTERS: tuple[str, ...] = ("regularised", "roughening", "none")


@dataclass(frozen=True)
class GeolocationConfig:
    """``estimate.pf.geolocation`` (rules/schemas/config.schema.yaml), the values we chose; every
    default is the schema's (:func:`~pipeline.config.cfield`)."""

    rate_hz: float = _g("rate_hz")
    focal_px: float = _g("focal_px")
    image_px: tuple[int, int] = _g("image_px")
    sigma_psi_rad: float = _g("sigma_psi_rad")
    n_particles: int = _g("n_particles")
    threshold: float = _g("threshold")
    speed_max_mps: float = _g("speed_max_mps")
    accel_mps2: tuple[float, float] = _g("accel_mps2")
    omega_radps: tuple[float, float] = _g("omega_radps")
    min_turn_radius_m: float = _g("min_turn_radius_m")
    jitter: str = _g("jitter")
    roughening: float = _g("roughening")
    estimate_down: bool = _g("estimate_down")
    noise: Mapping[str, float] = _g("noise")
    init: Mapping[str, float | None] = _g("init")
    observers: Mapping[str, Any] = _g("observers")

    @classmethod
    def from_config(cls, sec: Mapping[str, Any] | None) -> "GeolocationConfig":
        """The section validated and defaulted by the config schema (``estimate.pf.geolocation``:
        an unknown key or a bad value fails with one line naming it)."""
        return build(cls, validate_section("estimate.pf.geolocation", sec))

    @property
    def camera(self) -> PinholeCamera:
        return PinholeCamera(float(self.focal_px), int(self.image_px[0]), int(self.image_px[1]))

    @property
    def sigma_px(self) -> float:
        return self.camera.sigma_px_from_bearing(self.sigma_psi_rad)

    @property
    def dt(self) -> float:
        return 1.0 / float(self.rate_hz)

    def meta(self) -> dict[str, Any]:
        """The chosen values (output metadata), σ_px and the bound ``sin σ_ψ`` included."""
        return {"rate_hz": float(self.rate_hz), "focal_px": float(self.focal_px), "image_px": list(self.image_px),
                "sigma_psi_rad": float(self.sigma_psi_rad), "sigma_px": self.sigma_px,
                "bound_percent": 100.0 * float(np.sin(self.sigma_psi_rad)),
                "n_particles": int(self.n_particles), "threshold": float(self.threshold),
                "speed_max_mps": float(self.speed_max_mps), "accel_mps2": list(self.accel_mps2),
                "omega_radps": list(self.omega_radps), "min_turn_radius_m": float(self.min_turn_radius_m), "jitter": str(self.jitter),
                "roughening": float(self.roughening), "estimate_down": bool(self.estimate_down),
                "noise": dict(self.noise), "init": dict(self.init), "observers": dict(self.observers),
                "mobile_start_range_m": list(MOBILE_START_RANGE_M),
                "pi_d_rows_renormalised": True, "pi_rate_hz": PI_RATE_HZ}


# --- target ---------------------------------------------------------------------------------------
@dataclass
class TargetState:
    """The car: NED position (m), heading ψ (rad, from N toward E), speed (m/s), mode and its parameter."""

    pos: F64
    heading: float
    speed: float
    mode: int
    accel: float = 0.0
    omega: float = 0.0

    @property
    def vel(self) -> F64:
        return np.array([self.speed * np.cos(self.heading), self.speed * np.sin(self.heading), 0.0])


def enter_mode(s: TargetState, mode: int, cfg: GeolocationConfig, rng: np.random.Generator) -> None:
    """Switch ``s`` to ``mode`` and draw the mode's parameter (state kept, digest §7)."""
    s.mode = int(mode)
    s.accel = float(rng.uniform(*cfg.accel_mps2)) if mode in (ACCEL, DECEL) else 0.0
    s.omega = float(rng.uniform(*cfg.omega_radps) * rng.choice([-1.0, 1.0])) if mode == TURN else 0.0
    if mode == STOP:
        s.speed = 0.0


def target_step(s: TargetState, dt: float, Pi: F64 | None, cfg: GeolocationConfig, rng: np.random.Generator) -> None:
    """One step: Markov switch by ``Pi`` (None: no switching), forced switches, then motion."""
    if Pi is not None:
        new = int(np.searchsorted(np.cumsum(Pi[s.mode]), rng.random() * Pi[s.mode].sum(), side="right"))
        new = min(new, Pi.shape[0] - 1)
        if new == STOP and s.speed > 0.0:
            # thesis §3.6: "Stopping may only be reached after decelerating to a stop" and "the
            # previous target state is preserved": a DECEL→STOP draw while still moving keeps
            # braking; STOP is entered by the forced switch below when the speed reaches 0.
            new = s.mode
        if new != s.mode:
            enter_mode(s, new, cfg, rng)
    if s.mode == ACCEL:
        s.speed += s.accel * dt
        if s.speed >= cfg.speed_max_mps:
            s.speed = float(cfg.speed_max_mps)
            enter_mode(s, COAST, cfg, rng)
    elif s.mode == DECEL:
        s.speed -= s.accel * dt
        if s.speed <= 0.0:
            enter_mode(s, STOP, cfg, rng)
    w = 0.0
    if s.mode == TURN:
        cap = s.speed / cfg.min_turn_radius_m
        w = float(np.clip(s.omega, -cap, cap))
    h0 = s.heading
    s.heading = float(wrap_angle(h0 + w * dt))
    hm = h0 + 0.5 * w * dt          # midpoint heading: second-order exact for a constant turn
    s.pos = s.pos + s.speed * dt * np.array([np.cos(hm), np.sin(hm), 0.0])


def initial_target(scenario: str, cfg: GeolocationConfig, rng: np.random.Generator) -> TargetState:
    """§6.1: p₀ = [−30, 10, 0], v = [1.15, 0.96, 0] ENU (CV); §6.2+: p₀, v₀ uniform, random mode."""
    if scenario == "base":
        p = np.array([10.0, -30.0, 0.0])          # ENU [−30, 10, 0] → NED
        v = np.array([0.96, 1.15])                # ENU [1.15, 0.96] → NED
        return TargetState(p, float(np.arctan2(v[1], v[0])), float(np.hypot(*v)), COAST)
    e = rng.uniform(-25.0, 25.0, 2)
    ve = rng.uniform(-10.0, 10.0, 2)
    p = np.array([e[1], e[0], 0.0])
    v = np.array([ve[1], ve[0]])
    s = TargetState(p, float(np.arctan2(v[1], v[0])), float(min(np.hypot(*v), cfg.speed_max_mps)), COAST)
    enter_mode(s, int(rng.integers(5)), cfg, rng)
    if s.mode == DECEL and s.speed <= 0:
        enter_mode(s, STOP, cfg, rng)
    return s


# --- observers ------------------------------------------------------------------------------------
@dataclass
class Observers:
    """O point-mass UAVs: NED positions (O, 3), velocities (O, 3); mobile ones orbit."""

    pos: F64
    vel: F64
    mobile: bool
    direction: F64        # +1 / −1 orbit sense per observer

    @property
    def n(self) -> int:
        return len(self.pos)

    def rotations(self) -> F64:
        """Body→NED: yaw along the horizontal velocity (N when at rest), level (point mass)."""
        sp = np.hypot(self.vel[:, 0], self.vel[:, 1])
        yaw = np.where(sp > 0.1, np.arctan2(self.vel[:, 1], self.vel[:, 0]), 0.0)
        return rot_zyx(yaw, 0.0, 0.0)


def stationary_observers(n: int, cfg: GeolocationConfig, rng: np.random.Generator) -> Observers:
    """Thesis §6.1: ``[U(±box), U(±box), h]`` ENU → NED (D = −h)."""
    box, h = cfg.observers["stationary_box_m"], cfg.observers["stationary_height_m"]
    xy = rng.uniform(-box, box, (n, 2))
    pos = np.column_stack([xy[:, 1], xy[:, 0], np.full(n, -h)])
    return Observers(pos, np.zeros((n, 3)), False, np.ones(n))


def mobile_observers(n: int, target0: F64, cfg: GeolocationConfig, rng: np.random.Generator) -> Observers:
    """Thesis §6.3/§6.5: heights from ``mobile_heights_m`` in 10 m steps, orbit sense alternating."""
    h = cfg.observers["mobile_heights_m"] + 10.0 * np.arange(n)
    # one (n, 2) draw, so the first k observers of an n-observer scene are those of the
    # k-observer scene (the observer sweep adds UAVs to the same scene, common random numbers)
    u = rng.random((n, 2))
    lo, hi = MOBILE_START_RANGE_M
    r = lo + (hi - lo) * u[:, 0]
    b = -np.pi + 2.0 * np.pi * u[:, 1]
    pos = np.column_stack([target0[0] + r * np.cos(b), target0[1] + r * np.sin(b), -h])
    direction = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    return Observers(pos, np.zeros((n, 3)), True, direction)


def observers_step(ob: Observers, target_est: F64, dt: float, cfg: GeolocationConfig,
                   target_vel: F64 | None = None) -> None:
    """Move mobile observers one step toward their orbit reference about ``target_est`` (digest §9).

    The reference (4.49–4.51) rides on the estimated target, so it moves with the target's
    estimated velocity ``target_vel`` (thesis §4.4.2: "the position, p_t, and velocity, v_t, of the
    target are estimated"); the backstepping law ``v_d = (p_{r,k+1} − p_k + K₁e_p)/ΔT`` (4.23)
    tracks that moving reference. Here the commanded velocity is the reference's velocity plus an
    approach along the remaining offset at the speed that can still brake to it,
    ``√(2 a_m ‖e_p‖)`` (4.54's braking distance ``r_d = ‖v‖²/(2a_m)``), and the change of velocity
    per step is limited by ``a_m``. With ``observers.feedforward`` false ``target_vel`` is
    ignored (the first version: the reference approached as if it stood still). The thesis
    limits only the acceleration; ``speed_max_mps`` (default none) optionally caps the commanded
    speed.
    """
    if not ob.mobile:
        return
    c = cfg.observers
    zr, am, vmax, vorb = c["orbit_radius_m"], c["accel_max_mps2"], c["speed_max_mps"], c["orbit_speed_mps"]
    rel = ob.pos[:, :2] - np.asarray(target_est, dtype=np.float64)[None, :2]
    theta = np.arctan2(rel[:, 1], rel[:, 0])
    dtheta = 2.0 * np.arcsin(min(1.0, vorb * 1.0 / (2.0 * zr)))
    ang = theta + ob.direction * dtheta
    ref = np.asarray(target_est)[None, :2] + zr * np.column_stack([np.cos(ang), np.sin(ang)])
    d = ref - ob.pos[:, :2]
    dist = np.hypot(d[:, 0], d[:, 1])
    approach = np.sqrt(2.0 * am * dist)
    with np.errstate(invalid="ignore", divide="ignore"):
        vd = np.where(dist[:, None] > 1e-9, d / np.maximum(dist, 1e-9)[:, None] * approach[:, None], 0.0)
    if c["feedforward"] and target_vel is not None and np.all(np.isfinite(np.asarray(target_vel)[:2])):
        vd = vd + np.asarray(target_vel, dtype=np.float64)[None, :2]
    if vmax is not None:
        sp = np.hypot(vd[:, 0], vd[:, 1])
        vd *= np.minimum(1.0, vmax / np.maximum(sp, 1e-12))[:, None]
    a = (vd - ob.vel[:, :2]) / dt
    an = np.hypot(a[:, 0], a[:, 1])
    a *= np.minimum(1.0, am / np.maximum(an, 1e-12))[:, None]
    ob.pos[:, :2] += ob.vel[:, :2] * dt + 0.5 * a * dt * dt
    ob.vel[:, :2] += a * dt


def observer_poses(ob: Observers, aim_at: F64) -> F64:
    """Camera→world poses (O, 4, 4) with the gimbals aimed at ``aim_at`` (NED)."""
    R = ob.rotations()
    gy, gp = look_at_angles(ob.pos, R, np.broadcast_to(np.asarray(aim_at, dtype=np.float64), ob.pos.shape))
    return camera_to_world(ob.pos, R, gy, gp)


def detect(target: F64, T_wc: F64, cfg: GeolocationConfig,
           rng: np.random.Generator | list[np.random.Generator]) -> F64:
    """(O, 2) pixel detections: noise-free projection in the image + N(0, σ_px²); NaN rows otherwise.

    ``rng`` is one generator or one per observer (then observer ``o``'s noise does not depend
    on how many observers there are).
    """
    cam = cfg.camera
    uv = cam.project(np.asarray(target, dtype=np.float64)[None, :], T_wc)[:, 0, :]
    ok = np.all(np.isfinite(uv), axis=1) & cam.in_image(uv)
    if isinstance(rng, np.random.Generator):
        e = rng.standard_normal(uv.shape)
    else:
        e = np.stack([g.standard_normal(2) for g in rng[:len(uv)]]).reshape(uv.shape)
    noisy = uv + cfg.sigma_px * e
    return np.where(ok[:, None], noisy, np.nan)


# --- the filter -------------------------------------------------------------------------------------
def make_filter(cfg: GeolocationConfig, *, cv_only: bool, n_particles: int | None = None,
                rng: np.random.Generator) -> ParticleFilter:
    """The seed-001 PF: D4 modes + Π_p (or CV only), N_thr = threshold·N, systematic resampling."""
    nz = dict(cfg.noise)
    down = bool(cfg.estimate_down)
    collapse = cfg.init.get("collapse_sigma")
    win_s = cfg.init.get("collapse_window_s")
    window = (CollapseWindow(max(1, int(round(float(win_s) * cfg.rate_hz))), float(cfg.init["collapse_alpha"]))
              if win_s else None)
    lik = CameraLikelihood(cfg.camera, d_index=GEO_IX_DOWN if down else None,
                           reinit_sigma_m=float(cfg.init["sigma_pos_m"]),
                           collapse_sigma=None if collapse is None else float(collapse), window=window)
    if cv_only:
        cv = PfConstantVelocity(nz["coast_sigma_a"])
        models = [PfDownRandomWalk(cv, nz["down_sigma"]) if down else cv]
        Pi = None
    else:
        models = driving_mode_models(**nz, accel=cfg.accel_mps2, omega=cfg.omega_radps, estimate_down=down)
        Pi = PI_P
    # block-wise propagation: the same models, cache-sized blocks at 10⁵–10⁶ particles
    models = [PfBlocked(m) for m in models]
    return ParticleFilter(models, Pi, lik, n_particles=int(n_particles or cfg.n_particles), resample="systematic",
                          threshold=float(cfg.threshold), dt_ref=1.0 / PI_RATE_HZ, rng=rng)


#: roughened components of the geo-location state: N, E, v_N, v_E, D
ROUGHEN_INDEX = (0, 1, 2, 3, GEO_IX_DOWN)


def move_after_resampling(pf: ParticleFilter, jitter: str, cov: F64, roughening: float) -> None:
    """Separate the resampled copies again (digest 001 §13 item 7): ``jitter`` is ``regularised``
    (:func:`~pipeline.estimate.resample.regularise` over :data:`ROUGHEN_INDEX` with ``cov``, the
    weighted covariance before resampling), ``roughening``
    (:func:`~pipeline.estimate.resample.roughen` over the same components with K =
    ``roughening``) or ``none``.

    Why the kernel is the default: with N = 50 at 40 Hz the resampled cloud shrank far below the
    spread its own model implies (run 10 of the §6.1 study, 60 m off for 100 s with all three
    cameras seeing the target: position spread 0.3–2 m, velocity spread 0.1–0.2 m/s, against the
    ~2 m and ~0.6 m/s of a Kalman filter with the same CV noise and detections), and a cloud that
    narrow cannot follow the evidence; roughening scales with that shrunken range. The kernel
    keeps the spread the weights gave the cloud.

    Particles in STOP (the five-mode filter) keep v = 0: the mode holds them at rest (digest D4),
    and a jittered velocity would overwrite the heading they stopped with, along which a later
    ACCEL leaves (digest §7).
    """
    if jitter not in JITTERS:
        raise ValueError(f"geolocation: unknown jitter {jitter!r}; expected one of {', '.join(JITTERS)}")
    v_stop = pf.x[:, 2:4].copy() if pf.K == len(DRIVING_MODES) else None
    if jitter == "regularised":
        pf.x = regularise(pf.x, cov, pf.rng, ROUGHEN_INDEX)
    elif jitter == "roughening":
        pf.x = roughen(pf.x, roughening, pf.rng, ROUGHEN_INDEX)
    if v_stop is not None:
        rest = pf.mode == STOP
        pf.x[rest, 2:4] = v_stop[rest]


def init_filter(pf: ParticleFilter, row: F64, cfg: GeolocationConfig, fallback: F64) -> None:
    """Particles from the first detections (seed 001 §2.1: "a rough distribution built from the
    first measurement(s)"), ``w₀ = 1/N``.

    Positions are :meth:`~pipeline.estimate.camera.CameraLikelihood.sample_positions` draws (the
    rays re-noised by σ_px and intersected, digest §3) plus ``N(0, init.sigma_pos_m²)`` per
    axis; a draw without a fix, or a first step without detections, takes ``fallback`` (the
    true start: acquisition assumed) plus that spread. Velocity ``N(0, init.sigma_vel_mps²)``
    per axis, D ``N(0, init.sigma_down_m²)`` when estimated. The first detections are thereby
    used; :func:`run_once` does not weight by them a second time.
    """
    sp, sv, sd = cfg.init["sigma_pos_m"], cfg.init["sigma_vel_mps"], cfg.init["sigma_down_m"]
    mean = np.zeros(len(GEO_STATE))
    cov = np.diag([0.0, 0.0, sv ** 2, sv ** 2, 0.0, 0.0, 0.0, sd ** 2 if cfg.estimate_down else 0.0, 0.0])
    pf.init(mean=mean, cov=cov, mode_p=None if pf.K > 1 else None)
    pf.x[:, GEO_IX_HEADING] = np.arctan2(pf.x[:, 3], pf.x[:, 2])
    p = (pf.likelihood.sample_positions(row, pf.N, pf.rng) if np.all(np.isfinite(row))
         else np.full((pf.N, 3), np.nan))
    bad = ~np.all(np.isfinite(p[:, :2]), axis=1)
    p[bad, :2] = np.asarray(fallback, dtype=np.float64)[:2]
    pf.x[:, 0:2] = p[:, :2] + sp * pf.rng.standard_normal((pf.N, 2))
    if pf.K > 1:
        # enter each particle's initial mode (draws a, Ω along its velocity, D4)
        for k, m in enumerate(pf.models):
            sel = pf.mode == k
            if np.any(sel) and getattr(m, "enter", None) is not None:
                pf.x[sel] = m.enter(pf.x[sel], pf.rng)


@dataclass(frozen=True)
class RunResult:
    """Per-step series of one run (T,) plus the observers' count and the step times."""

    t_s: F64
    truth: F64           # (T, 3)
    estimate: F64        # (T, 3)
    err_m: F64
    mean_dist_m: F64
    eta: F64
    neff: F64
    mode_p: F64          # (T, K)
    true_mode: NDArray[np.int64]
    step_us: F64
    weight_us: F64
    n_detect: NDArray[np.int64]
    n_reinit: int


def run_once(scenario: str, cfg: GeolocationConfig, rng: np.random.Generator, *, n_observers: int = 3,
             n_particles: int | None = None, duration_s: float = 120.0, roughening: float | None = None) -> RunResult:
    """One closed-loop run: target, observers, detections and the filter stepping together."""
    if scenario not in SCENARIOS:
        raise ValueError(f"geolocation: unknown scenario {scenario!r}; expected one of {', '.join(SCENARIOS)}")
    dt = cfg.dt
    roughening = cfg.roughening if roughening is None else float(roughening)
    T = int(round(duration_s / dt))
    Pi_d = None if scenario == "base" else (PI_D if abs(cfg.rate_hz - PI_RATE_HZ) < 1e-9
                                           else retime(PI_D, dt, 1.0 / PI_RATE_HZ, "Pi_d"))
    # independent streams for the target, the observers' start, each observer's pixel noise and
    # the filter: the truth and the detections do not depend on the filter's draws (N) nor on
    # the observer count, so the particle and observer sweeps compare like with like
    # (common random numbers); the first version drew everything from one generator.
    g_target, g_obs, g_filter, g_det = rng.spawn(4)
    g_pix = g_det.spawn(max(int(n_observers), 1))
    tgt = initial_target(scenario, cfg, g_target)
    ob = (stationary_observers(n_observers, cfg, g_obs) if scenario in ("base", "maneuvering")
          else mobile_observers(n_observers, tgt.pos, cfg, g_obs))
    pf = make_filter(cfg, cv_only=scenario == "base", n_particles=n_particles, rng=g_filter)
    out = {k: np.full(T, np.nan) for k in ("err", "dist", "neff", "step", "wt")}
    truth, est = np.full((T, 3), np.nan), np.full((T, 3), np.nan)
    mode_p = np.full((T, pf.K), np.nan)
    tmode = np.zeros(T, dtype=np.int64)
    ndet = np.zeros(T, dtype=np.int64)
    aim = tgt.pos.copy()
    aim_vel = np.zeros(2)
    for k in range(T):
        if k > 0:
            target_step(tgt, dt, Pi_d, cfg, g_target)
            observers_step(ob, aim, dt, cfg, aim_vel)
        Twc = observer_poses(ob, aim)
        uv = detect(tgt.pos, Twc, cfg, g_pix)
        row = pack_detections(uv, cfg.sigma_px, Twc)
        ndet[k] = int(np.sum(np.all(np.isfinite(uv), axis=1)))
        t0 = time.perf_counter_ns()
        if k == 0:
            # the first detections built the particles (init_filter): the first step only
            # takes the estimate, it does not weight by the same detections again
            init_filter(pf, row, cfg, tgt.pos)
            s = pf.step(0.0, np.full_like(row, np.nan))
        else:
            s = pf.step(dt, row)
        if s.resampled:
            move_after_resampling(pf, cfg.jitter, s.cov, roughening)
        out["step"][k] = (time.perf_counter_ns() - t0) * 1e-3
        if k == 1:
            t1 = time.perf_counter_ns()
            pf.likelihood(pf.x, row) if np.all(np.isfinite(row)) else None
            out["wt"][k] = (time.perf_counter_ns() - t1) * 1e-3
        p = np.array([s.mean[0], s.mean[1], s.mean[GEO_IX_DOWN]])
        truth[k], est[k], mode_p[k], tmode[k] = tgt.pos, p, s.mode_p, tgt.mode
        out["err"][k] = float(np.linalg.norm(tgt.pos - p))
        out["dist"][k] = float(np.mean(np.linalg.norm(ob.pos - tgt.pos[None, :], axis=1)))
        out["neff"][k] = s.neff
        aim = np.array([p[0], p[1], 0.0]) if np.all(np.isfinite(p)) else tgt.pos.copy()
        aim_vel = (np.asarray(s.mean[2:4], dtype=np.float64) if np.all(np.isfinite(s.mean[2:4]))
                   else tgt.vel[:2].copy())
    return RunResult(np.arange(T) * dt, truth, est, out["err"], out["dist"], out["err"] / out["dist"], out["neff"],
                     mode_p, tmode, out["step"], out["wt"], ndet, int(pf.n_reinit))


def run_scenario(scenario: str, cfg: GeolocationConfig, *, n_runs: int, seed: int, n_observers: int = 3,
                 n_particles: int | None = None, duration_s: float = 120.0, tag: str = "",
                 first_run: int = 0) -> list[RunResult]:
    """``n_runs`` independent runs, run ``r`` seeded by ``SeedSequence([seed, crc32(scenario), r])``.

    ``tag`` labels a sweep point and is deliberately not in the seed: run ``r`` of every point
    has the same target, observer start and pixel noise streams (common random numbers).
    ``first_run`` numbers the runs from there (runs ``first_run … first_run + n_runs − 1``), so
    a scenario split across processes gives the same runs as one call.
    """
    import zlib

    # the tag (sweep point) is not part of the seed: every sweep point replays the same runs
    key = zlib.crc32(f"{scenario}".encode())
    return [run_once(scenario, cfg, np.random.default_rng([int(seed), key, r]), n_observers=n_observers,
                     n_particles=n_particles, duration_s=duration_s)
            for r in range(int(first_run), int(first_run) + int(n_runs))]


def lost_for_good(run: RunResult) -> bool:
    """Whether no observer detects the target at the run's last step: the cameras, aimed at the
    estimate, have lost it, and with no detection the cloud only predicts from then on."""
    return bool(len(run.n_detect) and run.n_detect[-1] == 0)


def summarise(runs: list[RunResult], *, skip_s: float = 1.0) -> dict[str, float]:
    """Pooled over time (after ``skip_s``) and runs: mean ε, mean η%, mean distance and the shares
    of time (%) the mean observer distance is below 50 m, within 60–80 m and above 80 m (thesis
    Fig. 6.11), µs per step;
    and, because a run whose cameras lose the target diverges for good and dominates the pooled
    mean, the median over runs of each run's mean η%, the runs lost for good
    (:func:`lost_for_good`) and the pooled η% and ε of the others."""
    if not any(np.any(r.t_s >= skip_s) for r in runs):
        skip_s = 0.0          # runs shorter than the skipped start (tests): keep every step
    keep = [r.t_s >= skip_s for r in runs]
    err = np.concatenate([r.err_m[k] for r, k in zip(runs, keep)])
    eta = np.concatenate([r.eta[k] for r, k in zip(runs, keep)])
    dist = np.concatenate([r.mean_dist_m[k] for r, k in zip(runs, keep)])
    step = np.concatenate([r.step_us[1:] for r in runs])
    lost = np.array([lost_for_good(r) for r in runs])
    run_eta = np.array([np.nanmean(r.eta[k]) if np.any(k) else np.nan for r, k in zip(runs, keep)])
    held = np.concatenate([r.eta[k] for r, k, lo in zip(runs, keep, lost) if not lo] or [np.array([np.nan])])
    held_err = np.concatenate([r.err_m[k] for r, k, lo in zip(runs, keep, lost) if not lo] or [np.array([np.nan])])
    d_ok = dist[np.isfinite(dist)]
    share = (lambda m: float(100 * np.mean(m)) if len(d_ok) else float("nan"))
    return {"eps_m": float(np.nanmean(err)), "eta_pct": float(100 * np.nanmean(eta)),
            "median_eps_m": float(np.nanmedian(err)), "mean_dist_m": float(np.nanmean(dist)),
            "dist_lt_50_pct": share(d_ok < 50.0), "dist_60_80_pct": share((d_ok >= 60.0) & (d_ok <= 80.0)),
            "dist_gt_80_pct": share(d_ok > 80.0),
            "step_us": float(np.nanmean(step)), "n_runs": len(runs),
            "n_reinit": int(sum(r.n_reinit for r in runs)),
            "median_run_eta_pct": float(100 * np.nanmedian(run_eta)) if np.isfinite(run_eta).any() else float("nan"),
            "n_lost": int(lost.sum()),
            "not_lost_eta_pct": float(100 * np.nanmean(held)) if np.isfinite(held).any() else float("nan"),
            "not_lost_eps_m": float(np.nanmean(held_err)) if np.isfinite(held_err).any() else float("nan")}


def per_step_frame(runs: list[RunResult], **labels: Any) -> pd.DataFrame:
    """Per time index, averaged over runs: ε_k, η_k (%), mean distance, N_eff, mode fractions."""
    err = np.stack([r.err_m for r in runs])
    df = pd.DataFrame({"t_s": runs[0].t_s, "eps_m": err.mean(0), "eta_pct": 100 * np.stack([r.eta for r in runs]).mean(0),
                       "mean_dist_m": np.stack([r.mean_dist_m for r in runs]).mean(0),
                       "neff": np.stack([r.neff for r in runs]).mean(0)})
    mp = np.stack([r.mode_p for r in runs]).mean(0)
    names = DRIVING_MODES if mp.shape[1] == len(DRIVING_MODES) else ("COAST",)
    for j, m in enumerate(names):
        df[f"mode_p_{m.lower()}"] = mp[:, j]
    for k, v in labels.items():
        df[k] = v
    return df
