"""RTS smoother against filterpy's rts_smoother, Markov re-timing Π(Δt), the white-jerk Q
against numerical integration of the continuous model, and the EKF+HMM's A_H and B."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad_vec
from scipy.linalg import expm

from pipeline.estimate.base import ConstantAcceleration, GaussianState, position_measurement
from pipeline.estimate.ekf import ExtendedKalmanFilter, run_filter
from pipeline.estimate.markov import check_stochastic, retime
from pipeline.estimate.models import (A_H, B, Q, ca_transition, hmm_input, hmm_transition, initial_cov,
                                      white_jerk_q)
from pipeline.estimate.montecarlo import measure, simulate_white_jerk
from pipeline.estimate.smoother import rts_smooth

from filterpy import kalman  # noqa: E402  (the test extra: the oracle, never skipped)

DT = 0.2
X0 = np.array([10.0, 20.0, -30.0, 1.0, -2.0, 0.5, 0.1, 0.0, -0.1])


def test_the_rts_smoother_equals_filterpys_rts_smoother_on_a_linear_case(rng):
    n_runs, n_steps, q = 3, 150, 0.8
    meas = position_measurement(3.0)
    truth = simulate_white_jerk(n_runs, n_steps, DT, q, X0, rng=rng)
    z = measure(meas, truth, rng)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), meas)
    t_ns = np.arange(n_steps) * 200_000_000
    track = run_filter(ekf, GaussianState(np.tile(X0, (n_runs, 1)), np.broadcast_to(initial_cov(), (n_runs, 9, 9)), 0),
                       t_ns, z)
    sm = rts_smooth(track)
    F = ca_transition(DT)
    for r in range(n_runs):
        xs, Ps, _, _ = kalman.rts_smoother(track.mean[r], track.cov[r], np.tile(F, (n_steps, 1, 1)),
                                           np.tile(white_jerk_q(DT, q), (n_steps, 1, 1)))
        np.testing.assert_allclose(sm.mean[r], xs, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(sm.cov[r], Ps, rtol=1e-7, atol=1e-12)
    # the last step is the filtered one; smoothing never raises the variance
    np.testing.assert_array_equal(sm.mean[:, -1], track.mean[:, -1])
    dvar = np.diagonal(sm.cov, axis1=-2, axis2=-1) - np.diagonal(track.cov, axis1=-2, axis2=-1)
    assert np.all(dvar <= 1e-12)
    # and on average it lowers the error
    assert np.mean((sm.mean - truth) ** 2) < np.mean((track.mean - truth) ** 2)


def test_the_smoother_refuses_a_track_without_predicted_covariances(rng):
    ekf = ExtendedKalmanFilter(ConstantAcceleration(1.0), position_measurement(1.0))
    track = run_filter(ekf, GaussianState(X0, initial_cov(), 0), [0, 1, 2], np.zeros((3, 1, 3)), store="filtered")
    with pytest.raises(ValueError, match="store='all'"):
        rts_smooth(track)


PI = np.array([[0.9, 0.07, 0.03], [0.05, 0.9, 0.05], [0.02, 0.08, 0.9]])


def test_pi_at_the_reference_step_is_pi_and_two_half_steps_make_one_step():
    np.testing.assert_allclose(retime(PI, 0.2, 0.2), PI, atol=1e-15)
    np.testing.assert_allclose(retime(PI, 0.2 * (1 + 1e-12), 0.2), PI, atol=1e-10)
    half = retime(PI, 0.1, 0.2)
    np.testing.assert_allclose(half @ half, PI, atol=1e-12)
    check_stochastic(half)
    np.testing.assert_allclose(retime(PI, 0.4, 0.2), PI @ PI, atol=1e-12)
    np.testing.assert_array_equal(retime(PI, 0.0, 0.2), np.eye(3))


@pytest.mark.parametrize("Pi, match", [
    ([[0.9, 0.2], [0.5, 0.5]], "row 0 sums to 1.1, not 1"),
    ([[1.1, -0.1], [0.5, 0.5]], "row 0 has a negative entry"),
    ([[0.5, 0.5], [np.nan, 0.5]], "row 1 has a non-finite entry"),
    ([[0.5, 0.5, 0.0]], "square"),
])
def test_an_invalid_pi_raises_a_clear_error_naming_the_row(Pi, match):
    with pytest.raises(ValueError, match=match):
        retime(Pi, 0.1, 0.2, name="imm.Pi")


def test_a_pi_without_a_real_logarithm_cannot_be_retimed():
    with pytest.raises(ValueError, match="no real matrix logarithm"):
        retime([[0.1, 0.9], [0.9, 0.1]], 0.1, 0.2)


@pytest.mark.parametrize("Pi", [[[0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]],   # cyclic
                                [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]])  # a permutation
def test_a_pi_whose_real_logarithm_is_no_generator_cannot_be_retimed(Pi):
    # clipping expm's negative entries used to break Π(Δt/2)² = Π(Δt) by 0.1 without a word
    with pytest.raises(ValueError, match=r"no valid generator.*of row \d's probability would be clipped"):
        retime(Pi, 0.5, 1.0)


def test_a_left_to_right_hmm_is_retimed_only_within_the_clip_the_caller_accepts():
    # a maneuver HMM's transmat has zeros two steps can reach: no valid generator, and its
    # quarter step clips ~1e-3 of probability; refused by default, approximated on request
    from pipeline.estimate.markov import hmm_to_step

    T = np.array([[0.8, 0.2, 0.0, 0.0], [0.0, 0.7, 0.3, 0.0], [0.0, 0.0, 0.9, 0.1], [0.0, 0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match="max_clip 0.0001"):
        hmm_to_step(T, 0.05, 0.2)
    q = hmm_to_step(T, 0.05, 0.2, max_clip=0.05)
    assert np.allclose(q.sum(axis=1), 1.0) and (q >= 0).all()
    np.testing.assert_allclose(np.linalg.matrix_power(q, 4), T, atol=0.05)


def test_the_seed001_driving_matrices_retime_within_the_default_clip():
    # the paper's Π_d and Π_p (40 Hz) have no valid generator either, but at 20 Hz or 80 Hz
    # they clip at most 2e-5 of a row: the geolocation study's other rates keep working
    from pipeline.simulate.geolocation import PI_D, PI_P, PI_RATE_HZ

    for P in (PI_D, PI_P):
        for rate in (20.0, 80.0):
            out = retime(P, 1.0 / rate, 1.0 / PI_RATE_HZ)
            assert np.allclose(out.sum(axis=1), 1.0) and (out >= 0).all()


def test_a_valid_generator_with_zero_rates_is_still_retimed():
    # rates of exactly zero (absorbing and one-way chains) are round-off, not an error
    from pipeline.estimate.pf import dwell_transition

    P = dwell_transition([2.0, 1.0, 3.0], 0.2, to=[[0, 1, 0], [0, 0, 1], [1, 0, 0]])
    half = retime(P, 0.1, 0.2)
    np.testing.assert_allclose(half @ half, P, atol=1e-12)
    absorbing = np.array([[1.0, 0.0], [0.3, 0.7]])
    np.testing.assert_allclose(retime(absorbing, 0.4, 0.2), absorbing @ absorbing, atol=1e-12)


@pytest.mark.parametrize("dt, dt_ref", [(np.inf, 0.2), (np.nan, 0.2), (0.1, np.inf), (0.1, np.nan), (-0.1, 0.2)])
def test_a_non_finite_or_negative_step_cannot_be_retimed(dt, dt_ref):
    with pytest.raises(ValueError, match="need finite dt >= 0 and dt_ref > 0"):
        retime(PI, dt, dt_ref)


@pytest.mark.parametrize("dt", [-0.5, np.nan, np.inf])
def test_dwell_transition_refuses_a_negative_or_non_finite_step(dt):
    from pipeline.estimate.pf import dwell_transition

    with pytest.raises(ValueError, match="dt must be finite and >= 0"):
        dwell_transition([1.0, 2.0], dt)  # a negative step used to come back as the identity


@pytest.mark.parametrize("dt, q", [(0.2, 1.0), (0.05, 3.0), (1.0, 0.1)])
def test_white_jerk_q_equals_the_integral_of_the_continuous_model(dt, q):
    Fc = np.kron(np.array([[0, 1, 0], [0, 0, 1], [0, 0, 0]], float), np.eye(3))
    G = np.kron(np.array([[0], [0], [1.0]]), np.eye(3))
    # Fc is nilpotent (Fc³ = 0), so exp(Fc t) = I + Fc t + Fc² t²/2 exactly; checked against expm
    # below, and it keeps the quadrature from calling expm at every node
    Fc2 = Fc @ Fc
    np.testing.assert_allclose(expm(Fc * dt), np.eye(9) + Fc * dt + Fc2 * dt**2 / 2, atol=1e-14)

    def integrand(t):
        e = np.eye(9) + Fc * t + Fc2 * (t * t / 2)
        return e @ G @ (q * np.eye(3)) @ G.T @ e.T

    num, _ = quad_vec(integrand, 0, dt, epsabs=1e-14)
    np.testing.assert_allclose(white_jerk_q(dt, q), num, rtol=1e-10, atol=1e-16)
    assert Q is white_jerk_q
    np.testing.assert_allclose(expm(Fc * dt), ca_transition(dt), atol=1e-14)
    # the closed form, per axis (n axis)
    np.testing.assert_allclose(white_jerk_q(dt, q)[0::3, 0::3],
                               q * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                                             [dt**3 / 6, dt**2 / 2, dt]]), rtol=1e-15)


def test_a_h_and_b_have_the_seed_shapes_and_predict_a_constant_jerk_step():
    dt = 0.2
    assert A_H is hmm_transition and B is hmm_input
    assert A_H(dt).shape == (9, 9) and B(dt).shape == (9, 6)
    r, v, a = np.array([1.0, 2.0, 3.0]), np.array([0.5, -1.0, 2.0]), np.array([9.0, 9.0, 9.0])
    a_hat, j_hat = np.array([1.0, -2.0, 0.5]), np.array([3.0, 0.0, -1.0])
    x1 = A_H(dt) @ np.r_[r, v, a] + B(dt) @ np.r_[a_hat, j_hat]
    # closed form: a constant-jerk step from (r, v, â, ĵ); the state's own a is not used
    np.testing.assert_allclose(x1[:3], r + v * dt + a_hat * dt**2 / 2 + j_hat * dt**3 / 6, rtol=1e-14)
    np.testing.assert_allclose(x1[3:6], v + a_hat * dt + j_hat * dt**2 / 2, rtol=1e-14)
    np.testing.assert_allclose(x1[6:], a_hat + dt * j_hat, rtol=1e-14)
    # A_H C A_Hᵀ has a zero acceleration block (digest §8: the a-variance is Q₂'s every step)
    C = initial_cov()
    assert np.all((A_H(dt) @ C @ A_H(dt).T)[6:, 6:] == 0)


def test_p0_is_diag_of_1_01_001_squared_per_axis_group():
    np.testing.assert_array_equal(np.diag(initial_cov()), [1.0] * 3 + [0.1**2] * 3 + [0.01**2] * 3)


class _Pendulum:
    """A nonlinear transition (θ, ω) -> (θ + ω dt, ω − (g/L) sin θ dt) for the nonlinear path."""

    def __init__(self, q):
        self.q = q

    def f(self, x, dt):
        x = np.asarray(x, dtype=float)
        return np.stack([x[..., 0] + x[..., 1] * dt, x[..., 1] - 9.81 * np.sin(x[..., 0]) * dt], axis=-1)

    def jacobian(self, x, dt):
        x = np.asarray(x, dtype=float)
        J = np.zeros(x.shape[:-1] + (2, 2))
        J[..., 0, 0] = 1.0
        J[..., 0, 1] = dt
        J[..., 1, 0] = -9.81 * np.cos(x[..., 0]) * dt
        J[..., 1, 1] = 1.0
        return J

    def noise(self, dt):
        return self.q * np.diag([dt ** 3 / 3, dt])


def test_a_nonlinear_transition_runs_the_ekf_and_extended_rts_as_filterpy_steps_them(rng):
    from filterpy.kalman import ExtendedKalmanFilter as FpEKF
    from pipeline.estimate.base import LinearMeasurement, NonlinearTransitionModel
    dt, n_steps, n_runs = 0.05, 120, 2
    model = _Pendulum(0.5)
    assert isinstance(model, NonlinearTransitionModel)
    meas = LinearMeasurement(np.array([[1.0, 0.0]]), np.array([[0.05 ** 2]]))
    x = np.array([1.0, 0.0])
    truth = [x]
    for _ in range(n_steps - 1):
        x = model.f(x, dt)
        truth.append(x)
    truth = np.array(truth)
    z = truth[:, None, :1] + 0.05 * rng.standard_normal((n_steps, n_runs, 1))
    z[40:45, 0] = np.nan   # predict-only steps
    x0, P0 = np.array([0.8, 0.3]), np.diag([0.2, 0.5])
    bu = 1e-3 * rng.standard_normal((n_steps, 2))
    track = run_filter(ExtendedKalmanFilter(model, meas), GaussianState(np.tile(x0, (n_runs, 1)),
                       np.broadcast_to(P0, (n_runs, 2, 2)), 0), np.arange(n_steps) * 50_000_000, z, bu=bu)
    assert track.F.shape == (n_runs, n_steps, 2, 2)
    sm = rts_smooth(track)
    for r in range(n_runs):
        ek = FpEKF(dim_x=2, dim_z=1)
        ek.x, ek.P, ek.R, ek.Q = x0.copy(), P0.copy(), meas.R, model.noise(dt)
        xs, Ps, xp, Pp, Fs = [], [], [], [], []
        for k in range(n_steps):
            F = np.eye(2)
            if k:
                F = model.jacobian(ek.x, dt)
                ek.x = model.f(ek.x, dt) + bu[k]
                ek.P = F @ ek.P @ F.T + ek.Q
            xp.append(ek.x.copy()), Pp.append(ek.P.copy()), Fs.append(F)
            if np.isfinite(z[k, r, 0]):
                ek.update(z[k, r], lambda s: np.array([[1.0, 0.0]]), lambda s: s[:1])
            xs.append(ek.x.copy()), Ps.append(ek.P.copy())
        np.testing.assert_allclose(track.mean[r], np.array(xs), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(track.cov[r], np.array(Ps), rtol=1e-7, atol=1e-14)
        # the extended RTS pass: C_k = P_k F_{k+1}ᵀ (P⁻_{k+1})⁻¹ with each step's own Jacobian
        m, P = np.array(xs), np.array(Ps)
        for k in range(n_steps - 2, -1, -1):
            C = P[k] @ Fs[k + 1].T @ np.linalg.inv(Pp[k + 1])
            m[k] = m[k] + C @ (m[k + 1] - xp[k + 1])
            P[k] = P[k] + C @ (P[k + 1] - Pp[k + 1]) @ C.T
        np.testing.assert_allclose(sm.mean[r], m, rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(sm.cov[r], P, rtol=1e-6, atol=1e-12)
    assert np.mean((sm.mean[:, 5:, 0] - truth[None, 5:, 0]) ** 2) < np.mean((track.mean[:, 5:, 0] - truth[None, 5:, 0]) ** 2)
