"""End-to-end preprocessing on synthetic FlightLogs: the state table, empty streams, gaps,
outputs on disk, CLI, config errors."""

import json

import numpy as np
import pandas as pd
import pytest

from pipeline.cli import main
from pipeline.config import ConfigError
from pipeline.frames.geodesy import ned_to_geodetic
from pipeline.frames.rotations import euler_to_quat
from pipeline.io import schema
from pipeline.io.base import FlightLog
from pipeline.io.parquet import read_table, read_table_meta, write_flightlog
from pipeline.preprocess.calibrate import CALIBRATION
from pipeline.preprocess.state import PreprocessConfig, preprocess_log
from helpers_preprocess import ns, synthetic_flight


def test_state_from_gps_circle(rng):
    log, w = synthetic_flight(rng)
    res = preprocess_log(log)
    state, seg, cal = res.tables
    assert list(state.columns) == [c.name for c in schema.STATE]
    assert state["t_ns"].dtype == np.int64 and state["gap"].dtype == bool
    assert np.all(np.diff(state["t_ns"]) == 40_000_000)  # 25 Hz
    t = state["t_ns"].to_numpy() * 1e-9
    gap = state["gap"].to_numpy()
    assert gap[(t > 30.3) & (t < 33.9)].all() and not gap[(t > 1) & (t < 29.5)].any()
    ok = ~gap & (t > 1.5) & (t < 58)
    ok &= np.abs(t - 32) > 3.5  # away from the gap edges
    # linear interpolation of 5 Hz fixes: chord sag R (1 - cos(w dt / 2)) = 0.025 m at most
    sag = 20 * (1 - np.cos(w * 0.1))
    np.testing.assert_allclose(state["pos_n_m"][ok], 20 * np.cos(w * t[ok]), atol=sag + 1e-3)
    np.testing.assert_allclose(state["pos_d_m"][ok], -10.0, atol=1e-3)
    # centripetal acceleration 20 w^2 = 5 m/s^2 toward the centre
    acc = np.c_[state["acc_n_mps2"], state["acc_e_mps2"]][ok]
    np.testing.assert_allclose(np.linalg.norm(acc, axis=1), 20 * w ** 2, rtol=0.02)
    assert np.isnan(state["acc_n_mps2"][gap]).all()
    np.testing.assert_allclose(state["roll_rad"][ok], 0.2, atol=1e-9)
    np.testing.assert_allclose(state["r_radps"][ok], w * np.cos(0.2), atol=1e-9)  # from the gyro
    np.testing.assert_allclose(state["ail"][ok], np.sin(t[ok]), atol=0.01)
    assert np.all(state["thr"][ok] == 0.5)
    assert seg["label"].tolist() == ["mode:STABILIZE", "mode:LOITER"]
    d = res.diagnostics
    assert d["sources"]["position"] == "gps" and d["calibration"]["method"] == "none"


def test_every_stream_empty_or_partial_never_crashes():
    empty = FlightLog.from_streams({"flight_id": "e"}, {})
    res = preprocess_log(empty)
    state, seg, cal = res.tables
    assert len(state) == 0 and list(state.columns) == [c.name for c in schema.STATE]
    assert len(seg) == 0 and len(cal) == 0
    t = np.arange(0, 5, 0.04)
    q = euler_to_quat(0 * t, 0.1 + 0 * t, 0.3 * t)
    only_att = FlightLog.from_streams({"flight_id": "a"}, {
        "attitude": pd.DataFrame({"t_ns": ns(t), **dict(zip(["q_w", "q_x", "q_y", "q_z"], q.T))})})
    res = preprocess_log(only_att)
    state, _, _ = res.tables
    assert len(state) == len(t)
    assert state["pos_n_m"].isna().all() and state["alt_cal_m"].isna().all()
    # body rates from differentiated attitude: yaw rate 0.3 rad/s -> (p, q, r) = 0.3 (-sin θ, 0, cos θ)
    mid = slice(30, -30)
    np.testing.assert_allclose(state["r_radps"][mid], 0.3 * np.cos(0.1), atol=1e-4)
    np.testing.assert_allclose(state["p_radps"][mid], -0.3 * np.sin(0.1), atol=1e-4)
    # a single sample of a single stream
    one = FlightLog.from_streams({}, {"baro": pd.DataFrame({"t_ns": [5], "alt_rel_m": [1.0]})})
    res = preprocess_log(one)
    state, _, _ = res.tables
    assert len(state) == 1


def test_gps_down_is_about_the_origin_altitude_when_the_log_gives_msl_only():
    # a DataFlash-style origin (ORGN: MSL altitude, no WGS-84) and MSL-only fixes: the flight
    # starts 20 m above its origin, so pos_d is -20 m, not 0 (the median of the first fixes)
    t = np.arange(0, 20, 0.2)
    lat0, lon0, h0 = 46.5, 6.6, 480.0
    lat, lon, h = ned_to_geodetic(0 * t + 5.0, 0 * t, -20.0 - 0.5 * t, lat0, lon0, h0)
    gps = pd.DataFrame({"t_ns": ns(t), "lat_deg": lat, "lon_deg": lon, "alt_msl_m": h, "fix_type": 3.0})
    meta = {"flight_id": "msl", "ned_origin": {"lat_deg": lat0, "lon_deg": lon0, "alt_wgs84_m": None,
                                               "alt_msl_m": h0}}
    res = preprocess_log(FlightLog.from_streams(meta, {"gps": gps}))
    st = res.state
    tt = st["t_ns"].to_numpy() * 1e-9
    np.testing.assert_allclose(st["pos_d_m"], -20.0 - 0.5 * tt, atol=1e-3)
    np.testing.assert_allclose(st["pos_n_m"], 5.0, atol=1e-3)
    # fixes in both datums (the simulated DataFlash GPS): the WGS-84 altitudes are used and the
    # MSL origin is shifted by their separation (29 m of geoid undulation), not dropped
    gps2 = gps.assign(alt_wgs84_m=h - 29.0)
    res = preprocess_log(FlightLog.from_streams(meta, {"gps": gps2}))
    np.testing.assert_allclose(res.state["pos_d_m"], -20.0 - 0.5 * tt, atol=1e-3)
    assert any("the fixes' median alt_wgs84_m - alt_msl_m" in n for n in res.diagnostics["notes"])


def test_rc_inputs_and_servo_outputs_on_rows_of_their_own_both_survive_resampling():
    # RCIN and RCOU arrive as separate rows (10 Hz each, RC at 0.00, 0.10, ... and servos at
    # 0.05, 0.15, ... plus every tenth servo row on an RC stamp): resampled together, each
    # grid point would interpolate towards the other group's missing value
    tr = np.arange(0, 20, 0.1)
    ts = np.sort(np.r_[tr[::10], tr + 0.05])
    rc = pd.DataFrame({"t_ns": ns(tr), "rc_1_us": 1500 + 400 * np.sin(tr), "rc_3_us": 1500.0})
    sv = pd.DataFrame({"t_ns": ns(ts), "servo_1_us": 1100 + 10 * ts})
    ctrl = pd.concat([rc, sv]).sort_values("t_ns", kind="stable").reset_index(drop=True)
    q = np.tile([1.0, 0, 0, 0], (len(tr), 1))
    att = pd.DataFrame({"t_ns": ns(tr), **dict(zip(["q_w", "q_x", "q_y", "q_z"], q.T))})
    res = preprocess_log(FlightLog.from_streams({"flight_id": "rc"}, {"control": ctrl, "attitude": att}))
    st = res.state
    t = st["t_ns"].to_numpy() * 1e-9
    inner = (t > 0.2) & (t < 19.7)
    assert st["ail"][inner].notna().all() and st["thr"][inner].notna().all()
    np.testing.assert_allclose(st["ail"][inner], np.sin(t[inner]), atol=0.01)
    assert "control" not in res.diagnostics["timestamp_repairs"]  # no spurious 'duplicates'


def test_timestamp_repairs_counted():
    t = ns(np.arange(0, 10, 0.04))
    t[50] = t[49]  # a duplicate
    q = np.tile([1.0, 0, 0, 0], (len(t), 1))
    log = FlightLog.from_streams({}, {"attitude": pd.DataFrame({"t_ns": t, **dict(zip(["q_w", "q_x", "q_y", "q_z"], q.T))})})
    res = preprocess_log(log)
    state, _, _ = res.tables
    assert res.diagnostics["timestamp_repairs"]["attitude"]["duplicate"] == 1


def test_outputs_and_cli(tmp_path, rng, capsys):
    log, _ = synthetic_flight(rng, gap=False)
    ingest = tmp_path / "ingest" / "synthetic"
    write_flightlog(log, ingest)
    rc = main(["preprocess", str(ingest), "-o", str(tmp_path / "pp")])
    assert rc == 0, capsys.readouterr().err
    out = tmp_path / "pp" / "synthetic"
    st = read_table(out / "state.parquet", schema.STATE)
    res = preprocess_log(log)
    ref, seg_ref, _ = res.tables
    pd.testing.assert_frame_equal(st, ref, check_like=False)
    assert read_table_meta(out / "state.parquet")["schema_version"] == schema.SCHEMA_VERSION
    assert len(read_table(out / "segments.parquet", schema.SEGMENTS)) == len(seg_ref)
    read_table(out / "calibration.parquet", CALIBRATION)
    assert json.loads((out / "preprocess.json").read_text())["sources"]["position"] == "gps"
    # a folder that is not an ingest output: clear message, non-zero exit
    rc = main(["preprocess", str(tmp_path), "-o", str(tmp_path / "pp")])
    assert rc == 1 and "not an ingest folder" in capsys.readouterr().err


@pytest.mark.parametrize("bad, match", [
    ({"rate_hz": -1}, "rate_hz"), ({"methods": {"gps": "cubic"}}, "cubic"), ({"bogus": 1}, "unknown key"),
    ({"butterworth": {"alt": {"order": 3}}}, "butterworth"), ({"derivatives": {"method": "x"}}, "derivatives"),
    ({"vehicles": {"v": {"imu_mount": {"convention": "enu"}}}, "flights": {"*": {"vehicle": "v"}}}, "convention"),
])
def test_bad_config_is_a_clear_error(bad, match):
    with pytest.raises(ConfigError, match=match):
        PreprocessConfig.from_config(bad, flight_id="x")


def test_cutoff_above_nyquist_names_the_column(rng):
    log, _ = synthetic_flight(rng, gap=False)
    with pytest.raises(ConfigError, match="attitude.q_w|gps.pos_n_m"):
        preprocess_log(log, {"butterworth": {"gps.pos_n_m": {"order": 2, "cutoff_hz": 20.0}}})


def test_stage_entry_point_writes_the_declared_outputs(tmp_path, rng):
    from pipeline.preprocess.run import run_preprocess

    log, _ = synthetic_flight(rng, gap=False)
    write_flightlog(log, tmp_path / "in")
    out = {"state": tmp_path / "state" / "f.parquet", "segments": tmp_path / "segments" / "f.parquet",
           "calibration": tmp_path / "calibration" / "f.parquet", "info": tmp_path / "state" / "f.json"}
    res = run_preprocess({"meta": tmp_path / "in" / "meta.json"}, out, {})
    diag = res.diagnostics
    assert res.status == "ok" and diag["flight_id"] == "synthetic"
    st = read_table(out["state"], schema.STATE)
    assert len(st) == diag["n_samples"]
    assert read_table_meta(out["state"])["preprocess"]["sources"]["position"] == "gps"
    assert json.loads(out["info"].read_text())["status"] == "ok"


def test_the_box_rotation_of_the_ingest_meta_reaches_the_state_metadata(tmp_path, rng):
    from pipeline.preprocess.run import run_preprocess
    from pipeline.preprocess.state import box_rotation_rad

    log, _ = synthetic_flight(rng, gap=False)
    log = FlightLog.from_streams({**log.meta, "params": {"rotation": -0.59, "box_rotation_rad": -0.59}},
                                 dict(log.streams))
    write_flightlog(log, tmp_path / "in")
    out = {k: tmp_path / k / "f.parquet" for k in ("state", "segments", "calibration")}
    out["info"] = tmp_path / "state" / "f.json"
    res = run_preprocess({"meta": tmp_path / "in" / "meta.json"}, out, {})
    meta = read_table_meta(out["state"])
    assert meta["box_rotation_rad"] == -0.59 == res.diagnostics["box_rotation_rad"]
    assert meta["preprocess"]["box_rotation_rad"] == -0.59
    assert json.loads(out["info"].read_text())["box_rotation_rad"] == -0.59
    # a flight without one (every non-FlightCoach log) gets no key, never a made-up 0
    plain, _ = synthetic_flight(rng, gap=False)
    write_flightlog(plain, tmp_path / "in2")
    run_preprocess({"meta": tmp_path / "in2" / "meta.json"}, out, {})
    assert "box_rotation_rad" not in read_table_meta(out["state"])
    assert [box_rotation_rad(m) for m in (None, {}, {"params": {"box_rotation_rad": None}},
                                          {"params": {"box_rotation_rad": "x"}},
                                          {"params": {"box_rotation_rad": 3}})] == [None, None, None, None, 3.0]


def test_a_pressure_logged_in_hpa_is_dropped_and_named_not_turned_into_a_wild_altitude():
    t = np.arange(0, 10, 0.1)
    good = pd.DataFrame({"t_ns": ns(t), "press_Pa": 101325.0 - 12.0 * t})  # ~1 m/s climb
    res = preprocess_log(FlightLog.from_streams({"flight_id": "pa"}, {"baro": good}))
    assert not any("pressures dropped" in n for n in res.diagnostics["notes"])
    hpa = good.assign(press_Pa=good["press_Pa"] / 100.0)
    res = preprocess_log(FlightLog.from_streams({"flight_id": "hpa"}, {"baro": hpa}))
    note = [n for n in res.diagnostics["notes"] if "pressures dropped" in n]
    assert note and "100 of 100" in note[0] and "looks like hPa" in note[0]
    assert res.state["alt_cal_m"].isna().all()
    # one corrupt record among good ones: that one is dropped, the rest kept
    one = good.copy()
    one.loc[50, "press_Pa"] = 0.0
    res = preprocess_log(FlightLog.from_streams({"flight_id": "one"}, {"baro": one}))
    note = [n for n in res.diagnostics["notes"] if "pressures dropped" in n]
    assert note and "1 of 100" in note[0] and "hPa" not in note[0]


def test_an_estimator_reset_in_the_local_position_is_a_gap_not_motion():
    # a hover at 10 m whose EKF resets its height by -5 m at 20 s (the reset counter steps)
    t = np.arange(0, 40, 0.1)
    d = np.where(t < 20.0, -10.0, -15.0)
    lp = pd.DataFrame({"t_ns": ns(t), "pos_n_m": 0.0, "pos_e_m": 0.0, "pos_d_m": d, "vel_n_mps": 0.0,
                       "vel_e_mps": 0.0, "vel_d_mps": 0.0, "reset_count": np.where(t < 20.0, 3.0, 4.0)})
    res = preprocess_log(FlightLog.from_streams({"flight_id": "reset"}, {"local_position": lp}),
                         {"velocity_source": "differentiate"})
    st = res.state
    tt = st["t_ns"].to_numpy() * 1e-9
    gap = st["gap"].to_numpy()
    assert gap[(tt > 19.85) & (tt < 20.05)].all() and not gap[(tt < 19.7) | (tt > 20.3)].any()
    # on the kept rows the differentiated velocity never sees the 5 m step
    assert np.abs(st["vel_d_mps"].to_numpy()[~gap]).max() < 1e-6
    assert any("1 estimator reset(s)" in n for n in res.diagnostics["notes"])
    # without the counter the same step is (as before) motion: 5 m in one sample
    res = preprocess_log(FlightLog.from_streams({"flight_id": "nocount"}, {"local_position": lp.drop(columns="reset_count")}),
                         {"velocity_source": "differentiate"})
    assert not res.state["gap"].any() and np.abs(res.state["vel_d_mps"]).max() > 5.0


def test_a_fix_without_a_climb_rate_keeps_its_measured_horizontal_velocity(rng):
    # GPS_RAW_INT carries ground speed and course but no vertical velocity: the measured north
    # and east velocities are used as they are (noisy positions would give a far noisier
    # derivative), only down is differentiated from the position, and the source says so
    log, w = synthetic_flight(rng, gap=False)
    gps = log["gps"].copy()
    # 2 m of white position noise: the differentiated horizontal velocity would be off by ~1 m/s
    gps["lat_deg"] += rng.normal(0.0, 2.0 / 111_000.0, len(gps))
    h = 0.3 * gps["t_ns"].to_numpy() * 1e-9                   # a 0.3 m/s climb
    gps["alt_wgs84_m"] += h
    gps["vel_d_mps"] = np.nan
    streams = {k: log[k] for k in ("attitude", "imu")}
    res = preprocess_log(FlightLog.from_streams(log.meta, {**streams, "gps": gps}))
    st = res.state
    t = st["t_ns"].to_numpy() * 1e-9
    mid = (t > 2) & (t < 58)
    # on the fix times the measured velocity is returned exactly (interpolated in between)
    on_fix = np.isin(st["t_ns"].to_numpy(), gps["t_ns"].to_numpy()) & mid
    np.testing.assert_allclose(st["vel_n_mps"][on_fix], -20 * w * np.sin(w * t[on_fix]), atol=1e-9)
    np.testing.assert_allclose(st["vel_e_mps"][on_fix], 20 * w * np.cos(w * t[on_fix]), atol=1e-9)
    np.testing.assert_allclose(st["vel_d_mps"][mid], -0.3, atol=1e-4)  # the noisy latitude leaks ~2e-5 through the curvature
    assert res.diagnostics["sources"]["velocity"] == "measured (n, e); differentiated position (d)"
    # the same fixes without any measured velocity: every axis differentiated, the noise shows
    res = preprocess_log(FlightLog.from_streams(log.meta, {**streams, "gps": gps.assign(vel_n_mps=np.nan)}))
    assert res.diagnostics["sources"]["velocity"] == "differentiated position (n, d); measured (e)"
    err = res.state["vel_n_mps"][mid] + 20 * w * np.sin(w * t[mid])
    assert np.sqrt(np.mean(err ** 2)) > 0.3


def test_a_gps_flight_takes_its_climb_rate_from_the_baro_not_from_the_noisy_fix_heights(rng):
    # fixes with 1 m of height noise and no climb rate beside a 20 Hz baro with 0.1 m: the down
    # velocity follows the baro's derivative (a 0.3 m/s climb), pos_d stays the GPS's
    log, w = synthetic_flight(rng, gap=False)
    gps = log["gps"].copy()
    tg = gps["t_ns"].to_numpy() * 1e-9
    gps["alt_wgs84_m"] += 0.3 * tg + rng.normal(0.0, 1.0, len(gps))
    gps["vel_d_mps"] = np.nan
    tb = np.arange(0, 60, 0.05)
    baro = pd.DataFrame({"t_ns": ns(tb), "alt_rel_m": 7.0 + 0.3 * tb + rng.normal(0.0, 0.1, len(tb))})
    streams = {"attitude": log["attitude"], "imu": log["imu"], "gps": gps, "baro": baro}
    res = preprocess_log(FlightLog.from_streams(log.meta, streams))
    st = res.state
    t = st["t_ns"].to_numpy() * 1e-9
    mid = (t > 2) & (t < 58)
    err = st["vel_d_mps"][mid] + 0.3
    assert np.sqrt(np.mean(err ** 2)) < 0.15       # the 1 Hz-filtered baro noise: ~0.1 m/s
    assert np.sqrt(np.mean(st["acc_d_mps2"][mid] ** 2)) < 0.5
    assert res.diagnostics["sources"]["velocity"] == "measured (n, e); baro height (d)"
    # the position's down axis is still the fixes' height about the origin (the baro reads 7 m
    # at the start: pos_d from it would be 3 m off), smoothed with nothing but the fixes
    assert abs(np.mean(st["pos_d_m"][mid] + 10 + 0.3 * t[mid])) < 0.5
    # switched off, or without a baro: the down axis differentiated from the fixes (as they are:
    # the GPS smoother off), ~10x noisier
    raw = {"gps_smoother": {"enabled": False}}
    for cfg, s in (({"vertical_from_baro": False, **raw}, streams), (raw, {k: v for k, v in streams.items() if k != "baro"})):
        res = preprocess_log(FlightLog.from_streams(log.meta, s), cfg)
        assert res.diagnostics["sources"]["velocity"] == "measured (n, e); differentiated position (d)"
        assert np.sqrt(np.mean((res.state["vel_d_mps"][mid] + 0.3) ** 2)) > 0.3
        assert np.sqrt(np.mean(res.state["acc_d_mps2"][mid] ** 2)) > 1.0


def test_values_no_sensor_reads_are_set_to_nan_counted_and_kept_out_of_the_state(rng):
    # damaged records that still decoded: a 1e11 m/s GPS velocity, a 2.9e38 rad/s gyro sample
    log, w = synthetic_flight(rng, gap=False)
    gps, imu = log["gps"].copy(), log["imu"].copy()
    gps.loc[40, "vel_e_mps"] = 1.06e11
    gps.loc[41, "alt_wgs84_m"] = 6.9e17
    imu.loc[[100, 200], "gyr_z_radps"] = [2.9e38, -np.inf]
    res = preprocess_log(FlightLog.from_streams(log.meta, {**{k: log[k] for k in ("attitude", "control")},
                                                           "gps": gps, "imu": imu}))
    d = res.diagnostics
    assert d["implausible_values"] == {"imu": {"gyr_z_radps": 2}, "gps": {"alt_wgs84_m": 1, "vel_e_mps": 1}}
    assert "gps: 2 value(s) outside physical limits set to NaN (alt_wgs84_m 1, vel_e_mps 1): damaged records" \
        in d["notes"]
    st = res.state
    assert np.nanmax(np.abs(st[["vel_n_mps", "vel_e_mps", "vel_d_mps"]].to_numpy())) < 20
    assert np.nanmax(np.abs(st["pos_d_m"])) < 20 and np.nanmax(np.abs(st["r_radps"])) < 1
    # the rows' other columns are kept: the fix with the bad velocity still gives its position
    # (checked against the undamaged log's state below)
    clean = preprocess_log(FlightLog.from_streams(log.meta, {**{k: log[k] for k in ("attitude", "control")},
                                                             "gps": log["gps"], "imu": log["imu"]})).state
    # the one without its altitude leaves a hole in the down position only, between its neighbours
    new_gap = st["gap"].to_numpy() & ~clean["gap"].to_numpy()
    t = st["t_ns"].to_numpy()
    assert new_gap.any() and np.all((t[new_gap] > gps.loc[40, "t_ns"]) & (t[new_gap] < gps.loc[42, "t_ns"]))
    assert st.loc[new_gap, "pos_d_m"].isna().all()
    near = np.abs(t - int(gps.loc[40, "t_ns"])) <= 600_000_000
    np.testing.assert_allclose(st.loc[near, ["pos_n_m", "pos_e_m"]].to_numpy(),
                               clean.loc[near, ["pos_n_m", "pos_e_m"]].to_numpy(), atol=0.05)
    # readings at the edge of a real envelope are not touched (2,000 °/s, 900 m/s)
    imu2 = log["imu"].assign(gyr_x_radps=34.9)
    res = preprocess_log(FlightLog.from_streams(log.meta, {"gps": log["gps"].assign(vel_d_mps=-900.0), "imu": imu2}))
    assert "implausible_values" not in res.diagnostics


@pytest.mark.parametrize("sec,message", [
    ({"vehicles": {"copter": {"controls": {"ail": {"channel": "rc_1_us", "min_us": 2000, "max_us": 1000}}}}},
     "preprocess.vehicles.copter.controls.ail: min_us 2000.0 must be below max_us 1000.0"),
    ({"flights": {"kd0aij-*": {"controls": {"ele": {"channel": "rc_2_us", "trim_us": 2500}}}}},
     "preprocess.flights.kd0aij-*.controls.ele: trim_us 2500.0 must lie in (1100.0, 1900.0)"),
    ({"vehicles": {"q": {"imu_mount": {"roll_deg": "x"}}}}, "preprocess.vehicles.q.imu_mount"),
])
def test_what_the_schema_cannot_check_is_one_error_naming_the_key_before_any_flight(sec, message, tmp_path, capsys):
    from pipeline.config import validate_section
    from pipeline.preprocess.state import check_preprocess_config

    try:
        full = validate_section("preprocess", sec)
    except ConfigError as exc:        # the schema itself refuses it: as good
        assert message in str(exc)
        return
    with pytest.raises(ConfigError) as err:
        check_preprocess_config(full)
    assert str(err.value) == message
    # the command line stops before any flight, naming the file
    cfg = tmp_path / "bad.yaml"
    import yaml
    cfg.write_text(yaml.safe_dump({"preprocess": sec}))
    (tmp_path / "IN").mkdir()
    assert main(["preprocess", str(tmp_path / "IN"), "-o", str(tmp_path / "OUT"), "--config", str(cfg)]) == 2
    err_lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert err_lines == [f"uavpipe preprocess: {cfg}: {message}"]
    assert not (tmp_path / "OUT").exists()



def test_a_stick_the_vehicle_has_not_is_null_and_passes_the_start_up_check():
    from pipeline.config import validate_section
    from pipeline.preprocess.state import check_preprocess_config

    sec = validate_section("preprocess", {"vehicles": {"wing": {"controls": {
        "ail": {"channel": "rc_1_us"}, "ele": {"channel": "rc_2_us"}, "thr": {"channel": "rc_3_us"}, "rud": None}}}})
    check_preprocess_config(sec)
    assert PreprocessConfig.from_config({"preprocess": sec}, vehicle="wing").controls["rud"] is None


def test_a_few_missing_measured_velocities_are_filled_not_the_axis_given_up(rng):
    # one damaged fix among 300 (its velocity NaN): the axis stays measured, that fix's
    # neighbourhood takes the differentiated position, and the notes say how many samples
    log, w = synthetic_flight(rng, gap=False)
    gps = log["gps"].copy()
    gps.loc[150, "vel_n_mps"] = np.nan
    res = preprocess_log(FlightLog.from_streams(log.meta, {"gps": gps, "attitude": log["attitude"]}))
    assert res.diagnostics["sources"]["velocity"] == "measured"
    assert any(n.startswith("measured velocity missing on ") for n in res.diagnostics["notes"])
    st = res.state
    t = st["t_ns"].to_numpy() * 1e-9
    mid = (t > 2) & (t < 58)
    assert np.isfinite(st["vel_n_mps"][mid]).all()
    np.testing.assert_allclose(st["vel_n_mps"][mid], -20 * w * np.sin(w * t[mid]), atol=0.1)


def test_a_height_spike_no_aircraft_could_fly_is_dropped_and_a_step_is_kept():
    from pipeline.preprocess.state import spikes

    t = ns(np.arange(0, 20, 0.05))                       # a 20 Hz baro: limit 1000 * 0.1 + 10 = 110 m
    h0 = 10.0 + 0.5 * np.sin(np.arange(len(t)) * 0.05)
    h = h0.copy()
    h[100], h[250:252] = 10_700.0, [-900.0, -850.0]      # one and two damaged records
    s = spikes(t, h)
    assert np.flatnonzero(s).tolist() == [100, 250, 251]
    step = np.where(np.arange(len(t)) < 200, 10.0, 400.0)  # a 390 m reset: a step, not a spike
    assert not spikes(t, step).any()
    assert not spikes(t, h0 + 105.0 * (np.arange(len(t)) == 300)).any()  # 105 m in 0.1 s: kept
    # through preprocessing: counted with the limits, and the calibrated height stays sane
    baro = pd.DataFrame({"t_ns": t, "alt_rel_m": h})
    res = preprocess_log(FlightLog.from_streams({"flight_id": "spk"}, {"baro": baro}))
    assert res.diagnostics["implausible_values"] == {"baro": {"alt_rel_m": 3}}


def test_a_second_sensor_instance_and_gps_fixes_left_out_are_counted_in_the_diagnostics(rng):
    log, _ = synthetic_flight(rng, gap=False)
    gps, imu = log["gps"].copy(), log["imu"].copy()
    gps.loc[[10, 11, 12], "fix_type"] = 2.0          # 2-D fixes: below the default minimum of 3
    gps.loc[20, ["lat_deg", "lon_deg"]] = np.nan      # a fix without coordinates
    imu2 = imu.iloc[::2].assign(instance=1)          # a second IMU with half the samples
    res = preprocess_log(FlightLog.from_streams(log.meta, {**{k: log[k] for k in ("attitude", "control")},
                                                           "gps": gps, "imu": pd.concat([imu, imu2])}))
    d = res.diagnostics
    assert d["instances"]["imu"] == {"used": 0, "rows_not_used": {"1": len(imu2)}}
    assert d["gps_fixes_dropped"] == {"no_position": 1, "low_fix": 3}
    assert f"gps: 3 of {len(gps)} fixes below fix type 3 not used (preprocess.bpm.gps_min_fix)" in d["notes"]
    clean = preprocess_log(FlightLog.from_streams(log.meta, {k: log[k] for k in ("attitude", "control", "gps", "imu")}))
    assert "instances" not in clean.diagnostics and "gps_fixes_dropped" not in clean.diagnostics


@pytest.mark.parametrize("text", ["{not json", "[1, 2]", None])
def test_a_damaged_or_missing_ingest_meta_json_is_the_flights_placeholder_naming_it(text, tmp_path):
    from pipeline.io.parquet import read_table_meta
    from pipeline.preprocess.run import run_preprocess

    d = tmp_path / "ingest" / "f1"
    d.mkdir(parents=True)
    meta = d / "meta.json"
    if text is not None:
        meta.write_text(text)
    out = {k: tmp_path / f"{k}.parquet" for k in ("state", "segments", "calibration")} | {"info": tmp_path / "i.json"}
    res = run_preprocess({"meta": str(meta)}, {k: str(v) for k, v in out.items()})
    assert res.status == "failed" and res.flight_id == "f1"
    reason = read_table_meta(out["state"])["error"]
    assert reason.startswith(f"cannot read {meta}: ") and "\n" not in reason
    assert ("FileNotFoundError" if text is None else "Error") in reason
