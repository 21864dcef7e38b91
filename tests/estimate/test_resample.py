"""Resampling schemes (issue 17 acceptance): copy counts and unbiasedness, N_eff."""

import numpy as np
import pytest

from pipeline.estimate import resample as R


def _weights(seed, n=37):
    w = np.random.default_rng(seed).gamma(0.7, size=n)
    return w / w.sum()


@pytest.mark.parametrize("seed", range(5))
def test_systematic_gives_each_particle_floor_or_ceil_of_n_w_copies(seed):
    w = _weights(seed)
    rng = np.random.default_rng(100 + seed)
    for _ in range(200):
        c = R.copies(R.systematic(w, rng), w.size)
        nw = w.size * w
        assert c.sum() == w.size
        assert np.all((c >= np.floor(nw) - 1e-12) & (c <= np.ceil(nw) + 1e-12))


@pytest.mark.parametrize("seed", range(5))
def test_stratified_copies_stay_within_two_of_n_w(seed):
    w = _weights(seed)
    rng = np.random.default_rng(200 + seed)
    for _ in range(200):
        c = R.copies(R.stratified(w, rng), w.size)
        assert c.sum() == w.size
        assert np.all(np.abs(c - w.size * w) < 2)


@pytest.mark.parametrize("scheme", R.SCHEMES)
def test_every_scheme_copies_n_w_on_average_over_ten_thousand_draws(scheme):
    w = _weights(7, n=25)
    n, draws = w.size, 10_000
    rng = np.random.default_rng(3)
    f = R.get_resampler(scheme)
    C = np.empty((draws, n))
    for r in range(draws):
        C[r] = R.copies(f(w, rng), n)
    mean, se = C.mean(axis=0), C.std(axis=0, ddof=1) / np.sqrt(draws)
    nw = n * w
    # 4 standard errors; a deterministic count (se = 0) must be exact
    assert np.all(np.abs(mean - nw) <= 4 * se + 1e-12), (scheme, np.max(np.abs(mean - nw) / np.maximum(se, 1e-300)))


def test_indices_are_ascending_in_range_and_int64_for_every_scheme():
    w = _weights(1, 1000)
    rng = np.random.default_rng(0)
    for scheme in R.SCHEMES:
        idx = R.get_resampler(scheme)(w, rng)
        assert idx.dtype == np.int64 and idx.shape == (1000,)
        assert idx.min() >= 0 and idx.max() < 1000 and np.all(np.diff(idx) >= 0)


def test_a_degenerate_weight_vector_copies_its_one_particle():
    w = np.zeros(10)
    w[4] = 1.0
    for scheme in R.SCHEMES:
        assert np.all(R.get_resampler(scheme)(w, np.random.default_rng(0)) == 4)


def test_bad_weights_and_unknown_schemes_fail_with_one_clear_line():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="not all zero"):
        R.systematic(np.zeros(4), rng)
    with pytest.raises(ValueError, match="non-negative"):
        R.systematic(np.array([0.5, -0.1, 0.6]), rng)
    with pytest.raises(ValueError, match="unknown scheme 'bogus'"):
        R.get_resampler("bogus")


def test_effective_sample_size_spans_one_to_n():
    assert R.effective_sample_size(np.ones(50)) == pytest.approx(50)
    assert R.effective_sample_size(np.eye(1, 50)[0]) == pytest.approx(1)
    assert R.effective_sample_size(np.array([3.0, 1.0])) == pytest.approx(1 / (0.75 ** 2 + 0.25 ** 2))


def test_the_same_seed_draws_the_same_indices():
    w = _weights(2, 100)
    for scheme in R.SCHEMES:
        f = R.get_resampler(scheme)
        assert np.array_equal(f(w, np.random.default_rng(9)), f(w, np.random.default_rng(9)))


@pytest.mark.parametrize("scheme", R.SCHEMES)
def test_a_negative_or_fractional_draw_count_is_refused_and_zero_draws_nothing(scheme):
    f = R.get_resampler(scheme)
    w = _weights(1)
    for n in (-2, 2.5):  # -2 used to give [] (systematic) or a numpy "repeats" error (residual)
        with pytest.raises(ValueError, match="n must be a whole number >= 0"):
            f(w, np.random.default_rng(0), n=n)
    assert f(w, np.random.default_rng(0), n=0).size == 0
    assert f(w, np.random.default_rng(0), n=5).size == 5


class _ZeroRng:
    """A generator whose uniforms are all exactly 0 (``rng.random()`` is in [0, 1))."""

    def random(self, n=None):
        return 0.0 if n is None else np.zeros(n)


@pytest.mark.parametrize("scheme", ["systematic", "stratified", "multinomial"])
def test_a_zero_weight_particle_is_never_drawn_even_by_a_uniform_of_exactly_zero(scheme):
    # the merge took the first cdf >= u: at u = 0 a leading zero-weight particle was drawn
    from pipeline.estimate import resample as rs

    idx = getattr(rs, scheme)(np.array([0.0, 0.5, 0.5]), _ZeroRng())
    assert 0 not in idx.tolist()


def test_the_regularisation_bandwidth_is_musso_s_gaussian_optimum():
    # Arulampalam et al. (2002) eq. 77: A = (4/(d+2))^(1/(d+4)), h = A N^(-1/(d+4))
    assert np.isclose(R.regularisation_bandwidth(50, 4), (4 / 6) ** (1 / 8) * 50 ** (-1 / 8))
    assert np.isclose(R.regularisation_bandwidth(50, 4), 0.583, atol=5e-4)
    assert np.isclose(R.regularisation_bandwidth(1, 2), (4 / 4) ** (1 / 6))
    assert R.regularisation_bandwidth(10 ** 6, 4) < R.regularisation_bandwidth(100, 4)
    with pytest.raises(ValueError, match="n >= 1 and d >= 1"):
        R.regularisation_bandwidth(0, 4)


def test_the_kernel_move_adds_h_squared_times_the_given_covariance_and_leaves_other_components_alone():
    rng = np.random.default_rng(11)
    n = 200_000
    S = np.array([[4.0, 1.2, 0.0], [1.2, 1.0, 0.3], [0.0, 0.3, 0.25]])
    x = np.zeros((n, 5))
    x[:, 4] = 7.0
    y = R.regularise(x, np.pad(S, ((0, 2), (0, 2))), rng, index=[0, 1, 2])
    h = R.regularisation_bandwidth(n, 3)
    # the jitter's covariance is h² S (5 standard errors of a sample covariance at this n)
    assert np.allclose(np.cov(y[:, :3], rowvar=False), h * h * S, atol=5 * h * h * 4.0 * np.sqrt(2 / n))
    assert np.all(y[:, 3] == 0.0) and np.all(y[:, 4] == 7.0)
    assert np.all(x == np.where(np.arange(5) == 4, 7.0, 0.0))        # the input is not modified


def test_a_constant_component_is_no_dimension_of_the_kernel_and_a_singular_covariance_still_moves():
    rng = np.random.default_rng(12)
    x = np.zeros((20_000, 3))
    S = np.diag([1.0, 1.0, 0.0])            # e.g. D on the ground plane
    y = R.regularise(x, S, rng)
    assert np.all(y[:, 2] == 0.0)
    # d = 2 varying components (h 0.192), not 3 (h 0.235)
    assert np.allclose(y[:, :2].std(axis=0), R.regularisation_bandwidth(20_000, 2), rtol=0.03)
    # rank one: the cloud moves along the one direction that has spread
    y1 = R.regularise(x, np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.0]]), rng)
    assert np.allclose(y1[:, 0], y1[:, 1]) and y1[:, 0].std() > 0.1
    assert np.all(R.regularise(x, np.zeros((3, 3)), rng) == 0.0)
    with pytest.raises(ValueError, match="non-finite"):
        R.regularise(x, np.full((3, 3), np.nan), rng)
