"""Filter correctness beyond test_ekf.py: the radar EKF against filterpy's ExtendedKalmanFilter,
the RTS smoother's consistency on the filter's own model, and the issue's NEES acceptance with
the seed-000 Ch. 2 initialisation (a perturbed truth start), each against a closed form or a
library oracle."""

from __future__ import annotations

import numpy as np

from pipeline.estimate.base import ConstantAcceleration, GaussianState
from pipeline.estimate.ekf import ExtendedKalmanFilter, run_filter
from pipeline.estimate.metrics import chi2_band, fraction_in_band, nees
from pipeline.estimate.models import RadarModel, ca_transition, initial_cov, white_jerk_q
from pipeline.estimate.montecarlo import measure, monte_carlo, simulate_white_jerk
from pipeline.estimate.smoother import rts_smooth

from filterpy import kalman  # noqa: E402  (the test extra: the oracle, never skipped)

DT = 0.2
DT_NS = 200_000_000
X0 = np.array([400.0, -300.0, -120.0, 8.0, 5.0, -1.0, 0.3, -0.2, 0.1])
RADAR = RadarModel(site_ned_m=(-200.0, 150.0, 0.0), tau_rd_s=0.01)


def _rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def test_with_the_radar_the_ekf_equals_filterpys_extended_kalman_filter_run_by_run(rng):
    # the benchmark's baseline: filterpy's EKF stepping each run with the analytic Jacobian
    n_runs, n_steps, q = 3, 150, 1.0
    truth = simulate_white_jerk(n_runs, n_steps, DT, q, X0, rng=rng)
    z = measure(RADAR, truth, rng)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), RADAR)
    x0 = truth[:, 0] + rng.standard_normal((n_runs, 9)) * np.sqrt(np.diag(initial_cov()))
    track = run_filter(ekf, GaussianState(x0, np.broadcast_to(initial_cov(), (n_runs, 9, 9)), 0),
                       np.arange(n_steps) * DT_NS, z)
    for r in range(n_runs):
        f = kalman.ExtendedKalmanFilter(dim_x=9, dim_z=4)
        f.x, f.P, f.F, f.Q, f.R = x0[r].copy(), initial_cov(), ca_transition(DT), white_jerk_q(DT, q), RADAR.R
        for k in range(n_steps):
            if k:
                f.predict()
            f.update(z[k, r], RADAR.jacobian, RADAR.h)
            # filterpy inverts S with LAPACK, ours by Cholesky planes: equal to round-off
            assert _rel(track.mean[r, k], f.x) < 1e-12, (r, k)
            assert _rel(track.cov[r, k], f.P) < 1e-9, (r, k)


def test_on_its_own_model_the_rts_smoothed_nees_is_consistent_and_below_the_filtered_error():
    rng = np.random.default_rng(1414)
    n_runs, n_steps, q = 1000, 80, 1.0
    truth = simulate_white_jerk(n_runs, n_steps, DT, q, X0, rng=rng)
    z = measure(RADAR, truth, rng)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), RADAR)
    mc = monte_carlo(ekf, truth, z, np.arange(n_steps) * DT_NS, GaussianState(X0, initial_cov(), 0), store="all")
    sm = rts_smooth(mc.track)
    e = sm.mean - truth
    ne = nees(e, sm.cov).mean(axis=0)
    assert fraction_in_band(ne, 9, n_runs) >= 0.90
    assert abs(ne.mean() - 9) <= 0.3
    # the smoother's own variance matches its Monte Carlo error variance, and is below the filter's
    ratio = e.var(axis=0, ddof=1)[5:-5] / np.diagonal(sm.cov, axis1=-2, axis2=-1).mean(axis=0)[5:-5]
    assert 0.85 < np.median(ratio) < 1.15
    assert np.mean(e ** 2) < np.mean(mc.err ** 2)


def test_with_the_seed000_chapter2_start_the_run_averaged_nees_meets_the_issue_band():
    # Ch. 2 MC initialisation x̂₀ = x₀ + [1·randn(3); 0.1·randn(3); 0.01·randn(3)], P₀ alike, on
    # 1000 runs of truth from the filter's own white-jerk model (one radar realisation each)
    rng = np.random.default_rng(2021)
    n_runs, n_steps, q = 1000, 120, 0.5
    truth = simulate_white_jerk(n_runs, n_steps, DT, q, X0, P0=1e-18 * np.eye(9), rng=rng)  # one start, as the MC sets
    z = measure(RADAR, truth, rng)
    x0 = truth[:, 0] + rng.standard_normal((n_runs, 9)) * np.sqrt(np.diag(initial_cov()))
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), RADAR)
    mc = monte_carlo(ekf, truth, z, np.arange(n_steps) * DT_NS,
                     GaussianState(x0, np.broadcast_to(initial_cov(), (n_runs, 9, 9)), 0))
    lo, hi = chi2_band(9, n_runs)
    inside = (mc.nees_avg >= lo) & (mc.nees_avg <= hi)
    assert inside.mean() >= 0.90
    assert abs(mc.nees_avg.mean() - 9) <= 0.3
    # the band is that of χ²(9000)/1000
    from scipy.stats import chi2

    np.testing.assert_allclose([lo, hi], chi2.ppf([0.025, 0.975], 9000) / 1000, rtol=1e-12)
