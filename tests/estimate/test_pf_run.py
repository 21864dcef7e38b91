"""pf_jm over one flight (issue 17): the jump-Markov PF on a state track, placeholders, config."""

import numpy as np
import pandas as pd
import pytest

from pipeline.config import validate_config
from pipeline.estimate.pf_run import DEFAULTS, PF_JM_MODES, classifier_softmax, job_config, pf_config, run_pf_jm, thin
from pipeline.io import schema
from pipeline.io.parquet import read_table, read_table_meta, write_table


def _state(tmp_path, *, omega=0.0, T=20.0, hz=25.0, speed=8.0, nan_at=(), name="state.parquet"):
    t = np.arange(0, T, 1 / hz)
    th = omega * t
    if omega:
        n, e = speed / omega * np.sin(th), speed / omega * (1 - np.cos(th))
    else:
        n, e = speed * t, np.zeros_like(t)
    rng = np.random.default_rng(0)
    df = pd.DataFrame({"t_ns": (t * 1e9).astype(np.int64), "pos_n_m": n + 0.3 * rng.standard_normal(t.size),
                       "pos_e_m": e + 0.3 * rng.standard_normal(t.size), "pos_d_m": -10.0,
                       "vel_n_mps": speed * np.cos(th), "vel_e_mps": speed * np.sin(th), "vel_d_mps": 0.0})
    for k in nan_at:
        df.loc[k, ["pos_n_m", "pos_e_m"]] = np.nan
    p = tmp_path / name
    write_table(df, p, name="state", extra={"status": "ok", "preprocess": {"sources": {"position": "gps"}}})
    return p


CFG = {"n_particles": 300, "rate_hz": 10.0}


def test_a_straight_track_gives_a_pf_table_whose_mode_fractions_sum_to_one(tmp_path):
    out = tmp_path / "pf.parquet"
    r = run_pf_jm({"state": _state(tmp_path)}, {"pf_jm": out}, CFG, flight_id="f1", vehicle="v")
    assert r.status == "ok"
    df, meta = read_table(out), read_table_meta(out)
    assert list(df.columns[:8]) == ["t_ns", "x_pos_n_m", "x_pos_e_m", "x_vel_n_mps", "x_vel_e_mps",
                                    "x_omega_radps", "x_acc_n_mps2", "x_acc_e_mps2"]
    assert [c for c in df.columns if c.startswith("mode_p_")] == [f"mode_p_{m}" for m in PF_JM_MODES]
    assert np.allclose(df[[f"mode_p_{m}" for m in PF_JM_MODES]].sum(axis=1), 1.0)
    assert len(df) == 200 and meta["n_steps"] == 200 and meta["n_particles"] == 300
    assert meta["table"] == "pf" and meta["status"] == "ok" and meta["n_reinit"] == 0
    assert np.all((df["neff"] >= 1) & (df["neff"] <= 300))
    assert df["resampled"].dtype == bool and df["resampled"].any()
    # the estimate follows the track: 8 m/s north
    assert np.nanmedian(np.abs(df["x_vel_n_mps"].to_numpy()[20:] - 8.0)) < 0.5
    assert np.allclose(np.array(meta["Pi_ref"]).sum(axis=1), 1.0)


def test_a_turning_track_holds_more_turn_mode_than_a_straight_one(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    s = run_pf_jm({"state": _state(tmp_path / "a")}, {"pf_jm": tmp_path / "s.parquet"}, CFG, flight_id="s")
    t = run_pf_jm({"state": _state(tmp_path / "b", omega=0.4)}, {"pf_jm": tmp_path / "t.parquet"}, CFG, flight_id="s")
    fs, ft = s.diagnostics["mode_fraction_mean"], t.diagnostics["mode_fraction_mean"]
    assert ft["ct"] > fs["ct"] + 0.1
    assert fs["cv"] > ft["cv"]


def test_missing_positions_are_predict_only_steps_counted_in_the_metadata(tmp_path):
    out = tmp_path / "pf.parquet"
    run_pf_jm({"state": _state(tmp_path, nan_at=range(100, 130))}, {"pf_jm": out}, CFG, flight_id="f")
    meta, df = read_table_meta(out), read_table(out)
    # 25 Hz samples 100–129 (4.00–5.16 s) have no position; the 10 Hz steps take the sample
    # nearest each 0.1 s tick, so the ticks 4.0, 4.1, …, 5.1 s (12 of them) land on them (4.0 s
    # on sample 100 itself, 5.1 s between samples 127 and 128, 5.2 s on the valid 130)
    t = (np.arange(0, 20.0, 1 / 25.0) * 1e9).astype(np.int64)
    nearest = np.abs(t[None, :] - np.arange(200)[:, None] * 100_000_000).argmin(axis=1)
    assert np.isin(nearest, np.arange(100, 130)).sum() == 12
    assert meta["n_predict_only"] == 12 and meta["n_steps"] == 200
    # those are the steps stamped inside the gap, and a predict-only step never resamples
    gap = df["t_ns"].between(t[100], t[129]).to_numpy()
    assert gap.sum() == 12 and not df.loc[gap, "resampled"].any()


def test_the_same_seed_writes_the_same_table(tmp_path):
    st = _state(tmp_path)
    a, b, c = (tmp_path / f"{k}.parquet" for k in "abc")
    run_pf_jm({"state": st}, {"pf_jm": a}, CFG, flight_id="f", seed=1)
    run_pf_jm({"state": st}, {"pf_jm": b}, CFG, flight_id="f", seed=1)
    run_pf_jm({"state": st}, {"pf_jm": c}, CFG, flight_id="f", seed=2)
    assert read_table(a).equals(read_table(b)) and not read_table(a).equals(read_table(c))
    assert a.read_bytes() == b.read_bytes()  # metadata included: no run time in the file


def test_no_positions_give_a_placeholder_with_the_reason(tmp_path):
    p = tmp_path / "state.parquet"
    write_table(pd.DataFrame({"t_ns": np.arange(5, dtype=np.int64), "pos_n_m": np.nan, "pos_e_m": np.nan}), p,
                name="state", extra={"status": "ok"})
    out = tmp_path / "pf.parquet"
    r = run_pf_jm({"state": p}, {"pf_jm": out}, CFG, flight_id="f")
    assert r.status == "failed" and "0 sample(s) with a position" in r.error
    assert len(read_table(out)) == 0 and read_table_meta(out)["status"] == "failed"
    r = run_pf_jm({"state": tmp_path / "none.parquet"}, {"pf_jm": out}, CFG, flight_id="f")
    assert r.status == "failed" and r.error == "no state table"


def test_a_failed_preprocess_gives_a_placeholder_naming_it(tmp_path):
    p = tmp_path / "state.parquet"
    write_table(schema.empty("state"), p, schema.STATE, name="state", extra={"status": "failed", "error": "no GPS"})
    out = tmp_path / "pf.parquet"
    r = run_pf_jm({"state": p}, {"pf_jm": out}, CFG, flight_id="f")
    assert r.status == "failed" and r.error == "preprocess failed: no GPS"


def test_the_classifier_softmax_sits_beside_the_mode_fractions(tmp_path):
    cls = pd.DataFrame({"run_id": "0", "t_ns": np.arange(0, 20_000_000_000, 200_000_000, dtype=np.int64)})
    cls["ll_A"] = -1.0
    cls["ll_B"] = -1.0 + np.log(3.0)
    cp = tmp_path / "sim" / "f.parquet"
    cp.parent.mkdir()
    write_table(cls, cp, name="classification", extra={"status": "ok"})
    out = tmp_path / "pf.parquet"
    run_pf_jm({"state": _state(tmp_path), "classified": [str(cp)]}, {"pf_jm": out}, CFG, flight_id="f")
    df, meta = read_table(out), read_table_meta(out)
    assert np.allclose(df["cls_p_A"], 0.25) and np.allclose(df["cls_p_B"], 0.75)
    assert meta["classifier"] == "sim" and meta["classifier_labels"] == ["A", "B"]


def test_classifier_samples_far_from_a_step_give_nan():
    cls = pd.DataFrame({"t_ns": np.array([0, 100, 200], dtype=np.int64), "ll_A": [0.0, 0.0, 0.0], "ll_B": [0.0, -np.inf, np.nan]})
    p = classifier_softmax(cls, np.array([0, 100, 10_000], dtype=np.int64))
    assert np.allclose(p["cls_p_A"][:2], [0.5, 1.0]) and np.isnan(p["cls_p_A"][2])


def test_thinning_picks_the_sample_nearest_each_tick():
    t = np.arange(0, 1_000_000_000, 40_000_000, dtype=np.int64)  # 25 Hz
    idx = thin(t, 10.0)
    assert np.all(np.abs(t[idx] - np.arange(len(idx)) * 100_000_000) <= 20_000_000)
    assert np.array_equal(thin(t, None), np.arange(len(t)))


def test_the_schema_defaults_are_the_entry_points_defaults():
    cfg = validate_config({})["estimate"]["pf"]
    assert pf_config(job_config(cfg)) == pf_config({}) == {**DEFAULTS, **{k: pf_config({})[k] for k in ("dwell_s", "noise")}}
    assert job_config({**cfg, "hmpf": {"x": 1}, "geolocation": {}}) == job_config(cfg)
    assert "vehicles" not in job_config(cfg)
    assert cfg["threshold"] == pytest.approx(DEFAULTS["threshold"])


def test_a_shorter_filter_state_leaves_the_missing_columns_nan(tmp_path):
    from pipeline.estimate.pf_run import pf_frame, write_pf

    T = 4
    df = pf_frame(np.arange(T, dtype=np.int64), np.ones((T, 5)), np.ones((T, 5, 5)), np.full((T, 4), 0.25),
                  np.full(T, 10.0), np.ones(T, bool), modes=("s", "l", "r", "w"))
    assert np.all(df["x_omega_radps"] == 1.0) and df["x_acc_n_mps2"].isna().all()
    assert np.all(df["P_4_4"] == 1.0) and df["P_0_5"].isna().all() and df["P_5_6"].isna().all()
    write_pf(df, tmp_path / "h.parquet", {"status": "ok"})
    assert [c for c in read_table(tmp_path / "h.parquet").columns if c.startswith("mode_p_")] == [
        "mode_p_s", "mode_p_l", "mode_p_r", "mode_p_w"]


def test_with_the_defaults_the_filter_follows_a_5_mps2_weave_within_a_metre_and_without_the_kernel_loses_it(tmp_path):
    # the simulated quad reaches 6-7 m/s² (M3 weaves at ~1 rad/s): with 500 particles and
    # 0.5 m/s² white acceleration (the earlier defaults) the cloud lagged metres behind; with more
    # noise but no regularisation kernel the fixes fall in the cloud's tail, the cloud narrows
    # and it is lost (re-initialised); the kernel after each resampling keeps it on the track
    t = np.arange(0, 30, 1 / 25.0)
    rng = np.random.default_rng(4)
    n, e = 6.0 * t, 5.0 * np.sin(t)                      # 5 m/s² peak lateral acceleration
    df = pd.DataFrame({"t_ns": (t * 1e9).astype(np.int64), "pos_n_m": n + 0.3 * rng.standard_normal(t.size),
                       "pos_e_m": e + 0.3 * rng.standard_normal(t.size), "pos_d_m": -10.0,
                       "vel_n_mps": 6.0, "vel_e_mps": 5.0 * np.cos(t), "vel_d_mps": 0.0})
    p = tmp_path / "state.parquet"
    write_table(df, p, name="state", extra={"status": "ok"})
    errs = {}
    before = {"jitter": "none", "n_particles": 500,
              "noise": {"cv": {"sigma_a": 0.5}, "ct": {"sigma_a": 0.5}, "ca": {"sigma_j": 2.0}}}
    for tag, cfg in (("default", {}), ("no kernel", {"jitter": "none"}), ("before", before)):
        out = tmp_path / f"{tag}.parquet"
        r = run_pf_jm({"state": p}, {"pf_jm": out}, pf_config(cfg), flight_id="w", seed=3)
        d = read_table(out)
        ref_e = np.interp(d["t_ns"], df["t_ns"], e)
        ref_n = np.interp(d["t_ns"], df["t_ns"], n)
        err = np.hypot(d["x_pos_n_m"] - ref_n, d["x_pos_e_m"] - ref_e)[20:]
        errs[tag] = (float(np.percentile(err, 90)), r.diagnostics.get("n_reinit", 0))
    assert errs["default"][0] < 1.2 and errs["default"][1] == 0          # measured 0.89 m, none
    assert errs["no kernel"][0] > 2.0 and errs["no kernel"][1] >= 1      # measured 4.67 m, one
    assert errs["before"][0] > 5.0 and errs["before"][1] >= 3            # measured 7.84 m, six
