"""The FlightCoach F3A study through its entry point, on the real flights of ../shared/realdata.

At ``tiny`` size (5 Baum-Welch iterations, slack grid 1.5) its tables equal what
``benchmarks/study_flightcoach_classification.py --n-iter 5 --slack-grid 1.5`` wrote before
the studies became a stage (goldens in ``tests/data/studies/``); at ``small`` size (the full
study) it meets the acceptance figures the script's test asserted. Both skip when
../shared/realdata is absent (fail under UAVPIPE_REQUIRE_SHARED=1).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
import yaml
from helpers import REALDATA, realdata_file

from pipeline.config import ROOT
from pipeline.studies import STUDY_TABLES, flightcoach_inputs
from pipeline.studies.base import FLIGHTCOACH_DIR, StudyError

NAME = "flightcoach_classification"


def _inputs():
    realdata_file(FLIGHTCOACH_DIR)   # skips, or fails under UAVPIPE_REQUIRE_SHARED=1, when absent
    return flightcoach_inputs(REALDATA)


@pytest.fixture(scope="module")
def tiny(ran, tmp_path_factory):
    inputs = _inputs()
    return ran(NAME, tmp_path_factory.mktemp("fc_tiny"), {"size": "tiny"}, inputs)


@pytest.mark.realdata
@pytest.mark.slow
def test_the_tiny_study_writes_results_report_and_page(tiny):
    assert tiny.result.status == "ok" and tiny.result.diagnostics["size"] == "tiny"
    text = Path(tiny.outputs["results"]).read_text().splitlines()
    assert text and all(line.startswith("RESULT ") and len(line.split()) == 3 for line in text)
    assert tiny.figures == tiny.result.results
    report = Path(tiny.outputs["report"]).read_text()
    assert "P23 #350" in report and "One-class slack sweep" in report
    page = Path(tiny.outputs["page"]).read_text()
    assert 'src="../assets/plotly.min.js"' in page and 'href="../../index.html"' in page
    for metric in tiny.figures:
        row = page[page.index(f"<code>{metric}</code>"):].split("</tr>")[0]
        assert row.count("<td") == 2 and "<td>–</td>" not in row, metric


@pytest.mark.realdata
@pytest.mark.slow
@pytest.mark.parametrize("table", STUDY_TABLES[NAME])
def test_each_table_equals_the_old_script_at_tiny_size(tiny, golden, same_as_golden, table):
    same_as_golden(tiny.table(table), pd.read_parquet(golden / f"{NAME}_tiny" / f"{table}.parquet"))


@pytest.fixture(scope="module")
def full(ran, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fc_small")
    r = ran(NAME, tmp, {"size": "small"}, _inputs())
    return r, pd.read_parquet(tmp / "results" / "studies" / NAME / "oneclass_slack_sweep.parquet"), tmp


@pytest.mark.realdata
@pytest.mark.slow
def test_the_full_study_meets_acceptance(full):
    # the assertions of the former tests/models/test_models_studies.py, at the script's settings
    run, sweep, tmp = full
    r = run.figures
    ok, n = map(int, r["flightcoach_p23_correct_at_segment_end"].split("/"))
    assert n == 17 and ok >= 14                                     # ≥ 80 % of P23 #350
    ok_b, n_b = map(int, r["flightcoach_p23_both_decision_correct_at_segment_end"].split("/"))
    assert ok_b >= 14                                               # same settings as F23
    assert float(r["flightcoach_f23_new_maneuvers_unknown_pct"]) >= 50.0
    assert r["flightcoach_oneclass_slack_source"] == "calibrate"     # slack from P21, not a test flight
    assert {"p21_balanced_pct", "f23_new_unknown_pct"} <= set(sweep.columns)
    assert (tmp / "results" / "studies" / NAME / "p23_timeline.parquet").exists()


@pytest.mark.realdata
@pytest.mark.slow
def test_the_f3a_default_is_calibrated_on_p21_and_keeps_new_f23_maneuvers_unknown(full):
    # issue 13 item 15: the workflow's f3a default (both, slack calibrated on P21 alone)
    run, sweep, _ = full
    r = run.figures
    used = float(r["flightcoach_oneclass_slack_used"])
    row = sweep[sweep["slack_nats_per_sample"] == used]
    assert len(row) == 1 and row["p21_balanced_pct"].iloc[0] == sweep["p21_balanced_pct"].max()
    assert (sweep.loc[sweep["p21_balanced_pct"] == sweep["p21_balanced_pct"].max(), "slack_nats_per_sample"]
            <= used).all()                                          # ties go to the largest slack
    # the impostor-fraction family, calibrated the same way on P21 (ties: the smallest fraction)
    frac = float(r["flightcoach_oneclass_fraction_used"])
    rep = Path(run.outputs["report"]).read_text()
    assert "Impostor-fraction rule (P21 calibration)" in rep and "Rule families" in rep
    fcal = [ln.split("|")[1:3] for ln in rep.split("## Impostor-fraction rule")[1].split("## Rule families")[0]
            .splitlines() if ln.startswith("| ") and not ln.startswith("| fraction")]
    fcal = pd.DataFrame({"f": [float(a) for a, _ in fcal], "b": [float(b) for _, b in fcal]})
    assert frac == pytest.approx(fcal.loc[fcal["b"] == fcal["b"].max(), "f"].min(), abs=1e-3)   # ties: smallest f
    rule = r["flightcoach_default_rule"]
    assert rule == "fraction"                                       # the study's default family
    d_slack, d_frac = (used, 1.0) if rule == "slack" else (0.0, frac)
    assert float(r["flightcoach_default_threshold_slack"]) == pytest.approx(d_slack, abs=1e-3)
    assert float(r["flightcoach_default_threshold_fraction"]) == pytest.approx(d_frac, abs=1e-3)
    models = yaml.safe_load((ROOT / "datasets" / "config.yaml").read_text())["model_sets"]["f3a"]["hmm"]
    assert models["decision"] == r["flightcoach_default_decision"] == "both"
    # the workflow uses the P21-calibrated default rule
    assert models.get("threshold_slack", 0.0) == pytest.approx(d_slack, abs=1e-3)
    assert models.get("threshold_fraction", 1.0) == pytest.approx(d_frac, abs=1e-3)
    unk, n_new = map(int, r["flightcoach_default_f23_new_maneuvers_unknown"].split("/"))
    assert n_new == 14 and unk >= 12                                # issue 13 item 15


@pytest.mark.realdata
@pytest.mark.slow
def test_the_f3a_default_gets_16_of_17_p23_maneuvers_right(full):
    # issue 13 item 15; the slack rule (1.85) gave 15/17, the P21-chosen impostor-fraction rule 17/17
    ok, n = map(int, full[0].figures["flightcoach_default_p23_correct_at_segment_end"].split("/"))
    assert n == 17 and ok >= 16


def test_a_missing_flight_fails_with_one_line_naming_the_file(tmp_path):
    with pytest.raises(StudyError) as e:
        flightcoach_inputs(tmp_path)
    msg = str(e.value)
    assert "\n" not in msg and str(tmp_path / FLIGHTCOACH_DIR) in msg and "not found" in msg


def test_each_family_is_calibrated_to_its_permissive_end():
    from pipeline.studies.flightcoach_classification import calibrated, p21_over_time

    curve = pd.DataFrame({"f": [0.4, 0.5, 0.6, 0.7], "p21_balanced_pct": [50.0, 60.0, 60.0, 55.0]})
    assert calibrated(curve, "f", "min") == 0.5 and calibrated(curve, "f", "max") == 0.6
    seg = pd.DataFrame({"known": [True, True, False], "accepted_pct": [80.0, 40.0, 30.0]})
    assert p21_over_time(seg) == pytest.approx(0.5 * (60.0 + 70.0))


def test_the_calibration_refines_from_the_grid_point_below_to_the_one_above_the_maximisers():
    from pipeline.studies.flightcoach_classification import p21_scores, refine_grid

    fine = refine_grid([0.0, 0.5, 1.0, 1.5, 2.0, 3.0], [50, 50, 57, 57, 54, 40], step=0.25)
    assert fine == [0.75, 1.25, 1.75]                               # [0.5, 2.0] without the coarse points
    assert refine_grid([1.5], [57]) == [] and refine_grid([1.0, 2.0], [1, 2], step=0) == []
    seg = pd.DataFrame({"known": [True, True, False, False, False],
                        "pred_end": ["hB", "unknown", "unknown", "unknown", "loop"]})
    assert p21_scores(seg) == pytest.approx({"known_accepted": 50.0, "unknown_rejected": 200 / 3,
                                             "balanced": 25.0 + 100 / 3})
