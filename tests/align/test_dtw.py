"""DTW (seed 004 §1, eqs. 2.18–2.25) against dtw-python and dtaidistance, properties, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from pipeline.align.dtw import DtwResult, dtw, dtw_distance, feature_scale

import dtw as dtw_python  # noqa: E402  (the test extra: an oracle, never skipped)
from dtaidistance import dtw_ndim  # noqa: E402

PATTERNS = ("symmetric1", "symmetric2", "asymmetricP0")


def _reference(x, y, pattern, window):
    kw = {} if window is None else {"window_type": "sakoechiba", "window_args": {"window_size": window}}
    return dtw_python.dtw(x, y, dist_method="euclidean", step_pattern=pattern, **kw)


def _cases(rng, count):
    """Random (x, y, window) of mixed lengths and widths, windows from |n − m| up."""
    out = []
    for _ in range(count):
        n, m, D = int(rng.integers(1, 30)), int(rng.integers(1, 30)), int(rng.integers(1, 5))
        x, y = rng.standard_normal((n, D)), rng.standard_normal((m, D))
        out += [(x, y, None), (x, y, abs(n - m) + int(rng.integers(0, 6)))]
    return out


@pytest.mark.parametrize("pattern", PATTERNS)
def test_distance_normalised_distance_and_path_equal_dtw_python_on_random_inputs(pattern, rng):
    for x, y, window in _cases(rng, 25):
        ref = _reference(x, y, pattern, window)
        ours = dtw(x, y, step_pattern=pattern, window=window)
        assert ours.distance == pytest.approx(ref.distance, rel=1e-12, abs=1e-12)
        if pattern == "symmetric1":  # no path-independent normaliser: NaN in both
            assert np.isnan(ours.normalized_distance) and np.isnan(ref.normalizedDistance)
        else:
            assert ours.normalized_distance == pytest.approx(ref.normalizedDistance, rel=1e-12, abs=1e-12)
        np.testing.assert_array_equal(ours.path, np.c_[ref.index1, ref.index2])
        assert dtw_distance(x, y, step_pattern=pattern, window=window) == pytest.approx(ours.distance, rel=1e-12, abs=1e-12)


def test_the_normalisers_are_the_seeds_weights_sums_n_plus_m_and_n(rng):
    x, y = rng.standard_normal((12, 2)), rng.standard_normal((17, 2))
    s2, p0 = dtw(x, y, step_pattern="symmetric2"), dtw(x, y, step_pattern="asymmetricP0")
    assert s2.normalized_distance == pytest.approx(s2.distance / (12 + 17))  # (2.25): Σ(Δi + Δj)
    assert p0.normalized_distance == pytest.approx(p0.distance / 12)  # (2.24): Σ Δi


def test_one_dimensional_inputs_equal_their_column_form(rng):
    x, y = rng.standard_normal(20), rng.standard_normal(25)
    a, b = dtw(x, y), dtw(x[:, None], y[:, None])
    assert a.distance == b.distance
    np.testing.assert_array_equal(a.path, b.path)
    ref = _reference(x, y, "symmetric2", None)
    assert a.distance == pytest.approx(ref.distance, rel=1e-12)


def test_sqrt_of_unit_weights_and_squared_cost_equals_dtaidistance_with_window_r_plus_1(rng):
    # dtaidistance: symmetric1 over squared Euclidean costs, the square root at the end; its
    # window w keeps |i − j| < w, i.e. our r = w − 1. On unequal lengths it widens its band by
    # |n − m| on the longer side (−(w−1) ≤ j − i ≤ w − 1 + m − n), where ours (dtw-python's
    # sakoechiba) stays |i − j| ≤ r, so windows are compared on equal lengths and unequal
    # lengths without a window
    for n, r in [(40, 0), (40, 1), (40, 5), (50, 100), (33, 7)]:
        for _ in range(3):
            x, y = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
            ours = dtw(x, y, step_pattern="symmetric1", local="sqeuclidean", window=r)
            theirs = dtw_ndim.distance(x, y, window=r + 1, use_c=True)
            assert np.sqrt(ours.distance) == pytest.approx(theirs, rel=1e-12)
            np.testing.assert_array_equal(ours.path, np.asarray(dtw_ndim.warping_path(x, y, window=r + 1, use_c=True)))
    for n, m in [(40, 47), (47, 40), (1, 9), (25, 60)]:
        x, y = rng.standard_normal((n, 3)), rng.standard_normal((m, 3))
        ours = dtw(x, y, step_pattern="symmetric1", local="sqeuclidean")
        assert np.sqrt(ours.distance) == pytest.approx(dtw_ndim.distance(x, y, use_c=True), rel=1e-12)
        np.testing.assert_array_equal(ours.path, np.asarray(dtw_ndim.warping_path(x, y, use_c=True)))


def test_a_window_of_zero_on_equal_lengths_is_the_diagonal_sum(rng):
    x, y = rng.standard_normal((30, 4)), rng.standard_normal((30, 4))
    res = dtw(x, y, step_pattern="symmetric1", window=0)
    assert res.distance == pytest.approx(np.linalg.norm(x - y, axis=1).sum())
    np.testing.assert_array_equal(res.path, np.c_[np.arange(30), np.arange(30)])


def test_a_window_never_lowers_the_distance_and_a_wide_one_changes_nothing(rng):
    x, y = rng.standard_normal((40, 2)), rng.standard_normal((35, 2))
    free = dtw_distance(x, y)
    for r in (5, 10, 20):
        assert dtw_distance(x, y, window=r) >= free - 1e-12
    assert dtw_distance(x, y, window=40) == free


def test_std_scaling_equals_dividing_both_series_by_the_pooled_std(rng):
    x = rng.standard_normal((30, 3)) * [1.0, 100.0, 0.01]
    y = rng.standard_normal((25, 3)) * [1.0, 100.0, 0.01]
    s = np.concatenate([x, y]).std(axis=0)
    np.testing.assert_allclose(feature_scale("std", x, y), s)
    a = dtw(x, y, scale="std")
    b = dtw(x / s, y / s)
    assert a.distance == pytest.approx(b.distance, rel=1e-12)
    np.testing.assert_array_equal(a.path, b.path)
    c = dtw(x, y, scale=[1.0, 100.0, 0.01])
    assert c.distance == pytest.approx(dtw(x / [1.0, 100.0, 0.01], y / [1.0, 100.0, 0.01]).distance, rel=1e-12)


def test_a_constant_feature_gets_unit_scale():
    x = np.c_[np.arange(5.0), np.ones(5)]
    np.testing.assert_array_equal(feature_scale("std", x, x)[1], 1.0)


def test_squared_local_cost_matches_dtw_python_with_a_squared_distance_matrix(rng):
    from scipy.spatial.distance import cdist

    x, y = rng.standard_normal((20, 3)), rng.standard_normal((23, 3))
    ref = dtw_python.dtw(cdist(x, y, "sqeuclidean"), step_pattern="symmetric2")
    ours = dtw(x, y, local="sqeuclidean")
    assert ours.distance == pytest.approx(ref.distance, rel=1e-12)
    np.testing.assert_array_equal(ours.path, np.c_[ref.index1, ref.index2])


series = st.integers(1, 25).flatmap(lambda n: arrays(np.float64, (n, 2), elements=st.floats(-10, 10, width=32)))


@settings(max_examples=60, deadline=None)
@given(series, series)
def test_symmetric2_is_symmetric_and_the_path_is_monotone_continuous_and_anchored(x, y):
    a, b = dtw(x, y), dtw(y, x)
    assert a.distance == pytest.approx(b.distance, rel=1e-9, abs=1e-9)
    p = a.path
    assert p.dtype == np.int64 and p.shape[1] == 2
    assert tuple(p[0]) == (0, 0) and tuple(p[-1]) == (len(x) - 1, len(y) - 1)
    steps = np.diff(p, axis=0)
    assert ((steps == 0) | (steps == 1)).all() and (steps.sum(axis=1) >= 1).all()
    # the path's cost with the (2.25) weights is the distance
    d = np.linalg.norm(x[p[:, 0]] - y[p[:, 1]], axis=1)
    w = np.r_[1, steps.sum(axis=1)]
    assert (d * w).sum() == pytest.approx(a.distance, rel=1e-9, abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(series, st.sampled_from(PATTERNS), st.sampled_from(["euclidean", "sqeuclidean"]))
def test_a_series_against_itself_has_distance_zero_and_the_diagonal_path(x, pattern, local):
    res = dtw(x, x, step_pattern=pattern, local=local, window=0)
    assert res.distance == 0.0
    free = dtw(x, x, step_pattern=pattern, local=local)
    assert free.distance == 0.0
    if len(np.unique(x, axis=0)) == len(x):  # distinct samples: only the diagonal costs 0
        np.testing.assert_array_equal(free.path, np.c_[np.arange(len(x)), np.arange(len(x))])


def test_path_false_returns_no_path_and_the_same_distances(rng):
    x, y = rng.standard_normal((15, 2)), rng.standard_normal((18, 2))
    a, b = dtw(x, y, path=False), dtw(x, y)
    assert isinstance(a, DtwResult) and a.path is None
    assert (a.distance, a.normalized_distance) == pytest.approx((b.distance, b.normalized_distance), rel=1e-12)


@pytest.mark.parametrize("kwargs, match", [
    ({"step_pattern": "symmetricP1"}, "unknown step_pattern"),
    ({"local": "cityblock"}, "unknown local cost"),
    ({"window": -1}, "non-negative integer"),
    ({"window": 2.5}, "non-negative integer"),
    ({"window": 2}, "admits no path"),
    ({"scale": "mad"}, "scale must be"),
    ({"scale": [1.0, 0.0]}, "positive and finite"),
    ({"scale": [1.0, 2.0, 3.0]}, "3 divisors for 2 features"),
])
def test_bad_options_are_refused_with_one_clear_line(kwargs, match):
    x, y = np.zeros((10, 2)), np.ones((14, 2))
    with pytest.raises(ValueError, match=match):
        dtw(x, y, **kwargs)


def test_bad_shapes_and_non_finite_values_are_refused_naming_the_row():
    with pytest.raises(ValueError, match="x must be"):
        dtw(np.zeros((3, 2, 2)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="empty"):
        dtw(np.zeros((0, 2)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="x has 2 features, y has 3"):
        dtw(np.zeros((3, 2)), np.zeros((3, 3)))
    y = np.zeros((5, 2))
    y[3, 1] = np.nan
    with pytest.raises(ValueError, match="y has a non-finite value .* row 3"):
        dtw_distance(np.zeros((4, 2)), y)
