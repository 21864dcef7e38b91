"""Preprocessing of every real log in ../shared/realdata (acceptance §4 and the real-data parts
of §3): state without errors, FlightCoach segments = `mans`, Husky IMU mount, motor_failure BPM."""

import numpy as np
import pytest

from helpers import realdata_file
from pipeline.config import load_config
from pipeline.io import schema
from pipeline.io.registry import read_log
from pipeline.preprocess.mount import apply_mount
from pipeline.preprocess.resample import repair_timestamps, resample
from pipeline.preprocess.state import PreprocessConfig, preprocess_log

# (file, vehicle as in datasets/flights.tsv)
REAL_LOGS = [
    ("ap_copter313_austin_4flights/2014-10-18_20-04-24.bin", "copter-pixhawk"),
    ("ap_copter313_austin_4flights/2014-10-18_20-44-05.bin", "copter-pixhawk"),
    ("ap_copter_forum_crash_pool/log_0036_mechanical_failure.bin", "copter"),
    ("ap_plane_flightcoach_box/pilot_0004.BIN", "f3a-plane"),
    ("pymavlink_test_bin/test.BIN", "plane-bench"),
    ("tlog_phoenix_ubc_quad/phoenix_mission1_2018-09-17_16-44-06.tlog", "copter"),
    ("ulg_px4_flight_review_fixtures/ekf_failure.ulg", "px4-quad"),
    ("ulg_px4_flight_review_fixtures/motor_failure.ulg", "px4-hexa"),
    ("ros1_husky_imu_gps/test1.bag", "husky"),
    ("ros2mcap_husky_imu_gps", "husky"),
    ("flightcoach_f3a_json/manual_F3A_P23_22_02_18_00000036.json", "f3a-plane"),
    ("flightcoach_f3a_json/manual_F3A_P23_22_05_31_00000350.json", "f3a-plane"),
    ("flightcoach_f3a_json/manual_F3A_F23_22_02_18_00000035.json", "f3a-plane"),
    ("flightcoach_f3a_json/UK_England_Bristol_AMARC2002_F3A_P21_21_08_12_00000026.json", "f3a-plane"),
    ("kd0aij_f3a_csv/P21.csv", "f3a-plane"),
    ("kd0aij_f3a_csv/141.csv", "f3a-plane"),
]

CFG = load_config()
_cache: dict = {}


@pytest.fixture(scope="module", autouse=True)
def _free_cache():
    yield
    _cache.clear()


def _read(rel):
    # logs are read once per module (the Husky and motor_failure tests reuse them); all of them
    # together hold well under 1 GB
    if rel not in _cache:
        _cache[rel] = read_log(realdata_file(rel))
    return _cache[rel]


@pytest.mark.realdata
@pytest.mark.slow  # preprocesses every real log (the fast lane keeps the synthetic preprocess tests)
@pytest.mark.parametrize("rel, vehicle", REAL_LOGS, ids=[r.split("/")[-1] for r, _ in REAL_LOGS])
def test_every_real_log_gives_a_state_table(rel, vehicle):
    log = _read(rel)
    res = preprocess_log(log, CFG, vehicle=vehicle)
    state, seg, cal = res.tables
    assert list(state.columns) == [c.name for c in schema.STATE]
    assert len(state) > 0
    assert np.all(np.diff(state["t_ns"].to_numpy()) > 0)
    d = res.diagnostics
    # where the log has a position or attitude source, the state carries it
    assert d["sources"]["position"] or d["sources"]["attitude"]
    if d["sources"]["attitude"]:
        assert state["q_w"].notna().mean() > 0.5
    if rel.endswith(".json"):
        # each FlightCoach flight: one segment per `mans` entry (the reader's labels rows)
        assert len(log["labels"]) > 0
        assert len(seg) == len(log["labels"])
        assert seg["label"].tolist() == log["labels"].sort_values("t_start_ns", kind="stable")["label"].tolist()
        assert d["sources"]["body_rates"] == "differentiated attitude"
    meth = d["calibration"]["method"]
    has_baro = log["baro"]["alt_rel_m"].notna().any() or log["baro"]["press_Pa"].notna().any()
    if not has_baro:
        assert meth == "none"
    elif "motor_failure" not in rel:
        # of these logs only motor_failure.ulg has a usable rangefinder (README): GPS fallback
        assert meth in ("gps", "uncalibrated")
        if log["gps"]["lat_deg"].notna().sum() > 20:
            assert meth == "gps"


@pytest.mark.realdata
def test_motor_failure_bpm_calibration():
    log = _read("ulg_px4_flight_review_fixtures/motor_failure.ulg")
    res = preprocess_log(log, CFG, vehicle="px4-hexa")
    state, _, cal = res.tables
    assert res.diagnostics["calibration"]["method"] == "rangefinder"
    used_t = cal.loc[cal["used"], "t_ns"].to_numpy() * 1e-9
    assert len(used_t) >= 20 and used_t.min() >= 33.6 and used_t.max() <= 43.91
    # touchdown: the first reading within 5 cm of the resting value (median of the last 2 s)
    rf = log["rangefinder"]
    t_rf = rf["t_ns"].to_numpy() * 1e-9
    d = rf["dist_m"].to_numpy()
    rest = np.median(d[t_rf > t_rf[-1] - 2.0])
    k = np.flatnonzero((d <= rest + 0.05) & (t_rf > 30))[0]
    t = state["t_ns"].to_numpy() * 1e-9
    alt_td = np.interp(t_rf[k], t, state["alt_cal_m"].to_numpy())
    assert abs(alt_td - d[k]) < 0.3, (t_rf[k], alt_td, d[k])


@pytest.mark.realdata
@pytest.mark.parametrize("rel", ["ros1_husky_imu_gps/test1.bag", "ros2mcap_husky_imu_gps"])
def test_husky_imu_mount(rel):
    log = _read(rel)
    cfg = PreprocessConfig.from_config(CFG, vehicle="husky")
    imu = apply_mount(repair_timestamps(log["imu"])[0], cfg.imu_mount)
    odo, ok = resample(repair_timestamps(log["odometry"])[0], imu["t_ns"].to_numpy(),
                       {"vel_x_mps": "linear", "vel_y_mps": "linear", "vel_z_mps": "linear",
                        "yaw_rate_radps": "linear"})
    speed = np.linalg.norm(odo[["vel_x_mps", "vel_y_mps", "vel_z_mps"]].fillna(0).to_numpy(), axis=1)
    wz = odo["yaw_rate_radps"].to_numpy()
    gyr = np.linalg.norm(imu[["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].to_numpy(), axis=1)
    rest = ok & (speed < 0.01) & (np.abs(wz) < 0.01) & (gyr < 0.01)
    assert rest.sum() > 30
    assert imu["acc_z_mps2"].to_numpy()[rest].mean() == pytest.approx(-9.80, abs=0.05)
    good = ok & np.isfinite(wz)
    r = np.corrcoef(imu["gyr_z_radps"].to_numpy()[good], -wz[good])[0, 1]
    assert r >= 0.8
    # and through the whole preprocessing: the state's r_radps (FRD, from the mounted gyro)
    res = preprocess_log(log, CFG, vehicle="husky")
    state, _, _ = res.tables
    o2, ok2 = resample(repair_timestamps(log["odometry"])[0], state["t_ns"].to_numpy(), {"yaw_rate_radps": "linear"})
    g2 = ok2 & state["r_radps"].notna().to_numpy()
    assert np.corrcoef(state["r_radps"][g2], -o2["yaw_rate_radps"][g2])[0, 1] >= 0.8
    # the 2.5 Hz GPS differentiated over 10 of its samples (4 s), not the 2.5 of a 1 s window:
    # a robot at walking pace, |acc| median 0.19 m/s² (1.45 before), |v_d| > 0.5 m/s on 9 % of
    # samples (27 %)
    assert res.diagnostics["derivative_window_s"] == pytest.approx(4.0, rel=0.01)
    assert res.diagnostics["ground_vehicle"] is True   # preprocess.vehicles.husky.ground: the pages' cue
    acc = np.linalg.norm(state[["acc_n_mps2", "acc_e_mps2", "acc_d_mps2"]].to_numpy(), axis=1)
    assert np.nanmedian(acc) < 0.3 and (state["vel_d_mps"].abs() > 0.5).mean() < 0.12


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["manual_F3A_P23_22_02_18_00000036.json", "manual_F3A_P23_22_05_31_00000350.json"])
def test_a_flightcoach_box_rotation_reaches_the_state_metadata(tmp_path, name):
    import json

    from pipeline.io.parquet import read_table_meta
    from pipeline.preprocess.state import write_outputs

    rel = f"flightcoach_f3a_json/{name}"
    log = _read(rel)
    expected = json.loads(realdata_file(rel).read_text())["parameters"]["rotation"]
    res = preprocess_log(log, CFG, vehicle="f3a-plane")
    write_outputs(res, state_path=tmp_path / "state.parquet", segments_path=tmp_path / "seg.parquet")
    assert read_table_meta(tmp_path / "state.parquet")["box_rotation_rad"] == pytest.approx(expected, abs=0)


@pytest.mark.realdata
def test_the_ekf_height_reset_of_the_px4_ekf_failure_log_is_a_gap_not_an_11_m_step():
    """PX4's EKF resets z by -10.9 m at boot 118.84 s (and vz at 94.25/119.04 s): read as motion,
    that was an 11 m altitude step in one grid period and a 19.7 m/s^2 acceleration spike with
    ``gap`` False."""
    res = preprocess_log(_read("ulg_px4_flight_review_fixtures/ekf_failure.ulg"), CFG, vehicle="px4-quad")
    st = res.state
    assert res.diagnostics["sources"]["position"] == "local_position"
    note = [n for n in res.diagnostics["notes"] if "estimator reset" in n]
    assert note and note[0].startswith("local_position: 3 estimator reset(s)")
    t = st["t_ns"].to_numpy() * 1e-9
    ok = ~st["gap"].to_numpy()
    assert not ok[(t > 71.9) & (t < 72.0)].any()  # the z reset's grid period
    step = np.abs(np.diff(st["pos_d_m"].to_numpy()))[ok[1:] & ok[:-1]]
    assert step.max() < 1.0  # 13 m/s of descent at most over 0.04 s; the reset was 10.9 m
    acc = st[["acc_n_mps2", "acc_e_mps2", "acc_d_mps2"]].to_numpy()[ok]
    assert np.isfinite(acc).all() and np.abs(acc[:, 2]).max() < 12.0
