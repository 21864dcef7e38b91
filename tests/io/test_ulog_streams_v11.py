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


# --- a synthetic ULog (the tests' ULog writer, parsed by pyulog): no shared data needed -------

def _ulog_msg(kind: str, payload: bytes) -> bytes:
    import struct

    return struct.pack("<HB", len(payload), ord(kind)) + payload


def test_synthetic_ulog_fills_every_new_stream(tmp_path):
    import struct

    from helpers_ulog import ULogWriter
    from pipeline.frames.rotations import euler_to_quat

    F = [("uint64_t", "timestamp")]
    w = ULogWriter(start_us=2_000_000)
    w.add_param("MPC_XY_VEL_MAX", 12.0)
    ts = np.array([2_100_000, 2_200_000], np.uint64)
    w.topic("battery_status", F + [("float", "voltage_v"), ("float", "current_a"), ("float", "discharged_mah"),
                                   ("float", "remaining"), ("float", "temperature")],
            {"timestamp": ts, "voltage_v": np.array([16.5, 16.25], np.float32),
             "current_a": np.array([10.0, 12.5], np.float32), "discharged_mah": np.array([100.0, 150.0], np.float32),
             "remaining": np.array([0.75, 0.5], np.float32), "temperature": np.array([25.0, 26.0], np.float32)})
    q = euler_to_quat(np.array([0.25, 0.0]), np.array([-0.125, 0.0]), np.array([1.5, -3.0]))
    w.topic("vehicle_attitude_setpoint", F + [("float[4]", "q_d")],
            {"timestamp": ts, "q_d": q.astype(np.float32)})
    w.topic("vehicle_rates_setpoint", F + [("float", "roll"), ("float", "pitch"), ("float", "yaw")],
            {"timestamp": ts, "roll": np.array([0.5, 0.0], np.float32), "pitch": np.zeros(2, np.float32),
             "yaw": np.array([-0.25, 1.0], np.float32)})
    w.topic("trajectory_setpoint", F + [("float[3]", "velocity")],
            {"timestamp": ts, "velocity": np.array([[1.0, 2.0, -0.5], [np.nan, np.nan, 0.0]], np.float32)})
    w.topic("vehicle_imu_status", F + [("uint32_t[3]", "accel_clipping"), ("float", "accel_vibration_metric"),
                                       ("float", "gyro_vibration_metric")],
            {"timestamp": ts, "accel_clipping": np.array([[0, 0, 0], [3, 0, 1]], np.uint32),
             "accel_vibration_metric": np.array([0.5, 4.0], np.float32),
             "gyro_vibration_metric": np.array([0.01, 0.02], np.float32)}, multi_id=1)
    w.log("WARNING", 2_150_000, "low battery")
    data = w.to_bytes()
    k = b"float MPC_XY_VEL_MAX"
    data += _ulog_msg("P", bytes([len(k)]) + k + struct.pack("<f", 8.0))  # a change after the data
    p = tmp_path / "v11.ulg"
    p.write_bytes(data)

    log = read_log(p)
    b = log["battery"]
    assert b["t_ns"].tolist() == [100_000_000, 200_000_000]
    assert b["voltage_V"].tolist() == [16.5, 16.25] and b["consumed_Ah"].tolist() == [0.1, 0.15]
    assert b["remaining_frac"].tolist() == [0.75, 0.5] and b["temp_degC"].tolist() == [25.0, 26.0]
    s = log["setpoint"]
    att = s[s["src"].astype(str) == "vehicle_attitude_setpoint"]
    np.testing.assert_allclose(att[["roll_rad", "pitch_rad", "yaw_rad"]].to_numpy(float),
                               [[0.25, -0.125, 1.5], [0.0, 0.0, -3.0]], atol=1e-6)
    rate = s[s["src"].astype(str) == "vehicle_rates_setpoint"]
    assert rate["p_radps"].tolist() == [0.5, 0.0] and rate["r_radps"].tolist() == [-0.25, 1.0]
    vel = s[s["src"].astype(str) == "trajectory_setpoint"]
    assert vel["vel_n_mps"].iloc[0] == 1.0 and np.isnan(vel["vel_n_mps"].iloc[1])
    assert vel["vel_d_mps"].tolist() == [-0.5, 0.0]
    v = log["vibration"]
    assert (v["instance"] == 1).all() and v["clip_0"].tolist() == [0, 3] and v["clip_2"].tolist() == [0, 1]
    assert v["acc_vibration_mps2"].tolist() == [0.5, 4.0]
    m = log["messages"].iloc[0]
    assert (m["text"], m["severity"], m["t_ns"]) == ("low battery", 4.0, 150_000_000)  # WARNING = 4
    prm = log["params"]
    assert prm["src"].astype(str).tolist() == ["initial_parameters", "changed_parameters"]
    assert prm["value"].tolist() == [12.0, 8.0] and prm["t_ns"].iloc[0] == 0 and prm["t_ns"].iloc[1] > 0
