"""The seed-000 classification study at ``tiny`` size, through its entry point.

Its tables equal a recorded snapshot (``tests/data/studies/``, made by
``tests/data/studies/make_golden.py``; ``gmr_error`` as a per-maneuver/quantity/axis summary): a
regression check, not an independent one. The snapshot was the pre-stage script's output
(``benchmarks/study_seed000_classification.py --runs 40 --switch-runs 4``, shown equal at commit
28a850e) until the issue "Seed-000 maneuvers as the thesis describes them" changed the simulated
maneuvers on purpose and it was regenerated from the study itself. Correctness rests on the
acceptance figures, which are those the smoke test of the script asserted.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from pipeline.studies import STUDY_TABLES
from pipeline.studies.base import StudyError, study_settings

NAME = "seed000_classification"
#: the EKF-input tables (ekf_input: true; written empty otherwise), newer than the old script's
#: goldens: tested in test_seed000_ekf_input.py
EKF_TABLES = ("ekf_tables", "ekf_switch_tables")


@pytest.fixture(scope="module")
def tiny(ran, tmp_path_factory):
    return ran(NAME, tmp_path_factory.mktemp("seed000"), {"size": "tiny"})


@pytest.mark.slow
def test_the_tiny_study_writes_results_report_and_page(tiny):
    assert tiny.result.status == "ok" and tiny.result.diagnostics["size"] == "tiny"
    text = Path(tiny.outputs["results"]).read_text().splitlines()
    assert text and all(line.startswith("RESULT ") and len(line.split()) == 3 for line in text)
    assert tiny.figures == tiny.result.results
    assert tiny.figures["seed000_runs_per_maneuver"] == "40"
    report = Path(tiny.outputs["report"]).read_text()
    assert "Where our maneuvers differ from the thesis" in report and "M2/M4 confusion" in report
    page = Path(tiny.outputs["page"]).read_text()
    assert 'src="../assets/plotly.min.js"' in page and 'href="../../index.html"' in page
    assert "<table" in page and "seed000_gmr_acc_rmse_mps2" in page and "Plotly.newPlot" in page


@pytest.mark.slow
def test_every_headline_figure_is_defined_in_one_sentence_on_the_page(tiny):
    page = Path(tiny.outputs["page"]).read_text()
    for metric in tiny.figures:
        row = page[page.index(f"<code>{metric}</code>"):].split("</tr>")[0]
        assert row.count("<td") == 2 and "<td>–</td>" not in row, metric


@pytest.mark.slow
@pytest.mark.parametrize("table", [t for t in STUDY_TABLES[NAME] if t not in ("gmr_error", *EKF_TABLES)])
def test_each_table_equals_its_recorded_snapshot_at_tiny_size(tiny, golden, same_as_golden, table):
    same_as_golden(tiny.table(table), pd.read_parquet(golden / f"{NAME}_tiny" / f"{table}.parquet"))


@pytest.mark.slow
def test_the_gmr_error_summary_equals_its_recorded_snapshot_at_tiny_size(tiny, golden, gmr_error_summary,
                                                                        same_as_golden):
    got = gmr_error_summary(tiny.table("gmr_error"))
    same_as_golden(got, pd.read_parquet(golden / f"{NAME}_tiny" / "gmr_error_summary.parquet"))


@pytest.mark.slow
def test_without_ekf_input_the_ekf_tables_are_written_empty_and_marked_skipped(tiny):
    from pipeline.io.parquet import read_table_meta

    for t in EKF_TABLES:
        assert tiny.table(t).empty and read_table_meta(tiny.outputs[t])["skipped"] is True
    assert not [m for m in tiny.figures if m.startswith("seed000_ekf_")]


@pytest.mark.slow
def test_the_tiny_study_meets_the_acceptance_figures_of_the_script_smoke_test(tiny):
    # the assertions of the former tests/models/test_models_studies.py::test_seed000_study_smoke
    r = tiny.figures
    assert float(r["seed000_cf_test_min_FA_pct"]) == 100.0
    assert float(r["seed000_1c_M5_unknown_FA_pct"]) == 100.0          # M5 is the unknown maneuver
    assert float(r["seed000_cf1c_M5_unknown_FA_pct"]) == 100.0
    assert int(r["seed000_gmr_maneuvers_below_fd"]) == 4              # pos_fd GMR beats the FD
    assert float(r["seed000_gmr_acc_rmse_mps2"]) < float(r["seed000_fd_acc_rmse_mps2"])
    assert float(r["seed000_switch_windowed_min_final_MAoT_pct_where_thesis_below_50"]) > 50
    tables = tiny.table("tables_3_1_3_4")
    assert set(tables["table"]) == {"3.1", "3.2", "3.3", "3.4", "3.4+1c", "3.4+bg"}
    assert float(r["seed000_cfbg_M5_unknown_FA_pct"]) == 100.0        # background rival: unknown
    sw = tiny.table("switch_tables")
    assert len(sw) == 3 * 4 * 3 and set(sw["mode"]) == {"cumulative", "windowed", "reset"}
    gerr = tiny.table("gmr_error")
    assert {"maneuver", "axis", "t_s", "mean_err", "err_var"} <= set(gerr.columns)


def test_the_sizes_map_to_the_script_commands():
    assert study_settings({"size": "thesis"}, NAME, *_defaults())[1]["runs"] == 2300
    assert study_settings({"size": "thesis"}, NAME, *_defaults())[1]["switch_runs"] == 243
    assert study_settings({}, NAME, *_defaults())[0] == "small"
    got = study_settings({"size": "small", NAME: {"sizes": {"small": {"runs": 7}}}}, NAME, *_defaults())[1]
    assert got["runs"] == 7 and got["switch_runs"] == 20


def test_a_bad_size_or_key_fails_with_one_line_naming_it():
    from pipeline.config import ConfigError

    with pytest.raises(ConfigError, match=r"studies.size: 'huge'"):
        study_settings({"size": "huge"}, NAME, *_defaults())
    with pytest.raises(ConfigError, match=r"studies.seed000_classification: unknown key\(s\) \['runz'\]"):
        study_settings({NAME: {"runz": 3}}, NAME, *_defaults())
    with pytest.raises(StudyError, match="unknown study"):
        from pipeline.studies import run_study
        run_study("nope", None, {}, {}, seed=1)


def _defaults():
    from pipeline.studies.seed000_classification import DEFAULTS, SIZES

    return DEFAULTS, SIZES


def test_the_gmr_error_panel_draws_each_maneuvers_two_estimates_in_one_colour():

    from pipeline.studies.seed000_classification import figures

    gerr = pd.DataFrame([{"maneuver": m, "quantity": q, "t_s": t, "err_var": 0.25}
                         for m in ("M1", "M2") for q in ("acc", "acc_fd") for t in (0.0, 0.2)])
    tables = pd.DataFrame(columns=["table", "maneuver", "MAoT_pct", "thesis_MAoT_pct"])
    fig = dict(figures(tables, None, gerr))["GMR error over time"]
    colour = {tr.name: (tr.line.color, tr.line.dash) for tr in fig.data}
    assert colour["M1 GMR"][0] == colour["M1 finite difference"][0] != colour["M2 GMR"][0]
    assert colour["M1 finite difference"][1] == "dot" and colour["M1 GMR"][1] is None
    assert fig.layout.yaxis.title.text == "error std, RMS over n/e/d [m/s²]"


def test_each_thesis_value_is_drawn_over_its_own_tables_bar_in_its_colour():
    from pipeline.studies.seed000_classification import figures

    tables = pd.DataFrame([{"table": tb, "maneuver": m, "MAoT_pct": 80.0, "thesis_MAoT_pct": th}
                           for tb, th in (("3.3", 98.0), ("3.4", 97.0), ("3.4+1c", float("nan")))
                           for m in ("M1", "M2")])
    fig = dict(figures(tables, None, None))["Tables 3.1–3.4: MAoT"]
    assert fig.layout.scattermode == "group"
    bars = {tr.offsetgroup: tr.marker.color for tr in fig.data if tr.type == "bar"}
    marks = {tr.offsetgroup: tr.marker.color for tr in fig.data if tr.type == "scatter"}
    assert bars == marks and len(bars) == 3
    assert [tr.showlegend for tr in fig.data if tr.type == "scatter"] == [True, True, False]


def test_the_ekf_input_chart_puts_each_thesis_value_over_its_truth_trained_bar():
    from pipeline.studies.seed000_classification import figures

    et = pd.DataFrame([{"table": tb, "trained_on": tr, "increments": "prior", "maneuver": m, "MAoT_pct": 80.0,
                        "thesis_MAoT_pct": 97.0 if tr == "truth" else float("nan")}
                       for tb in ("3.7", "3.8") for tr in ("truth", "ekf") for m in ("M1", "M2")])
    tables = pd.DataFrame(columns=["table", "maneuver", "MAoT_pct", "thesis_MAoT_pct"])
    fig = dict(figures(tables, None, None, et))["Tables 3.5–3.8: MAoT on EKF input"]
    bars = {tr.offsetgroup: tr.marker.color for tr in fig.data if tr.type == "bar"}
    marks = [(tr.offsetgroup, tr.marker.color, len(tr.x)) for tr in fig.data if tr.type == "scatter"]
    assert [(g, c) for g, c, _ in marks] == list(bars.items())          # one group per bar, same colour
    assert [n for g, _, n in marks] == [2, 0, 2, 0]                      # thesis values: truth-trained only
