"""The ω → 0-safe coordinated-turn helpers shared by the bearing-only bank, IMM and PFs."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pipeline.estimate.models import (TURN_SERIES_BELOW, ct_jacobian, ct_transition,
                                      turn_coefficient_derivatives, turn_coefficients, turn_coefficients_one,
                                      wrap_angle)


@pytest.mark.parametrize("w", [0.0, 1e-9, -1e-6, 3e-4, -0.02, 0.3, -1.2])
def test_turn_coefficients_match_the_closed_forms_and_their_limit(w):
    T = 0.7
    s, c = turn_coefficients(w, T)
    if abs(w * T) > 1e-2:
        assert s == pytest.approx(np.sin(w * T) / w, rel=1e-13)
        assert c == pytest.approx((1 - np.cos(w * T)) / w, rel=1e-12)
    # high-precision reference from the integral definitions s = ∫cos(wt), c = ∫sin(wt)
    t = np.linspace(0, T, 20001)
    assert s == pytest.approx(np.trapezoid(np.cos(w * t), t), abs=1e-9)
    assert c == pytest.approx(np.trapezoid(np.sin(w * t), t), abs=1e-9)


def test_the_scalar_turn_coefficients_equal_the_vectorised_ones_on_both_sides_of_the_series_switch():
    # the particle kernels of estimate.pf_fast inline the scalar form, compiled by numba
    T = 0.025
    edge = TURN_SERIES_BELOW / T
    w = np.r_[0.0, -0.0, 1e-12, edge * np.array([0.5, 0.999999, 1.0, 1.000001, 2.0]), -edge, 0.3, -1.7, 12.0]
    s, c = turn_coefficients(w, T)
    for wi, si, ci in zip(w, s, c):
        a, b = turn_coefficients_one(float(wi), T)
        assert a == pytest.approx(si, rel=1e-15, abs=0) and b == pytest.approx(ci, rel=1e-14, abs=1e-300)


@pytest.mark.parametrize("w", [0.0, 2e-4, -5e-4, 0.01, -0.4, 1.1])
def test_turn_coefficient_derivatives_equal_central_differences(w):
    T, h = 1.3, 1e-6
    ds, dc = turn_coefficient_derivatives(w, T)
    sp, cp = turn_coefficients(w + h, T)
    sm, cm = turn_coefficients(w - h, T)
    assert ds == pytest.approx((sp - sm) / (2 * h), abs=1e-8)
    assert dc == pytest.approx((cp - cm) / (2 * h), abs=1e-8)


def test_a_positive_turn_rate_turns_right_from_north_toward_east():
    x = np.array([0.0, 0.0, 10.0, 0.0, 0.1])
    y = ct_transition(x, 1.0)
    assert y[3] > 0 and y[1] > 0  # heading north, a right turn gains east velocity and position
    course = np.arctan2(y[3], y[2])
    assert course == pytest.approx(0.1)


@pytest.mark.parametrize("w", [0.0, 1e-7, 0.05, -0.3])
def test_ct_transition_equals_fine_integration_of_the_turn_ode(w):
    x0 = np.array([5.0, -3.0, 20.0, -7.0, w])

    def f(_t, x):
        return [x[2], x[3], -x[4] * x[3], x[4] * x[2], 0.0]

    ref = solve_ivp(f, (0, 2.0), x0, rtol=1e-12, atol=1e-12).y[:, -1]
    np.testing.assert_allclose(ct_transition(x0, 2.0), ref, rtol=1e-9, atol=1e-8)


@pytest.mark.parametrize("w", [0.0, 3e-4, -0.2, 0.9])
def test_ct_jacobian_equals_central_differences_and_keeps_trailing_states(w):
    x = np.array([1.0, 2.0, 15.0, -4.0, w, 3.0])
    F = ct_jacobian(x, 0.5)
    h = 1e-6
    num = np.empty((6, 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        num[:, j] = (ct_transition(x + e, 0.5) - ct_transition(x - e, 0.5)) / (2 * h)
    np.testing.assert_allclose(F, num, atol=1e-6)


def test_turn_helpers_vectorise_over_leading_axes():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4, 3, 5))
    y = ct_transition(x, 0.2)
    F = ct_jacobian(x, 0.2)
    assert y.shape == (4, 3, 5) and F.shape == (4, 3, 5, 5)
    np.testing.assert_allclose(y[2, 1], ct_transition(x[2, 1], 0.2))
    np.testing.assert_allclose(F[3, 0], ct_jacobian(x[3, 0], 0.2))


def test_wrap_angle_maps_into_minus_pi_to_pi():
    a = np.array([0.0, np.pi, -np.pi, 3 * np.pi / 2, -7.0, 7.0])
    w = wrap_angle(a)
    assert np.all(w >= -np.pi) and np.all(w < np.pi)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
