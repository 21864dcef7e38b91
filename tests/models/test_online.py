"""Online classifier: exactness against hmmlearn, confidence, windowed/reset recovery."""

from __future__ import annotations

import numpy as np
import pytest
from hmmlearn import hmm

from pipeline.models.hmm import HMMParams
from pipeline.models.online import UNKNOWN, OnlineClassifier, classify_batch, confidence


def chain_model(means, var=0.5, stay=0.9, seed=0):
    """Left-to-right-ish Gaussian HMM with the given state means (S, d)."""
    means = np.asarray(means, dtype=float)
    S, d = means.shape
    m = hmm.GaussianHMM(n_components=S, covariance_type="full", init_params="", random_state=seed)
    m.startprob_ = np.r_[0.9, np.full(S - 1, 0.1 / (S - 1))] if S > 1 else np.ones(1)
    A = np.full((S, S), (1 - stay) / max(S - 1, 1))
    np.fill_diagonal(A, stay if S > 1 else 1.0)
    m.transmat_ = A
    m.means_ = means
    m.covars_ = np.tile(np.eye(d) * var, (S, 1, 1))
    return m


@pytest.fixture
def three_models():
    a = chain_model([[0, 0], [2, 0], [4, 0]])
    b = chain_model([[0, 3], [0, 6], [0, 9], [0, 12]])          # different state count (padding)
    c = chain_model([[-3, -3], [-6, -3]])
    return [a, b, c]


def test_online_scores_equal_hmmlearn_prefix_scores(three_models, rng):
    ms = three_models
    lens = [30, 12, 25]
    seqs = [ms[i].sample(n, random_state=int(rng.integers(1 << 30)))[0] for i, n in enumerate(lens)]
    X = np.full((3, 30, 2), np.nan)
    for r, s in enumerate(seqs):
        X[r, :len(s)] = s
    clf = OnlineClassifier([HMMParams.from_hmmlearn(m) for m in ms], mode="cumulative")
    res = classify_batch(clf, X)
    for r, s in enumerate(seqs):
        for t in (1, 5, len(s)):
            for j, m in enumerate(ms):
                ref = m.score(s[:t])
                assert abs(res["scores"][r, t - 1, j] - ref) <= 1e-8 * abs(ref)
        assert (res["label"][r, len(s):] == -2).all()                 # past the end: untouched
    assert res["best"][0, 29] == 0 and res["best"][1, 11] == 1 and res["best"][2, 24] == 2


def test_online_viterbi_state_matches_decode(three_models, rng):
    m = three_models[1]
    X = m.sample(40, random_state=3)[0]
    clf = OnlineClassifier([HMMParams.from_hmmlearn(x) for x in three_models])
    res = classify_batch(clf, X[None])
    for t in (5, 20, 40):
        assert res["state"][0, t - 1] == m.decode(X[:t], algorithm="viterbi")[1][-1]


def test_confidence_formula():
    ll = np.array([[-10.0, -12.0, -20.0], [-5.0, -5.0, -5.0]])
    V = confidence(ll)
    for r in range(2):
        for j in range(3):
            ref = np.log10(sum(np.exp(ll[r, i] - ll[r, j]) for i in range(3) if i != j))
            assert V[r, j] == pytest.approx(ref, rel=1e-12)
    # two models: V_j = (LL_other - LL_j) / ln 10
    v2 = confidence(np.array([-1.0, -4.0]))
    assert v2[0] == pytest.approx(-3 / np.log(10)) and v2[1] == pytest.approx(3 / np.log(10))
    # huge differences stay finite (no overflow)
    assert np.isfinite(confidence(np.array([-1e6, 0.0]))).all()


def test_unknown_when_not_confident(three_models):
    params = [HMMParams.from_hmmlearn(m) for m in three_models]
    # points on the line between models 0 and 2's first states: V_c = log10 exp(LL_other - LL_c)
    # from hmmlearn's scores, labelled exactly where V_c < -1 (the thesis's threshold)
    a, c = three_models[0], three_models[2]

    def point(s):
        return s * np.array([-3.0, -3.0])

    def ll_v(s):
        ll = np.array([m.score(point(s)[None]) for m in (a, c)])
        return ll, (ll.min() - ll.max()) / np.log(10)

    # V_c rises from below -1 (at model 0's state) to 0 at the midpoint: bisect for V_c = -1
    lo, hi = 0.0, 0.5
    assert ll_v(lo)[1] < -1 < ll_v(hi)[1]
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ll_v(mid)[1] < -1 else (lo, mid)
    for s, confident in ((lo - 1e-3, True), (hi + 1e-3, False)):
        ll, v = ll_v(s)
        assert abs(v + 1) < 0.05 and (v < -1) == confident             # just below / just above -1
        res = OnlineClassifier([params[0], params[2]], mode="cumulative").start(1).step(point(s)[None])
        best = int(np.argmax(ll))
        assert res.best[0] == best and res.V[0, best] == pytest.approx(v, abs=1e-9)
        assert res.label[0] == (best if confident else UNKNOWN)
    # two equal models: V_c = log10(1) = 0 -> unknown
    clf = OnlineClassifier([params[0], params[0]], mode="cumulative").start(1)
    res = clf.step(np.array([[0.0, 0.0]]))
    assert res.V[0, res.best[0]] == pytest.approx(0.0, abs=1e-12)
    assert res.label[0] == UNKNOWN
    clf = OnlineClassifier(params, mode="cumulative").start(1)
    for _ in range(5):
        res = clf.step(np.array([[0.0, 0.0]]))
    assert res.label[0] == 0 and res.V[0, 0] < -1


def test_windowed_without_restart_is_a_likelihood_difference(three_models, rng):
    """With ε = 0 the windowed score is exactly log P(O_{1:t}) − log P(O_{1:t−W})."""
    ms = three_models
    X = ms[0].sample(40, random_state=5)[0]
    W = 8
    clf = OnlineClassifier([HMMParams.from_hmmlearn(m) for m in ms], mode="windowed", window=W,
                           restart_prob=0.0)
    clf.eps = 0.0
    res = classify_batch(clf, X[None])
    for t in (3, 8, 9, 25, 40):
        for j, m in enumerate(ms):
            ref = m.score(X[:t]) - (m.score(X[:t - W]) if t > W else 0.0)
            assert res["scores"][0, t - 1, j] == pytest.approx(ref, rel=1e-9, abs=1e-9)


def test_external_reset_restarts_the_forward_pass(three_models, rng):
    ms = three_models
    X = np.concatenate([ms[0].sample(20, random_state=1)[0], ms[2].sample(15, random_state=2)[0]])
    resets = np.zeros((1, 35), dtype=bool)
    resets[0, 20] = True
    clf = OnlineClassifier([HMMParams.from_hmmlearn(m) for m in ms])
    res = classify_batch(clf, X[None], resets)
    for j, m in enumerate(ms):
        assert res["scores"][0, 34, j] == pytest.approx(m.score(X[20:]), rel=1e-9)
    assert res["label"][0, 19] == 0 and res["label"][0, 34] == 2


def _switch_runs(ms, i, j, switch, total, n, rng):
    out = []
    for _ in range(n):
        a = ms[i].sample(switch, random_state=int(rng.integers(1 << 30)))[0]
        b = ms[j].sample(total - switch, random_state=int(rng.integers(1 << 30)))[0]
        out.append(np.concatenate([a, b]))
    return np.stack(out)


def test_windowed_and_reset_recover_after_a_switch(three_models, rng):
    ms = three_models
    params = [HMMParams.from_hmmlearn(m) for m in ms]
    X = _switch_runs(ms, 0, 1, 60, 100, 5, rng)
    cum = classify_batch(OnlineClassifier(params, mode="cumulative"), X)
    win = classify_batch(OnlineClassifier(params, mode="windowed", window=10), X)
    rst = classify_batch(OnlineClassifier(params, mode="reset", window=10, confirm=3), X)
    after = slice(75, 100)
    acc = {k: np.mean(r["label"][:, after] == 1) for k, r in (("cum", cum), ("win", win), ("rst", rst))}
    assert acc["win"] >= 0.95 and acc["rst"] >= 0.95
    assert np.mean(win["label"][:, 30:60] == 0) >= 0.95            # before the switch: right too
    # reset mode declares exactly one change per run, near the true switch
    assert (rst["change"].sum(1) == 1).all()
    cp = rst["change_at"][rst["change"]]
    assert np.all(np.abs(cp - 60) <= 3)


@pytest.mark.parametrize("shift", [-5, 5])
def test_detected_change_point_follows_the_switch(three_models, rng, shift):
    ms = three_models
    params = [HMMParams.from_hmmlearn(m) for m in ms]
    seed = int(rng.integers(1 << 30))
    cps = {}
    for sw in (40, 40 + shift):
        X = _switch_runs(ms, 2, 0, sw, 90, 4, np.random.default_rng(seed))
        rst = classify_batch(OnlineClassifier(params, mode="reset", window=10, confirm=3), X)
        cps[sw] = rst["change_at"][rst["change"]]
    delta = np.median(cps[40 + shift]) - np.median(cps[40])
    assert abs(delta - shift) <= 2


def test_oneclass_decision_uses_threshold(three_models):
    params = [HMMParams.from_hmmlearn(m) for m in three_models]
    thr = np.full((3, 10), -1e9)
    thr[0] = 0.0                                                     # model 0 never accepted
    clf = OnlineClassifier(params, decision="oneclass", thresholds=thr)
    X = three_models[0].sample(12, random_state=1)[0][None]
    res = classify_batch(clf, X)
    assert (res["best"][0] == 0).all() and (res["label"][0] == UNKNOWN).all()
    thr[0] = -1e9
    res = classify_batch(OnlineClassifier(params, decision="both", thresholds=thr), X)
    assert (res["label"][0, 5:] == 0).all()
    with pytest.raises(ValueError, match="thresholds"):
        OnlineClassifier(params, decision="oneclass")
