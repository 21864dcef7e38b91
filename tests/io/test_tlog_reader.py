"""MAVLink .tlog reader: pymavlink as the oracle on the real log, closed-form unit conversions
on synthetic tlogs written with pymavlink's encoder, sniffing and routing."""

from __future__ import annotations

import math
import shutil
from collections import Counter, defaultdict

import numpy as np
import pandas as pd
import pytest

from helpers import pymavlink_messages, realdata_file
from pipeline.frames.rotations import euler_to_quat, quat_to_euler
from pipeline.io import registry
from pipeline.io.base import IngestError
from pipeline.io.tlog import G0, TlogReader, write_tlog

REAL_TLOG = "tlog_phoenix_ubc_quad/phoenix_mission1_2018-09-17_16-44-06.tlog"
REAL_BIN = "pymavlink_test_bin/test.BIN"
T0_US = 1_700_000_000_123_456  # arbitrary 2023 framing time


# pymavlink oracle: helpers.pymavlink_messages


@pytest.fixture(scope="module")
def real():
    path = realdata_file(REAL_TLOG)
    log = TlogReader().read(path)
    msgs = pymavlink_messages(path)
    by_type = defaultdict(list)
    for m in msgs:
        if (m.get_srcSystem(), m.get_srcComponent()) == (1, 1):
            by_type[m.get_type()].append(m)
    return path, log, msgs, by_type


def _rows(log, stream, src, instance=None):
    df = log[stream]
    df = df[df["src"] == src]
    if instance is not None:
        df = df[df["instance"] == instance]
    return df.reset_index(drop=True)


def _f(msgs, field, scale=1.0):
    return np.array([getattr(m, field) * scale for m in msgs], dtype=float)


def _masked(msgs, field):
    return np.array([np.nan if getattr(m, field) in (0, 65535) else getattr(m, field) for m in msgs])


def assert_rel(actual, expected, rtol=1e-9, atol=0.0):
    np.testing.assert_allclose(np.asarray(actual, float), np.asarray(expected, float),
                               rtol=rtol, atol=atol, equal_nan=True)


# ---- real log vs pymavlink ----------------------------------------------------------------

@pytest.mark.realdata
def test_real_tlog_record_counts_equal_pymavlink(real):
    _, log, msgs, _ = real
    oracle = Counter(m.get_type() for m in msgs)
    assert "BAD_DATA" not in oracle
    assert len(oracle) > 40
    assert log.meta["diagnostics"]["record_counts"] == dict(oracle)


@pytest.mark.realdata
def test_real_tlog_meta_and_nonempty_streams(real):
    _, log, msgs, by_type = real
    m = log.meta
    d = m["diagnostics"]
    assert m["status"] == "ok" and m["source_format"] == "mavlink_tlog"
    assert d["bytes_skipped"] == 0 and d["records_dropped"] == {}
    assert m["mavlink"]["sysid"] == 1 and m["mavlink"]["compid"] == 1
    assert m["mavlink"]["bytes_decoded"] == realdata_file(REAL_TLOG).stat().st_size
    # the source has these; DISTANCE_SENSOR / ATTITUDE_QUATERNION / SCALED_IMU it has not
    for s in ("gps", "imu", "mag", "baro", "attitude", "local_position", "airspeed", "control", "mode"):
        assert len(log[s]) > 0, s
    assert len(log["rangefinder"]) == 0
    # t0 is the first framing time (host clock)
    assert m["utc_source"] == "host"
    assert abs(m["t0_utc_ns"] * 1e-9 - msgs[0]._timestamp) < 1e-6
    # GCS heartbeats and telemetry-radio status are not vehicle samples, but are counted
    gcs = sum(1 for x in msgs if (x.get_srcSystem(), x.get_srcComponent()) == (255, 190)
              and x.get_type() == "HEARTBEAT")
    assert d["records_ignored"]["other_sender:255/190"] == gcs
    # NED origin = the vehicle's first GPS_GLOBAL_ORIGIN (the EKF origin)
    o = by_type["GPS_GLOBAL_ORIGIN"][0]
    assert m["ned_origin"]["lat_deg"] == pytest.approx(o.latitude * 1e-7, rel=1e-12)
    assert m["ned_origin"]["lon_deg"] == pytest.approx(o.longitude * 1e-7, rel=1e-12)
    assert m["ned_origin"]["alt_msl_m"] == pytest.approx(o.altitude * 1e-3, rel=1e-12)
    assert m["params"]["SYSID_THISMAV"] == 1.0
    assert any("APM:Copter" in x["text"] for x in d["messages"])


@pytest.mark.realdata
def test_real_tlog_times_equal_pymavlink(real):
    _, log, _, by_type = real
    t0 = log.meta["t0_utc_ns"]
    for stream, src, field, scale in (("attitude", "ATTITUDE", "time_boot_ms", 10**6),
                                      ("gps", "GPS_RAW_INT", "time_usec", 10**3),
                                      ("control", "SERVO_OUTPUT_RAW", "time_usec", 10**3)):
        df = _rows(log, stream, src)
        ms = by_type[src]
        assert len(df) == len(ms)
        host = (df["t_ns"].to_numpy() + t0) * 1e-9
        assert np.max(np.abs(host - np.array([x._timestamp for x in ms]))) < 1e-6
        assert df["t_boot_ns"].tolist() == [getattr(x, field) * scale for x in ms]


@pytest.mark.realdata
def test_real_tlog_gps_equals_pymavlink(real):
    _, log, _, by_type = real
    ms = by_type["GPS_RAW_INT"]
    df = _rows(log, "gps", "GPS_RAW_INT", 0)
    assert len(df) == len(ms) > 700
    assert df["fix_type"].tolist() == [x.fix_type for x in ms]
    assert df["n_sats"].tolist() == [x.satellites_visible for x in ms]
    assert_rel(df["lat_deg"], _f(ms, "lat") / 1e7)
    assert_rel(df["lon_deg"], _f(ms, "lon") / 1e7)
    assert_rel(df["alt_msl_m"], _f(ms, "alt") / 1e3)
    spd = np.array([x.vel / 100 for x in ms])
    cog = np.radians([x.cog / 100 for x in ms])
    assert_rel(df["vel_n_mps"], spd * np.cos(cog), atol=1e-12)
    assert_rel(df["vel_e_mps"], spd * np.sin(cog), atol=1e-12)
    # this receiver fills no h_acc: no accuracy (its HDOP is in hdop, a dilution, not metres)
    h_acc = np.array([getattr(x, "h_acc", 0) for x in ms], dtype=np.float64)
    assert_rel(df["hacc_m"], np.where(h_acc > 0, h_acc * 1e-3, np.nan))
    assert_rel(df["hdop"], _masked(ms, "eph") / 100)
    ms = by_type["GLOBAL_POSITION_INT"]
    df = _rows(log, "gps", "GLOBAL_POSITION_INT", 1)
    assert len(df) == len(ms) > 700
    assert_rel(df["lat_deg"], _f(ms, "lat") / 1e7)
    assert_rel(df["lon_deg"], _f(ms, "lon") / 1e7)
    assert_rel(df["alt_msl_m"], _f(ms, "alt") / 1e3)
    for a, f in zip("ned", ("vx", "vy", "vz")):
        assert_rel(df[f"vel_{a}_mps"], _f(ms, f) / 100)


@pytest.mark.realdata
def test_real_tlog_imu_mag_equal_pymavlink(real):
    _, log, _, by_type = real
    for src, inst in (("RAW_IMU", 0), ("SCALED_IMU2", 1), ("SCALED_IMU3", 2)):
        ms = by_type[src]
        imu, mag = _rows(log, "imu", src, inst), _rows(log, "mag", src, inst)
        assert len(imu) == len(mag) == len(ms) > 700
        for a in "xyz":
            assert_rel(imu[f"acc_{a}_mps2"], _f(ms, f"{a}acc") / 1000 * 9.80665)
            assert_rel(imu[f"gyr_{a}_radps"], _f(ms, f"{a}gyro") / 1000)
            assert_rel(mag[f"mag_{a}_T"], _f(ms, f"{a}mag") * 1e-7)
    assert any("RAW_IMU used" in w for w in log.meta["diagnostics"]["warnings"])
    # at rest before arming the accelerometer reads -g on z (FRD)
    acc_z = _rows(log, "imu", "SCALED_IMU2", 1)["acc_z_mps2"].iloc[:20]
    assert np.all(np.abs(acc_z + 9.81) < 0.5)


@pytest.mark.realdata
def test_real_tlog_attitude_equals_pymavlink(real):
    _, log, _, by_type = real
    ms = by_type["ATTITUDE"]
    df = _rows(log, "attitude", "ATTITUDE")
    assert len(df) == len(ms) > 800
    q = df[["q_w", "q_x", "q_y", "q_z"]].to_numpy()
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    roll, pitch, yaw = quat_to_euler(q)
    for got, field in ((roll, "roll"), (pitch, "pitch"), (yaw, "yaw")):
        diff = np.angle(np.exp(1j * (got - _f(ms, field))))
        assert np.max(np.abs(diff)) < 1e-6, field


@pytest.mark.realdata
def test_real_tlog_baro_local_airspeed_equal_pymavlink(real):
    _, log, _, by_type = real
    for src, inst in (("SCALED_PRESSURE", 0), ("SCALED_PRESSURE2", 1)):
        ms = by_type[src]
        df = _rows(log, "baro", src, inst)
        assert len(df) == len(ms) > 700
        assert_rel(df["press_Pa"], _f(ms, "press_abs") * 100)
        assert_rel(df["temp_degC"], _f(ms, "temperature") / 100)
        assert 90_000 < df["press_Pa"].median() < 110_000
    ms = by_type["LOCAL_POSITION_NED"]
    df = _rows(log, "local_position", "LOCAL_POSITION_NED")
    for col, f in (("pos_n_m", "x"), ("pos_e_m", "y"), ("pos_d_m", "z"),
                   ("vel_n_mps", "vx"), ("vel_e_mps", "vy"), ("vel_d_mps", "vz")):
        assert_rel(df[col], _f(ms, f))
    ms = by_type["VFR_HUD"]
    assert_rel(_rows(log, "airspeed", "VFR_HUD")["airspeed_mps"], _f(ms, "airspeed"))


@pytest.mark.realdata
def test_real_tlog_rc_servo_equal_pymavlink(real):
    _, log, _, by_type = real
    ms = by_type["RC_CHANNELS"]
    df = _rows(log, "control", "RC_CHANNELS")
    assert len(df) == len(ms) > 700
    for i in range(1, 19):
        assert_rel(df[f"rc_{i}_us"], _masked(ms, f"chan{i}_raw"), rtol=0)
    ms = by_type["RC_CHANNELS_RAW"]
    assert {x.port for x in ms} == {0}
    df = _rows(log, "control", "RC_CHANNELS_RAW")
    for i in range(1, 9):
        assert_rel(df[f"rc_{i}_us"], _masked(ms, f"chan{i}_raw"), rtol=0)
    ms = by_type["SERVO_OUTPUT_RAW"]
    df = _rows(log, "control", "SERVO_OUTPUT_RAW")
    assert len(df) == len(ms) > 700
    for i in range(1, 9):
        assert_rel(df[f"servo_{i}_us"], _masked(ms, f"servo{i}_raw"), rtol=0)
    assert df["servo_1_us"].max() > 1500  # motors spun up during the missions


@pytest.mark.realdata
def test_real_tlog_mode_changes_equal_pymavlink(real):
    from pymavlink import mavutil

    _, log, _, by_type = real
    expected, prev = [], None
    for hb in by_type["HEARTBEAT"]:
        cur = (mavutil.mode_string_v10(hb), bool(hb.base_mode & 128))
        if cur != prev:
            expected.append(cur)
        prev = cur
    df = log["mode"]
    assert list(zip(df["mode"], df["armed"])) == expected
    assert {"STABILIZE", "AUTO"} <= set(df["mode"])
    assert df["armed"].any()


@pytest.mark.realdata
def test_real_tlog_sniff_and_routing(tmp_path):
    path = realdata_file(REAL_TLOG)
    head = path.read_bytes()[:65536]
    assert "MAVLink tlog" in TlogReader.sniff(path, head)
    # leading junk (a ground station that wrote a partial record first) is still recognised
    assert "after 5 leading bytes" in TlogReader.sniff(path, b"\x00\x01\x02\x03\x04" + head)
    binp = realdata_file(REAL_BIN)
    assert TlogReader.sniff(binp, binp.read_bytes()[:65536]) is None
    # a DataFlash log renamed .tlog: a clear IngestError from this reader ...
    fake = tmp_path / "renamed.tlog"
    shutil.copyfile(binp, fake)
    with pytest.raises(IngestError, match=r"renamed\.tlog: no valid MAVLink tlog record.*DataFlash"):
        TlogReader().read(fake)
    # ... and routed by content, not extension, through the registry
    assert registry.detect(path)[0] is TlogReader
    assert registry.detect(fake)[0].name == "dataflash"


@pytest.mark.realdata
def test_real_tlog_through_read_log():
    path = realdata_file(REAL_TLOG)
    log = registry.read_log(path)
    assert log.meta["reader"] == "tlog" and log.meta["status"] == "ok"
    assert log.meta["flight_id"] == "phoenix-mission1-2018-09-17-16-44-06"


# ---- synthetic tlogs: every listed message type, exact conversions ------------------------

def _mav():
    from pymavlink.dialects.v20 import ardupilotmega as v2

    return v2, v2.MAVLink(None)


def synthetic_records():
    """Records covering every message type the reader maps, from vehicle (1, 1), a GCS
    (255, 190) and a second vehicle (2, 1); values chosen to exercise sentinels."""
    v2, m = _mav()
    armed_loiter = v2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | v2.MAV_MODE_FLAG_SAFETY_ARMED
    t = T0_US
    recs = [
        (t, m.heartbeat_encode(6, 8, 0, 0, 4), 255, 190),  # GCS first
        (t + 1000, m.heartbeat_encode(2, 3, v2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0, 4)),  # STABILIZE
        (t + 2000, m.heartbeat_encode(2, 3, v2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0, 4)),  # no change
        (t + 3000, m.heartbeat_encode(2, 3, armed_loiter, 5, 4)),  # LOITER, armed
        (t + 4000, m.gps_global_origin_encode(473977420, 85455940, 488123, 0)),
        (t + 5000, m.global_position_int_encode(1000, 473977421, 85455941, 488500, 12345,
                                                -150, 275, -33, 9000)),
        (t + 6000, m.gps_raw_int_encode(1_001_000, 3, 473977422, 85455942, 488600, 121, 180,
                                        250, 9000, 11, 536700, 850, 1300, 0, 0, 0)),
        (t + 6500, m.gps_raw_int_encode(1_002_000, 1, 0, 0, 0, 65535, 65535, 65535, 65535, 255,
                                        0, 0, 0, 0, 0, 0)),
        (t + 7000, m.scaled_imu_encode(1100, 12, -25, -1003, 150, -200, 35, 210, -55, 430, 4150)),
        (t + 8000, m.scaled_imu2_encode(1101, -7, 3, -998, -1, 2, 3, 200, -50, 420, 0)),
        (t + 9000, m.raw_imu_encode(1_102_000, 1, 2, 3, 4, 5, 6, 7, 8, 9, 0, 0)),
        (t + 10000, m.attitude_encode(1200, 0.25, -0.5, 2.5, 0.01, 0.02, 0.03)),
        (t + 11000, m.attitude_quaternion_encode(1201, 0.5, 0.5, -0.5, 0.5, 0, 0, 0,
                                                 [1.0, 0.0, 0.0, 0.0])),
        (t + 12000, m.local_position_ned_encode(1300, 1.5, -2.25, -10.0, 0.5, -0.25, 1.0)),
        (t + 13000, m.scaled_pressure_encode(1400, 1013.25, 0.5, 2150, 0)),
        (t + 13500, m.scaled_pressure2_encode(1401, 1012.5, 0.0, -125, 0)),
        (t + 14000, m.vfr_hud_encode(17.5, 16.0, 90, 55, 488.5, -0.5)),
        (t + 15000, m.rc_channels_encode(1500, 8, 1100, 1200, 1300, 1400, 1500, 1600, 1700, 1800,
                                         65535, 65535, 0, 0, 0, 0, 0, 0, 0, 0, 200)),
        (t + 15500, m.rc_channels_raw_encode(1501, 1, 1901, 1902, 0, 0, 0, 0, 0, 65535, 100)),
        (t + 16000, m.servo_output_raw_encode(1_600_000, 0, 1000, 1100, 1200, 1300, 0, 0, 0, 0,
                                              1900, 0, 0, 0, 0, 0, 0, 2000)),
        (t + 17000, m.distance_sensor_encode(1700, 20, 700, 345, 0, 0, 25, 0, 0.0, 0.0,
                                             [0.0] * 4, 0)),
        (t + 17500, m.distance_sensor_encode(1701, 20, 700, 900, 0, 1, 25, 0, 0.0, 0.0,
                                             [0.0] * 4, 0)),
        (t + 18000, m.statustext_encode(6, b"hello tlog", 0, 0)),
        (t + 18500, m.param_value_encode(b"SYSID_THISMAV", 1.0, 9, 100, 0)),
        (t + 19000, m.attitude_encode(9999, 1.0, 1.0, 1.0, 0, 0, 0), 2, 1),  # other vehicle
        (t + 20000, m.heartbeat_encode(6, 8, 0, 0, 4), 255, 190),
        (t + 21000, m.heartbeat_encode(2, 3, armed_loiter, 5, 4)),  # no change
        (t + 22000, m.heartbeat_encode(2, 3, v2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5, 4)),  # disarm
    ]
    # more vehicle ATTITUDE than the other vehicle has: (1, 1) is the vehicle
    recs += [(t + 23000 + k, m.attitude_encode(2000 + k, 0.0, 0.0, 0.1 * k, 0, 0, 0)) for k in range(3)]
    return recs


@pytest.fixture(params=[False, True], ids=["mavlink2", "mavlink1"])
def synth(request, tmp_path):
    path = write_tlog(tmp_path / "synth.tlog", synthetic_records(), mavlink1=request.param)
    return request.param, path, TlogReader().read(path)


def test_synthetic_counts_senders_and_meta(synth):
    mavlink1, path, log = synth
    d = log.meta["diagnostics"]
    recs = synthetic_records()
    assert d["record_counts"] == dict(Counter(r[1].get_type() for r in recs))
    assert d["records_dropped"] == {} and d["bytes_skipped"] == 0
    assert d["records_ignored"] == {"other_sender:255/190": 2, "other_sender:2/1": 1}
    assert log.meta["status"] == "ok"
    assert log.meta["t0_utc_ns"] == T0_US * 1000
    assert log.meta["mavlink"]["protocol_versions"] == ([1] if mavlink1 else [2])
    assert log.meta["params"] == {"SYSID_THISMAV": 1.0}
    assert d["messages"] == [{"t_ns": 18_000_000, "severity": 6, "text": "hello tlog"}]
    o = log.meta["ned_origin"]
    assert (o["lat_deg"], o["lon_deg"], o["alt_msl_m"], o["source"]) == (
        pytest.approx(47.397742, rel=1e-12), pytest.approx(8.545594, rel=1e-12),
        pytest.approx(488.123, rel=1e-12), "GPS_GLOBAL_ORIGIN")
    if mavlink1:  # no alt_ellipsoid in MAVLink 1: MSL kept, flagged
        assert o["alt_is_msl"] and o["alt_wgs84_m"] == o["alt_msl_m"]
    else:  # geoid separation from GPS_RAW_INT: 536.7 - 488.6
        assert not o["alt_is_msl"]
        assert o["alt_wgs84_m"] == pytest.approx(488.123 + 536.7 - 488.6, rel=1e-12)
    # the second vehicle's attitude is not a sample
    assert (log["attitude"]["t_boot_ns"] != 9999 * 10**6).all()
    # t0_boot_ns: boot clock at t_ns = 0, the median of time_boot_ms * 1e6 - t_ns over the
    # vehicle's ATTITUDE, GLOBAL_POSITION_INT and SCALED_PRESSURE records of synthetic_records():
    offsets = [1000 * 10**6 - 5_000_000,                      # GLOBAL_POSITION_INT
               1200 * 10**6 - 10_000_000,                     # ATTITUDE
               1400 * 10**6 - 13_000_000,                     # SCALED_PRESSURE
               *[(2000 + k) * 10**6 - (23_000 + k) * 1000 for k in range(3)]]  # ATTITUDE x3
    offsets.sort()
    assert (offsets[2] + offsets[3]) // 2 == 1_682_000_000  # median of six: the mean of the middle two
    assert log.meta["t0_boot_ns"] == 1_682_000_000


def test_synthetic_gps(synth):
    mavlink1, _, log = synth
    gps = log["gps"]
    raw = gps[gps["src"] == "GPS_RAW_INT"].reset_index(drop=True)
    assert raw["instance"].tolist() == [0, 0]
    r = raw.iloc[0]
    assert r["t_ns"] == 6_000_000 and r["t_boot_ns"] == 1_001_000_000
    assert (r["lat_deg"], r["lon_deg"], r["alt_msl_m"]) == (
        pytest.approx(47.3977422, rel=1e-12), pytest.approx(8.5455942, rel=1e-12),
        pytest.approx(488.6, rel=1e-12))
    assert (r["fix_type"], r["n_sats"]) == (3, 11)
    # 2.5 m/s at course 90 deg: due east
    assert r["vel_n_mps"] == pytest.approx(0.0, abs=1e-12)
    assert r["vel_e_mps"] == pytest.approx(2.5, rel=1e-12)
    assert math.isnan(r["vel_d_mps"])
    if mavlink1:  # no h_acc/v_acc: no accuracy (HDOP/VDOP x 0.01 in hdop/vdop), no ellipsoid height
        assert math.isnan(r["hacc_m"]) and math.isnan(r["vacc_m"])
        assert (r["hdop"], r["vdop"]) == (pytest.approx(1.21), pytest.approx(1.80))
        assert math.isnan(r["alt_wgs84_m"])
    else:  # h_acc / v_acc in mm
        assert (r["hacc_m"], r["vacc_m"]) == (pytest.approx(0.85), pytest.approx(1.3))
        assert r["alt_wgs84_m"] == pytest.approx(536.7, rel=1e-12)
    nofix = raw.iloc[1]  # UINT16_MAX / 255 sentinels -> NaN
    assert nofix["fix_type"] == 1
    for c in ("vel_n_mps", "vel_e_mps", "n_sats", "hacc_m", "vacc_m"):
        assert math.isnan(nofix[c]), c
    g = gps[gps["src"] == "GLOBAL_POSITION_INT"].iloc[0]
    assert g["instance"] == 1 and g["t_boot_ns"] == 1_000_000_000
    assert (g["lat_deg"], g["alt_msl_m"]) == (pytest.approx(47.3977421, rel=1e-12), pytest.approx(488.5))
    assert (g["vel_n_mps"], g["vel_e_mps"], g["vel_d_mps"]) == (
        pytest.approx(-1.5), pytest.approx(2.75), pytest.approx(-0.33))
    assert math.isnan(g["fix_type"])


def test_synthetic_imu_mag(synth):
    mavlink1, _, log = synth
    imu, mag = log["imu"], log["mag"]
    # SCALED_IMU present: RAW_IMU is not used
    assert set(imu["src"]) == {"SCALED_IMU", "SCALED_IMU2"}
    assert any("RAW_IMU ignored" in w for w in log.meta["diagnostics"]["warnings"])
    a = imu[imu["instance"] == 0].iloc[0]
    assert a["src"] == "SCALED_IMU" and a["t_boot_ns"] == 1_100_000_000
    assert [a[f"acc_{x}_mps2"] for x in "xyz"] == pytest.approx(
        [0.012 * G0, -0.025 * G0, -1.003 * G0], rel=1e-12)
    assert [a[f"gyr_{x}_radps"] for x in "xyz"] == pytest.approx([0.15, -0.2, 0.035], rel=1e-12)
    if mavlink1:  # temperature is a MAVLink 2 extension
        assert math.isnan(a["temp_degC"])
    else:
        assert a["temp_degC"] == pytest.approx(41.5)
    b = imu[imu["instance"] == 1].iloc[0]
    assert math.isnan(b["temp_degC"])  # 0 = "no temperature" in MAVLink
    mg = mag[mag["instance"] == 0].iloc[0]
    assert [mg[f"mag_{x}_T"] for x in "xyz"] == pytest.approx([21e-6, -5.5e-6, 43e-6], rel=1e-12)


def test_synthetic_raw_imu_used_only_without_scaled_imu(tmp_path):
    v2, m = _mav()
    recs = [(T0_US, m.heartbeat_encode(2, 3, 1, 0, 4)),
            (T0_US + 1, m.raw_imu_encode(5_000_000, 100, 200, -1000, 10, 20, 30, 1, 2, 3, 0, 0))]
    log = TlogReader().read(write_tlog(tmp_path / "raw.tlog", recs))
    r = log["imu"].iloc[0]
    assert r["src"] == "RAW_IMU" and r["t_boot_ns"] == 5_000_000_000
    assert r["acc_z_mps2"] == pytest.approx(-G0) and r["gyr_z_radps"] == pytest.approx(0.03)
    # PX4 (autopilot 12) fills RAW_IMU with ADC counts: not SI without calibration -> skipped
    recs[0] = (T0_US, m.heartbeat_encode(2, 12, 1, 0, 4))
    log = TlogReader().read(write_tlog(tmp_path / "px4.tlog", recs))
    assert len(log["imu"]) == 0
    assert any("raw sensor units" in w for w in log.meta["diagnostics"]["warnings"])


def test_synthetic_attitude(synth):
    _, _, log = synth
    att = log["attitude"]
    e = att[att["src"] == "ATTITUDE"].iloc[0]
    q = e[["q_w", "q_x", "q_y", "q_z"]].to_numpy(dtype=float)
    # float32 on the wire: compare with the float32-rounded angles
    angles = [float(np.float32(x)) for x in (0.25, -0.5, 2.5)]
    np.testing.assert_allclose(q, euler_to_quat(*angles), rtol=0, atol=1e-15)
    np.testing.assert_allclose(quat_to_euler(q), angles, atol=1e-6)
    qq = att[att["src"] == "ATTITUDE_QUATERNION"].iloc[0]
    assert qq[["q_w", "q_x", "q_y", "q_z"]].tolist() == [0.5, 0.5, -0.5, 0.5]
    assert qq["t_boot_ns"] == 1_201_000_000


def test_synthetic_local_baro_airspeed(synth):
    _, _, log = synth
    lp = log["local_position"].iloc[0]
    assert lp[["pos_n_m", "pos_e_m", "pos_d_m", "vel_n_mps", "vel_e_mps", "vel_d_mps"]].tolist() == [
        1.5, -2.25, -10.0, 0.5, -0.25, 1.0]
    baro = log["baro"]
    b0, b1 = baro[baro["instance"] == 0].iloc[0], baro[baro["instance"] == 1].iloc[0]
    assert (b0["src"], b1["src"]) == ("SCALED_PRESSURE", "SCALED_PRESSURE2")
    assert b0["press_Pa"] == pytest.approx(101325.0, rel=1e-9)  # float32 1013.25 is exact
    assert (b0["temp_degC"], b1["temp_degC"]) == (pytest.approx(21.5), pytest.approx(-1.25))
    assert b1["press_Pa"] == pytest.approx(101250.0, rel=1e-9)
    assert log["airspeed"]["airspeed_mps"].tolist() == [17.5]


def test_synthetic_control(synth):
    _, _, log = synth
    c = log["control"]
    rc = c[c["src"] == "RC_CHANNELS"].iloc[0]
    assert [rc[f"rc_{i}_us"] for i in range(1, 9)] == [1100, 1200, 1300, 1400, 1500, 1600, 1700, 1800]
    assert all(math.isnan(rc[f"rc_{i}_us"]) for i in range(9, 19))  # 65535 / 0 = unused
    assert all(math.isnan(rc[f"servo_{i}_us"]) for i in range(1, 33))
    raw = c[c["src"] == "RC_CHANNELS_RAW"].iloc[0]  # port 1 -> channels 9..16
    assert (raw["rc_9_us"], raw["rc_10_us"]) == (1901, 1902)
    assert all(math.isnan(raw[f"rc_{i}_us"]) for i in [*range(1, 9), *range(11, 19)])
    sv = c[c["src"] == "SERVO_OUTPUT_RAW"].iloc[0]
    assert sv["t_boot_ns"] == 1_600_000_000
    assert [sv[f"servo_{i}_us"] for i in range(1, 5)] == [1000, 1100, 1200, 1300]
    assert math.isnan(sv["servo_5_us"])
    mavlink1 = log.meta["mavlink"]["protocol_versions"] == [1]
    if mavlink1:  # servo9..16 are MAVLink 2 extensions
        assert math.isnan(sv["servo_9_us"]) and math.isnan(sv["servo_16_us"])
    else:
        assert (sv["servo_9_us"], sv["servo_16_us"]) == (1900, 2000)


def test_synthetic_mode_and_rangefinder(synth):
    _, _, log = synth
    md = log["mode"]
    assert list(zip(md["t_ns"], md["mode"], md["armed"])) == [
        (1_000_000, "STABILIZE", False), (3_000_000, "LOITER", True), (22_000_000, "LOITER", False)]
    rf = log["rangefinder"]
    assert rf["instance"].tolist() == [0, 1]
    assert rf["dist_m"].tolist() == pytest.approx([3.45, 9.0])
    assert rf["valid"].tolist() == [True, False]  # 900 cm > max_distance 700 cm
    assert rf["orientation"].tolist() == [25, 25]


def test_synthetic_roundtrip_parquet(synth, tmp_path):
    from pipeline.io.parquet import read_flightlog, write_flightlog

    _, _, log = synth
    write_flightlog(log, tmp_path / "out")
    back = read_flightlog(tmp_path / "out")
    for name in ("gps", "imu", "attitude", "control", "mode", "rangefinder"):
        pd.testing.assert_frame_equal(back[name], log[name], check_categorical=False)


def test_encode_tlog_matches_pymavlink_decoder(tmp_path):
    """The writer's bytes decode back through pymavlink's own tlog loop."""
    path = write_tlog(tmp_path / "w.tlog", synthetic_records())
    msgs = pymavlink_messages(path)
    assert [x.get_type() for x in msgs] == [r[1].get_type() for r in synthetic_records()]
    assert [round(x._timestamp * 1e6) for x in msgs] == [r[0] for r in synthetic_records()]


def test_unknown_message_id_counted_like_pymavlink(tmp_path):
    """A frame whose id is not in the dialect (no CRC extra: unverifiable) is counted as
    pymavlink names it and dropped as unknown_type; the records around it are kept."""
    _, m = _mav()
    good = write_tlog(tmp_path / "g.tlog", [
        (T0_US, m.attitude_encode(1, 0.1, 0.2, 0.3, 0, 0, 0)),
        (T0_US + 2, m.attitude_encode(2, 0.1, 0.2, 0.3, 0, 0, 0))]).read_bytes()
    payload = bytes(range(7))
    frame = bytes([0xFD, len(payload), 0, 0, 9, 1, 1, 0xDE, 0xBC, 0x0A]) + payload + b"\x12\x34"
    unknown = (T0_US + 1).to_bytes(8, "big") + frame
    cut = len(good) // 2
    path = tmp_path / "u.tlog"
    path.write_bytes(good[:cut] + unknown + good[cut:])
    log = TlogReader().read(path)
    d = log.meta["diagnostics"]
    oracle = Counter(x.get_type() for x in pymavlink_messages(path))
    assert d["record_counts"] == dict(oracle) == {"ATTITUDE": 2, "UNKNOWN_703710": 1}
    assert d["records_dropped"] == {"unknown_type": 1} and d["bytes_skipped"] == 0
    assert len(log["attitude"]) == 2
    # the same frame followed by junk instead of a record is not trusted
    path.write_bytes(good[:cut] + unknown + b"\x00" * 40 + good[cut:])
    d = TlogReader().read(path).meta["diagnostics"]
    assert d["record_counts"] == {"ATTITUDE": 2}
    assert d["records_dropped"] == {"bad_frame": 1}
    assert d["bytes_skipped"] == len(unknown) + 40


def test_empty_and_directory_errors(tmp_path):
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    with pytest.raises(IngestError, match=r"empty\.tlog: empty file"):
        TlogReader().read(empty)
    with pytest.raises(IngestError, match="directory"):
        TlogReader().read(tmp_path)
    assert TlogReader.sniff(empty, b"") is None


def test_only_gcs_packets_is_partial_not_crash(tmp_path):
    _, m = _mav()
    recs = [(T0_US + k, m.heartbeat_encode(6, 8, 0, 0, 4), 255, 190) for k in range(3)]
    log = TlogReader().read(write_tlog(tmp_path / "gcs.tlog", recs))
    assert all(len(log[s]) == 0 for s in ("gps", "imu", "mode"))
    assert any("no vehicle sender" in w for w in log.meta["diagnostics"]["warnings"])
    assert log.meta["diagnostics"]["record_counts"] == {"HEARTBEAT": 3}


def test_progress_reports_bytes(tmp_path):
    path = write_tlog(tmp_path / "p.tlog", synthetic_records())
    calls = []
    TlogReader().read(path, progress=lambda done, total: calls.append((done, total)))
    size = path.stat().st_size
    assert calls[0] == (0, size) and calls[-1] == (size, size)


def test_a_magnetometer_reading_of_zero_is_missing_and_an_imu_without_compass_gives_no_mag(tmp_path):
    # a board without a compass fills SCALED_IMU's mag fields with 0 (the simulated tlog did):
    # read as a zero field it would be 0 T, which no place on Earth has (25-65 µT)
    v2, m = _mav()
    recs = [(T0_US, m.heartbeat_encode(2, 3, 1, 0, 4))]
    recs += [(T0_US + 1000 * k, m.scaled_imu_encode(100 + k, 0, 0, -1000, 0, 0, 0, 0, 0, 0, 0)) for k in range(1, 4)]
    recs += [(T0_US + 5000 + 1000 * k, m.scaled_imu2_encode(200 + k, 0, 0, -1000, 0, 0, 0,
                                                            *((210, -55, 430) if k != 2 else (0, 0, 0)), 0))
             for k in range(1, 4)]
    log = TlogReader().read(write_tlog(tmp_path / "nomag.tlog", recs))
    mag, warn = log["mag"], log.meta["diagnostics"]["warnings"]
    assert set(mag["src"]) == {"SCALED_IMU2"} and len(log["imu"]) == 6
    assert mag["mag_x_T"].isna().tolist() == [False, True, False]
    assert mag["mag_z_T"].iloc[0] == pytest.approx(43e-6)
    assert any("SCALED_IMU: magnetometer fields all zero" in w for w in warn)
    assert any("SCALED_IMU2: 1 magnetometer sample(s) of (0, 0, 0) read as missing" in w for w in warn)
