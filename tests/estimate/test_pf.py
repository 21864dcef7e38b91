"""The bootstrap/jump-Markov particle-filter core (issue 17, seed 001 §1–§2)."""

import numpy as np
import pytest

from pipeline.estimate.markov import retime
from pipeline.estimate.models import PfConstantVelocity, PfCoordinatedTurn
from pipeline.estimate.pf import (GaussianPositionLikelihood, ParticleFilter, dwell_transition,
                                  run_pf, track_meta)

DT = 0.5
SIG_A, SIG_Z = 0.4, 2.0


def cv_kalman(m0, P0, Z, dt=DT, sa=SIG_A, sz=SIG_Z):
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    G = np.zeros((4, 2))
    G[0, 0] = G[1, 1] = dt * dt / 2
    G[2, 0] = G[3, 1] = dt
    Q = sa ** 2 * G @ G.T
    H = np.eye(2, 4)
    Rm = sz ** 2 * np.eye(2)
    m, P, out = m0.copy(), P0.copy(), []
    for k, z in enumerate(Z):
        if k:
            m, P = F @ m, F @ P @ F.T + Q
        S = H @ P @ H.T + Rm
        K = P @ H.T @ np.linalg.inv(S)
        m = m + K @ (z - H @ m)
        P = (np.eye(4) - K @ H) @ P
        out.append((m.copy(), P.copy()))
    return out


def cv_track(T=20, seed=0):
    rng = np.random.default_rng(seed)
    x = np.array([0.0, 0.0, 3.0, -1.0])
    Z = []
    for _ in range(T):
        Z.append(x[:2] + SIG_Z * rng.standard_normal(2))
        a = SIG_A * rng.standard_normal(2)
        x = x + np.r_[DT * x[2:] + DT * DT / 2 * a, DT * a]
    return np.array(Z)


def _cv_pf(n, seed, **kw):
    return ParticleFilter([PfConstantVelocity(SIG_A)], None, GaussianPositionLikelihood(SIG_Z),
                          n_particles=n, rng=seed, **kw)


def test_a_linear_gaussian_pf_with_1e5_particles_matches_the_kalman_filter_mean():
    Z = cv_track()
    m0, P0 = np.array([0.0, 0.0, 2.0, 0.0]), np.diag([4.0, 4.0, 4.0, 4.0])
    kf = cv_kalman(m0, P0, Z)
    pf = _cv_pf(100_000, 1).init(mean=m0, cov=P0)
    tr = run_pf(pf, np.arange(len(Z)) * int(DT * 1e9), Z)
    for k, (m, P) in enumerate(kf):
        # Monte Carlo error of a weighted mean: sd/√N_eff; resampling adds more, so the
        # N_eff the estimate was taken at (before resampling) bounds it from below; 5 se
        se = np.sqrt(np.diag(P) / tr.neff[k])
        assert np.all(np.abs(tr.mean[k] - m) <= 5 * se + 1e-9), (k, tr.mean[k], m, se)
        assert np.allclose(np.diag(tr.cov[k]), np.diag(P), rtol=0.1)


def test_a_nan_measurement_is_a_predict_only_step():
    Z = cv_track(10)
    Z[4] = [np.nan, 1.0]
    pf = _cv_pf(5000, 2).init(mean=np.array([0.0, 0.0, 3.0, -1.0]), cov=np.eye(4))
    tr = run_pf(pf, np.arange(10) * int(DT * 1e9), Z)
    assert tr.predict_only.tolist() == [k == 4 for k in range(10)]
    assert not tr.resampled[4] and np.isnan(tr.loglik[4])
    # nothing weighted: N_eff carried from step 3 unless step 3 resampled (then N)
    assert tr.neff[4] == (5000 if tr.resampled[3] else tr.neff[3])
    assert track_meta(tr)["n_predict_only"] == 1


def test_a_predict_only_step_moves_the_mean_by_the_motion_model():
    pf = _cv_pf(20_000, 3).init(mean=np.array([1.0, 2.0, 3.0, -4.0]), cov=0.01 * np.eye(4))
    s = pf.step(2.0, [np.nan, np.nan])
    assert s.predict_only and not s.resampled
    assert np.allclose(s.mean, [7.0, -6.0, 3.0, -4.0], atol=0.05)


def test_all_zero_weights_reinitialise_around_the_measurement_and_are_counted():
    lik = GaussianPositionLikelihood(1.0, gate=5.0, reinit_spread=2.0)
    pf = ParticleFilter([PfConstantVelocity(0.1)], None, lik, n_particles=4000, rng=4)
    pf.init(mean=np.zeros(4), cov=np.eye(4))
    z = np.array([500.0, -300.0])  # every particle is far outside the 5σ gate
    tr = run_pf(pf, np.array([0, 10**9], dtype=np.int64), np.array([[0.0, 0.0], z]))
    assert tr.n_reinit == 1 and tr.reinit.tolist() == [False, True]
    assert np.allclose(pf.x[:, :2].mean(axis=0), z, atol=0.2)
    assert np.allclose(pf.x[:, :2].std(axis=0), 2.0, rtol=0.05)
    assert np.allclose(pf.weights, 1 / 4000)
    assert track_meta(tr)["n_reinit"] == 1


def test_all_zero_weights_without_a_reinit_fail_with_a_clear_message():
    pf = ParticleFilter([PfConstantVelocity(0.1)], None, lambda x, z: np.full(len(x), -np.inf),
                        n_particles=10, rng=0).init(mean=np.zeros(4))
    with pytest.raises(ValueError, match="every weight is zero"):
        pf.step(0.1, [0.0, 0.0])


def test_the_same_seed_gives_the_same_track_and_another_seed_another():
    Z = cv_track(15)
    t = np.arange(15) * int(DT * 1e9)
    models = [PfConstantVelocity(SIG_A), PfCoordinatedTurn(SIG_A, omega=0.2)]

    def go(seed):
        pf = ParticleFilter(models, [[0.9, 0.1], [0.2, 0.8]], GaussianPositionLikelihood(SIG_Z),
                            n_particles=500, rng=np.random.default_rng(seed), dt_ref=DT)
        pf.init(mean=np.array([0.0, 0.0, 3.0, -1.0, 0.0]), cov=np.eye(5))
        return run_pf(pf, t, Z)

    a, b, c = go(5), go(5), go(6)
    assert np.array_equal(a.mean, b.mean) and np.array_equal(a.mode_p, b.mode_p)
    assert not np.array_equal(a.mean, c.mean)


def test_modes_are_drawn_from_the_rows_of_pi():
    Pi = np.array([[0.7, 0.2, 0.1], [0.05, 0.9, 0.05], [0.3, 0.3, 0.4]])
    pf = ParticleFilter([PfConstantVelocity(0.0)] * 3, Pi, GaussianPositionLikelihood(1.0),
                        n_particles=60_000, rng=7).init(mean=np.zeros(4), modes=np.repeat([0, 1, 2], 20_000))
    before = pf.mode.copy()
    pf.predict(1.0)
    for i in range(3):
        frac = np.bincount(pf.mode[before == i], minlength=3) / 20_000
        se = np.sqrt(Pi[i] * (1 - Pi[i]) / 20_000)
        assert np.all(np.abs(frac - Pi[i]) <= 4 * se + 1e-12)


def test_a_pi_whose_rows_do_not_sum_to_one_is_refused_naming_the_row():
    with pytest.raises(ValueError, match="row 1 sums to"):
        ParticleFilter([PfConstantVelocity()] * 2, [[1.0, 0.0], [0.5, 0.6]], GaussianPositionLikelihood(), rng=0)
    with pytest.raises(ValueError, match="2 mode models"):
        ParticleFilter([PfConstantVelocity()] * 2, np.eye(3), GaussianPositionLikelihood(), rng=0)


def test_pi_is_retimed_to_each_step_by_the_matrix_exponential():
    Pi = dwell_transition([2.0, 0.5, 1.0], 0.1)
    pf = ParticleFilter([PfConstantVelocity()] * 3, Pi, GaussianPositionLikelihood(), dt_ref=0.1, rng=0)
    assert np.allclose(pf.transition_matrix(0.1), Pi)
    assert np.allclose(pf.transition_matrix(0.25), retime(Pi, 0.25, 0.1))
    assert np.allclose(pf.transition_matrix(0.05) @ pf.transition_matrix(0.05), Pi, atol=1e-12)
    # the dwell-time chain is the same continuous-time chain at every step
    assert np.allclose(dwell_transition([2.0, 0.5, 1.0], 0.25), retime(Pi, 0.25, 0.1), atol=1e-12)


def test_dwell_times_give_stay_probabilities_of_one_minus_dt_over_tau_for_small_steps():
    tau = np.array([5.0, 3.1, 2.8])
    P = dwell_transition(tau, 1e-3)
    assert np.allclose(P.sum(axis=1), 1.0)
    assert np.allclose(np.diag(P), 1 - 1e-3 / tau, atol=1e-6)
    assert np.allclose(P[0, 1], P[0, 2])  # leaves uniformly by default


def test_every_step_resampling_resamples_at_every_measurement():
    Z = cv_track(8)
    pf = _cv_pf(300, 8, every_step=True).init(mean=np.array([0.0, 0.0, 3.0, -1.0]), cov=np.eye(4))
    tr = run_pf(pf, np.arange(8) * int(DT * 1e9), Z)
    assert tr.resampled.all()


def test_threshold_resampling_happens_only_below_n_over_three():
    Z = cv_track(12)
    pf = _cv_pf(2000, 9).init(mean=np.array([0.0, 0.0, 3.0, -1.0]), cov=9 * np.eye(4))
    tr = run_pf(pf, np.arange(12) * int(DT * 1e9), Z)
    assert np.array_equal(tr.resampled, tr.neff < 2000 / 3)
    assert tr.resampled.any() and not tr.resampled.all()


def test_mode_fractions_favour_the_mode_that_generated_a_straight_track():
    Z = cv_track(40, seed=3)
    models = [PfConstantVelocity(SIG_A), PfCoordinatedTurn(SIG_A, omega=0.6)]
    pf = ParticleFilter(models, [[0.95, 0.05], [0.05, 0.95]], GaussianPositionLikelihood(SIG_Z),
                        n_particles=3000, rng=10, dt_ref=DT)
    pf.init(mean=np.array([0.0, 0.0, 3.0, -1.0, 0.0]), cov=np.diag([4, 4, 1, 1, 0]))
    tr = run_pf(pf, np.arange(40) * int(DT * 1e9), Z)
    assert np.allclose(tr.mode_p.sum(axis=1), 1.0)
    assert tr.mode_p[10:, 0].mean() > 0.8


def test_side_arrays_travel_with_their_particles_through_resampling():
    pf = _cv_pf(1000, 11, every_step=True).init(mean=np.zeros(4), cov=np.eye(4))
    pf.aux["tag"] = np.arange(1000)
    pf.aux["pos0"] = pf.x[:, 0].copy()
    pf.step(0.0, [0.5, 0.0])  # no prediction: the resampled particles keep their positions
    assert np.array_equal(pf.aux["pos0"], pf.x[:, 0])
    assert len(np.unique(pf.aux["tag"])) < 1000


def test_a_singular_initial_covariance_draws_fixed_components_exactly():
    pf = _cv_pf(500, 12).init(mean=[1.0, 2.0, 3.0, 4.0], cov=np.diag([1.0, 0.0, 1.0, 0.0]))
    assert np.all(pf.x[:, 1] == 2.0) and np.all(pf.x[:, 3] == 4.0) and pf.x[:, 0].std() > 0.5


def test_the_compiled_mode_draw_equals_a_searchsorted_per_from_mode_including_ties():
    from pipeline.estimate.pf import _draw_from_cdf

    rng = np.random.default_rng(11)
    P = rng.dirichlet(np.ones(5), size=5)
    P[2] = [0.0, 0.5, 0.0, 0.5, 0.0]                 # zero entries: repeated CDF values
    F = np.cumsum(P, axis=1)
    F[:, -1] = 1.0
    mode = rng.integers(0, 5, 20_000)
    u = rng.random(20_000)
    u[:5] = F[mode[:5], 1]                            # u exactly on a CDF value
    u[5] = 0.0
    out = np.empty(len(u), dtype=np.int64)
    _draw_from_cdf(mode, F, u, out)
    ref = np.empty_like(out)
    for r in range(5):
        sel = mode == r
        ref[sel] = np.searchsorted(F[r], u[sel], side="left")
    np.testing.assert_array_equal(out, ref)
    pos = u > 0                                       # a positive u never draws a zero-probability mode
    assert np.all(P[mode[pos], out[pos]] > 0)


def test_a_filter_or_a_monte_carlo_draw_without_an_rng_is_refused_rather_than_seeded_from_the_os():
    # every draw comes from the config's master seed: there is no unseeded default to fall back on
    from pipeline.estimate.models import RadarModel
    from pipeline.estimate.montecarlo import measure, simulate_white_jerk
    with pytest.raises(TypeError, match="rng"):
        ParticleFilter([PfConstantVelocity()], None, GaussianPositionLikelihood(), n_particles=10)
    with pytest.raises(TypeError, match="rng"):
        simulate_white_jerk(2, 3, 0.2, 1.0, np.zeros(9))
    with pytest.raises(TypeError, match="rng"):
        measure(RadarModel(), np.zeros((2, 3, 9)))


def test_a_measurement_of_another_width_than_the_likelihood_measures_is_refused_naming_both():
    Z = cv_track(10)
    t = np.arange(10) * int(DT * 1e9)
    with pytest.raises(ValueError, match=r"z has 1 component\(s\), the likelihood measures 2"):
        run_pf(_cv_pf(200, 5).init(mean=np.zeros(4), cov=np.eye(4)), t, Z[:, :1])  # was: E tracked N
    Z1 = np.c_[Z, Z[:, :1]]
    Z1[0] = np.nan  # a predict-only first row does not hide it
    with pytest.raises(ValueError, match=r"z has 3 component\(s\), the likelihood measures 2"):
        run_pf(_cv_pf(200, 5).init(mean=np.zeros(4), cov=np.eye(4)), t, Z1)
    pf = _cv_pf(200, 5).init(mean=np.zeros(4), cov=np.eye(4))
    with pytest.raises(ValueError, match=r"z has 1 component\(s\), the likelihood measures 2"):
        pf.step(0.5, [1.0])


def test_time_running_backwards_is_one_clear_error_naming_the_first_bad_row():
    Z = cv_track(12)
    t = np.arange(12) * int(DT * 1e9)
    t2 = t.copy()
    t2[[5, 6]] = t[[6, 5]]  # used to skip the negative predict silently
    with pytest.raises(ValueError, match=r"non-decreasing; row 6"):
        run_pf(_cv_pf(200, 6).init(mean=np.zeros(4)), t2, Z)
    with pytest.raises(ValueError, match=r"prior time 1 ns is after the first step"):
        run_pf(_cv_pf(200, 6).init(mean=np.zeros(4)), t, Z, t0_ns=1)
    with pytest.raises(ValueError, match=r"whole nanoseconds; row 1"):
        run_pf(_cv_pf(200, 6).init(mean=np.zeros(4)), t + np.r_[0.0, 0.5, np.zeros(10)], Z)
    pf = _cv_pf(200, 6).init(mean=np.zeros(4))
    for dt in (-0.5, np.nan):
        with pytest.raises(ValueError, match="dt must be >= 0"):
            pf.step(dt, Z[0])


def test_equal_stamps_and_whole_float_stamps_keep_their_current_meaning():
    Z = cv_track(8)
    t = np.arange(8) * int(DT * 1e9)
    a = run_pf(_cv_pf(300, 7).init(mean=np.zeros(4), cov=np.eye(4)), t, Z)
    b = run_pf(_cv_pf(300, 7).init(mean=np.zeros(4), cov=np.eye(4)), t.astype(np.float64), Z)
    np.testing.assert_array_equal(a.mean, b.mean)
    t3 = t.copy()
    t3[4] = t3[3]  # a second update at the same instant, no predict
    c = run_pf(_cv_pf(300, 7).init(mean=np.zeros(4), cov=np.eye(4)), t3, Z)
    # the same seed stepped by hand to step 3 (no predict at step 0: no prior time)
    pf = _cv_pf(300, 7).init(mean=np.zeros(4), cov=np.eye(4))
    for k in range(4):
        s = pf.step(0.0 if k == 0 else (t3[k] - t3[k - 1]) * 1e-9, Z[k])
        np.testing.assert_array_equal(c.mean[k], s.mean)
    x, logw = pf.x.copy(), pf.logw.copy()
    # step 4 weights those very particles by p(Z[4] | x) (the Gaussian of σ_z on N, E), unmoved
    lw = logw - 0.5 * np.sum(((Z[4] - x[:, :2]) / SIG_Z) ** 2, axis=1)
    w = np.exp(lw - lw.max())
    w /= w.sum()
    np.testing.assert_allclose(c.mean[4], w @ x, rtol=1e-12, atol=1e-12)
    s4 = pf.step(0.0, Z[4])
    np.testing.assert_array_equal(c.mean[4], s4.mean)
    np.testing.assert_array_equal(c.neff[4], s4.neff)
    # and it is an update: the second measurement moved the estimate
    assert not c.predict_only[4] and np.isfinite(c.loglik[4])
    assert np.abs(c.mean[4, :2] - c.mean[3, :2]).max() > 1e-3


def test_an_empty_track_gives_an_empty_result():
    pf = _cv_pf(50, 8).init(mean=np.zeros(4))
    tr = run_pf(pf, np.zeros(0, dtype=np.int64), np.zeros((0, 2)))
    assert tr.mean.shape == (0, 4) and tr.cov.shape == (0, 4, 4) and tr.mode_p.shape == (0, 1)
    assert tr.n_reinit == 0 and track_meta(tr)["n_predict_only"] == 0


def test_the_regularising_kernel_separates_resampled_copies_on_the_chosen_components_only():
    # the plain bootstrap filter leaves duplicates after resampling; with regularise_index the
    # copies move by the kernel on those components (N, E here) and keep the others
    z = np.array([0.3, -0.2])
    plain = _cv_pf(400, 5, every_step=True).init(mean=np.zeros(4), cov=4 * np.eye(4))
    kern = _cv_pf(400, 5, every_step=True, regularise_index=(0, 1)).init(mean=np.zeros(4), cov=4 * np.eye(4))
    s_plain, s_kern = plain.step(0.0, z), kern.step(0.0, z)
    assert s_plain.resampled and s_kern.resampled
    assert len(np.unique(plain.x[:, 0])) < 300                        # duplicates
    assert len(np.unique(kern.x[:, 0])) == 400                        # every copy moved
    assert len(np.unique(kern.x[:, 2])) == len(np.unique(plain.x[:, 2])) < 300   # velocity untouched
    # the kernel's spread is the posterior's, scaled by the bandwidth: the mean stays put
    assert abs(kern.x[:, 0].mean() - s_kern.mean[0]) < 0.2
