"""The bearing-only CRLB (seed 002 §7) and the seed-002 metrics (§8, D8)."""

import numpy as np
import pytest

from pipeline.estimate.bank import bank_prior, combine, BankSettings
from pipeline.estimate.base import GaussianState, LinearTransition
from pipeline.estimate.crlb import crlb, q_floor
from pipeline.estimate.ekf import ExtendedKalmanFilter
from pipeline.estimate.metrics import (CHI2_5_0999, bearing_errors, bearing_metrics, bearing_nees,
                                       divergence_flag, mean_abs_angle_error, mean_relative_abs_error)
from pipeline.estimate.models import BearingMeasurement, cppv_jacobian, cppv_process_noise, cppv_transition

SIG = np.deg2rad(0.2)
VO = np.array([40.0, 0.0])


def truth(T=400, dt=0.05, x0=(3000.0, 1500.0, 70.0, 1.0, np.deg2rad(6.0))):
    X = np.empty((T, 5))
    X[0] = x0
    for k in range(1, T):
        X[k] = cppv_transition(X[k - 1], dt, VO * dt)
    return np.arange(T) * dt, X


def test_the_crlb_equals_an_ekf_linearised_on_the_truth_without_process_noise():
    t, X = truth()
    P0 = np.diag([200.0 ** 2, 300.0 ** 2, 10.0 ** 2, 0.5 ** 2, 0.05 ** 2])
    b = crlb(X, t, P0, SIG)
    ekf = ExtendedKalmanFilter(LinearTransition(np.eye(5), np.zeros((5, 5))), BearingMeasurement(SIG))
    P = P0
    for k in range(1, len(t)):
        F = cppv_jacobian(X[k - 1], t[k] - t[k - 1])
        P = F @ P @ F.T
        P = ekf.update(GaussianState(X[k], P), np.arctan2(X[k, 1:2], X[k, 0:1])).cov  # H at the truth
        if k % 100 == 0:
            assert b.bound[k] == pytest.approx(P, rel=1e-5, abs=1e-10)
    assert b.bound[0] == pytest.approx(P0)
    g = X[-1, :2] / np.hypot(*X[-1, :2])
    assert b.range_std[-1] == pytest.approx(np.sqrt(g @ P[:2, :2] @ g), rel=1e-5)
    assert np.all(np.diff(b.std[:, 2]) <= 1e-9)  # information only grows: the speed bound falls


def test_the_crlb_with_the_bank_initial_covariance_lies_below_the_bank_spread():
    t, X = truth(T=200)
    c = bank_prior(BankSettings(), np.array([np.arctan2(X[0, 1], X[0, 0])]), SIG)
    _, P0 = combine(c.mean, c.cov, c.logw, (3,))
    b = crlb(X[None], t, P0, SIG)
    assert b.std.shape == (1, 200, 5) and np.all(b.std[0, -1] < np.sqrt(np.diag(P0[0])))


def test_the_q_floor_is_the_crlb_without_process_noise_and_lies_between_the_bound_and_the_filter_belief_with_it():
    t, X = truth(T=600)
    P0 = np.diag([400.0 ** 2, 400.0 ** 2, 10.0 ** 2, 0.5 ** 2, 0.05 ** 2])
    b = crlb(X, t, P0, SIG)
    zero = q_floor(X, t, P0, SIG, lambda dt: np.zeros((5, 5)))
    assert zero.bound == pytest.approx(b.bound, rel=1e-6, abs=1e-12)
    Q = lambda dt: cppv_process_noise(dt, 1e-3, 5e-6)
    fl = q_floor(X, t, P0, SIG, Q)
    believed = crlb(X, t, P0, SIG, process_noise=Q)   # the filter's own P is the Q-posterior bound
    for k in (100, 300, 599):
        # C − J⁻¹ and P − C are positive semi-definite (relative tolerance on the eigenvalues)
        for lo, hi in ((b.bound[k], fl.bound[k]), (fl.bound[k], believed.bound[k])):
            d = np.linalg.eigvalsh(hi - lo)
            assert d.min() >= -1e-7 * np.abs(d).max()
    # after 30 s the turn rate is already held at ~1.8× its bound by σ_ω̇² alone
    assert np.all(fl.std[-1] > b.std[-1]) and fl.std[-1, 4] > 1.5 * b.std[-1, 4]


def test_the_thesis_rmse_is_a_mean_relative_absolute_error():
    est = np.array([[110.0, 50.0], [90.0, 40.0]])
    tru = np.array([100.0, 50.0])
    assert mean_relative_abs_error(est, tru) == pytest.approx([0.1, 0.1])
    assert mean_abs_angle_error(np.array([[np.pi - 0.1], [0.2]]), np.array([-np.pi + 0.1])) == pytest.approx([(0.2 + (np.pi - 0.1)) / 2])


def test_bearing_metrics_and_nees():
    rng = np.random.default_rng(0)
    t, X = truth(T=50)
    Xr = np.broadcast_to(X, (400, 50, 5))
    sd = np.array([30.0, 30.0, 2.0, 0.05, 0.002])
    est = Xr + sd * rng.standard_normal((400, 50, 5))
    cov = np.broadcast_to(np.diag(sd ** 2), (400, 50, 5, 5))
    m = bearing_metrics(est, Xr, cov)
    assert m["nees_mean"].mean() == pytest.approx(5.0, rel=0.05)
    assert m["rmse_speed_mps"].mean() == pytest.approx(2.0, rel=0.05)
    assert m["mae_heading_rad"].mean() == pytest.approx(0.05 * np.sqrt(2 / np.pi), rel=0.05)
    e = bearing_errors(est, Xr)
    assert e["heading_rad"].max() < np.pi and set(e) >= {"range_m", "range_rel", "omega_rps"}
    wrapped = est.copy()
    wrapped[..., 3] += 2 * np.pi
    assert bearing_nees(wrapped, cov, Xr) == pytest.approx(bearing_nees(est, cov, Xr))


def test_the_d8_divergence_flag():
    t = np.arange(0, 60, 0.05)
    rel = np.zeros((3, len(t)))
    rel[1, -1] = 0.6  # final range error over 50 %
    q = np.ones((3, len(t)))
    q[2, 200:420] = CHI2_5_0999 + 1  # 11 s above χ²₅(0.999)
    q[0, 100:280] = 30.0  # 9 s: not enough
    q[0, 300:400] = 30.0
    assert divergence_flag(rel, q, t).tolist() == [False, True, True]


def test_the_crlb_with_process_noise_equals_the_ekf_on_the_truth_with_that_noise():
    t, X = truth(T=200)
    P0 = np.diag([200.0 ** 2, 300.0 ** 2, 10.0 ** 2, 0.5 ** 2, 0.05 ** 2])
    Qf = lambda dt: cppv_process_noise(dt, 1e-3, 5e-6)  # noqa: E731
    b = crlb(X, t, P0, SIG, process_noise=Qf)
    ekf = ExtendedKalmanFilter(LinearTransition(np.eye(5), np.zeros((5, 5))), BearingMeasurement(SIG))
    P = P0
    for k in range(1, len(t)):
        F = cppv_jacobian(X[k - 1], t[k] - t[k - 1])
        P = ekf.update(GaussianState(X[k], F @ P @ F.T + Qf(0.05)), np.arctan2(X[k, 1:2], X[k, 0:1])).cov
    assert b.bound[-1] == pytest.approx(P, rel=1e-5, abs=1e-10)
    assert np.all(b.std[-1] >= crlb(X, t, P0, SIG).std[-1])  # noise only loosens the bound


def test_the_crlb_equals_a_brute_force_fisher_information_of_the_initial_state():
    # independent of the recursion: on a deterministic trajectory x_k = f^k(x_0), the bound on
    # x_k is Φ_k J(x_0)⁻¹ Φ_kᵀ with J(x_0) = P₀⁻¹ + Σ_k (H_k Φ_k)ᵀ σ⁻² (H_k Φ_k) and the
    # sensitivities Φ_k = ∂x_k/∂x_0 by central differences of the whole trajectory
    t, X = truth(T=600)
    P0 = np.diag([800.0 ** 2, 900.0 ** 2, 12.0 ** 2, 0.6 ** 2, 0.1 ** 2])

    def traj(x0):
        out = np.empty((len(t), 5))
        out[0] = x0
        for k in range(1, len(t)):
            out[k] = cppv_transition(out[k - 1], 0.05, VO * 0.05)
        return out

    eps = np.array([1e-3, 1e-3, 1e-5, 1e-7, 1e-9])
    Phi = np.stack([(traj(X[0] + e) - traj(X[0] - e)) / (2 * e[i]) for i, e in enumerate(np.diag(eps))], axis=-1)
    r2 = X[:, 0] ** 2 + X[:, 1] ** 2
    H = np.stack([-X[:, 1] / r2, X[:, 0] / r2, 0 * r2, 0 * r2, 0 * r2], axis=-1)
    g = np.einsum("ki,kij->kj", H, Phi)
    J = np.linalg.inv(P0) + np.cumsum(g[:, :, None] * g[:, None, :], axis=0) / SIG ** 2 - g[0][:, None] * g[0] / SIG ** 2
    b = crlb(X, t, P0, SIG)
    for k in (100, 300, 599):
        B = Phi[k] @ np.linalg.inv(J[k]) @ Phi[k].T
        assert b.std[k] == pytest.approx(np.sqrt(np.diag(B)), rel=1e-4)


def test_an_ekf_started_near_the_truth_without_process_noise_attains_the_crlb():
    # the bound is reachable by this EKF algebra: 200 realisations of one orbit, each EKF from
    # x_0 + N(0, P₀) with Q = 0; the sample std of r, v, ω over 30-60 s is √CRLB(P₀) within
    # the sampling error of 200 runs (the bank's miss of issue 16 is not in the filter algebra)
    from pipeline.estimate.bank import Components, CppvModel, components_step

    R, T, dt = 200, 1200, 0.05
    t, X = truth(T=T)
    rng = np.random.default_rng(7)
    P0 = np.diag([100.0 ** 2, 100.0 ** 2, 2.0 ** 2, 0.05 ** 2, 0.002 ** 2])
    z = np.arctan2(X[:, 1], X[:, 0]) + SIG * rng.standard_normal((R, T))
    comp = Components(X[0] + rng.multivariate_normal(np.zeros(5), P0, R)[:, None, :],
                      np.broadcast_to(P0, (R, 1, 5, 5)).copy(), np.zeros((R, 1)), np.zeros((R, 1), bool))
    model = CppvModel(BankSettings(sigma_v2=0.0, sigma_omega_dot2=0.0))
    E = np.empty((R, T, 3))
    for k in range(1, T):
        comp, _ = components_step(model, comp, dt, VO, z[:, k], SIG)
        m = comp.mean[:, 0]
        E[:, k] = np.c_[np.hypot(m[:, 0], m[:, 1]) - np.hypot(*X[k, :2]), m[:, 2] - X[k, 2], m[:, 4] - X[k, 4]]
    b = crlb(X, t, P0, SIG)
    w = t >= 30.0
    ratio = E[:, w].std(axis=0, ddof=1).mean(axis=0) / np.c_[b.range_std, b.std[:, 2], b.std[:, 4]][w].mean(axis=0)
    assert ratio == pytest.approx(np.ones(3), abs=0.12)
