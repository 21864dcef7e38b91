"""BPM calibration (acceptance §3) on a simulated calibration flight with truth, plus the
GPS fallback and the no-barometer case.

The profile (generated here; seed 004 §6.3): ground, take-off to 2 m, hover, 4.5 m hover, a
cruise at 15 m (out of the 6 m rangefinder range), back to a 2 m hover, landing. The barometer
reads truth + 5 m + 0.01 m/s · t + N(0, 0.1 m); the rangefinder has N(0, 2 cm) noise, reads
h / (cos φ cos θ) when tilted, and gets injected tilted episodes (20°), out-of-range readings
and spikes.
"""

import numpy as np
import pandas as pd
import pytest

from pipeline.io.base import FlightLog
from pipeline.frames.rotations import euler_to_quat
from pipeline.preprocess.calibrate import BPMConfig, calibrate_baro, pressure_altitude
from pipeline.preprocess.state import preprocess_log

OFFSET, DRIFT = 5.0, 0.01


def _ramp(t, t0, dur, a, b):
    s = np.clip((t - t0) / dur, 0, 1)
    return a + (b - a) * (0.5 - 0.5 * np.cos(np.pi * s))


def height(t):
    h = np.full_like(t, 0.1)
    for t0, dur, a, b in ((5, 6, 0.1, 2.0), (35, 5, 2.0, 4.5), (65, 8, 4.5, 15.0),
                          (130, 8, 15.0, 2.0), (165, 5, 2.0, 0.1)):
        m = t >= t0
        h[m] = _ramp(t[m], t0, dur, a, b)
    return h


def calibration_flight(rng, baro_sigma=0.1):
    ns = lambda t: np.round(t * 1e9).astype(np.int64)  # noqa: E731
    tb = np.arange(0, 180, 1 / 25)
    baro = height(tb) + OFFSET + DRIFT * tb + rng.normal(scale=baro_sigma, size=len(tb))
    ta = np.arange(0, 180, 1 / 50)
    roll = np.radians(3) * np.sin(0.7 * ta)
    pitch = np.radians(2) * np.sin(0.45 * ta + 1)
    for t0 in (20, 50, 150):  # tilted episodes during the hovers
        roll[(ta >= t0) & (ta < t0 + 2)] = np.radians(20)
    q = euler_to_quat(roll, pitch, 0.3 + 0 * ta)
    tr = np.arange(0, 180, 1 / 10)
    r_i, p_i = np.interp(tr, ta, roll), np.interp(tr, ta, pitch)
    dist = height(tr) / (np.cos(r_i) * np.cos(p_i)) + rng.normal(scale=0.02, size=len(tr))
    dist[dist > 7.0] = 7.0  # beyond range the sensor saturates
    oor = rng.choice(len(tr), 40, replace=False)
    dist[oor] = rng.choice([0.05, 6.5, 9.9], size=40)  # injected out-of-range readings
    spikes = rng.choice(len(tr), 60, replace=False)
    dist[spikes] += rng.uniform(0.8, 3.0, size=60)  # injected spikes
    log = FlightLog.from_streams({"flight_id": "bpm-sim"}, {
        "baro": pd.DataFrame({"t_ns": ns(tb), "alt_rel_m": baro}),
        "attitude": pd.DataFrame({"t_ns": ns(ta), "q_w": q[:, 0], "q_x": q[:, 1], "q_y": q[:, 2], "q_z": q[:, 3]}),
        "rangefinder": pd.DataFrame({"t_ns": ns(tr), "dist_m": dist, "orientation": 25.0}),
    })
    return log, tr, oor, spikes


def test_bpm_calibration_recovers_offset_and_drift(rng):
    log, tr, oor, spikes = calibration_flight(rng)
    res = preprocess_log(log)
    state, _, cal = res.tables
    t = state["t_ns"].to_numpy() * 1e-9
    err = state["alt_cal_m"].to_numpy() - height(t)
    assert np.isfinite(err).all()
    assert np.max(np.abs(err)) < 0.2, np.max(np.abs(err))
    info = res.diagnostics["calibration"]
    assert info["method"] == "rangefinder" and len(info["regions"]) >= 3
    # the gating did the rejecting: tilted, out-of-range and spiky samples are never used
    used = cal[cal["used"]]
    tilted = np.zeros(len(tr), bool)
    for t0 in (20, 50, 150):
        tilted |= (tr >= t0 + 0.1) & (tr < t0 + 1.9)
    bad_ns = set(np.round(tr[np.r_[oor, spikes, np.flatnonzero(tilted)]] * 1e9).astype(np.int64))
    assert not bad_ns & set(used["t_ns"].tolist())
    assert set(cal["reason"]) >= {"ok", "range", "tilt", "spike"}
    # offsets are h_ref - h_baro = -(5 + 0.01 t) within noise
    resid = used["offset_m"] + OFFSET + DRIFT * used["t_ns"] * 1e-9
    assert abs(resid.median()) < 0.05


def test_without_gating_the_spikes_would_hurt(rng):
    # the same data with the spike/tilt gates disabled calibrates worse: the gates matter
    log, *_ = calibration_flight(rng)
    cfg = {"bpm": {"spike_m": 100.0, "max_tilt_deg": 90.0, "outlier_k": 1e9, "max_rate_mps": 1e9}}
    res = preprocess_log(log, cfg)
    state, _, _ = res.tables
    t = state["t_ns"].to_numpy() * 1e-9
    assert np.max(np.abs(state["alt_cal_m"].to_numpy() - height(t))) > 0.2


def test_piecewise_constant_thesis_scheme(rng):
    log, *_ = calibration_flight(rng, baro_sigma=0.0)
    res = preprocess_log(log, {"bpm": {"drift": False}})
    state, _, _ = res.tables
    t = state["t_ns"].to_numpy() * 1e-9
    err = np.abs(state["alt_cal_m"].to_numpy() - height(t))
    # held offsets cannot follow a 0.01 m/s drift over the 60 s cruise
    assert np.max(err) > 0.2
    assert np.median(err) < 0.2


def test_the_gps_fallback_fits_one_offset_over_the_flight_not_ten_second_pieces():
    # the documented scheme: GPS altitude is continuous but noisy, so one region; split like the
    # rangefinder (offset steps of 0.4 m, 10 s pieces) it followed the GPS noise: 12 pieces,
    # 0.115 m rms and 1.6 m/s of offset steps here, against 0.014 m with one region
    from pipeline.preprocess.calibrate import calibrate_baro

    t = np.arange(0, 120, 0.04)
    tn = (t * 1e9).astype(np.int64)
    h = 2 + 1.5 * np.sin(2 * np.pi * t / 40)
    gt = tn[::5]
    gu = h[::5] + np.random.default_rng(0).normal(0, 1.0, len(gt))
    cal = calibrate_baro(tn, h + 5.0, gps_t_ns=gt, gps_up_m=gu)
    assert cal.method == "gps" and len(cal.regions) == 1
    e = cal.alt_cal_m - h
    assert np.sqrt(np.mean(e ** 2)) < 0.05 and np.max(np.abs(np.diff(e))) / 0.04 < 0.1


def test_gps_fallback_and_none():
    rng = np.random.default_rng(3)
    n = 1000
    t = np.arange(n) * 0.1
    h = 10 + 5 * np.sin(0.05 * t)
    lat0, lon0, h0 = 47.0, 8.0, 400.0
    ns = np.round(t * 1e9).astype(np.int64)
    gps = pd.DataFrame({"t_ns": ns[::2], "lat_deg": lat0 + 1e-5 * np.arange(n // 2) * 0,
                        "lon_deg": lon0 + 0 * t[::2], "alt_wgs84_m": h0 + h[::2] + rng.normal(scale=1.0, size=n // 2),
                        "fix_type": 3.0})
    baro = pd.DataFrame({"t_ns": ns, "alt_rel_m": h - 20.0 + rng.normal(scale=0.1, size=n)})
    meta = {"flight_id": "g", "ned_origin": {"lat_deg": lat0, "lon_deg": lon0, "alt_wgs84_m": h0}}
    res = preprocess_log(FlightLog.from_streams(meta, {"gps": gps, "baro": baro}))
    state, _, cal = res.tables
    assert res.diagnostics["calibration"]["method"] == "gps"
    assert set(cal["method"]) == {"gps"}
    tt = state["t_ns"].to_numpy() * 1e-9
    ok = np.isfinite(state["alt_cal_m"])
    assert np.max(np.abs(state["alt_cal_m"][ok] - (10 + 5 * np.sin(0.05 * tt[ok])))) < 0.5
    # a rangefinder with no usable samples also falls back to GPS
    rf = pd.DataFrame({"t_ns": ns, "dist_m": 12.0})
    res = preprocess_log(FlightLog.from_streams(meta, {"gps": gps, "baro": baro, "rangefinder": rf}))
    state, _, _ = res.tables
    assert res.diagnostics["calibration"]["method"] == "gps"
    # no barometer: method none, NaN
    res = preprocess_log(FlightLog.from_streams(meta, {"gps": gps}))
    state, _, cal = res.tables
    assert res.diagnostics["calibration"]["method"] == "none"
    assert state["alt_cal_m"].isna().all() and len(cal) == 0
    # barometer, no reference at all: reported as uncalibrated
    res = preprocess_log(FlightLog.from_streams(meta, {"baro": baro}))
    state, _, _ = res.tables
    assert res.diagnostics["calibration"]["method"] == "uncalibrated"


def test_pressure_altitude_formula():
    assert pressure_altitude(101325.0) == pytest.approx(0.0)
    # ISA: 89 874.6 Pa at 1000 m
    assert pressure_altitude(89874.6) == pytest.approx(1000.0, abs=1.0)


def test_calibrate_baro_direct_constant_offset():
    t = np.arange(0, 60, 0.04)
    grid = np.round(t * 1e9).astype(np.int64)
    h = 1.0 + 0.5 * np.sin(0.2 * t)
    baro = h - 3.0
    rf = pd.DataFrame({"t_ns": grid[::4], "dist_m": h[::4], "valid": pd.array([True] * len(grid[::4]))})
    c = calibrate_baro(grid, baro, rangefinder=rf, cfg=BPMConfig(drift=False))
    assert c.method == "rangefinder"
    np.testing.assert_allclose(c.alt_cal_m, h, atol=1e-9)
    assert "no attitude" in " ".join(c.notes)


def test_gps_fixes_off_the_globe_are_dropped_and_counted_not_converted():
    # a reader's unit slip (degE7 as degrees) or a corrupt record gave positions 6000 km away
    n = 200
    t = np.arange(n) * 0.2
    ns = np.round(t * 1e9).astype(np.int64)
    lat = 47.0 + 1e-6 * np.arange(n)
    lat[[50, 120]] = 470_000_123.0
    gps = pd.DataFrame({"t_ns": ns, "lat_deg": lat, "lon_deg": 8.0 + 0 * t, "alt_wgs84_m": 400.0 + 0 * t,
                        "fix_type": 3.0})
    meta = {"flight_id": "g", "ned_origin": {"lat_deg": 47.0, "lon_deg": 8.0, "alt_wgs84_m": 400.0}}
    res = preprocess_log(FlightLog.from_streams(meta, {"gps": gps}))
    state = res.tables[0]
    assert np.nanmax(np.abs(state["pos_n_m"])) < 25.0   # the track spans 22 m north
    assert any("2 of 200 fixes dropped: latitude/longitude out of range" in n_ for n_ in res.diagnostics["notes"])


def test_a_zero_quaternion_is_a_gap_not_a_nan_row_marked_good():
    # consumers keep the ~gap rows (align demos): 15 NaN attitude rows had gap False
    from pipeline.io.schema import new_meta

    t = np.arange(0, 10, 0.1)
    q = euler_to_quat(0.1, 0.2, np.linspace(0, 3, len(t)))
    q[40:45] = 0.0
    att = pd.DataFrame({"t_ns": (t * 1e9).astype(np.int64), "instance": 0, "src": "ATT",
                        **{f"q_{c}": q[:, j] for j, c in enumerate("wxyz")}})
    s = preprocess_log(FlightLog.from_streams(new_meta(flight_id="x"), {"attitude": att})).state
    nan = s["q_w"].isna()
    assert nan.sum() > 0 and s["gap"][nan].all()
    assert not s["gap"][~nan].any()
