"""GMR against the closed-form conditional Gaussian, de-normalisation, the gate; §5 metrics."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.models.features import MinMaxNormaliser
from pipeline.models.gmr import fd_velocity_increments, gate, gmr, gmr_state9
from pipeline.models.metrics import (UNKNOWN, confusion, final_accuracy, is_correct,
                                     mean_accuracy_over_time, per_maneuver_table,
                                     thesis_side_by_side)


def random_spd(rng, d):
    L = rng.normal(size=(d, d))
    return L @ L.T + d * np.eye(d)


def test_gmr_single_gaussian_is_the_conditional_gaussian(rng):
    d = 5
    mu = rng.normal(size=d)
    S = random_spd(rng, d)
    i, o = [0, 2], [1, 3, 4]
    x = rng.normal(size=(7, 2))
    mean, cov = gmr(mu[None], S[None], x, i, o)
    # closed form via the precision matrix: E[u|k] = μ_u − Λ_uu⁻¹ Λ_uk (x − μ_k)
    P = np.linalg.inv(S)
    Puu, Puk = P[np.ix_(o, o)], P[np.ix_(o, i)]
    ref = mu[o] - (np.linalg.solve(Puu, Puk) @ (x - mu[i]).T).T
    np.testing.assert_allclose(mean, ref, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(cov[0], np.linalg.inv(Puu), rtol=1e-10)


def test_gmr_mixture_weights_and_one_hot(rng):
    d = 3
    mus = rng.normal(size=(2, d)) * 3
    Ss = np.stack([random_spd(rng, d), random_spd(rng, d)])
    x = rng.normal(size=(4, 1))
    m0, _ = gmr(mus[:1], Ss[:1], x, [0], [1, 2])
    m_hot, _ = gmr(mus, Ss, x, [0], [1, 2], weights=np.array([1.0, 0.0]))
    np.testing.assert_allclose(m_hot, m0, rtol=1e-12)
    # β_m ∝ w_m N(x; μ_k,m, Σ_k,m) (3.25)
    from scipy.stats import norm
    mean, _ = gmr(mus, Ss, x, [0], [1, 2])
    like = np.stack([norm.pdf(x[:, 0], mus[m, 0], np.sqrt(Ss[m, 0, 0])) for m in range(2)], 1)
    beta = like / like.sum(1, keepdims=True)
    ms = np.stack([gmr(mus[m:m + 1], Ss[m:m + 1], x, [0], [1, 2])[0] for m in range(2)], 1)
    np.testing.assert_allclose(mean, np.einsum("nm,nmo->no", beta, ms), rtol=1e-10)


def test_gmr_state9_denormalises_per_correction_13_3(rng):
    """Outputs exactly linear in the inputs: GMR recovers Δv, Δa; â = Δv/dt, ĵ = Δa/dt."""
    dt = 0.2
    norm = MinMaxNormaliser(np.arange(9.0) - 5, np.arange(9.0) + 3)
    G = rng.normal(size=(6, 3))
    Z = rng.normal(size=(4000, 3))
    obs = np.hstack([Z, Z @ G.T])
    obs[:, 3:] += 1e-6 * rng.normal(size=(4000, 6))
    mu, cov = obs.mean(0), np.cov(obs.T)
    xq = rng.normal(size=(5, 3))
    q = np.hstack([xq, np.zeros((5, 6))])
    acc, jerk = gmr_state9(mu[None], cov[None], q, np.zeros(5, dtype=int), norm, dt)
    yn = xq @ G.T                                                   # normalised increments
    span = norm.x_max - norm.x_min
    np.testing.assert_allclose(acc, (yn[:, :3] * span[3:6] + norm.x_min[3:6]) / dt, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(jerk, (yn[:, 3:] * span[6:9] + norm.x_min[6:9]) / dt, rtol=1e-4, atol=1e-4)
    # a sample without a state gives NaN
    a2, _ = gmr_state9(mu[None], cov[None], q[:2], np.array([0, -1]), norm, dt)
    assert np.isfinite(a2[0]).all() and np.isnan(a2[1]).all()
    # a state the model does not have, or states not one per sample: one line saying so
    with pytest.raises(ValueError, match="state index 3 out of range for a model with 1 states"):
        gmr_state9(mu[None], cov[None], q[:2], np.array([0, 3]), norm, dt)
    with pytest.raises(ValueError, match=r"states must have shape \(2,\)"):
        gmr_state9(mu[None], cov[None], q[:2], np.array([0, 0, 0]), norm, dt)


def test_gmr_pos_fd_is_exact_on_a_constant_jerk_trajectory():
    """``pos_fd``: Δv̂ from the last three positions plus ``dt·ĵ`` gives a(t_k) exactly for a
    cubic path when the state's Gaussian carries the (constant) Δa = j·dt; the plain second
    difference is one sample late, ``a(t_{k−1})``."""
    dt, j = 0.2, np.array([0.7, -1.3, 0.4])
    a0, v0 = np.array([1.0, 0.5, -2.0]), np.array([3.0, -1.0, 0.5])
    t = np.arange(30) * dt
    pos = v0 * t[:, None] + a0 * t[:, None] ** 2 / 2 + j * t[:, None] ** 3 / 6
    vel = v0 + a0 * t[:, None] + j * t[:, None] ** 2 / 2
    acc = a0 + j * t[:, None]
    x = np.hstack([pos, vel, acc])
    inc = x[1:] - x[:-1]                                           # observation at t_k = x_k − x_{k−1}
    norm = MinMaxNormaliser(inc.min(0) - 1.0, inc.max(0) + 1.0)
    obs = norm.transform(inc)
    Xfd = fd_velocity_increments(obs, norm, dt)
    assert np.isnan(Xfd[0, 3:6]).all()
    np.testing.assert_allclose(Xfd[:, :3], obs[:, :3])             # positions untouched
    fd = (pos[2:] - 2 * pos[1:-1] + pos[:-2]) / dt ** 2             # second difference at t_k
    np.testing.assert_allclose(norm.inverse(Xfd[1:, 3:6], (3, 4, 5)) / dt, fd, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(fd, acc[1:-1], rtol=1e-9, atol=1e-9)  # = a(t_{k−1})
    # one state whose Δa is constant j·dt and independent of the inputs
    mu = np.concatenate([obs[1:, :6].mean(0), norm.transform(np.r_[np.zeros(6), j * dt])[6:]])
    cov = np.eye(9)
    cov[:6, :6] = np.cov(Xfd[1:, :6].T) + 1e-9 * np.eye(6)
    a_hat, j_hat = gmr_state9(mu[None], cov[None], Xfd, np.zeros(len(Xfd), dtype=int), norm, dt,
                              inputs="pos_fd", align="sample")
    np.testing.assert_allclose(j_hat[1:], np.broadcast_to(j, (len(Xfd) - 1, 3)), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(a_hat[1:], acc[2:], rtol=1e-9, atol=1e-9)  # a(t_k)
    assert np.isnan(a_hat[0]).all()
    a_int, _ = gmr_state9(mu[None], cov[None], Xfd, np.zeros(len(Xfd), dtype=int), norm, dt,
                          inputs="pos_fd", align="interval")
    np.testing.assert_allclose(a_int[1:], (acc[1:-1] + acc[2:]) / 2, rtol=1e-9, atol=1e-9)  # a(t_{k−½})


def test_gate_per_axis():
    a = np.array([[0.0, 0.0, 0.0], [10.0, 20.0, 0.0], [12.0, 21.0, -16.0], [12.0, 0.0, -16.0]])
    g, dropped = gate(a, 15.0)
    np.testing.assert_array_equal(dropped, [[0, 0, 0], [0, 1, 0], [0, 0, 1], [0, 1, 0]])
    assert np.isnan(g[1, 1]) and g[1, 0] == 10.0 and g[3, 2] == -16.0


def test_is_correct_unknown_rules():
    known = ["M1", "M2"]
    pred = np.array(["M1", UNKNOWN, "M2", UNKNOWN, "M1"], dtype=object)
    truth = np.array(["M1", "M1", "M1", "M5", "M5"], dtype=object)
    np.testing.assert_array_equal(is_correct(pred, truth, known), [True, False, False, True, False])


def test_fa_maot_and_tables():
    known = ["M1", "M2"]
    df = pd.DataFrame({
        "run_id": [0] * 4 + [1] * 4 + [2] * 2,
        "label": ["M1"] * 8 + ["M5"] * 2,
        "pred": ["M2", "M1", "M1", "M1", UNKNOWN, "M1", "M2", "M2", UNKNOWN, UNKNOWN],
    })
    assert final_accuracy(["M1", "M2"], ["M1", "M1"], known) == 50.0
    preds = [g["pred"].to_numpy() for _, g in df.groupby("run_id")]
    truths = [g["label"].to_numpy() for _, g in df.groupby("run_id")]
    assert mean_accuracy_over_time(preds[:2], truths[:2], known) == pytest.approx((0.75 + 0.25) / 2 * 100)
    t = per_maneuver_table(df, known).set_index("maneuver")
    assert t.loc["M1", "FA_pct"] == 50.0 and t.loc["M1", "MAoT_pct"] == pytest.approx(50.0)
    assert t.loc["M5", "FA_pct"] == 100.0 and t.loc["M5", "MAoT_pct"] == 100.0
    side = thesis_side_by_side(t.reset_index(), "3.4").set_index("maneuver")
    assert side.loc["M1", "thesis_MAoT_pct"] == 98.21 and side.loc["M5", "thesis_MAoT_pct"] == 96.09
    c = confusion(["M1", "M1", "M5"], ["M1", "M2", UNKNOWN], known)
    assert c.loc["M1", "M1"] == 1 and c.loc["M1", "M2"] == 1 and c.loc["M5", UNKNOWN] == 1
    assert list(c.columns) == ["M1", "M2", UNKNOWN]


def test_gmr_state9_sample_alignment_and_pos_vel_inputs(rng):
    """``align="sample"`` adds (dt/2)·ĵ to Δv/dt; ``inputs="pos_vel"`` takes Δv as observed and
    regresses Δa on (Δr, Δv), exactly for linear data."""
    dt = 0.2
    norm = MinMaxNormaliser(np.arange(9.0) - 5, np.arange(9.0) + 3)
    G = rng.normal(size=(6, 3))
    Z = rng.normal(size=(4000, 3))
    obs = np.hstack([Z, Z @ G.T]) + 1e-6 * rng.normal(size=(4000, 9))
    mu, cov = obs.mean(0), np.cov(obs.T)
    q = obs[:5]
    st = np.zeros(5, dtype=int)
    a_i, j_i = gmr_state9(mu[None], cov[None], q, st, norm, dt, align="interval")
    a_s, j_s = gmr_state9(mu[None], cov[None], q, st, norm, dt, align="sample")
    np.testing.assert_allclose(j_s, j_i)
    np.testing.assert_allclose(a_s, a_i + 0.5 * dt * j_i)
    span = norm.x_max - norm.x_min
    phys = q * span + norm.x_min
    a_pv, j_pv = gmr_state9(mu[None], cov[None], q, st, norm, dt, inputs="pos_vel", align="interval")
    np.testing.assert_allclose(a_pv, phys[:, 3:6] / dt, rtol=1e-12)        # observed Δv
    np.testing.assert_allclose(j_pv, phys[:, 6:9] / dt, rtol=1e-4, atol=1e-3)
    # Δa depends on Δr only here, so the (Δr, Δv) and Δr regressions agree on Δa
    np.testing.assert_allclose(j_pv, j_i, rtol=1e-4, atol=1e-3)
    with pytest.raises(ValueError, match="align"):
        gmr_state9(mu[None], cov[None], q, st, norm, dt, align="centre")


# -- the classifier's GMR, end to end, against an independent computation (issue 14 checks) --------

def _box_obs(run, psi, norm):
    """Normalised ``state9box`` increments of one 5 Hz run, written out by hand (no features.py):
    every NED triple turned by ``[[c, s, 0], [−s, c, 0], [0, 0, 1]]``, differenced, min-max."""
    c, s = np.cos(psi), np.sin(psi)
    Rz = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    cols = [f"{k}_{a}_{u}" for k, u in (("pos", "m"), ("vel", "mps"), ("acc", "mps2")) for a in "ned"]
    x = run[cols].to_numpy()
    xb = np.hstack([x[:, 3 * g:3 * g + 3] @ Rz.T for g in range(3)])
    inc = xb[1:] - xb[:-1]
    return (inc - norm.x_min) / (norm.x_max - norm.x_min), Rz


@pytest.fixture(scope="module")
def box_models():
    """Two state9box maneuver HMMs on synthetic runs turned into a box at the P23 #36 heading."""
    from helpers_maneuvers import synth_bulk

    from pipeline.models.base import ModelsConfig
    from pipeline.models.classifier import ManeuverModelSet

    data = synth_bulk(("M1", "M2"), 3, np.random.default_rng(1414))
    cfg = ModelsConfig(feature_set="state9box", n_states=3, n_iter=5, tol=1e-1, gmm_restarts=1, seed=5)
    return ManeuverModelSet(config=cfg).fit(data, box_heading_rad=-0.59), data


@pytest.mark.parametrize("inputs", ["pos", "pos_fd"])
def test_classify_gmr_is_the_gaussian_conditioning_of_the_viterbi_state_emission(box_models, inputs):
    """``classify``'s ``acc_hmm``/``jerk_hmm`` equal E[Δv, Δa | inputs] of the emission Gaussian of
    the reported Viterbi state of the best model, computed here by hand from the stored model
    (explicit inverse of Σ_kk, the box rotation written out, de-normalised as §13.3, ``sample``
    alignment, turned back to NED by R_zᵀ). Pins the model, state, feature order, normaliser,
    frame and timing that reach the EKF+HMM."""
    import copy
    import dataclasses

    ms0, data = box_models
    ms = copy.copy(ms0)
    ms.config = dataclasses.replace(ms0.config, gmr_input=inputs, gmr_align="sample")
    psi, dt = -0.59 + 0.07, 0.2                      # another flight's box heading
    run = data[data.run_id == "M2-1"].reset_index(drop=True)
    out = ms.classify(run, box_heading_rad=psi)
    norm = ms.normaliser_
    obs, Rz = _box_obs(run, psi, norm)
    span = norm.x_max - norm.x_min
    if inputs == "pos_fd":                           # Δv̂_k = (Δr_k − Δr_{k−1})/dt, re-normalised
        dr = obs[:, :3] * span[:3] + norm.x_min[:3]
        dv = np.full_like(dr, np.nan)
        dv[1:] = (dr[1:] - dr[:-1]) / dt
        obs = obs.copy()
        obs[:, 3:6] = (dv - norm.x_min[3:6]) / span[3:6]
    k = [0, 1, 2] if inputs == "pos" else [0, 1, 2, 3, 4, 5]
    u = [3, 4, 5, 6, 7, 8] if inputs == "pos" else [6, 7, 8]
    labels = list(ms.labels_)
    acc = np.full((len(out), 3), np.nan)
    jerk = np.full((len(out), 3), np.nan)
    for n, row in enumerate(out.itertuples()):
        if row.best not in labels or row.state < 0 or not np.isfinite(obs[n]).all():
            continue
        p = ms.models_[labels.index(row.best)].params_
        mu, S = p.means[row.state, 0], p.covars[row.state, 0]
        cond = mu[u] + S[np.ix_(u, k)] @ np.linalg.inv(S[np.ix_(k, k)]) @ (obs[n, k] - mu[k])
        d_a = cond[-3:] * span[6:9] + norm.x_min[6:9]
        d_v = (cond[:3] if inputs == "pos" else obs[n, 3:6]) * span[3:6] + norm.x_min[3:6]
        j_box = d_a / dt
        # Δv/dt sits at t_{k−½} (pos) or t_{k−1} (pos_fd); "sample" moves it to t_k with ĵ
        a_box = d_v / dt + (0.5 if inputs == "pos" else 1.0) * dt * j_box
        acc[n], jerk[n] = Rz.T @ a_box, Rz.T @ j_box
    got_a = out[[f"acc_hmm_{a}_mps2" for a in "ned"]].to_numpy()
    got_j = out[[f"jerk_hmm_{a}_mps3" for a in "ned"]].to_numpy()
    assert np.isfinite(acc).mean() > 0.9
    np.testing.assert_array_equal(np.isnan(got_a), np.isnan(acc))
    np.testing.assert_allclose(got_a, acc, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(got_j, jerk, rtol=1e-9, atol=1e-9)


def test_pos_fd_acceleration_is_the_ned_second_difference_plus_dt_jerk_in_any_box(box_models):
    """With ``pos_fd``/``sample`` the HMM acceleration at ``t_k`` is, in NED and whatever the box
    heading, the second difference of the last three positions (``a(t_{k−1})``) plus ``dt·ĵ``:
    the box rotation is undone exactly and the estimate uses no sample after ``t_k``."""
    ms, data = box_models
    assert (ms.config.gmr_input, ms.config.gmr_align) == ("pos_fd", "sample")
    run = data[data.run_id == "M1-0"].reset_index(drop=True)
    dt = 0.2
    pos = run[[f"pos_{a}_m" for a in "ned"]].to_numpy()
    fd2 = np.full_like(pos, np.nan)
    fd2[2:] = (pos[2:] - 2 * pos[1:-1] + pos[:-2]) / dt ** 2        # a(t_{k−1}) at row k
    for psi in (-0.59, 1.1):
        out = ms.classify(run, box_heading_rad=psi)
        i = np.searchsorted(run["t_ns"].to_numpy(), out["t_ns"].to_numpy())
        a = out[[f"acc_hmm_{x}_mps2" for x in "ned"]].to_numpy()
        j = out[[f"jerk_hmm_{x}_mps3" for x in "ned"]].to_numpy()
        ok = np.isfinite(a).all(1)
        assert ok.mean() > 0.9 and not ok[0]             # the first increment has no Δr_{k−1}
        np.testing.assert_allclose(a[ok] - dt * j[ok], fd2[i[ok]], rtol=1e-9, atol=1e-8)
