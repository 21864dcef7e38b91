"""The fused numba particle-filter kernels (the speed path of issue 17's benchmark)."""

import numba
import numpy as np
import pytest
from scipy import stats

from pipeline.estimate import pf_fast
from pipeline.estimate.models import PfAugmentedCoordinatedTurn, PfConstantAcceleration, PfConstantVelocity
from pipeline.estimate.pf import GaussianPositionLikelihood, ParticleFilter, run_pf

from .test_pf import DT, SIG_A, SIG_Z, cv_track


def test_the_kernel_generator_draws_standard_normals():
    x = pf_fast.standard_normals(400_000, 5)
    assert abs(x.mean()) < 4 / np.sqrt(x.size)
    assert x.std() == pytest.approx(1.0, abs=4 * np.sqrt(2 / x.size))
    assert stats.kstest(x, "norm").pvalue > 1e-3
    assert abs(stats.kurtosis(x)) < 0.05  # the ziggurat tails are there


def test_the_fused_cv_bootstrap_filter_matches_the_kalman_filter_mean():
    Z = cv_track()
    m0, P0 = np.array([0.0, 0.0, 2.0, 0.0]), np.diag([4.0, 4.0, 4.0, 4.0])
    n, seeds = 20_000, 10
    # the kernel predicts before every measurement, so the KF does too
    kf = np.array([m for m, _ in _cv_kalman_from_predict(m0, P0, Z)])
    # independent runs (prior sample and seed), so their spread is the Monte Carlo error
    # (every-step resampling accumulates it: one step's sd/√N_eff would understate it)
    runs = np.array([pf_fast.cv_bootstrap_run(np.random.default_rng(100 + s).multivariate_normal(m0, P0, n),
                                              Z, DT, SIG_A, SIG_Z, seed=s)[0] for s in range(seeds)])
    sd = runs.std(axis=0, ddof=1)
    # 6 se: a t-bound with 9 degrees of freedom over 80 comparisons
    assert np.all(np.abs(runs.mean(axis=0) - kf) <= 6 * sd / np.sqrt(seeds) + 1e-9)
    assert np.all(np.abs(runs - kf) <= 6 * sd + 1e-9)


def _cv_kalman_from_predict(m0, P0, Z):
    F = np.eye(4)
    F[0, 2] = F[1, 3] = DT
    G = np.zeros((4, 2))
    G[0, 0] = G[1, 1] = DT * DT / 2
    G[2, 0] = G[3, 1] = DT
    Q, H, R = SIG_A ** 2 * G @ G.T, np.eye(2, 4), SIG_Z ** 2 * np.eye(2)
    m, P, out = m0.copy(), P0.copy(), []
    for z in Z:
        m, P = F @ m, F @ P @ F.T + Q
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        m, P = m + K @ (z - H @ m), (np.eye(4) - K @ H) @ P
        out.append((m, P))
    return out


@pytest.mark.slow  # 5-6 s on a cold numba cache; the full suite keeps the thread-count check
def test_kernel_results_do_not_depend_on_the_thread_count():
    rng = np.random.default_rng(0)
    n = 3 * pf_fast.BLOCK + 17
    x0 = rng.standard_normal((n, 7))
    modes = rng.integers(0, 3, n)
    Z = cv_track(6)
    Z[2] = np.nan
    Pi = [[0.9, 0.05, 0.05], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8]]
    args = (DT, Pi, [0, 1, 2], [0.5, 0.5, 0.5], [0, 0, 0.05], [0, 2.0, 0.1], SIG_Z, 4)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        a = pf_fast.cv_bootstrap_run(x0[:, :4], Z, DT, SIG_A, SIG_Z, 9)
        ja = pf_fast.jm_run(x0, modes, Z, *args)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        b = pf_fast.cv_bootstrap_run(x0[:, :4], Z, DT, SIG_A, SIG_Z, 9)
        jb = pf_fast.jm_run(x0, modes, Z, *args)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    for u, v in zip(ja, jb):
        assert np.array_equal(u, v)


def test_the_fused_jump_markov_step_agrees_with_the_generic_filter():
    Z = cv_track(30, seed=4)
    Pi = np.array([[0.9, 0.05, 0.05], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8]])
    n = 40_000
    rng = np.random.default_rng(2)
    x0 = np.zeros((n, 7))
    x0[:, :4] = rng.multivariate_normal([0, 0, 3, -1], np.eye(4), n)
    modes = rng.integers(0, 3, n)
    mean, mode_p, _, _ = pf_fast.jm_run(x0, modes, Z, DT, Pi, [0, 1, 2], [SIG_A, 0.5, SIG_A],
                                        [0, 0, 0.05], [0, 2.0, 0.1], SIG_Z, 1)
    models = [PfConstantVelocity(SIG_A), PfConstantAcceleration(0.5, 2.0),
              PfAugmentedCoordinatedTurn(SIG_A, 0.05, omega_init_sigma=0.1)]
    pf = ParticleFilter(models, Pi, GaussianPositionLikelihood(SIG_Z), n_particles=n, every_step=True, rng=5)
    pf.init(x0, modes=modes)
    t = np.arange(len(Z)) * int(DT * 1e9)
    tr = run_pf(pf, t, Z, t0_ns=-int(DT * 1e9))
    assert np.allclose(mean[:, :4], tr.mean[:, :4], atol=0.15)
    assert np.allclose(mode_p, tr.mode_p, atol=0.03)
