"""The vectorised EKF against filterpy's KalmanFilter, its consistency (NEES) on its own
white-jerk model with the radar, stacked and missing measurements, and the q tuning."""

from __future__ import annotations

import time

import numpy as np
import pytest

from pipeline.estimate.base import (ConstantAcceleration, GaussianState, LinearMeasurement, LinearTransition,
                                    position_measurement)
from pipeline.estimate.ekf import ExtendedKalmanFilter, run_filter
from pipeline.estimate.metrics import chi2_band, fraction_in_band
from pipeline.estimate.models import RadarModel, ca_transition, initial_cov, white_jerk_q
from pipeline.estimate.montecarlo import measure, monte_carlo, simulate_white_jerk, tune_q

from filterpy import kalman  # noqa: E402  (the test extra: the oracle, never skipped)

DT = 0.2
DT_NS = 200_000_000
X0 = np.array([400.0, -300.0, -120.0, 8.0, 5.0, -1.0, 0.3, -0.2, 0.1])


def _rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def _linear_case(rng, n_steps):
    """A 9-state CA model with a general 4×9 linear measurement (correlated R)."""
    q = 0.5
    H = rng.standard_normal((4, 9))
    A = rng.standard_normal((4, 4))
    R = A @ A.T + 4 * np.eye(4)
    truth = simulate_white_jerk(1, n_steps, DT, q, X0, rng=rng)[0]
    z = truth @ H.T + rng.standard_normal((n_steps, 4)) @ np.linalg.cholesky(R).T
    return q, H, R, truth, z


@pytest.mark.parametrize("joseph, tol", [(True, 1e-12), (False, 1e-9)])
@pytest.mark.parametrize("noise", ["correlated", "diagonal"])  # diagonal: the compiled Joseph update
def test_with_a_linear_measurement_the_ekf_equals_filterpys_kalman_filter(rng, joseph, tol, noise):
    n_steps = 300
    q, H, R, _, z = _linear_case(rng, n_steps)
    if noise == "diagonal":
        R = np.diag(np.diagonal(R))
    kf = kalman.KalmanFilter(dim_x=9, dim_z=4)
    kf.x, kf.P = X0.copy(), initial_cov()
    kf.F, kf.Q, kf.H, kf.R = ca_transition(DT), white_jerk_q(DT, q), H, R
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), LinearMeasurement(H, R), joseph=joseph)
    state = GaussianState(X0, initial_cov(), 0)
    for k in range(n_steps):
        kf.predict()
        state = ekf.predict(state, (k + 1) * DT_NS)
        assert _rel(state.mean, kf.x) < tol and _rel(state.cov, kf.P) < tol
        kf.update(z[k])
        state = ekf.update(state, z[k])
        assert _rel(state.mean, kf.x) < tol, k
        assert _rel(state.cov, kf.P) < tol, k


def test_the_batched_filter_over_runs_equals_filterpy_run_by_run(rng):
    n_runs, n_steps, q = 5, 200, 0.5
    meas = position_measurement(2.0)
    truth = simulate_white_jerk(n_runs, n_steps, DT, q, X0, rng=rng)
    z = measure(meas, truth, rng)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), meas)
    x0 = truth[:, 0] + rng.standard_normal((n_runs, 9))
    track = run_filter(ekf, GaussianState(x0, np.broadcast_to(initial_cov(), (n_runs, 9, 9)), 0),
                       np.arange(n_steps) * DT_NS, z)
    for r in range(n_runs):
        kf = kalman.KalmanFilter(dim_x=9, dim_z=3)
        kf.x, kf.P, kf.F, kf.Q = x0[r].copy(), initial_cov(), ca_transition(DT), white_jerk_q(DT, q)
        kf.H, kf.R = meas.H, meas.R
        for k in range(n_steps):
            if k:
                kf.predict()
            kf.update(z[k, r])
            assert _rel(track.mean[r, k], kf.x) < 1e-12 and _rel(track.cov[r, k], kf.P) < 1e-12


def test_an_update_with_no_measurement_is_a_predict_only_step(rng):
    ekf = ExtendedKalmanFilter(ConstantAcceleration(1.0), RadarModel(site_ned_m=(0.0, 0.0, 0.0)))
    pred = GaussianState(np.tile(X0, (3, 1)), np.broadcast_to(initial_cov(), (3, 9, 9)), 5)
    post, st = ekf.update_stats(pred, np.empty((3, 0, 4)))
    assert post is pred and np.all(st.dof == 0) and np.all(st.nis == 0)


def test_stacked_measurements_equal_sequential_updates_and_nan_rows_are_left_out(rng):
    meas = position_measurement(1.5)
    ekf = ExtendedKalmanFilter(LinearTransition(np.eye(9), np.zeros((9, 9))), meas)
    prior = GaussianState(np.tile(X0, (2, 1)), np.broadcast_to(initial_cov(), (2, 9, 9)), 0)
    z = X0[:3] + rng.standard_normal((2, 3, 3))
    joint, st = ekf.update_stats(prior, z)
    seq = prior
    for m in range(3):
        seq = ekf.update(seq, z[:, m])
    np.testing.assert_allclose(joint.mean, seq.mean, rtol=1e-12)
    np.testing.assert_allclose(joint.cov, seq.cov, rtol=1e-10, atol=1e-15)
    assert np.all(st.dof == 9)
    # run 0 misses its second measurement: equals an update with the other two only
    zg = z.copy()
    zg[0, 1] = np.nan
    gap, stg = ekf.update_stats(prior, zg)
    two = ekf.update(GaussianState(prior.mean[0], prior.cov[0], 0), z[0, [0, 2]])
    np.testing.assert_allclose(gap.mean[0], two.mean, rtol=1e-12)
    np.testing.assert_allclose(gap.cov[0], two.cov, rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(gap.mean[1], joint.mean[1], rtol=1e-12)
    assert stg.dof.tolist() == [6, 9]


def test_a_measurement_of_the_wrong_shape_is_refused_in_one_line():
    ekf = ExtendedKalmanFilter(ConstantAcceleration(1.0), position_measurement(1.0))
    prior = GaussianState(np.tile(X0, (2, 1)), np.broadcast_to(initial_cov(), (2, 9, 9)), 0)
    with pytest.raises(ValueError, match=r"measurement shape \(2, 4\)"):
        ekf.update(prior, np.zeros((2, 4)))


def test_on_its_own_white_jerk_model_with_the_radar_the_ekf_nees_is_consistent():
    rng = np.random.default_rng(14)
    n_runs, n_steps, q = 1000, 100, 1.0
    radar = RadarModel(site_ned_m=(-200.0, 150.0, 0.0))
    t0 = time.perf_counter()
    truth = simulate_white_jerk(n_runs, n_steps, DT, q, X0, rng=rng)
    z = measure(radar, truth, rng)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), radar)
    mc = monte_carlo(ekf, truth, z, np.arange(n_steps) * DT_NS, GaussianState(X0, initial_cov(), 0))
    elapsed = time.perf_counter() - t0
    lo, hi = chi2_band(9, n_runs)
    assert 8.2 < lo < 9 < hi < 9.9
    assert fraction_in_band(mc.nees_avg, 9, n_runs) >= 0.90
    assert abs(mc.nees_avg.mean() - 9) <= 0.3
    assert fraction_in_band(mc.nis_avg, 4, n_runs) >= 0.90 and mc.nis_dof == 4
    # the filter's variance matches the Monte Carlo error variance (consistency, per component)
    ratio = mc.err_var[10:] / mc.filter_var[10:]
    assert 0.8 < np.median(ratio) < 1.2
    assert elapsed < 30


def test_tune_q_finds_the_true_q_on_a_synthetic_case():
    rng = np.random.default_rng(7)
    q_true, n_runs, n_steps = 2.0, 200, 60
    meas = position_measurement(1.0)
    truth = simulate_white_jerk(n_runs, n_steps, DT, q_true, X0, rng=rng)
    z = measure(meas, truth, rng)
    grid = [0.02, 0.2, 2.0, 20.0, 200.0]
    tuned = tune_q(truth, z, np.arange(n_steps) * DT_NS, meas, grid)
    assert tuned.q == q_true and tuned.grid == tuple(grid) and tuned.rmse.shape == (5, 9)
    assert np.argmin(tuned.score) == 2
    with pytest.raises(ValueError, match="positive"):
        tune_q(truth, z, np.arange(n_steps) * DT_NS, meas, [0.0, 1.0])


def test_a_radar_gap_in_one_run_is_a_predict_only_step_for_that_run_alone(rng):
    radar = RadarModel(site_ned_m=(-200.0, 150.0, 0.0))
    n_steps = 20
    truth = simulate_white_jerk(2, n_steps, DT, 1.0, X0, rng=rng)
    z = measure(radar, truth, rng)
    z[5:8, 1] = np.nan  # run 1 loses three radar samples
    ekf = ExtendedKalmanFilter(ConstantAcceleration(1.0), radar)
    prior = GaussianState(np.tile(X0, (2, 1)), np.broadcast_to(initial_cov(), (2, 9, 9)), 0)
    t_ns = np.arange(n_steps) * DT_NS
    track = run_filter(ekf, prior, t_ns, z)
    assert track.n_predict_only.tolist() == [0, 3] and track.dof[1, 5:8].tolist() == [0, 0, 0]
    # run 1 by itself: the gap steps are predictions only
    one = GaussianState(X0, initial_cov(), 0)
    for k in range(n_steps):
        if k:
            one = ekf.predict(one, int(t_ns[k]))
        if not 5 <= k < 8:
            one = ekf.update(one, z[k, 1])
        np.testing.assert_allclose(track.mean[1, k], one.mean, rtol=1e-12)
        np.testing.assert_allclose(track.cov[1, k], one.cov, rtol=1e-9, atol=1e-15)
    np.testing.assert_array_equal(track.pred_cov[1, 6], track.cov[1, 6])  # nothing measured, nothing changed
    assert np.trace(track.cov[1, 7]) > np.trace(track.cov[0, 7])


@pytest.mark.parametrize("joseph", [True, False])
def test_an_update_written_into_a_given_covariance_array_equals_the_plain_update(rng, joseph):
    radar = RadarModel(site_ned_m=(-200.0, 150.0, 0.0))
    ekf = ExtendedKalmanFilter(ConstantAcceleration(1.0), radar, joseph=joseph)
    x = X0 + rng.normal(0, 1, (4, 9))
    pred = GaussianState(x, np.broadcast_to(initial_cov(), (4, 9, 9)), 0)
    zf = radar.measure(x, rng)
    z = zf.copy()
    z[2, 1] = np.nan  # one run missing: the masked path
    for zk in (zf, z, z[:, None], np.empty((4, 0, 4))):
        post, st = ekf.update_stats(pred, zk)
        out = np.full((4, 9, 9), np.nan)
        post_o, st_o = ekf.update_stats(pred, zk, out=out)
        assert np.shares_memory(post_o.cov, out)
        np.testing.assert_array_equal(out, post.cov)
        np.testing.assert_array_equal(post_o.mean, post.mean)
        np.testing.assert_array_equal(st_o.nis, st.nis)
        np.testing.assert_array_equal(st_o.dof, st.dof)


def _small_case(T=20):
    ekf = ExtendedKalmanFilter(ConstantAcceleration(1.0), position_measurement(1.0))
    prior = GaussianState(np.zeros(9), initial_cov(), 0)
    z = np.random.default_rng(1).standard_normal((T, 1, 3))
    return ekf, prior, np.arange(T) * 10**9, z


def test_time_running_backwards_or_a_late_prior_is_one_clear_error_naming_the_first_bad_row():
    ekf, prior, t, z = _small_case()
    t2 = t.copy()
    t2[[3, 4]] = t[[4, 3]]  # used to predict backwards with a negative definite Q, silently
    with pytest.raises(ValueError, match=r"run_filter: t_ns must be non-decreasing; row 4"):
        run_filter(ekf, prior, t2, z)
    with pytest.raises(ValueError, match=r"prior time 5000000000 ns is after the first step"):
        run_filter(ekf, GaussianState(np.zeros(9), initial_cov(), 5 * 10**9), t, z)
    with pytest.raises(ValueError, match=r"whole nanoseconds; row 2"):
        run_filter(ekf, prior, t + np.r_[0.0, 0.0, 0.25, np.zeros(17)], z)  # was truncated


def test_equal_stamps_update_twice_at_one_instant_and_whole_float_stamps_are_accepted():
    ekf, prior, t, z = _small_case(6)
    a = run_filter(ekf, prior, t, z)
    assert np.array_equal(run_filter(ekf, prior, t.astype(np.float64), z).mean, a.mean)
    t2 = np.r_[t[:3], t[2], t[3:5]]  # step 3 repeats step 2's time: no predict, one more update
    z2 = np.concatenate([z[:3], z[2:3], z[3:5]])
    b = run_filter(ekf, prior, t2, z2)
    twice = ekf.update(GaussianState(b.mean[0, 2], b.cov[0, 2], int(t[2])), z[2, 0])
    np.testing.assert_allclose(b.mean[0, 3], twice.mean, rtol=1e-12)


def test_an_infinite_measurement_is_a_counted_predict_only_step_like_nan():
    ekf, prior, t, z = _small_case()
    zi, zn = z.copy(), z.copy()
    zi[3, 0, 0], zn[3, 0, 0] = np.inf, np.nan
    ti, tn = run_filter(ekf, prior, t, zi), run_filter(ekf, prior, t, zn)
    assert np.isfinite(ti.mean).all()  # was NaN from step 3 on
    np.testing.assert_array_equal(ti.mean, tn.mean)
    assert ti.dof[0, 3] == 0 and ti.n_predict_only.tolist() == [1]
    # stacked rows (the LAPACK path for > 8 scalars): a -inf row is left out like a NaN one
    zs = np.repeat(z[:, :, None], 4, axis=2)
    zsi, zsn = zs.copy(), zs.copy()
    zsi[5, 0, 1, 2], zsn[5, 0, 1, 2] = -np.inf, np.nan
    np.testing.assert_array_equal(run_filter(ekf, prior, t, zsi).mean, run_filter(ekf, prior, t, zsn).mean)


@pytest.mark.parametrize("bad", ["mean", "cov"])
def test_a_non_finite_prior_is_refused(bad):
    ekf, prior, t, z = _small_case()
    m, P = np.zeros((2, 9)), np.broadcast_to(initial_cov(), (2, 9, 9)).copy()
    (m if bad == "mean" else P)[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"prior mean or covariance is not finite \(run 1"):
        run_filter(ekf, GaussianState(m, P, 0), t, np.repeat(z, 2, axis=1))


@pytest.mark.parametrize("n", [1, 2, 4, 5, 8])
def test_the_compiled_innovation_inverse_equals_the_scalar_planes_bit_for_bit_and_fails_alike(monkeypatch, n):
    from pipeline.estimate import ekf as ekf_mod

    rng = np.random.default_rng(n)
    A = rng.normal(size=(20, 25, n, n))
    S = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(n)
    y = rng.normal(size=(20, 25, n))
    compiled = ekf_mod._spd_inverse(S, y)              # 500 systems: the kernel
    monkeypatch.setattr(ekf_mod, "_KERNEL_FROM", 10**9)
    planes = ekf_mod._spd_inverse(S, y)
    for c, p in zip(compiled, planes):
        assert c.shape == p.shape and np.array_equal(c, p)
    np.testing.assert_allclose(compiled[0], np.linalg.inv(S), rtol=1e-9, atol=1e-12)
    monkeypatch.setattr(ekf_mod, "_KERNEL_FROM", 64)
    S[3, 7] = -np.eye(n)
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        ekf_mod._spd_inverse(S, y)


def _joseph_case(rng, n_runs, n_x, n_z, zero_cols=()):
    """Random SPD covariances, states and a measurement Jacobian with the given zero columns."""
    A = rng.normal(size=(n_runs, n_x, n_x))
    P = A @ np.swapaxes(A, -1, -2) + 0.5 * np.eye(n_x)
    x = rng.normal(size=(n_runs, n_x)) * 10.0
    H = rng.normal(size=(n_runs, n_z, n_x))
    H[..., list(zero_cols)] = 0.0
    return x, P, H, rng.normal(size=(n_runs, n_z)), rng.uniform(0.1, 2.0, n_z)


@pytest.mark.parametrize("n_x, n_z, zero_cols", [(9, 4, (6, 7, 8)), (5, 2, ()), (5, 1, (3, 4)), (9, 3, (0, 8))])
def test_the_compiled_joseph_update_equals_the_numpy_algebra(monkeypatch, n_x, n_z, zero_cols):
    from pipeline.estimate import ekf as ekf_mod

    rng = np.random.default_rng(n_x * 10 + n_z)
    x, P, H, y, r = _joseph_case(rng, 150, n_x, n_z, zero_cols)  # two full blocks of 64 and a tail
    ekf = ExtendedKalmanFilter(ConstantAcceleration(1.0), LinearMeasurement(np.eye(n_z, n_x), np.diag(r)))

    class Meas:  # a per-run Jacobian, as the radar's
        R = np.diag(r)

        @staticmethod
        def h(xx):
            return np.zeros(xx.shape[:-1] + (n_z,))

        @staticmethod
        def jacobian(xx):
            return H

    ekf = ExtendedKalmanFilter(ConstantAcceleration(1.0), Meas())
    z = y.copy()
    z[[3, 70, 149]] = np.nan  # three runs unmeasured
    pred = GaussianState(x, P, 0)
    fast, st_fast = ekf.update_stats(pred, z)
    monkeypatch.setattr(ekf_mod, "_JOSEPH_KERNEL", False)
    slow, st_slow = ekf.update_stats(pred, z)
    assert _rel(fast.mean, slow.mean) < 1e-13 and _rel(fast.cov, slow.cov) < 1e-12
    np.testing.assert_allclose(st_fast.nis, st_slow.nis, rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(st_fast.logdet, st_slow.logdet, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(st_fast.dof, st_slow.dof)
    # an unmeasured run is left exactly as it was
    np.testing.assert_array_equal(fast.cov[[3, 70, 149]], P[[3, 70, 149]])
    np.testing.assert_array_equal(fast.mean[[3, 70, 149]], x[[3, 70, 149]])
    assert st_fast.nis[70] == st_fast.logdet[70] == st_fast.dof[70] == 0


def test_a_runs_compiled_update_does_not_depend_on_the_runs_beside_it(rng):
    x, P, H, y, r = _joseph_case(rng, 100, 9, 4, (6, 7, 8))
    H[40, :, 5] = 0.0  # run 40 leaves a column the rest of its block uses

    class Meas:
        R = np.diag(r)

        @staticmethod
        def h(xx):
            return np.zeros(xx.shape[:-1] + (4,))

        @staticmethod
        def jacobian(xx):
            return H if xx.ndim == 2 else H[40]

    ekf = ExtendedKalmanFilter(ConstantAcceleration(1.0), Meas())
    batch, st = ekf.update_stats(GaussianState(x, P, 0), y)
    alone, st1 = ekf.update_stats(GaussianState(x[40], P[40], 0), y[40])
    np.testing.assert_array_equal(batch.mean[40], alone.mean)
    np.testing.assert_array_equal(batch.cov[40], alone.cov)
    assert st.nis[40] == st1.nis and st.logdet[40] == st1.logdet


def test_the_compiled_update_refuses_a_degenerate_run_fills_a_strided_out_array_and_takes_no_runs(rng):
    x, P, H, y, r = _joseph_case(rng, 70, 9, 4, (6, 7, 8))
    meas = LinearMeasurement(H[0], np.diag(r))
    ekf = ExtendedKalmanFilter(ConstantAcceleration(1.0), meas)
    out = np.empty((9, 9, 70)).transpose(2, 0, 1)  # not C-contiguous
    post = ekf.update_stats(GaussianState(x, P, 0), y, out=out)[0]
    assert np.shares_memory(post.cov, out) and np.array_equal(out, ekf.update(GaussianState(x, P, 0), y).cov)
    P[66] = np.nan
    with pytest.raises(ValueError, match="not positive definite"):
        ekf.update(GaussianState(x, P, 5), y)
    empty, st = ekf.update_stats(GaussianState(x[:0], P[:0], 0), y[:0])  # no runs: nothing to do
    assert empty.cov.shape == (0, 9, 9) and st.nis.shape == st.logdet.shape == (0,)
