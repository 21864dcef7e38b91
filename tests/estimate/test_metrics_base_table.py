"""Metrics closed forms (RMSE per group, NEES, χ² bands, best/worst run), the frozen Gaussian
state, and the estimator output table round trip."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from pipeline.estimate.base import GaussianState
from pipeline.estimate.metrics import best_worst, chi2_band, fraction_in_band, nees, rmse, rmse_groups
from pipeline.estimate.models import initial_cov
from pipeline.estimate.table import P_COLUMNS, X_COLUMNS, estimate_frame, frame_arrays
from pipeline.io import schema


def test_rmse_per_group_is_the_closed_form_on_constant_errors():
    err = np.zeros((4, 10, 9))
    err[..., 0:3] = [3.0, 4.0, 0.0]
    err[..., 4] = -2.0
    err[..., 8] = 0.5
    g = rmse_groups(err)
    assert g["pos_n_m"] == 3 and g["pos_e_m"] == 4 and g["pos"] == 5
    assert g["vel_e_mps"] == 2 and g["vel"] == 2 and g["acc_d_mps2"] == 0.5 and g["acc"] == 0.5
    np.testing.assert_array_equal(rmse(err), [3, 4, 0, 0, 2, 0, 0, 0, 0.5])


def test_nees_of_an_error_with_a_diagonal_covariance_is_the_weighted_sum_of_squares():
    P = initial_cov()
    e = np.r_[[1.0] * 3, [0.1] * 3, [0.02] * 3]
    assert nees(e, P) == pytest.approx(3 + 3 + 12)
    assert nees(np.tile(e, (2, 5, 1)), np.broadcast_to(P, (2, 5, 9, 9))).shape == (2, 5)


def test_the_chi2_band_of_a_run_average_is_the_scaled_chi2_quantile():
    lo, hi = chi2_band(9, 1000)
    assert lo == pytest.approx(chi2.ppf(0.025, 9000) / 1000) and hi == pytest.approx(chi2.ppf(0.975, 9000) / 1000)
    assert fraction_in_band(np.array([lo - 1e-9, 9.0, hi + 1e-9, 9.1]), 9, 1000) == 0.5


def test_best_and_worst_runs_have_the_lowest_and_highest_summed_absolute_error():
    err = np.ones((5, 3, 9))
    err[2] *= 0.1
    err[4] *= -7
    assert best_worst(err) == (2, 4)


def test_a_gaussian_state_is_frozen_read_only_shares_the_given_arrays_and_checks_its_shapes():
    m = np.zeros(9)
    s = GaussianState(m, initial_cov(), 5)
    with pytest.raises(AttributeError):
        s.t_ns = 3
    with pytest.raises(ValueError):
        s.mean[0] = 1.0
    m[0] = 2.0  # the caller's array stays writeable, and the state is a view of it (no copy)
    assert s.mean[0] == 2.0 and np.shares_memory(s.mean, m)
    assert s.batch_shape == () and s.n_x == 9
    with pytest.raises(ValueError, match="cov shape"):
        GaussianState(np.zeros((2, 9)), initial_cov(), 0)


def test_the_estimate_table_round_trips_the_mean_and_the_full_covariance(rng):
    T = 6
    A = rng.standard_normal((T, 9, 9))
    P = A @ np.swapaxes(A, 1, 2)
    P = 0.5 * (P + np.swapaxes(P, 1, 2))  # exactly symmetric
    m = rng.standard_normal((T, 9))
    df = estimate_frame(np.arange(T) * 10, m, P, nis=np.ones(T))
    assert list(df.columns) == schema.column_names("estimate")
    assert list(df.columns) == ["t_ns", *X_COLUMNS, *P_COLUMNS, "nis", "nees"] and len(P_COLUMNS) == 45
    assert X_COLUMNS[0] == "x_pos_n_m" and X_COLUMNS[-1] == "x_acc_d_mps2" and df["nees"].isna().all()
    t, m2, P2 = frame_arrays(df)
    np.testing.assert_array_equal(m2, m)
    np.testing.assert_array_equal(P2, P)
    np.testing.assert_array_equal(t, np.arange(T) * 10)


def test_a_run_without_a_finite_error_is_neither_best_nor_worst():
    assert best_worst(np.array([[[1.0]], [[np.nan]], [[0.5]]])) == (2, 0)
    err = np.ones((3, 4, 9))
    err[0] = np.nan
    err[2] *= 3
    assert best_worst(err) == (1, 2)
    with pytest.raises(ValueError, match="none of the 2 runs has a finite error"):
        best_worst(np.full((2, 3, 9), np.nan))


def test_nees_is_nan_where_the_covariance_is_not_positive_definite():
    assert np.isnan(nees([1.0, 2.0], np.diag([1.0, -4.0])))  # indefinite: was 0.0
    assert np.isnan(nees([1.0, 2.0], np.diag([1.0, 0.0])))   # singular: was a bare LinAlgError
    P = np.stack([np.diag([1.0, -4.0]), np.diag([1.0, 4.0]), np.diag([np.nan, 1.0]), np.zeros((2, 2))])
    out = nees(np.ones((4, 2)), P)
    assert np.isnan(out[[0, 2, 3]]).all() and out[1] == pytest.approx(1.25)
    # one shared covariance against a batch of errors, and the positive definite fast path unchanged
    assert nees(np.ones((2, 3, 2)), np.diag([1.0, 4.0])) == pytest.approx(np.full((2, 3), 1.25))


def test_divergence_flag_without_steps_or_with_mismatched_lengths_is_one_clear_error():
    from pipeline.estimate.metrics import divergence_flag

    with pytest.raises(ValueError, match="T = 0"):
        divergence_flag(np.zeros((2, 0)), np.zeros((2, 0)), np.zeros(0))
    with pytest.raises(ValueError, match="do not match"):
        divergence_flag(np.zeros((2, 5)), np.zeros((2, 5)), np.arange(4.0))
    with pytest.raises(ValueError, match="do not match"):
        divergence_flag(np.zeros((2, 5)), np.zeros((2, 4)), np.arange(5.0))
    assert divergence_flag(np.zeros((2, 5)), np.zeros((2, 5)), np.arange(5.0)).tolist() == [False, False]
