"""The align stage entry point (pipeline.align.run.run_align): tables, box frames, bad input.

Most tests put a stand-in learner behind :func:`pipeline.align.run.make_learner` (the tables and
the bookkeeping do not depend on the EM); one runs the real learner when it is installed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers_align import synthetic_segments, synthetic_state, write_flight

import pipeline.align.run as align_run
from pipeline.align.demos import DEMO_COLUMNS
from pipeline.io import schema
from pipeline.io.parquet import read_table, read_table_meta, write_table


class StandInLearner:
    """Linear-stretch 'learner': τ_j = round(j (T-1)/(N-1)), μ = the demos' mean on that axis."""

    def __init__(self, dt):
        self.dt = dt

    def fit(self, demos):
        T = int(round(2 * np.mean([len(d) for d in demos])))
        self.tau_ = [np.round(np.arange(len(d)) * (T - 1) / (len(d) - 1)).astype(int) for d in demos]
        acc = np.zeros((T, 13))
        cnt = np.zeros((T, 1))
        for d, tau in zip(demos, self.tau_):
            acc[tau] += d
            cnt[tau] += 1
        self.mean_ = np.array([np.interp(np.arange(T), np.flatnonzero(cnt[:, 0]), acc[cnt[:, 0] > 0, k]
                                         / cnt[cnt[:, 0] > 0, 0]) for k in range(13)]).T
        self.var_ = np.ones((T, 13))
        self.d_ = np.full((len(demos), 3), 1 / 3)
        self.loglik_ = np.array([-100.0, -50.0, -49.0])
        self.sigma_z_ = np.stack([np.eye(13) * (k + 1) for k in range(3)])
        self.sigma_y_ = np.eye(13)
        self.beta_ = np.zeros((T - 1, 13))
        self.model_error_ = np.zeros((T - 1, 13))
        self.n_iter_, self.converged_ = 2, True
        return self


@pytest.fixture
def stand_in(monkeypatch):
    monkeypatch.setattr(align_run, "make_learner", lambda config, dt: StandInLearner(dt))


def _config(sets, **kw):
    return {"window_C": 20, "max_iter": 5, "tol": 1e-6, "ridge": 1.0, "dynamics": "kinematic", "sample_hz": 5.0,
            "min_demos": 2, "exclude": ["tkOf"], "csv_fit": {"sample_hz": 1.0, "headings": 12, "iterations": 30},
            "sets": sets, **kw}


def _outputs(tmp_path):
    return {k: str(tmp_path / "align" / "s" / f"{k}.parquet") for k in align_run.ALIGN_OUTPUTS}


def _inputs(paths):
    return {"states": [p[0] for p in paths], "segments": [p[1] for p in paths]}


def _two_flights(tmp_path, *, gap=False):
    seg = synthetic_segments([(0, 4, "tkOf"), (4, 12, "a"), (12, 20, "b"), (20, 26, "a"), (26, 30, "solo")])
    psi1, psi2 = np.radians(30.0), np.radians(-100.0)
    st2 = synthetic_state(800, heading_rad=psi2, seed=2)
    if gap:
        st2.loc[400:401, "gap"] = True  # t 16 s: inside f2's segment b
    seg2 = seg[seg["label"] != "solo"]
    return [write_flight(tmp_path, "f1", synthetic_state(800, heading_rad=psi1, seed=1), seg, psi1),
            write_flight(tmp_path, "f2", st2, seg2, psi2)]


def test_every_maneuver_becomes_rows_of_the_four_declared_tables(tmp_path, stand_in):
    out = _outputs(tmp_path)
    res = align_run.run_align(_inputs(_two_flights(tmp_path)), out, _config({"s": {"flights": ["f1", "f2"]}}),
                              set_name="s")
    assert res.status == "partial"  # 'solo' has one demo
    learned = read_table(out["learned"], schema.ALIGN_LEARNED)
    assert list(learned.columns) == [c.name for c in schema.ALIGN_LEARNED]
    # 'a' is flown twice in each flight: two figures, one maneuver per occurrence
    assert set(learned["maneuver"]) == {"a#1", "a#2", "b"}
    al = read_table(out["alignment"], schema.ALIGN_ALIGNMENT)
    used = al[al["status"] == "used"]
    assert sorted(used["demo"].unique()) == ["f1:a#1", "f1:a#2", "f1:b#1", "f2:a#1", "f2:a#2", "f2:b#1"]
    assert (used.groupby("demo")["tau"].first() == 0).all()
    it = read_table(out["iterations"], schema.ALIGN_ITERATIONS)
    ok = it[it["status"] == "ok"]
    assert list(ok[ok["maneuver"] == "a#2"]["iteration"]) == [0, 1, 2]
    np.testing.assert_allclose(ok[ok["maneuver"] == "a#2"]["sigma_z_pos_n_m"], [1.0, 2.0, 3.0])
    assert sorted(used[used["maneuver"] == "a#2"]["demo"].unique()) == ["f1:a#2", "f2:a#2"]
    dm = read_table(out["demos"], schema.ALIGN_DEMOS)
    assert len(dm) == len(used)
    assert read_table_meta(out["learned"])["align"]["maneuvers"]["a#1"]["n_demos"] == 2
    # align.repeats: pool keeps every 'a' in one maneuver
    pooled = _outputs(tmp_path / "pool")
    align_run.run_align(_inputs(_two_flights(tmp_path)), pooled,
                        _config({"s": {"flights": ["f1", "f2"]}}, repeats="pool"), set_name="s")
    assert set(read_table(pooled["learned"])["maneuver"]) == {"a", "b"}
    assert read_table_meta(pooled["learned"])["align"]["maneuvers"]["a"]["n_demos"] == 4


def test_demos_of_flights_in_differently_rotated_boxes_coincide_in_the_box_frame(tmp_path, stand_in):
    out = _outputs(tmp_path)
    align_run.run_align(_inputs(_two_flights(tmp_path)), out, _config({"s": {"flights": ["f1", "f2"]}}),
                        set_name="s")
    dm = read_table(out["demos"], schema.ALIGN_DEMOS)
    b = dm[dm["maneuver"] == "b"]
    y1 = b[b["flight_id"] == "f1"]["pos_e_m"].to_numpy()
    y2 = b[b["flight_id"] == "f2"]["pos_e_m"].to_numpy()
    # box y = 5 sin(0.2 t) in both flights although their boxes point 130 deg apart
    np.testing.assert_allclose(y1, y2, atol=1e-6)
    al = read_table(out["alignment"], schema.ALIGN_ALIGNMENT)
    assert set(al[al["flight_id"] == "f2"]["frame"]) == {"box"}
    np.testing.assert_allclose(al[al["flight_id"] == "f2"]["heading_rad"].iloc[0], np.radians(-100.0))


def test_a_maneuver_with_fewer_than_two_demos_is_skipped_with_the_reason(tmp_path, stand_in):
    out = _outputs(tmp_path)
    align_run.run_align(_inputs(_two_flights(tmp_path)), out, _config({"s": {"flights": ["f1", "f2"]}}),
                        set_name="s")
    it = read_table(out["iterations"], schema.ALIGN_ITERATIONS)
    solo = it[it["maneuver"] == "solo"]
    assert list(solo["status"]) == ["skipped"] and list(solo["iteration"]) == [-1]
    assert solo["reason"].iloc[0] == "1 usable demo(s) (< align.min_demos = 2)"
    al = read_table(out["alignment"], schema.ALIGN_ALIGNMENT)
    assert list(al[al["maneuver"] == "solo"]["status"]) == ["skipped"]


def test_a_demo_with_gap_rows_is_dropped_and_its_maneuver_learned_without_it(tmp_path, stand_in, capsys):
    out = _outputs(tmp_path)
    align_run.run_align(_inputs(_two_flights(tmp_path, gap=True)), out,
                        _config({"s": {"flights": ["f1", "f2"]}}), set_name="s")
    al = read_table(out["alignment"], schema.ALIGN_ALIGNMENT)
    row = al[al["demo"] == "f2:b#1"]
    assert list(row["status"]) == ["dropped"] and row["reason"].iloc[0] == "2 gap rows inside the segment"
    # said per flight, naming it: the maneuver's "skipped (1 usable demo(s))" does not
    assert "set s: f2: 1 demo(s) dropped, first f2:b#1: 2 gap rows inside the segment" in capsys.readouterr().err
    it = read_table(out["iterations"], schema.ALIGN_ITERATIONS)
    assert it[it["maneuver"] == "b"]["status"].iloc[0] == "skipped"  # one demo of b left


def test_a_missing_flight_is_skipped_with_a_notice(tmp_path, stand_in, capsys):
    out = _outputs(tmp_path)
    res = align_run.run_align(_inputs(_two_flights(tmp_path)), out,
                              _config({"s": {"flights": ["f1", "f2", "gone"]}}), set_name="s")
    assert "set s: flight gone missing (no state/segments input): skipped" in capsys.readouterr().err
    assert res.diagnostics["notices"] == ["set s: flight gone missing (no state/segments input): skipped"]
    al = read_table(out["alignment"], schema.ALIGN_ALIGNMENT)
    assert al[al["flight_id"] == "gone"]["reason"].tolist() == ["flight missing"]
    assert set(read_table(out["learned"])["maneuver"]) == {"a#1", "a#2", "b"}


def test_an_input_flight_the_set_does_not_list_is_ignored_with_a_notice(tmp_path, stand_in, capsys):
    out = _outputs(tmp_path)
    res = align_run.run_align(_inputs(_two_flights(tmp_path)), out, _config({"s": {"flights": ["f1"]}}),
                              set_name="s")
    msg = "set s: input flight f2 is not a flight of the set (f1): ignored"
    assert msg in capsys.readouterr().err and res.diagnostics["notices"][0] == msg
    assert set(read_table(out["demos"], schema.ALIGN_DEMOS)["flight_id"]) <= {"f1"}


def test_a_set_with_nothing_to_learn_writes_empty_tables_with_the_reason(tmp_path, stand_in):
    out = _outputs(tmp_path)
    paths = _two_flights(tmp_path)[:1]
    res = align_run.run_align(_inputs(paths), out, _config({"s": {"flights": ["f1"]}}, min_demos=3), set_name="s")
    assert res.status == "failed" and "no maneuver learned" in res.error
    for k in align_run.ALIGN_OUTPUTS:
        assert read_table_meta(out[k])["status"] == "failed"
    assert len(read_table(out["learned"])) == 0


def test_the_real_learner_fits_a_synthetic_set_and_its_likelihood_rises(tmp_path):
    out = _outputs(tmp_path)
    res = align_run.run_align(_inputs(_two_flights(tmp_path)), out,
                              _config({"s": {"flights": ["f1", "f2"]}}, max_iter=3, sample_hz=2.5), set_name="s")
    assert res.diagnostics["maneuvers"]["a#1"]["status"] == "ok"
    it = read_table(out["iterations"], schema.ALIGN_ITERATIONS)
    a = it[it["maneuver"] == "a#1"]["loglik"].to_numpy()
    assert a[-1] > a[0]
    learned = read_table(out["learned"], schema.ALIGN_LEARNED)
    assert np.isfinite(learned[[f"mu_{c}" for c in DEMO_COLUMNS]].to_numpy()).all()


def test_a_demo_the_tau_steps_cannot_stretch_is_dropped_with_the_reason():
    from pipeline.align.demos import Demo

    def demo(name, n):
        return Demo(name, "f", "a", 0, np.arange(n, dtype=np.int64), np.zeros((n, 13)))

    keep, out = align_run.stretchable([demo("x", 100), demo("y", 110), demo("z", 20)])
    # T = round(2 * 76.7) = 153: z's 19 steps of at most 3 reach only 57
    assert [d.name for d in keep] == ["x", "y"]
    assert [d.name for d, _ in out] == ["z"]
    assert out[0][1].startswith("20 samples against a median of 100: τ steps of 1-3 cannot place it on the T = 153")


def test_the_same_set_learned_twice_gives_the_same_bytes(tmp_path):
    flights = _inputs(_two_flights(tmp_path))
    cfg = _config({"s": {"flights": ["f1", "f2"]}}, max_iter=2, sample_hz=2.5)
    a, b = _outputs(tmp_path / "a"), _outputs(tmp_path / "b")
    align_run.run_align(flights, a, cfg, set_name="s")
    align_run.run_align(flights, b, cfg, set_name="s")
    for k in a:  # metadata included: run times are said, not stored
        assert Path(a[k]).read_bytes() == Path(b[k]).read_bytes(), k


# --- flights that cannot be used: dropped with one line, the others go on ---------------------------

def _failed_flight(root: Path, flight: str, error: str) -> tuple[str, str]:
    """A flight whose ingest failed, preprocessed by the stage itself: its placeholder ``state``
    and ``segments`` (empty, ``status: failed`` and ``error`` at the top of their metadata)."""
    from pipeline.preprocess.run import run_preprocess

    meta = root / "ingest" / flight / "meta.json"
    meta.parent.mkdir(parents=True)
    meta.write_text(f'{{"flight_id": "{flight}", "status": "failed", "error": "{error}"}}')
    out = {"state": root / "state" / f"{flight}.parquet", "segments": root / "segments" / f"{flight}.parquet",
           "calibration": root / "calibration" / f"{flight}.parquet", "info": root / "state" / f"{flight}.json"}
    res = run_preprocess({"meta": str(meta)}, {k: str(v) for k, v in out.items()})
    assert res.status == "failed" and read_table_meta(out["state"])["status"] == "failed"
    return str(out["state"]), str(out["segments"])


def _box_less_flight(root: Path, flight: str = "f3") -> tuple[str, str]:
    seg = synthetic_segments([(0, 4, "tkOf"), (4, 12, "a"), (12, 20, "b"), (20, 26, "a")])
    return write_flight(root, flight, synthetic_state(800, seed=3), seg)  # no box rotation: NED


def test_a_flight_whose_preprocessing_failed_is_dropped_with_its_error_and_the_others_kept(tmp_path, stand_in):
    paths = [*_two_flights(tmp_path), _failed_flight(tmp_path, "bad", "no GPS fix")]
    cfg = _config({"s": {"flights": ["f1", "f2", "bad"]}})
    ds = align_run.load_demo_set(_inputs(paths), cfg, "s")
    assert [(d.name, d.reason) for d in ds.dropped if d.flight_id == "bad"] == [
        ("bad:", "preprocessing failed: ingest failed: no GPS fix")]
    assert "set s: flight bad: preprocessing failed: ingest failed: no GPS fix: skipped" in ds.notices
    out = _outputs(tmp_path)
    res = align_run.run_align(_inputs(paths), out, cfg, set_name="s")
    al = read_table(out["alignment"], schema.ALIGN_ALIGNMENT)
    bad = al[al["flight_id"] == "bad"]
    assert bad["status"].tolist() == ["dropped"]
    assert bad["reason"].tolist() == ["preprocessing failed: ingest failed: no GPS fix"]
    assert set(read_table(out["learned"])["maneuver"]) == {"a#1", "a#2", "b"}
    assert res.diagnostics["n_dropped"] == 1 and set(res.diagnostics["flights"]) == {"f1", "f2"}


def test_a_preprocess_error_that_already_says_preprocessing_failed_is_not_said_twice(tmp_path, stand_in):
    # the placeholder of a flight whose preprocessing raised (pipeline.preprocess.run): its error
    # starts "preprocessing failed: ", at the top of the state and segments metadata
    extra = {"flight_id": "bad", "status": "failed", "error": "preprocessing failed: time span 0 s"}
    sp, gp = tmp_path / "state" / "bad.parquet", tmp_path / "segments" / "bad.parquet"
    write_table(schema.empty("state"), sp, schema.STATE, name="state", extra=extra)
    write_table(schema.empty("segments"), gp, schema.SEGMENTS, name="segments", extra=extra)
    ds = align_run.load_demo_set(_inputs([*_two_flights(tmp_path), (str(sp), str(gp))]),
                                 _config({"s": {"flights": ["f1", "f2", "bad"]}}), "s")
    assert [d.reason for d in ds.dropped if d.flight_id == "bad"] == ["preprocessing failed: time span 0 s"]


def test_a_failed_reference_flight_leaves_the_box_less_flights_in_ned_with_a_notice(tmp_path, stand_in):
    paths = [*_two_flights(tmp_path), _box_less_flight(tmp_path), _failed_flight(tmp_path, "ref", "no GPS fix")]
    out = _outputs(tmp_path)
    res = align_run.run_align(_inputs(paths), out,
                              _config({"s": {"flights": ["f1", "f2", "f3", "ref"], "reference": "ref"}}),
                              set_name="s")
    assert "set s: reference ref not available: box-less flights stay in NED" in res.diagnostics["notices"]
    assert res.diagnostics["flights"]["f3"]["frame"] == "ned"
    al = read_table(out["alignment"], schema.ALIGN_ALIGNMENT)
    assert al[al["flight_id"] == "ref"]["reason"].tolist() == ["preprocessing failed: ingest failed: no GPS fix"]
    used = al[al["status"] == "used"]
    assert set(used["flight_id"]) == {"f1", "f2", "f3"}
    assert set(used[used["flight_id"] == "f3"]["frame"]) == {"ned"}


def test_a_reference_whose_demos_cannot_be_cut_is_dropped_and_the_box_less_flights_stay_in_ned(tmp_path,
                                                                                                 stand_in):
    seg = synthetic_segments([(0, 4, "tkOf"), (4, 12, "a"), (12, 20, "b")])
    sp, gp = write_flight(tmp_path, "ref", synthetic_state(600, seed=4), seg, 0.2)
    # a state table without pos_n_m (a foreign or older file): readable, but no demos in it
    cols = tuple(c for c in schema.STATE if c.name != "pos_n_m")
    write_table(synthetic_state(600, seed=4), sp, cols, name="state",
                extra={"flight_id": "ref", "preprocess": {"status": "ok"}, "box_rotation_rad": 0.2})
    paths = [*_two_flights(tmp_path), _box_less_flight(tmp_path), (sp, gp)]
    ds = align_run.load_demo_set(_inputs(paths), _config({"s": {"flights": ["f1", "f2", "f3", "ref"],
                                                                "reference": "ref"}}), "s")
    (drop,) = [d for d in ds.dropped if d.flight_id == "ref"]
    assert drop.reason.startswith(f"cannot cut the demos of {sp}: KeyError:") and "\n" not in drop.reason
    assert "set s: reference ref failed: box-less flights stay in NED" in ds.notices
    assert ds.flights["f3"]["frame"] == "ned" and set(ds.flights) == {"f1", "f2", "f3"}
    assert {d.flight_id for demos in ds.maneuvers.values() for d in demos} == {"f1", "f2", "f3"}


def test_a_box_less_flight_whose_fit_to_the_reference_fails_is_dropped_and_the_others_kept(tmp_path, stand_in):
    seg = synthetic_segments([(0, 4, "tkOf"), (4, 12, "a"), (12, 20, "b"), (20, 26, "a")])
    st = synthetic_state(800, heading_rad=np.radians(30.0), seed=1)
    st[["pos_n_m", "pos_e_m", "pos_d_m"]] = np.nan  # no position to fit to (its own demos: dropped, said)
    f2 = _two_flights(tmp_path)[1]  # (its f1 is overwritten below)
    paths = [write_flight(tmp_path, "f1", st, seg, np.radians(30.0)), f2, _box_less_flight(tmp_path)]
    ds = align_run.load_demo_set(_inputs(paths), _config({"s": {"flights": ["f1", "f2", "f3"],
                                                                "reference": "f1"}}), "s")
    (drop,) = [d for d in ds.dropped if d.flight_id == "f3"]
    assert drop.name == "f3:" and drop.reason.startswith("fit to reference f1 failed: ValueError:")
    assert "\n" not in drop.reason
    assert any(n.startswith("set s: flight f3: fit to reference f1 failed") for n in ds.notices)
    assert {d.flight_id for demos in ds.maneuvers.values() for d in demos} == {"f2"}


def test_an_unreadable_state_file_is_dropped_with_a_reason_naming_the_file(tmp_path, stand_in):
    paths = _two_flights(tmp_path)
    paths.append(write_flight(tmp_path, "f3", synthetic_state(800, seed=3), synthetic_segments([(4, 12, "a")]), 0.0))
    Path(paths[2][0]).write_bytes(b"\x00garbage, not Parquet\xff" * 8)
    out = _outputs(tmp_path)
    res = align_run.run_align(_inputs(paths), out, _config({"s": {"flights": ["f1", "f2", "f3"]}}), set_name="s")
    al = read_table(out["alignment"], schema.ALIGN_ALIGNMENT)
    (reason,) = al[al["flight_id"] == "f3"]["reason"].tolist()
    assert reason.startswith(f"cannot read {paths[2][0]}: ArrowInvalid:") and "\n" not in reason
    assert set(read_table(out["learned"])["maneuver"]) == {"a#1", "a#2", "b"}
    assert set(res.diagnostics["flights"]) == {"f1", "f2"}


def test_an_unreadable_segments_file_is_dropped_with_a_reason_naming_the_file(tmp_path, stand_in):
    paths = _two_flights(tmp_path)
    Path(paths[1][1]).write_bytes(b"not Parquet")
    ds = align_run.load_demo_set(_inputs(paths), _config({"s": {"flights": ["f1", "f2"]}}), "s")
    (drop,) = [d for d in ds.dropped if d.flight_id == "f2"]
    assert drop.reason.startswith(f"cannot read {paths[1][1]}: ") and set(ds.flights) == {"f1"}


def test_a_learner_error_of_any_kind_skips_its_maneuver_with_the_error_on_one_line(tmp_path, monkeypatch):
    class Broken:
        def fit(self, demos):
            raise IndexError("index 7 is out of bounds\nfor axis 0")

    monkeypatch.setattr(align_run, "make_learner", lambda config, dt: Broken())
    out = _outputs(tmp_path)
    res = align_run.run_align(_inputs(_two_flights(tmp_path)), out, _config({"s": {"flights": ["f1", "f2"]}}),
                              set_name="s")
    assert res.status == "failed"
    reason = res.diagnostics["maneuvers"]["b"]["reason"]
    assert reason.startswith("fit failed: IndexError: index 7 is out of bounds for axis 0 (at test_run.py:")
