"""The bearing-only replay's page (pipeline/report/bearing.py, results/report/bearing/<pair>.html):
the report pages' template with a back link to the index, English, readable estimator names and
numbers, a titled time axis on every panel, the course unwrapped through south and ±1σ bands
from each estimate's covariance."""

from __future__ import annotations

import html
import re

import numpy as np
import pandas as pd
import pytest

from pipeline.estimate.bearing_run import ESTIMATORS
from pipeline.io import schema
from pipeline.io.parquet import read_table, write_table
from pipeline.report import bearing
from pipeline.report.bearing import run_bearing_report


def _track(t, n, e, vn, ve):
    return pd.DataFrame({"t_ns": np.round(np.asarray(t) * 1e9).astype(np.int64), "pos_n_m": n, "pos_e_m": e,
                         "vel_n_mps": vn, "vel_e_mps": ve})


@pytest.fixture(scope="module")
def replay(tmp_path_factory):
    """A replay whose intruder turns through south (course +180° -> -180°): its page (under a
    results-like tree), the figures it drew, the written tables."""
    tmp = tmp_path_factory.mktemp("bearing")
    t = np.arange(0, 16.0, 0.1)
    th = 2.6 + 0.1 * t                                          # course 149° -> 241°: through 180°
    own = _track(t, 30.0 * t, 0 * t, np.full_like(t, 30.0), 0 * t)
    intr = _track(t, 400 * np.sin(th), -400 * np.cos(th), 40 * np.cos(th), 40 * np.sin(th))
    write_table(own, tmp / "own.parquet", name="state")
    write_table(intr, tmp / "intr.parquet", name="state")
    res = tmp / "results"
    out = {e: res / "estimate" / e / "syn.parquet" for e in ESTIMATORS}
    out.update({f"{e}_weights": res / "estimate" / e / "syn.weights.parquet" for e in ESTIMATORS})
    out["page"] = res / "report" / "bearing" / "syn.html"
    cfg = {"replay": {"syn": {"ownship": "own", "intruder": "intr", "offset_m": [3000.0, 0.0],
                              "duration_s": 15.0, "rate_hz": 5.0}}}
    figs = {}
    real = bearing.figure_divs
    mp = pytest.MonkeyPatch()
    mp.setattr(bearing, "figure_divs", lambda fs: (figs.update(dict(fs)), real(fs))[1])
    try:
        result = run_bearing_report({"ownship_state": tmp / "own.parquet", "intruder_state": tmp / "intr.parquet",
                                     "plotly": res / "report" / "assets" / "plotly.min.js"}, out, cfg,
                                    pair="syn", seed=1)
    finally:
        mp.undo()
    return {"page": out["page"].read_text(), "figs": figs, "result": result,
            "tables": {e: read_table(out[e], schema.BEARING_ESTIMATE) for e in ESTIMATORS}}


def _visible(page: str) -> str:
    """The page's text outside its scripts."""
    return html.unescape(re.sub(r"<script.*?</script>", "", page, flags=re.S))


def test_the_bearing_page_is_english_links_back_to_the_index_and_uses_the_report_template(replay):
    page = replay["page"]
    assert replay["result"].status == "ok"
    assert page.lower().startswith("<!doctype html>\n<html lang=\"en\">")
    assert '<a href="../../index.html">' in page                    # results/report/bearing/ -> results/
    assert "font-family:system-ui" in page and "uavpipePlots" in page  # the pages' CSS and plot loader
    assert '<script defer src="../assets/plotly.min.js">' in page


def test_the_bearing_page_names_its_estimators_and_writes_the_offset_as_a_vector(replay):
    text = _visible(replay["page"])
    assert "intruder offset" in text and "(3000, 0) m" in text and "3000.0" not in text
    for raw in ESTIMATORS:
        assert raw not in text, raw
    for name in ("CPPV bank", "MPC bank", "CV/CT IMM"):
        assert name in text, name
    names = {tr.name for _, f in replay["figs"].items() if f is not None for tr in f.data}
    assert {"CPPV bank", "MPC bank", "CV/CT IMM", "truth"} <= names and not names & set(ESTIMATORS)


def test_every_bearing_panel_titles_its_time_axis(replay):
    assert replay["page"].count('"t since the first bearing [s]"') == 6   # in the page's six figures
    drawn = [f for f in replay["figs"].values() if f is not None]
    assert len(drawn) == 6
    for f in drawn:
        assert f.layout.xaxis.title.text == "t since the first bearing [s]"
        assert f.layout.yaxis.title.text


def test_the_course_is_unwrapped_through_south_and_each_estimate_is_drawn_on_the_truths_turn(replay):
    fig = next(f for t, f in replay["figs"].items() if t.startswith("Course"))
    lines = {tr.name: np.asarray(tr.y, float) for tr in fig.data if tr.fill is None and "σ" not in tr.name}
    truth = lines["truth"]
    assert truth.max() > 200 and np.abs(np.diff(truth)).max() < 10   # past 180°, no 360° jump
    for e in ("CPPV bank", "MPC bank", "CV/CT IMM"):
        y = lines[e][np.isfinite(lines[e])]
        assert np.abs(np.diff(y)).max() < 180, e
        d = lines[e] - truth
        assert abs(np.nanmedian(d)) <= 180, e                        # drawn on the truth's turn


def test_the_bands_are_one_sigma_of_each_estimates_covariance_as_its_table_holds_it(replay):
    fig = next(f for t, f in replay["figs"].items() if t.startswith("Range"))
    for e, name in (("bank_cppv", "CPPV bank"), ("imm", "CV/CT IMM")):
        hi = next(np.asarray(tr.y, float) for tr in fig.data if tr.name == f"{name} +1σ")
        lo = next(np.asarray(tr.y, float) for tr in fig.data if tr.name == f"{name} ±1σ")
        table = replay["tables"][e]
        np.testing.assert_allclose(hi - table["range_m"], table["range_sigma_m"], rtol=1e-9)
        np.testing.assert_allclose(lo, np.maximum(table["range_m"] - table["range_sigma_m"], 0.0), rtol=1e-9)
    course = next(f for t, f in replay["figs"].items() if t.startswith("Course"))
    hi = next(np.asarray(tr.y, float) for tr in course.data if tr.name == "CPPV bank +1σ")
    lo = next(np.asarray(tr.y, float) for tr in course.data if tr.name == "CPPV bank ±1σ")
    np.testing.assert_allclose((hi - lo) / 2, np.degrees(np.sqrt(replay["tables"]["bank_cppv"]["P_3_3"])),
                               rtol=1e-9)


def test_a_skipped_pair_says_why_on_a_page_that_still_links_back(tmp_path):
    out = {e: tmp_path / e / "syn.parquet" for e in ESTIMATORS}
    out.update({f"{e}_weights": tmp_path / e / "syn.weights.parquet" for e in ESTIMATORS})
    out["page"] = tmp_path / "report" / "bearing" / "syn.html"
    cfg = {"replay": {"syn": {"ownship": "own", "intruder": "intr", "offset_m": [1500.0, -250.5]}}}
    res = run_bearing_report({"ownship_state": tmp_path / "nope.parquet", "intruder_state": None}, out, cfg,
                             pair="syn", seed=0)
    page = out["page"].read_text()
    assert res.status == "skipped"
    assert "Skipped: flight(s) own (ownship), intr (intruder) not available" in html.unescape(page)
    assert '<html lang="en">' in page and '<a href="../../index.html">' in page
    assert "(1500, -250.5) m" in html.unescape(page)


def test_the_course_error_panel_is_each_estimate_minus_the_truth_wrapped_to_180_degrees(replay):
    def lines(title):
        fig = replay["figs"][title]
        return {tr.name: np.asarray(tr.y, float) for tr in fig.data if tr.fill is None and "σ" not in tr.name}

    course = lines(next(t for t in replay["figs"] if t.startswith("Course (")))
    err = lines("Course error")
    for e in ("CPPV bank", "MPC bank", "CV/CT IMM"):
        # whole turns between the two unwrapped lines vanish in the wrapped difference
        expect = (course[e] - course["truth"] + 180.0) % 360.0 - 180.0
        drawn = err[e][np.isfinite(err[e])]           # the holes at ±180° wraps are extra rows
        np.testing.assert_allclose(drawn, expect[np.isfinite(expect)], atol=1e-6)
        assert np.nanmax(np.abs(err[e])) <= 180.0
        jumps = np.abs(np.diff(err[e]))
        assert not (jumps[np.isfinite(jumps)] > 180.0).any()     # never a stroke across the panel


def test_the_range_axis_is_scaled_to_the_truth_and_most_estimates_not_a_banks_first_seconds(replay):
    fig = next(f for t, f in replay["figs"].items() if t.startswith("Range"))
    truth = next(np.asarray(tr.y, float) for tr in fig.data if tr.name == "truth")
    est = np.concatenate([np.asarray(tr.y, float) for tr in fig.data
                          if tr.name in ("CPPV bank", "MPC bank", "CV/CT IMM")])
    lo, hi = fig.layout.yaxis.range
    assert lo == 0.0 and hi == pytest.approx(1.2 * max(truth.max(), np.percentile(est[np.isfinite(est)], 95)))


def test_a_band_with_holes_is_one_closed_outline_per_run_not_edges_joined_across_the_holes():
    import plotly.graph_objects as go

    from pipeline.report.bearing import _band

    fig = go.Figure()
    t = np.arange(7.0)
    mean = np.array([0.0, 1.0, np.nan, 2.0, 3.0, 4.0, np.nan])
    _band(fig, t, mean, np.full(7, 0.5), "x", "#1f77b4")
    (tr,) = fig.data
    assert tr.fill == "toself" and tr.name == "x ±1σ"
    assert list(tr.x) == [0, 1, 1, 0, None, 3, 4, 5, 5, 4, 3, None]
    assert list(tr.y) == [0.5, 1.5, 0.5, -0.5, None, 2.5, 3.5, 4.5, 3.5, 2.5, 1.5, None]
