"""Model set: training from state tables, thresholds, classification, persistence, CLI."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from pipeline.config import ConfigError
from pipeline.models.base import ModelError, ModelsConfig
from pipeline.models.classifier import ManeuverModelSet, _pad
from pipeline.models.features import MinMaxNormaliser, decimate, raw_features
from pipeline.models.online import classify_batch

FAST = dict(n_states=3, n_iter=15, tol=1e-1, gmm_restarts=1, seed=5)


def _train(synth, rng, labels=("M1", "M2", "M3"), n_runs=5, **cfg):
    _, bulk = synth
    data = bulk(labels, n_runs, rng)
    ms = ManeuverModelSet(config=ModelsConfig(**{**FAST, **cfg})).fit(data)
    return ms, data


@pytest.fixture(scope="module")
def trained3(synth):
    data = synth[1](("M1", "M2", "M3"), 5, np.random.default_rng(20261123))
    return ManeuverModelSet(config=ModelsConfig(**FAST)).fit(data), data


def test_normaliser_frozen_and_shared(trained3):
    ms, data = trained3
    obs = np.concatenate([np.diff(raw_features(g), axis=0) for _, g in data.groupby("run_id")])
    np.testing.assert_allclose(ms.normaliser_.x_min, obs.min(0))
    np.testing.assert_allclose(ms.normaliser_.x_max, obs.max(0))
    n = MinMaxNormaliser(np.zeros(2), np.array([2.0, 0.0]))
    np.testing.assert_allclose(n.transform([[3.0, 5.0]]), [[1.5, 5.0]])  # may leave [0, 1]
    np.testing.assert_allclose(n.inverse(n.transform([[3.0, 5.0]])), [[3.0, 5.0]])


def test_classify_synthetic_and_unknown(synth, rng, trained3):
    run, bulk = synth
    ms, _ = trained3
    test = pd.concat([bulk(("M1", "M2", "M3", "U"), 3, rng)], ignore_index=True)
    res = ms.classify(test, decision="confidence")
    final = res.groupby("run_id").tail(1).set_index("run_id")
    known = final["truth"] != "U"
    assert (final.loc[known, "pred"] == final.loc[known, "truth"]).all()
    # the unknown maneuver gets a known label from the confidence rule alone (its argmax is
    # clear-cut) but falls below every one-class threshold
    res1 = ms.classify(test, decision="both")
    final1 = res1.groupby("run_id").tail(1).set_index("run_id")
    assert (final1.loc[~known, "pred"] == "unknown").all()
    assert set(res1["pred"]) <= {*ms.labels_, "unknown"}
    assert {f"ll_{m}" for m in ms.labels_} <= set(res.columns)
    assert np.isfinite(res["acc_hmm_n_mps2"]).mean() > 0.9


def test_thresholds_percentile_of_training_scores(trained3):
    ms, data = trained3
    # recompute model M1's threshold curve from its training sequences
    seqs = []
    for _, g in data[data.label == "M1"].groupby("run_id"):
        seqs.append(ms.normaliser_.transform(np.diff(raw_features(g), axis=0)))
    clf = ms.classifier(mode="cumulative", decision="confidence")
    res = classify_batch(clf, np.stack(seqs))
    ref = np.percentile(res["scores"][:, :, 0], 0.5, axis=0)
    np.testing.assert_allclose(ms.thresholds_["cumulative"][0], ref, rtol=1e-10)
    assert ms.training_["M1"]["threshold"] == "training sequences"


def test_single_recording_uses_leave_one_phase_out(synth, rng):
    run, _ = synth
    df = run("M1", rng, duration_s=25.0, rate_hz=25.0).assign(run_id="only")
    df2 = run("M2", rng, duration_s=10.0, rate_hz=5.0).assign(run_id="two")
    df3 = run("M2", rng, duration_s=10.0, rate_hz=5.0).assign(run_id="three")
    ms = ManeuverModelSet(config=ModelsConfig(**{**FAST, "n_iter": 8})).fit(pd.concat([df, df2, df3]))
    assert ms.training_["M2"]["threshold"] == "training sequences"
    assert ms.training_["M1"]["threshold"] == "leave-one-phase-out"
    assert ms.training_["M1"]["n_sequences"] == 5                   # five 5 Hz phases of 25 Hz
    # held-out phases score lower than in-sample ones: the LOPO threshold is the stricter test
    ph = [ms.normaliser_.transform(np.diff(raw_features(decimate(df, 5.0, k)), axis=0)) for k in range(5)]
    assert len({len(p) for p in ph}) == 2                           # 126 rows: phases differ in length
    ins = classify_batch(ms.classifier(mode="cumulative", decision="confidence"), _pad(ph))
    T = min(len(p) for p in ph)
    assert ms.thresholds_["cumulative"][0, T - 1] <= np.percentile(ins["scores"][:, T - 1, 0], 0.5)


def test_save_load_roundtrip_identical(synth, rng, tmp_path):
    ms, data = _train(synth, rng, labels=("M1", "M2"), n_runs=4)
    paths = ms.save(tmp_path / "m")
    assert [p.name for p in paths] == ["params.npz", "meta.json"]
    z = np.load(tmp_path / "m" / "params.npz", allow_pickle=False)   # no pickles anywhere
    assert all(z[k].dtype != object for k in z.files)
    meta = json.loads((tmp_path / "m" / "meta.json").read_text())
    assert meta["labels"] == ["M1", "M2"] and "normaliser" in meta and "training" in meta
    ms2 = ManeuverModelSet.load(tmp_path / "m")
    a = ms.classify(data, mode="windowed")
    b = ms2.classify(data, mode="windowed")
    pd.testing.assert_frame_equal(a, b)


def test_a_meta_json_of_no_or_another_format_version_is_named_in_words(synth, rng, tmp_path):
    from pipeline.models.base import ModelError

    ms, _ = _train(synth, rng, labels=("M1", "M2"), n_runs=3)
    ms.save(tmp_path / "m")
    meta = json.loads((tmp_path / "m" / "meta.json").read_text())
    for fv, match in ((None, "meta.json has no format_version: not the meta.json of a trained model set"),
                      (0, "model format 0 \\(this uavpipe reads format 1\\): retrain the model set")):
        m = {k: v for k, v in meta.items() if k != "format_version"} if fv is None else {**meta, "format_version": fv}
        (tmp_path / "m" / "meta.json").write_text(json.dumps(m))
        with pytest.raises(ModelError, match=match):
            ManeuverModelSet.load(tmp_path / "m")
    # the placeholder of a failed training passes its reason on
    (tmp_path / "m" / "meta.json").write_text(json.dumps({"status": "failed", "error": "no rows in x.parquet"}))
    with pytest.raises(ModelError, match=r"m: the model set failed to train \(no rows in x\.parquet\)$"):
        ManeuverModelSet.load(tmp_path / "m")


def test_training_deterministic(synth, rng, tmp_path):
    _, bulk = synth
    data = bulk(("M1", "M2"), 3, rng)
    for k in range(2):
        ManeuverModelSet(config=ModelsConfig(**FAST)).fit(data).save(tmp_path / f"m{k}")
    assert (tmp_path / "m0" / "params.npz").read_bytes() == (tmp_path / "m1" / "params.npz").read_bytes()


def test_bad_inputs(synth, rng, tmp_path):
    run, _ = synth
    with pytest.raises(ConfigError, match="unknown key"):
        ModelsConfig.from_section({"n_stats": 3})
    with pytest.raises(ConfigError, match="mode"):
        ModelsConfig.from_section({"mode": "sliding"})
    with pytest.raises(ConfigError, match="gmr_align"):
        ModelsConfig.from_section({"gmr_align": "centre"})
    with pytest.raises(ConfigError, match="gmr_input"):
        ModelsConfig.from_section({"gmr_input": "acc"})
    with pytest.raises(ModelError, match="not a model directory"):
        ManeuverModelSet.load(tmp_path)
    df = run("M1", rng)
    with pytest.raises(ModelError, match="labels"):
        ManeuverModelSet(config=ModelsConfig(**FAST)).fit(df.assign(label=["M1", "M2"] * (len(df) // 2) + ["M1"] * (len(df) % 2)))
    with pytest.raises(ValueError, match="integer multiple"):
        ManeuverModelSet(config=ModelsConfig(**FAST)).fit(run("M1", rng, rate_hz=7.0))


def test_cli_train_and_classify(synth, rng, tmp_path, capsys):
    from pipeline.cli import main
    from pipeline.io.parquet import read_table_meta

    _, bulk = synth
    train = bulk(("M1", "M2"), 4, rng)
    train.to_parquet(tmp_path / "train.parquet")
    test = bulk(("M1", "M2"), 2, rng)
    test.to_parquet(tmp_path / "test.parquet")
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("hmm:\n  n_states: 3\n  n_iter: 15\n  tol: 0.1\n  gmm_restarts: 1\n")
    assert main(["train", str(tmp_path / "train.parquet"), "-o", str(tmp_path / "mdl"),
                 "--config", str(cfg)]) == 0
    assert main(["classify", str(tmp_path / "mdl"), str(tmp_path / "test.parquet"),
                 "-o", str(tmp_path / "out.parquet"), "--mode", "windowed"]) == 0
    out = pd.read_parquet(tmp_path / "out.parquet")
    assert {"t_ns", "pred", "V_best", "ll_M1", "ll_M2", "state", "acc_hmm_n_mps2"} <= set(out.columns)
    final = out.groupby("run_id").tail(1)
    assert (final["pred"] == final["truth"]).mean() == 1.0
    assert read_table_meta(tmp_path / "out.parquet")["schema_version"]
    # a bad model directory: one line, non-zero exit
    assert main(["classify", str(tmp_path), str(tmp_path / "test.parquet"), "-o", str(tmp_path / "x.parquet")]) == 2
    assert "not a model directory" in capsys.readouterr().err


@pytest.mark.slow  # ~2 s of leave-one-out fits
def test_threshold_slack_auto_is_leave_one_recording_out(synth, rng):
    run, _ = synth
    parts = [run("M1", rng, duration_s=8.0, rate_hz=25.0).assign(run_id=f"a{k}") for k in range(2)]
    parts.append(run("M2", rng, duration_s=8.0, rate_hz=25.0).assign(run_id="b"))
    data = pd.concat(parts, ignore_index=True)
    base = ManeuverModelSet(config=ModelsConfig(**{**FAST, "n_iter": 5})).fit(data)
    auto = ManeuverModelSet(config=ModelsConfig(**{**FAST, "n_iter": 5, "threshold_slack": "auto"})).fit(data)
    assert base.threshold_slack_ == 0.0
    assert auto.threshold_slack_ > 0                               # another flight scores lower
    n = np.arange(1, base.thresholds_["cumulative"].shape[1] + 1)
    np.testing.assert_allclose(auto.thresholds_["cumulative"],
                               base.thresholds_["cumulative"] - auto.threshold_slack_ * n, rtol=1e-9)
    with pytest.raises(ConfigError, match="threshold_slack"):
        ModelsConfig.from_section({"threshold_slack": "big"})


def test_state9h_is_heading_invariant_and_gmr_rotates_back(synth, rng):
    _, bulk = synth
    data = bulk(("M1", "M2"), 3, rng).assign(yaw_rad=0.0)
    ms = ManeuverModelSet(config=ModelsConfig(**{**FAST, "n_iter": 5, "feature_set": "state9h"})).fit(data)
    run = data[data.run_id == "M1-0"].copy()
    psi = 1.1
    c, s = np.cos(psi), np.sin(psi)
    rot = run.copy()
    for k, u in (("pos", "m"), ("vel", "mps"), ("acc", "mps2")):
        n, e = run[f"{k}_n_{u}"], run[f"{k}_e_{u}"]
        rot[f"{k}_n_{u}"], rot[f"{k}_e_{u}"] = c * n - s * e, s * n + c * e
    rot["yaw_rad"] = psi
    a, b = ms.classify(run), ms.classify(rot)
    for col in ("ll_M1", "ll_M2", "acc_hmm_d_mps2"):
        np.testing.assert_allclose(b[col], a[col], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(b["acc_hmm_n_mps2"], c * a["acc_hmm_n_mps2"] - s * a["acc_hmm_e_mps2"], atol=1e-9)
    np.testing.assert_allclose(b["acc_hmm_e_mps2"], s * a["acc_hmm_n_mps2"] + c * a["acc_hmm_e_mps2"], atol=1e-9)


def _turn(run: pd.DataFrame, R: np.ndarray) -> pd.DataFrame:
    """``run`` with every NED triple (pos, vel, acc) multiplied by the 3×3 ``R``."""
    out = run.copy()
    for k, u in (("pos", "m"), ("vel", "mps"), ("acc", "mps2")):
        cols = [f"{k}_{a}_{u}" for a in "ned"]
        out[cols] = run[cols].to_numpy() @ R.T
    return out


def test_state9box_gmr_rotates_back_to_ned_as_state9_on_the_box_frame_copy(synth, rng):
    from pipeline.models.features import heading_rotation

    _, bulk = synth
    psi = -0.59                                             # the P23 #36 box rotation
    R = heading_rotation(psi)
    data = bulk(("M1", "M2"), 3, rng)
    cfg = {**FAST, "n_iter": 5}
    box = ManeuverModelSet(config=ModelsConfig(**cfg, feature_set="state9box")).fit(data, box_heading_rad=psi)
    # the thesis features of the flight already turned into the box frame: the same models
    s9 = ManeuverModelSet(config=ModelsConfig(**cfg, feature_set="state9")).fit(_turn(data, R))
    np.testing.assert_allclose(box.normaliser_.x_min, s9.normaliser_.x_min, atol=1e-9)
    run = data[data.run_id == "M1-0"]
    a = box.classify(run, box_heading_rad=psi)
    b = s9.classify(_turn(run, R))
    for col in ("ll_M1", "ll_M2", "V_best"):
        np.testing.assert_allclose(a[col], b[col], rtol=1e-9, atol=1e-9)
    assert (a["pred"] == b["pred"]).all() and (a["state"] == b["state"]).all()
    for q, u in (("acc", "mps2"), ("jerk", "mps3")):
        ned = a[[f"{q}_hmm_{x}_{u}" for x in "ned"]].to_numpy()
        in_box = b[[f"{q}_hmm_{x}_{u}" for x in "ned"]].to_numpy()
        assert np.isfinite(ned).mean() > 0.9
        np.testing.assert_allclose(ned, in_box @ R, atol=1e-9)          # R^T applied to each row
    # flown in a box turned by another 1.2 rad: the same likelihoods, the GMR turned with it
    R2 = heading_rotation(-1.2)                             # NED -> NED turned by +1.2 rad
    c = box.classify(_turn(run, R2), box_heading_rad=psi + 1.2)
    np.testing.assert_allclose(c["ll_M1"], a["ll_M1"], rtol=1e-9, atol=1e-9)
    acc = [f"acc_hmm_{x}_mps2" for x in "ned"]
    np.testing.assert_allclose(c[acc].to_numpy(), a[acc].to_numpy() @ R2.T, atol=1e-9)


def test_gmr_estimates_are_causal_and_follow_config(synth, rng, trained3):
    """The HMM acceleration at ``t_k`` uses samples up to ``t_k`` only: truncating the run (or
    changing its future) leaves earlier estimates bit-identical; ``gmr_align`` only adds the
    (dt/2)·ĵ term."""
    import copy
    import dataclasses

    run, _ = synth
    ms, _ = trained3
    df = run("M2", rng)
    full = ms.classify(df)
    n = len(df) // 2
    head = ms.classify(df.iloc[:n])
    fut = df.copy()
    fut.iloc[n:, fut.columns.get_indexer(["pos_n_m", "vel_n_mps", "acc_n_mps2"])] += 3.0
    changed = ms.classify(fut)
    cols = [f"{q}_hmm_{a}_{u}" for q, u in (("acc", "mps2"), ("jerk", "mps3")) for a in "ned"]
    k = len(head)
    np.testing.assert_array_equal(full[cols].to_numpy()[:k], head[cols].to_numpy())
    np.testing.assert_array_equal(full[cols].to_numpy()[:k], changed[cols].to_numpy()[:k])
    assert not np.allclose(full[cols].to_numpy()[k:], changed[cols].to_numpy()[k:], equal_nan=True)
    iv = copy.copy(ms)
    iv.config = dataclasses.replace(ms.config, gmr_align="interval")
    other = iv.classify(df)
    dt = 1.0 / ms.config.rate_hz
    assert ms.config.gmr_align == "sample"
    for a in "ned":
        np.testing.assert_allclose(full[f"acc_hmm_{a}_mps2"], other[f"acc_hmm_{a}_mps2"]
                                   + 0.5 * dt * other[f"jerk_hmm_{a}_mps3"], rtol=1e-12, atol=1e-12)


def test_a_model_sets_hmm_block_overrides_the_hmm_section_for_that_set_only(synth, rng, tmp_path):
    """A ``model_sets`` entry's ``hmm:`` overrides the global section for that set only; a bad
    override key is a clear configuration error naming the key."""
    from pipeline.models.run import model_set_config, run_train

    _, bulk = synth
    sets = []
    for lab in ("M1", "M2"):
        p = tmp_path / f"{lab}_train.parquet"
        bulk([lab], 4, rng).to_parquet(p)
        sets.append(p)
    cfg = {"hmm": {"n_states": 5, "n_iter": 5},
           "model_sets": {"m": {"data": "simulated", "vehicles": ["x"],
                                "hmm": {"n_states": 3, "threshold_slack": 1.5}},
                          "m0": {"data": "simulated", "vehicles": ["x"]},
                          "bad": {"data": "simulated", "vehicles": ["x"], "hmm": {"n_stats": 3}}}}

    def train(name):
        d = tmp_path / name
        return run_train({"sets": sets}, {"params": d / "params.npz", "meta": d / "meta.json"},
                         model_set_config(cfg, name), model_set=name, seed=3).diagnostics

    meta = train("m")
    assert meta["status"] == "ok"
    assert meta["config"]["n_states"] == 3 and meta["config"]["n_iter"] == 5
    assert meta["threshold_slack"] == 1.5
    assert train("m0")["config"]["n_states"] == 5
    with pytest.raises(ConfigError, match=r"hmm\.n_stats: unknown key"):
        train("bad")
    with pytest.raises(ConfigError, match="no model set 'nope'"):
        model_set_config(cfg, "nope")


def test_a_training_run_with_nan_inf_or_text_features_is_dropped_by_name_and_counted_not_a_hmmlearn_error(
        synth, rng, tmp_path, capsys):
    # hmmlearn stopped the whole model set with "Input X contains NaN", naming no file,
    # column or run; one damaged run must not stop the others
    from pipeline.models.run import model_set_config, run_train

    _, bulk = synth
    df = bulk(["M1"], 4, rng)
    df.loc[df["run_id"] == "M1-1", "vel_e_mps"] = np.nan
    df.loc[df.index[df["run_id"] == "M1-2"][3], "acc_d_mps2"] = np.inf
    p = tmp_path / "M1_train.parquet"
    df.to_parquet(p)
    cfg = {"hmm": {"n_states": 3, "n_iter": 5}, "model_sets": {"m": {"data": "simulated", "vehicles": ["x"]}}}

    def train(name, path):
        d = tmp_path / name
        return run_train({"sets": [path]}, {"params": d / "params.npz", "meta": d / "meta.json"},
                         model_set_config(cfg, "m"), model_set="m", seed=3).diagnostics

    meta = train("ok", p)
    assert meta["status"] == "ok" and meta["training"]["M1"]["n_recordings"] == 2
    assert meta["training_dropped"] == {"M1_train:M1-1": "column vel_e_mps: 126 of 126 value(s) NaN or infinite",
                                        "M1_train:M1-2": "column acc_d_mps2: 1 of 126 value(s) NaN or infinite"}
    assert "m: 2 training run(s) dropped: M1_train:M1-1 (column vel_e_mps" in capsys.readouterr().err
    df["vel_e_mps"] = "x"
    df.to_parquet(p)
    meta = train("text", p)
    assert meta["status"] == "failed"
    assert meta["error"].endswith("no usable training run: all 4 dropped (first: run M1_train:M1-0: "
                                  "column vel_e_mps is not numeric)")
    empty = tmp_path / "E_train.parquet"
    df.iloc[:0].to_parquet(empty)
    assert train("empty", empty)["error"].endswith(f"no labelled training data (no rows in {empty})")


def test_a_sample_with_a_nan_feature_is_unknown_with_nan_scores_never_background(trained3):
    # an inactive sample (-2) indexed the label list from its end and read "background"
    ms, data = trained3
    run = data[data["run_id"] == data["run_id"].iloc[0]].copy()
    run.iloc[40:55, run.columns.get_loc("vel_e_mps")] = np.nan
    out = ms.classify(run)
    gap = out["V_best"].isna().to_numpy()
    assert gap.sum() >= 10 and not gap[:30].any()
    assert set(out.loc[gap, "pred"]) == {"unknown"} and set(out.loc[gap, "best"]) == {"unknown"}
    assert "background" not in set(out["pred"])
    assert out.loc[~gap, "pred"].ne("unknown").any()


def test_window_auto_is_half_the_median_training_run(synth, rng, tmp_path):
    _, bulk = synth
    data = pd.concat([bulk(["M1"], 3, rng, duration_s=20.0), bulk(["M2"], 3, rng, duration_s=30.0),
                      bulk(["M3"], 1, rng, duration_s=40.0)], ignore_index=True)
    with pytest.raises(ModelError, match="auto"):
        ModelsConfig(window_s="auto").window
    ms = ManeuverModelSet(config=ModelsConfig(n_states=3, n_iter=5, window_s="auto", phases=False)).fit(data)
    # 7 runs of 20/20/20/30/30/30/40 s at 5 Hz -> 100/100/100/150/150/150/200 increments
    assert ms.config.window_s == pytest.approx(0.5 * 150 / 5.0)
    assert ms.config.window == 75
    ms.save(tmp_path / "m")
    assert ManeuverModelSet.load(tmp_path / "m").config.window_s == ms.config.window_s
    with pytest.raises(ConfigError, match="window_s"):
        ModelsConfig.from_section({"window_s": "long"})


@pytest.mark.slow
def test_background_model_makes_an_unseen_maneuver_unknown(synth, rng, tmp_path):
    """``confidence_bg``: the background GMM is one more rival in V (never a label). A run of a
    class no model was trained on loses to it and is unknown; trained classes keep their
    labels; the plain confidence rule still forces one of the models."""
    _, bulk = synth
    train = bulk(["M1", "M2", "M3"], 12, rng)
    cfg = ModelsConfig(n_states=3, n_iter=20, background=1, seed=5)
    ms = ManeuverModelSet(config=cfg).fit(train)
    assert ms.background_.n_states == 1 and ms.background_.n_mix == 1
    test = bulk(["M1", "M2", "M3", "U"], 3, rng)
    res = ms.classify(test, decision="confidence_bg", gmr=False)
    assert "ll_background" in res.columns
    fin = res.groupby("run_id", sort=False).tail(1)
    known = fin[fin["truth"] != "U"]
    assert (known["pred"] == known["truth"]).all()
    assert (fin.loc[fin["truth"] == "U", "pred"] == "unknown").all()
    plain = ms.classify(test, decision="confidence", gmr=False).groupby("run_id", sort=False).tail(1)
    assert (plain.loc[plain["truth"] == "U", "pred"] != "unknown").any()
    # persisted with the model; a model without one refuses the decision clearly
    ms.save(tmp_path / "m")
    back = ManeuverModelSet.load(tmp_path / "m")
    np.testing.assert_array_equal(back.background_.covars, ms.background_.covars)
    pd.testing.assert_frame_equal(back.classify(test, decision="confidence_bg", gmr=False), res)
    none = ManeuverModelSet(config=ModelsConfig(n_states=3, n_iter=5, background=0)).fit(train)
    with pytest.raises(ModelError, match="background"):
        none.classify(test, decision="confidence_bg")
    with pytest.raises(ConfigError, match="background"):
        ModelsConfig(decision="confidence_bg", background=0).validate()


def _impostor_oracle(ms, data):
    """mean over the other labels' training runs of LL_m(T) / T, scored run by run."""
    per = {m: [] for m in ms.labels_}
    for _, g in data.groupby("run_id"):
        x = ms.normaliser_.transform(np.diff(raw_features(g), axis=0))
        sc = classify_batch(ms.classifier(mode="cumulative", decision="confidence"), x[None])["scores"][0, -1]
        for i, m in enumerate(ms.labels_):
            if m != g["label"].iloc[0]:
                per[m].append(sc[i] / len(x))
    return np.array([np.mean(per[m]) for m in ms.labels_])


def test_the_impostor_mean_is_each_models_per_sample_score_of_the_other_training_maneuvers(trained3):
    ms, data = trained3
    np.testing.assert_allclose(ms.impostor_ll_, _impostor_oracle(ms, data), rtol=1e-9)
    gen = np.array([ms.thresholds_["cumulative"][i, -1] for i in range(len(ms.labels_))])
    assert (ms.impostor_ll_ * ms.thresholds_["cumulative"].shape[1] < gen).all()   # impostors score lower


def test_the_impostor_fraction_threshold_is_f_q_plus_one_minus_f_n_times_the_impostor_mean(trained3):
    ms, _ = trained3
    q = ms.thresholds_["cumulative"]                                 # default f = 1, slack 0: the percentile
    assert ms.threshold_fraction_ == 1.0
    np.testing.assert_array_equal(ms.threshold_base_["cumulative"], q)
    f, s = 0.3, 0.2
    m2 = ms.with_threshold(fraction=f, slack=s)
    n = np.arange(1, q.shape[1] + 1)
    np.testing.assert_allclose(m2.thresholds_["cumulative"],
                               f * q + (1 - f) * n * ms.impostor_ll_[:, None] - s * n, rtol=1e-12)
    W = ms.config.window
    nw = np.minimum(np.arange(1, ms.thresholds_["windowed"].shape[1] + 1), W)
    np.testing.assert_allclose(m2.thresholds_["windowed"], f * ms.thresholds_["windowed"]
                               + (1 - f) * nw * ms.impostor_ll_[:, None] - s * nw, rtol=1e-12)
    # f = 0 accepts an average impostor: the threshold is its expected cumulative score
    np.testing.assert_allclose(ms.with_threshold(fraction=0.0).thresholds_["cumulative"],
                               n * ms.impostor_ll_[:, None], rtol=1e-12)
    back = m2.with_threshold(fraction=1.0, slack=0.0)
    np.testing.assert_array_equal(back.thresholds_["cumulative"], q)   # f = 1 is bit for bit the old rule
    assert ms.thresholds_["cumulative"] is q                             # the original is untouched


def test_a_lower_impostor_fraction_accepts_more_and_the_setting_survives_save_and_load(synth, rng, trained3, tmp_path):
    ms, _ = trained3
    _, bulk = synth
    test = bulk(("M1", "M2", "M3", "U"), 3, rng)
    acc = [(ms.with_threshold(fraction=f).classify(test, decision="oneclass", gmr=False)["pred"] != "unknown").mean()
           for f in (1.0, 0.5, 0.0)]
    assert acc[0] <= acc[1] <= acc[2] and acc[2] > acc[0]
    data = bulk(("M1", "M2"), 3, rng)
    cfg = ModelsConfig(**{**FAST, "threshold_fraction": 0.4})
    a = ManeuverModelSet(config=cfg).fit(data)
    a.save(tmp_path / "m")
    b = ManeuverModelSet.load(tmp_path / "m")
    assert b.threshold_fraction_ == 0.4 and json.loads((tmp_path / "m" / "meta.json").read_text())["threshold_fraction"] == 0.4
    for mode in a.thresholds_:
        np.testing.assert_array_equal(a.thresholds_[mode], b.thresholds_[mode])
        np.testing.assert_array_equal(a.threshold_base_[mode], b.threshold_base_[mode])
    np.testing.assert_array_equal(a.impostor_ll_, b.impostor_ll_)
    pd.testing.assert_frame_equal(a.classify(data, decision="both", gmr=False), b.classify(data, decision="both", gmr=False))


def test_a_bad_fraction_or_a_model_file_without_impostor_scores_fails_in_one_line(trained3):
    ms, _ = trained3
    with pytest.raises(ConfigError, match="threshold_fraction"):
        ModelsConfig.from_section({"threshold_fraction": 1.5})
    old = ms.with_threshold()
    old.impostor_ll_ = np.full(len(ms.labels_), np.nan)              # as loaded from a pre-fraction file
    old.with_threshold(fraction=1.0)                                  # the percentile rule needs none
    with pytest.raises(ModelError, match="retrain") as e:
        old.with_threshold(fraction=0.5)
    assert "\n" not in str(e.value)
