"""The particle-filter study at ``tiny`` size through its entry point: every seed-003 trend and
seed-001 geo-location check as a RESULT line, the tables, the report and the page."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest

from pipeline.studies import STUDIES, STUDY_TABLES
from pipeline.studies import pf as spf

NAME = "pf"


@pytest.fixture(scope="module")
def tiny(ran, tmp_path_factory):
    # studies.pf.geo reaches the seed-001 part: the observer sweep at its own particle count
    return ran(NAME, tmp_path_factory.mktemp("pf"), {"size": "tiny", "pf": {"geo": {"observer_particles": 40}}})


def test_the_study_is_registered_with_its_tables():
    assert STUDIES[NAME] == "pipeline.studies.pf:run_pf"
    assert STUDY_TABLES[NAME] == ("hmpf_runs", "hmpf_timeline", "geo_summary", "geo_series", "geo_config",
                                 "geo_timing")


@pytest.mark.slow
def test_the_tiny_study_writes_every_trend_as_a_result_line_with_numbers(tiny):
    assert tiny.result.status == "ok" and tiny.result.diagnostics["size"] == "tiny"
    text = Path(tiny.outputs["results"]).read_text().splitlines()
    assert text and all(line.startswith("RESULT ") and len(line.split()) == 3 for line in text)
    f = tiny.figures
    assert f["pf_hmpf_pi_m_stationary"] == "0.7870,0.0278,0.0278,0.1574"
    assert f["pf_hmpf_range_criterion_m"] == "16665"
    # every count and mean printed is the one the per-run table gives (recomputed here from it)
    runs = tiny.table("hmpf_runs")
    by = {k: g for k, g in runs.groupby("scenario")}
    assert f["pf_hmpf_straight_frac_ge_0.95_seeds"] == f"{int((by['straight_gps']['straight_frac'] >= 0.95).sum())}/3"
    assert float(f["pf_hmpf_straight_frac_mean"]) == pytest.approx(by["straight_gps"]["straight_frac"].mean(), abs=5e-4)
    dl = by["weave_gps_detector"]["flag_delay_steps"].to_numpy(dtype=float)
    assert f["pf_hmpf_weave_flagged_within_80_seeds"] == f"{int(np.sum(np.isfinite(dl) & (dl <= 80)))}/3"
    for nm in ("straight", "pi_turn"):
        never = int((~by[f"{nm}_gps_detector"]["ever_flagged"].astype(bool)).sum())
        assert f[f"pf_hmpf_{nm}_never_flagged_seeds"] == f"{never}/3", nm
    fin = by["pi_turn_gps_detector_final"]
    assert np.allclose(fin["delta_max_m"], 500.0) and np.allclose(fin["theta_max_rad"], np.pi)
    assert f["pf_hmpf_pi_turn_never_flagged_seeds_final"] == f"{int((~fin['ever_flagged'].astype(bool)).sum())}/3"
    # the π turn's detector bound under the ideal likelihood: a number per maxima and kill count
    for lab in ("", "_final"):
        b1, b2 = (float(f[f"pf_hmpf_pi_turn_bound_max_af{lab}_kill{k}"]) for k in (1, 2))
        assert 0.0 < b1 < 1.0 and 0.0 < b2 < 1.0, lab
    assert float(f["pf_hmpf_radar_weave_pos_rmse_m"]) == pytest.approx(by["weave_radar"]["pos_rmse_m"].mean(), abs=5e-3)
    assert float(f["pf_hmpf_radar_weave_vel_rmse_mps"]) == pytest.approx(by["weave_radar"]["vel_rmse_mps"].mean(),
                                                                         abs=5e-4)
    ranges = [k for k in by if k.startswith("range_")]
    wr = [by[k]["weave_frac_in_weave"].mean() for k in sorted(ranges, key=lambda k: float(k.split("_")[1]))]
    np.testing.assert_allclose([float(x) for x in f["pf_hmpf_range_weave_frac"].split(",")], wr, atol=5e-4)
    assert int(f["pf_hmpf_range_weave_frac_falls"]) == int(bool(np.all(np.diff(wr) < 0)))
    qw = [by[f"quadrant_{q}"]["weave_frac_in_weave"].mean() for q in range(1, 5)]
    np.testing.assert_allclose([float(x) for x in f["pf_hmpf_quadrant_weave_frac"].split(",")], qw, atol=5e-4)
    # the radar weave's errors are those of a track held: metres and tenths of m/s, not kilometres
    assert 0.5 < float(f["pf_hmpf_radar_weave_pos_rmse_m"]) < 20 and 0.05 < float(f["pf_hmpf_radar_weave_vel_rmse_mps"]) < 5
    met, total = map(int, f["pf_hmpf_trends_met"].split("/"))
    report = Path(tiny.outputs["report"]).read_text()
    assert total == 10 and met == report.count("| yes |"), "trends_met counts the report's met rows"


@pytest.mark.slow
def test_the_tables_hold_every_scenario_and_seed(tiny):
    runs, tl = tiny.table("hmpf_runs"), tiny.table("hmpf_timeline")
    scen = set(runs["scenario"])
    assert {"straight_gps", "pi_turn_gps", "weave_gps", "weave_gps_min", "weave_gps_0.8x", "weave_radar",
            "range_10000", "quadrant_4"} <= scen
    assert runs.groupby("scenario").size().eq(3).all()
    np.testing.assert_allclose(tl[[f"mode_p_{m}" for m in "SLRW"]].sum(axis=1), 1.0)
    # the π turn under the ideal likelihood, beside the filter's runs: its AF peak is the RESULT line
    f = tiny.figures
    for lab in ("", "_final"):
        g = tl[tl["scenario"] == f"pi_turn_ideal_likelihood{lab}"]
        assert len(g) == len(tl[tl["scenario"] == "pi_turn_gps"]) and g["rmse_pos_n_m"].isna().all()
        assert f"{g['af'][g['step'] > 25].max():.3f}" == f[f"pf_hmpf_pi_turn_bound_max_af{lab}_kill1"], lab
        assert g["flag_seed0"].any() == (float(f[f"pf_hmpf_pi_turn_bound_max_af{lab}_kill1"]) >= 0.269), lab
    d_true, t_true = spf.weave_truth_max({**spf.DEFAULTS, **spf.SIZES["tiny"]})
    w = runs[runs["scenario"] == "weave_gps_0.8x"]
    assert np.allclose(w["delta_max_m"], 0.8 * d_true)
    # thesis Fig. A.8: on radar, one maximum mis-set at a time, the other at its true value
    for lab, fd, ft in (("delta_0.8x", 0.8, 1.0), ("delta_1.2x", 1.2, 1.0), ("theta_0.8x", 1.0, 0.8),
                        ("theta_1.2x", 1.0, 1.2)):
        a = runs[runs["scenario"] == f"weave_radar_{lab}"]
        assert len(a) == 3 and set(a["sensor"]) == {"radar"}, lab
        assert np.allclose(a["delta_max_m"], fd * d_true) and np.allclose(a["theta_max_rad"], ft * t_true), lab


def test_the_ncv_third_noise_is_a_third_of_the_weaves_centripetal_acceleration():
    # seed 003 §4.2.2: "1/3 times the maximal acceleration"; the weave turns at 0.1 rad/s at 1.414 m/s
    assert spf.ncv_third_noise(spf.DEFAULTS) == pytest.approx(np.sqrt(2.0) * 0.1 / 3.0)


@pytest.mark.slow
def test_the_ncv_third_diagnostic_reruns_the_weave_on_both_sensors_with_the_same_noise(tiny):
    runs, f = tiny.table("hmpf_runs"), tiny.figures
    sig = spf.ncv_third_noise({**spf.DEFAULTS, **spf.SIZES["tiny"]})
    for sens in ("radar", "gps"):
        g = runs[runs["scenario"] == f"weave_{sens}_ncv_third"]
        assert len(g) == 3 and set(g["sensor"]) == {sens}
        assert float(f[f"pf_hmpf_{sens}_weave_vel_rmse_mps_ncv_third"]) == pytest.approx(
            g["vel_rmse_mps"].mean(), abs=6e-4)
        assert int(f[f"pf_hmpf_{sens}_weave_reinit_ncv_third"]) == int(g["n_reinit"].sum())
    assert f"{sig:.4f} m/s²" in Path(tiny.outputs["report"]).read_text()


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
    obs = summ["case"].str.startswith("observers_")
    assert (summ.loc[obs, "n_particles"] == 40).all() and (summ.loc[summ["case"] == "base", "n_particles"] == 50).all()
    assert {"focal_px", "sigma_px"} <= set(cfg["key"])


def test_the_cv_kalman_oracle_is_the_filters_actual_error_on_a_noise_free_track_not_its_nominal_std():
    # an independent Monte Carlo: the steady-state-gain CV filter run on a constant-velocity truth
    sa, sm = 2.0, 1.0
    F, G, H = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[0.5], [1.0]]), np.array([[1.0, 0.0]])
    P = np.eye(2) * 10.0
    for _ in range(500):   # the steady-state gain by iterating the Riccati recursion
        P = F @ P @ F.T + sa ** 2 * G @ G.T
        K = P @ H.T / (H @ P @ H.T + sm ** 2)
        P = (np.eye(2) - K @ H) @ P
    rng = np.random.default_rng(0)
    n, T = 4000, 60
    x = np.zeros((n, 2))
    x[:, 1] = 1.4
    xh = x + rng.standard_normal((n, 2))
    for _ in range(T):
        x = x @ F.T
        xh = xh @ F.T
        z = x[:, 0] + sm * rng.standard_normal(n)
        xh = xh + (z - xh[:, 0])[:, None] * K[:, 0][None, :]
    sd = (xh - x).std(axis=0)
    pos, vel = spf.cv_kf_error_on_cv_truth(sa, sm)
    assert vel == pytest.approx(sd[1], rel=0.05) and pos == pytest.approx(sd[0], rel=0.05)
    assert vel == pytest.approx(0.946, abs=0.002)
    nominal = spf.cv_kf_steady_state(sa, sm)[1]
    assert nominal == pytest.approx(np.sqrt(P[1, 1]), rel=1e-6) and nominal == pytest.approx(1.572, abs=0.002)
    assert nominal > 1.5 * vel


def test_the_ideal_likelihood_straight_fraction_bound_matches_the_two_state_closed_form():
    from pipeline.estimate.weave import HmpfConfig
    # S <-> W only; entering W starts at a curve (A3 'curve'), which survives only by switching to
    # its straight at once (p1); a weave straight survives when it stays in W and does not switch
    a, p1 = 0.1, 0.3
    pi = [[1 - a, 0, 0, a], [1, 0, 0, 0], [1, 0, 0, 0], [a, 0, 0, 1 - a]]
    c = HmpfConfig.from_config({}).with_(pi_m=tuple(map(tuple, pi)), p1=p1, enter_submode="curve",
                                         delta_max_m=1e12)
    f = spf.straight_fraction_bound(c, 1.0, kill_after=1, steps=150, n=30000, startup=50,
                                    rng=np.random.default_rng(1))
    A = np.array([[1 - a, a], [a * p1, (1 - a) * (1 - p1)]])   # new [S, W] = A @ old
    w, v = np.linalg.eig(A)
    v = np.abs(v[:, np.argmax(w.real)].real)
    assert f[1] == f[2] == 0.0
    np.testing.assert_allclose(f[[0, 3]], v / v.sum(), atol=0.004)


def test_with_pi_m_4_2_an_ideal_likelihood_caps_the_straight_fraction_near_0_95_only_on_leaf_counters():
    # leaf counters (digest A4): a particle entering W restarts δ, so its weave straight outlives
    # any likelihood for ~δ_max / v steps; segment counters (thesis (2.3)): the straight's δ is
    # already past δ_max and the particle turns at once, so only the curves' lifetime is left
    from pipeline.estimate.weave import HmpfConfig
    st = {**spf.DEFAULTS}
    d, t = spf.weave_truth_max(st)
    c = HmpfConfig.from_config({}).with_(delta_max_m=1.2 * d, theta_max_rad=1.2 * t)
    f = {(k, n): spf.straight_fraction_bound(c.with_(counters=k), st["speed_mps"], kill_after=n, steps=200,
                                             n=20000, rng=np.random.default_rng(n))
         for k in ("leaf", "segment") for n in (1, 2)}
    assert 0.94 < f["leaf", 1][0] < 0.96 and f["leaf", 2][0] < f["leaf", 1][0] - 0.01
    assert f["segment", 1][0] > 0.995 and 0.95 < f["segment", 2][0] < f["segment", 1][0] - 0.02
    with pytest.raises(ValueError, match="theta"):
        spf.straight_fraction_bound(c.with_(theta_max_rad=0.2), 1.0, kill_after=1, rng=np.random.default_rng(0))


def test_the_ideal_likelihood_on_a_left_turn_matches_the_curve_survival_closed_form():
    # a left turn from the first step, every particle not turning left removed at once: the
    # survivors are L (stays at Π_m[L, L] = 0.66; L -> S dies) and weave CL (stays at
    # 0.97 * (1 - p1) while θ < θ_max), so W's share grows by r = 0.97 * 0.95 / 0.66 a step from
    # F1 = P(CL) / (P(L) + P(CL)) after the uniform start (CL kept at 0.95, SR -> CL at p1)
    from pipeline.estimate.weave import HmpfConfig
    c = HmpfConfig.from_config({}).with_(enter_submode="keep", counters="leaf", theta_max_rad=100.0)
    pi = np.asarray(c.pi_m)
    f = spf.oracle_mode_fractions(c, np.full(6, -0.1), 1.4, kill_after=1, n=200_000, rng=np.random.default_rng(3))
    p_l = pi[:, 1].sum() / 4
    p_cl = pi[:, 3].sum() / 4 * (0.25 * (1 - c.p1) + 0.25 * c.p1)
    a = p_cl / (p_l + p_cl)
    r = pi[3, 3] * (1 - c.p1) / pi[1, 1]
    j = np.arange(6)
    F = a * r**j / (a * r**j + 1 - a)
    assert np.all(f[:, 0] == 0) and np.all(f[:, 2] == 0)
    # Monte Carlo error: 1.1e-3 a step, growing under resampling (worst of five seeds 4.2e-3);
    # dropping the submode's 0.95 from r moves the sixth step by 0.03
    np.testing.assert_allclose(f[:, 3], F, atol=0.008)
    np.testing.assert_allclose(f[:, 1], 1 - F, atol=0.008)
    with pytest.raises(ValueError, match="kill_after"):
        spf.oracle_mode_fractions(c, np.zeros(3), 1.0, kill_after=0, rng=np.random.default_rng(0))


def test_with_the_final_maxima_no_likelihood_keeps_the_pi_turn_unflagged():
    # digest 003 §7 (δ_max = 500 m, θ_max = π): the mode chains alone flag a π turn at
    # 0.1 rad/s even when every particle moving unlike the track dies at its first weighting;
    # at the study's weave-scaled maxima only that ideal (a 7 cm difference seen by 1 m GPS)
    # stays below τ, and the straight track and the weave sit far on either side
    from pipeline.estimate.weave import HmpfConfig
    st = {**spf.DEFAULTS}
    d, t = spf.weave_truth_max(st)
    final = HmpfConfig.from_config({})
    sim = final.with_(delta_max_m=1.2 * d, theta_max_rad=1.2 * t)
    trk = spf.tracks(st)

    def bound(c, name, k):
        return spf.detector_bound(c, trk[name], st["speed_mps"], kill_after=k, n=10_000, rng=np.random.default_rng(k))

    assert (final.delta_max_m, final.theta_max_rad) == (500.0, np.pi)
    assert bound(final, "pi_turn", 1) > final.tau + 0.1
    assert bound(sim, "pi_turn", 1) < final.tau < bound(sim, "pi_turn", 2) - 0.05
    assert bound(sim, "straight", 1) < final.tau / 2 and bound(sim, "weave", 2) > 2 * final.tau


# -- seed-003 trends missed on faithful code: strict xfails holding issue 17's targets ---------------
# The study's scenarios at the study's particle counts (small size: 2,000 particles, the detector
# checks at 10,000), so each xfail turns into a pass the day the study meets its target; at 200
# particles even the straight track's never-flagged count that the study meets falls to 11/20,
# and a fixed filter could still fail there. Each miss is diagnosed in the study report.
SMALL = {**spf.DEFAULTS, **spf.SIZES["small"]}

@functools.lru_cache(maxsize=4)
def _hmpf_scenario(name, sensor, n_particles, seeds=20, seed=20261123):
    from pipeline.estimate.weave import GpsSensor, HmpfConfig, RadarSensor, hmpf_filter
    from pipeline.simulate.seeds import set_rng
    from pipeline.simulate.ship import gps_measure, radar_measure
    st = {**spf.DEFAULTS}
    tr = spf.tracks(st)[name]
    d, t = spf.weave_truth_max(st)
    cfg = HmpfConfig.from_config({}, n_particles=n_particles).with_(delta_max_m=1.2 * d, theta_max_rad=1.2 * t)
    rz = set_rng(seed, f"pf/noise/{tr.name}/{sensor}")
    z = gps_measure(tr, seeds, rz) if sensor == "gps" else radar_measure(tr, seeds, rz)
    out = hmpf_filter(z, GpsSensor() if sensor == "gps" else RadarSensor(), cfg, set_rng(seed, f"pf/filter/{name}"))
    return tr, out


@pytest.mark.slow
@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "issue 17: straight fraction >= 0.95 over steps 25-end in >= 19/20 seeds (GPS). Pi_m (4.2) caps it: "
    "the mode chains alone under an ideal likelihood that kills every curve particle at its first weighting "
    "give 0.950 (0.926 at the second; pf_hmpf_straight_frac_bound_*); measured 0.845 mean, 0/20 seeds, at "
    "2,000 particles (0.874 at 20,000). With segment counters (thesis (2.3) as printed) the cap is ~1 but the "
    "filter reads 0.880, 0/20: slow curves outlive their weighting"))
def test_issue17_straight_tracks_keep_a_straight_fraction_of_0_95_in_19_of_20_seeds():
    _, out = _hmpf_scenario("straight", "gps", SMALL["n_particles"])
    frac = out.mode_p[:, 25:, 0].mean(axis=1)
    assert int((frac >= 0.95).sum()) >= 19, np.round(frac, 3)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "issue 17: velocity RMS <= 0.4 m/s on the simulated radar weave (digest 003 §8: the thesis's chapter-3 "
    "filter, whose process noise is not given). With the §4.2.2 CM noise sigma_aT = 2 m/s^2 a CV Kalman filter "
    "has an actual velocity error of 0.946 m/s even with a 1 m GPS on a noise-free straight "
    "(pf_hmpf_cv_kf_vel_error_cv_truth_mps); measured 1.02 m/s at 2,000 particles (position 3.61 m, <= 4 met). "
    "With the NCV rule §4.2.2 reports (sigma = a_max/3 = 0.047 m/s^2) GPS reaches 0.195 m/s but radar loses "
    "the track (1.59 m/s, 42 m; pf_hmpf_*_ncv_third)"))
def test_issue17_the_radar_weave_velocity_rms_is_at_most_0_4_mps():
    tr, out = _hmpf_scenario("weave", "radar", SMALL["n_particles"])
    ev = out.mean[:, 25:, 2:4] - tr.state[None, 25:, 2:4]
    vel = float(np.sqrt(np.mean(np.sum(ev * ev, axis=-1) / 2.0, axis=1)).mean())
    assert vel <= 0.4, vel


@pytest.mark.slow
@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "issue 17: pi-turn tracks never flagged in >= 19/20 seeds. Weave curve particles stay in their curve at "
    "0.97*0.95 per step against a left curve's 0.66 (Pi_m (4.2)), so W peaks in and after a long turn (the "
    "thesis's own §4.2.3 reading; it never ran the detector on this track); measured 7/20 at 2,000 particles "
    "with the printed AF(k) (6/20 with the average restarted after the start-up), 6/20 at 10,000 (the study's "
    "detector runs), 5/20 at 20,000 (before). An ideal likelihood (every particle moving unlike the track dies "
    "at its first weighting) gives a largest AF of 0.484 with the issue's 500 m / pi maxima, above tau = 0.269, "
    "and 0.240 with the study's (0.428 at the second weighting; pf_hmpf_pi_turn_bound_*)"))
def test_issue17_pi_turn_tracks_are_never_flagged_in_19_of_20_seeds():
    _, out = _hmpf_scenario("pi_turn", "gps", SMALL["detector_particles"])
    never = int((~out.weave_detected.any(axis=1)).sum())
    assert never >= 19, never


@pytest.mark.slow
def test_issue17_straight_tracks_are_never_flagged_in_19_of_20_seeds():
    # at 2,000 particles (the study's detector runs use 10,000: 20/20); with the printed AF(k)
    # and the start-up's F left out (thesis §6.2-§6.3, weave.detector) 19/20. It depends on the
    # particle count: 11/20 at 200, 9/20 at 500, 16/20 at 1,000 particles (resampling every step
    # makes F drift from seed to seed)
    _, out = _hmpf_scenario("straight", "gps", SMALL["n_particles"])
    never = int((~out.weave_detected.any(axis=1)).sum())
    assert never >= 19, never
