"""Simulated sensors: radar, GPS, IMU, barometer, rangefinder, attitude, RC/servo PWM.

Each sensor samples the 100 Hz+ truth at an integer decimation of the truth rate and returns a
canonical stream (``pipeline.io.schema``) with ``t_ns`` relative to the flight start. Noise is
drawn only from the ``rng`` passed in, in a fixed order, so the same seed gives the same bytes.

Parameters (``simulate.sensors`` in ``datasets/config.yaml``; defaults in brackets):

* ``radar`` — seed 000 §3 via :class:`pipeline.estimate.models.RadarModel`: ``site_ned_m``
  [[0, 0, 0]], ``tau_rd_s`` [0], ``rate_hz`` [5], ``sigma_range_m`` [1.5], ``sigma_dcos``
  [45e-6], ``sigma_range_rate_mps`` [0.2], ``sensor_id`` [0].
* ``gps`` — ``rate_hz`` [10] (5–10), white noise ``sigma_h_m`` [0.3], ``sigma_v_m`` [0.5],
  ``sigma_vel_mps`` [0.05]; ``n_sats`` [14]; dropouts ``dropout_count`` [0] gaps of
  ``dropout_s`` [2.0] s placed at random, non-overlapping, inside the flight.
* ``imu`` — ``rate_hz`` [200] (100–400), ``gyro_sigma_radps`` [0.002], ``acc_sigma_mps2`` [0.03],
  constant biases ``gyro_bias_radps`` [[0.001, -0.0005, 0.0008]], ``acc_bias_mps2``
  [[0.02, -0.01, 0.03]], ``temp_degC`` [35]. Specific force ``f_B = Rᵀ(a − g e3)``.
* ``baro`` — ``rate_hz`` [20], white ``sigma_m`` [0.1], ``offset_m`` [1.5], ``drift_mps``
  [0.005] (altitude error ``offset + drift·t``); pressure from the ISA troposphere
  ``p = 101325 (1 − 2.25577e-5 h)^5.25588`` at the origin's height plus the baro altitude.
* ``rangefinder`` — down-facing, ``rate_hz`` [20], ``min_m`` [0.17], ``max_m`` [6.0],
  ``sigma_m`` [0.02]; slant range ``h/(cos φ cos θ)`` over flat ground at NED down 0; valid
  only inside [min, max] (the reading is clipped there, as ArduPilot reports it).
* ``attitude`` — ``rate_hz`` [25], small-angle noise ``sigma_deg`` [0.1] per body axis.
* ``control`` — ``rate_hz`` [10]; sticks from the commands on ArduPilot's 1100–1900 µs range:
  roll/pitch ``1500 + 400·angle/angle_max_deg`` [50], throttle
  ``1100 + 800·(U1/mg)/thr_max`` [2], yaw ``1500 + 400·ψ̇/yaw_rate_max_dps`` [90]; servos 1–4 =
  motor PWM ``1100 + 800·F_i/F_max`` of the quad-X mixer (:func:`quadcopter.motor_thrusts`).
* ``origin`` (top level of ``simulate``) — NED origin ``lat_deg`` [32.5994], ``lon_deg``
  [-85.4897], ``alt_wgs84_m`` [200.0]; ``geoid_undulation_m`` [-29] (geoid height N; MSL = WGS84 − N).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from ..config import ConfigError, build, cfield, typed, validate_section
from ..estimate.models import RadarModel
from ..frames.geodesy import ned_to_geodetic
from ..frames.rotations import quat_multiply, quat_normalize, quat_rotate_inverse
from .quadcopter import QuadParams, Truth, motor_thrusts
from .scenarios import decimation


_sim = functools.partial(cfield, "simulate")


def _sensor(name: str):
    """A ``simulate.sensors.<name>`` dict field, numbers typed by the schema."""
    return _sim(f"sensors.{name}", convert=functools.partial(typed, f"simulate.sensors.{name}"))


@dataclass(frozen=True, kw_only=True)
class SensorSettings:
    """Validated ``simulate.sensors`` (+ ``simulate.origin``); defaults from the config schema.
    Built from the whole ``simulate`` section (:meth:`from_config`)."""

    radar: RadarModel = field(default_factory=RadarModel, metadata={"config_key": "sensors.radar"})
    gps: dict = _sensor("gps")
    imu: dict = _sensor("imu")
    baro: dict = _sensor("baro")
    rangefinder: dict = _sensor("rangefinder")
    attitude: dict = _sensor("attitude")
    control: dict = _sensor("control")
    origin: tuple[float, float, float] = _sim(("origin.lat_deg", "origin.lon_deg", "origin.alt_wgs84_m"))
    geoid_undulation_m: float = _sim("origin.geoid_undulation_m")

    @classmethod
    def from_config(cls, sim_sec: Mapping[str, Any] | None) -> "SensorSettings":
        """Validate a ``simulate`` section against the schema and build (ConfigError if bad)."""
        return build(cls, validate_section("simulate", sim_sec))


def _frame(t_ns: np.ndarray, src: str, cols: dict) -> pd.DataFrame:
    d = {"t_ns": t_ns.astype(np.int64), "instance": np.zeros(len(t_ns), np.uint8), "src": src}
    d.update(cols)
    return pd.DataFrame(d)


def t_ns_of(t_s: np.ndarray) -> np.ndarray:
    """Seconds -> integer ns (rounded; the grid is exact in ns for rates dividing 1e9)."""
    return np.round(np.asarray(t_s) * 1e9).astype(np.int64)


# --- radar ---------------------------------------------------------------------------------

def radar_batch(truth: Truth, model: RadarModel, step: int, rng: np.random.Generator) -> np.ndarray:
    """Radar measurements for all runs: (n_runs, n_samples, 4) = [ρ+τρ̇, u, v, ρ̇] + noise."""
    x = np.concatenate([truth.pos[:, ::step], truth.vel[:, ::step]], axis=-1)
    return model.measure(x, rng)


def radar_stream(truth: Truth, model: RadarModel, step: int, rng: np.random.Generator) -> pd.DataFrame:
    y = radar_batch(truth, model, step, rng)[0]
    t = t_ns_of(truth.t_s[::step])
    return _frame(t, "radar", {"range_m": y[:, 0], "dcos_u": y[:, 1], "dcos_v": y[:, 2],
                               "range_rate_mps": y[:, 3], "sensor_id": np.full(len(t), float(model.sensor_id))})


# --- GPS -------------------------------------------------------------------------------------

def dropout_mask(t_s: np.ndarray, count: int, length_s: float, rng: np.random.Generator) -> np.ndarray:
    """True where the receiver delivers a fix. ``count`` non-overlapping gaps of ``length_s``
    placed uniformly (rejection sampling on the free span) between 1 s and the end − 1 s."""
    keep = np.ones(len(t_s), bool)
    if count <= 0:
        return keep
    t0, t1 = t_s[0] + 1.0, t_s[-1] - 1.0 - length_s
    if t1 - t0 < count * length_s * 2:
        raise ConfigError(f"simulate.sensors.gps: {count} dropouts of {length_s} s do not fit a "
                          f"{t_s[-1] - t_s[0]:.1f} s flight")
    starts: list[float] = []
    while len(starts) < count:
        s = float(rng.uniform(t0, t1))
        if all(abs(s - o) > 1.5 * length_s for o in starts):
            starts.append(s)
    for s in sorted(starts):
        keep &= ~((t_s >= s) & (t_s < s + length_s))
    return keep


def gps_stream(truth: Truth, cfg: dict, origin, undulation: float, step: int,
               rng: np.random.Generator) -> pd.DataFrame:
    s = slice(None, None, step)
    t = truth.t_s[s]
    pos, vel = truth.pos[0, s], truth.vel[0, s]
    n = len(t)
    noise_p = rng.standard_normal((n, 3)) * np.array([cfg["sigma_h_m"], cfg["sigma_h_m"], cfg["sigma_v_m"]])
    noise_v = rng.standard_normal((n, 3)) * cfg["sigma_vel_mps"]
    p = pos + noise_p
    v = vel + noise_v
    lat, lon, h = ned_to_geodetic(p[:, 0], p[:, 1], p[:, 2], *origin)
    keep = dropout_mask(t, int(cfg["dropout_count"]), float(cfg["dropout_s"]), rng)
    df = _frame(t_ns_of(t), "gps", {
        "lat_deg": lat, "lon_deg": lon, "alt_wgs84_m": h, "alt_msl_m": h - undulation,
        "vel_n_mps": v[:, 0], "vel_e_mps": v[:, 1], "vel_d_mps": v[:, 2],
        "fix_type": np.full(n, 3.0), "n_sats": np.full(n, float(cfg["n_sats"])),
        "hacc_m": np.full(n, float(cfg["sigma_h_m"])), "vacc_m": np.full(n, float(cfg["sigma_v_m"])),
    })
    return df[keep].reset_index(drop=True)


# --- IMU -------------------------------------------------------------------------------------

def imu_stream(truth: Truth, cfg: dict, params: QuadParams, step: int, rng: np.random.Generator) -> pd.DataFrame:
    s = slice(None, None, step)
    t = truth.t_s[s]
    q = truth.quat[0, s]
    a = truth.acc[0, s].copy()
    a[:, 2] -= params.g_mps2
    f_b = quat_rotate_inverse(q, a)
    n = len(t)
    gyr = truth.rates[0, s] + np.asarray(cfg["gyro_bias_radps"]) + rng.standard_normal((n, 3)) * cfg["gyro_sigma_radps"]
    acc = f_b + np.asarray(cfg["acc_bias_mps2"]) + rng.standard_normal((n, 3)) * cfg["acc_sigma_mps2"]
    cols = {f"gyr_{ax}_radps": gyr[:, i] for i, ax in enumerate("xyz")}
    cols.update({f"acc_{ax}_mps2": acc[:, i] for i, ax in enumerate("xyz")})
    cols["temp_degC"] = np.full(n, float(cfg["temp_degC"]))
    return _frame(t_ns_of(t), "imu", cols)


# --- barometer ------------------------------------------------------------------------------

def isa_pressure(h_m: np.ndarray) -> np.ndarray:
    """ISA troposphere pressure (Pa) at geopotential height ``h_m``."""
    return 101325.0 * (1.0 - 2.25577e-5 * np.asarray(h_m)) ** 5.25588


def baro_stream(truth: Truth, cfg: dict, origin, undulation: float, step: int,
                rng: np.random.Generator) -> pd.DataFrame:
    s = slice(None, None, step)
    t = truth.t_s[s]
    n = len(t)
    alt = -truth.pos[0, s, 2] + cfg["offset_m"] + cfg["drift_mps"] * t + rng.standard_normal(n) * cfg["sigma_m"]
    press = isa_pressure(origin[2] - undulation + alt)
    return _frame(t_ns_of(t), "baro", {"press_Pa": press, "alt_rel_m": alt,
                                       "temp_degC": np.full(n, float(cfg["temp_degC"]))})


# --- rangefinder ----------------------------------------------------------------------------

def rangefinder_stream(truth: Truth, cfg: dict, step: int, rng: np.random.Generator) -> pd.DataFrame:
    s = slice(None, None, step)
    t = truth.t_s[s]
    n = len(t)
    e = truth.euler[0, s]
    tilt = np.cos(e[:, 0]) * np.cos(e[:, 1])
    dist = np.maximum(-truth.pos[0, s, 2], 0.0) / np.maximum(tilt, 0.05) + rng.standard_normal(n) * cfg["sigma_m"]
    valid = (dist >= cfg["min_m"]) & (dist <= cfg["max_m"])
    dist = np.clip(dist, 0.0, cfg["max_m"])
    return _frame(t_ns_of(t), "rangefinder", {"dist_m": dist, "valid": pd.array(valid, dtype="boolean"),
                                              "orientation": np.full(n, 25.0)})


# --- attitude --------------------------------------------------------------------------------

def attitude_stream(truth: Truth, cfg: dict, step: int, rng: np.random.Generator) -> pd.DataFrame:
    s = slice(None, None, step)
    t = truth.t_s[s]
    n = len(t)
    dth = rng.standard_normal((n, 3)) * np.deg2rad(cfg["sigma_deg"])
    dq = quat_normalize(np.concatenate([np.ones((n, 1)), 0.5 * dth], axis=1))
    q = quat_normalize(quat_multiply(truth.quat[0, s], dq))
    return _frame(t_ns_of(t), "attitude", {f"q_{c}": q[:, i] for i, c in enumerate("wxyz")})


# --- RC / servo ------------------------------------------------------------------------------

def sticks(truth: Truth, cfg: dict) -> dict[str, np.ndarray]:
    """Normalised sticks (n_runs, n_t): ``ail``, ``ele``, ``rud`` in [−1, 1], ``thr`` in [0, 1]."""
    amax = np.deg2rad(cfg["angle_max_deg"])
    c = truth.cmd
    ail = np.clip(c.euler[..., 0] / amax, -1, 1)
    ele = np.clip(c.euler[..., 1] / amax, -1, 1)
    rud = np.clip(c.euler_rate[..., 2] / np.deg2rad(cfg["yaw_rate_max_dps"]), -1, 1)
    thr = np.clip(c.thr / cfg["thr_max"], 0, 1)
    shape = truth.pos.shape[:2]
    return {k: np.broadcast_to(v, shape) for k, v in (("ail", ail), ("ele", ele), ("rud", rud), ("thr", thr))}


def control_stream(truth: Truth, cfg: dict, params: QuadParams, step: int) -> pd.DataFrame:
    s = slice(None, None, step)
    t = truth.t_s[s]
    st = sticks(truth, cfg)
    rc = {
        "rc_1_us": 1500 + 400 * st["ail"][0, s], "rc_2_us": 1500 + 400 * st["ele"][0, s],
        "rc_3_us": 1100 + 800 * st["thr"][0, s], "rc_4_us": 1500 + 400 * st["rud"][0, s],
    }
    rc = {k: np.round(v) for k, v in rc.items()}
    f = motor_thrusts(truth, params)[0, s]
    pwm = np.round(1100 + 800 * np.clip(f / params.motor_max_N, 0, 1))
    rc.update({f"servo_{i + 1}_us": pwm[:, i] for i in range(4)})
    return _frame(t_ns_of(t), "control", rc)


def mode_stream(duration_s: float) -> pd.DataFrame:
    return pd.DataFrame({"t_ns": np.array([0], np.int64), "instance": np.zeros(1, np.uint8), "src": "mode",
                         "mode": pd.array(["STABILIZE"], dtype="string"),
                         "armed": pd.array([True], dtype="boolean")})


def sensor_steps(sensors: SensorSettings, truth_rate_hz: float) -> dict[str, int]:
    """Decimation step of every sensor from the truth rate, ``{sensor: truth_rate / rate}``.

    Raises
    ------
    ConfigError
        ``simulate.sensors.<s>.rate_hz <r> must divide rate_hz <R>`` for the first sensor whose
        rate does not divide the truth rate (checked at workflow start-up too, by
        :func:`pipeline.simulate.run.planned_logs`).
    """
    rates = {"radar": sensors.radar.rate_hz,
             **{k: getattr(sensors, k)["rate_hz"]
                for k in ("gps", "imu", "baro", "rangefinder", "attitude", "control")}}
    return {what: decimation(truth_rate_hz, rate, f"simulate.sensors.{what}.rate_hz")
            for what, rate in rates.items()}


def all_streams(truth: Truth, sensors: SensorSettings, params: QuadParams, truth_rate_hz: float,
                rng: np.random.Generator) -> dict[str, pd.DataFrame]:
    """Every simulated sensor stream of run 0 of ``truth``, in a fixed draw order."""
    steps = sensor_steps(sensors, truth_rate_hz)
    o, und = sensors.origin, sensors.geoid_undulation_m
    return {
        "radar": radar_stream(truth, sensors.radar, steps["radar"], rng),
        "gps": gps_stream(truth, sensors.gps, o, und, steps["gps"], rng),
        "imu": imu_stream(truth, sensors.imu, params, steps["imu"], rng),
        "baro": baro_stream(truth, sensors.baro, o, und, steps["baro"], rng),
        "rangefinder": rangefinder_stream(truth, sensors.rangefinder,
                                          steps["rangefinder"], rng),
        "attitude": attitude_stream(truth, sensors.attitude, steps["attitude"], rng),
        "control": control_stream(truth, sensors.control, params, steps["control"]),
        "mode": mode_stream(float(truth.t_s[-1])),
    }


def truth_stream(truth: Truth, run: int = 0) -> pd.DataFrame:
    """The canonical ``truth`` stream (full truth rate) of one run."""
    cols = {}
    for name, arr in (("pos", truth.pos), ("vel", truth.vel), ("acc", truth.acc), ("jerk", truth.jerk)):
        unit = {"pos": "m", "vel": "mps", "acc": "mps2", "jerk": "mps3"}[name]
        for i, a in enumerate("ned"):
            cols[f"{name}_{a}_{unit}"] = arr[run, :, i]
    for i, c in enumerate("wxyz"):
        cols[f"q_{c}"] = truth.quat[run, :, i]
    for i, a in enumerate("xyz"):
        cols[f"gyr_{a}_radps"] = truth.rates[run, :, i]
    cols["label"] = pd.array(list(truth.label), dtype="string")
    return _frame(t_ns_of(truth.t_s), "simulation", cols)


def labels_table(truth: Truth) -> pd.DataFrame:
    """The canonical ``labels`` stream from the scenario phases."""
    ph = truth.meta.get("phases", [])
    return pd.DataFrame({
        "t_start_ns": np.array([round(a * 1e9) for a, _, _ in ph], np.int64),
        "t_end_ns": np.array([round(b * 1e9) for _, b, _ in ph], np.int64),
        "label": pd.array([lab for _, _, lab in ph], dtype="string"),
        "source": pd.array(["simulation_truth"] * len(ph), dtype="string"),
    })
