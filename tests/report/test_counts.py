"""Counts on the report pages agree with their noun (report audit): ``1 sample``, ``1 demo``,
``1 flight``, never ``1 samples`` (:func:`pipeline.report.pages.count_text`)."""

from __future__ import annotations

import html
import re

import numpy as np
import pandas as pd


def test_a_count_of_one_takes_the_singular_and_every_other_count_the_plural():
    from pipeline.report.pages import count_text

    assert [count_text(n, "sample") for n in (0, 1, 2, 1.0, np.int64(1))] == \
        ["0 samples", "1 sample", "2 samples", "1 sample", "1 sample"]
    assert count_text(1, "maneuver run") == "1 maneuver run" and count_text(None, "step") == "– steps"
    assert count_text(2, "fix", "fixes") == "2 fixes"


def test_one_lost_record_or_byte_and_one_gps_record_read_in_the_singular():
    from pipeline.report import flight_summary as fs

    assert fs.worst_warning({"diagnostics": {"records_dropped": {"truncated": 1}}}) == \
        "ingest: 1 record dropped (truncated)"
    assert fs.worst_warning({"diagnostics": {"bytes_skipped": 1}}) == "ingest: 1 byte skipped"
    gps = pd.DataFrame({"t_ns": [0], "instance": 0, "fix_type": [3.0], "lat_deg": [1.0], "lon_deg": [1.0]})
    assert fs.gps_fix_share(gps) == "100.0 % of 1 record (3-D fix or better)"


def test_a_one_step_estimate_and_a_one_state_hmm_are_titled_in_the_singular():
    from pipeline.report import plots
    from pipeline.report.model import hmm_figure

    df = pd.DataFrame({"t_ns": [0], "mode": [True], "pred": ["loop"], "V_best": [0.5]})
    assert plots.mode_timeline(df).layout.title.text == "EKF+HMM mode (1 of 1 step with HMM inputs)"
    fig = hmm_figure("loop", np.ones(1), np.ones((1, 1)), np.zeros((1, 2)), ["a", "b"])
    assert fig.layout.title.text == "HMM of loop: 1 state"


def test_the_index_of_one_flight_says_1_flight(tmp_path):
    from pipeline.io.ingest import outputs_for, run_ingest
    from pipeline.report.index import build_index

    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"garbage" * 50)
    run_ingest({"log": bad}, outputs_for(tmp_path / "ingest"), None, flight_id="bad")
    build_index(["bad"], [tmp_path / "ingest" / "meta.json"], tmp_path / "index.html",
                skipped={"gone": "log not found"})
    text = html.unescape((tmp_path / "index.html").read_text())
    assert "<p>1 flight, 1 failed, 1 manifest row skipped.</p>" in text


def test_the_align_page_says_1_demo_for_a_flight_that_gave_one(tmp_path):
    from helpers_align import synthetic_align_page

    text = html.unescape(synthetic_align_page(tmp_path, [(0, 8, "a")], 300))
    facts = re.findall(r"<th>flight f\d</th><td>(.*?)</td>", text)
    assert len(facts) == 2 and all(", 1 demo" in f and "1 demos" not in f for f in facts), facts
    assert "EM convergence (" in text and "of 1 maneuvers" not in text


def test_the_align_pages_left_out_reasons_say_1_sample_and_1_gap_row():
    from helpers_align import synthetic_segments, synthetic_state

    from pipeline.align.demos import flight_demos

    st = synthetic_state(500)
    st.loc[60, "gap"] = True                                  # one gap row at t 2.4 s
    # 0 to 0.1 s holds 3 grid rows (25 Hz), 1 of them at the 3 Hz demo rate
    fd = flight_demos(st, synthetic_segments([(0, 0.1, "a"), (2, 4, "b")]), flight_id="f", sample_hz=3.0)
    assert [d.reason for d in fd.dropped] == ["1 sample in the segment at 3 Hz", "1 gap row inside the segment"]
