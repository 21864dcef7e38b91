"""The canonical flight-log schema: the contract between ingest and every later stage.

Implements style.md §3.2. Every stream is a tidy wide table, one row per sample of one sensor
instance, with the common columns ``t_ns`` (int64 ns since the log's first sample), ``instance``
(uint8) and ``src`` (dictionary-encoded source message/topic), optionally ``t_boot_ns`` (nullable
int64, the source's own boot-time stamp). Units are in the column names (SI; degrees only in
``_deg`` columns); the world frame is NED, the body frame FRD; quaternions are Hamilton,
scalar-first, body FRD -> NED.

This module is the single place where streams, columns, dtypes, units and frames are declared,
for the canonical streams and for every derived table of every stage (``state``,
``segments``, ``calibration``, the simulated sets and summary, the flight manifest,
``classification``, ``model_evaluation``): :data:`TABLES` maps each name to its columns, and
:func:`columns`, :func:`empty`, :func:`conform` and :func:`cast` are the one way to shape a
table. Readers build loose DataFrames and call :func:`conform` (through ``FlightLog.from_streams``),
which orders and casts columns, adds every missing column (NaN / NA), sorts stably by
(``instance``, ``t_ns``) and rejects unknown columns, so a typo in a reader fails loudly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from .lazy import pandas as pd  # imported on first use: the Arrow path below needs none
import pyarrow as pa

#: 1.1.0 (minor): the streams ``battery``, ``setpoint``, ``messages``, ``params``, ``vibration``
#: and the ``gps`` columns ``hdop``/``vdop`` are new; every 1.0.0 column is unchanged.
#: 1.2.0: bearing stream (issue 16)
#: 1.3.0 (minor): the ``estimator_status`` stream (issue 13 item 2); every 1.2.0 column is unchanged.
#: 1.4.0 (minor): the studies' result tables are declared (:data:`STUDY_RESULTS`); no stream
#: or stage table changed.
#: 1.5.0: study tables only: the ``seed000_ekf`` RMSE columns carry their unit in the name
#: (``rmse_pos`` -> ``rmse_pos_m``, ``hmm_rmse`` ``acc`` -> ``acc_mps2``, ...); no stream or stage
#: table changed.
#: 1.6.0 (minor): ``local_position`` gains ``reset_count`` (the estimator's reset counters, so a
#: reset's step is not read as motion); every 1.5.0 column is unchanged.
#: 1.7.0 (minor): study table ``pf_geo_summary`` gains the observer-distance shares
#: ``dist_lt_50_pct``, ``dist_60_80_pct``, ``dist_gt_80_pct`` (thesis 001 Fig. 6.11); every
#: 1.6.0 column is unchanged.
SCHEMA_VERSION = "1.7.0"

#: Number of RC input / servo output channels carried by the ``control`` stream.
N_RC = 18
N_SERVO = 32


@dataclass(frozen=True)
class Column:
    """One column of a canonical stream.

    Parameters
    ----------
    name : str
        Column name, SI unit as suffix (``vel_n_mps``).
    dtype : str
        pandas dtype (``float64``, ``int64``, ``Int64`` nullable, ``uint8``, ``bool``,
        ``boolean`` nullable, ``category``, ``string``).
    unit : str
        Unit string (``m``, ``m/s``, ``rad/s``, ``1`` for dimensionless, ``""`` for labels).
    frame : str
        Reference frame (``NED``, ``FRD``, ``WGS84``, ``sensor``, ``source``) or ``""``.
    doc : str
        One-line description.
    """

    name: str
    dtype: str
    unit: str = ""
    frame: str = ""
    doc: str = ""


def _f(name: str, unit: str, frame: str = "", doc: str = "") -> Column:
    return Column(name, "float64", unit, frame, doc)


COMMON = (
    Column("t_ns", "int64", "ns", "",
           "time since the log's first sample (t0 in meta; event streams may precede it)"),
    Column("instance", "uint8", "1", "", "sensor instance (ArduPilot I, ULog multi_id)"),
    Column("src", "category", "", "", "source message type or topic"),
    Column("t_boot_ns", "Int64", "ns", "", "the source's own boot-time stamp, where it has one"),
)

_XYZ = ("x", "y", "z")
_NED = ("n", "e", "d")

STREAMS: dict[str, tuple[Column, ...]] = {
    "imu": (
        *(_f(f"gyr_{a}_radps", "rad/s", "FRD", "body rate, sensor axes in FRD convention") for a in _XYZ),
        *(_f(f"acc_{a}_mps2", "m/s^2", "FRD", "specific force, sensor axes in FRD convention") for a in _XYZ),
        _f("temp_degC", "degC"),
    ),
    "gps": (
        _f("lat_deg", "deg", "WGS84"),
        _f("lon_deg", "deg", "WGS84"),
        _f("alt_wgs84_m", "m", "WGS84", "ellipsoidal height"),
        _f("alt_msl_m", "m", "MSL"),
        *(_f(f"vel_{a}_mps", "m/s", "NED") for a in _NED),
        _f("fix_type", "1", "", "0 none, 1 no fix, 2 2D, 3 3D, 4 DGPS, 5 RTK float, 6 RTK fixed"),
        _f("n_sats", "1"),
        _f("hacc_m", "m"),
        _f("vacc_m", "m"),
        _f("hdop", "1", "", "horizontal dilution of precision"),
        _f("vdop", "1", "", "vertical dilution of precision"),
    ),
    "baro": (
        _f("press_Pa", "Pa"),
        _f("alt_rel_m", "m", "up", "barometric altitude above the reference (positive up)"),
        _f("temp_degC", "degC"),
    ),
    "mag": tuple(_f(f"mag_{a}_T", "T", "FRD") for a in _XYZ),
    "attitude": tuple(
        _f(f"q_{c}", "1", "FRD->NED", "Hamilton quaternion, scalar first") for c in "wxyz"
    ),
    "local_position": (
        *(_f(f"pos_{a}_m", "m", "NED", "about meta.ned_origin") for a in _NED),
        *(_f(f"vel_{a}_mps", "m/s", "NED") for a in _NED),
        _f("reset_count", "1", "", "estimator resets so far (PX4: xy, z, vxy and vz reset counters summed); "
           "a change is a step in the estimate, not motion"),
    ),
    "odometry": (
        *(_f(f"pos_{a}_m", "m", "source", "in meta.frames.odometry") for a in _XYZ),
        *(_f(f"vel_{a}_mps", "m/s", "source", "twist, child frame as logged") for a in _XYZ),
        _f("yaw_rate_radps", "rad/s", "source"),
    ),
    "rangefinder": (
        _f("dist_m", "m"),
        Column("valid", "boolean", "", "", "within the sensor's valid range"),
        _f("orientation", "1", "", "MAV_SENSOR_ORIENTATION (25 = down)"),
    ),
    "airspeed": (
        _f("airspeed_mps", "m/s"),
        _f("diff_press_Pa", "Pa"),
        _f("temp_degC", "degC"),
    ),
    "control": (
        *(_f(f"rc_{i}_us", "us", "", "RC input pulse width") for i in range(1, N_RC + 1)),
        *(_f(f"servo_{i}_us", "us", "", "servo/ESC output pulse width") for i in range(1, N_SERVO + 1)),
    ),
    "mode": (
        Column("mode", "string", "", "", "flight mode name (or number when unknown)"),
        Column("armed", "boolean", "", "", "armed state where the source has it"),
    ),
    "battery": (
        _f("voltage_V", "V", "", "battery (pack) voltage"),
        _f("current_A", "A", "", "battery current, positive discharging"),
        _f("consumed_Ah", "A.h", "", "charge drawn since boot"),
        _f("remaining_frac", "1", "", "remaining capacity, 0..1, as the autopilot estimates it"),
        _f("temp_degC", "degC"),
    ),
    "setpoint": (
        _f("roll_rad", "rad", "ZYX", "attitude setpoint (ZYX Euler, FRD -> NED)"),
        _f("pitch_rad", "rad", "ZYX"),
        _f("yaw_rad", "rad", "ZYX"),
        _f("p_radps", "rad/s", "FRD", "body rate setpoint"),
        _f("q_radps", "rad/s", "FRD"),
        _f("r_radps", "rad/s", "FRD"),
        *(_f(f"vel_{a}_mps", "m/s", "NED", "velocity setpoint") for a in _NED),
    ),
    "messages": (
        Column("text", "string", "", "", "the autopilot's text message"),
        _f("severity", "1", "", "MAV_SEVERITY / syslog level 0 emergency .. 7 debug; NaN: not logged"),
    ),
    "params": (
        Column("name", "string", "", "", "parameter name"),
        _f("value", "1", "", "parameter value (unit per parameter)"),
    ),
    "vibration": (
        *(_f(f"vibe_{a}_mps2", "m/s^2", "FRD", "accelerometer vibration level (autopilot's metric)")
          for a in _XYZ),
        _f("acc_vibration_mps2", "m/s^2", "", "one-number accelerometer vibration metric (PX4)"),
        _f("gyr_vibration_radps", "rad/s", "", "one-number gyro vibration metric (PX4)"),
        *(_f(f"clip_{i}", "1", "", f"accelerometer {i} clipping events since boot") for i in range(3)),
    ),
    # issue 13 item 2: the navigation filter's own health report, one row per report and EKF
    # core (``instance`` = core / lane: ArduPilot ``C`` or NKF4/NKF9, ULog multi_id). The bit
    # fields are as logged; their bit names depend on the source (``src``) and are tabled once in
    # :mod:`pipeline.io.estimator_bits`. A test ratio below 1 means the measurement passed its
    # innovation gate (ArduPilot logs the square root of its squared ratio, PX4 the ratio itself:
    # 1 is the gate in both).
    "estimator_status": (
        Column("solution_flags", "Int64", "1", "",
               "solution status bits (ArduPilot SS nav_filter_status; MAVLink EKF_STATUS_REPORT flags; "
               "PX4 solution_status_flags)"),
        Column("fault_flags", "Int64", "1", "", "filter fault bits (ArduPilot FS; PX4 filter_fault_flags)"),
        Column("innovation_fail_flags", "Int64", "1", "",
               "innovation-check failure bits (PX4 innovation_check_flags)"),
        Column("gps_check_flags", "Int64", "1", "", "failed GPS quality checks (ArduPilot GPS; PX4 "
                                                    "gps_check_fail_flags)"),
        Column("timeout_flags", "Int64", "1", "", "measurement timeout bits (ArduPilot TS; PX4 timeout_flags)"),
        Column("control_mode_flags", "Int64", "1", "", "filter control-mode bits (PX4 control_mode_flags)"),
        _f("vel_test_ratio", "1", "", "velocity innovation test ratio (>= 1: rejected)"),
        _f("pos_test_ratio", "1", "", "horizontal position innovation test ratio"),
        _f("hgt_test_ratio", "1", "", "height innovation test ratio"),
        _f("mag_test_ratio", "1", "", "magnetometer innovation test ratio"),
        _f("hdg_test_ratio", "1", "", "heading innovation test ratio (PX4 hdg_test_ratio)"),
        _f("tas_test_ratio", "1", "", "true-airspeed innovation test ratio"),
        _f("hagl_test_ratio", "1", "", "height-above-ground innovation test ratio"),
        _f("primary_core", "1", "", "primary EKF core index at this report (ArduPilot PI)"),
    ),
    "radar": (
        _f("range_m", "m", "", "as measured: rho + tau_RD * rho_dot"),
        _f("dcos_u", "1", "NED", "direction cosine (north component)"),
        _f("dcos_v", "1", "NED", "direction cosine (east component)"),
        _f("range_rate_mps", "m/s"),
        _f("sensor_id", "1"),
    ),
    # issue 17 (seed 001): a camera detection per observer (``instance``) and frame; the observer's
    # pose is in ``local_position``/``attitude`` of the same instance, the gimbal angles here.
    "camera_det": (
        _f("u_px", "px", "image", "detection centroid, column (x right; principal point at the image centre)"),
        _f("v_px", "px", "image", "detection centroid, row (y down)"),
        _f("sigma_px", "px", "image", "detection standard deviation per image axis"),
        _f("gimbal_yaw_rad", "rad", "FRD", "gimbal yaw relative to the body (Rz, ZYX, no roll)"),
        _f("gimbal_pitch_rad", "rad", "FRD", "gimbal pitch relative to the body (Ry; -pi/2 looks down)"),
    ),
    "truth": (
        *(_f(f"pos_{a}_m", "m", "NED") for a in _NED),
        *(_f(f"vel_{a}_mps", "m/s", "NED") for a in _NED),
        *(_f(f"acc_{a}_mps2", "m/s^2", "NED") for a in _NED),
        *(_f(f"jerk_{a}_mps3", "m/s^3", "NED") for a in _NED),
        *(_f(f"q_{c}", "1", "FRD->NED") for c in "wxyz"),
        *(_f(f"gyr_{a}_radps", "rad/s", "FRD") for a in _XYZ),
        Column("label", "string", "", "", "maneuver label"),
    ),
    # issue 16 (seed 002 §12 item 5): a bearing from observer ``instance`` (the ownship) to a
    # target; ``src`` says where it came from (``synthetic`` from two tracks, ``vision``)
    "bearing": (
        _f("az_rad", "rad", "NED", "bearing beta = atan2(dE, dN) from north toward east"),
        _f("sigma_rad", "rad", "", "1-sigma of the bearing noise"),
    ),
}

#: The one stream without ``t_ns``/``instance``/``src``.
LABELS: tuple[Column, ...] = (
    Column("t_start_ns", "int64", "ns"),
    Column("t_end_ns", "int64", "ns"),
    Column("label", "string"),
    Column("source", "string", "", "", "e.g. flightcoach_mans, simulation_truth"),
)

STREAM_NAMES: tuple[str, ...] = (*STREAMS, "labels")

#: Event streams (schema 1.1): records, not samples of a signal. Several may share a stamp (a
#: parameter dump at boot), so they are not counted in the timestamp anomalies, and they may
#: precede ``t_ns = 0`` (the first *sensor* record; see the readers), as ULog's stale topics do.
EVENT_STREAMS: tuple[str, ...] = ("messages", "params")
#: streams of measurements (not pilot inputs, modes, setpoints, events, labels or simulation
#: truth): the span a reader of the log means by "how long was the flight logged"
SENSOR_STREAMS: tuple[str, ...] = ("imu", "gps", "baro", "mag", "attitude", "local_position", "odometry",
                                   "rangefinder", "airspeed", "radar", "bearing", "camera_det")

#: The streams added by schema 1.1 (none of them moves a reader's ``t0``).
STREAMS_1_1: tuple[str, ...] = ("battery", "setpoint", "messages", "params", "vibration")

#: The streams added by schema 1.2 (issue 16).
STREAMS_1_2: tuple[str, ...] = ("bearing",)

#: The streams added by schema 1.3 (issue 13): reports, not measurements (they move no ``t0``).
STREAMS_1_3: tuple[str, ...] = ("estimator_status",)

#: Columns of the derived ``state`` table (preprocess output; style.md §3.2).
STATE: tuple[Column, ...] = (
    Column("t_ns", "int64", "ns"),
    *(_f(f"pos_{a}_m", "m", "NED") for a in _NED),
    *(_f(f"vel_{a}_mps", "m/s", "NED") for a in _NED),
    *(_f(f"acc_{a}_mps2", "m/s^2", "NED") for a in _NED),
    *(_f(f"jerk_{a}_mps3", "m/s^3", "NED") for a in _NED),
    *(_f(f"q_{c}", "1", "FRD->NED") for c in "wxyz"),
    _f("roll_rad", "rad", "ZYX"),
    _f("pitch_rad", "rad", "ZYX"),
    _f("yaw_rad", "rad", "ZYX"),
    _f("p_radps", "rad/s", "FRD"),
    _f("q_radps", "rad/s", "FRD"),
    _f("r_radps", "rad/s", "FRD"),
    _f("ail", "1"),
    _f("ele", "1"),
    _f("rud", "1"),
    _f("thr", "1"),
    # physical controls (seed 004 §6.8), NaN unless the vehicle config gives bench fits
    _f("delta_a_rad", "rad", "", "aileron deflection"),
    _f("delta_e_rad", "rad", "", "elevator deflection"),
    _f("delta_r_rad", "rad", "", "rudder deflection"),
    _f("thrust_N", "N", "", "propeller thrust"),
    _f("alt_cal_m", "m", "up"),
    Column("gap", "bool"),
)

#: Columns of the derived ``segments`` table.
SEGMENTS: tuple[Column, ...] = (
    Column("segment_id", "int64"),
    Column("t_start_ns", "int64", "ns"),
    Column("t_end_ns", "int64", "ns"),
    Column("label", "string"),
)

#: Columns of the per-flight calibration table (preprocess; one row per candidate reference
#: sample of the BPM calibration, :mod:`pipeline.preprocess.calibrate`).
CALIBRATION: tuple[Column, ...] = (
    Column("t_ns", "int64", "ns"),
    _f("h_ref_m", "m", "up", "reference height (tilt-compensated range, or GPS above origin)"),
    _f("h_baro_m", "m", "up", "filtered barometric altitude at t_ns"),
    _f("offset_m", "m", "up", "h_ref_m - h_baro_m"),
    Column("region", "int64", "1", "", "calibration region (-1: not used)"),
    Column("used", "bool", "", "", "point used in the fit"),
    Column("reason", "string", "", "", "ok, or why the point was rejected"),
    Column("method", "string", "", "", "rangefinder, gps"),
)

#: Columns of a simulated bulk set (simulate ``sets/<name>.parquet``): the ``state`` columns of
#: every run, so models read sets exactly as preprocessed flights, plus the run and its label.
SIM_SET: tuple[Column, ...] = (
    *STATE,
    Column("run_id", "int64", "1", "", "run number within the set"),
    Column("label", "string", "", "", "maneuver label (truth)"),
)

#: Columns of the simulation summary (simulate ``summary.parquet``): per maneuver, quantity and
#: axis, min / max / RMS over all samples of all runs at the truth rate.
SIM_SUMMARY: tuple[Column, ...] = (
    Column("maneuver", "string"),
    Column("quantity", "string", "", "", "acc (m/s^2) or jerk (m/s^3)"),
    Column("axis", "string", "", "", "n/e/d (NED), fwd/right/down (heading frame), norm"),
    Column("min", "float64"),
    Column("max", "float64"),
    Column("rms", "float64"),
    Column("n_runs", "int64"),
)

#: Columns of the simulated log flights' manifest (simulate ``logs/flights.tsv``; the layout of
#: the workflow's flight manifest).
FLIGHTS: tuple[Column, ...] = (
    Column("flight_id", "string"),
    Column("path", "string", "", "", "log file or ROS 2 bag directory"),
    Column("vehicle", "string"),
    Column("role", "string", "", "", "train, test"),
    Column("labels", "string", "", "", "labels / truth side-car path"),
    Column("format", "string", "", "", "reader name, empty: detected"),
    Column("notes", "string"),
)

#: Columns of a classification table (models ``classify``; one row per model-rate sample).
#: The first six (:data:`CLASSIFY_MIN_COLUMNS`) are the placeholder layout of a failed
#: classification. ``ll_*`` stands for one ``ll_<label>`` column per model of the set (and
#: ``ll_background``); the ``*_hmm_*`` columns are written with GMR only.
CLASSIFICATION: tuple[Column, ...] = (
    Column("run_id", "string", "", "", "run (simulated sets) or flight run id"),
    Column("t_ns", "int64", "ns"),
    Column("truth", "string", "", "", "label of the enclosing segment, '' outside"),
    Column("pred", "string", "", "", "decided label, or unknown"),
    Column("best", "string", "", "", "most likely model"),
    Column("V_best", "float64", "1", "", "online Viterbi score of best"),
    Column("oneclass_ok", "bool", "", "", "best passes its one-class threshold"),
    Column("ll_*", "float64", "1", "", "log-likelihood score per model label"),
    Column("state", "int64", "1", "", "online Viterbi state of best (-1: none)"),
    Column("change", "bool", "", "", "a maneuver change detected here"),
    Column("change_t_ns", "int64", "ns", "", "where the change began (-1: none)"),
    *(_f(f"acc_hmm_{a}_mps2", "m/s^2", "NED", "GMR acceleration estimate") for a in _NED),
    *(_f(f"jerk_hmm_{a}_mps3", "m/s^3", "NED", "GMR jerk estimate") for a in _NED),
    *(Column(f"acc_hmm_gated_{a}", "boolean", "", "", "GMR acceleration dropped by the gate") for a in _NED),
)
CLASSIFY_MIN_COLUMNS: tuple[str, ...] = ("run_id", "t_ns", "truth", "pred", "best", "V_best")

#: Columns of a model evaluation table (models ``evaluate``): FA / MAoT per maneuver beside the
#: thesis values (seed 000 §5, Tables 3.1-3.4).
MODEL_EVALUATION: tuple[Column, ...] = (
    Column("table", "string", "", "", "thesis table, or flights"),
    Column("split", "string", "", "", "train, test, test flights"),
    Column("decision", "string", "", "", "oneclass, confidence"),
    Column("maneuver", "string"),
    Column("n_runs", "int64"),
    _f("FA_pct", "%", "", "final accuracy"),
    _f("MAoT_pct", "%", "", "mean accuracy over time"),
    _f("thesis_FA_pct", "%"),
    _f("thesis_MAoT_pct", "%"),
)
EVAL_COLUMNS: tuple[str, ...] = tuple(c.name for c in MODEL_EVALUATION)


def _upper_covariance(state: tuple[tuple[str, str], ...], what: str = "covariance") -> tuple[Column, ...]:
    """``P_<i>_<j>`` (i <= j, state order) of an estimator table's state ``((name, unit), ...)``,
    unit the product of the two states' units, NED."""
    return tuple(_f(f"P_{i}_{j}", f"({state[i][1]})*({state[j][1]})", "NED",
                    f"{what} of x_{state[i][0]} and x_{state[j][0]}")
                 for i in range(len(state)) for j in range(i, len(state)))


#: Columns of an estimator output table (estimate ``results/estimate/<estimator>/<flight>.parquet``):
#: the 9-state CA estimate ``x_<state column>`` in the ``state`` table's names (NED), the upper
#: triangle of its covariance ``P_<i>_<j>`` (i <= j, state order pos n/e/d, vel n/e/d, acc
#: n/e/d; unit the product of the two states' units), the NIS and, where there is truth, the
#: NEES (NaN otherwise).
_EST_STATE = (*((f"pos_{a}_m", "m") for a in _NED), *((f"vel_{a}_mps", "m/s") for a in _NED),
              *((f"acc_{a}_mps2", "m/s^2") for a in _NED))
ESTIMATE: tuple[Column, ...] = (
    Column("t_ns", "int64", "ns"),
    *(_f(f"x_{n}", u, "NED", "estimate") for n, u in _EST_STATE),
    *_upper_covariance(_EST_STATE),
    _f("nis", "1", "", "normalised innovation squared (0 on predict-only steps)"),
    _f("nees", "1", "", "normalised estimation error squared (NaN without truth)"),
)

#: Columns of the EKF+HMM output (``results/estimate/ekf_hmm/<flight>.parquet``): the
#: :data:`ESTIMATE` columns of the EKF+HMM's own estimate, then whether the step was predicted
#: with the HMM inputs (A_H/B on at least one axis), the classifier's label and its confidence.
#: A new table beside ``estimate`` (no existing table changes, so ``SCHEMA_VERSION`` stays).
ESTIMATE_HMM: tuple[Column, ...] = (
    *ESTIMATE,
    Column("mode", "bool", "", "", "step predicted with the HMM inputs (A_H/B) on >= 1 axis"),
    Column("pred", "string", "", "", "classifier label at the step ('unknown' before the first)"),
    _f("V_best", "1", "", "online Viterbi confidence of the label"),
)

#: Columns of the seed-003 weave classifier output (``results/estimate/hmpf/<flight>.parquet``,
#: issue 17): the particle mean ``x_*`` of the planar state [N, E, v_N, v_E, ω] (NED, ω > 0 a
#: right turn), the upper triangle of its particle covariance ``P_<i>_<j>``, the class
#: (mode) fractions after resampling ``mode_p_<S|L|R|W>``, the weave submode fractions
#: ``submode_p_<CL|SL|CR|SR>``, N_eff before resampling, whether the step resampled, the
#: detector's windowed weave fraction ``af`` and its flag. A new table: ``SCHEMA_VERSION`` stays.
_HMPF_STATE = (("pos_n_m", "m"), ("pos_e_m", "m"), ("vel_n_mps", "m/s"), ("vel_e_mps", "m/s"),
               ("omega_radps", "rad/s"))
HMPF: tuple[Column, ...] = (
    Column("t_ns", "int64", "ns"),
    *(_f(f"x_{n}", u, "NED", "particle mean") for n, u in _HMPF_STATE),
    *_upper_covariance(_HMPF_STATE),
    *(_f(f"mode_p_{m}", "1", "", f"fraction of particles in mode {m} (straight/left/right/weave)")
      for m in ("S", "L", "R", "W")),
    *(_f(f"submode_p_{m}", "1", "", f"fraction of particles in weave submode {m}") for m in ("CL", "SL", "CR", "SR")),
    _f("neff", "1", "", "effective sample size before resampling"),
    Column("resampled", "bool", "", "", "the particles were resampled at this step"),
    _f("af", "1", "", "detector: weave fraction averaged over the last detector_window steps"),
    Column("weave_detected", "bool", "", "", "af >= tau after the start-up steps"),
)

#: Columns of a particle-filter output (issue 17, ``results/estimate/pf_jm/<flight>.parquet``,
#: :mod:`pipeline.estimate.pf_run`): the weighted mean ``x_<c>`` of the horizontal PF state
#: (:data:`pipeline.estimate.models.PF_STATE`: N/E position, velocity, turn rate, acceleration)
#: before resampling, the upper triangle of its weighted covariance ``P_<i>_<j>`` (i <= j in
#: that order), the weighted mode fractions ``mode_p_<mode>``, N_eff before resampling, whether
#: the step resampled, and, where the flight is classified, the classifier's softmax of its
#: ``ll_<label>`` at the nearest classified sample ``cls_p_<label>`` (NaN elsewhere). A new
#: table (no existing table changes, so ``SCHEMA_VERSION`` stays).
_PF_STATE = (("pos_n_m", "m"), ("pos_e_m", "m"), ("vel_n_mps", "m/s"), ("vel_e_mps", "m/s"),
             ("omega_radps", "rad/s"), ("acc_n_mps2", "m/s^2"), ("acc_e_mps2", "m/s^2"))
PF: tuple[Column, ...] = (
    Column("t_ns", "int64", "ns"),
    *(_f(f"x_{n}", u, "NED", "particle-weighted mean") for n, u in _PF_STATE),
    *_upper_covariance(_PF_STATE, what="weighted covariance"),
    Column("mode_p_*", "float64", "1", "", "weighted fraction of the particles in each mode"),
    _f("neff", "1", "", "effective sample size 1/sum(w^2) before resampling"),
    Column("resampled", "bool", "", "", "the particles were resampled after this step"),
    Column("cls_p_*", "float64", "1", "", "classifier softmax of ll_<label> at the nearest classified sample"),
)


#: Columns of a bearing-only estimate (issue 16, seed 002 §12 item 7:
#: ``results/estimate/{bank_cppv,bank_mpc,imm}/<pair>.parquet``): the CPPV state of the intruder
#: relative to the ownship (NED north/east offset, intruder speed, course from N toward E, turn
#: rate, > 0 a right turn; MPC estimates are mapped back by G^-1), the upper triangle of its
#: covariance ``P_<i>_<j>`` (i <= j), the range and its 1-sigma, the NIS of the combined
#: estimate's bearing innovation (NaN on predict-only steps), the IMM mode probabilities (NaN for
#: a bank alone) and the number of diverged (frozen) filters.
_BRG_STATE = (("rel_n_m", "m"), ("rel_e_m", "m"), ("speed_mps", "m/s"), ("course_rad", "rad"),
              ("omega_radps", "rad/s"))
BEARING_ESTIMATE: tuple[Column, ...] = (
    Column("t_ns", "int64", "ns"),
    *(_f(f"x_{n}", u, "NED", "estimate") for n, u in _BRG_STATE),
    *_upper_covariance(_BRG_STATE),
    _f("range_m", "m", "", "estimated range |rel|"),
    _f("range_sigma_m", "m", "", "1-sigma of the range (g^T P_pos g, g the unit LOS)"),
    _f("nis", "1", "", "NIS of the bearing innovation (NaN on predict-only steps)"),
    _f("mode_p_cv", "1", "", "IMM probability of the CV mode (NaN without an IMM)"),
    _f("mode_p_ct", "1", "", "IMM probability of the CT (bank) mode (NaN without an IMM)"),
    Column("n_diverged", "int64", "1", "", "bank filters flagged diverged and frozen"),
)

#: The bank weights beside a bearing-only estimate (``<pair>.weights.parquet``), long format:
#: one row per kept step and filter (the grid point is the filter's initial range, course and
#: turn rate).
BEARING_WEIGHTS: tuple[Column, ...] = (
    Column("t_ns", "int64", "ns"),
    Column("filter", "int64", "1", "", "filter index in the bank's grid enumeration"),
    _f("weight", "1", "", "normalised bank weight W_k^(i)"),
    _f("r0_m", "m", "", "the filter's initial range"),
    _f("course0_rad", "rad", "", "the filter's initial course"),
    _f("omega0_radps", "rad/s", "", "the filter's initial turn rate"),
)

#: Every table of every stage by name: the canonical streams (common columns first), ``labels``
#: and the derived tables. :func:`columns`, :func:`empty` and :func:`conform` take these names.
TABLES: dict[str, tuple[Column, ...]] = {
    **{name: (*COMMON, *cols) for name, cols in STREAMS.items()},
    "labels": LABELS,
    "state": STATE,
    "segments": SEGMENTS,
    "calibration": CALIBRATION,
    "simulate_set": SIM_SET,
    "simulate_summary": SIM_SUMMARY,
    "flights": FLIGHTS,
    "classification": CLASSIFICATION,
    "model_evaluation": MODEL_EVALUATION,
    "estimate": ESTIMATE,
    "estimate_hmm": ESTIMATE_HMM,
    "hmpf": HMPF,
    "pf": PF,
    "bearing_estimate": BEARING_ESTIMATE,
    "bearing_weights": BEARING_WEIGHTS,
}


#: unit of a column-name suffix (``vel_n_mps`` -> m/s), the naming rule every declared column
#: follows (:func:`units_from_names`; a test holds every declared table to it)
UNIT_SUFFIXES: dict[str, str] = {
    "m": "m", "s": "s", "ns": "ns", "us": "us", "mps": "m/s", "mps2": "m/s^2", "mps3": "m/s^3",
    "rad": "rad", "radps": "rad/s", "deg": "deg", "degps": "deg/s", "pct": "%", "Pa": "Pa", "T": "T",
    "degC": "degC", "Hz": "Hz", "V": "V", "A": "A", "N": "N", "px": "px",
}


_SQUARED_PREFIXES = ("var_", "P_", "sigma_z_", "sigma_y_")


def units_from_names(names) -> dict[str, dict[str, str]]:
    """``{column: {"unit", "frame"}}`` for the columns whose name ends in a unit suffix
    (:data:`UNIT_SUFFIXES`); frame left empty. Variances and covariances (``var_*``, ``P_*``,
    the Σ diagonals ``sigma_z_*``/``sigma_y_*``) are left out: their unit is the square of the
    suffix's."""
    out = {}
    for n in map(str, names):
        if "_" not in n or n.startswith(_SQUARED_PREFIXES):
            continue
        unit = UNIT_SUFFIXES.get(n.rsplit("_", 1)[1])
        if unit is not None:
            out[n] = {"unit": unit, "frame": ""}
    return out


class SchemaError(ValueError):
    """A DataFrame does not fit its canonical stream (unknown column, uncastable dtype)."""


def columns(table: str) -> tuple[Column, ...]:
    """All columns of ``table`` (a key of :data:`TABLES`) in canonical order (a stream's
    common columns first)."""
    if table not in TABLES:
        raise SchemaError(f"unknown table {table!r}; known: {', '.join(TABLES)}")
    return TABLES[table]


def layout(table: str | tuple[Column, ...], names) -> tuple[Column, ...]:
    """The declared columns of ``table`` that ``names`` holds, in canonical order, each wildcard
    family (``ll_*``, ``mode_p_*``) expanded to its members in the order ``names`` gives them.

    For tables whose optional columns are written only when computed (a classification's
    ``*_hmm_*`` columns come with GMR only): the file still gets declared types, units and
    order. Raises :class:`SchemaError` on a name the table does not declare.
    """
    cols, names = _cols(table), [str(n) for n in names]
    unknown = _undeclared(cols, names)
    if unknown:
        raise SchemaError(f"table {table if isinstance(table, str) else 'given'!r}: "
                          f"undeclared column(s) {unknown}")
    have, out = set(names), []
    for c in cols:
        if _is_wildcard(c):
            out += [Column(n, c.dtype, c.unit, c.frame, c.doc) for n in names if n.startswith(c.name[:-1])]
        elif c.name in have:
            out.append(c)
    return tuple(out)


def column_names(table: str) -> list[str]:
    """Column names of ``table`` in canonical order."""
    return [c.name for c in columns(table)]


def _cols(table: str | tuple[Column, ...]) -> tuple[Column, ...]:
    return columns(table) if isinstance(table, str) else tuple(table)


def _is_wildcard(col: Column) -> bool:
    # ``ll_*``: a family of columns named at run time (one per model label)
    return col.name.endswith("*")


def _undeclared(cols: tuple[Column, ...], names) -> list:
    """The ``names`` that are neither a column of ``cols`` nor a member of one of its wildcard
    families (:func:`conform` and :func:`layout` refuse them)."""
    known = {c.name for c in cols}
    prefixes = tuple(c.name[:-1] for c in cols if _is_wildcard(c))
    return [n for n in names if n not in known and not (prefixes and str(n).startswith(prefixes))]


def _empty_series(col: Column, n: int) -> pd.Series:
    if col.dtype == "float64":
        return pd.Series(np.full(n, np.nan))
    if col.dtype in ("int64", "uint8", "bool"):
        if n:
            raise SchemaError(f"required column {col.name!r} missing")
        return pd.Series(np.empty(0, dtype=col.dtype))
    if col.dtype == "category":
        return pd.Series(pd.Categorical([None] * n, categories=[]))
    return pd.Series(pd.array([None] * n, dtype=col.dtype))


def cast(column: Column, series: pd.Series) -> pd.Series:
    """``series`` cast to the declared dtype of ``column``.

    Raises
    ------
    SchemaError
        Naming the column, when a value cannot be cast or an ``int64``/``uint8`` column has
        missing values.
    """
    col, s = column, series
    try:
        if col.dtype == "category":
            return s.astype("string").astype("category")
        if col.dtype in ("int64", "uint8"):
            if s.isna().any():
                raise SchemaError(f"column {col.name!r} ({col.dtype}) contains missing values")
            return s.astype(col.dtype)
        return s.astype(col.dtype)
    except (TypeError, ValueError, OverflowError) as exc:
        if isinstance(exc, SchemaError):
            raise
        raise SchemaError(f"column {col.name!r} cannot be cast to {col.dtype}: {exc}") from None


def empty(table: str | tuple[Column, ...]) -> pd.DataFrame:
    """An empty DataFrame with the full schema of ``table`` (a :data:`TABLES` name, or its
    columns; wildcard column families such as ``ll_*`` have no member yet and are left out)."""
    return pd.DataFrame({c.name: _empty_series(c, 0) for c in _cols(table) if not _is_wildcard(c)})


def conform(table: str | tuple[Column, ...], df: pd.DataFrame | None) -> pd.DataFrame:
    """Return ``df`` in the canonical layout of ``table`` (a :data:`TABLES` name, or columns).

    Adds missing optional columns (NaN/NA), casts dtypes and orders columns canonically
    (columns of a wildcard family such as ``ll_*`` at its place, in their given order). A
    stream also gets ``instance`` 0 where it has none, and its rows are sorted stably by
    (``instance``, ``t_ns``) (``labels``: by ``t_start_ns``); derived tables keep their row
    order. Samples are never dropped or repaired here: timestamp anomalies are counted by
    :func:`timestamp_anomalies` and repaired in preprocessing.

    Raises
    ------
    SchemaError
        On an unknown table or column, or a value that cannot be cast.
    """
    stream = table if isinstance(table, str) else ""
    if df is None or (len(df) == 0 and len(df.columns) == 0):
        return empty(table)
    cols = _cols(table)
    known = {c.name for c in cols}
    unknown = _undeclared(cols, df.columns)
    if unknown:
        kind = "stream" if stream in STREAM_NAMES else "table"
        raise SchemaError(f"{kind} {stream or 'given'!r}: unknown column(s) {unknown}")
    n = len(df)
    if stream in STREAMS and "instance" not in df.columns:
        df = df.assign(instance=np.zeros(n, dtype=np.uint8))
    out = {}
    for c in cols:
        if _is_wildcard(c):
            for name in df.columns:
                if str(name).startswith(c.name[:-1]) and name not in known:
                    out[name] = cast(Column(name, c.dtype, c.unit, c.frame, c.doc), df[name].reset_index(drop=True))
        elif c.name in df.columns:
            out[c.name] = cast(c, df[c.name].reset_index(drop=True))
        else:
            out[c.name] = _empty_series(c, n)
    res = pd.DataFrame(out)
    keys = ["t_start_ns"] if stream == "labels" else ["instance", "t_ns"] if stream in STREAMS else []
    if keys:
        order = np.lexsort([res[k].to_numpy() for k in reversed(keys)])
        if not np.array_equal(order, np.arange(n)):
            res = res.iloc[order].reset_index(drop=True)
    return res


def timestamp_anomalies(df: pd.DataFrame, by_src: bool = True) -> dict[str, int]:
    """Count timestamp anomalies of one conformed stream, in *arrival order*.

    Must be called on the reader's rows before sorting (``FlightLog.from_streams`` does).
    Counted per (``instance``, ``src``) sequence: ``backwards`` (t[k] < t[k-1]) and
    ``duplicate`` (t[k] == t[k-1]).
    """
    if len(df) < 2 or "t_ns" not in df.columns:
        return {"backwards": 0, "duplicate": 0}
    keys = [df["instance"].to_numpy()] if "instance" in df.columns else []
    if by_src and "src" in df.columns:
        keys.append(df["src"].astype("string").fillna("").to_numpy())
    t = df["t_ns"].to_numpy(dtype=np.int64)
    if keys:
        grp = pd.DataFrame({f"k{i}": k for i, k in enumerate(keys)})
        gid = grp.groupby(list(grp.columns), sort=False).ngroup().to_numpy()
        order = np.argsort(gid, kind="stable")
        t = t[order]
        same = gid[order][1:] == gid[order][:-1]
    else:
        same = np.ones(len(t) - 1, dtype=bool)
    d = np.diff(t)
    return {"backwards": int(np.sum((d < 0) & same)), "duplicate": int(np.sum((d == 0) & same))}


def arrow_schema(table: str) -> pa.Schema:
    """pyarrow schema of ``table`` (any :data:`TABLES` name) with per-column
    ``unit``/``frame`` field metadata (wildcard families left out)."""
    return _arrow_schema(columns(table))


def arrow_schema_for(cols: tuple[Column, ...]) -> pa.Schema:
    """pyarrow schema for given columns (``STATE``, ``SEGMENTS``...)."""
    return _arrow_schema(cols)


_PA = {
    "float64": pa.float64(),
    "int64": pa.int64(),
    "Int64": pa.int64(),
    "uint8": pa.uint8(),
    "bool": pa.bool_(),
    "boolean": pa.bool_(),
    "string": pa.string(),
    "category": pa.dictionary(pa.int32(), pa.string()),
}


def _arrow_schema(cols: tuple[Column, ...]) -> pa.Schema:
    fields = [
        pa.field(
            c.name,
            _PA[c.dtype],
            nullable=c.dtype not in ("int64", "uint8", "bool"),
            metadata={"unit": c.unit, "frame": c.frame, "doc": c.doc},
        )
        for c in cols
        if not _is_wildcard(c)
    ]
    return pa.schema(fields)


def units(table: str) -> dict[str, dict[str, str]]:
    """``{column: {"unit": ..., "frame": ...}}`` for the file metadata."""
    return {c.name: {"unit": c.unit, "frame": c.frame} for c in columns(table)}


def new_meta(**kw) -> dict:
    """A ``meta`` dict with every key of style.md §3.2 present (defaults ``None``/empty).

    Keys: ``schema_version``, ``flight_id``, ``source_path``, ``source_format``,
    ``source_sha256``, ``source_size_bytes``, ``reader``, ``reader_version``, ``detected_by``,
    ``t0_boot_ns`` (source clock value at ``t_ns = 0``), ``t0_utc_ns`` (UTC of ``t_ns = 0``,
    nullable), ``utc_source`` (gps/host/none), ``leap_seconds``, ``ned_origin`` (``lat_deg``,
    ``lon_deg``, ``alt_wgs84_m`` or ``None``), ``ned_origin_reason`` (why it is ``None``),
    ``frames`` (world/body plus per-source frames),
    ``diagnostics`` (see :func:`new_diagnostics`), ``params`` (autopilot parameters),
    ``status`` (``ok``/``partial``/``failed``) and ``error`` (reason when failed).
    """
    meta = {
        "schema_version": SCHEMA_VERSION,
        "flight_id": None,
        "source_path": None,
        "source_format": None,
        "source_sha256": None,
        "source_size_bytes": None,
        "reader": None,
        "reader_version": None,
        "detected_by": None,
        "t0_boot_ns": None,
        "t0_utc_ns": None,
        "utc_source": "none",
        "leap_seconds": None,
        "ned_origin": None,
        "ned_origin_reason": None,
        "frames": {"world": "NED", "body": "FRD"},
        "diagnostics": new_diagnostics(),
        "params": {},
        "status": "ok",
        "error": None,
    }
    meta.update(kw)
    return meta


def new_diagnostics() -> dict:
    """Ingest diagnostics, every counter present.

    ``bytes_skipped``: bytes not part of any decoded record (resync, garbage, truncation);
    ``records_dropped``: ``{reason: count}`` (e.g. ``bad_format``, ``truncated``, ``unknown_type``,
    ``format_lost:<TYPE>``); ``timestamp_anomalies``: ``{stream: {backwards, duplicate}}``;
    ``messages``: text messages logged by the vehicle (first 1000); ``warnings``: reader notes;
    ``record_counts``: ``{source message type: records decoded}``.
    """
    return {
        "bytes_skipped": 0,
        "records_dropped": {},
        "timestamp_anomalies": {},
        "messages": [],
        "warnings": [],
        "record_counts": {},
    }


# --------------------------------------------------------------------------------------------
# Arrow-native tables: the ingest path builds, conforms and writes pyarrow tables without pandas
# --------------------------------------------------------------------------------------------
#
# A conformed Arrow table of a stream has exactly the columns of ``arrow_schema(stream)`` in
# canonical order, rows sorted stably by (``instance``, ``t_ns``) (``labels``: ``t_start_ns``),
# and is what ``pa.Table.from_pandas(conform(stream, df), schema=arrow_schema(stream))`` gives
# for the same data: missing values (NaN, None, NA) are nulls, ``src`` is a dictionary with
# sorted values. ``tests/io/test_arrow_conform.py`` checks the two paths against each other.

import functools as _functools  # noqa: E402  (new section: its imports stay with it)
import json as _json  # noqa: E402


# pyarrow's ``pa.array``, ``Array.to_numpy`` and ``Schema.empty_table`` import pandas when it is
# installed; the helpers below build and read arrays through their buffers instead.

def _bitmap(valid: np.ndarray) -> pa.Buffer:
    return pa.py_buffer(np.packbits(valid, bitorder="little"))


def np_to_arrow(a: np.ndarray, t: pa.DataType, mask: np.ndarray | None = None) -> pa.Array:
    """Arrow array of type ``t`` over NumPy values ``a`` (``mask``: True = missing), without
    pandas. Numeric types are zero-copy views of ``a`` (cast to ``t``'s width); ``bool`` is
    bit-packed; ``string`` takes Python ``str`` values."""
    n = len(a)
    validity = None if mask is None or not mask.any() else _bitmap(~mask)
    if pa.types.is_string(t):
        enc = [b"" if (mask is not None and mask[i]) else x.encode() for i, x in enumerate(a.tolist())]
        offsets = np.zeros(n + 1, np.int32)
        np.cumsum([len(x) for x in enc], out=offsets[1:])
        return pa.Array.from_buffers(t, n, [validity, pa.py_buffer(offsets), pa.py_buffer(b"".join(enc))])
    if pa.types.is_boolean(t):
        return pa.Array.from_buffers(t, n, [validity, _bitmap(a.astype(bool, copy=False))])
    data = np.ascontiguousarray(a, dtype=_NP_OF[str(t)])
    return pa.Array.from_buffers(t, n, [validity, pa.py_buffer(data)])


_NP_OF = {"double": np.float64, "int64": np.int64, "uint8": np.uint8, "int32": np.int32, "int8": np.int8}


def arrow_to_np(arr) -> np.ndarray:
    """Values of a primitive Arrow array as NumPy (nulls hold whatever their slots hold; see
    :func:`arrow_nulls`), without pandas. ``bool`` arrays come back unpacked."""
    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks()
    n, off = len(arr), arr.offset
    buf = arr.buffers()[1]
    if pa.types.is_boolean(arr.type):
        if buf is None:
            return np.zeros(n, bool)
        bits = np.unpackbits(np.frombuffer(buf, np.uint8), bitorder="little")
        return bits[off:off + n].astype(bool)
    dt = _NP_OF[str(arr.type)]
    if buf is None:
        return np.zeros(n, dt)
    return np.frombuffer(buf, dtype=dt, count=off + n)[off:]


def arrow_nulls(arr) -> np.ndarray:
    """Missing-value mask (True = null) of an Arrow array, without pandas."""
    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks()
    n = len(arr)
    if not arr.null_count:
        return np.zeros(n, bool)
    if pa.types.is_null(arr.type):
        return np.ones(n, bool)
    bits = np.unpackbits(np.frombuffer(arr.buffers()[0], np.uint8), bitorder="little")
    return ~bits[arr.offset:arr.offset + n].astype(bool)


def empty_arrow(stream: str) -> pa.Table:
    """An empty conformed Arrow table of ``stream``."""
    sch = arrow_schema(stream)
    return pa.Table.from_arrays([pa.nulls(0, f.type) for f in sch], schema=sch)


def _part_len(part) -> int:
    for v in part.values():
        if not _is_scalar(v):
            return len(v)
    return 0


def _is_scalar(v) -> bool:
    return v is None or isinstance(v, (str, bytes, int, float, bool, np.generic))


def _np_values(col: Column, v, n: int) -> tuple[np.ndarray, np.ndarray | None]:
    """One column of one part as (NumPy values, missing mask or ``None``), cast as
    :func:`cast` casts (NumPy ``astype`` semantics); text columns give object arrays of str."""
    if isinstance(v, (pa.Array, pa.ChunkedArray)):
        arr = v.combine_chunks() if isinstance(v, pa.ChunkedArray) else v
        if pa.types.is_dictionary(arr.type):
            arr = arr.cast(pa.string()) if col.dtype in ("string", "category") else arr.dictionary_decode()
        if pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type) or pa.types.is_null(arr.type):
            v = np.array(arr.to_pylist(), dtype=object)
        else:
            m = arrow_nulls(arr)
            v = np.ma.masked_array(arrow_to_np(arr), mask=m) if m.any() else arrow_to_np(arr)
    text = col.dtype in ("string", "category")
    if _is_scalar(v):
        if v is None:
            if col.dtype in ("int64", "uint8", "bool") and n:
                raise SchemaError(f"column {col.name!r} ({col.dtype}) contains missing values")
            fill = {"float64": np.nan, "boolean": False, "string": "", "category": ""}.get(col.dtype, 0)
            return np.full(n, fill, dtype=object if text else None), np.ones(n, bool)
        v = np.full(n, v, dtype=object if isinstance(v, str) else None)
    mask = None
    if isinstance(v, np.ma.MaskedArray):
        mask = np.ma.getmaskarray(v)
        v = np.ma.getdata(v)
    a = np.asarray(v)
    try:
        if a.dtype == object:  # Python values; None/NaN/NA are missing
            a, m2 = _from_objects(a, col)
            mask = m2 if mask is None else (mask | m2)
        if col.dtype == "float64":
            a = a.astype(np.float64, copy=False)
            nan = np.isnan(a)  # NaN is missing, as pa.Table.from_pandas makes it
            if mask is not None:
                nan |= mask
            return a, nan if nan.any() else None
        if col.dtype in ("int64", "uint8", "bool"):
            if mask is not None and mask.any() or a.dtype.kind == "f" and np.isnan(a).any():
                raise SchemaError(f"column {col.name!r} ({col.dtype}) contains missing values")
            return a.astype(col.dtype, copy=False), None
        if col.dtype in ("Int64", "boolean"):
            if a.dtype.kind == "f":
                bad = np.isnan(a)
                mask = bad if mask is None else (mask | bad)
                a = np.where(bad, 0, a)
            return a.astype(np.int64 if col.dtype == "Int64" else bool, copy=False), mask
        # string / category: text
        if a.dtype.kind in "US":
            a = a.astype(str).astype(object)
        elif not all(isinstance(x, str) for x in a.tolist()):
            a = np.array([x if isinstance(x, str) else str(x) for x in a.tolist()], dtype=object)
        return a, mask
    except (TypeError, ValueError, OverflowError) as exc:
        if isinstance(exc, SchemaError):
            raise
        raise SchemaError(f"column {col.name!r} cannot be cast to {col.dtype}: {exc}") from None


def _missing(x) -> bool:
    """None, NaN or pandas' NA (recognised without importing pandas)."""
    return x is None or (isinstance(x, float) and x != x) or type(x).__name__ in ("NAType", "NaTType")


def _from_objects(a: np.ndarray, col: Column) -> tuple[np.ndarray, np.ndarray]:
    """An object array as (values, missing mask); text columns keep the objects."""
    items = a.tolist()
    mask = np.fromiter((_missing(x) for x in items), dtype=bool, count=len(items))
    if col.dtype in ("string", "category"):
        return np.array(["" if m else x for x, m in zip(items, mask.tolist())], dtype=object), mask
    fill = {"float64": np.nan, "boolean": False}.get(col.dtype, 0)
    return np.array([fill if m else x for x, m in zip(items, mask.tolist())]), mask


def _categories(col: Column, parts: list, lens: list[int]) -> tuple[np.ndarray, np.ndarray | None, list[str]]:
    """A dictionary column over all parts: (int32 codes, missing mask, sorted values), as
    ``astype('category')`` orders them. A part may give one ``str`` for all its rows (no
    per-row string is built)."""
    vals: list[str] = []
    index: dict[str, int] = {}

    def code(x: str) -> int:
        if x not in index:
            index[x] = len(vals)
            vals.append(x)
        return index[x]

    chunks = []  # (codes into vals, missing mask or None)
    for part, n in zip(parts, lens):
        v = part.get(col.name)
        if isinstance(v, str):
            chunks.append((np.full(n, code(v), np.int32), None))
            continue
        a, mask = _np_values(col, v, n)
        uniq, inv = np.unique(a, return_inverse=True) if n else (np.empty(0, object), np.zeros(0, np.int64))
        remap = np.array([code(x) for x in uniq.tolist()] or [0], np.int32)
        chunks.append((remap[inv.reshape(-1)], mask))
    if mask_needed := any(m is not None for _, m in chunks):
        mask = np.concatenate([np.zeros(len(c), bool) if m is None else m for c, m in chunks])
    else:
        mask = None
    # values that occur only in missing rows (the "" placeholder) are not categories
    used = np.zeros(max(len(vals), 1), bool)
    for c, m in chunks:
        used[np.unique(c if m is None else c[~m])] = True
    keep = sorted((i for i in range(len(vals)) if used[i]), key=lambda i: vals[i])
    rank = np.zeros(max(len(vals), 1), np.int32)
    rank[keep] = np.arange(len(keep), dtype=np.int32)
    codes = rank[np.concatenate([c for c, _ in chunks])] if chunks else np.zeros(0, np.int32)
    if mask_needed:
        codes[mask] = 0
    return codes, mask, [vals[i] for i in keep]


def _np_columns(stream: str, data) -> tuple[dict[str, tuple], int]:
    """``data`` (see :func:`arrow_table`) as ``{column: (values, mask[, categories])}`` in
    arrival order, and the row count."""
    cols = columns(stream)
    if isinstance(data, pa.Table):
        data = [{n: data.column(n) for n in data.column_names}]
    elif isinstance(data, dict):
        data = [data]
    parts = [p for p in data if p is not None]
    known = {c.name for c in cols}
    for p in parts:
        unknown = [k for k in p if k not in known]
        if unknown:
            raise SchemaError(f"stream {stream!r}: unknown column(s) {unknown}")
    lens = [_part_len(p) for p in parts]
    n = sum(lens)
    out: dict[str, tuple] = {}
    if n == 0:
        return out, 0
    for c in cols:
        if c.dtype == "category":
            out[c.name] = _categories(c, parts, lens)
            continue
        vals, masks = [], []
        for p, m in zip(parts, lens):
            v = p.get(c.name)
            if v is None and c.name == "instance":
                v = np.zeros(m, np.uint8)
            if v is None and c.dtype in ("int64", "uint8", "bool") and m:
                raise SchemaError(f"required column {c.name!r} missing")
            a, mask = _np_values(c, v, m)
            vals.append(a)
            masks.append(mask)
        a = vals[0] if len(vals) == 1 else np.concatenate(vals)
        if all(m is None for m in masks):
            mask = None
        else:
            mask = masks[0] if len(masks) == 1 else np.concatenate(
                [np.zeros(len(v), bool) if m is None else m for v, m in zip(vals, masks)])
        out[c.name] = (a, mask)
    return out, n


def _to_arrow(stream: str, cols_np: dict[str, tuple], order: np.ndarray | None) -> pa.Table:
    sch = arrow_schema(stream)
    arrays = []
    for c, f in zip(columns(stream), sch):
        entry = cols_np[c.name]
        vals, mask = entry[0], entry[1]
        if order is not None:
            vals = vals[order]
            mask = None if mask is None else mask[order]
        if c.dtype == "category":
            dictionary = np_to_arrow(np.array(entry[2], dtype=object), pa.string())
            arrays.append(pa.DictionaryArray.from_arrays(np_to_arrow(vals, pa.int32(), mask), dictionary))
        else:
            arrays.append(np_to_arrow(vals, f.type, mask))
    return pa.Table.from_arrays(arrays, schema=sch)


def _sort_order(stream: str, cols_np: dict[str, tuple]) -> np.ndarray | None:
    """Stable (``instance``, ``t_ns``) order (``labels``: ``t_start_ns``); ``None`` if sorted."""
    if stream == "labels":
        a = cols_np["t_start_ns"][0]
        return None if np.all(a[1:] >= a[:-1]) else np.argsort(a, kind="stable")
    inst, t = cols_np["instance"][0], cols_np["t_ns"][0]
    same = inst[1:] == inst[:-1]
    if np.all((inst[1:] > inst[:-1]) | (same & (t[1:] >= t[:-1]))):
        return None
    return np.lexsort([t, inst])


def _anomalies_np(cols_np: dict[str, tuple]) -> dict[str, int]:
    """:func:`timestamp_anomalies` (arrival order, per instance and ``src``) on NumPy columns."""
    t = cols_np["t_ns"][0]
    if len(t) < 2:
        return {"backwards": 0, "duplicate": 0}
    gid = cols_np["instance"][0].astype(np.int64)
    codes, mask, cats = cols_np["src"]
    # missing and "" are one group, as in timestamp_anomalies (fillna(""))
    k = len(cats) + 1
    empty = cats.index("") if "" in cats else len(cats)
    src = codes.astype(np.int64)
    if mask is not None:
        src = np.where(mask, empty, src)
    gid = gid * k + src
    order = np.argsort(gid, kind="stable")
    ts = t[order]
    g = gid[order]
    same = g[1:] == g[:-1]
    d = np.diff(ts)
    return {"backwards": int(np.sum((d < 0) & same)), "duplicate": int(np.sum((d == 0) & same))}


def arrow_table(stream: str, data) -> pa.Table:
    """``data`` as an Arrow table of ``stream``'s schema, rows in the order given (not sorted).

    Parameters
    ----------
    stream : str
        A canonical stream (``STREAM_NAMES``).
    data : None, pyarrow.Table, pandas.DataFrame, mapping or list of mappings
        Columns by name: NumPy arrays, Arrow arrays, masked arrays (masked = missing) or one
        scalar for all rows (``src="IMU"``); a list of such mappings is concatenated in order
        (absent columns of a part are missing values). A DataFrame goes through :func:`conform`
        first (so its rows come back sorted).

    Raises
    ------
    SchemaError
        Unknown column, a missing required column, or a value that cannot be cast.
    """
    if data is None:
        return empty_arrow(stream)
    if hasattr(data, "iloc") and hasattr(data, "columns"):  # a pandas DataFrame
        df = conform(stream, data)
        return pa.Table.from_pandas(df[column_names(stream)], schema=arrow_schema(stream),
                                    preserve_index=False).replace_schema_metadata(None)
    cols_np, n = _np_columns(stream, data)
    return _to_arrow(stream, cols_np, None) if n else empty_arrow(stream)


def conform_arrow_counted(stream: str, data) -> tuple[pa.Table, dict[str, int]]:
    """:func:`conform_arrow` and the stream's :func:`timestamp_anomalies` in arrival order
    (zero for ``labels`` and for a DataFrame, which :func:`timestamp_anomalies` counts itself).

    Rows are ordered in NumPy before the Arrow arrays are built (zero-copy views), so a
    stream is gathered once."""
    none = {"backwards": 0, "duplicate": 0}
    if data is None or hasattr(data, "iloc") and hasattr(data, "columns"):
        return sort_arrow(stream, arrow_table(stream, data)), none
    cols_np, n = _np_columns(stream, data)
    if not n:
        return empty_arrow(stream), none
    anomalies = none if stream == "labels" else _anomalies_np(cols_np)
    return _to_arrow(stream, cols_np, _sort_order(stream, cols_np)), anomalies


def sort_arrow(stream: str, table: pa.Table) -> pa.Table:
    """Rows sorted stably by (``instance``, ``t_ns``) (``labels``: ``t_start_ns``), as :func:`conform`."""
    if table.num_rows < 2:
        return table
    keys = ["t_start_ns"] if stream == "labels" else ["instance", "t_ns"]
    order = _sort_order(stream, {k: (arrow_to_np(table.column(k)), None) for k in keys})
    return table if order is None else table.take(np_to_arrow(order.astype(np.int64), pa.int64()))


def conform_arrow(stream: str, data) -> pa.Table:
    """The conformed Arrow table of ``stream``: canonical columns and types, missing columns
    null, rows sorted stably by (``instance``, ``t_ns``).

    Equals ``pa.Table.from_pandas(conform(stream, df), schema=arrow_schema(stream))`` for the
    same data, without pandas for NumPy/Arrow input (see :func:`arrow_table` for the forms).
    """
    return conform_arrow_counted(stream, data)[0]


def frame_from_arrow(cols: tuple[Column, ...], table: pa.Table):
    """pandas DataFrame of a table of declared columns, dtypes as :func:`conform` gives them.

    Nullable integers are converted exactly (no float detour). Imports pandas (lazily: the
    ingest path never calls this)."""
    n = table.num_rows
    out = {}
    for c in cols:
        if not n:
            out[c.name] = _empty_series(c, 0)
            continue
        a = table.column(c.name).combine_chunks()
        if c.dtype == "Int64":
            mask = arrow_nulls(a)
            vals = np.where(mask, 0, arrow_to_np(a)).astype(np.int64)
            out[c.name] = pd.Series(pd.arrays.IntegerArray(vals, mask))
        else:
            out[c.name] = cast(c, pd.Series(a.to_pandas()))
    return pd.DataFrame(out)


def pandas_metadata(cols: tuple[Column, ...], table: pa.Table) -> bytes:
    """The ``pandas`` schema metadata ``pa.Table.from_pandas`` writes for a conformed frame.

    Written with Arrow-native tables so that ``pd.read_parquet`` restores the same dtypes
    (nullable ``Int64``, ``string``, ``boolean``) as for files written from pandas."""
    entries = []
    for c in cols:
        meta = None
        pt = {"float64": "float64", "int64": "int64", "Int64": "int64", "uint8": "uint8", "bool": "bool",
              "boolean": "bool", "string": "unicode", "category": "categorical"}[c.dtype]
        nt = {"boolean": "boolean", "string": "string"}.get(c.dtype, c.dtype)
        if c.dtype == "category":
            col = table.column(c.name)
            k = len(col.chunk(0).dictionary) if col.num_chunks else 0
            meta = {"num_categories": k, "ordered": False}
            nt = "int8" if k < 2**7 else "int16" if k < 2**15 else "int32"
        entries.append({"name": c.name, "field_name": c.name, "pandas_type": pt, "numpy_type": nt,
                        "metadata": meta})
    return _json.dumps({"index_columns": [], "column_indexes": [], "columns": entries, "attributes": {},
                        "creator": {"library": "pyarrow", "version": pa.__version__},
                        "pandas_version": _pandas_version()}).encode()


@_functools.lru_cache(maxsize=1)
def _pandas_version() -> str:
    """The installed pandas' version, read from its distribution metadata (no import)."""
    import importlib.metadata as im

    try:
        return im.version("pandas")
    except im.PackageNotFoundError:  # pragma: no cover - pandas is a core dependency
        return ""


# --- issue 15: trajectory learning (results/align/<set>/*.parquet) ------------------------------
# Maneuvers are rows (static DAG): every table has a ``maneuver`` column. The 13 demo
# dimensions are the ``state`` names of NED position, velocity, acceleration and the
# quaternion, in the set's box frame (pipeline.align.demos.DEMO_COLUMNS).
_ALIGN_DIMS: tuple[tuple[str, str], ...] = (
    *((f"pos_{a}_m", "m") for a in _NED), *((f"vel_{a}_mps", "m/s") for a in _NED),
    *((f"acc_{a}_mps2", "m/s^2") for a in _NED), *((f"q_{c}", "1") for c in "wxyz"))
_ALIGN_KEY: tuple[Column, ...] = (
    Column("maneuver", "string", "", "", "segment label"),
)
#: ``learned``: per hidden step t the smoothed mean μ_t, diag Σ_t, the bias β_t and the model
#: prediction error (NaN where the learner gives none, e.g. the last step).
ALIGN_LEARNED: tuple[Column, ...] = (
    *_ALIGN_KEY,
    Column("t", "int64", "1", "", "hidden time step"),
    _f("t_s", "s", "", "hidden time (t * hidden dt)"),
    *(_f(f"mu_{n}", u, "box", "learned trajectory (smoothed mean)") for n, u in _ALIGN_DIMS),
    *(_f(f"var_{n}", f"({u})^2", "box", "smoothed variance (diag of Sigma_t)") for n, u in _ALIGN_DIMS),
    *(_f(f"beta_{n}", u, "box", "bias term beta_t") for n, u in _ALIGN_DIMS),
    *(_f(f"mpe_{n}", u, "box", "model prediction error") for n, u in _ALIGN_DIMS),
)
#: ``alignment``: per demo sample j its hidden step τ_j and the demo's step probabilities d;
#: a dropped or skipped demo is one row (j = -1) with the reason.
ALIGN_ALIGNMENT: tuple[Column, ...] = (
    *_ALIGN_KEY,
    Column("demo", "string", "", "", "<flight>:<label>#<k>"),
    Column("flight_id", "string"),
    Column("segment_id", "int64"),
    Column("status", "string", "", "", "used, dropped (bad demo) or skipped (maneuver not learned)"),
    Column("reason", "string", "", "", "why dropped or skipped, '' when used"),
    Column("frame", "string", "", "", "box (FlightCoach heading), rigid (fitted to the reference), ned"),
    _f("heading_rad", "rad", "", "rotation about down into the box frame"),
    Column("j", "int64", "1", "", "demo sample (-1: none)"),
    Column("t_ns", "int64", "ns", "", "the demo sample's time on its flight's clock"),
    Column("tau", "int64", "1", "", "hidden step of the sample (-1: none)"),
    *(_f(f"d_{i}", "1", "", f"probability of a {i}-step jump of tau") for i in (1, 2, 3)),
)
#: ``iterations``: per EM iteration the log-likelihood and the diagonals of Σ^(z) and Σ^(y);
#: a skipped maneuver is one row (iteration -1) with the reason.
ALIGN_ITERATIONS: tuple[Column, ...] = (
    *_ALIGN_KEY,
    Column("iteration", "int64", "1", "", "EM iteration (0 = initial; -1: not fitted)"),
    _f("loglik", "1", "", "log-likelihood"),
    *(_f(f"sigma_z_{n}", f"({u})^2", "box", "process noise Sigma^(z) diagonal") for n, u in _ALIGN_DIMS),
    *(_f(f"sigma_y_{n}", f"({u})^2", "box", "observation noise Sigma^(y) diagonal") for n, u in _ALIGN_DIMS),
    Column("status", "string", "", "", "ok, or skipped"),
    Column("reason", "string"),
    Column("n_demos", "int64"),
    Column("converged", "bool"),
)
#: ``demos``: each used demo on the hidden time axis (sample j at hidden step τ_j).
ALIGN_DEMOS: tuple[Column, ...] = (
    *_ALIGN_KEY,
    Column("demo", "string"),
    Column("flight_id", "string"),
    Column("j", "int64"),
    Column("tau", "int64", "1", "", "hidden step"),
    _f("t_s", "s", "", "hidden time of the sample"),
    *(_f(n, u, "box") for n, u in _ALIGN_DIMS),
)
TABLES.update({"align_learned": ALIGN_LEARNED, "align_alignment": ALIGN_ALIGNMENT,
               "align_iterations": ALIGN_ITERATIONS, "align_demos": ALIGN_DEMOS})


# --- the studies' result tables (results/studies/<study>/<table>.parquet) -----------------------
# Declared like every other table: pipeline.io.parquet.write_table looks a study table up here by
# the name it writes under (``<study>_<table>``) and casts it to these types, units and order,
# refusing a column not declared. A part that did not run writes the declared columns, no rows.
# Units: a column whose physical unit depends on another column of its row (``component``,
# ``quantity``) has unit "" and says so in its doc.
_STUDY_STATE = (*((f"pos_{a}_m", "m") for a in _NED), *((f"vel_{a}_mps", "m/s") for a in _NED),
          *((f"acc_{a}_mps2", "m/s^2") for a in _NED))
_STUDY_KNOWN = ("M1", "M2", "M3", "M4")

# shared by seed000_tables_3_10_3_12 and seed000_tables_3_13_3_15 (switch_stats)
_STUDY_SWITCH = (
    Column("table", "string", "", "", "thesis table of the cell (3.10/3.11/3.12 truth; 3.13/3.14/3.15 EKF)"),
    _f("switch_s", "s", "", "time of the maneuver switch"),
    Column("scenario", "string", "", "", "change scenario A-D"),
    Column("first", "string", "", "", "maneuver before the switch"),
    Column("final", "string", "", "", "maneuver after the switch"),
    Column("mode", "string", "", "", "classifier mode: cumulative, windowed or reset"),
    Column("n_runs", "int64", "1", "", "runs in the cell"),
    _f("FA_initial_pct", "%", "", "runs whose label just before the switch is the first maneuver"),
    _f("FA_final_pct", "%", "", "runs whose final label is the final maneuver"),
    _f("MAoT_initial_pct", "%", "", "mean accuracy over time before the switch"),
    _f("MAoT_final_pct", "%", "", "mean accuracy over time from the end of the 2 s blend"),
    _f("detection_delay_s", "s", "", "median time from the switch until the final maneuver holds 1 s (NaN: never)"),
    _f("detected_pct", "%", "", "runs where the final maneuver was detected"),
    _f("change_point_s", "s", "", "median detected change point (NaN: none)"),
    _f("thesis_FA_initial_pct", "%", "", "thesis FA of the first maneuver (NaN: no thesis value)"),
    _f("thesis_FA_final_pct", "%", "", "thesis FA of the final maneuver (NaN: no thesis value)"),
    _f("thesis_MAoT_initial_pct", "%", "", "thesis MAoT of the first maneuver (NaN: no thesis value)"),
    _f("thesis_MAoT_final_pct", "%", "", "thesis MAoT of the final maneuver (NaN: no thesis value)"),
)

# shared by flightcoach_p23_segments and flightcoach_f23_segments (per_segment)
_FC_SEGMENTS = (
    Column("segment_id", "int64", "", "", "labelled segment of the flight"),
    Column("label", "string", "", "", "true maneuver label of the segment"),
    Column("known", "bool", "", "", "the label has a trained model"),
    _f("t_start_s", "s", "", "segment start on the flight's clock"),
    _f("duration_s", "s", "", "segment duration"),
    Column("pred_end", "string", "", "", "decided label at segment end (or unknown)"),
    Column("best_end", "string", "", "", "most likely model at segment end"),
    _f("V_end", "1", "", "confidence V of the best model at segment end"),
    Column("oneclass_ok_end", "bool", "", "", "best model passes its one-class threshold at segment end"),
    Column("correct_end", "bool", "", "", "label at segment end is right (unknown for unknown maneuvers)"),
    _f("MAoT_pct", "%", "", "share of the segment's samples labelled right"),
    _f("accepted_pct", "%", "", "share of the segment's samples not labelled unknown"),
)

# shared by flightcoach_ekf_hmm_maneuvers and flightcoach_ekf_hmm_train_maneuvers (per_maneuver)
_FC_EKF_MANEUVERS = (
    Column("segment_id", "int64", "", "", "labelled segment of the flight"),
    Column("label", "string", "", "", "true maneuver label"),
    _f("t_start_s", "s", "", "segment start on the flight's clock"),
    _f("duration_s", "s", "", "segment duration"),
    Column("n_steps", "int64", "1", "", "5 Hz radar steps in the segment"),
    _f("hmm_share_pct", "%", "", "share of steps predicted with HMM inputs"),
    Column("pred_end", "string", "", "", "classifier label at segment end"),
    _f("label_pct", "%", "", "share of steps the classifier labels with the true label"),
    _f("ekf_pos_rmse_m", "m", "", "EKF position RMSE against the reference (norm over NED axes)"),
    _f("ekf_hmm_pos_rmse_m", "m", "", "EKF+HMM output position RMSE (norm over NED axes)"),
    _f("ekf_vel_rmse_mps", "m/s", "", "EKF velocity RMSE (norm over NED axes)"),
    _f("ekf_hmm_vel_rmse_mps", "m/s", "", "EKF+HMM output velocity RMSE (norm over NED axes)"),
    _f("ekf_acc_rmse_mps2", "m/s^2", "", "EKF acceleration RMSE (norm over NED axes)"),
    _f("ekf_hmm_acc_rmse_mps2", "m/s^2", "", "EKF+HMM output acceleration RMSE (norm over NED axes)"),
    _f("gmr_acc_rmse_mps2", "m/s^2", "", "GMR acceleration input RMSE on the steps that used it (NaN: none)"),
    _f("acc_ratio", "1", "", "ekf_hmm_acc_rmse / ekf_acc_rmse"),
    Column("better", "bool", "", "", "acc_ratio < 0.95 and HMM inputs on >= 20 % of steps"),
)

_STUDY_TABLES_A: dict[str, tuple[Column, ...]] = {
    # pipeline/studies/seed000_classification.py (per_maneuver_table + thesis_side_by_side)
    "seed000_classification_tables_3_1_3_4": (
        Column("table", "string", "", "", "thesis table of the row (3.1 ... 3.4; ours 3.4+1c, 3.4+bg)"),
        Column("classifier", "string", "", "", "decision: oneclass, confidence, both, confidence_bg"),
        Column("split", "string", "", "", "train or test runs"),
        Column("maneuver", "string", "", "", "true maneuver M1-M5"),
        Column("n_runs", "int64", "1", "", "runs of the maneuver"),
        _f("FA_pct", "%", "", "final accuracy: runs whose final label is right"),
        _f("MAoT_pct", "%", "", "mean accuracy over time"),
        _f("thesis_FA_pct", "%", "", "thesis FA (NaN: no thesis value)"),
        _f("thesis_MAoT_pct", "%", "", "thesis MAoT (NaN: no thesis value)"),
    ),
    # pipeline/studies/seed000_classification.py (models.metrics.confusion; columns KNOWN + unknown)
    "seed000_classification_confusion": (
        Column("truth", "string", "", "", "true maneuver (row of the confusion matrix)"),
        *(Column(m, "int64", "1", "", f"runs whose final label is {m}") for m in _STUDY_KNOWN),
        Column("unknown", "int64", "1", "", "runs whose final label is unknown (or any label outside M1-M4)"),
        Column("table", "string", "", "", "thesis table of the classification (3.1 ... 3.4+bg)"),
    ),
    # pipeline/studies/seed000_classification.py (switch_stats; truth input)
    "seed000_classification_switch_tables": _STUDY_SWITCH,
    # pipeline/studies/seed000_classification.py (reset-mode switch moved by +-1 s)
    "seed000_classification_switch_shift": (
        Column("scenario", "string", "", "", "change scenario A-D"),
        _f("base_switch_s", "s", "", "thesis switch time (3, 8, 13 s)"),
        _f("switch_s", "s", "", "switch time used (base - 1, base, base + 1)"),
        _f("change_point_s", "s", "", "median reset-mode change point (NaN: none)"),
        _f("detection_delay_s", "s", "", "median detection delay (NaN: never)"),
    ),
    # pipeline/studies/seed000_classification.py (gmr_errors)
    "seed000_classification_gmr_error": (
        Column("maneuver", "string", "", "", "maneuver M1-M4"),
        Column("quantity", "string", "", "",
               "acc_fd, acc, jerk, acc_<variant>, jerk_<variant> (variants _pos, _interval, _posfd, _posvel)"),
        Column("axis", "string", "", "", "NED axis n, e or d"),
        _f("t_s", "s", "", "time in the run"),
        _f("mean_err", "", "NED", "mean error over test runs; unit of `quantity`: m/s^2 (acc*) or m/s^3 (jerk*)"),
        _f("err_var", "", "NED",
           "error variance over test runs; square of the unit of `quantity`: (m/s^2)^2 or (m/s^3)^2"),
    ),
    # pipeline/studies/seed000_classification.py (gmr_errors)
    "seed000_classification_gmr_rmse": (
        Column("maneuver", "string", "", "", "maneuver M1-M4"),
        Column("quantity", "string", "", "", "acc_fd, acc, jerk, acc_<variant>, jerk_<variant>"),
        _f("rmse", "", "", "RMSE over the common samples; unit of `quantity`: m/s^2 (acc*) or m/s^3 (jerk*)"),
        Column("n", "int64", "1", "", "samples (all axes) the RMSE is over"),
    ),
    # pipeline/studies/seed000_classification.py (ekf_tables; only with ekf_input, else empty)
    "seed000_classification_ekf_tables": (
        Column("table", "string", "", "", "thesis table of the row (3.5 ... 3.8; ours 3.8+bg)"),
        Column("classifier", "string", "", "", "decision: oneclass, confidence, confidence_bg"),
        Column("split", "string", "", "", "train or test runs"),
        Column("trained_on", "string", "", "", "models trained on truth or ekf estimates"),
        Column("increments", "string", "", "", "what the classifier sees: prior or posterior increments"),
        Column("maneuver", "string", "", "", "true maneuver M1-M5"),
        Column("n_runs", "int64", "1", "", "runs of the maneuver"),
        _f("FA_pct", "%", "", "final accuracy on EKF input"),
        _f("MAoT_pct", "%", "", "mean accuracy over time on EKF input"),
        _f("thesis_FA_pct", "%", "", "thesis FA (NaN: no thesis value)"),
        _f("thesis_MAoT_pct", "%", "", "thesis MAoT (NaN: no thesis value)"),
        _f("MAoT_after_5s_pct", "%", "", "MAoT without each run's first 5 s (ours, STARTUP_S)"),
    ),
    # pipeline/studies/seed000_classification.py (ekf_switch_tables; only with ekf_input and switch)
    "seed000_classification_ekf_switch_tables": (
        *_STUDY_SWITCH,
        Column("trained_on", "string", "", "", "models trained on truth or ekf estimates"),
    ),

    # pipeline/studies/seed000_ekf.py (tune_q_on_training)
    "seed000_ekf_q_tuning": (
        _f("q", "m^2/s^5", "", "white-jerk density of the grid"),
        _f("score", "1", "", "normalised RMSE pooled over M1-M4 (minimum chosen)"),
        Column("chosen", "bool", "", "", "the frozen q"),
        *(_f(f"rmse_{n}", u, "NED", "pooled RMSE of the state component") for n, u in _STUDY_STATE),
        _f("rmse_pos_m", "m", "", "pooled 3-D position RMSE"),
        _f("rmse_vel_mps", "m/s", "", "pooled 3-D velocity RMSE"),
        _f("rmse_acc_mps2", "m/s^2", "", "pooled 3-D acceleration RMSE"),
        *(_f(f"score_{m}", "1", "", f"normalised RMSE on {m}'s tuning runs") for m in _STUDY_KNOWN),
    ),
    # pipeline/studies/seed000_ekf.py (mc_maneuver)
    "seed000_ekf_mc_time": (
        Column("maneuver", "string", "", "", "Monte Carlo maneuver (mc_<M>)"),
        Column("filter", "string", "", "", "ekf or rts"),
        _f("t_s", "s", "", "time since the first step"),
        Column("component", "string", "", "", "state component pos_n_m ... acc_d_mps2 (its unit in the name)"),
        _f("mean_err", "", "NED", "mean error over runs; unit of `component`: m, m/s or m/s^2"),
        _f("err_var", "", "NED", "error variance over runs; square of the unit of `component`"),
        _f("filter_var", "", "NED", "mean filter variance (diag P); square of the unit of `component`"),
        _f("nees_avg", "1", "", "run-averaged NEES at this step"),
    ),
    # pipeline/studies/seed000_ekf.py (mc_maneuver summary)
    "seed000_ekf_mc_rmse": (
        Column("maneuver", "string", "", "", "Monte Carlo maneuver"),
        Column("n_runs", "int64", "1", "", "Monte Carlo runs"),
        Column("n_steps", "int64", "1", "", "steps per run"),
        _f("nees_band_lo", "1", "", "lower bound of the 95 % band of chi2(9N)/N"),
        _f("nees_band_hi", "1", "", "upper bound of the 95 % band of chi2(9N)/N"),
        *(c for f in ("ekf", "rts") for c in (
            _f(f"{f}_rmse_pos_m", "m", "", f"{f.upper()} 3-D position RMSE over runs and time"),
            _f(f"{f}_rmse_vel_mps", "m/s", "", f"{f.upper()} 3-D velocity RMSE over runs and time"),
            _f(f"{f}_rmse_acc_mps2", "m/s^2", "", f"{f.upper()} 3-D acceleration RMSE over runs and time"),
            _f(f"{f}_nees_mean", "1", "", f"time mean of the run-averaged {f.upper()} NEES"),
            _f(f"{f}_nees_in_band_pct", "%", "", f"steps whose run-averaged {f.upper()} NEES is in the band"),
            _f(f"{f}_var_ratio_median", "1", "",
               f"median MC error variance / {f.upper()} filter variance (NaN with one run)"),
        )),
    ),
    # pipeline/studies/seed000_ekf.py (tune_ekf_hmm; empty when skip: hmm)
    "seed000_ekf_q2_tuning": (
        Column("gmr_input", "string", "", "", "GMR conditioning block: pos, pos_fd, pos_vel"),
        _f("gate_mps2", "m/s^2", "", "GMR outlier gate (per step)"),
        Column("q2_input", "string", "", "", "what the GMR sees when Q2 is estimated: truth or ekf"),
        _f("q2_scale", "1", "", "scale of the estimated Q2"),
        _f("score", "1", "", "mean over components of pooled EKF+HMM RMSE / EKF RMSE"),
        _f("hmm_rmse_pos_m", "m", "", "EKF+HMM output 3-D position RMSE, pooled"),
        _f("ekf_rmse_pos_m", "m", "", "EKF 3-D position RMSE, pooled"),
        _f("hmm_rmse_vel_n_mps", "m/s", "NED", "EKF+HMM output north velocity RMSE, pooled"),
        _f("ekf_rmse_vel_n_mps", "m/s", "NED", "EKF north velocity RMSE, pooled"),
        _f("hmm_rmse_vel_e_mps", "m/s", "NED", "EKF+HMM output east velocity RMSE, pooled"),
        _f("ekf_rmse_vel_e_mps", "m/s", "NED", "EKF east velocity RMSE, pooled"),
        _f("hmm_rmse_vel_d_mps", "m/s", "NED", "EKF+HMM output down velocity RMSE, pooled"),
        _f("ekf_rmse_vel_d_mps", "m/s", "NED", "EKF down velocity RMSE, pooled"),
        _f("hmm_rmse_acc_mps2", "m/s^2", "", "EKF+HMM output 3-D acceleration RMSE, pooled"),
        _f("ekf_rmse_acc_mps2", "m/s^2", "", "EKF 3-D acceleration RMSE, pooled"),
        Column("chosen", "bool", "", "", "the frozen candidate (lowest score)"),
    ),
    # pipeline/studies/seed000_ekf.py (hmm_maneuver + input_quality; empty when skip: hmm)
    "seed000_ekf_scenarios": (
        Column("maneuver", "string", "", "", "maneuver M1-M4"),
        Column("scenario", "string", "", "", "S1 (best test run) or S2 (worst)"),
        Column("run_id", "int64", "", "", "test run chosen for the scenario"),
        _f("summed_abs_error", "", "",
           "summed |EKF+HMM error| over steps and the 9 state components (mixed m, m/s, m/s^2)"),
        Column("n_realisations", "int64", "1", "", "radar noise realisations"),
        _f("MAoT_pct", "%", "", "classifier mean accuracy over time"),
        _f("thesis_MAoT_pct", "%", "", "thesis Chapter-4 MAoT"),
        _f("hmm_mode_pct", "%", "", "share of steps in HMM mode"),
        _f("hmm_output_pct", "%", "", "share of steps whose output is the EKF+HMM estimate"),
        _f("gated_pct", "%", "", "share of GMR inputs dropped by the gate"),
        _f("gmr_input_acc_rmse_mps2", "m/s^2", "", "3-D RMSE of the GMR acceleration input on HMM steps (NaN: none)"),
        _f("ekf_acc_rmse_on_hmm_steps_mps2", "m/s^2", "", "EKF 3-D acceleration RMSE on the same steps (NaN: none)"),
        _f("ekf_hmm_acc_rmse_on_hmm_steps_mps2", "m/s^2", "",
           "EKF+HMM output 3-D acceleration RMSE on the same steps (NaN: none)"),
    ),
    # pipeline/studies/seed000_ekf.py (group_rmse; empty when skip: hmm)
    "seed000_ekf_hmm_rmse": (
        Column("maneuver", "string", "", "", "maneuver M1-M4"),
        Column("scenario", "string", "", "", "S1 or S2"),
        Column("filter", "string", "", "", "ekf or ekf_hmm"),
        _f("pos_m", "m", "", "3-D position RMSE over realisations and time"),
        _f("vel_n_mps", "m/s", "NED", "north velocity RMSE"),
        _f("vel_e_mps", "m/s", "NED", "east velocity RMSE"),
        _f("vel_d_mps", "m/s", "NED", "down velocity RMSE"),
        _f("acc_mps2", "m/s^2", "", "3-D acceleration RMSE"),
    ),
    # pipeline/studies/seed000_ekf.py (hmm_maneuver; empty when skip: hmm)
    "seed000_ekf_hmm_time": (
        Column("maneuver", "string", "", "", "maneuver M1-M4"),
        Column("scenario", "string", "", "", "S1 or S2"),
        Column("filter", "string", "", "", "ekf or ekf_hmm"),
        _f("t_s", "s", "", "time since the first step"),
        Column("component", "string", "", "", "state component pos_n_m ... acc_d_mps2 (its unit in the name)"),
        _f("mean_err", "", "NED", "mean error over realisations; unit of `component`: m, m/s or m/s^2"),
        _f("err_var", "", "NED", "error variance over realisations; square of the unit of `component`"),
        _f("filter_var", "", "NED", "mean filter variance (diag P); square of the unit of `component`"),
        _f("mode_pct", "%", "", "share of realisations in HMM mode at this step"),
    ),

    # pipeline/studies/flightcoach_classification.py (per_segment; P23 #350, reset per segment)
    "flightcoach_classification_p23_segments": _FC_SEGMENTS,
    # pipeline/studies/flightcoach_classification.py (timeline; whole flight, windowed)
    "flightcoach_classification_p23_timeline": (
        _f("t_start_s", "s", "", "start of a run of one predicted label"),
        _f("t_end_s", "s", "", "last sample of the run"),
        Column("pred", "string", "", "", "predicted label"),
        Column("truth", "string", "", "", "true label at the run start"),
    ),
    # pipeline/studies/flightcoach_classification.py (sweep_row)
    "flightcoach_classification_oneclass_slack_sweep": (
        _f("slack_nats_per_sample", "1", "", "one-class slack (nats per sample)"),
        Column("auto", "bool", "", "", "the slack is the model set's auto slack"),
        _f("p21_known_accepted_pct", "%", "", "P21 known segments not labelled unknown at the end"),
        _f("p21_unknown_rejected_pct", "%", "", "P21 unknown segments labelled unknown at the end"),
        _f("p21_balanced_pct", "%", "", "mean of the two P21 shares (calibration score)"),
        _f("p21_balanced_over_time_pct", "%", "", "balanced P21 accuracy over all samples"),
        Column("p23_correct_at_end", "int64", "1", "", "P23 #350 segments right at segment end"),
        Column("p23_n", "int64", "1", "", "P23 #350 segments scored"),
        _f("f23_new_unknown_pct", "%", "", "F23 #35 new maneuvers labelled unknown at the end"),
        Column("f23_new_n", "int64", "1", "", "F23 #35 new maneuvers scored"),
    ),
    # pipeline/studies/flightcoach_classification.py (per_segment; F23 #35, decision both)
    "flightcoach_classification_f23_segments": _FC_SEGMENTS,

    # pipeline/studies/flightcoach_ekf_hmm.py (per_maneuver; test flight)
    "flightcoach_ekf_hmm_maneuvers": _FC_EKF_MANEUVERS,
    # pipeline/studies/flightcoach_ekf_hmm.py (per_maneuver; training flight, in-sample)
    "flightcoach_ekf_hmm_train_maneuvers": _FC_EKF_MANEUVERS,
    # pipeline/studies/flightcoach_ekf_hmm.py (q and Q2-scale grids)
    "flightcoach_ekf_hmm_tuning": (
        Column("parameter", "string", "", "", "q or q2_scale"),
        Column("gmr_input", "string", "", "", "GMR conditioning block ('' for q rows)"),
        _f("value", "", "", "grid value; unit of `parameter`: q m^2/s^5, q2_scale 1"),
        _f("score", "1", "", "q: normalised RMSE; q2_scale: mean EKF+HMM/EKF acceleration-RMSE ratio"),
        Column("chosen", "bool", "", "", "the frozen value"),
    ),
    # pipeline/studies/flightcoach_ekf_hmm.py (_timeline; test flight per 5 Hz step)
    "flightcoach_ekf_hmm_timeline": (
        _f("t_s", "s", "", "time since the first radar step"),
        Column("label", "string", "", "", "true maneuver label ('' outside segments)"),
        Column("pred", "string", "", "", "classifier label"),
        Column("mode", "bool", "", "", "step predicted with HMM inputs"),
        *(c for a in _NED for c in (
            _f(f"ref_acc_{a}_mps2", "m/s^2", "NED", "reference acceleration"),
            _f(f"ekf_acc_{a}_mps2", "m/s^2", "NED", "EKF acceleration"),
            _f(f"ekf_hmm_acc_{a}_mps2", "m/s^2", "NED", "EKF+HMM output acceleration"),
            _f(f"gmr_acc_{a}_mps2", "m/s^2", "NED", "GMR acceleration input"),
        )),
    ),
}

# the key of a seed-001 case, shared by its summary and its step times (pf_geolocation's ``key``)
_GEO_CASE = (
    Column("case", "string", "", "", "base, maneuvering, mobile, particles_<N>, observers_<O>"),
    Column("scenario", "string", "", "", "base, maneuvering or mobile (digest 001 §6.1-6.3)"),
    Column("n_observers", "int64", "1", "", "observer UAVs"),
    Column("n_particles", "int64", "1", "", "particles N"),
)
# a leave-one-out fold's distances to the left-out demo (real_loo; real_summary: their means)
_TL_RMS = (
    _f("rms_learned_m", "m", "", "RMS distance along the DTW path, learned trajectory to the left-out demo"),
    _f("rms_best_other_m", "m", "", "the same for the closest other demo"),
    _f("rms_worst_other_m", "m", "", "the same for the farthest other demo"),
    _f("rms_dba_m", "m", "", "the same for the others' DBA average"),
)

_STUDY_TABLES_B: dict[str, tuple[Column, ...]] = {
    # ---------------------------------------------------------------------------------------------
    # pipeline/studies/bearing_only.py (run_bearing_only -> write_table(name=f"bearing_only_{key}"),
    # key in OUTPUT_TABLES = curves, runs, trends, crlb, study3)
    # ---------------------------------------------------------------------------------------------
    # curves_table(): per configuration and kept step (every curve_every_s), means over the runs
    "bearing_only_curves": (
        Column("config", "string", "", "", "configuration name (bank preset, sweep_*, imm_td*_d*, crlb_*, study3_*)"),
        Column("part", "string", "", "", "study part: table_4_2, cppv_vs_mpc, sweeps, imm_grid, crlb, study3"),
        Column("kind", "string", "", "", "scenario kind of the encounter set (orbit, ct_cv, ct_cv_ct, cv_ct, cv_ct_cv)"),
        _f("t_s", "s", "", "time since the encounter start"),
        _f("thesis_r", "1", "", "thesis 'RMSE' of range: mean over runs of |r_hat - r| / |r| (digest §8)"),
        _f("thesis_v", "1", "", "thesis 'RMSE' of speed: mean over runs of |v_hat - v| / |v|"),
        _f("thesis_w", "1", "", "thesis 'RMSE' of turn rate: mean over runs of |w_hat - w| / |w| (NaN on straight truth)"),
        _f("heading_deg", "deg", "", "mean over runs of the heading error |wrap(theta_hat - theta)|"),
        _f("rmse_r_m", "m", "", "true range RMSE over runs"),
        _f("nees", "1", "", "mean 5-state CPPV NEES over runs (NaN without covariance)"),
        _f("mu_cv", "1", "", "IMM: mean CV-mode probability over runs (NaN for a bank)"),
        Column("n_runs", "int64", "1", "", "runs of the configuration"),
    ),
    # runs_table(): one row per configuration and run
    "bearing_only_runs": (
        Column("config", "string", "", "", "configuration name"),
        Column("part", "string", "", "", "study part"),
        Column("run", "int64", "", "", "run index in the shared scenario set"),
        _f("range_score", "1", "", "mean relative range error over score_window_s"),
        _f("heading_score_rad", "rad", "", "mean heading error over score_window_s"),
        _f("range_score_all", "1", "", "mean relative range error over imm_window_s"),
        _f("final_range_err", "1", "", "relative range error |r_hat - r| / r at the last step"),
        Column("diverged", "bool", "", "", "D8 divergence flag (final range error or NEES run too long)"),
    ),
    # trends() / _trend() / sign_test(): one row per component sign test of a trend
    "bearing_only_trends": (
        Column("trend", "string", "", "", "trend id (nr25, cppv_range, mpc_heading, delta_1e2_worse, delta_over_td, faster_ownship)"),
        Column("claim", "string", "", "", "the trend's claim in words"),
        Column("comparison", "string", "", "", "the component test 'a < b[, note]'"),
        _f("p", "1", "", "one-sided paired sign-test p-value of the component (NaN without runs)"),
        Column("n", "int64", "1", "", "runs where the pair differs (ties and NaN pairs dropped)"),
        Column("n_better", "int64", "1", "", "runs where the claimed winner is better"),
        _f("median_effect", "", "", "median paired difference b - a over every finite pair, ties included "
           "(> 0: a better); unit of the score: "
           "1 (relative range error or its spread) except trend mpc_heading: rad"),
        _f("frac_better", "1", "", "share of differing runs where the claimed winner is better"),
        _f("p_trend", "1", "", "the trend's p: the largest component p (NaN if any is undecided)"),
        Column("holds", "bool", "", "", "p_trend < alpha"),
        Column("note", "string", "", "", "free note ('' if none)"),
    ),
    # crlb_check(): one row per quantity and step of the fixed orbit
    "bearing_only_crlb": (
        Column("quantity", "string", "", "", "r, v, omega or theta"),
        _f("t_s", "s", "", "time since the encounter start"),
        _f("sample_std", "", "", "sample std of the estimate error over realisations; unit per quantity: "
           "r m, v m/s, omega rad/s, theta rad"),
        _f("sqrt_crlb", "", "", "sqrt of the CRLB (digest §7); unit per quantity as sample_std"),
        _f("ratio", "1", "", "sample_std / sqrt_crlb"),
        _f("floor_std", "", "", "error std of the ideal filter carrying the bank's Q (q_floor); unit per quantity as sample_std"),
        _f("floor_ratio", "1", "", "floor_std / sqrt_crlb"),
    ),
    # run_bearing_only(), study3 part: single IMM runs, one row per scenario and step
    "bearing_only_study3": (
        Column("scenario", "string", "", "", "ct_cv_ct, ct_cv_ct_redraw, cv_ct or cv_ct_cv"),
        _f("t_s", "s", "", "time since the encounter start"),
        _f("r_true_m", "m", "", "true range ownship-intruder"),
        _f("r_est_m", "m", "", "estimated range"),
        _f("theta_true_deg", "deg", "", "true intruder course (from N toward E)"),
        _f("theta_est_deg", "deg", "", "estimated intruder course"),
        _f("omega_true_degps", "deg/s", "", "true intruder turn rate (> 0 right turn)"),
        _f("omega_est_degps", "deg/s", "", "estimated intruder turn rate"),
        _f("mu_cv", "1", "", "IMM probability of the CV mode"),
        Column("mode_true", "int64", "", "", "true motion mode: 1 CT, 0 CV"),
    ),

    # ---------------------------------------------------------------------------------------------
    # pipeline/studies/pf.py (run_pf): seed-003 weave classifier (hmpf)
    # ---------------------------------------------------------------------------------------------
    # summarise(): one row per scenario and seed
    "pf_hmpf_runs": (
        Column("scenario", "string", "", "", "scenario (straight_gps, weave_radar, range_<d>, quadrant_<i>, ...)"),
        Column("sensor", "string", "", "", "gps or radar"),
        Column("seed", "int64", "", "", "noise realisation index"),
        _f("delta_max_m", "m", "", "filter's maximal straight length delta_max"),
        _f("theta_max_rad", "rad", "", "filter's maximal turn angle theta_max"),
        Column("method", "string", "", "", "submode switching rule: ifelse or min"),
        _f("straight_frac", "1", "", "mean S-mode fraction over steps after start-up"),
        _f("weave_frac_in_weave", "1", "", "mean W-mode fraction during the weave (NaN: no weave)"),
        _f("weave_frac_off_weave", "1", "", "mean W-mode fraction off the weave after start-up (NaN: none)"),
        Column("ever_flagged", "bool", "", "", "the detector flagged the weave at some step"),
        Column("first_flag_step", "int64", "1", "", "first flagged step (-1: never)"),
        Column("flagged_before_weave", "bool", "", "", "flagged before the weave began (false alarm)"),
        Column("third_turn_end_step", "int64", "1", "", "step at the end of the 3rd turn (-1: no weave)"),
        _f("flag_delay_steps", "1", "", "first flag in the weave minus the 3rd turn's end, steps of T = 1 s (NaN: none)"),
        _f("pos_rmse_m", "m", "", "per-axis position RMS error after start-up"),
        _f("vel_rmse_mps", "m/s", "", "per-axis velocity RMS error after start-up"),
        Column("n_reinit", "int64", "1", "", "all-zero-weight re-initialisations"),
    ),
    # timeline(): one row per scenario and step, over seeds
    "pf_hmpf_timeline": (
        Column("scenario", "string", "", "", "scenario"),
        Column("step", "int64", "1", "", "step k (T = 1 s)"),
        _f("truth_n_m", "m", "NED", "true north position"),
        _f("truth_e_m", "m", "NED", "true east position"),
        Column("in_weave", "bool", "", "", "the step lies in the weave"),
        *(_f(f"mode_p_{m}", "1", "", f"mean over seeds of the fraction of particles in mode {m} (straight/left/right/weave)")
          for m in ("S", "L", "R", "W")),
        _f("af", "1", "", "detector weave fraction AF(k), mean over seeds"),
        _f("af_seed0", "1", "", "AF(k) of seed 0"),
        _f("flagged_share", "1", "", "share of seeds flagged at the step"),
        Column("flag_seed0", "bool", "", "", "seed 0 flagged at the step"),
        _f("rmse_pos_n_m", "m", "NED", "RMS north position error over seeds"),
        _f("rmse_pos_e_m", "m", "NED", "RMS east position error over seeds"),
        _f("rmse_vel_n_mps", "m/s", "NED", "RMS north velocity error over seeds"),
        _f("rmse_vel_e_mps", "m/s", "NED", "RMS east velocity error over seeds"),
    ),

    # ---------------------------------------------------------------------------------------------
    # pipeline/studies/pf_geolocation.py (geolocation_study, written by pf.py as f"pf_{t}",
    # t in GEO_TABLES = geo_summary, geo_series, geo_config, geo_timing); rows from
    # pipeline/simulate/geolocation.py summarise() / per_step_frame()
    # ---------------------------------------------------------------------------------------------
    # one row per scenario / sweep point: key, duration, then summarise() without step_us
    "pf_geo_summary": (
        *_GEO_CASE,
        _f("duration_s", "s", "", "simulated duration of each run"),
        _f("eps_m", "m", "", "mean 3-D error pooled over time (after 1 s) and runs"),
        _f("eta_pct", "%", "", "mean percent error 100 eps_k / mean observer distance"),
        _f("median_eps_m", "m", "", "median 3-D error pooled over time and runs"),
        _f("mean_dist_m", "m", "", "mean observer-target distance"),
        _f("dist_lt_50_pct", "%", "", "share of time the mean observer-target distance is below 50 m"),
        _f("dist_60_80_pct", "%", "", "share of time the mean observer-target distance is within 60-80 m"),
        _f("dist_gt_80_pct", "%", "", "share of time the mean observer-target distance is above 80 m"),
        Column("n_runs", "int64", "1", "", "runs"),
        Column("n_reinit", "int64", "1", "", "filter re-initialisations summed over runs"),
        _f("median_run_eta_pct", "%", "", "median over runs of each run's mean eta%"),
        Column("n_lost", "int64", "1", "", "runs ending with no observer detecting the target"),
        _f("not_lost_eta_pct", "%", "", "pooled eta% over the runs not lost (NaN: all lost)"),
        _f("not_lost_eps_m", "m", "", "pooled 3-D error over the runs not lost (NaN: all lost)"),
    ),
    # per_step_frame(): per case and time index, means over runs
    "pf_geo_series": (
        _f("t_s", "s", "", "time since the run start"),
        _f("eps_m", "m", "", "3-D error eps_k, mean over runs"),
        _f("eta_pct", "%", "", "percent error eta_k, mean over runs"),
        _f("mean_dist_m", "m", "", "mean observer-target distance, mean over runs"),
        _f("neff", "1", "", "effective sample size, mean over runs"),
        Column("mode_p_*", "float64", "1", "", "fraction of particles per driving mode (stop, accel, decel, coast, "
               "turn; coast only for the CV-only base filter), mean over runs"),
        Column("case", "string", "", "", "case (as in pf_geo_summary)"),
    ),
    # the chosen config values (GeolocationConfig.meta() + size, seed, runs), JSON-encoded
    "pf_geo_config": (
        Column("key", "string", "", "", "setting name"),
        Column("value", "string", "", "", "setting value as JSON text (number, list, dict or string)"),
    ),
    # one row per scenario / sweep point: this machine's filter step time
    "pf_geo_timing": (
        *_GEO_CASE,
        _f("step_us", "us", "", "mean wall time of one filter step (perf_counter_ns, first step excluded)"),
    ),

    # ---------------------------------------------------------------------------------------------
    # pipeline/studies/trajectory_learning.py (run_trajectory_learning, f"trajectory_learning_{k}");
    # sim_* from pipeline/studies/trajectory_sim.py simulated_study()
    # ---------------------------------------------------------------------------------------------
    # one row per reference, seed and candidate method
    "trajectory_learning_sim_cases": (
        Column("reference", "string", "", "", "simulated reference (REFERENCES, YAK54_REFERENCES)"),
        Column("seed", "int64", "", "", "seed index i of the case"),
        Column("method", "string", "", "", "candidate: learned, best_demo, mean_demo, dba, dba_smoothed, "
               "best_smoothed_demo, mean_smoothed_demo (Yak54: + learned_no_bias, learned_kinematic)"),
        _f("rmse_m", "m", "", "position RMSE against the intended trajectory"),
        Column("n_iter", "int64", "1", "", "EM iterations of the case's main learner"),
        Column("converged", "bool", "", "", "the main learner converged"),
    ),
    # per reference and method over seeds
    "trajectory_learning_sim_summary": (
        Column("reference", "string", "", "", "simulated reference"),
        Column("method", "string", "", "", "candidate method"),
        _f("rmse_mean_m", "m", "", "mean over seeds of rmse_m"),
        _f("rmse_std_m", "m", "", "std over seeds of rmse_m (NaN with one seed)"),
        _f("rmse_min_m", "m", "", "min over seeds of rmse_m"),
        _f("rmse_max_m", "m", "", "max over seeds of rmse_m"),
        Column("n_seeds", "int64", "1", "", "seeds"),
        Column("learned_best", "bool", "", "", "the learned mean RMSE beats every baseline on the reference"),
    ),
    # loo_maneuver() / real_part(): one row per set, maneuver, frame and left-out demo
    # (a skipped maneuver or failed fit is one row with the rms columns NaN)
    "trajectory_learning_real_loo": (
        Column("set", "string", "", "", "align.sets demo set (p23, p21)"),
        Column("maneuver", "string", "", "", "maneuver label (label#k per occurrence with repeats: split)"),
        Column("frame", "string", "", "", "box (demos as they are) or centred (mean position subtracted)"),
        Column("left_out", "string", "", "", "left-out demo <flight>:<label>#<k> ('' for a skipped maneuver)"),
        Column("n_others", "int64", "1", "", "demos left to learn from (usable demos - 1 when skipped)"),
        Column("single_other", "bool", "", "", "only one other demo (learner given it twice)"),
        Column("status", "string", "", "", "ok, 'fit failed: ...' or 'skipped: ...'"),
        *_TL_RMS,
        Column("closest_other", "string", "", "", "name of the closest other demo (NA unless status ok)"),
        _f("rms_between_others_m", "m", "", "mean RMS distance between the training demos (NaN with one)"),
        Column("n_iter", "Int64", "1", "", "EM iterations of the fit (NA unless status ok)"),
    ),
    # real_part(): per frame, set and maneuver, means over its ok folds
    "trajectory_learning_real_summary": (
        Column("frame", "string", "", "", "box or centred"),
        Column("set", "string", "", "", "demo set"),
        Column("maneuver", "string", "", "", "maneuver label"),
        Column("folds", "int64", "1", "", "ok folds"),
        Column("demos", "int64", "1", "", "demos of the maneuver"),
        Column("single_other", "bool", "", "", "folds had only one other demo"),
        *(_f(c.name, c.unit, "", f"mean over folds of {c.name}") for c in _TL_RMS),
        Column("better", "bool", "", "", "rms_learned_m < rms_best_other_m"),
        Column("better_than_dba", "bool", "", "", "rms_learned_m < rms_dba_m"),
    ),
}

#: the studies' result tables by the name their file is written under
STUDY_RESULTS: dict[str, tuple[Column, ...]] = {**_STUDY_TABLES_A, **_STUDY_TABLES_B}
TABLES.update(STUDY_RESULTS)
