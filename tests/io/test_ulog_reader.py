"""PX4 ULog reader: real logs against the pyulog oracle, plus round trips through a minimal
ULog writer (tests/helpers_ulog.py) for every listed topic the real logs lack."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from pyulog import ULog

from helpers import realdata_file
from helpers_ulog import ULogWriter
from pipeline.io import registry
from pipeline.io.base import IngestError
from pipeline.io.parquet import read_flightlog, write_flightlog
from pipeline.io.ulog import NAV_STATES, ULogReader

REAL = ["ulg_px4_flight_review_fixtures/ekf_failure.ulg", "ulg_px4_flight_review_fixtures/motor_failure.ulg"]


def _ds(u: ULog, name: str, multi_id: int = 0):
    for d in u.data_list:
        if d.name == name and d.multi_id == multi_id:
            return d.data
    return None


def _rows(log, stream, src, instance=0):
    df = log[stream]
    return df[(df["src"] == src) & (df["instance"] == instance)].sort_values("t_ns", kind="stable")


def _t_ns(u: ULog, data) -> np.ndarray:
    return (data["timestamp"].astype(np.int64) - int(u.start_timestamp)) * 1000


# --- real logs ----------------------------------------------------------------------------------

@pytest.fixture(scope="module", params=REAL, ids=["ekf_failure", "motor_failure"])
def real(request):
    p = realdata_file(request.param)
    return p, ULog(str(p)), registry.read_log(p)


def test_real_detected_and_timed(real):
    p, u, log = real
    assert log.meta["reader"] == "ulog"
    assert log.meta["source_format"] == "px4_ulog"
    assert log.meta["t0_boot_ns"] == u.start_timestamp * 1000
    assert log.meta["status"] == "ok"
    assert log.meta["diagnostics"]["bytes_skipped"] == 0
    assert log.meta["diagnostics"]["dropouts"] == {"count": len(u.dropouts), "total_ms": 0}
    n_msgs = len(u.logged_messages) + sum(len(v) for v in u.logged_messages_tagged.values())
    assert len(log.meta["diagnostics"]["messages"]) == n_msgs
    if n_msgs:
        m0 = min(u.logged_messages, key=lambda m: m.timestamp)
        first = log.meta["diagnostics"]["messages"][0]
        assert first["t_ns"] == (m0.timestamp - u.start_timestamp) * 1000
        assert first["text"] == m0.message.strip()
    assert log.meta["params"] == pytest.approx({k: v for k, v in u.initial_parameters.items()})


def test_real_imu_equals_pyulog(real):
    _, u, log = real
    sc = _ds(u, "sensor_combined")
    got = _rows(log, "imu", "sensor_combined")
    np.testing.assert_array_equal(got["t_ns"], _t_ns(u, sc))
    np.testing.assert_array_equal(got["t_boot_ns"].to_numpy(np.int64), sc["timestamp"].astype(np.int64) * 1000)
    for i, a in enumerate("xyz"):
        np.testing.assert_array_equal(got[f"gyr_{a}_radps"], sc[f"gyro_rad[{i}]"].astype(np.float64))
        np.testing.assert_array_equal(got[f"acc_{a}_mps2"], sc[f"accelerometer_m_s2[{i}]"].astype(np.float64))
    # FRD specific force of a multicopter (ground, hover, climb) points along -z (FLU: +z)
    assert np.median(got["acc_z_mps2"]) < -8.0


def test_real_gps_equals_pyulog(real):
    _, u, log = real
    g = _ds(u, "vehicle_gps_position")
    got = _rows(log, "gps", "vehicle_gps_position")
    np.testing.assert_array_equal(got["t_ns"], _t_ns(u, g))
    if "latitude_deg" in g:  # newer PX4: float deg, m
        lat, lon = g["latitude_deg"], g["longitude_deg"]
        alt, alt_e = g["altitude_msl_m"], g["altitude_ellipsoid_m"]
    else:  # older: int32 1e-7 deg, int32 mm
        assert g["lat"].dtype.kind == "i"
        lat, lon = g["lat"] * 1e-7, g["lon"] * 1e-7
        alt, alt_e = g["alt"] * 1e-3, g["alt_ellipsoid"] * 1e-3
    np.testing.assert_allclose(got["lat_deg"], lat, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got["lon_deg"], lon, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got["alt_msl_m"], alt, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got["alt_wgs84_m"], alt_e, rtol=0, atol=1e-9)
    for a in "ned":
        np.testing.assert_array_equal(got[f"vel_{a}_mps"], g[f"vel_{a}_m_s"].astype(np.float64))
    np.testing.assert_array_equal(got["fix_type"], g["fix_type"].astype(np.float64))
    np.testing.assert_array_equal(got["n_sats"], g["satellites_used"].astype(np.float64))
    np.testing.assert_array_equal(got["hacc_m"], g["eph"].astype(np.float64))
    # UTC: t0_utc_ns + t_ns reproduces time_utc_usec at each fix (same offset for all)
    ok = (g["time_utc_usec"] > 0) & (g["fix_type"] >= 2)
    rel = g["timestamp_time_relative"].astype(np.int64)
    utc_pred = log.meta["t0_utc_ns"] + _t_ns(u, g) + rel * 1000
    err_us = (utc_pred[ok] - g["time_utc_usec"][ok].astype(np.int64) * 1000) / 1000
    assert log.meta["utc_source"] == "gps"
    # the offset is the median: signed residuals centre on 0; GPS publication jitters by
    # tens of ms against the boot clock
    assert abs(np.median(err_us)) <= 1.0
    assert np.max(np.abs(err_us)) < 50_000


def test_real_attitude_position_baro_mag(real):
    _, u, log = real
    att = _ds(u, "vehicle_attitude")
    got = _rows(log, "attitude", "vehicle_attitude")
    np.testing.assert_array_equal(got["t_ns"], _t_ns(u, att))
    for i, c in enumerate("wxyz"):
        np.testing.assert_array_equal(got[f"q_{c}"], att[f"q[{i}]"].astype(np.float64))
    lp = _ds(u, "vehicle_local_position")
    got = _rows(log, "local_position", "vehicle_local_position")
    for s, dcol in (("x", "pos_n_m"), ("y", "pos_e_m"), ("z", "pos_d_m"),
                    ("vx", "vel_n_mps"), ("vy", "vel_e_mps"), ("vz", "vel_d_mps")):
        np.testing.assert_array_equal(got[dcol], lp[s].astype(np.float64))
    # the EKF's reset counters, summed: a change marks a step in the estimate
    resets = sum(lp[f"{k}_reset_counter"].astype(np.float64) for k in ("xy", "z", "vxy", "vz"))
    np.testing.assert_array_equal(got["reset_count"], resets)
    o = log.meta["ned_origin"]
    k = int(np.argmax(lp["xy_global"] != 0))
    assert (o["lat_deg"], o["lon_deg"]) == (lp["ref_lat"][k], lp["ref_lon"][k])
    assert o["alt_msl_m"] == pytest.approx(float(lp["ref_alt"][k]))
    assert 40 < o["geoid_separation_m"] < 50  # EGM96 in central Europe: 45-48 m
    ad = _ds(u, "vehicle_air_data")
    got = _rows(log, "baro", "vehicle_air_data")
    np.testing.assert_array_equal(got["press_Pa"], ad["baro_pressure_pa"].astype(np.float64))
    np.testing.assert_array_equal(got["alt_rel_m"], ad["baro_alt_meter"].astype(np.float64))
    mg = _ds(u, "vehicle_magnetometer")
    got = _rows(log, "mag", "vehicle_magnetometer")
    for i, a in enumerate("xyz"):
        np.testing.assert_allclose(got[f"mag_{a}_T"], mg[f"magnetometer_ga[{i}]"].astype(np.float64) * 1e-4, rtol=1e-15)
    # the Earth's field: 25-65 µT
    norm = np.sqrt(sum(got[f"mag_{a}_T"] ** 2 for a in "xyz"))
    assert 20e-6 < np.median(norm) < 70e-6


def test_real_control_and_mode(real):
    _, u, log = real
    for d in u.data_list:
        if d.name == "input_rc":
            got = _rows(log, "control", "input_rc", d.multi_id)
            n = d.data["channel_count"]
            for i in range(18):
                want = np.where(n > i, d.data[f"values[{i}]"].astype(np.float64), np.nan)
                np.testing.assert_array_equal(got[f"rc_{i + 1}_us"], want)
        if d.name == "actuator_outputs":
            got = _rows(log, "control", "actuator_outputs", d.multi_id)
            assert len(got) == len(d.data["timestamp"])
            n = d.data["noutputs"]
            for i in range(16):
                want = np.where(n > i, d.data[f"output[{i}]"].astype(np.float64), np.nan)
                np.testing.assert_array_equal(got[f"servo_{i + 1}_us"], want)
    st = _ds(u, "vehicle_status")
    key = np.stack([st["nav_state"], st["arming_state"]], 1).astype(int)
    change = np.r_[True, np.any(key[1:] != key[:-1], axis=1)]
    got = log["mode"]
    assert list(got["mode"]) == [NAV_STATES[int(v)] for v in st["nav_state"][change]]
    assert list(got["armed"]) == list(st["arming_state"][change] == 2)
    np.testing.assert_array_equal(got["t_ns"], _t_ns(u, st)[change])


def test_real_rangefinder_motor_failure():
    p = realdata_file(REAL[1])
    u = ULog(str(p))
    ds = _ds(u, "distance_sensor")
    log = registry.read_log(p)
    rf = log["rangefinder"]
    np.testing.assert_array_equal(rf["dist_m"], ds["current_distance"].astype(np.float64))
    assert (rf["orientation"] == 25).all()  # ROTATION_DOWNWARD_FACING
    inside = (ds["current_distance"] >= ds["min_distance"]) & (ds["current_distance"] <= ds["max_distance"])
    assert rf["valid"].sum() == inside.sum()
    # the README's "~98 samples in range" is the 0.17-6 m window of a typical lidar
    narrow = registry.read_log(p, config={"ulog": {"rangefinder_valid_m": [0.17, 6.0]}})
    assert int(narrow["rangefinder"]["valid"].sum()) == int(((ds["current_distance"] >= 0.17)
                                                            & (ds["current_distance"] <= 6.0)).sum()) == 98


def test_real_vehicle_imu_multi_instance_by_config():
    p = realdata_file(REAL[0])
    u = ULog(str(p))
    log = registry.read_log(p, config={"ulog": {"imu": "vehicle_imu"}})
    imu = log["imu"]
    assert set(imu["src"]) == {"vehicle_imu"}
    assert sorted(imu["instance"].unique()) == [0, 1]
    for k in (0, 1):
        d = _ds(u, "vehicle_imu", k)
        got = _rows(log, "imu", "vehicle_imu", k)
        np.testing.assert_allclose(got["gyr_x_radps"], d["delta_angle[0]"] / (d["delta_angle_dt"] * 1e-6), rtol=1e-12)
        np.testing.assert_allclose(got["acc_z_mps2"], d["delta_velocity[2]"] / (d["delta_velocity_dt"] * 1e-6),
                                   rtol=1e-12)



def test_a_configured_topic_the_log_lacks_is_a_warning_naming_it_not_a_silently_empty_stream():
    p = realdata_file(REAL[0])
    log = registry.read_log(p, config={"ulog": {"gps": "vehicle_gps_positon"}})   # misspelt
    assert len(log["gps"]) == 0
    warn = [w for w in log.meta["diagnostics"]["warnings"] if w.startswith("ingest.ulog.gps:")]
    assert warn == ["ingest.ulog.gps: topic(s) vehicle_gps_positon not in the log; logged candidates: "
                    "vehicle_gps_position, sensor_gps"], log.meta["diagnostics"]["warnings"]
    # auto and a present topic say nothing
    for choice in ("auto", "vehicle_gps_position"):
        log = registry.read_log(p, config={"ulog": {"gps": choice}})
        assert len(log["gps"]) and not any(w.startswith("ingest.ulog.") for w in log.meta["diagnostics"]["warnings"])


# --- synthetic round trips -----------------------------------------------------------------------

F = [("uint64_t", "timestamp")]


def _fixture(tmp_path, rng, *, old_gps=False, dropouts=0):
    w = ULogWriter(start_us=5_000_000)
    w.add_info("sys_name", "PX4")
    w.add_param("MPC_XY_VEL_MAX", 12.0)
    w.add_param("SYS_AUTOSTART", 4001)
    n = 20
    ts = 5_000_000 + np.arange(n, dtype=np.uint64) * 10_000
    imu_f = F + [("uint64_t", "timestamp_sample"), ("float[3]", "delta_angle"), ("float[3]", "delta_velocity"),
                 ("uint16_t", "delta_angle_dt"), ("uint16_t", "delta_velocity_dt")]
    imu = {}
    for k in (0, 1):
        imu[k] = {"timestamp": ts + k, "timestamp_sample": ts + k,
                  "delta_angle": rng.normal(0, 0.01, (n, 3)).astype(np.float32),
                  "delta_velocity": rng.normal([0, 0, -0.0981], 0.001, (n, 3)).astype(np.float32),
                  "delta_angle_dt": np.full(n, 10_000, np.uint16), "delta_velocity_dt": np.full(n, 5_000, np.uint16)}
        w.topic("vehicle_imu", imu_f, imu[k], multi_id=k)
    if old_gps:
        gps_f = F + [("uint64_t", "time_utc_usec"), ("int32_t", "lat"), ("int32_t", "lon"), ("int32_t", "alt"),
                     ("int32_t", "alt_ellipsoid"), ("float", "eph"), ("float", "epv"), ("float", "vel_n_m_s"),
                     ("float", "vel_e_m_s"), ("float", "vel_d_m_s"), ("int32_t", "timestamp_time_relative"),
                     ("uint8_t", "fix_type"), ("uint8_t", "satellites_used")]
        gps = {"timestamp": ts[::4], "time_utc_usec": 1_700_000_000_000_000 + ts[::4] - 4_000_000,
               "lat": np.full(5, 473_565_835, np.int32), "lon": np.full(5, 85_189_385, np.int32),
               "alt": np.full(5, 419_888, np.int32), "alt_ellipsoid": np.full(5, 467_228, np.int32),
               "eph": np.full(5, 0.8, np.float32), "epv": np.full(5, 1.2, np.float32),
               "vel_n_m_s": np.ones(5, np.float32), "vel_e_m_s": np.zeros(5, np.float32),
               "vel_d_m_s": np.zeros(5, np.float32), "timestamp_time_relative": np.zeros(5, np.int32),
               "fix_type": np.full(5, 3, np.uint8), "satellites_used": np.full(5, 12, np.uint8)}
        w.topic("vehicle_gps_position", gps_f, gps)
    else:
        gps_f = F + [("uint64_t", "time_utc_usec"), ("double", "latitude_deg"), ("double", "longitude_deg"),
                     ("double", "altitude_msl_m"), ("double", "altitude_ellipsoid_m"), ("float", "eph"),
                     ("float", "epv"), ("float", "vel_n_m_s"), ("float", "vel_e_m_s"), ("float", "vel_d_m_s"),
                     ("int32_t", "timestamp_time_relative"), ("uint8_t", "fix_type"), ("uint8_t", "satellites_used")]
        gps = {}
        for k in (0, 1):
            gps[k] = {"timestamp": ts[::4] + k, "time_utc_usec": 1_700_000_000_000_000 + ts[::4] - 4_000_000,
                      "latitude_deg": 47.0 + rng.normal(0, 1e-5, 5), "longitude_deg": 8.0 + rng.normal(0, 1e-5, 5),
                      "altitude_msl_m": np.full(5, 400.0), "altitude_ellipsoid_m": np.full(5, 447.5),
                      "eph": np.full(5, 0.8, np.float32), "epv": np.full(5, 1.2, np.float32),
                      "vel_n_m_s": np.ones(5, np.float32), "vel_e_m_s": np.zeros(5, np.float32),
                      "vel_d_m_s": np.zeros(5, np.float32), "timestamp_time_relative": np.zeros(5, np.int32),
                      "fix_type": np.full(5, 3, np.uint8), "satellites_used": np.full(5, 12, np.uint8)}
            w.topic("sensor_gps", gps_f, gps[k], multi_id=k)
    asp_f = F + [("float", "indicated_airspeed_m_s"), ("float", "true_airspeed_m_s"),
                 ("float", "air_temperature_celsius"), ("float", "confidence")]
    asp = {"timestamp": ts, "indicated_airspeed_m_s": rng.uniform(15, 25, n).astype(np.float32),
           "true_airspeed_m_s": rng.uniform(15, 25, n).astype(np.float32),
           "air_temperature_celsius": np.full(n, 21.5, np.float32), "confidence": np.ones(n, np.float32)}
    w.topic("airspeed", asp_f, asp)
    dp_f = F + [("float", "differential_pressure_pa"), ("float", "temperature")]
    dp = {"timestamp": ts + 3, "differential_pressure_pa": rng.uniform(100, 300, n).astype(np.float32),
          "temperature": np.full(n, 22.0, np.float32)}
    w.topic("differential_pressure", dp_f, dp)
    ds_f = F + [("float", "min_distance"), ("float", "max_distance"), ("float", "current_distance"),
                ("int8_t", "signal_quality"), ("uint8_t", "orientation")]
    dist = np.array([0.1, 0.3, 2.0, 7.0, 4.0] * 4, np.float32)
    sq = np.array([100, 100, 0, 100, -1] * 4, np.int8)
    rf = {"timestamp": ts, "min_distance": np.full(n, 0.2, np.float32), "max_distance": np.full(n, 6.0, np.float32),
          "current_distance": dist, "signal_quality": sq, "orientation": np.full(n, 25, np.uint8)}
    w.topic("distance_sensor", ds_f, rf)
    rc_f = F + [("uint32_t", "channel_count"), ("uint16_t[18]", "values")]
    rc = {"timestamp": ts, "channel_count": np.full(n, 8, np.uint32),
          "values": rng.integers(1000, 2000, (n, 18)).astype(np.uint16)}
    w.topic("input_rc", rc_f, rc)
    ao_f = F + [("uint32_t", "noutputs"), ("float[16]", "output")]
    ao = {}
    for k in (0, 1):
        ao[k] = {"timestamp": ts + 2 + k, "noutputs": np.full(n, 4 + 2 * k, np.uint32),
                 "output": rng.uniform(1000, 2000, (n, 16)).astype(np.float32)}
        w.topic("actuator_outputs", ao_f, ao[k], multi_id=k)
    st_f = F + [("uint8_t", "nav_state"), ("uint8_t", "arming_state")]
    st = {"timestamp": ts, "nav_state": np.array([0] * 5 + [2] * 5 + [2] * 5 + [18] * 5, np.uint8),
          "arming_state": np.array([1] * 3 + [2] * 12 + [2] * 2 + [1] * 3, np.uint8)}
    w.topic("vehicle_status", st_f, st)
    ad_f = F + [("float", "baro_alt_meter"), ("float", "baro_temp_celcius"), ("float", "baro_pressure_pa")]
    ad = {"timestamp": ts, "baro_alt_meter": rng.uniform(400, 410, n).astype(np.float32),
          "baro_temp_celcius": np.full(n, 30.0, np.float32),
          "baro_pressure_pa": rng.uniform(96000, 97000, n).astype(np.float32)}
    w.topic("vehicle_air_data", ad_f, ad)
    mag_f = F + [("float", "x"), ("float", "y"), ("float", "z")]
    mags = {}
    for k in (0, 1):
        mags[k] = {"timestamp": ts + k, "x": rng.normal(0.2, 0.01, n).astype(np.float32),
                   "y": rng.normal(0.0, 0.01, n).astype(np.float32), "z": rng.normal(0.4, 0.01, n).astype(np.float32)}
        w.topic("sensor_mag", mag_f, mags[k], multi_id=k)
    w.log("INFO", 5_000_100, "[commander] Armed by RC")
    w.log("WARNING", 5_100_000, "[ekf2] GPS check failed")
    for _ in range(dropouts):
        w.dropout(37)
    p = w.write(tmp_path / "synthetic.ulg")
    return p, dict(imu=imu, gps=gps, asp=asp, dp=dp, rf=rf, rc=rc, ao=ao, st=st, ad=ad, mags=mags, ts=ts)


def test_writer_output_parses_with_pyulog(tmp_path, rng):
    p, src = _fixture(tmp_path, rng, dropouts=2)
    u = ULog(str(p))
    assert not u.file_corruption
    assert u.start_timestamp == 5_000_000
    names = sorted({(d.name, d.multi_id) for d in u.data_list})
    assert ("vehicle_imu", 1) in names and ("sensor_gps", 1) in names and ("airspeed", 0) in names
    np.testing.assert_array_equal(_ds(u, "vehicle_imu", 1)["delta_angle[2]"], src["imu"][1]["delta_angle"][:, 2])
    np.testing.assert_array_equal(_ds(u, "input_rc")["values[17]"], src["rc"]["values"][:, 17])
    assert [m.message for m in u.logged_messages] == ["[commander] Armed by RC", "[ekf2] GPS check failed"]
    assert [d.duration for d in u.dropouts] == [37, 37]
    assert u.initial_parameters["SYS_AUTOSTART"] == 4001
    assert u.msg_info_dict["sys_name"] == "PX4"


def test_synthetic_round_trip(tmp_path, rng):
    p, s = _fixture(tmp_path, rng, dropouts=2)
    log = registry.read_log(p)
    t0 = 5_000_000
    assert log.meta["reader"] == "ulog"
    # vehicle_imu, two instances: rate = delta / dt
    for k in (0, 1):
        got = _rows(log, "imu", "vehicle_imu", k)
        np.testing.assert_array_equal(got["t_ns"], (s["imu"][k]["timestamp"].astype(np.int64) - t0) * 1000)
        np.testing.assert_allclose(got[["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].to_numpy(),
                                   s["imu"][k]["delta_angle"].astype(np.float64) / 0.01, rtol=1e-12)
        np.testing.assert_allclose(got[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy(),
                                   s["imu"][k]["delta_velocity"].astype(np.float64) / 0.005, rtol=1e-12)
    # sensor_gps (no vehicle_gps_position): both instances, float degrees
    for k in (0, 1):
        got = _rows(log, "gps", "sensor_gps", k)
        np.testing.assert_array_equal(got["lat_deg"], s["gps"][k]["latitude_deg"])
        np.testing.assert_array_equal(got["alt_wgs84_m"], s["gps"][k]["altitude_ellipsoid_m"])
        assert (got["n_sats"] == 12).all() and (got["fix_type"] == 3).all()
    assert log.meta["t0_utc_ns"] == (1_700_000_000_000_000 - 4_000_000) * 1000 + t0 * 1000
    # airspeed + differential pressure
    got = _rows(log, "airspeed", "airspeed")
    np.testing.assert_array_equal(got["airspeed_mps"], s["asp"]["indicated_airspeed_m_s"].astype(np.float64))
    np.testing.assert_array_equal(got["temp_degC"], 21.5)
    got = _rows(log, "airspeed", "differential_pressure")
    np.testing.assert_array_equal(got["diff_press_Pa"], s["dp"]["differential_pressure_pa"].astype(np.float64))
    # rangefinder validity: inside [min, max] and signal_quality != 0
    rf = log["rangefinder"]
    np.testing.assert_array_equal(rf["dist_m"], s["rf"]["current_distance"].astype(np.float64))
    assert list(rf["valid"][:5]) == [False, True, False, False, True]
    # control: rc channels beyond channel_count are NaN; outputs beyond noutputs NaN
    rc = _rows(log, "control", "input_rc")
    np.testing.assert_array_equal(rc["rc_8_us"], s["rc"]["values"][:, 7].astype(np.float64))
    assert rc["rc_9_us"].isna().all() and rc["servo_1_us"].isna().all()
    for k in (0, 1):
        ao = _rows(log, "control", "actuator_outputs", k)
        nout = 4 + 2 * k
        np.testing.assert_array_equal(ao[f"servo_{nout}_us"], s["ao"][k]["output"][:, nout - 1].astype(np.float64))
        assert ao[f"servo_{nout + 1}_us"].isna().all() and ao["rc_1_us"].isna().all()
    # mode: one row per change of (nav_state, arming_state)
    mode = log["mode"]
    assert list(mode["mode"]) == ["MANUAL", "MANUAL", "POSCTL", "AUTO_LAND", "AUTO_LAND"]
    assert list(mode["armed"]) == [False, True, True, True, False]
    assert list(mode["t_ns"]) == [0, 30_000_000, 50_000_000, 150_000_000, 170_000_000]
    # baro and multi-instance sensor_mag (Gauss -> T)
    np.testing.assert_array_equal(log["baro"]["press_Pa"], s["ad"]["baro_pressure_pa"].astype(np.float64))
    for k in (0, 1):
        got = _rows(log, "mag", "sensor_mag", k)
        np.testing.assert_allclose(got["mag_z_T"], s["mags"][k]["z"].astype(np.float64) * 1e-4, rtol=1e-15)
    # diagnostics: messages, dropouts, params
    d = log.meta["diagnostics"]
    assert [(m["level"], m["text"], m["t_ns"]) for m in d["messages"]] == [
        ("INFO", "[commander] Armed by RC", 100_000), ("WARNING", "[ekf2] GPS check failed", 100_000_000)]
    assert d["dropouts"] == {"count": 2, "total_ms": 74}
    assert log.meta["status"] == "partial"
    assert log.meta["params"] == {"MPC_XY_VEL_MAX": pytest.approx(12.0), "SYS_AUTOSTART": 4001}
    assert d["record_counts"]["vehicle_imu[1]"] == 20
    # the Parquet store round-trips it (meta is strict JSON)
    back = read_flightlog(write_flightlog(log, tmp_path / "store")[0].parent)
    for name, df in log.streams.items():
        pd.testing.assert_frame_equal(back[name], df)
    assert back.meta["diagnostics"]["dropouts"] == d["dropouts"]


def test_synthetic_old_gps_integer_fields(tmp_path, rng):
    p, s = _fixture(tmp_path, rng, old_gps=True)
    log = registry.read_log(p)
    g = log["gps"]
    assert set(g["src"]) == {"vehicle_gps_position"}
    np.testing.assert_allclose(g["lat_deg"], 47.3565835, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g["lon_deg"], 8.5189385, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g["alt_msl_m"], 419.888, rtol=0, atol=1e-9)
    np.testing.assert_allclose(g["alt_wgs84_m"], 467.228, rtol=0, atol=1e-9)
    assert log.meta["status"] == "ok"


def test_sniff_is_by_magic_only(tmp_path):
    assert ULogReader.sniff(tmp_path / "x", b"ULog\x01\x12\x35\x01" + bytes(8))
    assert ULogReader.sniff(tmp_path / "x", b"ULog\x01\x12\x36\x01") is None
    assert ULogReader.sniff(tmp_path / "x", b'{"data": []}') is None


def test_no_data_messages_is_ingest_error(tmp_path):
    w = ULogWriter()
    w.add_format("vehicle_status", F + [("uint8_t", "nav_state")])
    p = w.write(tmp_path / "defs_only.ulg")
    with pytest.raises(IngestError, match="defs_only.ulg: .*no data messages"):
        registry.read_log(p)


def test_truncated_fixture_counts_cut_bytes(tmp_path, rng):
    p, s = _fixture(tmp_path, rng)
    raw = p.read_bytes()
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(raw[:-5])  # the final LOGGING message loses 5 bytes
    log = registry.read_log(cut)
    d = log.meta["diagnostics"]
    last_len = 3 + 1 + 8 + len("[ekf2] GPS check failed")
    assert d["bytes_skipped"] == last_len - 5
    assert d["records_dropped"]["truncated"] == 1
    assert log.meta["status"] == "partial"
    assert len(d["messages"]) == 1
    pd.testing.assert_frame_equal(log["imu"], registry.read_log(p)["imu"])
