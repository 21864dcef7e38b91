"""Bit names of the ``estimator_status`` stream's flag columns, per source (the one table).

The readers copy the autopilots' bit fields as logged (:mod:`pipeline.io.schema`,
``estimator_status``); what a bit means depends on who wrote it, so the names live here, keyed
by a *layout* that :func:`layout_of` finds from the row's ``src``:

``ardupilot`` (DataFlash ``XKF4``/``XKF9``/``NKF4``/``NKF9``/``EKF4``)
    ``solution_flags`` = ``SS``: ``union nav_filter_status`` and ``gps_check_flags`` = ``GPS``:
    ``union nav_gps_status``, both in ArduPilot ``libraries/AP_NavEKF/AP_Nav_Common.h``
    (bits 15-18 of ``nav_filter_status`` exist from Copter 4.0 on; older firmware leaves them
    0); ``fault_flags`` = ``FS``: ``NavEKF2_core/NavEKF3_core::getFilterFaults`` (the comment
    block in ``AP_NavEKF3_Outputs.cpp``); ``timeout_flags`` = ``TS``: the ``XKF4`` field
    documentation in ``AP_NavEKF3/LogStructure.h`` ("0:position measurement, 1:velocity
    measurement, 2:height measurement, 3:magnetometer measurement, 4:airspeed measurement,
    5:drag measurement").
``mavlink_ekf`` (tlog ``EKF_STATUS_REPORT``)
    ``solution_flags`` = ``flags``: MAVLink ``EKF_STATUS_FLAGS`` (``ardupilotmega.xml``; the
    values are checked against pymavlink's enum in the tests).
``px4`` / ``px4_legacy`` (ULog ``estimator_status``, tlog ``ESTIMATOR_STATUS``)
    PX4 ``msg/EstimatorStatus.msg``: ``solution_status_flags`` (= MAVLink
    ``ESTIMATOR_STATUS_FLAGS``), ``gps_check_fail_flags`` (``GPS_CHECK_FAIL_*``),
    ``control_mode_flags`` (``CS_*``), ``timeout_flags`` (the legacy "vel, pos, hgt" mask).
    ``filter_fault_flags`` changed layout when EKF2 dropped its per-axis velocity/position
    fusion faults: ``px4`` is the current ``fault_status_u`` (EKF ``common.h``), ``px4_legacy``
    the 0-17 one of PX4 1.9-1.13; the ULog reader picks one from the log's own
    ``estimator_status_flags`` fields (:mod:`pipeline.io.ulog`). ``innovation_check_flags``
    (legacy only; the field left ``estimator_status`` later) follows the PX4 1.9-1.13
    ``estimator_status.msg``, or the log's own ``reject_*`` names where it logs them (also for the
    ``estimator_status_flags`` rows the ULog reader packs from those booleans, PX4 1.14+). PX4
    releases before 1.7 (``estimator_status`` with ``nan_flags``) numbered
    ``gps_check_fail_flags`` and ``control_mode_flags`` differently; their bits are named by
    this table all the same.

A bit with no name here is shown as ``bit <k>``. The ROS 1/2, MCAP, FlightCoach and CSV readers
have no such message: their ``estimator_status`` stream is empty.
"""

from __future__ import annotations

import numpy as np

#: ArduPilot ``nav_filter_status`` (AP_Nav_Common.h), bit -> name
AP_NAV_FILTER_STATUS = dict(enumerate((
    "attitude", "horiz_vel", "vert_vel", "horiz_pos_rel", "horiz_pos_abs", "vert_pos", "terrain_alt",
    "const_pos_mode", "pred_horiz_pos_rel", "pred_horiz_pos_abs", "takeoff_detected", "takeoff",
    "touchdown", "using_gps", "gps_glitching", "gps_quality_good", "initialized", "rejecting_airspeed",
    "dead_reckoning")))
#: ArduPilot ``nav_gps_status`` (AP_Nav_Common.h): GPS checks failing
AP_NAV_GPS_STATUS = dict(enumerate((
    "bad_sAcc", "bad_hAcc", "bad_yaw", "bad_sats", "bad_VZ", "bad_horiz_drift", "bad_hdop", "bad_vert_vel",
    "bad_fix", "bad_horiz_vel", "bad_vAcc")))
#: ArduPilot EKF2/EKF3 ``getFilterFaults``
AP_FILTER_FAULTS = dict(enumerate((
    "quaternions_nan", "velocities_nan", "bad_mag_x_fusion", "bad_mag_y_fusion", "bad_mag_z_fusion",
    "bad_airspeed_fusion", "bad_sideslip_fusion", "not_initialised")))
#: ArduPilot ``XKF4.TS`` (AP_NavEKF3/LogStructure.h)
AP_TIMEOUTS = dict(enumerate(("position", "velocity", "height", "magnetometer", "airspeed", "drag")))

#: MAVLink ``EKF_STATUS_FLAGS`` (ardupilotmega.xml): bit -> name (sparse)
MAVLINK_EKF_STATUS_FLAGS = {
    0: "attitude", 1: "velocity_horiz", 2: "velocity_vert", 3: "pos_horiz_rel", 4: "pos_horiz_abs",
    5: "pos_vert_abs", 6: "pos_vert_agl", 7: "const_pos_mode", 8: "pred_pos_horiz_rel",
    9: "pred_pos_horiz_abs", 10: "uninitialized", 15: "gps_glitching"}

#: PX4 ``solution_status_flags`` = MAVLink ``ESTIMATOR_STATUS_FLAGS``
PX4_SOLUTION_STATUS = dict(enumerate((
    "attitude", "velocity_horiz", "velocity_vert", "pos_horiz_rel", "pos_horiz_abs", "pos_vert_abs",
    "pos_vert_agl", "const_pos_mode", "pred_pos_horiz_rel", "pred_pos_horiz_abs", "gps_glitch",
    "accel_error")))
#: PX4 ``filter_fault_flags``, current layout (``fault_status_u`` in ``src/modules/ekf2/EKF/common.h``
#: since the per-axis velocity/position fusion faults were removed; the ULog ``estimator_status_flags``
#: of ``ekf_failure.ulg``, PX4 1.15, sets ``fs_bad_acc_vertical`` when this field reads 1024)
PX4_FILTER_FAULTS = {
    **dict(enumerate(("bad_mag_x", "bad_mag_y", "bad_mag_z", "bad_hdg", "bad_mag_decl", "bad_airspeed",
                      "bad_sideslip", "bad_optflow_x", "bad_optflow_y"))),
    10: "bad_acc_vertical", 11: "bad_acc_clipping"}
#: PX4 ``filter_fault_flags``, legacy layout (``msg/estimator_status.msg`` / ``EstimatorStatus.msg``
#: comments, the ECL ``fault_status_u`` of PX4 1.9-1.13)
PX4_FILTER_FAULTS_LEGACY = dict(enumerate((
    "bad_mag_x", "bad_mag_y", "bad_mag_z", "bad_hdg", "bad_mag_decl", "bad_airspeed", "bad_sideslip",
    "bad_optflow_x", "bad_optflow_y", "bad_vel_n", "bad_vel_e", "bad_vel_d", "bad_pos_n", "bad_pos_e",
    "bad_pos_d", "bad_acc_bias", "bad_acc_vertical", "bad_acc_clipping")))
#: PX4 ``innovation_check_flags`` (estimator_status.msg, PX4 1.9-1.13): observation rejected
PX4_INNOVATION_CHECKS = dict(enumerate((
    "reject_vel", "reject_pos_horiz", "reject_pos_vert", "reject_mag_x", "reject_mag_y", "reject_mag_z",
    "reject_yaw", "reject_airspeed", "reject_sideslip", "reject_hagl", "reject_optflow_x",
    "reject_optflow_y")))
#: PX4 ``gps_check_fail_flags`` (``GPS_CHECK_FAIL_*``)
PX4_GPS_CHECKS = dict(enumerate((
    "gps_fix", "min_sat_count", "max_pdop", "max_horz_err", "max_vert_err", "max_spd_err", "max_horz_drift",
    "max_vert_drift", "max_horz_spd_err", "max_vert_spd_err", "spoofed")))
#: PX4 ``control_mode_flags`` (``CS_*`` of EstimatorStatus.msg; bits 21 and 28-42 as the ``cs_*``
#: fields of ``estimator_status_flags`` name them, in the order of ``ekf_failure.ulg``, PX4 1.15:
#: the tests check this table against that log)
PX4_CONTROL_MODE = {
    **dict(enumerate((
        "tilt_align", "yaw_align", "gps", "opt_flow", "mag_hdg", "mag_3d", "mag_dec", "in_air", "wind",
        "baro_hgt", "rng_hgt", "gps_hgt", "ev_pos", "ev_yaw", "ev_hgt", "fuse_beta", "mag_field_disturbed",
        "fixed_wing", "mag_fault", "fuse_aspd", "gnd_effect", "rng_stuck", "gnss_yaw", "mag_aligned_in_flight",
        "ev_vel", "synthetic_mag_z", "vehicle_at_rest", "gnss_yaw_fault", "rng_fault", "inertial_dead_reckoning",
        "wind_dead_reckoning", "rng_kin_consistent", "fake_pos", "fake_hgt", "gravity_vector", "mag",
        "ev_yaw_fault", "mag_heading_consistent", "aux_gpos", "rng_terrain", "opt_flow_terrain",
        "valid_fake_pos", "constant_pos"))),
    44: "gnss_vel"}
#: PX4 legacy ``timeout_flags`` ("vel, pos, hgt")
PX4_TIMEOUTS = {0: "vel", 1: "pos", 2: "hgt"}

#: layout -> flag column -> {bit: name}
LAYOUTS: dict[str, dict[str, dict[int, str]]] = {
    "ardupilot": {"solution_flags": AP_NAV_FILTER_STATUS, "gps_check_flags": AP_NAV_GPS_STATUS,
                  "fault_flags": AP_FILTER_FAULTS, "timeout_flags": AP_TIMEOUTS},
    "mavlink_ekf": {"solution_flags": MAVLINK_EKF_STATUS_FLAGS},
    "px4": {"solution_flags": PX4_SOLUTION_STATUS, "fault_flags": PX4_FILTER_FAULTS,
            "gps_check_flags": PX4_GPS_CHECKS, "control_mode_flags": PX4_CONTROL_MODE,
            "timeout_flags": PX4_TIMEOUTS},
    "px4_legacy": {"solution_flags": PX4_SOLUTION_STATUS, "fault_flags": PX4_FILTER_FAULTS_LEGACY,
                   "innovation_fail_flags": PX4_INNOVATION_CHECKS, "gps_check_flags": PX4_GPS_CHECKS,
                   "control_mode_flags": PX4_CONTROL_MODE, "timeout_flags": PX4_TIMEOUTS},
}
#: ``src`` -> layout
SRC_LAYOUT = {
    **{m: "ardupilot" for m in ("XKF4", "XKF9", "NKF4", "NKF9", "EKF4", "EKF9")},
    "EKF_STATUS_REPORT": "mavlink_ekf",
    "ESTIMATOR_STATUS": "px4",
    "estimator_status": "px4",
    "estimator_status_flags": "px4",
}
#: The flag columns of the stream, in display order.
FLAG_COLUMNS = ("solution_flags", "fault_flags", "innovation_fail_flags", "gps_check_flags",
                "timeout_flags", "control_mode_flags")


def layout_of(src: str, meta: dict | None = None) -> str | None:
    """The bit layout of rows whose ``src`` is ``src`` (``None``: unknown source); a reader that
    tells layouts apart records its choice in ``meta['estimator_status']['layout']`` (ULog)."""
    layout = SRC_LAYOUT.get(str(src))
    chosen = ((meta or {}).get("estimator_status") or {}).get("layout")
    if layout == "px4" and chosen in LAYOUTS and str(src) == "estimator_status":
        return chosen
    return layout


def bit_names(src: str, column: str, meta: dict | None = None) -> dict[int, str]:
    """``{bit: name}`` of flag ``column`` in rows from ``src`` (empty when unknown); names that
    the log itself gives (``meta['estimator_status'][column]``, a list in bit order) win."""
    own = ((meta or {}).get("estimator_status") or {}).get(column)
    if str(src) in ("estimator_status", "estimator_status_flags") and isinstance(own, list):
        return {k: str(n) for k, n in enumerate(own)}
    return dict(LAYOUTS.get(layout_of(src, meta) or "", {}).get(column, {}))


def bit_name(src: str, column: str, bit: int, meta: dict | None = None) -> str:
    """Name of ``bit`` of flag ``column`` in rows from ``src`` (``"bit <k>"`` when unnamed)."""
    return bit_names(src, column, meta).get(int(bit), f"bit {int(bit)}")


def bits_set(values) -> list[int]:
    """Bits that are set in at least one of ``values`` (integers; missing values ignored), ascending."""
    v = np.asarray(values)
    if v.dtype.kind == "f":
        v = v[np.isfinite(v)]
    v = v.astype(np.int64)
    acc = int(np.bitwise_or.reduce(v)) if len(v) else 0
    return [k for k in range(64) if acc >> k & 1]
