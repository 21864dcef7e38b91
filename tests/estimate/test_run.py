"""The estimate stage's entry points (``run_estimate``, ``run_q2``): outputs, placeholders with
their reasons, radar gaps counted, synthetic radar seeded, a bad ``estimate`` key named."""

from __future__ import annotations

import copy
import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from helpers_estimate import SITE, ingested_flight
from helpers_maneuvers import synth_bulk, synth_run
from pipeline.config import ConfigError, validate_config
from pipeline.estimate.models import RADAR_FIELDS, STATE_COLUMNS, RadarModel
import pipeline.estimate.run as estimate_run
from pipeline.estimate.run import (ESTIMATORS, YAW_GAP_LIMIT_S, job_config, radar_rng, radar_steps, run_estimate,
                                   run_q2, synthesise_radar)
from pipeline.io import schema
from pipeline.io.base import FlightLog
from pipeline.io.parquet import read_flightlog, read_table, read_table_meta, write_flightlog
from pipeline.models.base import ModelsConfig
from pipeline.models.classifier import ManeuverModelSet
from pipeline.report.plots import mode_timeline

FAST = dict(n_states=3, n_iter=10, tol=1e-1, gmm_restarts=1, seed=5)


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """A tiny state9 model set with GMR, the same set relabelled as aero (no GMR), and Q₂."""
    root = tmp_path_factory.mktemp("models")
    data = synth_bulk(("M1", "M2", "M3"), 4, np.random.default_rng(20261201))
    ms = ManeuverModelSet(config=ModelsConfig(**FAST)).fit(data)
    ms.save(root / "sim")
    aero = copy.copy(ms)
    aero.config = dataclasses.replace(ms.config, feature_set="aero")
    n = len(aero.feature_set.names)  # a loadable aero set: its normaliser spans aero's features
    aero.normaliser_ = dataclasses.replace(ms.normaliser_, x_min=np.zeros(n), x_max=np.ones(n))
    aero.save(root / "aero")
    sets = root / "M_train.parquet"
    data.to_parquet(sets)
    q2 = run_q2({"params": root / "sim" / "params.npz", "sets": [sets]}, {"q2": root / "q2.json"},
                {"q2_scale": 1.0}, model_set="sim")
    assert q2.status == "ok", q2.error
    return root


def _run(tmp, inputs, models=None, model="sim", vehicle_cfg=None, seed=3, fid="f1"):
    section = validate_config({"estimate": vehicle_cfg or {}})["estimate"]
    cfg = job_config(section, "veh")
    if models is not None:
        inputs = {**inputs, "model_params": models / model / "params.npz", "q2": models / "q2.json"}
    outputs = {e: tmp / e / f"{fid}.parquet" for e in ESTIMATORS}
    return run_estimate(inputs, outputs, cfg, flight_id=fid, vehicle="veh", seed=seed), outputs


def test_estimates_have_the_declared_columns_and_the_ekf_hmm_adds_mode_pred_and_confidence(tmp_path, models):
    res, out = _run(tmp_path, ingested_flight(tmp_path), models)
    assert res.status == "ok", res.error
    ekf, hmm = read_table(out["ekf"]), read_table(out["ekf_hmm"])
    assert list(ekf.columns) == schema.column_names("estimate") == list(read_table(out["ekf_rts"]).columns)
    assert list(hmm.columns) == schema.column_names("estimate_hmm")
    assert [c for c in ekf.columns if c.startswith("P_")] == [f"P_{i}_{j}" for i in range(9) for j in range(i, 9)]
    assert [c for c in ekf.columns if c.startswith("x_")] == [f"x_{c}" for c in STATE_COLUMNS]
    assert len(ekf) == len(hmm) == 151 and ekf["nees"].notna().all() and hmm["nees"].notna().all()
    assert str(hmm["mode"].dtype) == "bool" and hmm["mode"].any()
    assert set(hmm["pred"]) <= {"unknown", "M1", "M2", "M3"}
    assert mode_timeline(hmm) is not None  # the flight page's mode panel
    m = read_table_meta(out["ekf"])
    assert (m["status"], m["reference"], m["radar"], m["radar_site_ned_m"]) == ("ok", "truth", "stream", list(SITE))
    # the smoother uses the future: its position error is below the filter's
    assert res.diagnostics["rmse"]["ekf_rts"]["pos"] < res.diagnostics["rmse"]["ekf"]["pos"]


def test_a_flight_without_radar_gets_three_placeholders_with_the_reason(tmp_path, models):
    res, out = _run(tmp_path, ingested_flight(tmp_path, radar=False), models)
    assert res.status == "failed" and "no radar stream" in res.error
    for e in ESTIMATORS:
        m = read_table_meta(out[e])
        assert m["status"] == "failed" and m["error"] == res.error and "\n" not in res.error
        assert len(read_table(out[e])) == 0
    assert list(read_table(out["ekf_hmm"]).columns) == schema.column_names("estimate_hmm")


def test_a_model_without_gmr_gives_an_ekf_hmm_placeholder_beside_complete_ekf_tables(tmp_path, models):
    res, out = _run(tmp_path, ingested_flight(tmp_path), models, model="aero")
    assert res.status == "partial" and "no GMR (feature set aero" in res.error
    assert len(read_table(out["ekf"])) == len(read_table(out["ekf_rts"])) == 151
    assert len(read_table(out["ekf_hmm"])) == 0
    assert read_table_meta(out["ekf_hmm"])["error"] == res.error
    q2 = run_q2({"params": models / "aero" / "params.npz", "sets": []}, {"q2": tmp_path / "q2.json"}, {},
                model_set="aero")
    assert q2.status == "failed" and "no GMR" in json.loads((tmp_path / "q2.json").read_text())["error"]


def test_radar_gaps_are_predict_only_steps_counted_in_the_metadata(tmp_path, models):
    res, out = _run(tmp_path, ingested_flight(tmp_path, drop=range(40, 52)), models)
    assert res.status == "ok" and res.diagnostics["n_predict_only"] == 12
    for e in ESTIMATORS:
        m = read_table_meta(out[e])
        assert (m["n_steps"], m["n_predict_only"]) == (151, 12), e
    ekf = read_table(out["ekf"])
    assert (ekf["nis"].iloc[40:52] == 0).all() and (ekf["nis"].iloc[52:] > 0).all()
    # the gap's steps keep the radar's 0.2 s grid
    assert set(np.diff(ekf["t_ns"].to_numpy())) == {200_000_000}


def test_radar_steps_keep_the_sample_times_and_fill_the_grid():
    t = np.array([0, 200, 400, 1000, 1200, 1401]) * 1_000_000
    r = pd.DataFrame({"t_ns": t, **{f: np.arange(6.0) for f in RADAR_FIELDS}})
    steps, z, period, dropped = radar_steps(r)
    assert period == 200_000_000 and dropped == {"nan_field": 0, "duplicate_stamp": 0, "same_step": 0}
    assert steps.tolist() == (np.array([0, 200, 400, 600, 800, 1000, 1200, 1401]) * 1_000_000).tolist()
    assert np.isnan(z[3:5]).all() and z[:3, 0].tolist() == [0, 1, 2] and z[5:, 0].tolist() == [3, 4, 5]


def test_synthetic_radar_is_deterministic_per_seed_and_flight_and_gaps_are_nan():
    st = synth_run("M2", np.random.default_rng(1), duration_s=10.0, rate_hz=25.0).drop(columns="label")
    st.loc[100:120, "gap"] = True
    model = RadarModel(site_ned_m=SITE)
    a = synthesise_radar(st, model, 5.0, radar_rng(3, "f1"))
    pd.testing.assert_frame_equal(a, synthesise_radar(st, model, 5.0, radar_rng(3, "f1")))
    for other in (radar_rng(4, "f1"), radar_rng(3, "f2")):
        b = synthesise_radar(st, model, 5.0, other)
        assert not np.allclose(a["range_m"], b["range_m"], equal_nan=True)
    assert len(a) == 51 and np.diff(a["t_ns"]).tolist() == [200_000_000] * 50
    gap = (a["t_ns"] >= st["t_ns"][100]) & (a["t_ns"] <= st["t_ns"][120])
    assert a.loc[gap, "range_m"].isna().all() and a.loc[~gap, "range_m"].notna().all()
    # the noise is the seed-000 radar's: on a 200 s flight (1001 samples) the residuals against
    # h(x) are N(0, σ²) per field, so Σ r²/σ² is χ² with n degrees of freedom (the mean is known,
    # 0); 99.9 % bounds per field, which a σ 20 % off (a variance ratio of 1.44 or 0.69) leaves
    long = synth_run("M2", np.random.default_rng(2), duration_s=200.0, rate_hz=25.0).drop(columns="label")
    a = synthesise_radar(long, model, 5.0, radar_rng(3, "f1"))
    assert len(a) == 1001 and a[list(RADAR_FIELDS)].notna().all().all()
    x = long[list(STATE_COLUMNS)].to_numpy()[np.searchsorted(long["t_ns"], a["t_ns"])]
    resid = a[list(RADAR_FIELDS)].to_numpy() - model.h(x)
    n = len(resid)
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], n)
    q = np.sum((resid / np.asarray(model.sigma)) ** 2, axis=0)
    assert np.all((q > lo) & (q < hi)), (q / n, lo / n, hi / n)
    assert np.all(np.abs(resid.mean(axis=0)) < 4 * np.asarray(model.sigma) / np.sqrt(n))


def test_a_synthetic_radar_vehicle_uses_the_state_and_takes_it_as_the_reference(tmp_path):
    inputs = ingested_flight(tmp_path, radar=False, truth=False)
    cfg = {"synthetic_radar": {"veh": {"site_ned_m": list(SITE)}}}
    res, out = _run(tmp_path, inputs, vehicle_cfg=cfg, seed=11)
    assert res.status == "partial" and "no model set" in res.error  # no model given: EKF only
    m = read_table_meta(out["ekf"])
    assert (m["radar"], m["reference"], m["n_steps"]) == ("synthetic", "state", 151)
    first = read_table(out["ekf"])
    again, _ = _run(tmp_path / "again", inputs, vehicle_cfg=cfg, seed=11)
    pd.testing.assert_frame_equal(first, read_table(tmp_path / "again" / "ekf" / "f1.parquet"))
    assert res.diagnostics["rmse"]["ekf"]["pos"] < 3.0


def test_a_bad_estimate_key_or_value_is_one_line_naming_it():
    for bad, match in (({"ekf": {"qq": 1.0}}, "estimate.ekf.qq: unknown key"),
                       ({"synthetic_radar": {"v": {"sigma_rnage_m": 1}}}, "estimate.synthetic_radar.v.sigma_rnage_m: unknown key"),
                       ({"ekf": {"q": -1}}, "estimate.ekf.q: "),
                       ({"ekf_hmm": {"model": 3}}, "estimate.ekf_hmm.model: 3 is not a string")):
        with pytest.raises(ConfigError, match=match.replace(".", r"\.")) as exc:
            validate_config({"estimate": bad})
        assert "\n" not in str(exc.value)


def test_the_job_config_holds_only_the_flights_own_sub_sections():
    sec = validate_config({"estimate": {"synthetic_radar": {"a": {}, "b": {"rate_hz": 2.0}}}})["estimate"]
    cfg = job_config(sec, "b")
    assert set(cfg) == {"synthetic_radar", "radar", "ekf", "ekf_hmm"}
    assert cfg["synthetic_radar"]["rate_hz"] == 2.0 and job_config(sec, "c")["synthetic_radar"] is None


def test_without_truth_the_nees_is_nan_and_the_filter_starts_from_the_first_measurement(tmp_path):
    res, out = _run(tmp_path, ingested_flight(tmp_path, truth=False))
    m = read_table_meta(out["ekf"])
    assert (m["reference"], m["init"]) == ("none", "radar")
    ekf = read_table(out["ekf"])
    assert ekf["nees"].isna().all() and ekf["nis"].notna().all()
    # from the first measurement (the site is below the flight) the position starts within metres
    run = read_table(tmp_path / "state" / "f1.parquet")
    assert abs(ekf["x_pos_n_m"].iloc[0] - run["pos_n_m"].iloc[0]) < 10.0


def test_q2_of_a_model_set_trained_on_estimates_takes_its_errors_against_the_truth(tmp_path, models):
    """``truth_sets`` beside ``sets`` (input: ekf): the GMR sees the estimates, the one-step errors
    are the truth's; noisier inputs give a larger Q₂ than the truth alone."""
    data = pd.read_parquet(models / "M_train.parquet")
    noisy = data.copy()
    rng = np.random.default_rng(7)
    for c in ("pos_n_m", "pos_e_m", "pos_d_m"):
        noisy[c] = noisy[c] + rng.normal(0, 0.3, len(noisy))
    est = tmp_path / "est" / "M_train.parquet"
    est.parent.mkdir()
    noisy.to_parquet(est)
    args = ({"q2_scale": 1.0},)
    truth_only = run_q2({"params": models / "sim" / "params.npz", "sets": [models / "M_train.parquet"]},
                        {"q2": tmp_path / "a.json"}, *args, model_set="sim")
    both = run_q2({"params": models / "sim" / "params.npz", "sets": [est], "truth_sets": [models / "M_train.parquet"]},
                  {"q2": tmp_path / "b.json"}, *args, model_set="sim")
    assert truth_only.status == both.status == "ok"
    qa = np.array(json.loads((tmp_path / "a.json").read_text())["Q2"])
    qb = np.array(json.loads((tmp_path / "b.json").read_text())["Q2"])
    # the truth's own position increments are unchanged, so only the GMR inputs differ: larger errors
    assert np.trace(qb[6:, 6:]) > np.trace(qa[6:, 6:])


# --- bad input: rows set aside are counted, errors become placeholders with one line ---------------

def _rewrite(inputs: dict, **change) -> dict:
    """``inputs``'s ingested flight with streams replaced: ``change[stream](frame) -> frame``."""
    d = Path(inputs["meta"]).parent
    log = read_flightlog(d)
    streams = {n: log[n] for n in schema.STREAM_NAMES}
    for name, edit in change.items():
        streams[name] = edit(streams[name].copy())
    write_flightlog(FlightLog.from_streams(log.meta, streams), d)
    return inputs


def _radar_meta(out) -> list[tuple]:
    return [(m["n_radar_rows"], m["radar_dropped"], m["notes"]) for m in (read_table_meta(out[e]) for e in ESTIMATORS)]


def test_radar_steps_keep_the_first_row_of_a_repeated_stamp_and_count_every_row_set_aside():
    ms = [0, 200, 200, 400, 600, 610, 800, 1000, 1000, 1200]   # two repeats; 610 shares 600's step
    r = pd.DataFrame({"t_ns": np.array(ms) * 1_000_000, **{f: np.arange(10.0) for f in RADAR_FIELDS}})
    r.loc[4, "range_m"], r.loc[6, "dcos_u"] = np.nan, np.inf         # 600 and 800: unusable fields
    steps, z, period, dropped = radar_steps(r.iloc[::-1])       # in any order
    assert dropped == {"nan_field": 2, "duplicate_stamp": 2, "same_step": 0} and period == 200_000_000
    # 610 now holds the step of 600 (whose row had a NaN field); 800 is a predict-only step
    assert steps.tolist() == (np.array([0, 200, 400, 610, 800, 1000, 1200]) * 1_000_000).tolist()
    assert z[:4, 0].tolist() == [0, 2, 3, 5] and np.isnan(z[4]).all() and z[5:, 0].tolist() == [8, 9]
    assert len(steps) - np.isnan(z[:, 0]).sum() == len(r) - sum(dropped.values())
    # the stable sort keeps the first row of a repeated stamp in stream order, here the reversed one
    assert radar_steps(r)[1][1, 0] == 1 and radar_steps(r.iloc[::-1])[1][1, 0] == 2
    # two samples in one step with no NaN: the first taken, the later one counted
    r2 = r.copy()
    r2.loc[4, "range_m"] = 4.0
    steps, z, _, dropped = radar_steps(r2)
    assert dropped == {"nan_field": 1, "duplicate_stamp": 2, "same_step": 1} and z[3, 0] == 4.0
    assert len(steps) - np.isnan(z[:, 0]).sum() == len(r2) - sum(dropped.values())


def test_radar_steps_of_a_radar_whose_stamps_all_repeat_is_one_sample_not_an_error():
    r = pd.DataFrame({"t_ns": np.full(5, 7, dtype=np.int64), **{f: np.arange(5.0) for f in RADAR_FIELDS}})
    steps, z, period, dropped = radar_steps(r)
    assert (len(steps), period, dropped["duplicate_stamp"]) == (1, 0, 4) and z[0, 0] == 0.0


def test_a_flight_whose_radar_repeats_time_stamps_is_estimated_with_the_repeats_counted(tmp_path, models):
    """Every radar row written twice (the repeats of rows 10-14 with other values; ingest keeps
    them all): more repeats than distinct stamps once stopped the job. Duplicated stamps are data,
    not a failure: the first row of each is used, the flight is ``ok`` (every step still has its
    measurement) and the repeats are counted in every output."""
    def repeat(r):
        again = r.copy()
        again.loc[10:14, "range_m"] += 50.0
        return pd.concat([r, again], ignore_index=True)

    plain, _ = _run(tmp_path / "plain", ingested_flight(tmp_path / "plain"))
    res, out = _run(tmp_path, _rewrite(ingested_flight(tmp_path), radar=repeat), models)
    assert res.status == "ok", res.error
    d = res.diagnostics
    assert (d["n_steps"], d["n_predict_only"], d["n_radar_rows"]) == (151, 0, 302)
    assert d["radar_dropped"] == {"nan_field": 0, "duplicate_stamp": 151, "same_step": 0, "other_instance": 0}
    assert any("151 row(s) repeat an earlier time stamp" in n for n in d["notes"])
    for e in ESTIMATORS:
        assert len(read_table(out[e])) == 151 and read_table_meta(out[e])["status"] == "ok", e
    assert {(n, str(dr)) for n, dr, _ in _radar_meta(out)} == {(302, str(d["radar_dropped"]))}
    # the first row of each stamp: the estimate is the flight's without its repeats
    pd.testing.assert_frame_equal(read_table(out["ekf"]), read_table(tmp_path / "plain" / "ekf" / "f1.parquet"))
    assert plain.diagnostics["radar_dropped"]["duplicate_stamp"] == 0


def test_radar_rows_with_nan_fields_or_sharing_a_step_are_counted_in_every_outputs_metadata(tmp_path):
    def damage(r):
        r.loc[[20, 21], "range_rate_mps"] = np.nan
        extra = r.iloc[[30]].copy()
        extra["t_ns"] += 10_000_000   # 10 ms after row 30: the same 0.2 s step
        return pd.concat([r, extra], ignore_index=True)

    res, out = _run(tmp_path, _rewrite(ingested_flight(tmp_path), radar=damage))
    assert res.status == "partial" and "no model set" in res.error     # EKF only: no model given
    d = res.diagnostics
    assert (d["n_steps"], d["n_predict_only"], d["n_radar_rows"]) == (151, 2, 152)
    assert d["radar_dropped"] == {"nan_field": 2, "duplicate_stamp": 0, "same_step": 1, "other_instance": 0}
    assert d["n_steps"] - d["n_predict_only"] == d["n_radar_rows"] - sum(d["radar_dropped"].values())
    for n_rows, dropped, _ in _radar_meta(out):   # the ekf_hmm placeholder's too
        assert (n_rows, dropped) == (152, d["radar_dropped"])


def test_a_second_radar_instance_is_counted_and_noted_and_leaves_the_estimate_unchanged(tmp_path):
    plain, _ = _run(tmp_path / "plain", ingested_flight(tmp_path / "plain"))

    def second(r):
        other = r.copy()
        other["instance"], other["range_m"] = 1, other["range_m"] + 500.0
        return pd.concat([r, other], ignore_index=True)

    res, out = _run(tmp_path, _rewrite(ingested_flight(tmp_path), radar=second))
    d = res.diagnostics
    assert (d["n_radar_rows"], d["radar_dropped"]["other_instance"], d["n_predict_only"]) == (302, 151, 0)
    assert any("radar: instance 1 ignored (151 rows)" in n and "instance 0 only" in n for n in d["notes"])
    assert all(any("instance 1 ignored" in n for n in notes) for _, _, notes in _radar_meta(out))
    pd.testing.assert_frame_equal(read_table(out["ekf"]), read_table(tmp_path / "plain" / "ekf" / "f1.parquet"))
    assert plain.diagnostics["radar_dropped"]["other_instance"] == 0 and plain.diagnostics["notes"] == []


def test_an_error_inside_the_filter_gives_three_placeholders_with_a_one_line_reason(tmp_path, models, monkeypatch):
    inputs = ingested_flight(tmp_path)
    good, out = _run(tmp_path, inputs, models)   # outputs of an earlier run: replaced, not left stale
    assert good.status == "ok"

    def broken(*args, **kwargs):
        raise RuntimeError("covariance\nnot positive definite")

    monkeypatch.setattr(estimate_run, "run_filter", broken)
    res, out = _run(tmp_path, inputs, models)   # returns: nothing escapes run_estimate
    assert res.status == "failed"
    assert res.error.startswith("estimate failed: RuntimeError: covariance not positive definite (at ")
    assert "\n" not in res.error
    for e in ESTIMATORS:
        m = read_table_meta(out[e])
        assert (m["status"], m["error"], len(read_table(out[e]))) == ("failed", res.error, 0), e
        assert m["n_radar_rows"] == 151   # what was learnt before the failure is kept
    assert list(read_table(out["ekf_hmm"]).columns) == schema.column_names("estimate_hmm")


def test_an_error_inside_the_ekf_hmm_leaves_the_ekf_tables_and_a_placeholder_saying_why(tmp_path, models, monkeypatch):
    def broken(*args, **kwargs):
        raise KeyError("pos_n_m")

    monkeypatch.setattr(estimate_run, "run_ekf_hmm", broken)
    res, out = _run(tmp_path, ingested_flight(tmp_path), models)
    assert res.status == "partial" and res.error.startswith("EKF+HMM failed: KeyError: 'pos_n_m' (at ")
    assert len(read_table(out["ekf"])) == len(read_table(out["ekf_rts"])) == 151
    m = read_table_meta(out["ekf_hmm"])
    assert (m["status"], m["error"], len(read_table(out["ekf_hmm"]))) == ("failed", res.error, 0)


def test_an_unreadable_input_is_named_in_one_line_and_never_a_traceback(tmp_path, models):
    # the model set's meta.json: the EKF tables stand, the ekf_hmm placeholder names the file
    bad_models = tmp_path / "models"
    shutil.copytree(models, bad_models)
    (bad_models / "sim" / "meta.json").write_text("{not json")
    res, out = _run(tmp_path / "m", ingested_flight(tmp_path / "m"), bad_models)
    assert res.status == "partial" and res.error.startswith(f"{bad_models / 'sim' / 'meta.json'}: not a readable JSON")
    assert len(read_table(out["ekf"])) == 151 and "\n" not in res.error
    # the model set's params.npz: the loader's own line, naming the folder
    shutil.copy(models / "sim" / "meta.json", bad_models / "sim" / "meta.json")
    (bad_models / "sim" / "params.npz").write_bytes(b"truncated")
    res, _ = _run(tmp_path / "p", ingested_flight(tmp_path / "p"), bad_models)
    assert res.status == "partial" and str(bad_models / "sim") in res.error
    # the flight's own inputs: three placeholders naming the file
    for name, damage in (("meta", lambda i: Path(i["meta"]).write_text("[1, 2]")),
                         ("state", lambda i: Path(i["state"]).write_bytes(b"PAR1 not parquet"))):
        inputs = ingested_flight(tmp_path / name)
        damage(inputs)
        res, out = _run(tmp_path / name, inputs, models)
        assert res.status == "failed" and res.error.startswith(str(inputs[name])), res.error
        assert "\n" not in res.error and read_table_meta(out["ekf"])["error"] == res.error


def test_ekf_hmm_heading_bridged_over_a_long_attitude_gap_or_held_past_its_end_is_counted(tmp_path, models):
    """Attitude rows 50-69 missing (a 4.2 s gap: 20 steps bridged), row 100 missing (0.4 s, under
    the limit: not counted) and none after row 140 (10 steps held)."""
    assert YAW_GAP_LIMIT_S == 1.0
    inputs = _rewrite(ingested_flight(tmp_path),
                      attitude=lambda a: a.drop(index=[*range(50, 70), 100, *range(141, 151)]))
    res, out = _run(tmp_path, inputs, models)
    assert res.status == "ok", res.error
    assert res.diagnostics["yaw_filled"] == {"across_gap": 20, "held": 10}
    m = read_table_meta(out["ekf_hmm"])
    assert (m["yaw_from"], m["yaw_gap_limit_s"], m["yaw_filled"]) == ("attitude", 1.0, {"across_gap": 20, "held": 10})
    note = "heading: 20 step(s) interpolated across attitude gaps over 1 s, 10 held beyond its span"
    assert note in m["notes"] and note in res.diagnostics["notes"]
    plain, _ = _run(tmp_path / "plain", ingested_flight(tmp_path / "plain"), models)
    assert plain.diagnostics["yaw_filled"] == {"across_gap": 0, "held": 0}
