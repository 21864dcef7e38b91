"""IMM with EKF and bank modes (seed 002 §6, D3–D5) and the transmat re-timing bridge."""

import numpy as np
import pytest

from pipeline.estimate.bank import BankSettings, Components, CppvModel, CvModel, bank_prior, run_bank
from pipeline.estimate.imm import (ImmMode, bank_mode, cv_mode_from, ekf_mode, embed, mix_components,
                                   mix_interval, mixing_probabilities, run_imm, switching_matrix)
from pipeline.estimate.markov import hmm_to_step, step_to_hmm
from pipeline.estimate.models import CPPV_STATE, CV_CPPV_STATE, cppv_transition

SIG = np.deg2rad(0.2)
VO = np.array([40.0, 0.0])


def scenario(T=300, switch=None, seed=1, R=1):
    rng = np.random.default_rng(seed)
    X = np.empty((R, T, 5))
    X[:, 0] = (3000.0, 1500.0, 70.0, 1.0, np.deg2rad(6.0))
    for k in range(1, T):
        if switch is not None and k == switch:
            X[:, k - 1, 4] = 0.0
        X[:, k] = cppv_transition(X[:, k - 1], 0.05, VO * 0.05)
    z = np.arctan2(X[..., 1], X[..., 0]) + SIG * rng.standard_normal((R, T))
    return np.arange(T) * 0.05, X, z, np.broadcast_to(np.r_[0.0, 0.0, VO], (T, 4))


def test_mixing_probabilities_match_a_hand_computed_two_mode_example():
    mu = np.array([[0.3, 0.7]])
    Pi = np.array([[0.9, 0.1], [0.2, 0.8]])
    cbar, mij = mixing_probabilities(mu, Pi)
    assert cbar[0] == pytest.approx([0.41, 0.59])
    assert mij[0] == pytest.approx(np.array([[0.27 / 0.41, 0.03 / 0.59], [0.14 / 0.41, 0.56 / 0.59]]))
    assert mij[0].sum(axis=0) == pytest.approx([1.0, 1.0])


def test_mixed_inputs_match_the_hand_computed_cv_and_bank_formulas():
    # mode 1: CV EKF (4 states); mode 2: a 2-filter CT bank (5 states); eqs. 3.41–3.44 with D3
    rng = np.random.default_rng(0)
    x1 = np.array([3000.0, 1000.0, 60.0, 0.5])
    A = rng.normal(size=(4, 4))
    P1 = A @ A.T + np.eye(4)
    x2 = np.array([[3100.0, 950.0, 65.0, 0.6, 0.05], [2900.0, 1040.0, 58.0, 0.4, -0.03]])
    B = rng.normal(size=(2, 5, 5))
    P2 = B @ np.swapaxes(B, 1, 2) + np.eye(5)
    W = np.array([0.25, 0.75])
    cv = ekf_mode("cv", CvModel(), x1, P1)
    ct = ImmMode("ct", CppvModel(BankSettings()), Components(x2[None], P2[None], np.log(W)[None], np.zeros((1, 2), bool)))
    mij = np.array([[[0.8, 0.1], [0.2, 0.9]]])  # μ(i|j), columns j
    out = mix_components([cv, ct], [cv.prior, ct.prior], mij)
    # bank moments X̄², P̄²
    xb = W @ x2
    Pb = sum(W[n] * (P2[n] + np.outer(x2[n] - xb, x2[n] - xb)) for n in range(2))
    x01 = 0.8 * x1 + 0.2 * xb[:4]
    P01 = 0.8 * (P1 + np.outer(x1 - x01, x1 - x01)) + 0.2 * (Pb[:4, :4] + np.outer(xb[:4] - x01, xb[:4] - x01))
    assert out[0].mean[0, 0] == pytest.approx(x01) and out[0].cov[0, 0] == pytest.approx(P01)
    for n in range(2):
        e1 = np.r_[x1, x2[n, 4]]  # CV → CT: the filter's own ω appended (D3)
        E1 = np.zeros((5, 5))
        E1[:4, :4], E1[4, 4] = P1, P2[n, 4, 4]
        x02 = 0.1 * e1 + 0.9 * x2[n]
        P02 = 0.1 * (E1 + np.outer(e1 - x02, e1 - x02)) + 0.9 * (P2[n] + np.outer(x2[n] - x02, x2[n] - x02))
        assert out[1].mean[0, n] == pytest.approx(x02) and out[1].cov[0, n] == pytest.approx(P02)
    assert np.array_equal(out[1].logw, ct.prior.logw)  # D4: W_n survive mixing


def test_an_imm_with_identical_modes_equals_a_single_ekf():
    t, X, z, own = scenario(T=200)
    s = BankSettings(n_r=1, n_omega=1, n_theta=1)
    single = run_bank(s, t, z[0], SIG, own)
    c = bank_prior(s, z[0, :1], SIG)
    m = ekf_mode("a", CppvModel(s), c.mean[:, 0], c.cov[:, 0])
    tr = run_imm([m, ImmMode("b", m.model, m.prior)], switching_matrix(0.1), t, z[0], SIG, own)
    assert tr.mean[0] == pytest.approx(single.mean[0], rel=1e-8, abs=1e-10)
    d = np.sqrt(np.diagonal(single.cov[0], axis1=-2, axis2=-1))
    assert np.max(np.abs(tr.cov[0] - single.cov[0]) / (d[..., :, None] * d[..., None, :])) < 1e-7  # round-off, correlation units
    assert tr.mode_p[0] == pytest.approx(np.full((200, 2), 0.5))


def test_a_one_mode_imm_reduces_exactly_to_its_bank():
    t, X, z, own = scenario(T=150)
    bank = run_bank("cppv_10_1_6", t, z[0], SIG, own)
    tr = run_imm([bank_mode("cppv_10_1_6", z[0, :1], SIG)], np.eye(1), t, z[0], SIG, own, store_weights=True)
    assert tr.mean[0] == pytest.approx(bank.mean[0], rel=1e-11, abs=1e-12)
    assert tr.cov[0] == pytest.approx(bank.cov[0], rel=1e-9, abs=1e-12)
    assert tr.weights[0][0] == pytest.approx(bank.weights[0], rel=1e-9, abs=1e-300)
    assert (tr.mode_p == 1.0).all() and tr.loglik[0] == pytest.approx(bank.loglik[0])


def test_mode_probabilities_sum_to_one_and_cv_wins_after_a_ct_to_cv_switch():
    t, X, z, own = scenario(T=1000, switch=600)
    ct = bank_mode(BankSettings(n_r=10, n_omega=1, n_theta=3), z[:, 0], SIG)
    tr = run_imm([cv_mode_from(ct), ct], (20.0, 1e-4), t, z, SIG, own)
    assert tr.mode_p.sum(axis=-1) == pytest.approx(np.ones((1, 1000)))
    assert tr.mixed[1:].all() and tr.metadata["mix_every"] == 1
    assert tr.metadata["mode_models"]["cv"]["sigma_theta_dot2"] > 0 and tr.metadata["mode_models"]["ct"]["n_filters"] == 30
    assert tr.mode_p[0, 500:600, 0].mean() < 0.5  # turning: the bank holds
    assert tr.mode_p[0, 900:, 0].mean() > 0.5     # flying straight: CV takes over
    assert tr.state_names == CPPV_STATE and tr.mode_mean[0].shape == (1, 1000, 4)


def test_the_mixing_rate_sets_the_mixing_steps():
    assert [mix_interval(f, 0.05) for f in (20, 10, 5, 1)] == [1, 2, 4, 20]
    t, X, z, own = scenario(T=30)
    ct = bank_mode("cppv_10_1_6", z[:, 0], SIG)
    tr = run_imm([cv_mode_from(ct), ct], (5.0, 1e-3), t, z, SIG, own)
    assert np.flatnonzero(tr.mixed).tolist() == list(range(1, 30, 4))
    assert switching_matrix(1e-3) == pytest.approx(np.array([[0.999, 0.001], [0.001, 0.999]]))


def test_embedding_drops_and_appends_states_by_name():
    m, P = embed(np.arange(5.0), np.diag(np.arange(1.0, 6.0)), CPPV_STATE, CV_CPPV_STATE, np.zeros(4), np.eye(4))
    assert m == pytest.approx([0, 1, 2, 3]) and np.diag(P) == pytest.approx([1, 2, 3, 4])
    m, P = embed(np.arange(4.0), np.ones((4, 4)), CV_CPPV_STATE, CPPV_STATE, np.full(5, 9.0), 7 * np.eye(5))
    assert m == pytest.approx([0, 1, 2, 3, 9]) and P[4, 4] == 7 and not P[4, :4].any() and P[:4, :4].sum() == 16


def test_a_converted_transmat_converts_back():
    transmat = np.array([[0.95, 0.04, 0.01], [0.03, 0.9, 0.07], [0.02, 0.08, 0.9]])
    step = hmm_to_step(transmat, 0.05, 0.2)
    assert step.sum(axis=1) == pytest.approx(np.ones(3))
    assert np.linalg.matrix_power(step, 4) == pytest.approx(transmat, abs=1e-10)
    assert step_to_hmm(step, 0.05, 0.2) == pytest.approx(transmat, abs=1e-10)


def test_bad_imm_input_is_one_clear_error():
    t, X, z, own = scenario(T=10)
    ct = bank_mode("cppv_10_1_6", z[:, 0], SIG)
    with pytest.raises(ValueError, match="shaped"):
        run_imm([ct], np.eye(2), t, z, SIG, own)
    mpc = bank_mode(BankSettings(coords="mpc", n_r=2, n_omega=1, n_theta=1), z[:, 0], SIG)
    with pytest.raises(ValueError, match="share no state"):
        run_imm([cv_mode_from(ct), mpc], switching_matrix(1e-3), t, z, SIG, own)
    with pytest.raises(ValueError, match="row 0 sums"):
        run_imm([ct, ct], np.array([[0.5, 0.4], [0.5, 0.5]]), t, z, SIG, own)


def test_a_one_hot_mu0_with_an_identity_transmat_equals_the_single_mode_run():
    # c̄_ct = 0 at every mix: the CT mode must keep its own components (not be zeroed by
    # all-zero mixing weights) and the output must be the CV mode's run alone
    t, X, z, own = scenario(T=60)
    ct = bank_mode("cppv_10_1_6", z[:, 0], SIG)
    cv = cv_mode_from(ct)
    single = run_imm([cv], np.eye(1), t, z, SIG, own, output_names=CV_CPPV_STATE)
    tr = run_imm([cv, ct], np.eye(2), t, z, SIG, own, mu0=[1, 0])
    assert np.isfinite(tr.mean).all() and np.isfinite(tr.mode_p).all() and np.isfinite(tr.loglik).all()
    assert (tr.mode_p[..., 0] == 1.0).all() and (tr.mode_p[..., 1] == 0.0).all()
    assert tr.mode_mean[0] == pytest.approx(single.mean, rel=1e-12, abs=1e-12)
    assert tr.mean[..., :4] == pytest.approx(single.mean, rel=1e-12, abs=1e-12)
    assert tr.loglik == pytest.approx(single.loglik, rel=1e-12, abs=1e-12)
    assert np.isfinite(tr.mode_mean[1]).all()  # the idle CT mode still runs on its own components


@pytest.mark.parametrize("mu0, match", [([0, 0], "positive sum"), ([np.nan, 1], "finite"),
                                        ([0.5, -0.1], ">= 0"), ([1, 0, 0], "mu0 must have shape"),
                                        (np.ones((3, 2)), "mu0 must have shape")])
def test_a_bad_mu0_is_one_clear_error(mu0, match):
    t, X, z, own = scenario(T=10)
    ct = bank_mode("cppv_10_1_6", z[:, 0], SIG)
    with pytest.raises(ValueError, match=match):
        run_imm([cv_mode_from(ct), ct], switching_matrix(1e-3), t, z, SIG, own, mu0=mu0)


def test_an_unnormalised_mu0_is_normalised():
    t, X, z, own = scenario(T=10)
    ct = bank_mode("cppv_10_1_6", z[:, 0], SIG)
    a = run_imm([cv_mode_from(ct), ct], switching_matrix(1e-3), t, z, SIG, own, mu0=[2, 6])
    b = run_imm([cv_mode_from(ct), ct], switching_matrix(1e-3), t, z, SIG, own, mu0=[0.25, 0.75])
    assert a.mode_p[:, 0] == pytest.approx(np.array([[0.25, 0.75]])) and np.array_equal(a.mean, b.mean)
