"""The range-parameterised EKF bank (seed 002 §4): grids, weights, combination, bad input."""

import numpy as np
import pytest

from pipeline.estimate.bank import (PRESETS, BankSettings, Components, CppvModel, bank_prior,
                                    combine, components_step, omega_grid, range_grid, run_bank,
                                    settings_for, theta_grid, weight_entropy)
from pipeline.estimate.base import GaussianState, LinearTransition
from pipeline.estimate.ekf import ExtendedKalmanFilter
from pipeline.estimate.models import (BearingMeasurement, cppv_jacobian, cppv_process_noise,
                                      cppv_transition)

SIG = np.deg2rad(0.2)
VO = np.array([40.0, 0.0])


def orbit(T=1200, dt=0.05, x0=(3000.0, 1500.0, 70.0, 1.0, np.deg2rad(6.0)), seed=0, R=1):
    """Exact CT truth (relative CPPV state) and noisy bearings."""
    rng = np.random.default_rng(seed)
    X = np.empty((R, T, 5))
    X[:, 0] = x0
    for k in range(1, T):
        X[:, k] = cppv_transition(X[:, k - 1], dt, VO * dt)
    z = np.arctan2(X[..., 1], X[..., 0]) + SIG * rng.standard_normal((R, T))
    own = np.broadcast_to(np.r_[0.0, 0.0, VO], (T, 4))
    return np.arange(T) * dt, X, z, own


@pytest.mark.parametrize("n_r,r1,s1,rn,sn", [(10, 1129.5, 74.7, 8971.6, 593.7), (25, 1048.2, 27.9, 9560.1, 254.0),
                                             (150, 1007.7, 4.5, 9923.8, 44.0)])
def test_the_range_grid_reproduces_the_digest_table(n_r, r1, s1, rn, sn):
    r, s = range_grid(n_r, 1000.0, 10000.0)
    assert (r[0], s[0], r[-1], s[-1]) == pytest.approx((r1, s1, rn, sn), abs=0.06)


def test_the_turn_rate_and_heading_grids_use_the_corrected_spacings():
    w, sw = omega_grid(BankSettings(n_omega=3))
    assert np.rad2deg(w) == pytest.approx([-8, 0, 8]) and np.rad2deg(sw) == pytest.approx(4.0)
    w, sw = omega_grid(BankSettings(n_omega=1))
    assert w == pytest.approx([0.0]) and np.rad2deg(sw) == pytest.approx(8.0)  # D2
    assert omega_grid(BankSettings(n_omega=1, sigma_omega_faithful=True))[1] == pytest.approx(0.0)
    th, sth = theta_grid(BankSettings(n_theta=6))
    assert np.rad2deg(th) == pytest.approx([0, 60, 120, 180, 240, 300]) and np.rad2deg(sth) == pytest.approx(30)
    th, sth = theta_grid(BankSettings(n_theta=1))
    assert th == pytest.approx([0.0]) and sth == pytest.approx(np.pi / np.sqrt(3))


def test_the_presets_carry_the_thesis_tables():
    assert PRESETS["cppv_25_1_6"].n_filters == 150 and PRESETS["mpc_15_5_2"].coords == "mpc"
    assert PRESETS["table5_3_ft50"].n_filters == 180
    assert PRESETS["table5_2_ft10"].omega_min_rps < PRESETS["table5_2_ft10"].omega_max_rps < 0
    s = BankSettings.from_mapping({"preset": "cppv_25_1_6", "sigma_v2": 2e-3})
    assert s.sigma_v2 == 2e-3 and s.n_r == 25
    with pytest.raises(ValueError, match="unknown key"):
        BankSettings.from_mapping({"n_rr": 3})
    with pytest.raises(ValueError, match="preset 'nope'"):
        settings_for("nope")


def test_the_prior_lies_on_the_first_bearing_with_a_rotated_line_of_sight_covariance():
    s = BankSettings(n_r=5, n_omega=3, n_theta=2)
    beta0 = np.array([0.3, -2.0])
    c = bank_prior(s, beta0, SIG)
    assert c.mean.shape == (2, 30, 5) and c.cov.shape == (2, 30, 5, 5)
    assert np.arctan2(c.mean[..., 1], c.mean[..., 0]) == pytest.approx(np.repeat(beta0[:, None], 30, 1))
    r, sr = range_grid(5, 1000.0, 10000.0)
    # range fastest, then ω, then θ
    assert np.hypot(c.mean[0, :5, 0], c.mean[0, :5, 1]) == pytest.approx(r)
    assert c.mean[0, 5, 4] == pytest.approx(0.0) and c.mean[0, 15, 3] == pytest.approx(np.pi)
    u = np.array([np.cos(0.3), np.sin(0.3)])
    p = np.array([-np.sin(0.3), np.cos(0.3)])
    Pp = c.cov[0, 2, :2, :2]
    assert u @ Pp @ u == pytest.approx(sr[2] ** 2) and p @ Pp @ p == pytest.approx((r[2] * SIG) ** 2)
    assert np.exp(c.logw).sum(axis=1) == pytest.approx([1.0, 1.0])


@pytest.mark.slow
def test_a_one_filter_bank_equals_the_ekf_stepped_by_hand():
    t, X, z, own = orbit(T=60)
    s = BankSettings(n_r=1, n_omega=1, n_theta=1)
    tr = run_bank(s, t, z[0], SIG, own, store_components=True)
    c = bank_prior(s, z[0, :1], SIG)
    ekf = ExtendedKalmanFilter(LinearTransition(np.eye(5), np.zeros((5, 5))), BearingMeasurement(SIG))
    st = GaussianState(c.mean[0, 0], c.cov[0, 0])
    for k in range(1, 60):
        dt = t[k] - t[k - 1]
        F = cppv_jacobian(st.mean, dt)
        st = ekf.predict(st, 1, F=F, Q=cppv_process_noise(dt, 1e-3, 5e-6), fx=cppv_transition(st.mean, dt, VO * dt))
        st = ekf.update(GaussianState(st.mean, st.cov, 1), z[0, k:k + 1])
        assert tr.mean[0, k] == pytest.approx(st.mean, rel=1e-8)  # round-off: batched vs unbatched products
    assert tr.cov[0, -1] == pytest.approx(st.cov, rel=1e-7)
    assert tr.entropy == pytest.approx(0.0) and (tr.ml_index == 0).all()


def test_weights_normalise_and_the_bank_tracks_an_orbit():
    t, X, z, own = orbit(T=1200)
    tr = run_bank("cppv_25_1_6", t, z[0], SIG, own)
    assert tr.weights.sum(axis=-1) == pytest.approx(np.ones((1, 1200)))
    assert np.all(tr.entropy >= -1e-12) and np.all(tr.entropy <= np.log(150) + 1e-9)
    assert tr.entropy[0, 0] == pytest.approx(np.log(150))
    assert (tr.ml_index == np.argmax(tr.weights, axis=-1)).all()
    r = np.hypot(X[0, :, 0], X[0, :, 1])
    rh = np.hypot(tr.mean[0, :, 0], tr.mean[0, :, 1])
    assert abs(rh[-1] - r[-1]) / r[-1] < 0.1
    assert np.isfinite(tr.nis[0, 1:]).all() and np.isnan(tr.nis[0, 0])
    assert not tr.diverged.any() and tr.measured[0, 1:].all() and not tr.measured[0, 0]


def test_runs_in_one_call_equal_the_runs_one_by_one():
    t, X, z, own = orbit(T=80, R=2, seed=5)
    z[1] += 0.3
    both = run_bank("cppv_10_1_6", t, z, SIG, own)
    for i in range(2):
        one = run_bank("cppv_10_1_6", t, z[i], SIG, own)
        assert both.mean[i] == pytest.approx(one.mean[0], rel=1e-12)
        assert both.weights[i] == pytest.approx(one.weights[0], rel=1e-9, abs=1e-300)


def test_the_combination_uses_a_circular_heading():
    mean = np.zeros((2, 5))
    mean[:, 3] = [np.pi - 0.1, -np.pi + 0.1]
    cov = np.broadcast_to(np.eye(5), (2, 5, 5))
    m, P = combine(mean, cov, np.log([0.5, 0.5]), (3,))
    assert abs(abs(m[3]) - np.pi) < 1e-12
    assert P[3, 3] == pytest.approx(1.0 + 0.01)
    assert weight_entropy(np.log([0.5, 0.5])) == pytest.approx(np.log(2))


def test_a_nan_bearing_is_a_predict_only_step():
    t, X, z, own = orbit(T=40)
    z[0, 20:25] = np.nan
    tr = run_bank("cppv_10_1_6", t, z[0], SIG, own, store_components=True)
    assert not tr.measured[0, 20:25].any() and tr.measured[0, 25]
    assert tr.n_predict_only[0] == 6
    assert tr.weights[0, 20:25] == pytest.approx(np.broadcast_to(tr.weights[0, 19], (5, 60)), rel=1e-12)
    pred = cppv_transition(tr.component_mean[0, 19], 0.05, VO * 0.05)
    assert tr.component_mean[0, 20] == pytest.approx(pred, rel=1e-12)
    assert np.isnan(tr.nis[0, 20:25]).all() and tr.loglik[0, 20] == 0.0


def test_a_filter_whose_covariance_stops_being_finite_is_flagged_and_frozen():
    c = bank_prior(BankSettings(n_r=3, n_omega=1, n_theta=2), np.array([0.4]), SIG)
    cov = c.cov.copy()
    cov[0, 1, 2, 2] = np.inf  # filter 1 breaks
    comp = Components(c.mean, cov, c.logw, c.diverged)
    model = CppvModel(BankSettings(n_r=3, n_omega=1, n_theta=2))
    nxt, st = components_step(model, comp, 0.05, VO, np.array([0.401]), SIG)
    assert st.new_diverged[0].tolist() == [False, True, False, False, False, False]
    assert nxt.diverged[0, 1] and np.exp(nxt.logw[0, 1]) == 0.0
    assert np.array_equal(nxt.mean[0, 1], c.mean[0, 1])  # frozen
    assert np.exp(nxt.logw).sum() == pytest.approx(1.0)
    assert np.isfinite(nxt.mean[0, [0, 2, 3, 4, 5]]).all() and not np.allclose(nxt.mean[0, 0], c.mean[0, 0])
    again, st2 = components_step(model, nxt, 0.05, VO, np.array([0.402]), SIG)
    assert not st2.new_diverged.any() and np.array_equal(again.mean[0, 1], c.mean[0, 1])
    assert np.isfinite(st2.loglik).all()


def test_the_gate_rejects_an_outlier_bearing_for_the_whole_bank():
    t, X, z, own = orbit(T=200)
    z[0, 150] += np.deg2rad(5.0)
    gated = run_bank("cppv_10_1_6", t, z[0], SIG, own, gate=True)
    assert gated.gated[0, 150] and not gated.measured[0, 150]
    assert gated.gated[0].sum() <= 3
    plain = run_bank("cppv_10_1_6", t, z[0], SIG, own)
    assert not plain.gated.any() and plain.nis[0, 150] > 6.63


def test_an_mpc_bank_reports_its_estimate_in_cppv_too():
    t, X, z, own = orbit(T=300)
    tr = run_bank(BankSettings(coords="mpc", n_r=5, n_omega=3, n_theta=2), t, z[0], SIG, own)
    assert tr.state_names[2] == "beta_rad" and tr.cppv_mean.shape == (1, 300, 5)
    # the MPC bearing state follows the measured bearing; its CPPV image points along it
    assert np.abs(np.angle(np.exp(1j * (tr.mean[0, -1, 2] - z[0, -1])))) < 0.01
    assert np.arctan2(tr.cppv_mean[0, -1, 1], tr.cppv_mean[0, -1, 0]) == pytest.approx(tr.mean[0, -1, 2], abs=0.01)
    assert np.isfinite(tr.cppv_cov).all()


def test_bad_input_is_one_clear_error():
    with pytest.raises(ValueError, match="z_rad shaped"):
        run_bank("cppv_10_1_6", np.arange(5.0), np.zeros(4))
    with pytest.raises(ValueError, match="no finite bearing"):
        run_bank("cppv_10_1_6", np.arange(5.0), np.full(5, np.nan))
    with pytest.raises(ValueError, match="strictly increasing"):
        run_bank("cppv_10_1_6", np.zeros(5), np.zeros(5))


def test_a_run_whose_first_bearing_is_missing_is_refused_not_started_from_a_later_one():
    # the prior used to take the first finite bearing, stamped at t_s[0]: 10 s late here, on a
    # line of sight 11 degrees off, and that bearing was then used again at its own step
    t, X, z, own = orbit(T=300)
    late = z.copy()
    late[0, :200] = np.nan
    with pytest.raises(ValueError, match=r"run\(s\) \[0\] start with \[200\] missing bearing\(s\)"):
        run_bank("cppv_10_1_6", t, late[0], SIG, own)
    tr = run_bank("cppv_10_1_6", t[200:] - t[200], late[0, 200:], SIG, own[200:])
    assert np.isfinite(tr.mean).all()


@pytest.mark.parametrize("preset", ["cppv_10_1_6", BankSettings(coords="mpc", n_r=5, n_omega=3, n_theta=2)])
def test_the_compiled_algebra_equals_the_extended_kalman_filter_path(preset):
    t, X, z, own = orbit(T=120)
    z[0, 50] = np.nan
    fast = run_bank(preset, t, z[0], SIG, own, store_components=True)
    ref = run_bank(preset, t, z[0], SIG, own, store_components=True, algebra="ekf")
    assert fast.component_mean == pytest.approx(ref.component_mean, rel=1e-9, abs=1e-12)
    assert fast.cov == pytest.approx(ref.cov, rel=1e-7, abs=1e-14)
    assert fast.weights == pytest.approx(ref.weights, rel=1e-7, abs=1e-300)
    assert fast.nis[0, 1:] == pytest.approx(ref.nis[0, 1:], rel=1e-8, nan_ok=True)
    with pytest.raises(ValueError, match="algebra"):
        run_bank(preset, t[:3], z[0, :3], SIG, own[:3], algebra="cuda")


def test_a_two_filter_weight_update_matches_the_hand_computed_gaussian_likelihoods():
    # eq. 3.18-3.20: W_k ∝ W_{k-1} det(S)^{-1/2} exp(-ỹ²/2S), ỹ wrapped; S at the predicted
    # mean and covariance; the prior enters once. Bearings near the ±π cut test the wrap.
    dt, s2 = 0.05, SIG ** 2
    mean = np.array([[[-3000.0, 5.0, 70.0, 1.0, 0.05], [-2500.0, -20.0, 60.0, 2.0, -0.03]]])
    cov = np.stack([np.diag([300.0 ** 2, 50.0 ** 2, 4.0, 0.1, 1e-3]), np.diag([200.0 ** 2, 80.0 ** 2, 9.0, 0.2, 2e-3])])[None]
    w0 = np.array([0.3, 0.7])
    z = np.array([np.pi - 0.004])
    model = CppvModel(BankSettings())
    Q = cppv_process_noise(dt, 1e-3, 5e-6)
    post, st = components_step(model, Components(mean, cov, np.log(w0)[None], np.zeros((1, 2), bool)),
                               dt, VO, z, SIG)
    loglik = []
    for i in range(2):
        F = cppv_jacobian(mean[0, i], dt)
        xp = cppv_transition(mean[0, i], dt, VO * dt)
        Pp = F @ cov[0, i] @ F.T + Q
        r2 = xp[0] ** 2 + xp[1] ** 2
        H = np.array([-xp[1] / r2, xp[0] / r2, 0.0, 0.0, 0.0])
        S = H @ Pp @ H + s2
        y = (z[0] - np.arctan2(xp[1], xp[0]) + np.pi) % (2 * np.pi) - np.pi
        assert abs(y) < 0.1                                        # wrapped across the cut
        loglik.append(-0.5 * np.log(2 * np.pi * S) - 0.5 * y * y / S)
        K = Pp @ H / S
        assert post.mean[0, i] == pytest.approx(xp + K * y, rel=1e-9)
    w = w0 * np.exp(loglik)
    assert np.exp(post.logw[0]) == pytest.approx(w / w.sum(), rel=1e-9)
    assert st.loglik[0] == pytest.approx(np.log(w.sum()), rel=1e-12)


def test_the_table_4_2_presets_are_the_thesis_cases():
    # seed Table 4.2: Case 1 (N_r, 1, 1); Case 2 (25, N_ω, 1); Case 3 (25, 1, N_θ); Case 4 mixed
    from pipeline.studies.bearing_only import CASE1, TABLE_4_2

    grids = {n: (PRESETS[n].n_r, PRESETS[n].n_omega, PRESETS[n].n_theta) for n in TABLE_4_2}
    assert set(grids.values()) == {(10, 1, 1), (25, 1, 1), (150, 1, 1), (25, 3, 1), (25, 6, 1), (25, 1, 3),
                                   (25, 1, 6), (25, 2, 3), (15, 2, 5), (16, 3, 3)}
    assert [grids[n] for n in CASE1] == [(25, 1, 1), (10, 1, 1), (150, 1, 1)]
    assert all(PRESETS[n].coords == "cppv" and PRESETS[n].n_filters <= 150 for n in TABLE_4_2)


def test_the_compiled_combination_equals_the_numpy_reference(rng):
    from pipeline.estimate.bank import combine_numpy

    mean = rng.normal(size=(3, 2, 7, 5)) * [100.0, 100.0, 5.0, 3.0, 0.1]
    mean[..., 3] += np.pi * rng.choice([-1.0, 1.0], size=(3, 2, 7))      # headings across the ±π cut
    A = rng.normal(size=(3, 2, 7, 5, 5))
    cov = A @ np.swapaxes(A, -1, -2) + np.eye(5)
    logw = rng.normal(size=(3, 2, 7))
    logw[0, 1, 2:] = -np.inf                                              # excluded components
    logw -= np.log(np.exp(logw).sum(axis=-1, keepdims=True))
    for idx in ((), (3,), (2, 3)):
        m, P = combine(mean, cov, logw, idx)
        m0, P0 = combine_numpy(mean, cov, logw, idx)
        assert m.shape == (3, 2, 5) and P.shape == (3, 2, 5, 5)
        np.testing.assert_allclose(m, m0, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(P, P0, rtol=1e-10, atol=1e-8)
    m, P = combine(mean[0, 0], cov[0, 0], logw[0, 0], (3,))             # one mixture, no batch
    np.testing.assert_allclose(P, combine_numpy(mean[0, 0], cov[0, 0], logw[0, 0], (3,))[1], rtol=1e-10)
