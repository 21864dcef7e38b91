"""Seed 002 bearing-only models: CPPV-CT, CV-CPPV, MPC, G/G⁻¹ and the wrapped bearing."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pipeline.estimate.base import GaussianState
from pipeline.estimate.ekf import ExtendedKalmanFilter
from pipeline.estimate.base import LinearTransition
from pipeline.estimate.models import (BearingMeasurement, cppv_jacobian, cppv_predict, cppv_process_noise,
                                      cppv_to_mpc, cppv_transition, cv_cppv_jacobian,
                                      cv_cppv_transition, mpc_derivative, mpc_jacobian,
                                      mpc_to_cppv, mpc_to_cppv_jacobian, mpc_transition,
                                      numerical_jacobian)

VO = np.array([40.0, 5.0])


def cppv_ode(t, x, vo):
    v, th, w = x[2], x[3], x[4]
    return [v * np.cos(th) - vo[0], v * np.sin(th) - vo[1], 0.0, w, 0.0]


@pytest.mark.parametrize("w", [0.09, -0.12, 1e-3, 0.0, -3e-7])
def test_the_cppv_step_equals_a_fine_integration_of_the_relative_motion(w):
    x0 = np.array([3000.0, -1500.0, 70.0, 1.1, w])
    T = 0.05 * 7
    ref = solve_ivp(cppv_ode, (0, T), x0, args=(VO,), rtol=1e-12, atol=1e-9).y[:, -1]
    got = cppv_transition(x0, T, u=VO * T)
    assert got == pytest.approx(ref, rel=1e-10, abs=1e-7)


@pytest.mark.parametrize("w", [0.09, -0.12, 2e-4, 0.0])
def test_the_cppv_jacobian_equals_central_differences(w):
    x0 = np.array([3000.0, -1500.0, 70.0, 1.1, w])
    T = 0.05
    F = cppv_jacobian(x0, T)
    Fn = numerical_jacobian(lambda x: cppv_transition(x, T), x0, eps=1e-5)
    assert F == pytest.approx(Fn, abs=1e-6)


def test_the_cppv_jacobian_at_zero_turn_rate_is_the_d2_limit():
    v, th, T = 60.0, 0.7, 0.05
    F = cppv_jacobian(np.array([100.0, 200.0, v, th, 0.0]), T)
    assert F[0, 2:] == pytest.approx([T * np.cos(th), -v * T * np.sin(th), -0.5 * v * T * T * np.sin(th)], abs=1e-15)
    assert F[1, 2:] == pytest.approx([T * np.sin(th), v * T * np.cos(th), 0.5 * v * T * T * np.cos(th)], abs=1e-15)
    x1 = cppv_transition(np.array([100.0, 200.0, v, th, 0.0]), T)
    assert x1[:2] == pytest.approx([100 + v * T * np.cos(th), 200 + v * T * np.sin(th)], abs=1e-12)


def test_a_positive_turn_rate_is_a_right_turn_and_theta_is_the_course_from_north():
    # heading north (θ = 0) and turning with ω > 0 gains east position; θ = π/2 flies east
    x = cppv_transition(np.array([0.0, 0.0, 50.0, 0.0, 0.2]), 1.0)
    assert x[1] > 0 and x[3] == pytest.approx(0.2)
    x = cppv_transition(np.array([0.0, 0.0, 50.0, np.pi / 2, 0.0]), 1.0)
    assert x[:2] == pytest.approx([0.0, 50.0], abs=1e-12)


def test_the_cv_mode_step_and_jacobian():
    x0 = np.array([3000.0, -1500.0, 70.0, 1.1])
    T = 0.05
    ref = solve_ivp(lambda t, x: cppv_ode(t, np.r_[x, 0.0], VO)[:4], (0, T), x0, rtol=1e-12, atol=1e-10).y[:, -1]
    assert cv_cppv_transition(x0, T, u=VO * T) == pytest.approx(ref, rel=1e-11)
    Fn = numerical_jacobian(lambda x: cv_cppv_transition(x, T), x0, eps=1e-5)
    assert cv_cppv_jacobian(x0, T) == pytest.approx(Fn, abs=1e-6)


def test_the_corrected_process_noise_is_symmetric_and_the_faithful_one_is_as_printed():
    Q = cppv_process_noise(0.05, 1e-3, 5e-6)
    assert np.array_equal(Q, Q.T) and np.all(np.linalg.eigvalsh(Q) >= 0)
    assert Q[2, 2] == pytest.approx(0.05 ** 2 * 1e-3)
    Qf = cppv_process_noise(0.05, 1e-3, 5e-6, faithful=True)
    assert Qf[3, 4] == pytest.approx(5e-6 * 0.05 ** 3 / 2) and Qf[4, 3] == pytest.approx(5e-6 * 0.05 ** 2 / 2)


def test_g_inverse_after_g_is_the_identity():
    rng = np.random.default_rng(3)
    x = np.column_stack([rng.uniform(-6000, 6000, 50), rng.uniform(-6000, 6000, 50), rng.uniform(40, 90, 50),
                         rng.uniform(-np.pi, np.pi, 50), rng.uniform(-0.14, 0.14, 50)])
    vo = rng.normal(0, 30, (50, 2))
    back = mpc_to_cppv(cppv_to_mpc(x, vo), vo)
    assert back == pytest.approx(x, rel=1e-10, abs=1e-9)
    y = cppv_to_mpc(x, vo)
    assert y[:, 2] == pytest.approx(np.arctan2(x[:, 1], x[:, 0]))  # β = atan2(ΔE, ΔN)
    assert y[:, 3] == pytest.approx(1 / np.hypot(x[:, 0], x[:, 1]))


def test_the_mpc_dynamics_equal_the_time_derivative_of_g():
    rng = np.random.default_rng(4)
    for _ in range(10):
        x = np.array([rng.uniform(-6000, 6000), rng.uniform(-6000, 6000), rng.uniform(40, 90),
                      rng.uniform(-np.pi, np.pi), rng.uniform(-0.14, 0.14)])
        vo = rng.normal(0, 30, 2)
        xdot = np.array(cppv_ode(0, x, vo))
        dG = numerical_jacobian(lambda z: cppv_to_mpc(z, vo), x, eps=1e-7) @ xdot
        assert mpc_derivative(cppv_to_mpc(x, vo), vo) == pytest.approx(dG, rel=1e-5, abs=1e-12)


def test_the_mpc_jacobian_equals_central_differences():
    x = np.array([2500.0, -3100.0, 75.0, 2.0, 0.1])
    y = cppv_to_mpc(x, VO)
    J = mpc_jacobian(y, VO)
    Jn = numerical_jacobian(lambda z: mpc_derivative(z, VO), y, eps=1e-6)
    assert J == pytest.approx(Jn, rel=1e-6, abs=1e-12)


def test_the_mpc_step_matches_fine_integration_and_its_phi_the_variational_solution():
    x = np.array([2500.0, -3100.0, 75.0, 2.0, 0.1])
    y0 = cppv_to_mpc(x, VO)
    T = 0.05
    y1, Phi = mpc_transition(y0, VO, T)
    ref = solve_ivp(lambda t, y: mpc_derivative(y, VO), (0, T), y0, rtol=1e-12, atol=1e-16).y[:, -1]
    # Euler at 1 ms: first order, so agreement to ~dt·|ÿ|·T
    assert y1 == pytest.approx(ref, rel=1e-4, abs=1e-9)
    # exact CT motion mapped through G agrees with the MPC integration
    x1 = cppv_transition(x, T, u=VO * T)
    assert cppv_to_mpc(x1, VO) == pytest.approx(ref, rel=1e-8, abs=1e-14)
    Phin = numerical_jacobian(lambda z: mpc_transition(z, VO, T, engine="numpy")[0], y0, eps=1e-6)
    assert Phi == pytest.approx(Phin, rel=1e-5, abs=1e-9)
    y1n, Phinp = mpc_transition(np.stack([y0, y0]), VO, T, engine="numpy")
    assert y1n[1] == pytest.approx(y1, rel=1e-14) and Phinp[0] == pytest.approx(Phi, rel=1e-12)


def test_the_bearing_convention_is_atan2_of_east_over_north():
    m = BearingMeasurement(np.deg2rad(0.2))
    assert m.h(np.array([0.0, 1000.0, 0, 0, 0]))[0] == pytest.approx(np.pi / 2)   # due east
    assert m.h(np.array([-1000.0, -1e-9, 0, 0, 0]))[0] == pytest.approx(-np.pi)   # due south
    x = np.array([2000.0, -700.0, 60.0, 0.3, 0.05])
    Hn = numerical_jacobian(lambda z: m.h(z), x, eps=1e-7)
    assert m.jacobian(x) == pytest.approx(Hn, abs=1e-12)
    assert BearingMeasurement(0.01, "mpc").h(cppv_to_mpc(x, VO))[0] == pytest.approx(m.h(x)[0])


def test_the_ekf_wraps_a_bearing_residual_across_the_pi_cut():
    m = BearingMeasurement(0.01)
    ekf = ExtendedKalmanFilter(LinearTransition(np.eye(5), np.zeros((5, 5))), m)
    x = np.array([-1000.0, 1.0, 50.0, 0.0, 0.0])  # β just below π
    st = GaussianState(x, np.diag([100.0, 100.0, 1.0, 0.1, 0.01]))
    z = np.array([-np.pi + 0.001])  # just past the cut: the true residual is small
    post, stats = ekf.update_stats(st, z)
    assert stats.nis < 1.0
    assert abs(post.mean[1] - x[1]) < 5.0
    # the plain difference (2π) is what a model without the hook would see
    assert abs((z - m.h(x))[0]) > 6.0


def test_the_jacobian_of_g_inverse_equals_central_differences():
    x = np.array([2500.0, -3100.0, 75.0, 2.0, 0.1])
    y = cppv_to_mpc(x, VO)
    Jn = numerical_jacobian(lambda z: mpc_to_cppv(z, VO), y, eps=[1e-8, 1e-8, 1e-7, 1e-10, 1e-7])
    assert mpc_to_cppv_jacobian(y, VO) == pytest.approx(Jn, rel=1e-6, abs=1e-9)


def test_the_compiled_cppv_predict_equals_the_transition_and_its_jacobian():
    rng = np.random.default_rng(7)
    x = np.column_stack([rng.uniform(-6000, 6000, 40), rng.uniform(-6000, 6000, 40), rng.uniform(40, 90, 40),
                         rng.uniform(-7, 7, 40), np.r_[0.0, 1e-9, -1e-5, 0.019, rng.uniform(-0.14, 0.14, 36)]])
    u = rng.normal(0, 2, (40, 2))
    fx, F = cppv_predict(x.reshape(4, 10, 5), 0.05, u.reshape(4, 10, 2))
    assert fx.reshape(40, 5) == pytest.approx(cppv_transition(x, 0.05, u), rel=1e-14, abs=1e-12)
    assert F.reshape(40, 5, 5) == pytest.approx(cppv_jacobian(x, 0.05), rel=1e-13, abs=1e-15)
