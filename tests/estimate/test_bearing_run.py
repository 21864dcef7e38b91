"""The bearing-only replay of two flights: the bearing synthesis (common origin, time offset,
variable T), the three estimator tables and the skip of a pair with a missing flight."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.estimate.bearing_run import (ESTIMATORS, heading_converged_s, range_error_pct_at,
                                           run_bearing_replay, synthesise_pair)
from pipeline.io import schema
from pipeline.io.parquet import read_table, read_table_meta, write_table


def _track(t, n, e, vn, ve):
    return pd.DataFrame({"t_ns": np.round(np.asarray(t) * 1e9).astype(np.int64), "pos_n_m": n, "pos_e_m": e,
                         "vel_n_mps": vn, "vel_e_mps": ve})


def _pair(duration=40.0, rate=25.0, jitter=0.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(0, duration, 1 / rate) + jitter * rng.uniform(-1, 1, int(np.ceil(duration * rate)))[:len(
        np.arange(0, duration, 1 / rate))]
    t = np.sort(t)
    own = _track(t, 30.0 * t, 0 * t, np.full_like(t, 30.0), 0 * t)
    w, v, R = 0.1, 40.0, 400.0                                   # a right-hand orbit about (0, 0)
    th = w * t
    intr = _track(t + 100.0, -R * np.sin(th), R * np.cos(th) - R, v * np.cos(th), v * np.sin(th))
    return own, intr


def test_bearings_use_the_common_origin_the_offset_and_the_time_offset():
    own, intr = _pair()
    bp = synthesise_pair(own, intr, pair="p", seed=1, offset_m=(2000.0, 500.0), t_offset_s=5.0, duration_s=30.0,
                         rate_hz=10.0, sigma_bearing_deg=0.0)
    t = bp.t_s
    assert np.all(np.diff(t) >= 0.1 - 1e-6) and t[-1] <= 30.0 + 1e-9
    ti = t + 5.0                                               # the intruder's own clock
    n = -400 * np.sin(0.1 * ti) + 2000.0
    e = 400 * np.cos(0.1 * ti) - 400 + 500.0
    np.testing.assert_allclose(bp.intruder_pos, np.column_stack([n, e]), atol=0.05)
    np.testing.assert_allclose(bp.bearing, np.arctan2(e - 0.0, n - 30.0 * t), atol=1e-4)
    np.testing.assert_allclose(bp.truth[:, 2], 40.0, atol=1e-6)
    np.testing.assert_allclose(bp.truth[5:-5, 4], 0.1, atol=2e-3)   # ω = dθ/dt > 0: right turn
    s = bp.bearing_stream()
    assert list(s.columns) == schema.column_names("bearing") and set(s["src"]) == {"synthetic"}


def test_the_bearing_noise_is_seeded_per_pair():
    own, intr = _pair()
    a = synthesise_pair(own, intr, pair="p", seed=1, sigma_bearing_deg=0.2)
    b = synthesise_pair(own, intr, pair="p", seed=1, sigma_bearing_deg=0.2)
    c = synthesise_pair(own, intr, pair="q", seed=1, sigma_bearing_deg=0.2)
    np.testing.assert_array_equal(a.bearing, b.bearing)
    assert not np.allclose(a.bearing, c.bearing)
    assert abs(np.std(a.bearing - a.bearing_true) / np.radians(0.2) - 1) < 0.15


def test_the_scores_read_the_sigma_and_the_range_at_their_times():
    t = np.arange(0, 100.0, 1.0)
    sig = np.radians(np.where(t < 42, 50.0, 10.0))
    sig[50] = np.radians(31)                                   # one excursion: converged after it
    assert heading_converged_s(t, sig) == 51.0
    assert np.isnan(heading_converged_s(t, np.full_like(t, 1.0)))
    assert range_error_pct_at(t, np.full_like(t, 1100.0), np.full_like(t, 1000.0)) == pytest.approx(10.0)
    assert np.isnan(range_error_pct_at(t[:30], t[:30], t[:30] + 1))


@pytest.fixture()
def cfg():
    return {"replay": {"syn": {"ownship": "own", "intruder": "intr", "offset_m": [1500.0, 800.0], "t_offset_s": 0.0,
                               "duration_s": 12.0, "rate_hz": 5.0}}}


def test_a_synthetic_pair_writes_three_estimates_with_weights_and_a_page(tmp_path, cfg, capsys):
    own, intr = _pair(duration=20.0, jitter=0.01)
    write_table(own, tmp_path / "own.parquet", name="state")
    write_table(intr, tmp_path / "intr.parquet", name="state")
    outputs = {e: tmp_path / e / "syn.parquet" for e in ESTIMATORS}
    outputs.update({f"{e}_weights": tmp_path / e / "syn.weights.parquet" for e in ESTIMATORS})
    outputs["page"] = tmp_path / "report" / "bearing" / "syn.html"
    res = run_bearing_replay({"ownship_state": tmp_path / "own.parquet", "intruder_state": tmp_path / "intr.parquet"},
                             outputs, cfg, pair="syn", seed=3)
    assert res.status == "ok"
    err = capsys.readouterr().err
    assert "RESULT bearing_replay_heading_converged_s" in err and "RESULT bearing_replay_range_err_60s_pct" in err
    for e in res.scores:
        df = read_table(outputs[e], schema.BEARING_ESTIMATE)
        assert list(df.columns) == schema.column_names("bearing_estimate")
        assert 45 <= len(df) <= 61 and np.isfinite(df["x_rel_n_m"]).all()
        assert np.all(np.diff(df["t_ns"]) > 0)
        meta = read_table_meta(outputs[e])
        assert meta["status"] == "ok" and meta["track"] == "state" and "bank" in meta
        w = read_table(outputs[f"{e}_weights"], schema.BEARING_WEIGHTS)
        n = w["filter"].nunique()
        np.testing.assert_allclose(w.groupby("t_ns")["weight"].sum(), 1.0, atol=1e-9)
        assert 10 <= w["t_ns"].nunique() <= 13 and n == meta["bank"]["n_filters"]
    assert set(res.scores) == set(ESTIMATORS)
    imm = read_table(outputs["imm"], schema.BEARING_ESTIMATE)
    np.testing.assert_allclose(imm["mode_p_cv"] + imm["mode_p_ct"], 1.0, atol=1e-9)
    assert read_table(outputs["bank_cppv"], schema.BEARING_ESTIMATE)["mode_p_cv"].isna().all()
    assert not outputs["page"].exists()      # the page is the report stage's (pipeline.report.bearing)


def test_a_pair_with_a_missing_flight_is_skipped_with_a_notice(tmp_path, cfg, capsys):
    outputs = {e: tmp_path / e / "syn.parquet" for e in ESTIMATORS}
    outputs.update({f"{e}_weights": tmp_path / e / "syn.weights.parquet" for e in ESTIMATORS})
    outputs["page"] = tmp_path / "syn.html"
    res = run_bearing_replay({"ownship_state": tmp_path / "nope.parquet", "intruder_state": None}, outputs, cfg,
                             pair="syn", seed=0)
    assert res.status == "skipped" and "own (ownship)" in res.reason and "intr (intruder)" in res.reason
    assert "skipping pair syn" in capsys.readouterr().err
    for e in ESTIMATORS:
        assert len(read_table(outputs[e])) == 0 and read_table_meta(outputs[e])["status"] == "skipped"
    assert not outputs["page"].exists()      # the page is the report stage's (pipeline.report.bearing)
