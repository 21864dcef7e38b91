"""The particle-filter study at ``tiny`` size through its entry point: every seed-003 trend and
seed-001 geo-location check as a RESULT line, the tables, the report and the page."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.studies import STUDIES, STUDY_TABLES
from pipeline.studies import pf as spf

NAME = "pf"


@pytest.fixture(scope="module")
def tiny(ran, tmp_path_factory):
    return ran(NAME, tmp_path_factory.mktemp("pf"), {"size": "tiny"})


def test_the_study_is_registered_with_its_tables():
    assert STUDIES[NAME] == "pipeline.studies.pf:run_pf"
    assert STUDY_TABLES[NAME] == ("hmpf_runs", "hmpf_timeline", "geo_summary", "geo_series", "geo_config")


@pytest.mark.slow
def test_the_tiny_study_writes_every_trend_as_a_result_line_with_numbers(tiny):
    assert tiny.result.status == "ok" and tiny.result.diagnostics["size"] == "tiny"
    text = Path(tiny.outputs["results"]).read_text().splitlines()
    assert text and all(line.startswith("RESULT ") and len(line.split()) == 3 for line in text)
    f = tiny.figures
    assert f["pf_hmpf_pi_m_stationary"] == "0.7870,0.0278,0.0278,0.1574"
    assert f["pf_hmpf_range_criterion_m"] == "16665"
    for key in ("straight_frac_ge_0.95_seeds", "weave_flagged_within_80_seeds", "straight_never_flagged_seeds",
                "pi_turn_never_flagged_seeds"):
        n, d = f[f"pf_hmpf_{key}"].split("/")
        assert int(d) == 3 and 0 <= int(n) <= 3, key
    assert len(f["pf_hmpf_range_weave_frac"].split(",")) == 4 and len(f["pf_hmpf_quadrant_weave_frac"].split(",")) == 4
    assert float(f["pf_hmpf_radar_weave_pos_rmse_m"]) > 0 and float(f["pf_hmpf_radar_weave_vel_rmse_mps"]) > 0
    met, total = map(int, f["pf_hmpf_trends_met"].split("/"))
    assert total == 10 and 0 <= met <= total


@pytest.mark.slow
def test_the_tables_hold_every_scenario_and_seed(tiny):
    runs, tl = tiny.table("hmpf_runs"), tiny.table("hmpf_timeline")
    scen = set(runs["scenario"])
    assert {"straight_gps", "pi_turn_gps", "weave_gps", "weave_gps_min", "weave_gps_0.8x", "weave_radar",
            "range_10000", "quadrant_4"} <= scen
    assert runs.groupby("scenario").size().eq(3).all()
    np.testing.assert_allclose(tl[[f"mode_p_{m}" for m in "SLRW"]].sum(axis=1), 1.0)
    w = runs[runs["scenario"] == "weave_gps_0.8x"]
    assert np.allclose(w["delta_max_m"], 0.8 * spf.weave_truth_max({**spf.DEFAULTS, **spf.SIZES["tiny"]})[0])


@pytest.mark.slow
def test_the_report_has_both_seed_parts_and_the_page_has_the_panels_of_both_digests(tiny):
    report = Path(tiny.outputs["report"]).read_text()
    assert "## Seed 001: multi-UAV camera geo-location" in report and "Not yet in" not in report
    assert "| check | measured | target | met |" in report and "geo_eta_base_met" in report
    page = Path(tiny.outputs["page"]).read_text()
    # 5 seed-003 panels (digest 003 §11 item 7) + 5 seed-001 panels (digest 001 §13 item 5)
    assert 'src="../assets/plotly.min.js"' in page and page.count("Plotly.newPlot") >= 10
    for metric in tiny.figures:
        row = page[page.index(f"<code>{metric}</code>"):].split("</tr>")[0]
        assert row.count("<td") == 2 and "<td>–</td>" not in row, metric


@pytest.mark.slow
def test_the_seed_001_part_writes_its_checks_and_the_config_values_fixed_before_the_runs(tiny):
    f = tiny.figures
    for key in ("geo_eta_pct_base", "geo_eta_pct_maneuvering", "geo_eta_base_met", "geo_eta_maneuvering_met",
                "geo_obs_1_to_2_met", "geo_particles_10_vs_80_met", "geo_sigma_px"):
        assert key in f, key
    assert float(f["geo_sigma_px"]) == pytest.approx(800 * np.tan(0.3), abs=0.01)
    summ, cfg = tiny.table("geo_summary"), tiny.table("geo_config")
    assert {"base", "maneuvering", "mobile", "particles_10", "observers_2"} <= set(summ["case"])
    assert {"focal_px", "sigma_px"} <= set(cfg["key"])
