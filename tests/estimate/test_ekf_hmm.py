"""EKF+HMM (seed 000 §8): step assembly, causality, fallbacks, Q₂ and bad input."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from helpers_maneuvers import synth_bulk
from pipeline.estimate.base import ConstantAcceleration, GaussianState, LinearTransition
from pipeline.estimate.ekf import ExtendedKalmanFilter, run_filter
from pipeline.estimate.ekf_hmm import (EkfHmmError, classifier_state, ekf_state_frame, hmm_filter, hmm_step,
                                       prior_increment_track, q2_from_runs, run_ekf_hmm)
from pipeline.estimate.models import (STATE_COLUMNS, RadarModel, ca_transition, hmm_input,
                                      hmm_transition, initial_cov, white_jerk_q)
from pipeline.models.base import ModelsConfig
from pipeline.models.classifier import ManeuverModelSet

FAST = dict(n_states=3, n_iter=10, tol=1e-1, gmm_restarts=1, seed=5)
DT = 0.2


@pytest.fixture(scope="module")
def trained():
    data = synth_bulk(("M1", "M2", "M3"), 4, np.random.default_rng(20261201))
    return ManeuverModelSet(config=ModelsConfig(**FAST)).fit(data), data


def _with(ms, **cfg):
    """A shallow copy of a trained model set with config fields replaced."""
    out = copy.copy(ms)
    out.config = dataclasses.replace(ms.config, **cfg)
    return out


def _radar_runs(data, labels, rng, n=2):
    """Radar measurements of the first ``n`` runs of each label, site 2 km north-west, below."""
    radar = RadarModel(site_ned_m=(2000.0, -1500.0, 300.0))
    runs = [g for _, g in data.groupby("run_id", sort=True) if g["label"].iloc[0] in labels][:n]
    truth = np.stack([g[list(STATE_COLUMNS)].to_numpy() for g in runs])      # (R, T, 9)
    t_ns = runs[0]["t_ns"].to_numpy()
    z = np.swapaxes(radar.measure(truth, rng), 0, 1)                          # (T, R, 4)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(50.0), radar)
    prior = GaussianState(truth[:, 0], np.broadcast_to(initial_cov(), (len(runs), 9, 9)).copy(), int(t_ns[0]))
    return ekf, prior, t_ns, z, truth


def test_hmm_step_takes_a_h_b_and_q2_on_hmm_axes_and_ca_elsewhere():
    A, Q = ca_transition(DT), white_jerk_q(DT, 3.0)
    AH, B = hmm_transition(DT), hmm_input(DT)
    rng = np.random.default_rng(1)
    L = rng.standard_normal((9, 9))
    Q2 = L @ L.T
    acc, jerk = rng.standard_normal((3, 3)), rng.standard_normal((3, 3))
    axes = np.array([[True, True, True], [False, False, False], [True, False, True]])
    F, Qk, bu = hmm_step(axes, A, Q, AH, B, Q2, acc, jerk)
    np.testing.assert_array_equal(F[0], AH)
    np.testing.assert_array_equal(Qk[0], Q2)
    np.testing.assert_allclose(bu[0], B @ np.r_[acc[0], jerk[0]])
    np.testing.assert_array_equal(F[1], A)
    np.testing.assert_array_equal(Qk[1], Q)
    np.testing.assert_array_equal(bu[1], 0.0)
    # mixed: the east components (1, 4, 7) keep CA, north/down take the HMM step
    e, nd = [1, 4, 7], [0, 2, 3, 5, 6, 8]
    np.testing.assert_array_equal(F[2][e], A[e])
    np.testing.assert_array_equal(F[2][nd], AH[nd])
    np.testing.assert_array_equal(Qk[2][np.ix_(e, nd)], 0.0)
    np.testing.assert_array_equal(Qk[2][np.ix_(nd, nd)], Q2[np.ix_(nd, nd)])
    np.testing.assert_array_equal(Qk[2][np.ix_(e, e)], Q[np.ix_(e, e)])
    np.testing.assert_array_equal(bu[2][e], 0.0)
    assert np.linalg.eigvalsh(Qk[2]).min() > -1e-12      # still a covariance
    # the predicted acceleration of an HMM axis is â + dt·ĵ (the state's own a is dropped)
    x = rng.standard_normal(9)
    xp = F[0] @ x + bu[0]
    np.testing.assert_allclose(xp[6:], acc[0] + DT * jerk[0])


def test_never_confident_classifier_leaves_the_ekf_hmm_equal_to_the_ekf(trained):
    ms, data = trained
    never = _with(ms, confidence_threshold=-1e9)
    ekf, prior, t_ns, z, _ = _radar_runs(data, ("M1", "M2"), np.random.default_rng(2))
    out = run_ekf_hmm(ekf, prior, t_ns, z, never, np.eye(9))
    assert not out.mode.any()
    np.testing.assert_array_equal(out.hmm.mean, out.ekf.mean)
    np.testing.assert_array_equal(out.hmm.cov, out.ekf.cov)
    # and the baseline is exactly run_filter's
    np.testing.assert_array_equal(out.ekf.mean, run_filter(ekf, prior, t_ns, z, store="filtered").mean)


def test_ekf_hmm_uses_hmm_inputs_causally_and_tracks_the_truth(trained):
    ms, data = trained
    Q2 = q2_from_runs(ms, data[data["label"] == "M1"], scale=2.0)
    ekf, prior, t_ns, z, truth = _radar_runs(data, ("M1",), np.random.default_rng(3))
    out = run_ekf_hmm(ekf, prior, t_ns, z, ms, Q2)
    assert out.mode.shape == (2, len(t_ns)) and out.mode.mean() > 0.3   # known maneuver: HMM steps
    assert not out.mode[:, :2].any()                              # step 0, and no output before step 1
    # mode at k follows the classifier's output at k − 1
    known = out.pred != "unknown"
    assert not (out.mode[:, 1:] & ~known[:, :-1]).any()
    rmse = np.sqrt(np.mean((out.hmm.mean - truth) ** 2, axis=(0, 1)))
    assert np.all(rmse[:3] < 5.0) and np.all(np.isfinite(out.hmm.cov))
    # changing the radar after step k changes nothing at or before k (both filters, the mode)
    k = len(t_ns) // 2
    z2 = z.copy()
    z2[k + 1:] += 5.0
    out2 = run_ekf_hmm(ekf, prior, t_ns, z2, ms, Q2)
    np.testing.assert_array_equal(out2.hmm.mean[:, :k + 1], out.hmm.mean[:, :k + 1])
    np.testing.assert_array_equal(out2.mode[:, :k + 1], out.mode[:, :k + 1])


def test_radar_gaps_are_predict_only_steps_of_both_filters(trained):
    ms, data = trained
    ekf, prior, t_ns, z, _ = _radar_runs(data, ("M2",), np.random.default_rng(4))
    z = z.copy()
    z[10:15, 0] = np.nan
    Q2 = np.eye(9) * 0.1
    out = run_ekf_hmm(ekf, prior, t_ns, z, ms, Q2)
    assert out.ekf.n_predict_only.tolist() == [5, 0] and out.hmm.n_predict_only.tolist() == [5, 0]
    assert (out.ekf.dof[0, 10:15] == 0).all() and (out.hmm.dof[0, 10:15] == 0).all()
    assert out.hmm_axes[0, 10:15].any()          # the gap holds HMM-input predictions, not only CA
    for k in range(10, 15):
        dt = (int(t_ns[k]) - int(t_ns[k - 1])) * 1e-9
        A, Q = ca_transition(dt), white_jerk_q(dt, ekf.transition.q)
        # baseline EKF: the CA prediction of the posterior before, nothing added by an update
        m, P = out.ekf.mean[0, k - 1], out.ekf.cov[0, k - 1]
        np.testing.assert_allclose(out.ekf.mean[0, k], A @ m, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(out.ekf.cov[0, k], A @ P @ A.T + Q, rtol=1e-12, atol=1e-12)
        # EKF+HMM: F·x + B·u, F P Fᵀ + Q_k as hmm_step assembles them from step k−1's inputs
        F, Qk, bu = hmm_step(out.hmm_axes[:1, k], A, Q, hmm_transition(dt), hmm_input(dt), Q2,
                             out.acc_hmm[:1, k - 1], out.jerk_hmm[:1, k - 1])
        m, P = out.hmm.mean[0, k - 1], out.hmm.cov[0, k - 1]
        np.testing.assert_allclose(out.hmm.mean[0, k], F[0] @ m + bu[0], rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(out.hmm.cov[0, k], F[0] @ P @ F[0].T + Qk[0], rtol=1e-12, atol=1e-12)
    # the first step after the gap is an update again: the covariance shrinks below the prediction
    k, dt = 15, (int(t_ns[15]) - int(t_ns[14])) * 1e-9
    A = ca_transition(dt)
    pred = A @ out.ekf.cov[0, 14] @ A.T + white_jerk_q(dt, ekf.transition.q)
    assert np.trace(out.ekf.cov[0, k]) < 0.5 * np.trace(pred)


def test_gated_axes_fall_back_to_ca(trained):
    ms, data = trained
    tight = _with(ms, gate_mps2=1e-6)    # every change is a jump
    ekf, prior, t_ns, z, _ = _radar_runs(data, ("M1",), np.random.default_rng(5))
    out = run_ekf_hmm(ekf, prior, t_ns, z, tight, np.eye(9))
    # the gate compares with the previous estimate, so it keeps only the first GMR output
    first = np.isfinite(out.acc_hmm[..., 0]).argmax(axis=1)
    assert np.all(first >= 1)
    for r, f in enumerate(first):
        assert not out.gated[r, f].any() and out.gated[r, f + 1:].all()
        # ... which feeds the one step after it; every later step falls back to CA on every axis
        assert out.hmm_axes[r, f + 1].all() and not out.hmm_axes[r, f + 2:].any()


def test_q2_is_a_symmetric_covariance_with_r_v_a_cross_terms_and_scales_linearly(trained):
    ms, data = trained
    q1 = q2_from_runs(ms, data)
    q3 = q2_from_runs(ms, data, scale=3.0)
    np.testing.assert_allclose(q3, 3.0 * q1)
    np.testing.assert_allclose(q1, q1.T)
    assert np.linalg.eigvalsh(q1).min() > -1e-12
    assert np.abs(q1[3:6, 6:9]).max() > 0 and np.abs(q1[0:3, 6:9]).max() > 0


def test_bad_inputs_raise_one_clear_error(trained):
    ms, data = trained
    aero = _with(ms, feature_set="aero")
    ekf, prior, t_ns, z, _ = _radar_runs(data, ("M1",), np.random.default_rng(6))
    with pytest.raises(EkfHmmError, match="'aero' does not give"):
        run_ekf_hmm(ekf, prior, t_ns, z, aero, np.eye(9))
    with pytest.raises(EkfHmmError, match="aero"):
        q2_from_runs(aero, data)
    with pytest.raises(EkfHmmError, match="9×9"):
        run_ekf_hmm(ekf, prior, t_ns, z, ms, np.eye(6))
    with pytest.raises(EkfHmmError, match="scale"):
        q2_from_runs(ms, data, scale=0.0)
    with pytest.raises(EkfHmmError, match="lacks column"):
        q2_from_runs(ms, data.drop(columns=["acc_n_mps2"]))


def test_state_frame_lays_runs_end_to_end_with_their_heading():
    mean = np.arange(2 * 3 * 9, dtype=float).reshape(2, 3, 9)
    df = ekf_state_frame(mean, [0, 200_000_000, 400_000_000], yaw_rad=[0.1, 0.2])
    assert list(df.columns[:2]) == ["run_id", "t_ns"] and list(df.columns[2:11]) == list(STATE_COLUMNS)
    np.testing.assert_array_equal(df["run_id"], [0, 0, 0, 1, 1, 1])
    np.testing.assert_array_equal(df["yaw_rad"], [0.1] * 3 + [0.2] * 3)
    np.testing.assert_array_equal(df[list(STATE_COLUMNS)].to_numpy(), mean.reshape(6, 9))
    with pytest.raises(EkfHmmError, match="2 times for 3 steps"):
        ekf_state_frame(mean, [0, 1])


def test_the_hmm_filter_alone_reproduces_the_ekf_hmm_from_its_classification(trained, rng):
    ms, data = trained
    ekf, prior, t_ns, z, _ = _radar_runs(data, ("M1", "M2"), rng)
    Q2 = q2_from_runs(ms, data)
    tr = run_ekf_hmm(ekf, prior, t_ns, z, ms, Q2)
    again = hmm_filter(ekf, prior, t_ns, z, Q2, tr.hmm_axes, tr.acc_hmm, tr.jerk_hmm)
    np.testing.assert_array_equal(again.mean, tr.hmm.mean)
    np.testing.assert_array_equal(again.cov, tr.hmm.cov)
    # a larger Q₂ changes only the EKF+HMM, never the classification it is given
    bigger = hmm_filter(ekf, prior, t_ns, z, 10 * Q2, tr.hmm_axes, tr.acc_hmm, tr.jerk_hmm, store="mean")
    assert bigger.cov is None and not np.allclose(bigger.mean, tr.hmm.mean)
    with pytest.raises(EkfHmmError, match=r"axes/acc/jerk must be shaped"):
        hmm_filter(ekf, prior, t_ns, z, Q2, tr.hmm_axes[:, :-1], tr.acc_hmm, tr.jerk_hmm)


def test_q2_from_estimated_inputs_equals_the_truth_q2_on_the_truth_and_grows_with_input_noise(trained, rng):
    ms, data = trained
    q1 = q2_from_runs(ms, data)
    np.testing.assert_array_equal(q2_from_runs(ms, data, input_state=data), q1)
    noisy = data.copy()
    for c in STATE_COLUMNS[:3]:
        noisy[c] = noisy[c] + rng.normal(0.0, 0.5, len(noisy))
    qn = q2_from_runs(ms, data, input_state=noisy)
    # the errors are still taken against the truth, with the GMR fed by noisy states
    assert np.trace(qn[6:, 6:]) > np.trace(q1[6:, 6:])
    with pytest.raises(EkfHmmError, match=r"input_state lacks column"):
        q2_from_runs(ms, data, input_state=noisy.drop(columns=["pos_n_m"]))


def test_the_a_h_b_filter_is_exact_with_the_current_inputs_and_one_step_late_loses_a_whole_step():
    """The EKF+HMM machinery (A_H, B, Q₂ from one-step errors, the radar update) isolated from
    the GMR: on white-jerk truth, inputs ``[a_k; (a_{k+1} − a_k)/dt]`` make the predicted
    acceleration exact (4.3: a_{k+1} = â + dt ĵ), so the filter's acceleration error vanishes;
    the same inputs one step late leave an error of about the acceleration's one-step change
    (the radar update barely corrects it). The real-data diagnosis of issue 14 rests on this:
    an HMM acceleration that trails the current one by a fraction of a step costs that much."""
    from pipeline.estimate.montecarlo import measure, simulate_white_jerk

    dt, q, R, T = DT, 20.0, 30, 100
    rng = np.random.default_rng(14)
    truth = simulate_white_jerk(R, T, dt, q, np.array([0, 0, -100, 20, 5, 0, 0, 0, 0.0]), rng=rng)
    radar = RadarModel(site_ned_m=(-800.0, 600.0, 0.0))
    z = measure(radar, truth, rng)
    z = z if z.shape[0] == T else np.swapaxes(z, 0, 1)
    t_ns = np.arange(T, dtype=np.int64) * int(dt * 1e9)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), radar)
    prior = GaussianState(truth[:, 0], np.broadcast_to(initial_cov(), (R, 9, 9)).copy(), 0)
    base = run_filter(ekf, prior, t_ns, z, store="mean")
    a = truth[..., 6:]
    j = np.zeros_like(a)
    j[:, :-1] = (a[:, 1:] - a[:, :-1]) / dt
    axes = np.ones((R, T, 3), dtype=bool)
    axes[:, 0] = False

    def q2(acc, jerk):                           # E[e eᵀ] of the one-step A_H/B errors (q2_from_runs)
        u = np.concatenate([acc, jerk], -1)[:, :-1]
        e = (truth[:, 1:] - truth[:, :-1] @ hmm_transition(dt).T - u @ hmm_input(dt).T).reshape(-1, 9)
        return e.T @ e / len(e)

    def acc_rmse(mean):
        return float(np.sqrt(np.mean(np.sum((mean - truth)[:, 5:, 6:] ** 2, -1))))

    exact = hmm_filter(ekf, prior, t_ns, z, q2(a, j), axes, a, j, store="mean")
    la, lj = np.concatenate([a[:, :1], a[:, :-1]], 1), np.concatenate([j[:, :1], j[:, :-1]], 1)
    late = hmm_filter(ekf, prior, t_ns, z, q2(la, lj), axes, la, lj, store="mean")
    step = float(np.sqrt(np.mean(np.sum((a[:, 6:] - a[:, 5:-1]) ** 2, -1))))   # one-step change
    e_ekf, e_exact, e_late = acc_rmse(base.mean), acc_rmse(exact.mean), acc_rmse(late.mean)
    assert e_exact < 1e-6 * e_ekf
    assert 0.8 * step < e_late < 1.1 * step


def test_one_step_q2_is_the_second_moment_of_the_a_h_b_errors_and_skips_nan_steps(rng):
    from pipeline.estimate.ekf_hmm import one_step_q2

    x, acc, jerk = rng.normal(size=(40, 9)), rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    acc[7] = np.nan
    e = np.array([x[k + 1] - hmm_transition(DT) @ x[k] - hmm_input(DT) @ np.r_[acc[k], jerk[k]]
                  for k in range(39) if k != 7])
    np.testing.assert_allclose(one_step_q2(x, acc, jerk, DT), e.T @ e / len(e), rtol=1e-12)
    np.testing.assert_allclose(one_step_q2(x[None], acc[None], jerk[None], DT), e.T @ e / len(e), rtol=1e-12)
    with pytest.raises(EkfHmmError, match="do not fit"):
        one_step_q2(x, acc[:, :2], jerk, DT)


def test_q2_from_runs_pairs_each_gmr_input_with_the_step_that_leaves_it(trained):
    """``q2_from_runs`` recomputed by hand: per run, the classifier's ``â_k, ĵ_k`` (known label, no
    axis gated) drive the step ``x_k → x_{k+1}``; the second moment of those errors, through
    :func:`one_step_q2`, is the same matrix."""
    from pipeline.estimate.ekf_hmm import one_step_q2

    ms, data = trained
    cls = ms.classify(data)
    xs, accs, jerks = [], [], []
    for rid, run in data.groupby("run_id", sort=False):
        c = cls[cls["run_id"] == rid].set_index("t_ns")
        run = run.sort_values("t_ns")
        a = c.reindex(run["t_ns"])[[f"acc_hmm_{x}_mps2" for x in "ned"]].to_numpy()
        j = c.reindex(run["t_ns"])[[f"jerk_hmm_{x}_mps3" for x in "ned"]].to_numpy()
        g = c.reindex(run["t_ns"])[[f"acc_hmm_gated_{x}" for x in "ned"]].fillna(True).to_numpy(dtype=bool)
        bad = (c.reindex(run["t_ns"])["pred"] == "unknown").to_numpy() | g.any(axis=1)
        a[bad], j[bad] = np.nan, np.nan
        xs.append(run[list(STATE_COLUMNS)].to_numpy())
        accs.append(a)
        jerks.append(j)
    T = min(len(x) for x in xs)
    x, a, j = (np.stack([v[:T] for v in vs]) for vs in (xs, accs, jerks))
    by_hand = one_step_q2(x, a, j, DT)
    assert np.isfinite(a).all(axis=-1).mean() > 0.5          # most steps carry HMM inputs
    np.testing.assert_allclose(q2_from_runs(ms, data), by_hand, rtol=1e-10, atol=1e-14)


def test_second_differences_of_ekf_posterior_positions_are_a_far_worse_acceleration_than_the_ekfs():
    """Why ``pos_fd`` (and any GMR on posterior position increments, digest §13.4) suffers on EKF
    input: each radar update moves the posterior position, and the second difference divides
    those moves by dt² — on white-jerk truth at a few km the result is several times the EKF's
    own acceleration error (seed-000 sim, 12 test runs each, measured: M1 20.4 vs 2.9 m/s², M2 5.9
    vs 1.0, M3 10.1 vs 1.7, M4 10.0 vs 0.9)."""
    from pipeline.estimate.montecarlo import measure, simulate_white_jerk

    dt, q, R, T = DT, 3.0, 30, 100
    rng = np.random.default_rng(1414)
    truth = simulate_white_jerk(R, T, dt, q, np.array([2000, 1500, -150, -20, 10, 0, 0, 0, 0.0]), rng=rng)
    radar = RadarModel(site_ned_m=(0.0, 0.0, 0.0))
    t_ns = np.arange(T, dtype=np.int64) * int(dt * 1e9)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), radar)
    prior = GaussianState(truth[:, 0], np.broadcast_to(initial_cov(), (R, 9, 9)).copy(), 0)
    post = run_filter(ekf, prior, t_ns, measure(radar, truth, rng), store="mean").mean
    p = post[..., :3]
    fd2 = (p[:, 2:] - 2 * p[:, 1:-1] + p[:, :-2]) / dt ** 2                  # a(t_{k−1})

    def rmse(e):
        return float(np.sqrt(np.mean(np.sum(e[:, 10:] ** 2, -1))))

    e_ekf = rmse(post[:, 1:-1, 6:] - truth[:, 1:-1, 6:])
    e_fd2 = rmse(fd2 - truth[:, 1:-1, 6:])
    e_true_fd2 = rmse((truth[:, 2:, :3] - 2 * truth[:, 1:-1, :3] + truth[:, :-2, :3]) / dt ** 2
                      - truth[:, 1:-1, 6:])
    assert e_true_fd2 < 0.2 * e_ekf                  # on the truth the difference is nearly exact
    assert e_fd2 > 3.0 * e_ekf, (e_fd2, e_ekf)


def test_the_output_is_the_ekf_hmm_estimate_after_a_known_classification_and_the_ekf_after_unknown(trained):
    # seed 000 Ch. 4.1: "if the classification is unknown, the output of the filter is the EKF
    # estimate"; a classification with V < -1 makes the output the EKF+HMM estimate
    ms, data = trained
    Q2 = q2_from_runs(ms, data[data["label"] == "M1"], scale=2.0)
    ekf, prior, t_ns, z, _ = _radar_runs(data, ("M1",), np.random.default_rng(3))
    tr = run_ekf_hmm(ekf, prior, t_ns, z, ms, Q2)
    known = tr.pred != "unknown"
    assert not tr.switched[:, 0].any()
    np.testing.assert_array_equal(tr.switched[:, 1:], known[:, :-1])
    out = tr.output
    sw = tr.switched
    np.testing.assert_array_equal(out.mean[sw], tr.hmm.mean[sw])
    np.testing.assert_array_equal(out.mean[~sw], tr.ekf.mean[~sw])
    np.testing.assert_array_equal(out.cov[~sw], tr.ekf.cov[~sw])
    np.testing.assert_array_equal(out.nis[sw], tr.hmm.nis[sw])
    # after an HMM stretch the EKF+HMM filter keeps its own state (no reset), which differs from
    # the EKF's: an unknown step then outputs the EKF's estimate, not that state
    half = np.zeros_like(sw)
    half[:, : len(t_ns) // 2] = sw[:, : len(t_ns) // 2]
    assert tr.mode[:, : len(t_ns) // 2].any()
    later = dataclasses.replace(tr, switched=half).output
    k = len(t_ns) // 2 + 1
    assert not np.allclose(tr.hmm.mean[:, k], tr.ekf.mean[:, k])
    np.testing.assert_array_equal(later.mean[:, k:], tr.ekf.mean[:, k:])


def test_the_seed000_study_scores_the_ekf_hmm_output_not_its_internal_state(trained):
    from pipeline.studies.seed000_ekf import ekf_hmm_errors

    ms, data = trained
    Q2 = q2_from_runs(ms, data[data["label"] == "M1"], scale=2.0)
    ekf, _, t_ns, z, truth = _radar_runs(data, ("M1", "M2"), np.random.default_rng(7))
    tr, e_ekf, e_hmm = ekf_hmm_errors(ekf, ms, Q2, t_ns, truth, None, z)
    np.testing.assert_array_equal(e_hmm, tr.output.mean - truth)
    np.testing.assert_array_equal(e_hmm[~tr.switched], e_ekf[~tr.switched])


def test_gmr_decomposition_reproduces_the_classifiers_gmr_and_splits_nothing_on_exact_input(trained, rng):
    from pipeline.studies.seed000_ekf import _gmr_acc, gmr_decomposition

    ms, data = trained
    ms = _with(ms, feature_set="state9h", gate_mps2=1e9)
    ekf, prior, t_ns, z, truth = _radar_runs(data, ("M1", "M2"), rng)
    yaw = np.broadcast_to(np.array([0.3, -1.2])[:, None], truth.shape[:2])
    est = run_filter(ekf, prior, t_ns, z, store="mean").mean
    # the recomputed GMR (heading frame and back) is the classifier's own, bit for bit
    c = ms.classify(ekf_state_frame(est, t_ns, yaw_rad=yaw))
    c0 = c[c["run_id"] == 1]
    from pipeline.models.features import heading_rotation, rotate_triples
    obs = ms.normaliser_.transform(rotate_triples(np.diff(est[1], axis=0), heading_rotation(-1.2)))
    mine = _gmr_acc(ms, obs, c0["best"].to_numpy(dtype=object), c0["state"].to_numpy(), -1.2)
    np.testing.assert_allclose(mine, c0[[f"acc_hmm_{a}_mps2" for a in "ned"]].to_numpy(), atol=1e-9)
    # with the truth as "estimate" every part equals the regression's own error
    d = gmr_decomposition(ms, t_ns, truth, truth.copy(), yaw)
    assert d["gmr_tt"] == d["gmr_et"] == d["gmr_te"] == d["gmr_ee"]
    assert d["best_agree_pct"] == d["state_agree_pct"] == 100.0 and d["dr_noise_d_m"] == 0.0
    assert d["gmr_lag_steps"] in (-2, -1, 0, 1, 2) and d["gain_max_per_s2"] > 0
    e = gmr_decomposition(ms, t_ns, truth, est, yaw)
    assert e["dr_noise_d_m"] > 0 and e["gmr_ee"] != e["gmr_tt"]


def test_the_printed_increments_are_the_ekfs_predicted_ones_x_minus_next_minus_x_plus():
    rng = np.random.default_rng(11)
    t_ns = np.r_[0, np.cumsum(np.r_[[200_000_000] * 5, 100_000_000, [200_000_000] * 3])]   # one short step
    x = rng.standard_normal((2, len(t_ns), 9))
    p = prior_increment_track(x, t_ns)
    assert p.shape == x.shape
    np.testing.assert_allclose(p[:, 0], x[:, 0] @ ca_transition(0.2).T)   # q₀ = x̂⁻₁ = A x̂⁺₀
    dts = np.r_[np.diff(t_ns), t_ns[-1] - t_ns[-2]] * 1e-9
    for k in range(len(t_ns)):
        # increment stamped at t_k: x̂⁻_{k+1} − x̂⁺_k = (A(dt_k) − I) x̂⁺_k, the CA prediction's step
        inc = p[:, k] - (x[:, 0] if k == 0 else p[:, k - 1])
        want = x[:, k] @ ca_transition(dts[k]).T - x[:, k]
        np.testing.assert_allclose(inc, want, atol=1e-12)
        np.testing.assert_array_equal(want[:, 6:], 0.0)                # CA: the acceleration is carried over
    np.testing.assert_allclose(prior_increment_track(x[0], t_ns), p[0])   # one run as (T, 9)
    np.testing.assert_array_equal(classifier_state(x, t_ns, "posterior"), x)
    np.testing.assert_array_equal(classifier_state(x, t_ns, "prior"), p)
    with pytest.raises(EkfHmmError, match="increments must be one of prior, posterior"):
        classifier_state(x, t_ns, "predicted")
    with pytest.raises(EkfHmmError, match="do not fit"):
        prior_increment_track(x[:, :-1], t_ns)


def test_the_printed_increments_feed_the_classifier_causally_and_run_ekf_hmm_checks_the_choice(trained):
    ms, data = trained
    Q2 = q2_from_runs(ms, data[data["label"] == "M1"], scale=2.0)
    ekf, prior, t_ns, z, truth = _radar_runs(data, ("M1",), np.random.default_rng(3))
    out = run_ekf_hmm(ekf, prior, t_ns, z, ms, Q2, increments="prior")
    base = run_ekf_hmm(ekf, prior, t_ns, z, ms, Q2, increments="posterior")
    np.testing.assert_array_equal(out.ekf.mean, base.ekf.mean)         # the baseline EKF is the same
    assert out.mode.mean() > 0.3 and not np.array_equal(out.acc_hmm, base.acc_hmm, equal_nan=True)
    # the classification of step k is that of the predicted-increment track
    want = ms.classify(ekf_state_frame(prior_increment_track(out.ekf.mean, t_ns), t_ns))
    np.testing.assert_array_equal(out.pred[0, 1:], want[want.run_id == 0]["pred"].to_numpy(dtype=object))
    # radar after step k changes nothing at or before k
    k = len(t_ns) // 2
    z2 = z.copy()
    z2[k + 1:] += 5.0
    out2 = run_ekf_hmm(ekf, prior, t_ns, z2, ms, Q2, increments="prior")
    np.testing.assert_array_equal(out2.hmm.mean[:, :k + 1], out.hmm.mean[:, :k + 1])
    np.testing.assert_array_equal(out2.mode[:, :k + 1], out.mode[:, :k + 1])
    with pytest.raises(EkfHmmError, match="run_ekf_hmm: increments must be one of"):
        run_ekf_hmm(ekf, prior, t_ns, z, ms, Q2, increments="x")


def _small_hmm_case(R=2, T=6):
    """A tiny EKF+HMM input set: radar runs of a still target, the HMM on every axis after step 0."""
    radar = RadarModel(site_ned_m=(-800.0, 600.0, 0.0))
    truth = np.zeros((R, T, 9))
    truth[..., 2] = -100.0
    z = np.swapaxes(radar.measure(truth, np.random.default_rng(1)), 0, 1)
    t_ns = np.arange(T, dtype=np.int64) * int(DT * 1e9)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(20.0), radar)
    prior = GaussianState(truth[:, 0], np.broadcast_to(initial_cov(), (R, 9, 9)).copy(), 0)
    axes = np.ones((R, T, 3), dtype=bool)
    axes[:, 0] = False
    return ekf, prior, t_ns, z, np.eye(9), axes, np.zeros((R, T, 3)), np.zeros((R, T, 3))


def test_the_hmm_filter_on_every_axis_is_the_framework_filter_of_a_h_q2_and_the_b_input():
    ekf, prior, t_ns, z, Q2, axes, acc, jerk = _small_hmm_case()
    out = hmm_filter(ekf, prior, t_ns, z, Q2, axes, acc, jerk, store="filtered")
    # step 0 is an update of the prior (no predict); every later step predicts with A_H and Q₂
    # on all three axes: the linear transition (A_H(dt), Q₂) in run_filter, with â = ĵ = 0
    lin = ExtendedKalmanFilter(LinearTransition(hmm_transition(DT), Q2), ekf.measurement)
    ref = run_filter(lin, prior, t_ns, z, store="filtered")
    np.testing.assert_allclose(out.mean, ref.mean, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(out.cov, ref.cov, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(out.dof, ref.dof)
    # non-zero GMR inputs enter as B [â; ĵ] of the step before (run_filter's bu into step k)
    rng = np.random.default_rng(7)
    acc, jerk = rng.standard_normal(acc.shape), rng.standard_normal(jerk.shape)
    out = hmm_filter(ekf, prior, t_ns, z, Q2, axes, acc, jerk, store="filtered")
    u = np.concatenate([acc, jerk], axis=-1)                          # (R, T, 6)
    bu = np.zeros((len(t_ns), acc.shape[0], 9))
    bu[1:] = np.swapaxes(u[:, :-1] @ hmm_input(DT).T, 0, 1)
    ref = run_filter(lin, prior, t_ns, z, store="filtered", bu=bu)
    np.testing.assert_allclose(out.mean, ref.mean, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(out.cov, ref.cov, rtol=1e-12, atol=1e-12)
    # ... and the CA filter (white-jerk Q) is something else: the check can tell them apart
    ca = run_filter(ekf, prior, t_ns, z, store="filtered")
    assert np.abs(ca.mean[:, 1:] - out.mean[:, 1:]).max() > 1e-3


@pytest.mark.parametrize("run, axis", [(0, 0), (1, 2)])
def test_the_hmm_filter_refuses_hmm_inputs_before_the_first_step(run, axis):
    ekf, prior, t_ns, z, Q2, axes, acc, jerk = _small_hmm_case()
    axes[run, 0, axis] = True       # would take acc[:, −1], the last step's inputs (future data)
    with pytest.raises(EkfHmmError, match=rf"axes\[:, 0\] must be False .*run {run}"):
        hmm_filter(ekf, prior, t_ns, z, Q2, axes, acc, jerk)


@pytest.mark.parametrize("change, match", [
    (lambda t: t[[0, 1, 3, 2, 4, 5]], r"t_ns must be non-decreasing; row 3"),
    (lambda t: t[::-1].copy(), r"t_ns must be non-decreasing; row 1"),
    (lambda t: t.astype(float) + 0.5, r"t_ns must hold whole nanoseconds; row 0"),
    (lambda t: t + (-1_000), r"the prior time 0 ns is after the first step"),
    (lambda t: t[None], r"t_ns must be 1-D"),
])
def test_the_hmm_filter_refuses_step_times_that_go_back(change, match):
    ekf, prior, t_ns, z, Q2, axes, acc, jerk = _small_hmm_case()
    with pytest.raises(EkfHmmError, match=match):
        hmm_filter(ekf, prior, change(t_ns), z, Q2, axes, acc, jerk)


def test_the_decision_rule_can_be_set_for_the_ekf_hmm_and_an_out_of_class_flight_stays_ca(trained):
    ms, data = trained
    # models of M1 and M2 only: M3's runs are out of class for them
    m12 = ManeuverModelSet(config=ModelsConfig(**FAST)).fit(data[data["label"].isin(["M1", "M2"])])
    ekf, prior, t_ns, z, _ = _radar_runs(data, ("M3",), np.random.default_rng(4))
    conf = run_ekf_hmm(ekf, prior, t_ns, z, m12, np.eye(9) * 0.1, decision="confidence")
    both = run_ekf_hmm(ekf, prior, t_ns, z, m12, np.eye(9) * 0.1, decision="both")
    default = run_ekf_hmm(ekf, prior, t_ns, z, m12, np.eye(9) * 0.1)
    assert m12.config.decision == "confidence"
    np.testing.assert_array_equal(default.mode, conf.mode)           # default: the model set's rule
    # the confidence rule always names one of the known maneuvers; the one-class test refuses more
    assert both.mode.sum() < conf.mode.sum()
    assert (np.asarray(both.pred) == "unknown").sum() > (np.asarray(conf.pred) == "unknown").sum()
