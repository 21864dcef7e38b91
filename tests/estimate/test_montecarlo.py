"""Monte Carlo summaries (run-averaged NIS over measured runs) and the simulator's input checks."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.estimate.base import ConstantAcceleration, GaussianState, position_measurement
from pipeline.estimate.ekf import ExtendedKalmanFilter
from pipeline.estimate.metrics import chi2_band, fraction_in_band
from pipeline.estimate.models import initial_cov
from pipeline.estimate.montecarlo import measure, monte_carlo, simulate_white_jerk

MEAS = position_measurement(1.0)


def _case(R=400, T=60, seed=11):
    truth = simulate_white_jerk(R, T, 0.1, 1.0, np.zeros(9), rng=seed)
    z = measure(MEAS, truth, seed + 1)
    return truth, z, np.arange(T) * 10**8


def _mc(truth, z, t_ns, **kw):
    return monte_carlo(ExtendedKalmanFilter(ConstantAcceleration(1.0), MEAS), truth, z, t_ns,
                       GaussianState(np.zeros(9), initial_cov(), 0), **kw)


def test_with_half_the_fixes_missing_the_run_averaged_nis_still_averages_to_its_dof():
    truth, z, t_ns = _case()
    z[::2, ::2] = np.nan  # half the runs lose every other fix
    z[5] = np.nan         # and one step has no fix at all
    mc = _mc(truth, z, t_ns)
    assert mc.nis_dof == 3
    assert np.isnan(mc.nis_avg[5]) and mc.nis_count[5] == 0
    expected = np.where(np.arange(60) % 2 == 0, 200, 400)
    expected[5] = 0
    assert mc.nis_count.tolist() == expected.tolist()
    assert abs(np.nanmean(mc.nis_avg[10:]) - 3) < 0.1  # was 2.25: the predict-only zeros averaged in
    assert mc.nis_avg[10] == pytest.approx(mc.nis[1::2, 10].mean())
    assert fraction_in_band(mc.nis_avg, mc.nis_dof, mc.nis_count) >= 0.85


def test_fraction_in_band_takes_a_run_count_per_step_and_skips_steps_without_runs():
    lo2, hi2 = chi2_band(3, 2)
    lo4, hi4 = chi2_band(3, 4)
    # 2.9 lies in both bands; hi2 * 0.99 only in the 2-run band
    avg = np.array([2.9, hi2 * 0.99, hi2 * 0.99, np.nan])
    assert hi4 < hi2 * 0.99 < hi2
    assert fraction_in_band(avg, 3, np.array([4, 2, 4, 0])) == pytest.approx(2 / 3)
    assert np.isnan(fraction_in_band(np.array([1.0]), 3, np.array([0])))
    with np.errstate(all="raise"):
        assert np.isnan(fraction_in_band(np.array([]), 3, 10))


def test_monte_carlo_with_store_mean_or_mismatched_shapes_is_one_clear_error():
    truth, z, t_ns = _case(R=3, T=5)
    with pytest.raises(ValueError, match="store must be 'filtered' or 'all'"):
        _mc(truth, z, t_ns, store="mean")
    with pytest.raises(ValueError, match="do not match"):
        _mc(truth[:, :4], z, t_ns)
    with pytest.raises(ValueError, match="do not match"):
        _mc(truth[:2], z, t_ns)


def test_the_simulator_and_measure_refuse_a_missing_rng():
    with pytest.raises(TypeError, match="rng is required"):
        simulate_white_jerk(2, 5, 0.1, 1.0, np.zeros(9), rng=None)
    truth = simulate_white_jerk(2, 5, 0.1, 1.0, np.zeros(9), rng=np.random.default_rng(0))
    with pytest.raises(TypeError, match="rng is required"):
        measure(MEAS, truth, None)


@pytest.mark.parametrize("n_runs, n_steps, dt, q", [(2, 5, 0.1, 0.0), (2, 5, 0.1, -1.0), (2, 5, 0.0, 1.0),
                                                    (2, 5, -0.1, 1.0), (2, 5, np.nan, 1.0), (2, 0, 0.1, 1.0),
                                                    (0, 5, 0.1, 1.0)])
def test_the_simulator_refuses_a_non_positive_step_noise_or_size(n_runs, n_steps, dt, q):
    with pytest.raises(ValueError, match="simulate_white_jerk"):
        simulate_white_jerk(n_runs, n_steps, dt, q, np.zeros(9), rng=0)
