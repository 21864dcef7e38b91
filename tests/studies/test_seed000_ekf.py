"""The seed-000 estimation study at ``tiny`` size, through its entry point: q tuned and frozen,
the EKF/RTS Monte Carlo tables, the EKF+HMM S1/S2 tables, the RESULT lines and the page."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from pipeline.config import ConfigError
from pipeline.studies import STUDIES, STUDY_TABLES
from pipeline.studies import seed000_ekf as s0e
from pipeline.studies.base import study_settings

NAME = "seed000_ekf"
SCHEMA = Path(__file__).resolve().parents[2] / "rules" / "schemas" / "config.schema.yaml"


@pytest.fixture(scope="module")
def tiny(ran, tmp_path_factory):
    return ran(NAME, tmp_path_factory.mktemp("seed000_ekf"), {"size": "tiny"})


@pytest.mark.slow
def test_the_tiny_study_writes_results_report_page_and_every_table(tiny):
    assert tiny.result.status == "ok" and tiny.result.diagnostics["size"] == "tiny"
    text = Path(tiny.outputs["results"]).read_text().splitlines()
    assert text and all(line.startswith("RESULT ") and len(line.split()) == 3 for line in text)
    assert tiny.figures == tiny.result.results
    for t in STUDY_TABLES[NAME]:
        assert len(tiny.table(t)), t
    report = Path(tiny.outputs["report"]).read_text()
    assert "tuned on training runs and frozen" in report and "Acceptance (targets ours)" in report
    page = Path(tiny.outputs["page"]).read_text()
    assert 'src="../assets/plotly.min.js"' in page and "Plotly.newPlot" in page
    for metric in tiny.figures:  # each headline figure defined in one sentence on the page
        row = page[page.index(f"<code>{metric}</code>"):].split("</tr>")[0]
        assert row.count("<td") == 2 and "<td>–</td>" not in row, metric


@pytest.mark.slow
def test_q_is_the_grid_value_with_the_lowest_training_score(tiny):
    qt = tiny.table("q_tuning")
    q = float(tiny.figures["seed000_ekf_q_tuned"])
    assert q == qt.loc[qt["score"].idxmin(), "q"] and qt["chosen"].sum() == 1
    assert list(qt["q"]) == s0e.DEFAULTS["q_grid"]
    q2 = tiny.table("q2_tuning")
    assert float(tiny.figures["seed000_ekf_hmm_q2_scale"]) == q2.loc[q2["score"].idxmin(), "q2_scale"]


@pytest.mark.slow
def test_the_monte_carlo_tables_hold_every_maneuver_filter_and_component(tiny):
    mt, ms = tiny.table("mc_time"), tiny.table("mc_rmse")
    assert list(ms["maneuver"]) == ["M1", "M2", "M3", "M4", "M5"] and set(ms["n_runs"]) == {10}
    assert set(mt["filter"]) == {"ekf", "rts"} and mt["component"].nunique() == 9
    assert np.all(mt["err_var"] >= 0) and np.all(mt["filter_var"] > 0)
    # the smoother lowers every group's RMSE on every maneuver
    for g in ("pos_m", "vel_mps", "acc_mps2"):
        assert np.all(ms[f"rts_rmse_{g}"] < ms[f"ekf_rmse_{g}"]), g
    # the band is the two-sided 95 % band of chi2(9 N)/N for the N runs averaged, scipy's own
    # quantiles; the NEES mean and the in-band share are recomputed from the per-time table
    from scipy.stats import chi2

    from pipeline.estimate.models import STATE_COLUMNS

    for r in ms.itertuples():
        n = int(r.n_runs)
        lo, hi = chi2.ppf(0.025, 9 * n) / n, chi2.ppf(0.975, 9 * n) / n
        assert (r.nees_band_lo, r.nees_band_hi) == pytest.approx((lo, hi), rel=1e-12), r.maneuver
        got = {}
        for f in ("ekf", "rts"):
            g = mt[(mt["maneuver"] == r.maneuver) & (mt["filter"] == f)]
            # one run-averaged NEES per step, repeated on the step's nine component rows
            assert (g.groupby("t_s")["nees_avg"].nunique(dropna=False) == 1).all(), (r.maneuver, f)
            step = g[g["component"] == STATE_COLUMNS[0]].sort_values("t_s")["nees_avg"].to_numpy()
            assert len(step) == r.n_steps and len(g) == 9 * r.n_steps, (r.maneuver, f)
            got[f] = float(np.mean(step)), 100.0 * float(np.mean((step >= lo) & (step <= hi)))
            assert getattr(r, f"{f}_nees_mean") == pytest.approx(got[f][0], rel=1e-12), (r.maneuver, f)
            assert getattr(r, f"{f}_nees_in_band_pct") == pytest.approx(got[f][1], abs=1e-9), (r.maneuver, f)
        # the RESULT lines print the EKF's two, to 2 and 1 decimals
        assert float(tiny.figures[f"seed000_ekf_mc_{r.maneuver}_ekf_nees_mean"]) == pytest.approx(
            got["ekf"][0], abs=0.005 + 1e-9)
        assert float(tiny.figures[f"seed000_ekf_mc_{r.maneuver}_ekf_nees_in_band_pct"]) == pytest.approx(
            got["ekf"][1], abs=0.05 + 1e-9)


@pytest.mark.slow
def test_s1_and_s2_are_the_best_and_worst_test_runs_and_both_filters_are_scored(tiny):
    sc, hr = tiny.table("scenarios"), tiny.table("hmm_rmse")
    assert len(sc) == 8 and set(sc["scenario"]) == {"S1", "S2"}
    piv = sc.pivot(index="maneuver", columns="scenario", values="summed_abs_error")
    assert np.all(piv["S1"] <= piv["S2"])
    assert list(sc["thesis_MAoT_pct"][:2]) == [94.79, 70.27]
    assert len(hr) == 16 and set(hr["filter"]) == {"ekf", "ekf_hmm"}
    assert {"pos_m", "vel_n_mps", "vel_e_mps", "vel_d_mps", "acc_mps2"} <= set(hr.columns)
    for m in ("M1", "M2", "M3", "M4"):
        for s in ("S1", "S2"):
            assert f"seed000_ekf_hmm_{m}_{s}_acc_rmse_change_pct" in tiny.figures


def test_the_study_is_registered_with_its_tables_sizes_and_schema_defaults():
    assert STUDIES[NAME].endswith(":run_seed000_ekf")
    assert STUDY_TABLES[NAME] == s0e.OUTPUT_TABLES
    assert study_settings({"size": "thesis"}, NAME, s0e.DEFAULTS, s0e.SIZES)[1]["mc_runs"] == 1000
    sec = yaml.safe_load(SCHEMA.read_text())["properties"]["studies"]["properties"][NAME]["properties"]
    for key, value in s0e.DEFAULTS.items():
        if key in sec:
            assert sec[key].get("default") == value, key
    for size, over in s0e.SIZES.items():
        assert {k: v.get("default") for k, v in sec["sizes"]["properties"][size]["properties"].items()} == over


def test_a_bad_setting_is_refused_in_one_line(tmp_path):
    with pytest.raises(ConfigError, match=r"studies.seed000_ekf.skip: unknown part"):
        s0e.run_seed000_ekf(None, s0e.outputs_for(str(tmp_path)), {"size": "tiny", NAME: {"skip": ["mc"]}}, seed=1)
    with pytest.raises(ConfigError, match=r"studies.seed000_ekf.mc_maneuvers: unknown maneuver"):
        s0e.run_seed000_ekf(None, s0e.outputs_for(str(tmp_path)), {"size": "tiny", NAME: {"mc_maneuvers": ["M9"]}},
                            seed=1)
    with pytest.raises(ConfigError, match=r"studies.seed000_ekf.increments: 'predicted' is not one of prior, posterior"):
        s0e.run_seed000_ekf(None, s0e.outputs_for(str(tmp_path)), {"size": "tiny", NAME: {"increments": "predicted"}},
                            seed=1)


def test_pooled_rmse_equals_one_rmse_over_all_samples(rng):
    a, b = rng.normal(size=(3, 50, 9)), rng.normal(size=(2, 80, 9)) * 2
    ra = np.sqrt(np.mean(a ** 2, axis=(0, 1)))[None]
    rb = np.sqrt(np.mean(b ** 2, axis=(0, 1)))[None]
    both = np.sqrt(np.mean(np.concatenate([a.reshape(-1, 9), b.reshape(-1, 9)]) ** 2, axis=0))
    np.testing.assert_allclose(s0e.pooled_rmse([(ra, 150), (rb, 160)])[0], both, rtol=1e-12)


@pytest.mark.slow
def test_the_target_plans_only_the_study_and_plotly_js():
    import os
    import re
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[2]
    p = subprocess.run([str(Path(sys.executable).parent / "snakemake"), "--cores", "2", "-n", "--forceall",
                        "study_seed000_ekf"], cwd=root, capture_output=True, text=True, timeout=300,
                       env={**os.environ, "PYTHONWARNINGS": "ignore"})
    out = p.stdout + p.stderr
    assert p.returncode == 0, out[-3000:]
    m = re.search(r"Job stats:\njob\s+count\n[- ]+\n(.*?)\ntotal", out, re.S)
    assert m, out[-3000:]
    jobs = {r.split()[0]: int(r.split()[1]) for r in m.group(1).strip().splitlines()}
    assert jobs == {"plotly_js": 1, "study_seed000_ekf": 1}


def test_the_monte_carlo_panels_put_each_unit_on_its_own_axis_and_each_filter_in_one_colour():
    from pipeline.estimate.models import STATE_COLUMNS
    from pipeline.studies.seed000_ekf import figures

    t = np.arange(3) * 0.2
    mc = pd.DataFrame([{"maneuver": "M1", "filter": f, "component": c, "t_s": tt, "err_var": 0.04,
                        "filter_var": 0.09, "nees_avg": 9.0} for f in ("ekf", "rts") for c in STATE_COLUMNS for tt in t])
    figs = dict(figures(pd.DataFrame({"q": [0.1, 1.0, 10.0], "score": [1.2, 1.0, 1.1]}), mc))
    fig = figs["MC M1"]
    assert [a.text for a in fig.layout.annotations] == ["position [m]", "velocity [m/s]", "acceleration [m/s²]"]
    assert {tr.yaxis for tr in fig.data} == {"y", "y2", "y3"}          # never two units on one axis
    colour = {tr.name: set() for tr in fig.data}
    for tr in fig.data:
        colour[tr.name].add(tr.line.color)
    assert sorted(colour) == ["EKF error std", "EKF filter std", "RTS error std", "RTS filter std"]
    assert colour["EKF error std"] == colour["EKF filter std"] != colour["RTS error std"]
    np.testing.assert_allclose(fig.data[0].y, 0.2)
