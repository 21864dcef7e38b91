"""tlog schema 1.1 streams (battery, setpoint, messages, params, vibration, GPS quality): the
real Phoenix tlog against pymavlink's ``recv_msg()`` loop (the oracle), and synthetic tlogs
written with pymavlink's own encoders for the types the real log lacks."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import pymavlink_messages, realdata_file
from pipeline.frames.rotations import euler_to_quat
from pipeline.io.tlog import TlogReader, write_tlog

REAL_TLOG = "tlog_phoenix_ubc_quad/phoenix_mission1_2018-09-17_16-44-06.tlog"
T0_US = 1_700_000_000_123_456


@pytest.fixture(scope="module")
def real():
    path = realdata_file(REAL_TLOG)
    log = TlogReader().read(path)
    by_type: dict[str, list] = {}
    for m in pymavlink_messages(path):
        if (m.get_srcSystem(), m.get_srcComponent()) == (1, 1):  # the vehicle
            by_type.setdefault(m.get_type(), []).append(m)
    return log, by_type


def _rows(log, stream, src):
    d = log[stream]
    return d[d["src"].astype(str) == src].reset_index(drop=True)


def _f(msgs, field, scale=1.0):
    return np.array([getattr(m, field) * scale for m in msgs], dtype=float)


def _t(msgs, log):
    t0_us = log.meta["t0_utc_ns"] // 1000
    return np.array([(round(m._timestamp * 1e6) - t0_us) * 1000 for m in msgs], dtype=np.int64)


def test_real_tlog_messages_and_params_equal_pymavlink(real):
    log, orc = real
    m = _rows(log, "messages", "STATUSTEXT")
    assert m["text"].tolist() == [x.text for x in orc["STATUSTEXT"]]
    assert np.array_equal(m["severity"], _f(orc["STATUSTEXT"], "severity"))
    p = _rows(log, "params", "PARAM_VALUE")
    assert p["name"].tolist() == [x.param_id for x in orc["PARAM_VALUE"]]
    assert np.array_equal(p["value"], _f(orc["PARAM_VALUE"], "param_value"))
    assert dict(zip(p["name"], p["value"])) == log.meta["params"]
    assert np.all(np.abs(p["t_ns"].to_numpy() - _t(orc["PARAM_VALUE"], log)) <= 3000)  # link-id bits


def test_real_tlog_vibration_nav_setpoint_and_gps_quality_equal_pymavlink(real):
    log, orc = real
    v = _rows(log, "vibration", "VIBRATION")
    assert len(v) == len(orc["VIBRATION"]) > 100
    for a in "xyz":
        assert np.array_equal(v[f"vibe_{a}_mps2"], _f(orc["VIBRATION"], f"vibration_{a}"))
    for i in range(3):
        assert np.array_equal(v[f"clip_{i}"], _f(orc["VIBRATION"], f"clipping_{i}"))
    s = _rows(log, "setpoint", "NAV_CONTROLLER_OUTPUT")
    nav = orc["NAV_CONTROLLER_OUTPUT"]
    assert len(s) == len(nav)
    assert np.array_equal(s["roll_rad"], np.deg2rad(_f(nav, "nav_roll")))
    assert np.array_equal(s["pitch_rad"], np.deg2rad(_f(nav, "nav_pitch")))
    assert np.array_equal(s["yaw_rad"], np.deg2rad(_f(nav, "nav_bearing")))
    g = _rows(log, "gps", "GPS_RAW_INT")
    gps = orc["GPS_RAW_INT"]
    assert np.array_equal(g["hdop"], _f(gps, "eph", 0.01))
    assert np.array_equal(g["vdop"], _f(gps, "epv", 0.01))
    assert np.array_equal(g["fix_type"], _f(gps, "fix_type"))
    assert np.array_equal(g["n_sats"], _f(gps, "satellites_visible"))
    # SYS_STATUS says "no battery monitor" throughout (0 mV, -1 cA, -1 %): no battery rows
    assert all(x.voltage_battery == 0 for x in orc["SYS_STATUS"]) and len(log["battery"]) == 0


def _mav():
    from pymavlink.dialects.v20 import ardupilotmega as v2

    return v2, v2.MAVLink(None)


def test_synthetic_battery_attitude_target_and_velocity_setpoint_convert_to_si(tmp_path):
    v2, m = _mav()
    q = euler_to_quat(np.array([0.1]), np.array([-0.2]), np.array([1.5]))[0]
    t = T0_US
    recs = [
        (t, m.heartbeat_encode(2, 3, 0, 0, 4)),
        (t + 1000, m.attitude_encode(1000, 0.0, 0.0, 0.0, 0, 0, 0)),
        (t + 2000, m.sys_status_encode(0, 0, 0, 500, 12600, 1530, 80, 0, 0, 0, 0, 0, 0)),
        (t + 3000, m.battery_status_encode(1, 0, 0, 3210, [4100, 4150, 4050] + [65535] * 7, 1530, 2500,
                                           -1, 80)),
        (t + 4000, m.attitude_target_encode(1100, 0, list(map(float, q)), 0.01, 0.02, 0.03, 0.5)),
        (t + 5000, m.attitude_target_encode(1200, 128 | 4, list(map(float, q)), 0.04, 0.05, 0.06, 0.5)),
        (t + 6000, m.position_target_local_ned_encode(1300, 1, 0b110111000111, 0, 0, 0, 1.5, -2.5, 0.25,
                                                      0, 0, 0, 0, 0)),
        (t + 7000, m.position_target_local_ned_encode(1301, 1, 0b110111100111, 0, 0, 0, 9, 9, 9,
                                                      0, 0, 0, 0, 0)),
        (t + 8000, m.vibration_encode(1_400_000, 1.5, 2.5, 3.5, 1, 2, 3)),
        (t + 9000, m.statustext_encode(3, b"battery low", 0, 0)),
    ]
    log = TlogReader().read(write_tlog(tmp_path / "s.tlog", recs))
    b = log["battery"]
    assert b["src"].astype(str).tolist() == ["BATTERY_STATUS"]  # BATTERY_STATUS wins over SYS_STATUS
    r = b.iloc[0]
    assert (r["instance"], r["voltage_V"], r["current_A"], r["consumed_Ah"], r["remaining_frac"]) == \
        (1, pytest.approx(12.3), pytest.approx(15.3), pytest.approx(2.5), pytest.approx(0.8))
    assert r["temp_degC"] == pytest.approx(32.1)
    s = _rows(log, "setpoint", "ATTITUDE_TARGET")
    np.testing.assert_allclose(s.loc[0, ["roll_rad", "pitch_rad", "yaw_rad"]].to_numpy(float),
                               [0.1, -0.2, 1.5], atol=1e-6)
    np.testing.assert_allclose(s.loc[0, ["p_radps", "q_radps", "r_radps"]].to_numpy(float),
                               [0.01, 0.02, 0.03], rtol=1e-6)
    assert s.loc[1, ["roll_rad", "r_radps"]].isna().all()  # type_mask 128 | 4: attitude, yaw rate ignored
    assert s.loc[1, "p_radps"] == pytest.approx(0.04)
    assert s["t_boot_ns"].tolist() == [1_100_000_000, 1_200_000_000]
    v = _rows(log, "setpoint", "POSITION_TARGET_LOCAL_NED")
    np.testing.assert_allclose(v.loc[0, ["vel_n_mps", "vel_e_mps", "vel_d_mps"]].to_numpy(float),
                               [1.5, -2.5, 0.25])
    assert np.isnan(v.loc[1, "vel_d_mps"]) and v.loc[1, "vel_n_mps"] == 9  # bit 32: vz ignored
    w = log["vibration"].iloc[0]
    assert (w["vibe_x_mps2"], w["vibe_z_mps2"], w["clip_2"], w["t_boot_ns"]) == (1.5, 3.5, 3, 1_400_000_000)
    msg = log["messages"].iloc[0]
    assert (msg["text"], msg["severity"], msg["t_ns"]) == ("battery low", 3, 9_000_000)


def test_synthetic_sys_status_is_the_battery_without_battery_status(tmp_path):
    v2, m = _mav()
    recs = [(T0_US, m.heartbeat_encode(2, 3, 0, 0, 4)),
            (T0_US + 1000, m.attitude_encode(1000, 0.0, 0.0, 0.0, 0, 0, 0)),
            (T0_US + 2000, m.sys_status_encode(0, 0, 0, 500, 12600, -1, 80, 0, 0, 0, 0, 0, 0))]
    b = TlogReader().read(write_tlog(tmp_path / "s.tlog", recs))["battery"]
    assert len(b) == 1 and b["src"].astype(str).iloc[0] == "SYS_STATUS"
    assert b["voltage_V"].iloc[0] == pytest.approx(12.6) and np.isnan(b["current_A"].iloc[0])
    assert b["remaining_frac"].iloc[0] == pytest.approx(0.8)
