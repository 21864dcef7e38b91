"""Simulation settings and batch runs of maneuvers, Monte Carlo, switch and calibration scenarios.

Parameters (``simulate`` section of ``datasets/config.yaml``; defaults in brackets):

* ``rate_hz`` [200] — integration and truth rate (≥ 100 Hz); every sensor rate must divide it.
* ``vehicle`` — :class:`pipeline.simulate.quadcopter.QuadParams` (Luukkonen's quadcopter).
* ``disturbance`` — first-order Gauss–Markov acceleration disturbance per NED axis:
  ``tau_s`` [0.5], ``sigma_mps2`` [0.2], ``clip_mps2`` [0.8] (norm bound, see quadcopter.py),
  ``knot_s`` [0.1] (knot spacing of the band-limited process).
* ``start`` — per-run randomisation of the bare maneuvers: ``north_m`` [[-800, 800]],
  ``east_m`` [[-800, 800]] (uniform ranges about the NED origin, the radar's neighbourhood),
  ``heading_deg`` [[-180, 180]] (the command profile is rotated with it). The altitude is the
  maneuver's own start altitude (M1 10 m, M2 180 m, M3 60 m, M4 70 m, M5 40 m).
* ``low_dynamic_pitch_deg`` [-5] — pitch of the low-dynamic padding (thrust holds altitude).
* ``mc`` — padded Monte Carlo runs (seed 000 §2): ``pre_s`` [15], ``post_s`` [per maneuver
  {M1: 25, M2: 20, M3: 20, M4: 20, M5: 25}, each within 20–25], ``ramp_in_s`` [[12, 14.8]],
  ``ramp_out_s`` [[40, 50]], fixed ``start_ne_m`` [[500, -300]] and ``heading_deg`` [30]
  (same start and end for every run, only the disturbance varies). Like the switch scenarios,
  a Monte Carlo scenario is lifted so its nominal path stays above ``switch.min_alt_m``.
* ``switch`` — change scenarios A–D: ``times_s`` [[3, 8, 13]], ``blend_s`` [2],
  ``min_alt_m`` [20] (a scenario whose nominal path dips below is lifted as a whole).
* ``calibration`` — ``hover_alts_m`` [[2.0, 4.5]], ``hover_s`` [8], ``climb_alt_m`` [25]; flown
  from rest on the ground with the horizontal disturbance only.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..config import ConfigError, build, cfield, validate_section
from . import maneuvers as mv
from .quadcopter import QuadParams, Truth, gauss_markov, simulate

_sim = functools.partial(cfield, "simulate")


def post_s_by_maneuver(v: Any) -> dict[str, float]:
    """``mc.post_s``: one number for every maneuver, or ``{M1: s, ...}`` (schema-defaulted)."""
    if isinstance(v, dict):
        return {str(k): float(x) for k, x in v.items()}
    return {m: float(v) for m in mv.MANEUVERS}


def _no_clip(v: Any) -> float | None:
    return None if v in (None, 0) else float(v)


@dataclass(frozen=True, kw_only=True)
class SimSettings:
    """Validated ``simulate`` config (dynamics and scenario parts); defaults from the config
    schema. ``pipeline.config.build(SimSettings, section)`` or :meth:`from_config`."""

    rate_hz: float = _sim("rate_hz")
    vehicle: QuadParams = field(default_factory=QuadParams)
    dist_tau_s: float = _sim("disturbance.tau_s")
    dist_sigma_mps2: float = _sim("disturbance.sigma_mps2")
    dist_clip_mps2: float | None = _sim("disturbance.clip_mps2", convert=_no_clip)
    dist_knot_s: float = _sim("disturbance.knot_s")
    north_m: tuple[float, float] = _sim("start.north_m")
    east_m: tuple[float, float] = _sim("start.east_m")
    heading_deg: tuple[float, float] = _sim("start.heading_deg")
    low_pitch_deg: float = _sim("low_dynamic_pitch_deg")
    mc_pre_s: float = _sim("mc.pre_s")
    mc_post_s: dict = _sim("mc.post_s", convert=post_s_by_maneuver)
    mc_ramp_in: tuple[float, float] = _sim("mc.ramp_in_s")
    mc_ramp_out: tuple[float, float] = _sim("mc.ramp_out_s")
    mc_start_ne_m: tuple[float, float] = _sim("mc.start_ne_m")
    mc_heading_deg: float = _sim("mc.heading_deg")
    switch_times_s: tuple[float, ...] = _sim("switch.times_s")
    switch_blend_s: float = _sim("switch.blend_s")
    switch_min_alt_m: float = _sim("switch.min_alt_m")
    cal_hover_alts_m: tuple[float, ...] = _sim("calibration.hover_alts_m")
    cal_hover_s: float = _sim("calibration.hover_s")
    cal_climb_alt_m: float = _sim("calibration.climb_alt_m")

    def __post_init__(self):
        # the schema checks the file; these guard direct construction as well
        if self.rate_hz < 100:
            raise ConfigError(f"simulate.rate_hz: must be >= 100 Hz (seed 000 §1), got {self.rate_hz}")
        if self.dist_tau_s <= 0 or self.dist_sigma_mps2 < 0 or self.dist_knot_s <= 0:
            raise ConfigError("simulate.disturbance: tau_s and knot_s must be > 0, sigma_mps2 >= 0")
        if any(not 0 < h < 6 for h in self.cal_hover_alts_m) or len(self.cal_hover_alts_m) < 2:
            raise ConfigError("simulate.calibration.hover_alts_m: need >= 2 heights in (0, 6) m")

    @classmethod
    def from_config(cls, sec: Mapping[str, Any] | None) -> "SimSettings":
        """Validate a ``simulate`` section against the schema and build (ConfigError if bad)."""
        return build(cls, validate_section("simulate", sec))

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    def decimation(self, rate_hz: float, key: str) -> int:
        """Integer step from the truth rate to ``rate_hz`` (:func:`decimation`; ``key`` names
        the setting in the error)."""
        return decimation(self.rate_hz, rate_hz, key)


def decimation(truth_rate_hz: float, rate_hz: float, key: str) -> int:
    """Integer step ``truth_rate_hz / rate_hz`` from the truth rate to a slower one.

    Raises
    ------
    ConfigError
        ``<key> <rate> must divide rate_hz <truth rate> (e.g. ...)`` when it does not divide.
    """
    step = truth_rate_hz / rate_hz if rate_hz > 0 else float("nan")
    if not rate_hz > 0 or abs(step - round(step)) > 1e-9:
        fits = [f"{truth_rate_hz / k:g}" for k in range(1, 41) if (truth_rate_hz / k) % 1 == 0]
        raise ConfigError(f"{key} {rate_hz:g} must divide rate_hz {truth_rate_hz:g} (e.g. {', '.join(fits[:8])})")
    return int(round(step))


def maneuvers() -> dict[str, mv.KnotCommand]:
    return mv.default_maneuvers()


def scenario_for(kind: str, settings: SimSettings, name: str | None = None,
                 t_switch: float | None = None) -> mv.Scenario:
    """``kind``: ``maneuver`` (name M1..M5), ``mc`` (name), ``switch`` (name A..D, t_switch),
    ``calibration``."""
    mans = maneuvers()
    # HMM-set runs and the change scenarios start in the Monte Carlo's low-dynamic flight and
    # reach the first command through its ramp-in window, shifted to the run start (seed 000 §2.4)
    lead = {"lead_s": settings.mc_pre_s - settings.mc_ramp_in[0],
            "ramp_s": settings.mc_ramp_in[1] - settings.mc_ramp_in[0], "pitch_deg": settings.low_pitch_deg}
    if kind == "maneuver":
        return mv.maneuver_scenario(name, mans[name], **lead)
    if kind == "mc":
        return mv.padded_scenario(name, mans[name], pre_s=settings.mc_pre_s,
                                  post_s=settings.mc_post_s.get(name, 25.0),
                                  ramp_in=settings.mc_ramp_in, ramp_out=settings.mc_ramp_out,
                                  pitch_deg=settings.low_pitch_deg)
    if kind == "switch":
        return mv.switch_scenario(name, float(t_switch), mans, settings.switch_blend_s, **lead)
    if kind == "calibration":
        return mv.calibration_scenario(hover_alts_m=settings.cal_hover_alts_m, hover_s=settings.cal_hover_s,
                                       climb_alt_m=settings.cal_climb_alt_m, params=settings.vehicle)
    raise ValueError(f"unknown scenario kind {kind!r}")


def time_grid(duration_s: float, rate_hz: float) -> np.ndarray:
    n = int(round(duration_s * rate_hz)) + 1
    return np.arange(n) / rate_hz


def run_scenario(sc: mv.Scenario, settings: SimSettings, n_runs: int, rng: np.random.Generator | int | None,
                 *, fixed_start: tuple[float, float, float] | None = None, disturbance: bool = True,
                 min_alt_m: float | None = None, vel0_zero: bool = False,
                 vertical_disturbance: bool = True) -> Truth:
    """Integrate ``n_runs`` runs of one scenario as one batch.

    Parameters
    ----------
    sc : Scenario
    settings : SimSettings
    n_runs : int
    rng : Generator or int
        Draw order: start N, start E, heading, then the disturbance — fixed, so the same seed
        gives the same runs.
    fixed_start : (north_m, east_m, heading_deg), optional
        Same start and heading for every run (Monte Carlo sets).
    disturbance : bool
        Add the Gauss–Markov disturbance.
    min_alt_m : float, optional
        Lift the whole scenario so the nominal (undisturbed) path stays above this altitude.
    vel0_zero : bool
        Start at rest (calibration take-off) instead of the first command's equilibrium.
    vertical_disturbance : bool
        False zeroes the disturbance's down axis (calibration: an altitude-hold loop rejects
        vertical gusts, so the hovers stay at their heights).
    """
    rng = np.random.default_rng(rng)
    t = time_grid(sc.duration_s, settings.rate_hz)
    cmd = sc.command.sample(t)
    n_e = rng.uniform(*settings.north_m, n_runs), rng.uniform(*settings.east_m, n_runs)
    yaw = np.deg2rad(rng.uniform(*settings.heading_deg, n_runs))
    if fixed_start is not None:
        n_e = np.full(n_runs, fixed_start[0]), np.full(n_runs, fixed_start[1])
        yaw = np.full(n_runs, np.deg2rad(fixed_start[2]))
    alt0 = sc.start_alt_m
    if min_alt_m is not None:
        nominal = simulate(cmd, t, settings.vehicle, yaw0=np.zeros(1), pos0=np.zeros((1, 3)),
                           vel0=np.zeros((1, 3)) if vel0_zero else None)
        lowest = alt0 + float(np.min(-nominal.pos[0, :, 2]))
        alt0 += max(0.0, min_alt_m - lowest)
    pos0 = np.stack([n_e[0], n_e[1], np.full(n_runs, -alt0)], axis=-1)
    dist = None
    if disturbance:
        dist = gauss_markov(n_runs, len(t), settings.dt, settings.dist_tau_s, settings.dist_sigma_mps2,
                            rng, settings.dist_clip_mps2, settings.dist_knot_s)
        if not vertical_disturbance:
            dist[..., 2] = 0.0
    tr = simulate(cmd, t, settings.vehicle, yaw0=yaw, pos0=pos0, dist=dist,
                  vel0=np.zeros((n_runs, 3)) if vel0_zero else None, label=sc.labels_at(t))
    tr.meta.update({"scenario": sc.name, "phases": [(p.t_start, p.t_end, p.label) for p in sc.phases],
                    "start_alt_m": alt0, **sc.meta})
    return tr


def run_named(kind: str, settings: SimSettings, n_runs: int, rng, name: str | None = None,
              t_switch: float | None = None, disturbance: bool = True) -> Truth:
    """Convenience: build the scenario and run it with the kind's conventions (MC: fixed start;
    switch: lifted above ``switch.min_alt_m``; calibration: from rest on the ground)."""
    sc = scenario_for(kind, settings, name, t_switch)
    if kind == "mc":
        return run_scenario(sc, settings, n_runs, rng, disturbance=disturbance,
                            fixed_start=(*settings.mc_start_ne_m, settings.mc_heading_deg),
                            min_alt_m=settings.switch_min_alt_m)
    if kind == "switch":
        return run_scenario(sc, settings, n_runs, rng, disturbance=disturbance,
                            min_alt_m=settings.switch_min_alt_m)
    if kind == "calibration":
        return run_scenario(sc, settings, n_runs, rng, disturbance=disturbance, vel0_zero=True,
                            vertical_disturbance=False)
    return run_scenario(sc, settings, n_runs, rng, disturbance=disturbance)
