"""The weave classifier on flights (pipeline.estimate.weave_run): the hmpf table, the δ/θ maxima
from training flights' labelled segments, placeholders."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.io import schema
from pipeline.io.parquet import read_table, read_table_meta, write_table
from pipeline.estimate.weave_run import run_hmpf, sample_positions, segment_runs, weave_maxima, weave_noise
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
    # a noise-free ship track is smoother than the configured along-track and turn noise, which
    # stay (and are said); only the ship's near-zero cross-track σ (1.754e-5) is raised, by the
    # interpolation's corners
    assert meta["sigma_at_mps2"] == 2.0 and meta["noise"]["sigma_at_mps2"]["rms"] < 0.01
    assert meta["sigma_axy_mps2"] == 1.0 and 1.754e-5 < meta["sigma_an_mps2"] < 0.05
    assert meta["noise_source"] == "train (sigma_an_mps2), config (the others)"


def test_without_training_flights_the_config_maxima_are_used_and_said(tmp_path):
    tr = weave_track(n_turns=3)
    p_state = tmp_path / "s.parquet"
    write_table(state_of(tr), p_state, schema.STATE, name="state")
    out = tmp_path / "f.parquet"
    res = run_hmpf({"state": str(p_state)}, {"hmpf": str(out)}, {"n_particles": 100}, flight_id="f")
    assert res.diagnostics["delta_max_m"] == 500.0 and "no other role-train flight" in res.diagnostics["maxima_source"]
    assert res.diagnostics["sigma_an_mps2"] == 1.754e-5 and "no other role-train flight" in res.diagnostics["noise_source"]


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
    assert not [t for t, _ in figs if t.startswith("Estimates (")]   # no "not in estimate.vehicles" above it
    assert any(getattr(s, "y0", None) == 0.269 for s in fig.layout.shapes)
    assert facts[-1][0] == "hmpf" and "δ_max 500 m" in facts[-1][1]
    assert "σ_aT/σ_aN/σ_xy 2.00/1.8e-05/1.00 m/s²" in facts[-1][1] and "re-initialised" in facts[-1][1]


def cm_track(sigma_t, sigma_n, n_seg=100, steps=30, speed=60.0, dt=1.0, seed=3):
    """``n_seg`` northbound CM (seed 003 §4.2.2) runs of ``steps`` steps, back to back: the
    piecewise-constant white acceleration has σ_t along and σ_n across the velocity,
    x_{k+1} = F x_k + G w_k with G = [T²/2, T]. Returns the state table and one labelled
    segment per run (short runs keep the speed far from zero)."""
    rng = np.random.default_rng(seed)
    n = n_seg * steps
    p, v = np.zeros((n, 2)), np.zeros((n, 2))
    for k in range(n):
        if k % steps == 0:
            p[k], v[k] = (p[k - 1] + [1000.0, 0.0]) if k else (0.0, 0.0), (speed, 0.0)
            continue
        t = v[k - 1] / np.linalg.norm(v[k - 1])
        w = sigma_t * rng.standard_normal() * t + sigma_n * rng.standard_normal() * np.array([-t[1], t[0]])
        p[k] = p[k - 1] + dt * v[k - 1] + dt * dt / 2 * w
        v[k] = v[k - 1] + dt * w
    df = schema.empty("state").reindex(range(n))
    df["t_ns"] = (np.arange(n) * dt * 1e9).astype(np.int64)
    df["pos_n_m"], df["pos_e_m"], df["gap"] = p[:, 0], p[:, 1], False
    start = df["t_ns"].to_numpy()[::steps]
    seg = pd.DataFrame({"segment_id": np.arange(n_seg), "t_start_ns": start,
                        "t_end_ns": start + int((steps - 1) * dt * 1e9), "label": "s"})
    return df, seg


def test_the_noise_levels_recover_the_white_acceleration_that_drove_a_straight_track():
    # along-track 3 m/s², cross-track 0.3 m/s² at ~60 m/s: a course change of ~0.005 rad/s per
    # step, below the 0.05 rad/s curve threshold, so every transition counts as straight
    st, seg = cm_track(3.0, 0.3)
    sig, diag = weave_noise([st], [seg], 1.0, 0.05)
    assert sig["sigma_at_mps2"] == pytest.approx(3.0, rel=0.06)
    assert sig["sigma_an_mps2"] == pytest.approx(0.3, rel=0.06)
    assert "sigma_axy_mps2" not in sig and diag["sigma_axy_mps2"]["n"] < 10   # no curves: config stays
    assert diag["sigma_at_mps2"]["rms"] == pytest.approx(3.0 / np.sqrt(2), rel=0.06)   # a_k = (w_k + w_k+1)/2


def test_a_flight_is_filtered_with_the_noise_of_the_training_flights_unless_switched_off(tmp_path):
    tr, (st, seg) = weave_track(n_turns=3), cm_track(3.0, 0.3, n_seg=10)
    p_state, p_train, p_seg = tmp_path / "s.parquet", tmp_path / "t.parquet", tmp_path / "g.parquet"
    write_table(state_of(tr), p_state, schema.STATE, name="state")
    write_table(st, p_train, schema.STATE, name="state")
    write_table(seg, p_seg, schema.SEGMENTS, name="segments")
    inp = {"state": str(p_state), "train_states": [str(p_train)], "train_segments": [str(p_seg)]}
    on = run_hmpf(inp, {"hmpf": str(tmp_path / "on.parquet")}, {"n_particles": 100}, flight_id="f")
    off = run_hmpf(inp, {"hmpf": str(tmp_path / "off.parquet")}, {"n_particles": 100, "noise_from_train": False},
                   flight_id="f")
    d = on.diagnostics
    assert d["sigma_at_mps2"] == pytest.approx(3.0, rel=0.2) and d["sigma_axy_mps2"] == 1.0
    assert d["noise_source"].startswith("train (sigma_an_mps2, sigma_at_mps2)")
    assert off.diagnostics["sigma_at_mps2"] == 2.0 and off.diagnostics["noise_source"] == "config"
    assert read_table_meta(tmp_path / "on.parquet")["noise"]["sigma_at_mps2"]["n"] > 200


def test_a_training_flight_without_another_takes_its_noise_from_its_own_segments(tmp_path):
    # fc-p23-036, the one role-train F3A flight: the ship values re-initialised it on 92 of 496
    # steps; its own segments give the airframe's noise, the maxima stay the config's
    st, seg = cm_track(3.0, 0.3, n_seg=10)
    p_state, p_seg = tmp_path / "s.parquet", tmp_path / "g.parquet"
    write_table(st, p_state, schema.STATE, name="state")
    write_table(seg, p_seg, schema.SEGMENTS, name="segments")
    res = run_hmpf({"state": str(p_state), "segments": str(p_seg)}, {"hmpf": str(tmp_path / "f.parquet")},
                   {"n_particles": 100}, flight_id="f")
    d = res.diagnostics
    assert d["sigma_at_mps2"] == pytest.approx(3.0, rel=0.2) and d["sigma_an_mps2"] == pytest.approx(0.3, rel=0.2)
    assert d["noise_source"] == ("own segments (sigma_an_mps2, sigma_at_mps2), config (the others) "
                                 "(no other role-train flight of the vehicle)")
    assert d["delta_max_m"] == 500.0 and "no other role-train flight" in d["maxima_source"]
    # switched off, the config's
    off = run_hmpf({"state": str(p_state), "segments": str(p_seg)}, {"hmpf": str(tmp_path / "o.parquet")},
                   {"n_particles": 100, "noise_from_train": False}, flight_id="f")
    assert off.diagnostics["sigma_at_mps2"] == 2.0 and off.diagnostics["noise_source"] == "config"
