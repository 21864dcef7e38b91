"""The trajectory learner (seed 004 §3): monotone EM for the linear kinematic model with τ
fixed, the full loop's trace, τ's steps and band, recovery of a known trajectory from noisy
time-warped copies, determinism and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.align.trajectory import (COLUMNS, TrajectoryError, TrajectoryLearner, alignment_band,
                                       kinematic_transition, quaternion_continuous)
from pipeline.simulate.demos import DemoSimSettings, simulate_demos

DT = 0.1


def _truth(n_hidden, dt_h):
    t = np.arange(n_hidden) * dt_h
    pos = np.stack([20 * np.sin(0.25 * t), 6 * t, -30 + 2 * np.cos(0.4 * t)], axis=1)
    vel = np.gradient(pos, dt_h, axis=0)
    acc = np.gradient(vel, dt_h, axis=0)
    a = 0.3 * t
    q = np.stack([np.cos(a / 2), 0.1 * np.sin(a / 2), 0 * a, np.sin(a / 2)], axis=1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.hstack([pos, vel, acc, q])


def _case(rng, D=3, n=80, m=5, sigma=(0.5, 0.2, 0.3, 0.01), p=(0.2, 0.6, 0.2)):
    """m demos of n samples, warped by τ steps from p, with white noise; truth (hidden, D)."""
    truth = _truth(2 * n + 3 * n, DT / 2)[:, :D]
    s = np.r_[[sigma[0]] * 3, [sigma[1]] * 3, [sigma[2]] * 3, [sigma[3]] * 4][:D]
    demos, taus = [], []
    for _ in range(m):
        tau = np.concatenate([[0], np.cumsum(rng.choice([1, 2, 3], size=n - 1, p=p))])
        y = truth[tau] + rng.standard_normal((n, D)) * s
        demos.append(y)
        taus.append(tau)
    return truth, demos, taus


def _rmse_learned(L, truth, taus):
    """Position RMSE of the learned trajectory through the learned τ against the truth through
    the true τ (sample by sample)."""
    e = [L.mean_[L.tau_[k]][:, :3] - truth[tk][:, :3] for k, tk in enumerate(taus)]
    return float(np.sqrt(np.mean(np.concatenate(e) ** 2) * 3))


@pytest.mark.parametrize("cov_type", ["diag", "full"])
def test_with_tau_fixed_and_no_bias_the_marginal_loglik_never_decreases(rng, cov_type):
    _, demos, taus = _case(rng, D=9, n=60)
    L = TrajectoryLearner(dt=DT, fix_tau=True, use_bias=False, max_iter=12, tol=0.0,
                          cov_type=cov_type).fit(demos, tau=taus)
    ll = np.asarray(L.loglik_)
    assert len(ll) == 12 and L.n_iter_ == 12
    assert np.all(np.diff(ll) >= -1e-9 * np.abs(ll[:-1])), np.diff(ll)
    assert ll[-1] > ll[0]
    # τ never moved
    for tk, t0 in zip(L.tau_, taus):
        np.testing.assert_array_equal(tk, t0)


@pytest.mark.parametrize("D, init", [(3, "dtw"), (9, "linear"), (13, "dtw")])
def test_the_full_loop_writes_its_trace_and_ends_above_where_it_started(rng, D, init):
    _, demos, _ = _case(rng, D=D, n=70)
    L = TrajectoryLearner(dt=DT, max_iter=10, init_tau=init).fit(demos)
    n_x = 13 if D == 13 else 9
    assert L.n_iter_ == len(L.loglik_) == len(L.loglik_y_) == len(L.sigma_z_trace_) == len(L.sigma_y_trace_)
    assert np.all(np.isfinite(L.loglik_))
    assert L.loglik_[-1] > L.loglik_[0]
    T = L.T_
    assert T == round(2 * np.mean([len(y) for y in demos]))
    assert L.mean_.shape == L.var_.shape == (T, D)
    assert L.state_mean_.shape == (T, n_x)
    assert L.sigma_z_.shape == (n_x, n_x) and L.sigma_y_.shape == (D, D)
    assert L.beta_.shape == L.model_error_.shape == (T - 1, n_x)
    assert np.all(L.beta_[:, :6] == 0) and np.any(L.beta_[:, 6:] != 0)
    assert L.d_.shape == (5, 3)
    np.testing.assert_allclose(L.d_.sum(axis=1), 1.0)
    assert np.all(L.var_ > 0)
    if D == 13:
        np.testing.assert_allclose(np.linalg.norm(L.mean_[:, 9:13], axis=1), 1.0)


def test_tau_starts_at_zero_rises_by_one_to_three_and_stays_in_the_band(rng):
    _, demos, _ = _case(rng, D=3, n=70)
    demos[1] = demos[1][:60]  # a shorter demo: its band has its own slope
    C = 6
    L = TrajectoryLearner(dt=DT, window_C=C, max_iter=6).fit(demos)
    for k, tk in enumerate(L.tau_):
        assert tk.dtype.kind == "i" and len(tk) == len(demos[k])
        assert tk[0] == 0 and tk[-1] <= L.T_ - 1
        assert set(np.unique(np.diff(tk))) <= {1, 2, 3}
        lo = alignment_band(len(tk), L.T_, C)
        assert np.all(tk >= lo) and np.all(tk <= lo + 2 * C)
        on = L.demo_on_hidden(k)
        assert on.shape == (L.T_, 3)
        np.testing.assert_array_equal(on[tk], demos[k])
        assert np.isnan(np.delete(on, tk, axis=0)).all()


def test_the_learned_trajectory_is_closer_to_the_truth_than_the_plain_mean_and_every_demo(rng):
    truth, demos, taus = _case(rng, D=3, n=100, sigma=(1.0, 0, 0, 0))
    L = TrajectoryLearner(dt=DT, max_iter=20).fit(demos)
    learned = _rmse_learned(L, truth, taus)
    # the plain mean: the demos averaged sample by sample (no alignment)
    plain = np.mean(demos, axis=0)
    e_plain = np.concatenate([plain - truth[tk] for tk in taus])
    e_demo = [np.sqrt(np.mean((y - truth[tk]) ** 2) * 3) for y, tk in zip(demos, taus)]
    assert learned < np.sqrt(np.mean(e_plain ** 2) * 3)
    assert learned < min(e_demo)


def test_on_simulated_13d_demos_with_their_true_tau_the_marginal_loglik_never_decreases():
    ds = simulate_demos("loop", n_demos=5, rng=np.random.default_rng(11), settings=DemoSimSettings(duration_s=8.0))
    L = TrajectoryLearner(dt=ds.dt, fix_tau=True, use_bias=False, max_iter=10, tol=0.0).fit(ds.demos, tau=ds.tau_true)
    ll = np.asarray(L.loglik_)
    assert np.all(np.diff(ll) >= -1e-9 * np.abs(ll[:-1])), np.diff(ll)
    assert L.T_ >= max(t[-1] for t in ds.tau_true) + 1


def test_the_same_demos_give_the_same_fit():
    a = TrajectoryLearner(dt=DT, max_iter=5).fit(_case(np.random.default_rng(3), D=9, n=50)[1])
    b = TrajectoryLearner(dt=DT, max_iter=5).fit(_case(np.random.default_rng(3), D=9, n=50)[1])
    np.testing.assert_array_equal(a.mean_, b.mean_)
    np.testing.assert_array_equal(a.loglik_, b.loglik_)
    for x, y in zip(a.tau_, b.tau_):
        np.testing.assert_array_equal(x, y)


def test_bad_demos_are_refused_with_one_clear_line(rng):
    _, demos, _ = _case(rng, D=3, n=30)
    with pytest.raises(TrajectoryError, match="at least 2 demos"):
        TrajectoryLearner(dt=DT).fit(demos[:1])
    bad = [d.copy() for d in demos]
    bad[2][7, 1] = np.nan
    with pytest.raises(TrajectoryError, match="demo 2 has non-finite values in row 7"):
        TrajectoryLearner(dt=DT).fit(bad)
    with pytest.raises(TrajectoryError, match=r"demo 0 shaped \(30, 4\)"):
        TrajectoryLearner(dt=DT).fit([np.zeros((30, 4))] * 3)
    with pytest.raises(TrajectoryError, match="demo 1 has 9 columns"):
        TrajectoryLearner(dt=DT).fit([np.zeros((30, 3)), np.zeros((30, 9))])
    with pytest.raises(TrajectoryError, match="dt must be a positive"):
        TrajectoryLearner(dt=0.0).fit(demos)
    with pytest.raises(TrajectoryError, match="init_tau must be 'dtw' or 'linear'"):
        TrajectoryLearner(dt=DT, init_tau="mean").fit(demos)
    with pytest.raises(TrajectoryError, match="tau\\[0\\] must start at 0"):
        TrajectoryLearner(dt=DT).fit(demos, tau=[np.arange(30) * 4] * 5)


def test_quaternion_signs_are_made_continuous_and_the_model_matrix_integrates_acceleration():
    q = np.array([[1.0, 0, 0, 0], [-0.99, -0.1, 0, 0], [0.98, 0.2, 0, 0]])
    out = quaternion_continuous(q)
    assert np.all(np.einsum("ij,ij->i", out[1:], out[:-1]) > 0)
    np.testing.assert_array_equal(np.abs(out), np.abs(q))
    assert quaternion_continuous(q, reference=[-1.0, 0, 0, 0])[0, 0] == -1.0
    F = kinematic_transition(0.5, 13)
    x = np.r_[1.0, 2, 3, 0.1, 0.2, 0.3, 1, 1, 1, 1, 0, 0, 0]
    np.testing.assert_allclose((F @ x)[:3], x[:3] + 0.5 * x[3:6] + 0.125 * x[6:9])
    np.testing.assert_allclose((F @ x)[9:], x[9:])
    assert len(COLUMNS) == 13


def test_with_yak54_dynamics_em_learns_17_column_demos_with_bias_on_the_six_accelerations_only():
    from pipeline.estimate.aircraft import YAK54_DRIVEN
    from pipeline.simulate.demos import simulate_yak54_demos
    ds = simulate_yak54_demos("yak54_pull_up", n_demos=3, rng=np.random.default_rng(2),
                              settings=DemoSimSettings(duration_s=4.0))
    L = TrajectoryLearner(dt=ds.dt, dynamics="yak54", max_iter=6, window_C=10).fit(ds.demos)
    T = L.T_
    assert L.mean_.shape == L.state_mean_.shape == (T, 17) and L.beta_.shape == (T - 1, 17)
    assert L.loglik_[-1] > L.loglik_[0] and np.all(np.isfinite(L.loglik_))
    other = np.setdiff1d(np.arange(17), YAK54_DRIVEN)
    assert np.all(L.beta_[:, other] == 0) and np.all(np.any(L.beta_[:, list(YAK54_DRIVEN)] != 0, axis=0))
    np.testing.assert_allclose(np.linalg.norm(L.mean_[:, 6:10], axis=1), 1.0)
    # closer to the intent than the demos themselves (sample by sample through the true τ)
    e_l = np.concatenate([L.mean_[L.tau_[k], :3] - ds.intended[tk, :3] for k, tk in enumerate(ds.tau_true)])
    e_d = np.concatenate([y[:, :3] - ds.intended[tk, :3] for y, tk in zip(ds.demos, ds.tau_true)])
    assert np.mean(e_l ** 2) < np.mean(e_d ** 2)
    with pytest.raises(TrajectoryError, match="yak54 dynamics need \\(N, 17\\)"):
        TrajectoryLearner(dt=ds.dt, dynamics="yak54").fit([y[:, :13] for y in ds.demos])
    with pytest.raises(TrajectoryError, match="known: kinematic, yak54"):
        TrajectoryLearner(dt=ds.dt, dynamics="f22").fit(ds.demos)


@pytest.mark.parametrize("kw, match", [
    (dict(window_C=1.9), r"window_C must be a whole number >= 1, not 1.9"),
    (dict(window_C=0), r"window_C must be a whole number >= 1"),
    (dict(window_C="20"), r"window_C must be a whole number >= 1"),
    (dict(max_iter=2.7), r"max_iter must be a whole number >= 1, not 2.7"),
    (dict(max_iter=np.nan), r"max_iter must be a whole number >= 1"),
    (dict(max_iter=True), r"max_iter must be a whole number >= 1"),
    (dict(d_prior=-1.0), r"d_prior \(a Dirichlet pseudo-count\) must be a finite number >= 0"),
    (dict(d_prior=np.inf), r"d_prior .* must be a finite number >= 0"),
    (dict(d_prior=np.nan), r"d_prior .* must be a finite number >= 0"),
    (dict(learn_d="no"), r"learn_d must be True or False, not 'no'"),
    (dict(learn_d=0), r"learn_d must be True or False"),
    (dict(fix_tau="yes"), r"fix_tau must be True or False"),
    (dict(hidden_factor=np.nan), r"hidden_factor must be a finite number in \(1, 3\]"),
    (dict(hidden_factor=-2.0), r"hidden_factor must be a finite number in \(1, 3\]"),
    (dict(hidden_factor=1.0), r"hidden_factor must be a finite number in \(1, 3\]"),
    (dict(hidden_factor=3.5), r"hidden_factor must be a finite number in \(1, 3\]"),
])
def test_bad_learner_settings_are_refused_before_any_fitting(rng, kw, match):
    _, demos, _ = _case(rng, D=3, n=30)
    with pytest.raises(TrajectoryError, match=match):
        TrajectoryLearner(dt=DT, **kw).fit(demos)


@pytest.mark.parametrize("shift, match", [
    (0.7, r"tau\[0\] must hold integer hidden indices; sample 0 is 0.7 \(refused rather than truncated\)"),
    (np.nan, r"tau\[0\] must hold integer hidden indices; sample 0 is nan"),
])
def test_a_given_tau_must_hold_whole_hidden_indices(rng, shift, match):
    _, demos, taus = _case(rng, D=3, n=30)
    with pytest.raises(TrajectoryError, match=match):
        TrajectoryLearner(dt=DT).fit(demos, tau=[tk + shift for tk in taus])


def test_a_given_tau_of_whole_floats_fits_as_its_integers(rng):
    _, demos, taus = _case(rng, D=3, n=30)
    kw = dict(dt=DT, fix_tau=True, use_bias=False, max_iter=2, tol=0.0)
    a = TrajectoryLearner(**kw).fit(demos, tau=taus)
    b = TrajectoryLearner(**kw).fit(demos, tau=[tk.astype(float) for tk in taus])
    np.testing.assert_array_equal(a.mean_, b.mean_)
