"""``uavpipe align``: the align stage from the command line (stand-in learner: the CLI's own work)."""

from __future__ import annotations


import numpy as np
from helpers_align import synthetic_segments, synthetic_state, write_flight

import pipeline.align.run as align_run
from pipeline.cli import main
from pipeline.io import schema
from pipeline.io.parquet import read_table, write_table



class _Stand:
    def fit(self, demos):
        T = int(round(2 * np.mean([len(d) for d in demos])))
        self.tau_ = [np.round(np.arange(len(d)) * (T - 1) / (len(d) - 1)).astype(int) for d in demos]
        self.mean_, self.var_ = np.zeros((T, 13)), np.ones((T, 13))
        self.d_, self.loglik_ = np.full((len(demos), 3), 1 / 3), [-2.0, -1.0]
        return self


def test_uavpipe_align_writes_the_four_tables_and_the_page(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(align_run, "make_learner", lambda config, dt: _Stand())
    seg = synthetic_segments([(0, 8, "a"), (8, 16, "b")])
    p = [write_flight(tmp_path, f, synthetic_state(500, seed=k), seg, 0.1) for k, f in enumerate(("fc-p23-036", "fc-p23-350"))]
    rc = main(["align", "--state", p[0][0], p[1][0], "--segments", p[0][1], p[1][1], "--set", "p23",
               "-o", str(tmp_path / "out"), "--page", str(tmp_path / "page" / "p23.html")])
    assert rc == 0
    assert "set p23 -> " in capsys.readouterr().out
    assert (tmp_path / "page" / "p23.html").stat().st_size > 1000
    out = {k: read_table(tmp_path / "out" / f"{k}.parquet") for k in ("learned", "alignment", "iterations", "demos")}
    flights = ("fc-p23-036", "fc-p23-350")
    # each 8 s segment resampled every 0.32 s: n = 25 samples per demo, one demo per flight and
    # maneuver; the stand-in learns T = 2n = 50 steps and reports len(loglik_) = 2 iterations
    n, T = 25, 50
    learned = out["learned"]
    assert learned.groupby("maneuver", observed=True).size().to_dict() == {"a": T, "b": T}
    assert learned["t"].tolist() == list(range(T)) * 2
    for k in ("alignment", "demos"):
        t = out[k]
        sizes = t.groupby(["maneuver", "flight_id", "demo"], observed=True).size().to_dict()
        assert sizes == {(m, f, f"{f}:{m}#1"): n for m in "ab" for f in flights}, k
        assert t["j"].tolist() == list(range(n)) * 4, k
        # the stand-in's warp, j -> round(j (T - 1) / (n - 1)), carried to both tables
        assert t["tau"].tolist() == [round(j * (T - 1) / (n - 1)) for j in range(n)] * 4, k
    assert set(out["alignment"]["status"]) == {"used"}
    it = out["iterations"]
    assert it[["maneuver", "iteration", "loglik", "n_demos"]].values.tolist() == \
        [["a", 0, -2.0, 2], ["a", 1, -1.0, 2], ["b", 0, -2.0, 2], ["b", 1, -1.0, 2]]
    assert set(it["status"]) == {"ok"}


def test_uavpipe_align_names_an_unknown_set_in_one_line(tmp_path, capsys):
    rc = main(["align", "--state", "x.parquet", "--segments", "x.parquet", "--set", "nope", "-o", str(tmp_path)])
    assert rc == 2
    assert capsys.readouterr().err.strip() == "uavpipe align: --set nope: not an align.sets entry (p23, p21)"


def _cli_layout(root, flight, state, segments, *, flight_id=True):
    """``uavpipe preprocess``'s layout: ``root/<flight>/{state,segments}.parquet``."""
    meta = {"flight_id": flight} if flight_id else {}
    sp, gp = root / flight / "state.parquet", root / flight / "segments.parquet"
    write_table(state, sp, schema.STATE, name="state", extra={**meta, "preprocess": {"status": "ok"}})
    write_table(segments, gp, schema.SEGMENTS, name="segments", extra=meta)
    return str(sp), str(gp)


def test_uavpipe_align_reads_what_uavpipe_preprocess_writes(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(align_run, "make_learner", lambda config, dt: _Stand())
    seg = synthetic_segments([(0, 8, "a"), (8, 16, "b")])
    p = [_cli_layout(tmp_path / "pp", f, synthetic_state(500, seed=k), seg)
         for k, f in enumerate(("fc-p23-036", "fc-p23-350"))]
    # every file is state.parquet or segments.parquet; the segments listed in the other order
    rc = main(["align", "--state", p[0][0], p[1][0], "--segments", p[1][1], p[0][1], "--set", "p23",
               "-o", str(tmp_path / "out")])
    assert rc == 0, capsys.readouterr().err
    demos = read_table(tmp_path / "out" / "demos.parquet")
    assert set(demos["flight_id"]) == {"fc-p23-036", "fc-p23-350"}


def test_a_tables_flight_is_its_metadata_else_its_folder_for_a_generic_name_else_its_stem(tmp_path):
    st, seg = synthetic_state(10), synthetic_segments([(0, 0.2, "a")])
    _cli_layout(tmp_path / "renamed", "f1", st, seg)
    (tmp_path / "renamed" / "f1").rename(tmp_path / "renamed" / "x")   # the metadata wins over the folder
    without = _cli_layout(tmp_path / "pp", "f2", st, seg, flight_id=False)  # an older state table
    workflow = write_flight(tmp_path, "f3", st, seg)                        # results/state/<flight>.parquet
    assert align_run.table_flight_id(tmp_path / "renamed" / "x" / "state.parquet") == "f1"
    assert [align_run.table_flight_id(p) for p in without] == ["f2", "f2"]
    assert [align_run.table_flight_id(p) for p in workflow] == ["f3", "f3"]
    assert align_run.table_flight_id(tmp_path / "gone" / "f4.parquet") == "f4"   # unreadable: its name


def test_uavpipe_align_names_state_and_segments_of_different_flights(tmp_path, capsys):
    st, seg = synthetic_state(10), synthetic_segments([(0, 0.2, "a")])
    a = _cli_layout(tmp_path, "fc-p23-036", st, seg)
    b = _cli_layout(tmp_path, "fc-p23-350", st, seg)
    rc = main(["align", "--state", a[0], "--segments", b[1], "--set", "p23", "-o", str(tmp_path / "o")])
    assert rc == 2
    assert capsys.readouterr().err.strip() == ("uavpipe align: --state and --segments name different flights "
                                               "(fc-p23-036 vs fc-p23-350)")
    rc = main(["align", "--state", a[0], a[0], "--segments", a[1], b[1], "--set", "p23", "-o", str(tmp_path / "o")])
    assert rc == 2
    assert capsys.readouterr().err.strip() == f"uavpipe align: --state: {a[0]} and {a[0]} are both flight fc-p23-036"
    assert not (tmp_path / "o").exists()
