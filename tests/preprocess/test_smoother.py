"""The GPS track smoother: filterpy's Kalman filter and RTS smoother as the oracle, and what it
does to a noisy GPS flight in preprocessing."""

from __future__ import annotations

import numpy as np
import pandas as pd
from filterpy.kalman import KalmanFilter

from pipeline.io.base import FlightLog
from pipeline.preprocess.smoother import GpsSmoother, smooth_track
from pipeline.preprocess.state import preprocess_log
from helpers_preprocess import ns, synthetic_flight


def _filterpy(t_s, zp, sp, zv, sv, q, x0, P0, smooth=True):
    """The same white-jerk CA model stepped by filterpy, one event at a time."""
    kf = KalmanFilter(dim_x=3, dim_z=1)
    kf.x, kf.P = x0.copy(), P0.copy()
    xs, Ps, Fs, Qs = [], [], [], []
    for k in range(len(t_s)):
        dt = t_s[k] - t_s[k - 1] if k else 0.0
        F = np.array([[1, dt, dt * dt / 2], [0, 1, dt], [0, 0, 1]])
        Q = q * np.array([[dt ** 5 / 20, dt ** 4 / 8, dt ** 3 / 6], [dt ** 4 / 8, dt ** 3 / 3, dt ** 2 / 2],
                          [dt ** 3 / 6, dt ** 2 / 2, dt]])
        if k:
            kf.predict(F=F, Q=Q)
        # the first event is the first fix, already the prior (x0, P0): not applied twice
        for j, (z, r) in enumerate(((zp[k], sp[k] ** 2), (zv[k], sv ** 2)) if k else ()):
            if np.isfinite(z):
                H = np.zeros((1, 3))
                H[0, j] = 1.0
                kf.update(np.array([z]), R=np.array([[r]]), H=H)
        xs.append(kf.x.copy())
        Ps.append(kf.P.copy())
        Fs.append(F)
        Qs.append(Q)
    xs, Ps = np.array(xs), np.array(Ps)
    if not smooth:
        return xs
    # filterpy's rts_smoother steps from k to k+1 with Fs[k + 1], Qs[k + 1]: the predict steps as made
    xs_s, _, _, _ = kf.rts_smoother(xs, Ps, Fs=np.array(Fs), Qs=np.array(Qs))
    return xs_s


def test_the_smoother_equals_filterpys_kalman_filter_and_rts_pass_with_missing_measurements(rng):
    # fixes at irregular times (some without velocity) merged with grid times that carry none
    t_fix = np.cumsum(rng.uniform(0.08, 0.12, 60))
    t_grid = np.arange(t_fix[0], t_fix[-1], 0.04)
    p = 3.0 * np.sin(0.7 * t_fix) + 0.5 * t_fix
    pos = np.c_[p, -p, 0.2 * p] + rng.normal(0, 0.3, (60, 3))
    vel = np.c_[2.1 * np.cos(0.7 * t_fix) + 0.5, -(2.1 * np.cos(0.7 * t_fix) + 0.5), np.full(60, np.nan)]
    vel[rng.random(60) < 0.3, :2] = np.nan
    sig = np.c_[np.full(60, 0.3), np.full(60, 0.3), rng.uniform(0.4, 0.6, 60)]
    cfg = GpsSmoother(jerk_psd=2.0, sigma_vel_mps=0.05)
    for causal in (False, True):
        got = smooth_track(ns(t_fix), pos, vel, sig, ns(t_grid), cfg, max_gap_ns=1e9, causal=causal)
        t_all = np.union1d(ns(t_fix), ns(t_grid))
        i_fix, i_grid = np.searchsorted(t_all, ns(t_fix)), np.searchsorted(t_all, ns(t_grid))
        t_s = (t_all - t_all[0]) * 1e-9
        for j in range(3):
            zp, zv, sp = (np.full(len(t_all), np.nan) for _ in range(3))
            zp[i_fix], zv[i_fix], sp[i_fix] = pos[:, j], vel[:, j], sig[:, j]
            v0 = vel[0, j] if np.isfinite(vel[0, j]) else 0.0
            P0 = np.diag([sig[0, j] ** 2, 0.05 ** 2 if np.isfinite(vel[0, j]) else 1e4, 1e2])
            ref = _filterpy(t_s, zp, sp, zv, 0.05, 2.0, np.array([pos[0, j], v0, 0.0]), P0, smooth=not causal)
            np.testing.assert_allclose(got[:, j], ref[i_grid, 0], rtol=0, atol=1e-9)


def test_fixes_further_apart_than_the_gap_limit_are_smoothed_as_separate_runs_with_nan_between():
    t = np.r_[np.arange(0, 10, 0.1), np.arange(20, 30, 0.1)]
    pos = np.c_[t, 2 * t, np.zeros_like(t)]
    vel = np.c_[np.ones_like(t), 2 * np.ones_like(t), np.zeros_like(t)]
    grid = np.arange(0, 30, 0.04)
    out = smooth_track(ns(t), pos, vel, np.full((len(t), 3), 0.3), ns(grid), GpsSmoother(), max_gap_ns=0.3e9)
    gap = ((grid > 9.9 + 1e-9) & (grid < 20 - 1e-9)) | (grid > 29.9 + 1e-9)   # and after the last fix
    assert np.isnan(out[gap]).all() and np.isfinite(out[~gap]).all()
    # noise-free constant velocity: the smoother reproduces the line (no pull across the gap)
    np.testing.assert_allclose(out[~gap, 0], grid[~gap], atol=1e-6)
    np.testing.assert_allclose(out[~gap, 1], 2 * grid[~gap], atol=1e-6)


def test_a_noisy_gps_flight_gets_positions_within_a_fifth_of_the_fix_noise(rng):
    # the 20 m circle at 5 Hz with 0.5 m of horizontal and 1 m of vertical fix noise, measured
    # velocity exact to 0.05 m/s: the smoothed track is far closer to the truth than the fixes
    log, w = synthetic_flight(rng, gap=False)
    gps = log["gps"].copy()
    n = len(gps)
    gps["lat_deg"] += rng.normal(0.0, 0.5, n) / 111_200.0
    gps["alt_wgs84_m"] += rng.normal(0.0, 1.0, n)
    gps["vel_n_mps"] += rng.normal(0.0, 0.05, n)
    gps["hacc_m"], gps["vacc_m"] = 0.5, 1.0
    streams = {"attitude": log["attitude"], "imu": log["imu"], "gps": gps}
    t = None
    rms = {}
    for on in (True, False):
        res = preprocess_log(FlightLog.from_streams(log.meta, streams), {"gps_smoother": {"enabled": on}})
        st = res.state
        t = st["t_ns"].to_numpy() * 1e-9
        mid = (t > 2) & (t < 58)
        rms[on] = (np.sqrt(np.mean((st["pos_n_m"][mid] - 20 * np.cos(w * t[mid])) ** 2)),
                   np.sqrt(np.mean((st["pos_d_m"][mid] + 10.0) ** 2)))
        assert any("gps positions smoothed" in x for x in res.diagnostics["notes"]) is on
    assert rms[False][0] > 0.3 and rms[False][1] > 0.6          # the interpolated fixes
    assert rms[True][0] < 0.1 and rms[True][1] < 0.2            # fused with the velocity


def test_the_first_fix_is_the_prior_once_and_an_axis_without_fixes_is_nan():
    from pipeline.preprocess.smoother import _rts_axis

    # two fixes 1 ms apart, 0 and 1 m, equal noise, no process noise to speak of: the filtered
    # second state is their mean (the first fix weighted once, not twice: it read 0.338)
    x = _rts_axis(np.array([0.0, 1e-3]), np.array([0.0, 1.0]), np.ones(2), np.full(2, np.nan), 0.1,
                  np.full(2, np.nan), np.ones(2), 1e-3, 0.3, 1e-9, False)
    assert abs(x[1, 0] - 1.01 / 2.01) < 1e-6     # prior 1 + the unknown velocity over 1 ms (1e4 * 1e-6)
    # no finite position on an axis: NaN there, not zeros
    t = np.arange(0, 5, 0.1)
    pos = np.c_[t, t, np.full_like(t, np.nan)]
    out = smooth_track(ns(t), pos, np.full((len(t), 3), np.nan), np.ones((len(t), 3)), ns(np.arange(0, 4.9, 0.04)),
                       GpsSmoother(), max_gap_ns=1e9)
    assert np.isnan(out[:, 2]).all() and np.isfinite(out[:, :2]).all()


def test_the_kernels_compiled_white_jerk_q_equals_the_one_the_estimators_use():
    from pipeline.estimate.models import white_jerk_q
    from pipeline.preprocess.smoother import white_jerk_q1
    for dt, q in [(0.2, 10.0), (0.013, 3.0), (1.7, 0.5)]:
        np.testing.assert_allclose(white_jerk_q1(dt, q), white_jerk_q(dt, q, 1), rtol=1e-14)


def _filterpy_acc(t_s, zp, sp, za, sa, q, qb, x0, P0):
    """The four-state model (CA + accelerometer bias) with position and acceleration
    measurements, stepped and smoothed by filterpy."""
    kf = KalmanFilter(dim_x=4, dim_z=1)
    kf.x, kf.P = x0.copy(), P0.copy()
    xs, Ps, Fs, Qs = [], [], [], []
    for k in range(len(t_s)):
        dt = t_s[k] - t_s[k - 1] if k else 0.0
        F = np.eye(4)
        F[:3, :3] = [[1, dt, dt * dt / 2], [0, 1, dt], [0, 0, 1]]
        Q = np.zeros((4, 4))
        Q[:3, :3] = q * np.array([[dt ** 5 / 20, dt ** 4 / 8, dt ** 3 / 6], [dt ** 4 / 8, dt ** 3 / 3, dt ** 2 / 2],
                                  [dt ** 3 / 6, dt ** 2 / 2, dt]])
        Q[3, 3] = qb * dt
        if k:
            kf.predict(F=F, Q=Q)
        for z, r, h in ((zp[k], sp[k] ** 2, [1, 0, 0, 0]) if k else (np.nan, 1, 0), (za[k], sa[k] ** 2, [0, 0, 1, 1])):
            if np.isfinite(z):
                kf.update(np.array([z]), R=np.array([[r]]), H=np.array([h], dtype=float))
        xs.append(kf.x.copy())
        Ps.append(kf.P.copy())
        Fs.append(F)
        Qs.append(Q)
    xs_s, _, _, _ = kf.rts_smoother(np.array(xs), np.array(Ps), Fs=np.array(Fs), Qs=np.array(Qs))
    return xs_s


def test_the_accelerometer_update_with_its_bias_state_equals_filterpys_four_state_smoother(rng):
    t_fix = np.cumsum(rng.uniform(0.08, 0.12, 40))
    t_grid = np.arange(t_fix[0], t_fix[-1], 0.04)
    pos = np.c_[np.sin(t_fix), 0.5 * t_fix, np.zeros(40)] + rng.normal(0, 0.3, (40, 3))
    acc = np.c_[-np.sin(t_grid), np.zeros_like(t_grid), np.zeros_like(t_grid)] + 0.05 + rng.normal(0, 0.1, (len(t_grid), 3))
    acc[rng.random(len(t_grid)) < 0.2] = np.nan                      # grid rows without an IMU value
    sig_acc = rng.uniform(0.3, 0.8, (len(t_grid), 3))                 # the per-row sigma
    cfg = GpsSmoother(jerk_psd=3.0, acc_bias_psd=1e-3, acc_bias_sigma_mps2=0.3)
    got = smooth_track(ns(t_fix), pos, np.full((40, 3), np.nan), np.full((40, 3), 0.3), ns(t_grid), cfg,
                       max_gap_ns=1e9, acc=acc, sigma_acc=sig_acc, full=True)
    t_all = np.union1d(ns(t_fix), ns(t_grid))
    i_fix, i_grid = np.searchsorted(t_all, ns(t_fix)), np.searchsorted(t_all, ns(t_grid))
    t_s = (t_all - t_all[0]) * 1e-9
    for j in range(3):
        zp, za, sp, sa = (np.full(len(t_all), np.nan) for _ in range(4))
        zp[i_fix], sp[i_fix] = pos[:, j], 0.3
        za[i_grid], sa[i_grid] = acc[:, j], sig_acc[:, j]
        ref = _filterpy_acc(t_s, zp, sp, za, sa, 3.0, 1e-3, np.array([pos[0, j], 0.0, 0.0, 0.0]),
                            np.diag([0.09, 1e4, 1e2, 0.09]))
        np.testing.assert_allclose(got[:, j, :], ref[i_grid, :3], rtol=0, atol=1e-7)


def _level_circle_flight(rng, imu_on_log: bool):
    """GPS fixes without velocity (10 Hz, 0.3 m) on a 15 m circle at 0.4 rad/s, and a level,
    nose-forward vehicle whose 100 Hz accelerometer reads the centripetal acceleration in the
    body frame with a bias of 0.05 and noise of 0.05 m/s² (f = Rᵀ(a − g e₃))."""
    from pipeline.frames.geodesy import ned_to_geodetic
    from pipeline.frames.rotations import euler_to_quat, quat_rotate_inverse

    w, r = 0.4, 15.0
    tg = np.arange(0, 60, 0.1)
    n, e = r * np.cos(w * tg) + rng.normal(0, 0.3, len(tg)), r * np.sin(w * tg) + rng.normal(0, 0.3, len(tg))
    lat, lon, h = ned_to_geodetic(n, e, -10 + rng.normal(0, 0.3, len(tg)), 46.5, 6.6, 500.0)
    gps = pd.DataFrame({"t_ns": ns(tg), "lat_deg": lat, "lon_deg": lon, "alt_wgs84_m": h, "fix_type": 3.0,
                        "hacc_m": 0.3, "vacc_m": 0.3})
    ti = np.arange(0, 60, 0.01)
    q = euler_to_quat(0 * ti, 0 * ti, w * ti + np.pi / 2)
    a = np.c_[-r * w * w * np.cos(w * ti), -r * w * w * np.sin(w * ti), 0 * ti]
    f = quat_rotate_inverse(q, a - [0.0, 0.0, 9.80665]) + 0.05 + rng.normal(0, 0.05, (len(ti), 3))
    att = pd.DataFrame({"t_ns": ns(ti), **dict(zip(["q_w", "q_x", "q_y", "q_z"], q.T))})
    streams = {"gps": gps, "attitude": att}
    if imu_on_log:
        streams["imu"] = pd.DataFrame({"t_ns": ns(ti), "acc_x_mps2": f[:, 0], "acc_y_mps2": f[:, 1],
                                       "acc_z_mps2": f[:, 2], "gyr_x_radps": 0.0, "gyr_y_radps": 0.0,
                                       "gyr_z_radps": w})
    meta = {"flight_id": "circle", "ned_origin": {"lat_deg": 46.5, "lon_deg": 6.6, "alt_wgs84_m": 500.0}}
    return FlightLog.from_streams(meta, streams), w, r


def test_a_gps_flight_with_an_accelerometer_gets_its_velocity_and_acceleration_from_both(rng):
    log, w, r = _level_circle_flight(rng, True)
    rms = {}
    for imu in (True, False):
        res = preprocess_log(log, {"gps_smoother": {"imu": imu}, "vertical_from_baro": False})
        st = res.state
        t = st["t_ns"].to_numpy() * 1e-9
        mid = (t > 3) & (t < 57)
        ve = st["vel_n_mps"].to_numpy()[mid] + r * w * np.sin(w * t[mid])
        ae = st["acc_n_mps2"].to_numpy()[mid] + r * w * w * np.cos(w * t[mid])
        rms[imu] = (np.sqrt(np.mean(ve ** 2)), np.sqrt(np.mean(ae ** 2)))
        fused = res.diagnostics["sources"]["velocity"] == "GPS + accelerometer smoother"
        assert fused is imu
        assert any("and the accelerometer on" in x for x in res.diagnostics["notes"]) is imu
    # the fixes alone: a second difference of 0.3 m noise; with the accelerometer: measured
    assert rms[False][0] > 0.1 and rms[False][1] > 0.2
    assert rms[True][0] < 0.5 * rms[False][0] and rms[True][1] < 0.1


def test_an_accelerometer_that_disagrees_with_the_attitude_is_not_fused_and_the_notes_say_why(rng):
    log, _, _ = _level_circle_flight(rng, True)
    imu = log["imu"].copy()
    # a mount the config does not know: x and z swapped, so g lies along the body x axis
    imu["acc_x_mps2"], imu["acc_z_mps2"] = imu["acc_z_mps2"].to_numpy(), imu["acc_x_mps2"].to_numpy()
    bad = FlightLog.from_streams(log.meta, {"gps": log["gps"], "attitude": log["attitude"], "imu": imu})
    res = preprocess_log(bad, {"vertical_from_baro": False})
    assert res.diagnostics["sources"]["velocity"] == "differentiated position"
    assert any(x.startswith("accelerometer not fused into the GPS track") for x in res.diagnostics["notes"])


def test_velocity_source_differentiate_still_differentiates_the_fused_track(rng):
    log, _, _ = _level_circle_flight(rng, True)
    res = preprocess_log(log, {"velocity_source": "differentiate", "vertical_from_baro": False})
    assert res.diagnostics["sources"]["velocity"] == "differentiated position"
    # the positions are still the accelerometer-aided track
    assert any("and the accelerometer on" in x for x in res.diagnostics["notes"])
