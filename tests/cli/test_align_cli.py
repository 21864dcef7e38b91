"""``uavpipe align``: the align stage from the command line (stand-in learner: the CLI's own work)."""

from __future__ import annotations


import numpy as np
from helpers_align import synthetic_segments, synthetic_state, write_flight

import pipeline.align.run as align_run
from pipeline.cli import main
from pipeline.io.parquet import read_table



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
    assert set(read_table(tmp_path / "out" / "learned.parquet")["maneuver"]) == {"a", "b"}
    assert (tmp_path / "page" / "p23.html").stat().st_size > 1000


def test_uavpipe_align_names_an_unknown_set_in_one_line(tmp_path, capsys):
    rc = main(["align", "--state", "x.parquet", "--segments", "x.parquet", "--set", "nope", "-o", str(tmp_path)])
    assert rc == 2
    assert capsys.readouterr().err.strip() == "uavpipe align: --set nope: not an align.sets entry (p23, p21)"
