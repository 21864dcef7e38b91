"""The weave classifier on flights (pipeline.estimate.weave_run): the hmpf table, the δ/θ maxima
from training flights' labelled segments, placeholders."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.io import schema
from pipeline.io.parquet import read_table, read_table_meta, write_table
from pipeline.estimate.weave_run import run_hmpf, sample_positions, segment_runs, weave_maxima
from pipeline.simulate.ship import weave_track


def state_of(track, rate_hz=5.0, speed_scale=1.0):
    """A state table sampled at rate_hz from a 1-s ship track (linear interpolation)."""
    t = np.arange(0, track.t_s[-1] + 1e-9, 1 / rate_hz)
    d = {"t_ns": (t * 1e9).astype(np.int64)}
    for c, i in (("pos_n_m", 0), ("pos_e_m", 1)):
        d[c] = np.interp(t, track.t_s, track.state[:, i]) * speed_scale
    df = schema.empty("state").reindex(range(len(t)))
    for c, v in d.items():
        df[c] = v
    df["gap"] = False
    return schema.conform("state", df) if hasattr(schema, "conform") else df


def test_the_maxima_are_the_longest_straight_and_the_largest_turn_of_the_labelled_segments():
    tr = weave_track(n_turns=4, turn_steps=15, straight_steps=20, lead=30, tail=30)
    st = state_of(tr)
    seg = pd.DataFrame({"segment_id": [0], "t_start_ns": [0], "t_end_ns": [int(tr.t_s[-1] * 1e9)], "label": ["w"]})
    dm, tm, diag = weave_maxima([st], [seg], 1.0, 0.05)
    assert dm == pytest.approx(30 * np.sqrt(2), rel=0.08)   # the 30-step lead/tail straights
    assert tm == pytest.approx(1.5, rel=0.1)                # 15 steps at 0.1 rad/s
    assert diag["n_turns"] == 4 and diag["n_segments"] == 1
    tk, z = sample_positions(st, 1.0)
    s_, t_ = segment_runs(tk, z, 1.0, 0.05)
    assert len(t_) == 4 and max(s_) == pytest.approx(dm)


def test_a_flight_gets_its_hmpf_table_with_maxima_from_the_training_flight(tmp_path):
    tr = weave_track(n_turns=3)
    p_state, p_train, p_seg = tmp_path / "s.parquet", tmp_path / "t.parquet", tmp_path / "g.parquet"
    write_table(state_of(tr), p_state, schema.STATE, name="state")
    write_table(state_of(tr), p_train, schema.STATE, name="state")
    write_table(pd.DataFrame({"segment_id": [0], "t_start_ns": [0], "t_end_ns": [int(1e12)], "label": ["w"]}),
                p_seg, schema.SEGMENTS, name="segments")
    out = tmp_path / "hmpf" / "f.parquet"
    res = run_hmpf({"state": str(p_state), "train_states": [str(p_train)], "train_segments": [str(p_seg)]},
                   {"hmpf": str(out)}, {"n_particles": 200}, flight_id="f", seed=1)
    assert res.status == "ok"
    df, meta = read_table(out, schema.HMPF), read_table_meta(out)
    assert list(df.columns) == [c.name for c in schema.HMPF] and len(df) == tr.n_steps
    np.testing.assert_allclose(df[[f"mode_p_{m}" for m in "SLRW"]].sum(axis=1), 1.0)
    # the default weave: 80-step tail straight at √2 m/s, 12-step turns at 0.1 rad/s
    assert meta["maxima_source"] == "train" and meta["delta_max_m"] == pytest.approx(80 * np.sqrt(2), rel=0.05)
    assert meta["theta_max_rad"] == pytest.approx(1.2, rel=0.1)
    assert not df["weave_detected"][:25].any()


def test_without_training_flights_the_config_maxima_are_used_and_said(tmp_path):
    tr = weave_track(n_turns=3)
    p_state = tmp_path / "s.parquet"
    write_table(state_of(tr), p_state, schema.STATE, name="state")
    out = tmp_path / "f.parquet"
    res = run_hmpf({"state": str(p_state)}, {"hmpf": str(out)}, {"n_particles": 100}, flight_id="f")
    assert res.diagnostics["delta_max_m"] == 500.0 and "no other role-train flight" in res.diagnostics["maxima_source"]


def test_a_flight_without_positions_gets_a_placeholder_with_the_reason(tmp_path):
    st = schema.empty("state")
    p = tmp_path / "s.parquet"
    write_table(st, p, schema.STATE, name="state")
    out = tmp_path / "f.parquet"
    res = run_hmpf({"state": str(p)}, {"hmpf": str(out)}, {}, flight_id="empty")
    assert res.status == "failed" and "positions" in res.error
    assert len(read_table(out)) == 0 and read_table_meta(out)["status"] == "failed"


def test_the_flight_page_shows_the_weave_af_with_the_tau_line(tmp_path):
    from pipeline.report.flight import estimate_panels
    tr = weave_track(n_turns=3)
    p_state = tmp_path / "s.parquet"
    write_table(state_of(tr), p_state, schema.STATE, name="state")
    out = tmp_path / "hmpf" / "f.parquet"
    run_hmpf({"state": str(p_state)}, {"hmpf": str(out)}, {"n_particles": 100}, flight_id="f")
    figs, facts = estimate_panels({"hmpf": str(out)}, truth=None, state=None)
    title, fig = figs[-1]
    assert title == "Weave classifier AF(k)" and fig is not None
    assert any(getattr(s, "y0", None) == 0.269 for s in fig.layout.shapes)
    assert facts[-1][0] == "hmpf" and "δ_max 500 m" in facts[-1][1]
