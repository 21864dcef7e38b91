"""The framework extensions the trajectory learner needs: ``log|S|`` per update and the
prediction-error log-likelihood against the joint Gaussian of the whole measurement sequence,
many stacked rows with some missing (LAPACK path, missing rows left out), and the ``bu`` input
of ``run_filter``."""

from __future__ import annotations

import numpy as np
from scipy.stats import multivariate_normal

from pipeline.estimate.base import GaussianState, LinearMeasurement, LinearTransition
from pipeline.estimate.ekf import ExtendedKalmanFilter, run_filter


def _model(rng, n_x=3, n_z=2):
    F = np.eye(n_x) + 0.1 * rng.standard_normal((n_x, n_x))
    A = rng.standard_normal((n_x, n_x))
    Q = 0.1 * A @ A.T + 0.05 * np.eye(n_x)
    H = rng.standard_normal((n_z, n_x))
    B = rng.standard_normal((n_z, n_z))
    R = 0.2 * B @ B.T + 0.1 * np.eye(n_z)
    return F, Q, H, R


def _joint_loglik(F, Q, H, R, m0, P0, z, bu=None):
    """log N(vec z; mean, cov) of the stacked sequence (rows of z: (T, M, n_z), NaN missing)."""
    T = z.shape[0]
    n_x = len(m0)
    # x_k = F^k x_0 + Σ F^(k-1-j) (w_j + bu): mean and the covariance between all x_k, x_l
    Phi = [np.eye(n_x)]
    for k in range(1, T):
        Phi.append(F @ Phi[-1])
    mean_x = [m0]
    for k in range(1, T):
        mean_x.append(F @ mean_x[-1] + (0 if bu is None else bu[k]))
    Cx = np.zeros((T, T, n_x, n_x))
    for k in range(T):
        for l in range(T):
            c = Phi[k] @ P0 @ Phi[l].T
            for j in range(1, min(k, l) + 1):
                c = c + Phi[k - j] @ Q @ Phi[l - j].T
            Cx[k, l] = c
    rows, mu, idx = [], [], []
    for k in range(T):
        for m in range(z.shape[1]):
            if not np.isnan(z[k, m]).any():
                rows.append(z[k, m]); mu.append(H @ mean_x[k]); idx.append(k)
    n_z = H.shape[0]
    S = np.zeros((len(idx) * n_z, len(idx) * n_z))
    for a, k in enumerate(idx):
        for b, l in enumerate(idx):
            S[a * n_z:(a + 1) * n_z, b * n_z:(b + 1) * n_z] = H @ Cx[k, l] @ H.T + (R if a == b else 0)
    return multivariate_normal(np.concatenate(mu), S).logpdf(np.concatenate(rows))


def test_the_filter_loglik_equals_the_joint_gaussian_of_the_stacked_measurements_with_gaps(rng):
    F, Q, H, R = _model(rng)
    T, M = 6, 5  # 5 × 2 = 10 stacked rows: the LAPACK path
    z = rng.standard_normal((T, M, 2))
    z[rng.random((T, M)) < 0.4] = np.nan
    z[2] = np.nan  # one predict-only step
    m0, P0 = rng.standard_normal(3), np.eye(3) * 0.7
    bu = 0.3 * rng.standard_normal((T, 3))
    ekf = ExtendedKalmanFilter(LinearTransition(F, Q), LinearMeasurement(H, R))
    tr = run_filter(ekf, GaussianState(m0, P0, 0), np.arange(T) * 10, z[:, None], bu=bu)
    np.testing.assert_allclose(tr.loglik()[0], _joint_loglik(F, Q, H, R, m0, P0, z, bu), rtol=1e-10)
    assert tr.dof[0, 2] == 0 and tr.logdet[0, 2] == 0


def test_the_loglik_of_single_measurements_on_the_planes_path_equals_the_joint_gaussian(rng):
    F, Q, H, R = _model(rng)
    T = 5
    z = rng.standard_normal((T, 1, 2))
    z[3] = np.nan
    m0, P0 = rng.standard_normal(3), np.eye(3)
    ekf = ExtendedKalmanFilter(LinearTransition(F, Q), LinearMeasurement(H, R))
    tr = run_filter(ekf, GaussianState(m0, P0, 0), np.arange(T) * 10, z[:, None])
    np.testing.assert_allclose(tr.loglik()[0], _joint_loglik(F, Q, H, R, m0, P0, z), rtol=1e-10)


def test_many_stacked_rows_with_some_missing_equal_the_sequential_updates_of_the_present_ones(rng):
    F, Q, H, R = _model(rng, n_x=4, n_z=3)
    ekf = ExtendedKalmanFilter(LinearTransition(F, Q), LinearMeasurement(H, R))
    pred = GaussianState(rng.standard_normal(4), np.eye(4) * 2.0, 0)
    z = rng.standard_normal((5, 3))
    z[[1, 3]] = np.nan
    post, st = ekf.update_stats(pred, z)
    seq = pred
    for row in z[[0, 2, 4]]:
        seq = ekf.update(seq, row)
    np.testing.assert_allclose(post.mean, seq.mean, rtol=1e-10)
    np.testing.assert_allclose(post.cov, seq.cov, rtol=1e-9, atol=1e-12)
    assert st.dof == 9
