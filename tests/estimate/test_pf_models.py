"""Particle-filter motion models (issue 17, seed 001 §4, seed 003 §2), NED with ω > 0 right."""

import numpy as np
import pytest

from pipeline.estimate.models import (PF_STATE, PfAugmentedCoordinatedTurn, PfConstantAcceleration,
                                      PfConstantVelocity, PfCoordinatedTurn, PfCurvilinear,
                                      ct_transition, curvilinear_axes)

RNG = np.random.default_rng


def _x(n=7, N=3):
    x = np.zeros((N, n))
    x[:, 2:4] = [[10.0, 0.0], [0.0, -5.0], [3.0, 4.0]][:N]
    return x


def _sample_cov(d):
    return np.cov(d, rowvar=False)


def test_the_state_layout_puts_omega_at_index_four_for_ct_transition():
    assert PF_STATE[:5] == ("pos_n_m", "pos_e_m", "vel_n_mps", "vel_e_mps", "omega_radps")


def test_cv_without_noise_moves_by_velocity_times_dt_and_zeroes_omega_and_acceleration():
    x = _x()
    x[:, 4:] = 1.0
    y = PfConstantVelocity(0.0).propagate(x, 0.5, RNG(0))
    assert np.allclose(y[:, :2], 0.5 * x[:, 2:4]) and np.allclose(y[:, 2:4], x[:, 2:4])
    assert np.all(y[:, 4:] == 0)
    assert np.all(PfConstantVelocity(0.0, zero_unused=False).propagate(x, 0.5, RNG(0))[:, 4:] == 1.0)


def test_cv_noise_has_the_white_acceleration_covariance():
    N, dt, sa = 200_000, 0.8, 1.5
    y = PfConstantVelocity(sa).propagate(np.zeros((N, 4)), dt, RNG(1))
    G = np.array([dt * dt / 2, dt])
    Q1 = sa ** 2 * np.outer(G, G)  # per axis, [p, v]
    C = _sample_cov(y)
    assert np.allclose(C[np.ix_([0, 2], [0, 2])], Q1, rtol=0.02, atol=1e-4)
    assert abs(C[0, 1]) < 0.01 * Q1[0, 0]


def test_ca_without_noise_follows_constant_acceleration_kinematics():
    x = _x()
    x[:, 5:7] = [1.0, -2.0]
    y = PfConstantAcceleration(0.0).propagate(x, 2.0, RNG(0))
    assert np.allclose(y[:, :2], 2.0 * x[:, 2:4] + 2.0 * np.array([1.0, -2.0]))
    assert np.allclose(y[:, 2:4], x[:, 2:4] + 2.0 * np.array([1.0, -2.0]))
    assert np.allclose(y[:, 5:7], [1.0, -2.0])


def test_ca_jerk_noise_grows_the_acceleration_variance_linearly_in_time():
    N, dt, sj = 200_000, 0.5, 2.0
    y = PfConstantAcceleration(sj).propagate(np.zeros((N, 7)), dt, RNG(2))
    assert np.var(y[:, 5]) == pytest.approx((sj * dt) ** 2, rel=0.02)
    assert np.var(y[:, 0]) == pytest.approx((sj * dt ** 3 / 6) ** 2, rel=0.02)


def test_entering_ca_draws_an_acceleration_along_the_velocity():
    x = _x()
    y = PfConstantAcceleration(acc_init_sigma=3.0).enter(x, RNG(3))
    v, a = x[:, 2:4], y[:, 5:7]
    assert np.allclose(v[:, 0] * a[:, 1] - v[:, 1] * a[:, 0], 0.0)  # parallel
    assert np.any(a != 0)


def test_ct_is_the_shared_ct_transition_plus_noise_and_turns_right_for_positive_omega():
    x = _x()
    x[:, 4] = 0.2
    y = PfCoordinatedTurn(0.0).propagate(x, 1.5, RNG(0))
    assert np.allclose(y[:, :5], ct_transition(x, 1.5)[:, :5])
    assert y[0, 3] > 0 and y[0, 1] > 0  # heading north, ω > 0: toward east
    assert np.allclose(np.hypot(y[:, 2], y[:, 3]), np.hypot(x[:, 2], x[:, 3]))


def test_ct_reduces_to_cv_as_omega_goes_to_zero():
    x = _x()
    for w in (0.0, 1e-12, -1e-10):
        x[:, 4] = w
        y = PfCoordinatedTurn(0.0).propagate(x, 2.0, RNG(0))
        z = PfConstantVelocity(0.0).propagate(x, 2.0, RNG(0))
        assert np.allclose(y[:, :4], z[:, :4], atol=1e-7)  # |ω|T·|v|T ≤ 2e-8
        assert np.all(np.isfinite(y))


def test_ct_with_a_known_rate_sets_it_and_left_turns_are_negative():
    x = _x()
    y = PfCoordinatedTurn(0.0, omega=-0.3).propagate(x, 1.0, RNG(0))
    assert np.allclose(y[:, 4], -0.3)
    assert y[0, 3] < 0  # heading north, ω < 0: a left turn toward west


def test_augmented_ct_random_walks_omega_by_sigma_root_dt_or_per_step():
    N = 200_000
    x = np.zeros((N, 5))
    x[:, 2] = 5.0
    y = PfAugmentedCoordinatedTurn(0.0, sigma_omega=0.1).propagate(x, 4.0, RNG(4))
    assert np.std(y[:, 4]) == pytest.approx(0.2, rel=0.02)
    y = PfAugmentedCoordinatedTurn(0.0, sigma_omega=0.1, per_step=True).propagate(x, 4.0, RNG(4))
    assert np.std(y[:, 4]) == pytest.approx(0.1, rel=0.02)


def test_entering_augmented_ct_draws_omega_with_the_leaf_sign():
    x = np.zeros((5000, 5))
    r = PfAugmentedCoordinatedTurn(omega_init=(0.01, 0.3), sign=+1).enter(x, RNG(5))[:, 4]
    l_ = PfAugmentedCoordinatedTurn(omega_init=(0.01, 0.3), sign=-1).enter(x, RNG(5))[:, 4]
    assert np.all((r >= 0.01) & (r <= 0.3)) and np.all((l_ <= -0.01) & (l_ >= -0.3))
    both = PfAugmentedCoordinatedTurn(omega_init=(0.01, 0.3)).enter(x, RNG(5))[:, 4]
    assert 0.45 < np.mean(both > 0) < 0.55


def test_curvilinear_noise_is_along_and_cross_track():
    N, dt, st, sn = 200_000, 1.0, 2.0, 0.25
    x = np.zeros((N, 4))
    x[:, 2:4] = [3.0, 4.0]
    y = PfCurvilinear(st, sn).propagate(x, dt, RNG(6))
    t = np.array([0.6, 0.8])
    n = np.array([-0.8, 0.6])
    Cv = _sample_cov(y[:, 2:4])
    assert t @ Cv @ t == pytest.approx(st ** 2, rel=0.02)
    assert n @ Cv @ n == pytest.approx(sn ** 2, rel=0.02)
    assert abs(t @ Cv @ n) < 0.02 * st ** 2


def test_curvilinear_axes_use_the_right_hand_normal_in_ned():
    t, n = curvilinear_axes(np.array([[10.0, 0.0], [0.0, 0.0]]))
    assert np.allclose(t[0], [1, 0]) and np.allclose(n[0], [0, 1])  # north -> the normal points east
    assert np.allclose(t[1], [1, 0])  # at rest: a fixed frame, no NaN


def test_curvilinear_with_equal_sigmas_has_the_cv_covariance():
    N, dt = 200_000, 0.7
    x = np.zeros((N, 4))
    x[:, 2:4] = [1.0, -2.0]
    a = PfCurvilinear(1.3, 1.3).propagate(x, dt, RNG(7))
    b = PfConstantVelocity(1.3).propagate(x, dt, RNG(8))
    assert np.allclose(_sample_cov(a), _sample_cov(b), rtol=0.03, atol=2e-3)


@pytest.mark.parametrize("model,n", [(PfConstantVelocity(), 3), (PfConstantAcceleration(), 6),
                                     (PfCoordinatedTurn(), 4), (PfCurvilinear(), 3)])
def test_a_too_short_state_fails_naming_the_model(model, n):
    with pytest.raises(ValueError, match=type(model).__name__):
        model.propagate(np.zeros((2, n)), 0.1, RNG(0))
