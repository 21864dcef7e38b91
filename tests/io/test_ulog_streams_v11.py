"""ULog schema 1.1 streams (battery, setpoint, messages, params, vibration, GPS quality) on the
real PX4 logs against pyulog's own parse (the oracle), values as logged after the documented
conversion."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import realdata_file
from pipeline.frames.rotations import quat_to_euler
from pipeline.io.registry import read_log

REAL = ("ulg_px4_flight_review_fixtures/ekf_failure.ulg", "ulg_px4_flight_review_fixtures/motor_failure.ulg")


@pytest.fixture(scope="module", params=REAL)
def real(request):
    import pyulog

    path = realdata_file(request.param)
    u = pyulog.ULog(str(path))
    topics = {}
    for d in u.data_list:
        topics.setdefault(d.name, []).append(d)
    return read_log(path), u, topics


def _rows(log, stream, src, inst=0):
    d = log[stream]
    return d[(d["src"].astype(str) == src) & (d["instance"] == inst)].reset_index(drop=True)


def _t(u, d):
    return (d.data["timestamp"].astype(np.int64) - int(u.start_timestamp)) * 1000


def test_battery_equals_pyulog_battery_status(real):
    log, u, topics = real
    d = topics["battery_status"][0]
    b = _rows(log, "battery", "battery_status")
    assert np.array_equal(b["t_ns"], _t(u, d))
    assert np.array_equal(b["voltage_V"], d.data["voltage_v"].astype(float))
    assert np.array_equal(b["current_A"], d.data["current_a"].astype(float))
    assert np.array_equal(b["consumed_Ah"], d.data["discharged_mah"].astype(float) * 1e-3)
    assert np.array_equal(b["remaining_frac"], d.data["remaining"].astype(float))


def test_setpoints_equal_pyulog_attitude_rates_and_velocity(real):
    log, u, topics = real
    d = topics["vehicle_attitude_setpoint"][0]
    a = _rows(log, "setpoint", "vehicle_attitude_setpoint")
    assert np.array_equal(a["t_ns"], _t(u, d))
    if "roll_body" in d.data:
        expect = [d.data[f"{k}_body"].astype(float) for k in ("roll", "pitch", "yaw")]
    else:
        expect = quat_to_euler(np.column_stack([d.data[f"q_d[{i}]"].astype(float) for i in range(4)]))
    for col, e in zip(("roll_rad", "pitch_rad", "yaw_rad"), expect):
        assert np.array_equal(a[col], e)
    r = topics["vehicle_rates_setpoint"][0]
    rr = _rows(log, "setpoint", "vehicle_rates_setpoint")
    for col, f in (("p_radps", "roll"), ("q_radps", "pitch"), ("r_radps", "yaw")):
        assert np.array_equal(rr[col], r.data[f].astype(float))
    v = topics["vehicle_local_position_setpoint"][0]
    vv = _rows(log, "setpoint", "vehicle_local_position_setpoint")
    for col, f in (("vel_n_mps", "vx"), ("vel_e_mps", "vy"), ("vel_d_mps", "vz")):
        assert np.array_equal(vv[col], v.data[f].astype(float), equal_nan=True)


def test_messages_and_params_equal_pyulog(real):
    log, u, topics = real
    m = log["messages"]
    assert m["text"].tolist() == [str(x.message).strip() for x in sorted(u.logged_messages, key=lambda x: x.timestamp)]
    assert m["severity"].tolist() == [float(x.log_level - ord("0")) for x in u.logged_messages]
    p = log["params"]
    init = p[p["src"].astype(str) == "initial_parameters"]
    assert dict(zip(init["name"], init["value"])) == {k: float(v) for k, v in u.initial_parameters.items()}
    assert (init["t_ns"] == 0).all()
    assert (p["src"].astype(str) == "changed_parameters").sum() == len(u.changed_parameters)


def test_vibration_equals_pyulog_imu_status_or_estimator_status(real):
    log, u, topics = real
    if "vehicle_imu_status" in topics:
        for d in topics["vehicle_imu_status"]:
            v = _rows(log, "vibration", "vehicle_imu_status", d.multi_id)
            assert np.array_equal(v["t_ns"], _t(u, d))
            assert np.array_equal(v["acc_vibration_mps2"], d.data["accel_vibration_metric"].astype(float))
            assert np.array_equal(v["gyr_vibration_radps"], d.data["gyro_vibration_metric"].astype(float))
            assert np.array_equal(v["clip_0"], d.data["accel_clipping[0]"].astype(float))
    else:
        d = topics["estimator_status"][0]
        v = _rows(log, "vibration", "estimator_status")
        assert np.array_equal(v["acc_vibration_mps2"], d.data["vibe[2]"].astype(float))
        assert np.array_equal(v["gyr_vibration_radps"], d.data["vibe[1]"].astype(float))


def test_gps_quality_equals_pyulog(real):
    log, u, topics = real
    d = topics["vehicle_gps_position"][0]
    g = _rows(log, "gps", "vehicle_gps_position")
    for col, f in (("hdop", "hdop"), ("vdop", "vdop"), ("fix_type", "fix_type"), ("n_sats", "satellites_used"),
                   ("hacc_m", "eph")):
        assert np.array_equal(g[col], d.data[f].astype(float))
