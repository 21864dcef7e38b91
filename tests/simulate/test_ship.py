"""Seed-003 ship tracks (pipeline.simulate.ship): exact noise-free geometry in NED, ω > 0 right."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.estimate.models import Radar2DModel
from pipeline.simulate.ship import (Segment, build_track, gps_measure, non_weave_track, pi_turn_track, radar_measure,
                                    straight_track, weave_track)


def heading(v):
    return np.arctan2(v[..., 1], v[..., 0])  # from North toward East


def test_a_straight_track_moves_at_constant_velocity_from_the_thesis_start():
    tr = straight_track(50)
    assert tr.n_steps == 51 and tr.dt == 1.0
    np.testing.assert_allclose(tr.state[0, :4], [200, 200, 1, 1])
    np.testing.assert_allclose(tr.state[-1, :2], [250, 250], atol=1e-9)
    assert not tr.weave.any() and len(tr.turn_end) == 0


def test_a_left_turn_is_negative_omega_and_turns_the_course_anticlockwise_seen_from_above():
    tr = build_track([Segment("L", 10, 0.1)], vel_ne=(1.0, 0.0))  # heading North, turn left
    assert np.all(tr.state[1:, 4] < 0)
    assert heading(tr.state[-1, 2:4]) == pytest.approx(-1.0, abs=1e-12)  # course 1 rad toward West
    assert tr.state[-1, 1] < tr.state[0, 1]  # the ship ends West of its start
    tr = build_track([Segment("R", 10, 0.1)], vel_ne=(1.0, 0.0))
    assert np.all(tr.state[1:, 4] > 0) and heading(tr.state[-1, 2:4]) == pytest.approx(1.0, abs=1e-12)


def test_the_pi_turn_reverses_the_course_and_keeps_the_speed():
    tr = pi_turn_track()
    np.testing.assert_allclose(tr.state[-1, 2:4], -tr.state[0, 2:4], atol=1e-9)
    assert np.all(np.isclose(np.hypot(tr.state[:, 2], tr.state[:, 3]), np.sqrt(2)))
    assert (tr.kind == "L").sum() == round(np.pi / 0.1) and len(tr.turn_end) == 1


def test_a_weave_alternates_its_turns_and_returns_to_its_course_after_each_pair():
    tr = weave_track(n_turns=4, turn_steps=10, straight_steps=12)
    kinds = [k for i, k in enumerate(tr.kind) if k != "S" and (i == 0 or tr.kind[i - 1] != k)]
    assert kinds == ["L", "R", "L", "R"] and len(tr.turn_end) == 4
    h = heading(tr.state[:, 2:4])
    np.testing.assert_allclose(h[tr.turn_end[1]], h[0], atol=1e-9)  # L then R of equal angle
    first = int(np.flatnonzero(tr.kind != "S")[0])
    assert tr.weave[first:tr.turn_end[-1] + 1].all() and not tr.weave[:first].any()
    assert not non_weave_track().weave.any()


def test_a_rotated_and_moved_track_keeps_its_turns_and_ends_where_asked():
    tr = weave_track(n_turns=3)
    rot = tr.transformed(rotate_rad=np.pi / 2).moved_to_end_at((-1000.0, 1000.0))
    np.testing.assert_allclose(rot.state[-1, :2], [-1000, 1000], atol=1e-9)
    np.testing.assert_array_equal(rot.state[:, 4], tr.state[:, 4])
    np.testing.assert_allclose(np.diff(heading(rot.state[:, 2:4])) % (2 * np.pi),
                               np.diff(heading(tr.state[:, 2:4])) % (2 * np.pi), atol=1e-9)


def test_sensor_noise_is_seeded_and_vectorised_over_seeds():
    tr = straight_track(20)
    a = gps_measure(tr, 4, np.random.default_rng(3))
    b = gps_measure(tr, 4, np.random.default_rng(3))
    assert a.shape == (4, 21, 2)
    np.testing.assert_array_equal(a, b)
    z = radar_measure(tr, 500, np.random.default_rng(4))
    e = Radar2DModel().residual(z, Radar2DModel().h(tr.state))
    np.testing.assert_allclose(e.reshape(-1, 3).std(axis=0), [10, 0.005, 3], rtol=0.05)


@pytest.mark.parametrize("dt", [0.0, -1.0, np.nan, np.inf, "1"])
def test_a_track_refuses_a_step_that_is_not_a_positive_finite_time(dt):
    with pytest.raises(ValueError, match="dt must be a positive finite step"):
        build_track([Segment("S", 5)], dt=dt)


@pytest.mark.parametrize("sigma", [-1.0, np.nan, np.inf, "1"])
def test_gps_measurements_refuse_a_negative_or_non_finite_sigma(sigma):
    with pytest.raises(ValueError, match="sigma_m must be a finite number >= 0"):
        gps_measure(straight_track(5), 2, np.random.default_rng(0), sigma)


def test_gps_measurements_with_zero_sigma_are_the_exact_positions():
    tr = straight_track(5)
    np.testing.assert_array_equal(gps_measure(tr, 2, np.random.default_rng(0), 0.0)[1], tr.state[:, :2])


@pytest.mark.parametrize("omega", [0.0, -0.0, np.nan, np.inf, 7.0, "0.1"])
def test_the_pi_turn_refuses_a_turn_rate_that_gives_no_turn(omega):
    with pytest.raises(ValueError, match="pi_turn_track: omega must be a non-zero finite turn rate"):
        pi_turn_track(omega=omega)
