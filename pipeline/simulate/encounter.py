"""Bearing-only encounters (issue 16, seed 002 §9): a constant-velocity ownship measures the
bearing to an intruder that orbits (CT) or switches between CT and CV flight.

Conventions (pinned by ``tests/simulate/test_encounter.py``): NED with ``(x, y) = (N, E)``; the
bearing ``β = atan2(ΔE, ΔN)`` (from north toward east); the course θ from north toward east;
``ω = dθ/dt > 0`` a right (clockwise seen from above) turn. The relative CPPV state is
``[r_N, r_E, v, θ, ω]`` with ``r = p_intruder − p_ownship`` (digest §2).

Scenario kinds (``KINDS``): ``orbit`` (CT for ``orbit_s``), ``ct_cv``, ``ct_cv_ct``, ``cv_ct``,
``cv_ct_cv`` (segment durations in ``estimate.bearing_only.scenarios.segments_s``).

Randomisation (digest §9, per run): ``|ω| ~ U(3, 8)°/s`` with a random sign, ``v ~ U(60, 80)``
m/s, ``θ₀ ~ U(0, 360)°``, the initial range ``~ U(1.8, 6.5)`` km at an angle ``U(0, 180)°`` to
the right of the ownship's course, placing either the intruder (default, so ``r₀`` lies in the
bank's 1-10 km grid) or the orbit centre (``place: centre``; a CV-first scenario always places
the intruder). The ownship flies a straight track
at ``ownship_speed_mps`` from the origin.

Seeding: the scenario geometry, the bearing noise and the ownship-velocity noise are three
independent streams, ``default_rng([seed, crc32(part)])`` with ``part`` one of ``geometry``,
``bearing``, ``ownship_velocity``. The kind of scenario, the ownship speed, the bias and the
noise levels do not enter the geometry stream, so **the same seed gives the same scenarios and
the same standard-normal noise draws** for every configuration and sweep value: the runs are
paired across configurations (the sign tests of the study rely on it). Every draw is made for
all runs at once (vectorised over runs); the trajectories are exact (closed-form CT arcs from
:func:`pipeline.estimate.models.turn_coefficients`), not integrated.
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..estimate.models import turn_coefficients, wrap_angle

F64 = NDArray[np.float64]

#: scenario kinds -> mode sequence (1 = CT, 0 = CV)
KINDS: dict[str, tuple[int, ...]] = {
    "orbit": (1,),
    "ct_cv": (1, 0),
    "ct_cv_ct": (1, 0, 1),
    "cv_ct": (0, 1),
    "cv_ct_cv": (0, 1, 0),
}
DEG = np.pi / 180.0


def _stream(seed: int, part: str) -> np.random.Generator:
    return np.random.default_rng([int(seed), zlib.crc32(part.encode())])


@dataclass(frozen=True, kw_only=True)
class ScenarioSettings:
    """The encounter settings (``estimate.bearing_only.scenarios``; see the config schema).

    Angles in degrees as configured; :func:`simulate_encounters` converts to radians.
    """

    dt_s: float = 0.05
    sigma_bearing_deg: float = 0.2
    bias_deg: float = 0.0
    orbit_s: float = 120.0
    segments_s: Mapping[str, tuple[float, ...]] = field(default_factory=lambda: {
        "ct_cv": (120.0, 70.0), "ct_cv_ct": (60.0, 15.0, 125.0), "cv_ct": (30.0, 160.0),
        "cv_ct_cv": (30.0, 30.0, 130.0)})
    second_ct_omega: str = "same"
    omega_deg_s: tuple[float, float] = (3.0, 8.0)
    speed_mps: tuple[float, float] = (60.0, 80.0)
    range_m: tuple[float, float] = (1800.0, 6500.0)
    angle_deg: tuple[float, float] = (0.0, 180.0)
    place: str = "intruder"
    ownship_speed_mps: float = 40.0
    ownship_course_deg: float = 0.0
    ownship_vel_noise_mps: float = 0.0
    sweeps: Mapping[str, tuple[float, ...]] = field(default_factory=lambda: {
        "ownship_vel_noise_mps": (0.0, 1.0, 3.0), "bias_deg": (0.0, 0.2), "ownship_speed_mps": (40.0, 50.0, 60.0)})

    def __post_init__(self) -> None:
        # every instance, however made (from_config, direct construction, replace() with the
        # sweep overrides of simulate_encounters), gets the config path's checks
        check_scenario_settings(self)

    @classmethod
    def from_config(cls, section: Mapping[str, Any] | None) -> "ScenarioSettings":
        """From the ``scenarios`` sub-section (validated and defaulted by the config schema)."""
        from ..config import validate_section

        s = validate_section("estimate.bearing_only.scenarios", dict(section or {}))
        s["segments_s"] = {k: tuple(v) for k, v in s["segments_s"].items()}
        s["sweeps"] = {k: tuple(v) for k, v in s["sweeps"].items()}
        for k in ("omega_deg_s", "speed_mps", "range_m", "angle_deg"):
            s[k] = tuple(s[k])
        return cls(**s)

    def durations(self, kind: str) -> tuple[float, ...]:
        """Segment durations (s) of scenario ``kind``."""
        if kind not in KINDS:
            raise ValueError(f"estimate.bearing_only.scenarios: unknown scenario {kind!r}; known: {', '.join(KINDS)}")
        return (self.orbit_s,) if kind == "orbit" else tuple(self.segments_s[kind])

    def meta(self) -> dict[str, Any]:
        """The settings as plain JSON values (output metadata)."""
        return {k: (dict(v) if isinstance(v, Mapping) else list(v) if isinstance(v, tuple) else v)
                for k, v in self.__dict__.items()}


#: ScenarioSettings' (lo, hi) ranges: U(lo, hi) draws, so lo <= hi
_RANGES = ("omega_deg_s", "speed_mps", "range_m", "angle_deg")


def _plain(v: Any) -> Any:
    """A settings value as the plain Python the config schema validates."""
    if isinstance(v, Mapping):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


def _numbers(v: Any):
    if isinstance(v, Mapping):
        for x in v.values():
            yield from _numbers(x)
    elif isinstance(v, list):
        for x in v:
            yield from _numbers(x)
    elif isinstance(v, (int, float)) and not isinstance(v, bool):
        yield v


def check_scenario_settings(s: ScenarioSettings) -> None:
    """The one check of the encounter settings (``ScenarioSettings.__post_init__``): every value
    against the ``estimate.bearing_only.scenarios`` schema (``place`` and ``second_ct_omega``
    enums, dt_s > 0, σ >= 0, positive durations, |ω|, speeds and ranges...), every number finite
    (the schema's bounds let NaN through), the (lo, hi) ranges ordered and every switching
    scenario's durations given.

    Raises
    ------
    ConfigError (a ValueError)
        One line naming the key and the value.
    """
    from ..config import ConfigError, validate_section

    where = "estimate.bearing_only.scenarios"
    sec = {k: _plain(v) for k, v in s.__dict__.items()}
    validate_section(where, sec)
    for k, v in sec.items():
        if any(not np.isfinite(x) for x in _numbers(v)):
            raise ConfigError(f"{where}.{k}: {v!r} is not finite")
    for k in _RANGES:
        lo, hi = sec[k]
        if lo > hi:
            raise ConfigError(f"{where}.{k}: need low <= high, got {list(sec[k])}")
    missing = [k for k in KINDS if k != "orbit" and k not in sec["segments_s"]]
    if missing:
        raise ConfigError(f"{where}.segments_s: gives no durations for {', '.join(missing)}")


@dataclass(frozen=True)
class Encounter:
    """A set of R simulated encounters over T steps (all arrays in SI units, NED).

    Attributes
    ----------
    kind : str
        Scenario kind (a key of :data:`KINDS`).
    t_s : ndarray, shape (T,)
        Bearing times (s), ``k·dt``.
    dt : float
        Step T (s).
    ownship : ndarray, shape (R, T, 4)
        True ownship ``[N, E, v_N, v_E]``.
    ownship_vel : ndarray, shape (R, T, 2)
        Ownship velocity given to the filter (truth plus ``ownship_vel_noise_mps`` noise).
    intruder : ndarray, shape (R, T, 5)
        True intruder ``[N, E, v, θ, ω]``.
    rel : ndarray, shape (R, T, 5)
        True relative CPPV state ``[r_N, r_E, v, θ, ω]``.
    bearing_true, bearing : ndarray, shape (R, T)
        True and measured bearing (rad, wrapped to [−π, π)).
    mode : ndarray, shape (R, T), int8
        1 where the intruder turns (CT), 0 in CV.
    switch_s : tuple of float
        Segment boundaries (s from the start).
    params : dict of ndarray
        Per-run draws: ``omega`` (rad/s, first CT segment), ``omega2`` (second), ``speed``,
        ``theta0``, ``range0``, ``angle`` (rad).
    meta : dict
        Settings, seed and the sweep values used.
    """

    kind: str
    t_s: F64
    dt: float
    ownship: F64
    ownship_vel: F64
    intruder: F64
    rel: F64
    bearing_true: F64
    bearing: F64
    sigma_bearing: float
    mode: NDArray[np.int8]
    switch_s: tuple[float, ...]
    params: dict[str, F64]
    meta: dict[str, Any]

    @property
    def n_runs(self) -> int:
        return self.rel.shape[0]

    @property
    def range_m(self) -> F64:
        """True range (R, T)."""
        return np.hypot(self.rel[..., 0], self.rel[..., 1])


def draw_geometry(n_runs: int, seed: int, settings: ScenarioSettings) -> dict[str, F64]:
    """The per-run scenario draws (digest §9), identical for every configuration of one seed.

    The draw order is fixed (sign, |ω|, v, θ₀, r₀, angle, second |ω| and its sign), each for all
    runs at once, so run ``i`` of a set of ``n`` runs depends on the seed and on ``n`` only.
    """
    g = _stream(seed, "geometry")
    s = settings
    sign = np.where(g.random(n_runs) < 0.5, -1.0, 1.0)
    omega = sign * g.uniform(*s.omega_deg_s, n_runs) * DEG
    speed = g.uniform(*s.speed_mps, n_runs)
    theta0 = g.uniform(0.0, 2.0 * np.pi, n_runs)
    range0 = g.uniform(*s.range_m, n_runs)
    angle = g.uniform(*s.angle_deg, n_runs) * DEG
    omega2 = np.where(g.random(n_runs) < 0.5, -1.0, 1.0) * g.uniform(*s.omega_deg_s, n_runs) * DEG
    return {"omega": omega, "omega2": omega2 if s.second_ct_omega == "redraw" else omega.copy(),
            "speed": speed, "theta0": theta0, "range0": range0, "angle": angle}


def _arcs(p0: F64, v: F64, th0: F64, omegas: list[F64], durations: tuple[float, ...], modes: tuple[int, ...],
          t: F64) -> tuple[F64, F64, F64]:
    """Exact piecewise CT/CV trajectory: positions (R, T, 2), course (R, T), ω (R, T)."""
    R, T = len(v), len(t)
    pos = np.empty((R, T, 2))
    th = np.empty((R, T))
    om = np.empty((R, T))
    pa, tha, ta = p0.copy(), th0.copy(), 0.0
    bounds = np.cumsum(durations)
    ct_i = 0
    for seg, (dur, m) in enumerate(zip(durations, modes)):
        w = omegas[ct_i] if m == 1 else np.zeros(R)
        ct_i += m
        last = seg == len(durations) - 1
        sel = (t >= ta) & ((t < bounds[seg]) | last)
        tau = t[sel] - ta
        s, c = turn_coefficients(w[:, None], tau[None, :])
        cth, sth = np.cos(tha)[:, None], np.sin(tha)[:, None]
        # N' = N + s v_N − c v_E, E' = E + c v_N + s v_E (models.ct_transition, closed form)
        pos[:, sel, 0] = pa[:, None, 0] + v[:, None] * (s * cth - c * sth)
        pos[:, sel, 1] = pa[:, None, 1] + v[:, None] * (c * cth + s * sth)
        th[:, sel] = tha[:, None] + w[:, None] * tau[None, :]
        om[:, sel] = w[:, None]
        # the state at the segment's end (which need not be a sample time)
        s1, c1 = turn_coefficients(w, dur)
        pa = np.stack([pa[:, 0] + v * (s1 * np.cos(tha) - c1 * np.sin(tha)),
                       pa[:, 1] + v * (c1 * np.cos(tha) + s1 * np.sin(tha))], axis=1)
        tha = tha + w * dur
        ta = float(bounds[seg])
    return pos, th, om


def simulate_encounters(kind: str, n_runs: int, seed: int, settings: ScenarioSettings | None = None, *,
                        fixed_geometry: bool = False, **overrides: Any) -> Encounter:
    """Simulate ``n_runs`` encounters of one scenario kind, vectorised over runs.

    Parameters
    ----------
    kind : str
        ``orbit``, ``ct_cv``, ``ct_cv_ct``, ``cv_ct`` or ``cv_ct_cv``.
    n_runs : int
        Number of runs R (500 in the thesis).
    seed : int
        Master seed: the same seed gives the same scenarios (and noise draws) for every kind,
        sweep value and filter configuration.
    settings : ScenarioSettings, optional
        Defaults from the config schema.
    fixed_geometry : bool
        Every run gets run 0's geometry (one fixed orbit, R noise realisations: the CRLB check).
    **overrides
        Settings fields for this set (the sweeps: ``ownship_vel_noise_mps``, ``bias_deg``,
        ``ownship_speed_mps``).

    Returns
    -------
    Encounter

    Notes
    -----
    The bearing noise is ``σ_β·n`` with ``n ~ N(0, 1)`` from the ``bearing`` stream, the ownship
    velocity noise ``σ_o·m`` with ``m`` from the ``ownship_velocity`` stream; both are drawn for
    (R, T) of the *longest* scenario and cut, so two kinds share the draws of their common steps.
    """
    if isinstance(n_runs, bool) or int(n_runs) != n_runs or n_runs < 1:
        # zero runs gave an empty Encounter whose metrics are NaN means; a negative count numpy's
        # "negative dimensions" error far from the cause
        raise ValueError(f"simulate_encounters: n_runs must be a whole number >= 1, got {n_runs!r}")
    n_runs = int(n_runs)
    s = replace(settings or ScenarioSettings(), **overrides)
    durations = s.durations(kind)
    modes = KINDS[kind]
    geo = draw_geometry(n_runs, seed, s)
    if fixed_geometry:
        geo = {k: np.full(n_runs, v[0]) for k, v in geo.items()}
    dt = float(s.dt_s)
    n_steps = int(round(sum(durations) / dt)) + 1
    t = np.arange(n_steps) * dt

    # ownship: straight line from the origin
    psi = s.ownship_course_deg * DEG
    vo = s.ownship_speed_mps * np.array([np.cos(psi), np.sin(psi)])
    own_pos = t[:, None] * vo[None, :]
    ownship = np.broadcast_to(np.concatenate([own_pos, np.broadcast_to(vo, own_pos.shape)], axis=1),
                              (n_runs, n_steps, 4)).copy()

    # intruder's start: the placed point at range0, angle to the right of the ownship's course
    th0, v, w1 = geo["theta0"], geo["speed"], geo["omega"]
    a = psi + geo["angle"]
    placed = geo["range0"][:, None] * np.stack([np.cos(a), np.sin(a)], axis=1)
    if s.place == "centre" and modes[0] == 1:
        # centre = p + (v/ω)(−sin θ, cos θ) (right of the velocity for ω > 0)
        p0 = placed - (v / w1)[:, None] * np.stack([-np.sin(th0), np.cos(th0)], axis=1)
    else:
        p0 = placed
    pos, th, om = _arcs(p0, v, th0, [w1, geo["omega2"]], durations, modes, t)
    intruder = np.concatenate([pos, np.broadcast_to(v[:, None, None], (n_runs, n_steps, 1)),
                               wrap_angle(th)[..., None], om[..., None]], axis=2)
    rel = intruder.copy()
    rel[..., :2] = pos - ownship[..., :2]
    beta = wrap_angle(np.arctan2(rel[..., 1], rel[..., 0]))

    # noise: drawn for the longest scenario so kinds share their common steps' draws
    n_max = int(round(max(sum(s.durations(k)) for k in KINDS) / dt)) + 1
    nb = _stream(seed, "bearing").standard_normal((n_runs, max(n_max, n_steps)))[:, :n_steps]
    nv = _stream(seed, "ownship_velocity").standard_normal((n_runs, max(n_max, n_steps), 2))[:, :n_steps]
    sig = s.sigma_bearing_deg * DEG
    bearing = wrap_angle(beta + s.bias_deg * DEG + sig * nb)
    own_vel = ownship[..., 2:4] + s.ownship_vel_noise_mps * nv
    bounds = tuple(float(b) for b in np.cumsum(durations)[:-1])
    meta = {"kind": kind, "seed": int(seed), "n_runs": int(n_runs), "fixed_geometry": bool(fixed_geometry),
            "durations_s": list(durations), "settings": s.meta(),
            "units": {"angles": "rad", "omega": "rad/s, > 0 right turn", "frame": "NED (x, y) = (N, E)"}}
    return Encounter(kind=kind, t_s=t, dt=dt, ownship=ownship, ownship_vel=own_vel, intruder=intruder, rel=rel,
                     bearing_true=beta, bearing=bearing, sigma_bearing=sig,
                     mode=np.broadcast_to(np.where(om != 0.0, 1, 0).astype(np.int8), om.shape).copy(),
                     switch_s=bounds, params=geo, meta=meta)


def sweep_sets(kind: str, n_runs: int, seed: int, settings: ScenarioSettings | None = None
               ) -> dict[str, dict[float, Encounter]]:
    """The robustness sweeps over one scenario set: ``{sweep: {value: Encounter}}`` for
    ``ownship_vel_noise_mps``, ``bias_deg`` and ``ownship_speed_mps`` (settings ``sweeps``),
    every set with the same geometry and noise draws."""
    s = settings or ScenarioSettings()
    return {name: {float(x): simulate_encounters(kind, n_runs, seed, s, **{name: float(x)}) for x in values}
            for name, values in s.sweeps.items()}


def encounter_streams(enc: Encounter, run: int = 0) -> dict[str, dict[str, Any]]:
    """One run as canonical streams (for ``FlightLog.from_streams``): ``truth`` with the ownship
    as ``instance`` 0 and the intruder as ``instance`` 1 (NED position and velocity), and
    ``bearing`` from observer 0 (``src`` ``synthetic``)."""
    t_ns = np.round(enc.t_s * 1e9).astype(np.int64)
    n = len(t_ns)
    o, i = enc.ownship[run], enc.intruder[run]
    vi = i[:, 2:3] * np.stack([np.cos(i[:, 3]), np.sin(i[:, 3])], axis=1)
    truth = {"t_ns": np.concatenate([t_ns, t_ns]), "instance": np.repeat(np.array([0, 1], np.uint8), n),
             "src": "simulation", "label": np.concatenate([np.full(n, "ownship"),
                                                           np.where(enc.mode[run] == 1, "CT", "CV")]).astype(object)}
    for k, a in enumerate("ne"):
        truth[f"pos_{a}_m"] = np.concatenate([o[:, k], i[:, k]])
        truth[f"vel_{a}_mps"] = np.concatenate([o[:, 2 + k], vi[:, k]])
    truth["pos_d_m"] = np.zeros(2 * n)
    truth["vel_d_mps"] = np.zeros(2 * n)
    bearing = {"t_ns": t_ns, "instance": np.zeros(n, np.uint8), "src": "synthetic",
               "az_rad": enc.bearing[run], "sigma_rad": np.full(n, enc.sigma_bearing)}
    return {"truth": truth, "bearing": bearing}
