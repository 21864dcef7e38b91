"""Seed-003 weave classifier (pipeline.estimate.weave) and its 2-D radar: the exact checks of
issue 17, the conventions, and fast versions of the trends."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import ConfigError
from pipeline.estimate.models import Radar2DModel, radar2d_range_criterion
from pipeline.estimate.weave import (CL, CR, LEAF_SIGN, LEAVES, SL, SR, GpsSensor, HmpfConfig, RadarSensor, detector,
                                     leaf_of, hmpf_filter, stationary_distribution, submode_matrix, switch_probability)
from pipeline.simulate.ship import gps_measure, radar_measure, straight_track, weave_track


@pytest.fixture(scope="module")
def cfg():
    return HmpfConfig.from_config({})


def test_the_stationary_distribution_of_pi_m_4_2_is_the_thesis_value(cfg):
    np.testing.assert_allclose(stationary_distribution(cfg.pi_m), [0.7870, 0.0278, 0.0278, 0.1574], atol=5e-5)
    first = [[0.97, 0.01, 0.01, 0.01], [0.35, 0.65, 0, 0], [0.35, 0, 0.65, 0], [0.03, 0, 0, 0.97]]
    np.testing.assert_allclose(stationary_distribution(first), [0.7192, 0.0205, 0.0205, 0.2397], atol=5e-5)


def test_a_500_m_straight_fits_inside_three_bearing_sigmas_beyond_16665_m():
    r = radar2d_range_criterion(500.0, 0.005)
    assert round(r) == 16665
    # at that range the straight's chord subtends exactly ±3σ_b
    assert 2 * np.arctan(250.0 / r) == pytest.approx(2 * 3 * 0.005, rel=1e-4)


@pytest.mark.parametrize("method", ["if_else", "min"])
def test_the_submode_matrix_rows_are_stochastic_and_follow_the_cycle(cfg, method):
    c = cfg.with_(method=method)
    rng = np.random.default_rng(0)
    P = submode_matrix(rng.uniform(0, 1500, 200), rng.uniform(-7, 7, 200), c)
    assert P.shape == (200, 4, 4) and np.all(P >= 0)
    np.testing.assert_allclose(P.sum(axis=-1), 1.0)
    for sm in range(4):  # only stay or advance CL → SL → CR → SR → CL
        others = [j for j in range(4) if j not in (sm, (sm + 1) % 4)]
        assert np.all(P[:, sm, others] == 0)


def test_if_else_switches_with_p1_below_and_p2_at_the_maximum_and_min_caps(cfg):
    assert switch_probability([0, 499.9, 500, 900], 500, cfg).tolist() == [0.05, 0.05, 0.95, 0.95]
    P = submode_matrix(10.0, 4.0, cfg)  # δ below δ_max, |θ| above π
    assert P[CL, SL] == 0.95 and P[CR, SR] == 0.95 and P[SL, CR] == 0.05 and P[SR, CL] == 0.05
    m = cfg.with_(method="min")
    np.testing.assert_allclose(switch_probability([250, 500, 1000], 500, m), [0.5 ** 25, 0.95, 0.95])
    assert switch_probability(-np.pi, np.pi, cfg) == 0.95  # |θ| is compared (digest A5)


def test_left_leaves_turn_with_negative_omega_in_ned():
    assert [LEAVES[i] for i in np.flatnonzero(LEAF_SIGN < 0)] == ["L", "CL"]
    assert [LEAVES[i] for i in np.flatnonzero(LEAF_SIGN > 0)] == ["R", "CR"]
    assert leaf_of([0, 1, 2, 3, 3, 3, 3], [2, 0, 0, CL, SL, CR, SR]).tolist() == [0, 1, 2, 3, 4, 5, 6]


def test_the_detector_averages_80_steps_and_ignores_the_start_up():
    F = np.zeros(200)
    F[100:130] = 0.8
    af, flag = detector(F, 80, 0.269, 25)
    assert af[129] == pytest.approx(0.8 * 30 / 80) and af[209 - 100] == pytest.approx(0.8 * 10 / 80)
    assert flag[129] and not flag[100] and np.flatnonzero(flag)[0] == 126
    # before k = N the printed (1/k) Σ F(1..k), k the track's step, with the start-up's F left out
    af, flag = detector(np.full(120, 0.5), 80, 0.269, 25)
    j = np.arange(25, 80)
    np.testing.assert_allclose(af[25:80], 0.5 * (j - 24) / (j + 1))
    np.testing.assert_allclose(af[104:], 0.5)                  # the window holds no start-up step
    assert np.all(np.isnan(af[:25])) and not flag[:25].any()
    assert np.flatnonzero(flag)[0] == np.flatnonzero(af >= 0.269)[0] == 54   # 0.5·30/55 ≥ 0.269


def test_the_detector_leaves_the_start_up_weave_fraction_out_of_its_average():
    # thesis §6.3: "we do not take the fraction of particles in the mode weave in consideration
    # during this startup time. We disregard the detector output during this period." A high F
    # during the 25 start-up steps must not carry into AF after them.
    F = np.zeros(150)
    F[:25] = 1.0
    F[25:] = 0.1
    af, flag = detector(F, 80, 0.269, 25)
    assert np.all(af[25:] <= 0.1 + 1e-12) and not flag.any()
    # k stays "the current time step" of the printed AF(k): AF(26) = F(26)/26, AF(40) =
    # Σ F(26..40)/40, and from k = 80 the last 80 steps (start-up steps counted as 0 until k = 105)
    F = np.arange(1, 201) / 1000.0
    af, _ = detector(F, 80, 0.269, 25)
    assert af[25] == pytest.approx(F[25] / 26) and af[39] == pytest.approx(F[25:40].sum() / 40)
    assert af[90] == pytest.approx(F[25:91].sum() / 80) and af[150] == pytest.approx(F[71:151].mean())


def test_the_2d_radar_uses_bearing_from_north_toward_east_and_closing_doppler():
    r = Radar2DModel()
    z = r.h(np.array([[100.0, 0, -2, 0], [0, 100, 0, 1], [-100, -1e-9, 0, 0]]))
    np.testing.assert_allclose(z[:2], [[100, 0, 2], [100, np.pi / 2, -1]])
    assert abs(abs(z[2, 1]) - np.pi) < 1e-9
    cols = r.to_stream(z)
    np.testing.assert_allclose([cols["dcos_u"][1], cols["dcos_v"][1], cols["range_rate_mps"][0]], [0, 1, -2], atol=1e-12)
    np.testing.assert_allclose(r.from_stream(cols), z, atol=1e-12)


def test_the_bearing_residual_is_wrapped_so_a_target_due_south_scores_normally():
    r = Radar2DModel()
    x = np.array([-1000.0, 0.001, 0, 0])   # bearing just under +π
    z = np.array([1000.0, -np.pi + 0.001, 0.0])  # measured just over −π
    assert abs(r.residual(z, r.h(x))[1]) < 0.01
    assert r.log_likelihood(z, x[None]) == pytest.approx(-0.5 * ((1e-3 - 1e-6) / 0.005) ** 2, abs=1e-3)


def test_bad_settings_fail_with_one_line_naming_the_key():
    with pytest.raises(ConfigError, match="method"):
        HmpfConfig.from_config({"method": "max"})
    with pytest.raises(ValueError, match="pi_m"):
        HmpfConfig.from_config({"pi_m": [[0.5, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 0.9]]})


def test_the_filter_is_seeded_and_its_fractions_are_distributions(cfg):
    tr = straight_track(40)
    z = gps_measure(tr, 2, np.random.default_rng(1))
    c = cfg.with_(n_particles=300)
    a = hmpf_filter(z, GpsSensor(), c, np.random.default_rng(5))
    b = hmpf_filter(z, GpsSensor(), c, np.random.default_rng(5))
    np.testing.assert_array_equal(a.mean, b.mean)
    np.testing.assert_allclose(a.mode_p.sum(axis=-1), 1.0)
    np.testing.assert_allclose(a.submode_p.sum(axis=-1), a.mode_p[..., 3])
    assert a.resampled[:, 1:].all() and np.all(a.neff[:, 1:] <= 300)
    # class probability = particle fraction: multiples of 1/N after resampling every step
    np.testing.assert_allclose(a.mode_p[:, 1:] * 300, np.round(a.mode_p[:, 1:] * 300), atol=1e-6)


def test_nan_measurements_are_predict_only_steps_and_the_track_keeps_going(cfg):
    tr = straight_track(40)
    z = gps_measure(tr, 1, np.random.default_rng(2))
    z[0, 10:15] = np.nan
    out = hmpf_filter(z, GpsSensor(), cfg.with_(n_particles=300), np.random.default_rng(0))
    assert np.all(np.isfinite(out.mean)) and out.n_reinit[0] == 0
    assert np.abs(out.mean[0, -1, :2] - tr.state[-1, :2]).max() < 5


def test_impossible_measurements_re_initialise_around_z_and_are_counted(cfg):
    tr = straight_track(30)
    z = gps_measure(tr, 1, np.random.default_rng(2))
    z[0, 20:] += 1e4   # a 10 km jump: every weight underflows
    out = hmpf_filter(z, GpsSensor(), cfg.with_(n_particles=200), np.random.default_rng(0))
    assert out.n_reinit[0] >= 1
    assert np.abs(out.mean[0, -1, :2] - z[0, -1]).max() < 20


def test_the_turn_sign_guard_zeroes_curve_particles_whose_omega_changed_sign(cfg):
    # a large α random walk makes ω cross zero often; the guard must catch those particles
    tr = straight_track(30)
    z = gps_measure(tr, 1, np.random.default_rng(3))
    out = hmpf_filter(z, GpsSensor(), cfg.with_(n_particles=400, sigma_alpha_radps=0.3), np.random.default_rng(0))
    assert out.n_guarded[0, 1:].sum() > 0


def test_fast_trend_the_weave_raises_the_weave_fraction_over_a_straight(cfg):
    v = 1.0
    wv, st = weave_track(n_turns=4, turn_steps=15, straight_steps=20), straight_track(160)
    c = cfg.with_(n_particles=800, delta_max_m=1.2 * np.sqrt(2) * 20 * v, theta_max_rad=1.2 * 1.5)
    rng = np.random.default_rng(11)
    ow = hmpf_filter(gps_measure(wv, 3, rng), GpsSensor(), c, rng)
    os_ = hmpf_filter(gps_measure(st, 3, rng), GpsSensor(), c, rng)
    w_in = ow.mode_p[:, wv.weave, 3].mean()
    w_st = os_.mode_p[:, 25:, 3].mean()
    assert w_in > w_st + 0.1, (w_in, w_st)
    assert os_.mode_p[:, 25:, 0].mean() > 0.6


def test_fast_trend_the_radar_filter_tracks_the_weave_near_the_site(cfg):
    wv = weave_track(n_turns=3)
    rng = np.random.default_rng(12)
    out = hmpf_filter(radar_measure(wv, 2, rng), RadarSensor(), cfg.with_(n_particles=600), rng)
    e = out.mean[:, 25:, :2] - wv.state[None, 25:, :2]
    assert np.sqrt(np.mean(e ** 2)) < 8.0


def test_the_detector_averages_the_filter_outputs_after_the_start_up_and_never_the_initial_cloud(cfg):
    # thesis §2.4: the filter outputs k = 1..T; §6 averages F but leaves the 25 start-up steps out;
    # index 0 is the initial cloud (modes uniform by construction), neither averaged nor counted
    tr = straight_track(60)
    out = hmpf_filter(gps_measure(tr, 2, np.random.default_rng(4)), GpsSensor(), cfg.with_(n_particles=300),
                      np.random.default_rng(6))
    np.testing.assert_allclose(out.mode_p[:, 0], 0.25, atol=0.1)   # the uniform initial spread
    assert np.all(np.isnan(out.af[:, 0])) and not out.weave_detected[:, 0].any()
    F = out.mode_p[:, 1:, 3]
    assert np.all(np.isnan(out.af[:, 1:26]))                               # the start-up is not averaged
    np.testing.assert_allclose(out.af[:, 26], F[:, 25] / 26)               # AF(26) = F(26)/26
    np.testing.assert_allclose(out.af[:, 40], F[:, 25:40].sum(axis=1) / 40)  # AF(40) = Σ F(26..40)/40
    af, flag = detector(F, cfg.detector_window, cfg.tau, cfg.startup_steps)
    np.testing.assert_allclose(out.af[:, 1:], af)
    np.testing.assert_array_equal(out.weave_detected[:, 1:], flag)
    assert not out.weave_detected[:, :26].any()   # steps 1..25 ignored


def test_with_segment_counters_a_straight_continued_into_the_weave_keeps_its_length():
    # thesis (2.3): δ is "the already traveled length of the current straight segment"; a particle
    # that goes S -> W on a straight track stays on that straight (SL/SR), so with `segment` its δ
    # is past δ_max and its straight submode turns (p2) and dies at once, while with `leaf` (digest
    # A4: restart on entering W) it lives ~δ_max / v more steps as a weave straight
    a = 0.05
    pi = ((1 - a, 0.0, 0.0, a), (1.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (a, 0.0, 0.0, 1 - a))
    tr = straight_track(90, vel_ne=(10.0, 10.0))   # fast enough for 1 m GPS to see a curve at once
    z = gps_measure(tr, 20, np.random.default_rng(7))
    c = HmpfConfig.from_config({}).with_(n_particles=1000, pi_m=pi, delta_max_m=100.0, omega_init_radps=(0.2, 0.3))
    # the weave's straight submodes (SL + SR) after δ has passed δ_max on the track
    w = {k: hmpf_filter(z, GpsSensor(), c.with_(counters=k), np.random.default_rng(8)).submode_p[:, 40:, [1, 3]]
         .sum(axis=-1).mean() for k in ("leaf", "segment")}
    assert w["segment"] < 0.6 * w["leaf"], w
    assert HmpfConfig.from_config({}).counters == "leaf"   # the digest's A4, the default


@pytest.mark.parametrize("kw, match", [
    (dict(window=0), "window must be a whole number >= 1"),
    (dict(window=-3), "window must be a whole number >= 1"),
    (dict(window=1.9), "window must be a whole number >= 1"),
    (dict(window=np.nan), "window must be a whole number >= 1"),
    (dict(window=True), "window must be a whole number >= 1"),
    (dict(startup=-1), "startup must be a whole number >= 0"),
    (dict(startup=2.5), "startup must be a whole number >= 0"),
    (dict(tau=np.nan), "tau must be a finite number"),
    (dict(tau=np.inf), "tau must be a finite number"),
])
def test_the_detector_refuses_a_window_start_up_or_threshold_it_cannot_use(kw, match):
    with pytest.raises(ValueError, match=match):
        detector(np.full(200, 0.3), **{"window": 80, "tau": 0.269, "startup": 25, **kw})


def test_the_detector_takes_a_whole_window_given_as_a_float_and_gives_the_same_result():
    F = np.random.default_rng(2).random(150)
    for a, b in zip(detector(F, 80, 0.269, 25), detector(F, 80.0, 0.269, np.int64(25))):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("bad, match", [
    (dict(p1=1.5), r"p1: 1.5 is out of range"),
    (dict(p2=-0.1), r"p2: -0.1 is out of range"),
    (dict(dt_s=-1.0), r"dt_s: -1.0 is out of range"),
    (dict(dt_s=np.nan), r"dt_s: nan is not a finite number"),
    (dict(counters="bogus"), r"counters: 'bogus' is not one of leaf, segment"),
    (dict(enter_submode="bogus"), r"enter_submode: 'bogus' is not one of keep, uniform, curve"),
    (dict(method="max"), r"method: 'max' is not one of"),
    (dict(resample="bogus"), r"resample: 'bogus' is not one of"),
    (dict(n_particles=0), r"n_particles: 0 is out of range"),
    (dict(n_particles=300.5), r"n_particles: 300.5 is not an integer"),
    (dict(omega_init_radps=(0.3, 0.01)), r"omega_init_radps: need 0 < low <= high"),
    (dict(pi_m=((0.5, 0.6, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1))), r"pi_m: row 0 sums to 1.1"),
    (dict(detector_window=0), r"detector_window: 0 is out of range"),
    (dict(tau=np.nan), r"tau: nan is not a finite number"),
    (dict(tau=1.5), r"tau: 1.5 is out of range"),
    (dict(delta_max_m=np.inf), r"delta_max_m: inf is not a finite number"),
])
def test_settings_made_by_with_or_direct_construction_get_the_config_paths_checks(cfg, bad, match):
    with pytest.raises(ValueError, match=match):     # ConfigError (a ValueError), or pi_m's
        cfg.with_(**bad)
    with pytest.raises(ValueError, match=match):
        HmpfConfig(**bad)
    with pytest.raises(ValueError, match=match):
        HmpfConfig.from_config({}, **bad)


def test_valid_settings_made_with_numpy_values_are_kept_as_given(cfg):
    c = cfg.with_(n_particles=np.int64(300), delta_max_m=np.float64(120.0), omega_init_radps=(0.2, 0.3))
    assert c.n_particles == 300 and c.delta_max_m == 120.0 and c.omega_init_radps == (0.2, 0.3)
    assert HmpfConfig() == HmpfConfig.from_config({})
