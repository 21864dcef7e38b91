"""HMM core: log-space forward and Viterbi against hmmlearn, published discrete anchors, training."""

from __future__ import annotations

import numpy as np
import pytest
from hmmlearn import hmm

from pipeline.models.hmm import HMMParams, ManeuverHMM, forward_categorical, forward_log, safe_log
from pipeline.models.viterbi import online_viterbi_states, viterbi


def random_gaussian_hmm(rng, S=4, d=3, seed=1):
    m = hmm.GaussianHMM(n_components=S, covariance_type="full", init_params="", random_state=seed)
    m.startprob_ = rng.dirichlet(np.ones(S))
    m.transmat_ = rng.dirichlet(np.full(S, 2.0), size=S)
    m.means_ = rng.normal(size=(S, d)) * 2
    L = rng.normal(size=(S, d, d)) * 0.4
    m.covars_ = L @ L.transpose(0, 2, 1) + 0.3 * np.eye(d)
    return m


@pytest.mark.parametrize("S,d,T", [(2, 1, 5), (4, 3, 200), (6, 9, 124)])
def test_forward_equals_hmmlearn_score(rng, S, d, T):
    m = random_gaussian_hmm(rng, S, d)
    X, _ = m.sample(T, random_state=int(rng.integers(1 << 30)))
    p = HMMParams.from_hmmlearn(m)
    ours = ManeuverHMM.from_params(p).score(X)
    ref = m.score(X)
    assert abs(ours - ref) <= 1e-8 * abs(ref)
    # every prefix, too (the online classifier's LL_m(t))
    pref = ManeuverHMM.from_params(p).score_prefixes(X)
    for t in (1, T // 2, T):
        assert abs(pref[t - 1] - m.score(X[:t])) <= 1e-8 * abs(m.score(X[:t]))


def test_forward_equals_hmmlearn_gmm_emissions(rng):
    S, K, d = 3, 2, 2
    m = hmm.GMMHMM(n_components=S, n_mix=K, covariance_type="full", init_params="")
    m.startprob_ = rng.dirichlet(np.ones(S))
    m.transmat_ = rng.dirichlet(np.full(S, 2.0), size=S)
    m.weights_ = rng.dirichlet(np.ones(K), size=S)
    m.means_ = rng.normal(size=(S, K, d))
    L = rng.normal(size=(S, K, d, d)) * 0.3
    m.covars_ = L @ np.swapaxes(L, -1, -2) + 0.2 * np.eye(d)
    m.n_features = d
    X, _ = m.sample(80, random_state=5)
    ours = ManeuverHMM.from_params(HMMParams.from_hmmlearn(m)).score(X)
    assert abs(ours - m.score(X)) <= 1e-8 * abs(m.score(X))


def test_viterbi_equals_hmmlearn_decode(rng):
    for _ in range(3):
        m = random_gaussian_hmm(rng, S=5, d=3)
        X, _ = m.sample(150, random_state=int(rng.integers(1 << 30)))
        lp, path = viterbi(HMMParams.from_hmmlearn(m), X)
        lp_ref, path_ref = m.decode(X, algorithm="viterbi")
        np.testing.assert_array_equal(path, path_ref)
        assert abs(lp - lp_ref) <= 1e-8 * abs(lp_ref)


def test_online_viterbi_last_state_is_offline_end(rng):
    m = random_gaussian_hmm(rng, S=4, d=2)
    X, _ = m.sample(60, random_state=3)
    p = HMMParams.from_hmmlearn(m)
    on = online_viterbi_states(p, X)
    for t in (1, 10, 60):
        assert on[t - 1] == viterbi(p, X[:t])[1][-1]


def test_seed004_discrete_anchors():
    # weather chain, identity emissions: P = .8·.1·.6·.2·.3·.1 (seed 004 §1)
    A = [[0.8, 0.1, 0.1], [0.2, 0.6, 0.2], [0.3, 0.3, 0.4]]
    p = forward_categorical([1, 0, 0], A, np.eye(3), [0, 0, 1, 1, 2, 0, 2])
    assert p == pytest.approx(0.8 * 0.1 * 0.6 * 0.2 * 0.3 * 0.1, rel=1e-12)
    assert p == pytest.approx(2.88e-4, rel=1e-12)
    # soda machine: the state-emission forward gives 0.252 (the thesis's 0.162 is a typo)
    p2 = forward_categorical([1, 0], [[0.7, 0.3], [0.5, 0.5]], [[0.6, 0.1, 0.3], [0.1, 0.2, 0.7]], [0, 2])
    assert p2 == pytest.approx(0.252, rel=1e-12)


def test_hmmlearn_published_wikipedia_example():
    # hmmlearn tests/test_base.py (Wikipedia forward-backward example): log P = -3.3725
    frameprob = np.array([[0.9, 0.2], [0.9, 0.2], [0.1, 0.8], [0.9, 0.2], [0.9, 0.2]])
    la, ll = forward_log(safe_log([0.5, 0.5]), safe_log([[0.7, 0.3], [0.3, 0.7]]), np.log(frameprob))
    assert round(ll, 4) == -3.3725
    # the published lattice is the unscaled alpha, printed to 4 decimals
    ref = [[0.4500, 0.1000], [0.3105, 0.0410], [0.0230, 0.0975], [0.0408, 0.0150], [0.0298, 0.0046]]
    np.testing.assert_allclose(np.exp(la), ref, rtol=0, atol=5e-5)
    # and exactly the hand-written unscaled recursion alpha_t = (alpha_{t-1} A) * b_t
    A = np.array([[0.7, 0.3], [0.3, 0.7]])
    alpha = [0.5 * frameprob[0]]
    for b in frameprob[1:]:
        alpha.append((alpha[-1] @ A) * b)
    np.testing.assert_allclose(np.exp(la), alpha, rtol=1e-12, atol=0)
    assert ll == pytest.approx(np.log(alpha[-1].sum()), rel=1e-12)


def _train_data(rng, S=3, d=2, n=25, T=60):
    m = hmm.GaussianHMM(n_components=S, covariance_type="full", init_params="")
    m.startprob_ = np.r_[1.0, np.zeros(S - 1)]
    A = np.eye(S) * 0.9 + 0.1 / S
    A[-1] = np.r_[np.zeros(S - 1), 1.0]
    m.transmat_ = A / A.sum(1, keepdims=True)
    m.means_ = np.arange(S)[:, None] * np.full((1, d), 4.0)
    m.covars_ = np.tile(np.eye(d) * 0.5, (S, 1, 1))
    seqs = [m.sample(T, random_state=int(rng.integers(1 << 30)))[0] for _ in range(n)]
    return m, np.concatenate(seqs), [T] * n


def test_training_recovers_means_and_is_monotone(rng):
    true, X, lengths = _train_data(rng, n=12)
    f = ManeuverHMM(n_states=3, seed=3, tol=1e-3, hmm_restarts=3).fit(X, lengths)
    h = np.array(f.history_)
    assert np.all(np.diff(h) >= -1e-6 * np.abs(h[1:]))          # EM never decreases the LL
    # GMM init orders states by time: state 0 starts the maneuver
    np.testing.assert_allclose(f.params_.means[:, 0], true.means_, atol=0.3)
    assert f.params_.startprob[0] > 0.9
    # the initial A had non-zero off-diagonals, so learned transitions exist (§13.1)
    assert f.params_.transmat[0, 1] > 0.02
    assert f.score(X, lengths) == pytest.approx(f.history_[-1], rel=1e-3)


def test_training_is_deterministic(rng):
    _, X, lengths = _train_data(rng, n=10)
    a = ManeuverHMM(n_states=3, seed=11).fit(X, lengths).to_arrays()
    b = ManeuverHMM(n_states=3, seed=11).fit(X, lengths).to_arrays()
    for k in a:
        assert a[k].tobytes() == b[k].tobytes()


def test_auto_states_by_bic(rng):
    _, X, lengths = _train_data(rng, S=3, n=12)
    f = ManeuverHMM(n_states="auto", n_states_range=(2, 4), seed=0).fit(X, lengths)
    assert f.n_states_ == 3
    assert min(f.bic_, key=f.bic_.get) == 3 and set(f.bic_) == {2, 3, 4}


def test_the_bic_and_the_restart_choice_use_the_likelihood_of_the_returned_parameters(rng):
    # stopped early by n_iter, hmmlearn's last history entry belongs to the parameters before
    # its last M-step (-431.7 against -378.8 here): the BIC must be that of params_
    r = np.random.default_rng(0)
    X = np.concatenate([r.standard_normal((60, 2)) + [3, 0], r.standard_normal((60, 2)) - [3, 0]])
    m = ManeuverHMM(n_states=2, n_iter=3, tol=1e-9, seed=4).fit(X, lengths=[60, 60])
    bic = -2.0 * m.score(X, [60, 60]) + m.params_.n_parameters() * np.log(len(X))
    assert m.bic_[2] == pytest.approx(bic, rel=1e-12)
    best = ManeuverHMM(n_states=2, n_iter=3, tol=1e-9, seed=4, hmm_restarts=3).fit(X, lengths=[60, 60])
    each = [ManeuverHMM(n_states=2, n_iter=3, tol=1e-9, seed=4)._fit_one(X, np.array([60, 60]), 2, r)[0]
            for r in range(3)]
    assert best.score(X, [60, 60]) == pytest.approx(max(ManeuverHMM._score(p, X, [60, 60]) for p in each))


def test_gmm_emissions_train(rng):
    _, X, lengths = _train_data(rng, n=5)
    f = ManeuverHMM(n_states=3, n_mix=2, seed=0, n_iter=8).fit(X, lengths)
    assert f.params_.weights.shape == (3, 2)
    np.testing.assert_allclose(f.params_.weights.sum(1), 1.0)
    ref = f.params_.to_hmmlearn().score(X[:60])
    assert f.score(X[:60]) == pytest.approx(ref, rel=1e-8)


def test_bad_training_input():
    from pipeline.models.base import ModelError
    with pytest.raises(ModelError, match="NaN"):
        ManeuverHMM(n_states=2).fit(np.array([[0.0], [np.nan], [1.0]]))
    with pytest.raises(ModelError, match="lengths"):
        ManeuverHMM(n_states=2).fit(np.zeros((10, 1)), [3, 3])


def test_a_nan_or_empty_observation_sequence_is_refused_naming_the_row_instead_of_a_path_of_zeros(rng):
    # a NaN row made δ NaN and argmax answered state 0 at every later step, log-prob NaN
    from pipeline.models.base import ModelError
    from pipeline.models.viterbi import online_viterbi_states, viterbi

    _, X, lengths = _train_data(rng, n=4)
    m = ManeuverHMM(n_states=3, seed=0, n_iter=5).fit(X, lengths)
    bad = X[:40].copy()
    bad[3, 1] = np.nan
    for call in (lambda x: viterbi(m.params_, x), lambda x: online_viterbi_states(m.params_, x), m.score,
                 m.score_prefixes):
        with pytest.raises(ModelError, match=r"observation row 3 is not finite \(1 of 40 rows\)"):
            call(bad)
        with pytest.raises(ModelError, match="non-empty"):
            call(X[:0])
    with pytest.raises(ModelError, match="features, the model"):
        m.score(X[:40, :1])
    for ls in ([40, 0, len(X) - 40], [len(X) + 5, -5]):
        with pytest.raises(ModelError, match="lengths must be positive"):
            m.score(X, ls)
