"""The bearing-only encounter simulator: NED conventions, the digest §9 draws, shared scenarios
across configurations and the robustness sweeps."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.estimate.models import wrap_angle
from pipeline.io.base import FlightLog
from pipeline.simulate.encounter import (KINDS, ScenarioSettings, encounter_streams, simulate_encounters,
                                         sweep_sets)

DEG = np.pi / 180


@pytest.fixture(scope="module")
def settings():
    return ScenarioSettings.from_config({"orbit_s": 20.0, "segments_s": {"ct_cv": [10.0, 6.0]}})


def test_the_bearing_is_atan2_of_east_over_north_offsets(settings):
    e = simulate_encounters("orbit", 20, 3, settings)
    d = e.intruder[..., :2] - e.ownship[..., :2]
    np.testing.assert_allclose(e.bearing_true, np.arctan2(d[..., 1], d[..., 0]), atol=1e-12)
    np.testing.assert_allclose(e.rel[..., :2], d, atol=1e-9)


@pytest.mark.parametrize("course_deg, side, expected", [
    (0.0, "east", np.pi / 2), (180.0, "west", -np.pi / 2), (270.0, "north", 0.0), (90.0, "south", np.pi)])
def test_an_intruder_due_east_west_north_or_south_is_at_plus_90_minus_90_0_or_180_degrees(course_deg, side,
                                                                                          expected):
    # the intruder starts at range0, `angle` to the right of the ownship's course, with the ownship
    # at the origin: a fixed 90 deg right of a course of 0 / 180 / 270 / 90 deg is E / W / N / S
    s = ScenarioSettings.from_config({"orbit_s": 1.0, "range_m": [2000.0, 2000.0], "angle_deg": [90.0, 90.0],
                                      "ownship_course_deg": course_deg})
    e = simulate_encounters("orbit", 3, 7, s)
    np.testing.assert_allclose(e.ownship[:, 0, :2], 0.0, atol=0.0)
    n, east = {"east": (0, 1), "west": (0, -1), "north": (1, 0), "south": (-1, 0)}[side]
    np.testing.assert_allclose(e.rel[:, 0, :2], np.broadcast_to([2000.0 * n, 2000.0 * east], (3, 2)), atol=1e-9)
    # ±π are the same bearing (wrapped to [−π, π)): compare through the wrap
    np.testing.assert_allclose(wrap_angle(e.bearing_true[:, 0] - expected), 0.0, atol=1e-12)


def test_the_course_runs_from_north_toward_east_and_positive_omega_turns_right(settings):
    e = simulate_encounters("orbit", 40, 5, settings)
    v = np.diff(e.intruder[..., :2], axis=1) / e.dt                      # finite-difference velocity
    course = np.arctan2(v[..., 1], v[..., 0])                            # atan2(v_E, v_N)
    mid = wrap_angle(e.intruder[:, :-1, 3] + 0.5 * e.dt * e.intruder[:, :-1, 4])
    np.testing.assert_allclose(wrap_angle(course - mid), 0.0, atol=1e-6)
    # a chord of the arc: 2 v sin(ωT/2) / (ωT) per unit time
    wT = e.intruder[:, :-1, 4] * e.dt
    np.testing.assert_allclose(np.hypot(v[..., 0], v[..., 1]), e.intruder[:, 1:, 2] * np.sinc(wT / (2 * np.pi)),
                               rtol=1e-9)
    # a right turn (ω > 0) rotates the velocity clockwise seen from above: v × a along +D,
    # i.e. v_N a_E − v_E a_N > 0 in (N, E)
    a = np.diff(v, axis=1)
    cross = v[:, :-1, 0] * a[..., 1] - v[:, :-1, 1] * a[..., 0]
    w = e.params["omega"]
    assert np.all(np.sign(cross) == np.sign(w)[:, None])
    assert (w > 0).any() and (w < 0).any()


def test_the_draws_follow_the_digest_ranges(settings):
    e = simulate_encounters("orbit", 400, 11, settings)
    p = e.params
    assert np.all((np.abs(p["omega"]) >= 3 * DEG) & (np.abs(p["omega"]) <= 8 * DEG))
    assert np.all((p["speed"] >= 60) & (p["speed"] <= 80))
    assert np.all((p["range0"] >= 1800) & (p["range0"] <= 6500))
    np.testing.assert_allclose(e.range_m[:, 0], p["range0"], rtol=1e-12)
    assert 0.4 < np.mean(p["omega"] > 0) < 0.6
    assert e.dt == 0.05 and np.isclose(e.sigma_bearing, 0.2 * DEG)
    np.testing.assert_allclose(e.t_s[-1], 20.0)
    res = wrap_angle(e.bearing - e.bearing_true)
    assert abs(res.std() / (0.2 * DEG) - 1) < 0.02
    # the ownship flies north at 40 m/s from the origin
    np.testing.assert_allclose(e.ownship[0, -1, :2], [800.0, 0.0], atol=1e-9)


def test_placing_the_orbit_centre_keeps_the_intruder_on_a_circle_about_it():
    s = ScenarioSettings.from_config({"orbit_s": 20.0, "place": "centre"})
    e = simulate_encounters("orbit", 10, 2, s)
    p, v, w = e.params, e.params["speed"], e.params["omega"]
    c = p["range0"][:, None] * np.stack([np.cos(p["angle"]), np.sin(p["angle"])], axis=1)
    d = np.hypot(*(e.intruder[..., :2] - c[:, None, :]).transpose(2, 0, 1))
    np.testing.assert_allclose(d, np.broadcast_to((v / np.abs(w))[:, None], d.shape), rtol=1e-9)


def test_switching_scenarios_change_mode_at_the_configured_times(settings):
    e = simulate_encounters("ct_cv", 8, 1, settings)
    k = int(round(10.0 / e.dt))
    assert e.switch_s == (10.0,) and e.rel.shape[1] == int(round(16 / e.dt)) + 1
    assert np.all(e.mode[:, :k] == 1) and np.all(e.mode[:, k:] == 0)
    assert np.all(e.intruder[:, k:, 4] == 0)
    # position and course are continuous through the switch
    jump = np.hypot(*np.diff(e.intruder[:, k - 1:k + 1, :2], axis=1)[:, 0].T)
    np.testing.assert_allclose(jump, e.params["speed"] * e.dt, rtol=1e-3)
    for kind, modes in KINDS.items():
        m = simulate_encounters(kind, 2, 1).mode[0]
        seq = [int(m[0])] + [int(b) for a, b in zip(m[:-1], m[1:]) if a != b]
        assert tuple(seq) == modes


def test_one_seed_gives_the_same_scenarios_and_noise_for_every_configuration(settings):
    a = simulate_encounters("orbit", 30, 7, settings)
    b = simulate_encounters("ct_cv", 30, 7, settings)
    c = simulate_encounters("orbit", 30, 7, settings, ownship_speed_mps=60.0, bias_deg=0.2)
    for k in a.params:
        np.testing.assert_array_equal(a.params[k], b.params[k])
        np.testing.assert_array_equal(a.params[k], c.params[k])
    n = b.rel.shape[1]                                  # ct_cv here is the shorter one
    np.testing.assert_allclose(a.rel[:, :int(10 / a.dt)], b.rel[:, :int(10 / a.dt)], atol=1e-9)
    na = wrap_angle(a.bearing - a.bearing_true)
    np.testing.assert_allclose(wrap_angle(b.bearing - b.bearing_true), na[:, :n], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(c.bearing - c.bearing_true - 0.2 * DEG), na, atol=1e-12)
    d = simulate_encounters("orbit", 30, 8, settings)
    assert not np.allclose(a.params["omega"], d.params["omega"])


def test_the_sweeps_vary_only_their_own_quantity(settings):
    sw = sweep_sets("orbit", 50, 4, settings)
    assert set(sw) == {"ownship_vel_noise_mps", "bias_deg", "ownship_speed_mps"}
    assert sorted(sw["ownship_vel_noise_mps"]) == [0.0, 1.0, 3.0]
    assert sorted(sw["ownship_speed_mps"]) == [40.0, 50.0, 60.0]
    for sigma, e in sw["ownship_vel_noise_mps"].items():
        err = e.ownship_vel - e.ownship[..., 2:4]
        assert abs(err.std() - sigma) < 0.03 * max(sigma, 1.0)
        np.testing.assert_array_equal(e.bearing, sw["ownship_vel_noise_mps"][0.0].bearing)
    for v, e in sw["ownship_speed_mps"].items():
        np.testing.assert_allclose(np.hypot(e.ownship[..., 2], e.ownship[..., 3]), v)
        np.testing.assert_array_equal(e.intruder, sw["ownship_speed_mps"][40.0].intruder)
    b = sw["bias_deg"]
    np.testing.assert_allclose(wrap_angle(b[0.2].bearing - b[0.0].bearing), 0.2 * DEG, atol=1e-12)


def test_a_fixed_geometry_set_repeats_one_orbit_with_fresh_noise(settings):
    e = simulate_encounters("orbit", 25, 9, settings, fixed_geometry=True)
    np.testing.assert_allclose(e.rel, np.broadcast_to(e.rel[:1], e.rel.shape))
    assert np.std(e.bearing[:, 5]) > 0.5 * e.sigma_bearing


def test_one_run_becomes_truth_of_two_instances_and_a_bearing_stream(settings):
    e = simulate_encounters("ct_cv", 3, 1, settings)
    log = FlightLog.from_streams({}, encounter_streams(e, 1))
    tr, br = log["truth"], log["bearing"]
    assert sorted(tr["instance"].unique()) == [0, 1]
    assert list(br["src"].unique()) == ["synthetic"] and (br["instance"] == 0).all()
    np.testing.assert_allclose(br["az_rad"].to_numpy(), e.bearing[1])
    i1 = tr[tr["instance"] == 1]
    np.testing.assert_allclose(i1["pos_e_m"].to_numpy(), e.intruder[1, :, 1])
    assert set(i1["label"]) == {"CT", "CV"}


def test_an_unknown_scenario_is_one_clear_error():
    with pytest.raises(ValueError, match="unknown scenario 'loop'"):
        simulate_encounters("loop", 2, 0)


@pytest.mark.parametrize("n_runs", [0, -3, 2.5, True])
def test_a_run_count_below_one_or_not_whole_is_one_clear_error(n_runs):
    with pytest.raises(ValueError, match=r"n_runs must be a whole number >= 1"):
        simulate_encounters("orbit", n_runs, 0)


@pytest.mark.parametrize("bad, match", [
    (dict(place="center"), r"place: 'center' is not one of intruder, centre"),
    (dict(second_ct_omega="Redraw"), r"second_ct_omega: 'Redraw' is not one of same, redraw"),
    (dict(range_m=(-100.0, -50.0)), r"range_m\[0\]: -100.0 is out of range"),
    (dict(range_m=(6500.0, 1800.0)), r"range_m: need low <= high"),
    (dict(speed_mps=(80.0, 60.0)), r"speed_mps: need low <= high"),
    (dict(omega_deg_s=(0.0, 8.0)), r"omega_deg_s\[0\]: 0.0 is out of range"),
    (dict(angle_deg=(180.0, 0.0)), r"angle_deg: need low <= high"),
    (dict(sigma_bearing_deg=-1.0), r"sigma_bearing_deg: -1.0 is out of range"),
    (dict(sigma_bearing_deg=np.nan), r"sigma_bearing_deg: nan is not a finite number"),
    (dict(dt_s=0.0), r"dt_s: 0.0 is out of range"),
    (dict(dt_s=-0.05), r"dt_s: -0.05 is out of range"),
    (dict(orbit_s=np.inf), r"orbit_s: inf is not a finite number"),
    (dict(ownship_vel_noise_mps=-1.0), r"ownship_vel_noise_mps: -1.0 is out of range"),
    (dict(segments_s={"ct_cv": (10.0, 6.0)}), r"segments_s: gives no durations for ct_cv_ct, cv_ct, cv_ct_cv"),
])
def test_scenario_settings_however_made_get_the_config_paths_checks(bad, match):
    with pytest.raises(ValueError, match=match):
        simulate_encounters("ct_cv_ct", 2, 4, **bad)
    with pytest.raises(ValueError, match=match):
        ScenarioSettings(**bad)


def test_the_default_settings_are_the_config_defaults():
    assert ScenarioSettings() == ScenarioSettings.from_config({})
