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


# -- bad input: one clear error before any kernel runs ------------------------------------------------

_PI3 = np.array([[0.9, 0.05, 0.05], [0.05, 0.9, 0.05], [0.05, 0.05, 0.9]])
_JM = dict(dt=0.1, Pi_dt=_PI3, kinds=[0, 1, 2], sigma=[1.0, 1.0, 1.0], sigma_omega=[0.1, 0.1, 0.1],
           enter_sigma=[1.0, 1.0, 0.1], sigma_z=1.0, seed=7)


def _jm(**kw):
    x0 = kw.pop("x0", np.zeros((50, 7)))
    mode0 = kw.pop("mode0", np.zeros(50, dtype=np.int64))
    z = kw.pop("z", np.zeros((3, 2)))
    return pf_fast.jm_run(x0, mode0, z, **{**_JM, **kw})


@pytest.mark.parametrize("bad, match", [
    (dict(sigma=[1.0, 1.0]), r"sigma must have one entry per mode kind \(K = len\(kinds\) = 3\)"),
    (dict(sigma_omega=[0.1] * 4), r"sigma_omega must have one entry per mode kind"),
    (dict(enter_sigma=[1.0]), r"enter_sigma must have one entry per mode kind"),
    (dict(sigma=[1.0, np.nan, 1.0]), r"sigma\[1\] must be a finite number >= 0"),
    (dict(enter_sigma=[1.0, -1.0, 0.1]), r"enter_sigma\[1\] must be a finite number >= 0"),
    (dict(mode0=np.full(50, 5)), r"mode0 must lie in \[0, 3\).*particle 0 has mode 5"),
    (dict(mode0=np.r_[np.zeros(49, int), -1]), r"particle 49 has mode -1"),
    (dict(mode0=np.zeros(49, int)), r"mode0 must have shape \(50,\)"),
    (dict(mode0=np.full(50, 0.5)), r"mode0 must hold integer mode indices"),
    (dict(Pi_dt=[[0.5, 0.6, 0.1], [0, 1, 0], [0, 0, 1]]), r"Pi_dt row 0 sums to 1.2"),
    (dict(Pi_dt=[[1.0, 0, 0], [0, 1, 0], [0, 0, 0.9]]), r"Pi_dt row 2 sums to 0.9"),
    (dict(Pi_dt=[[1.2, -0.2, 0], [0, 1, 0], [0, 0, 1]]), r"Pi_dt row 0 has a negative probability"),
    (dict(Pi_dt=[[np.nan, 0.5, 0.5], [0, 1, 0], [0, 0, 1]]), r"Pi_dt row 0 is not finite"),
    (dict(Pi_dt=np.eye(2)), r"Pi_dt must be 3x3"),
    (dict(kinds=[0, 1, 7]), r"kinds must be KIND_CV"),
    (dict(x0=np.zeros((50, 4))), r"particles must have shape \(N, 7\)"),
    (dict(z=np.zeros((3, 3))), r"z must have shape \(T, 2\)"),
    (dict(sigma_z=0.0), r"sigma_z must be a positive finite number"),
    (dict(dt=np.nan), r"dt must be a positive finite number"),
])
def test_the_jump_markov_run_refuses_mismatched_mode_settings_with_one_clear_error(bad, match):
    with pytest.raises(ValueError, match=match):
        _jm(**bad)


def test_the_jump_markov_run_keeps_a_pi_whose_rows_miss_one_by_round_off_only():
    # an asymmetric Π (its transpose or a column normalisation is another chain), rows off by
    # ±4e-10, within the 1e-9 row-sum tolerance
    exact = np.array([[0.8, 0.15, 0.05], [0.1, 0.7, 0.2], [0.05, 0.25, 0.7]])
    pi = exact.copy()
    pi[0, 0] += 4e-10
    pi[1, 1] -= 4e-10
    pi[2, 2] += 2e-10
    n, T = 3000, 8
    x0 = np.random.default_rng(3).standard_normal((n, 7))
    kw = dict(x0=x0, mode0=np.arange(n) % 3, z=0.1 * cv_track(T, seed=6), sigma_z=2.0)
    a = _jm(Pi_dt=pi, **kw)
    # the same seed on the row-renormalised Π: a draw falls in a 1e-10 sliver with probability
    # ~N·T·1e-10, so every particle takes the same mode, draw for draw
    b = _jm(Pi_dt=pi / pi.sum(axis=1, keepdims=True), **kw)
    for u, v in zip(a, b):
        np.testing.assert_array_equal(u, v)
    assert np.all(np.isfinite(a[0])) and np.allclose(a[1].sum(axis=1), 1.0)
    # ... and the chain used is Π's rows as given: one step from mode 0 lands in modes 0, 1, 2
    # with 0.8, 0.15, 0.05 (Πᵀ's first row would give 0.8, 0.1, 0.1), on a predict-only step
    # so that no resampling reshuffles the modes
    m = 20_000
    c = _jm(Pi_dt=pi, x0=np.zeros((m, 7)), mode0=np.zeros(m, dtype=np.int64), z=np.full((1, 2), np.nan))
    frac = np.bincount(c[3], minlength=3) / m
    assert np.all(np.abs(frac - exact[0]) < 4 * np.sqrt(exact[0] * (1 - exact[0]) / m)), frac


@pytest.mark.parametrize("x0, z, kw, match", [
    (np.zeros((4, 1000)), np.zeros((5, 2)), {}, r"x0 must have shape \(N, 4\)"),   # transposed
    (np.zeros((1000, 7)), np.zeros((5, 2)), {}, r"x0 must have shape \(N, 4\)"),
    (np.zeros((0, 4)), np.zeros((5, 2)), {}, r"x0 must have shape \(N, 4\) with N >= 1"),
    (np.zeros((100, 4)), np.zeros((5, 3)), {}, r"z must have shape \(T, 2\)"),
    (np.zeros((100, 4)), np.zeros(5), {}, r"z must have shape \(T, 2\)"),
    (np.zeros((100, 4)), np.zeros((5, 2)), dict(sigma_z=np.nan), "sigma_z must be a positive finite number"),
    (np.zeros((100, 4)), np.zeros((5, 2)), dict(sigma_z=0.0), "sigma_z must be a positive finite number"),
    (np.zeros((100, 4)), np.zeros((5, 2)), dict(sigma_z=-1.0), "sigma_z must be a positive finite number"),
    (np.zeros((100, 4)), np.zeros((5, 2)), dict(sigma_a=-1.0), "sigma_a must be a positive finite number"),
    (np.zeros((100, 4)), np.zeros((5, 2)), dict(sigma_a=np.inf), "sigma_a must be a positive finite number"),
    (np.zeros((100, 4)), np.zeros((5, 2)), dict(dt=0.0), "dt must be a positive finite number"),
    (np.zeros((100, 4)), np.zeros((5, 2)), dict(dt=-0.1), "dt must be a positive finite number"),
    (np.zeros((100, 4)), np.zeros((5, 2)), dict(dt="0.1"), "dt must be a positive finite number"),
])
def test_the_cv_bootstrap_run_refuses_bad_shapes_and_noise_levels_with_one_clear_error(x0, z, kw, match):
    with pytest.raises(ValueError, match=match):
        pf_fast.cv_bootstrap_run(x0, z, **{"dt": 0.1, "sigma_a": 1.0, "sigma_z": 1.0, "seed": 3, **kw})
