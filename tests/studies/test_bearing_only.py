"""The bearing-only study: the paired sign test against scipy's exact binomial test, and the
whole study at ``tiny`` size through its entry point (tables, trends, RESULT lines, page)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.stats import binomtest

from pipeline.config import ConfigError
from pipeline.studies import STUDIES, STUDY_TABLES, run_study, study_outputs
from pipeline.studies import bearing_only as bo

NAME = "bearing_only"
TRENDS = ("nr25", "cppv_range", "mpc_heading", "delta_1e2_worse", "delta_over_td", "faster_ownship")


@pytest.mark.parametrize("n_better,n_worse,n_tie", [(9, 1, 0), (14, 11, 3), (3, 17, 2), (25, 0, 5), (0, 0, 4)])
def test_the_sign_test_equals_the_exact_one_sided_binomial_test(n_better, n_worse, n_tie, rng):
    a = np.concatenate([np.zeros(n_better), np.ones(n_worse), np.full(n_tie, 0.5)])
    b = np.concatenate([np.ones(n_better), np.zeros(n_worse), np.full(n_tie, 0.5)])
    b = b + 0.1 * rng.standard_normal(len(b)) * 0          # exact ties stay ties
    perm = rng.permutation(len(a))
    t = bo.sign_test(a[perm], b[perm])
    n = n_better + n_worse
    assert t["n"] == n and t["n_better"] == n_better
    if n:
        assert t["p"] == pytest.approx(binomtest(n_better, n, 0.5, alternative="greater").pvalue, rel=1e-12)
        assert t["frac_better"] == pytest.approx(n_better / n)
    else:
        assert np.isnan(t["p"])


def test_the_sign_test_drops_nan_pairs_and_reports_the_median_improvement():
    a = np.array([1.0, 2.0, np.nan, 0.5, 3.0])
    b = np.array([2.0, 4.0, 1.0, np.nan, 2.0])
    t = bo.sign_test(a, b)
    assert t["n"] == 3 and t["n_better"] == 2 and t["median_effect"] == pytest.approx(1.0)


def test_an_unknown_part_is_one_clear_error(tmp_path):
    with pytest.raises(ConfigError, match="unknown part"):
        run_study(NAME, None, study_outputs(NAME, results_dir=tmp_path, models=False),
                  {"size": "tiny", NAME: {"parts": ["loops"]}}, seed=1, estimate={})


@pytest.fixture(scope="module")
def tiny(ran, tmp_path_factory):
    return ran(NAME, tmp_path_factory.mktemp("bearing_only"), {"size": "tiny"}, estimate={})


@pytest.mark.slow
def test_the_tiny_study_writes_results_report_page_and_every_table(tiny):
    assert NAME in STUDIES and tiny.result.status == "ok" and tiny.result.diagnostics["size"] == "tiny"
    text = Path(tiny.outputs["results"]).read_text().splitlines()
    assert text and all(line.startswith("RESULT ") and len(line.split()) == 3 for line in text)
    for name in TRENDS:
        assert f"bearing_trend_{name}_p" in tiny.figures, name
    for key in ("bearing_crlb_ratio_r", "bearing_crlb_ratio_v", "bearing_crlb_ratio_omega",
                "bearing_imm_switch_detected_pct", "bearing_trends_held"):
        assert key in tiny.figures
    for t in STUDY_TABLES[NAME]:
        assert len(tiny.table(t)), t
    page = Path(tiny.outputs["page"]).read_text()
    assert 'src="../assets/plotly.min.js"' in page and "Plotly.newPlot" in page
    for title in ("Table 4.2 parameterisations", "CPPV vs MPC", "sqrt(CRLB)", "mu_CV(t)", "Study 3 single runs"):
        assert title in page
    report = Path(tiny.outputs["report"]).read_text()
    assert "mean relative absolute error" in report and "paired one-sided sign tests" in report


@pytest.mark.slow
def test_every_trend_is_the_larger_p_of_its_paired_tests_over_the_same_runs(tiny):
    tr = tiny.table("trends")
    assert set(tr["trend"]) == set(TRENDS)
    for name, g in tr.groupby("trend"):
        p = g["p"].max() if g["p"].notna().all() else np.nan    # an undecidable comparison: NaN
        assert g["p_trend"].nunique(dropna=False) == 1 and g["p_trend"].iloc[0] == pytest.approx(p, nan_ok=True)
        assert float(tiny.figures[f"bearing_trend_{name}_p"]) == pytest.approx(p, rel=1e-3, nan_ok=True)
        assert (g["n"] <= 6).all()                              # tiny: 6 shared runs
    nr = tr[tr["trend"] == "nr25"]["comparison"].tolist()
    assert nr == ["cppv_25_1_1 < cppv_10_1_1", "cppv_25_1_1 < cppv_150_1_1"]       # Case 1: N_ω = N_θ = 1
    runs = tiny.table("runs")
    orbit = runs[runs["part"].isin(["table_4_2", "cppv_vs_mpc", "sweeps"])]
    assert all(sorted(g["run"]) == list(range(6)) for _, g in orbit.groupby("config"))


@pytest.mark.slow
def test_the_crlb_table_holds_sample_std_and_bound_for_r_v_omega(tiny):
    c = tiny.table("crlb")
    assert {"r", "v", "omega", "theta"} == set(c["quantity"])
    assert (c["sqrt_crlb"] > 0).all()
    r = c[c["quantity"] == "r"]
    assert r["sqrt_crlb"].iloc[-1] < r["sqrt_crlb"].iloc[0]     # bearings shrink the range bound
    # the floor of a filter carrying the bank's Q is never below the bound, and is reported
    assert (c["floor_ratio"] >= 1.0 - 1e-6).all()
    for q in ("r", "v", "omega", "theta"):
        assert float(tiny.figures[f"bearing_crlb_floor_ratio_{q}"]) >= 1.0 - 1e-3


@pytest.mark.slow
def test_the_crlb_part_reruns_the_same_orbit_with_the_other_q_form_as_a_diagnostic(tiny):
    # the setting is the corrected B_θω block: the second arm carries the printed one
    other = {q: float(tiny.figures[f"bearing_crlb_other_q_floor_ratio_{q}"]) for q in ("r", "v", "omega", "theta")}
    assert all(v >= 1.0 - 1e-3 for v in other.values())
    assert other["omega"] != pytest.approx(float(tiny.figures["bearing_crlb_floor_ratio_omega"]), rel=1e-3)
    for q in ("r", "v", "omega", "theta"):
        assert np.isfinite(float(tiny.figures[f"bearing_crlb_other_q_ratio_{q}"]))
    assert "faithful B_θω block" in Path(tiny.outputs["report"]).read_text()
    # the arm is a configuration of its own, beside the setting's crlb_cppv_25_1_6
    assert {"crlb_cppv_25_1_6", "crlb_cppv_25_1_6_other_q"} <= set(tiny.result.diagnostics["configs"])


@pytest.mark.slow
def test_the_crlb_table_is_the_same_bytes_on_two_worker_processes_as_in_one_process(tiny, ran, tmp_path):
    # a worker's estimates come back C-ordered through pickling, the bank's are not: the
    # sample std over runs rounded differently (96 values, last digits, at tiny size) until execute_job
    # made them C-ordered in both cases
    two = ran(NAME, tmp_path, {"size": "tiny", NAME: {"workers": 2, "parts": ["crlb"]}}, estimate={})
    pd.testing.assert_frame_equal(two.table("crlb"), tiny.table("crlb"), check_exact=True)


def test_the_case_5_removal_drops_the_mpc_diverged_scenarios_from_both_sides():
    # seed Case 5: MPC's divergent scenarios removed, and as many CPPV scenarios (paired: the same)
    mpc_div = np.array([False, True, False, False, True, False])
    keep = bo.case5_keep(mpc_div)
    assert keep.tolist() == [True, False, True, True, False, True] and (~keep).sum() == mpc_div.sum()


def test_a_trend_with_an_undecidable_comparison_does_not_hold():
    rows = []
    bo._trend(rows, "x", "claim", [("all", {"p": 1e-6, "n": 24}), ("kept", {"p": float("nan"), "n": 0})], 0.05)
    assert all(np.isnan(r["p_trend"]) and not r["holds"] for r in rows)
    rows = []
    bo._trend(rows, "y", "claim", [("a", {"p": 0.01}), ("b", {"p": 0.03})], 0.05)
    assert all(r["p_trend"] == 0.03 and r["holds"] for r in rows)


def test_a_failing_trend_names_the_configurations_on_both_sides_of_its_comparisons():
    R = {"cppv_25_1_6": {}, "mpc_15_5_2": {}, "cppv_10_1_1": {}}
    comps = ["cppv_25_1_6 < mpc_15_5_2, all runs", "cppv_25_1_6 < mpc_15_5_2, Case-5 removal (3 runs dropped)",
             "spread_T_d < spread_δ", "δ 0.001 < δ 1e-2", "cppv_10_1_1 < cppv_150_1_1"]
    assert bo._trend_arms(comps, R) == ["cppv_25_1_6", "mpc_15_5_2", "cppv_10_1_1"]


@pytest.mark.slow
# Issue 16's CRLB target, asserted as stated on a reduced set (60 of the 500 realisations).
# On the faithful bank it is missed: at thesis size (500 realisations, 60-120 s) std/sqrt(CRLB) for
# r/v/omega/theta is 6.42/5.70/31.9/6.36, and the error std of the best Kalman filter carrying Table 4.1's Q on
# that orbit (estimate.crlb.q_floor: gains linearised on the truth, the bank's P0) is
# 4.66/4.07/30.1/5.96 (RESULT bearing_crlb_floor_ratio_*): the CRLB (App. D) has no process noise,
# the filter has, and that alone keeps the ideal filter above the band; with Q = 0 it is the CRLB exactly
# (tests/estimate/test_crlb.py). With the printed B_θω block (q_form: faithful) instead, bank 4.71/4.01/9.35/3.10
# and floor 2.94/2.59/8.44/2.85 (RESULT bearing_crlb_other_q_*): still above the band.
# strict: the day it passes, this marker must go.
@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="issue-16 CRLB band [0.9, 2] is below what the ideal filter carrying the thesis's Q reaches")
def test_the_bank_sample_std_lies_within_the_crlb_band_on_one_fixed_orbit():
    from pipeline.estimate.bank import run_bank
    from pipeline.simulate.encounter import ScenarioSettings, simulate_encounters

    enc = simulate_encounters("orbit", 60, 0, ScenarioSettings(), fixed_geometry=True)
    tr = run_bank(bo.BASE, enc.t_s, enc.bearing, enc.sigma_bearing, enc.ownship_vel, store_weights=False)
    _, ratio = bo.crlb_check(enc.rel[0], enc.t_s, tr.cppv_mean, tr.cppv_cov[0, 0], enc.sigma_bearing, (60.0, 120.0))
    # preconditions fail as failures, not as the expected miss: a NaN ratio (no sample std, or no
    # bound, in the window) compares False with the band and would otherwise pass as the xfail
    if not all(np.isfinite(ratio[q]) for q in ("r", "v", "omega")):
        pytest.fail(f"precondition: a std/sqrt(CRLB) ratio is not finite: {ratio}")
    assert all(0.9 <= ratio[q] <= 2.0 for q in ("r", "v", "omega")), ratio


def test_each_configuration_has_one_colour_on_the_range_and_the_heading_panel():
    from types import SimpleNamespace

    from pipeline.studies.bearing_only import figures

    t = np.arange(3.0)
    curves = pd.concat([pd.DataFrame({"part": "table_4_2", "config": name, "kind": "orbit", "t_s": t,
                                      "thesis_r": 0.1 * k + t, "heading_deg": 10.0 * k + t})
                        for k, name in enumerate(("cppv_10_1_1", "cppv_25_1_1", "cppv_150_1_1"))])
    figs = dict(figures(curves, pd.DataFrame(), pd.DataFrame(), SimpleNamespace(results={})))
    fig = figs["Table 4.2 parameterisations"]
    by_name: dict[str, set] = {}
    for tr in fig.data:
        by_name.setdefault(tr.name, set()).add(tr.line.color)
    assert len(by_name) == 3 and all(len(c) == 1 for c in by_name.values())      # same on both panels
    assert len({c for cs in by_name.values() for c in cs}) == 3                      # and apart from each other


def test_a_configuration_that_never_converges_is_marked_and_the_crlb_panels_start_after_the_shared_start():
    from types import SimpleNamespace

    from pipeline.studies.bearing_only import CRLB_PLOT_FROM_S, figures

    t = np.arange(0.0, 3.0, 0.5)
    head = {"fast": np.full((2, len(t)), 0.05), "never": np.full((2, len(t)), 0.5)}
    run = SimpleNamespace(results={k: {"t_s": t, "err": {"head": v}} for k, v in head.items()})
    curves = pd.DataFrame({"part": "table_4_2", "config": "fast", "kind": "orbit", "t_s": t,
                           "thesis_r": 0.1, "heading_deg": 1.0})
    crlb = pd.DataFrame({"quantity": "r", "t_s": t, "sample_std": np.r_[0.0, np.ones(len(t) - 1)],
                         "sqrt_crlb": np.ones(len(t))})
    figs = dict(figures(curves, crlb, pd.DataFrame(), run))
    conv = figs["Convergence"]
    assert list(conv.data[0].x) == ["fast"] and list(conv.data[1].x) == ["never"]
    assert conv.data[1].name == "not within the run"
    std = next(tr for tr in figs["CRLB"].data if tr.name == "sample std")
    assert min(std.x) >= CRLB_PLOT_FROM_S and min(std.y) > 0
