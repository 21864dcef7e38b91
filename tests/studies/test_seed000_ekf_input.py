"""The seed-000 classification study with ``ekf_input: true`` at ``tiny`` size: Tables 3.5–3.8
and 3.13–3.15 on EKF estimates, truth- and EKF-trained, beside the thesis values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.io.parquet import read_table_meta
from pipeline.models.metrics import THESIS_EKF, THESIS_SWITCH_EKF

NAME = "seed000_classification"
pytestmark = pytest.mark.slow   # the tiny study plus the EKF part: about a minute on 2 cores


@pytest.fixture(scope="module")
def tiny_ekf(ran, tmp_path_factory):
    return ran(NAME, tmp_path_factory.mktemp("seed000ekf"), {"size": "tiny", NAME: {"ekf_input": True}})


def test_tables_3_5_to_3_8_are_written_for_truth_and_ekf_trained_models_beside_the_thesis(tiny_ekf):
    et = tiny_ekf.table("ekf_tables")
    assert set(et["table"]) == {"3.5", "3.6", "3.7", "3.8", "3.8+bg"} and set(et["trained_on"]) == {"truth", "ekf"}
    # the printed (4.1) increments (default, the headline) beside the digest's: both trainings, every table
    assert set(et["increments"]) == {"posterior", "prior"}
    pr, post = et[et.increments == "prior"], et[et.increments == "posterior"]
    assert set(pr["trained_on"]) == set(post["trained_on"]) == {"truth", "ekf"}
    assert set(pr["table"]) == set(post["table"]) == set(et["table"])
    assert len(pr) == len(post) and (pr["n_runs"].to_numpy() == post["n_runs"].to_numpy()).all()
    assert tiny_ekf.figures["seed000_ekf_increments"] == "prior"
    for r in et.itertuples():
        if r.table in THESIS_EKF:
            assert (r.thesis_FA_pct, r.thesis_MAoT_pct) == THESIS_EKF[r.table][r.maneuver]
        else:                                               # ours (background rival): no thesis value
            assert np.isnan(r.thesis_FA_pct) and np.isnan(r.thesis_MAoT_pct)
    assert set(et[et.split == "test"]["maneuver"]) == {"M1", "M2", "M3", "M4", "M5"}   # M5 reported
    assert et["n_runs"].gt(0).all() and et["MAoT_pct"].between(0, 100).all()
    assert et["MAoT_after_5s_pct"].between(0, 100).all()      # ours: without the EKF's first 5 s
    meta = read_table_meta(tiny_ekf.outputs["ekf_tables"])
    assert meta["q"] == 3.0 and meta["runs_per_maneuver"] == 40


def test_tables_3_13_to_3_15_cover_every_cell_in_both_modes_and_both_trainings(tiny_ekf):
    sw = tiny_ekf.table("ekf_switch_tables")
    assert len(sw) == 12 * 2 * 2
    assert set(sw["mode"]) == {"cumulative", "windowed"} and set(sw["table"]) == {"3.13", "3.14", "3.15"}
    r = sw[(sw.scenario == "D") & (sw.switch_s == 3.0)].iloc[0]
    assert r.thesis_FA_initial_pct == THESIS_SWITCH_EKF[(3, "D")][0]
    assert sw["n_runs"].eq(4).all()


def test_the_noise_aware_gain_is_the_ekf_trained_minus_the_truth_trained_mean_on_each_reading(tiny_ekf):
    # the issue's target (gain >= 0) is a thesis-size study figure: met on the posterior increments
    # (+21.1), missed by 1.6 points on the printed ones (README "Estimators: measured results")
    r, et = tiny_ekf.figures, tiny_ekf.table("ekf_tables")
    t8 = et[(et.table == "3.8") & et.maneuver.isin(["M1", "M2", "M3", "M4"])]
    mean = t8.groupby(["increments", "trained_on"])["MAoT_pct"].mean()
    assert float(r["seed000_ekf_cf_test_mean_MAoT_ekf_trained_pct"]) == pytest.approx(mean["prior", "ekf"], abs=0.006)
    assert float(r["seed000_ekf_cf_test_mean_MAoT_truth_trained_pct"]) == pytest.approx(mean["prior", "truth"], abs=0.006)
    assert float(r["seed000_ekf_cf_test_mean_MAoT_gain_pct"]) == pytest.approx(
        mean["prior", "ekf"] - mean["prior", "truth"], abs=0.011)
    assert float(r["seed000_ekf_other_cf_test_mean_MAoT_gain_pct"]) == pytest.approx(
        mean["posterior", "ekf"] - mean["posterior", "truth"], abs=0.011)
    for k in ("seed000_ekf_cf_min_FA_pct", "seed000_ekf_cf_min_MAoT_minus_thesis_pct", "seed000_ekf_cf_M5_unknown_FA_pct",
              "seed000_ekf_switch_cumulative_truth_trained_mean_final_MAoT_pct",
              "seed000_ekf_switch_windowed_ekf_trained_mean_final_MAoT_pct"):
        assert np.isfinite(float(r[k])), k


def test_the_ekf_section_and_figures_are_on_the_report_and_the_page(tiny_ekf):
    report = Path(tiny_ekf.outputs["report"]).read_text()
    assert "EKF input: Tables 3.5–3.8" in report and "Tables 3.13–3.15" in report
    assert "Diagnosis: the other reading of (4.1), `increments: posterior`" in report
    for man in ("M1", "M2", "M3", "M4", "M5"):
        assert 0 <= float(tiny_ekf.figures[f"seed000_ekf_other_cf_test_{man}_MAoT_pct"]) <= 100
    page = Path(tiny_ekf.outputs["page"]).read_text()
    for metric in (m for m in tiny_ekf.figures if m.startswith("seed000_ekf_")):
        row = page[page.index(f"<code>{metric}</code>"):].split("</tr>")[0]
        assert row.count("<td") == 2 and "<td>–</td>" not in row, metric
    assert "Tables 3.5\\u20133.8: MAoT on EKF" in page and page.count("Plotly.newPlot") == 4   # JSON-escaped title
