"""The estimate stage's entry points (``run_estimate``, ``run_q2``): outputs, placeholders with
their reasons, radar gaps counted, synthetic radar seeded, a bad ``estimate`` key named."""

from __future__ import annotations

import copy
import dataclasses
import json

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from helpers_estimate import SITE, ingested_flight
from helpers_maneuvers import synth_bulk, synth_run
from pipeline.config import ConfigError, validate_config
from pipeline.estimate.models import RADAR_FIELDS, STATE_COLUMNS, RadarModel
from pipeline.estimate.run import (ESTIMATORS, job_config, radar_rng, radar_steps, run_estimate, run_q2,
                                   synthesise_radar)
from pipeline.io import schema
from pipeline.io.parquet import read_table, read_table_meta
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
    steps, z, period = radar_steps(r)
    assert period == 200_000_000
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
