"""Simulated demos with a known intent (issue 15, Build item 4): the τ warps follow the seed's
step model, the truth is kept, the noise and pilot deviation have the set sizes, the attitude
follows the flight path, and the same rng gives the same demos."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.frames.rotations import quat_rotate
from pipeline.simulate.demos import (COLUMNS, REFERENCES, DemoSimSettings, intended_trajectory,
                                     simulate_demos)

SMALL = DemoSimSettings(duration_s=12.0)


@pytest.mark.parametrize("reference", REFERENCES)
def test_each_demo_sits_on_the_intent_through_its_true_warp(reference):
    ds = simulate_demos(reference, n_demos=5, rng=np.random.default_rng(1), settings=SMALL)
    L = len(ds.intended)
    assert ds.intended.shape == (L, 13) and ds.columns == COLUMNS and ds.reference == reference
    assert ds.dt == SMALL.dt_s and ds.dt_hidden == SMALL.dt_s / 2
    assert len(ds.demos) == len(ds.tau_true) == 5
    for y, tau in zip(ds.demos, ds.tau_true):
        assert tau[0] == 0 and tau[-1] <= L - 1 and set(np.unique(np.diff(tau))) <= {1, 2, 3}
        assert y.shape == (len(tau), 13)
        # about half as many samples as hidden steps (mean step 2)
        assert 0.4 * L < len(y) < 0.6 * L
        # position error: white noise (0.5 m) plus the pilot deviation (1 m): a few metres at most
        e = np.linalg.norm(y[:, :3] - ds.intended[tau, :3], axis=1)
        assert 0.3 < np.sqrt(np.mean(e ** 2)) < 6.0
        np.testing.assert_allclose(np.linalg.norm(y[:, 9:13], axis=1), 1.0)
        assert np.all(np.einsum("ij,ij->i", y[1:, 9:13], y[:-1, 9:13]) > 0)


def test_the_step_frequencies_follow_d_and_the_same_rng_gives_the_same_demos():
    s = DemoSimSettings(duration_s=60.0, step_probs=(0.1, 0.5, 0.4))
    a = simulate_demos("loop", n_demos=4, rng=np.random.default_rng(7), settings=s)
    b = simulate_demos("loop", n_demos=4, rng=np.random.default_rng(7), settings=s)
    c = simulate_demos("loop", n_demos=4, rng=np.random.default_rng(8), settings=s)
    steps = np.concatenate([np.diff(t) for t in a.tau_true])
    freq = np.array([(steps == i).mean() for i in (1, 2, 3)])
    np.testing.assert_allclose(freq, s.step_probs, atol=0.04)
    for x, y in zip(a.demos, b.demos):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a.demos[0][:50], c.demos[0][:50])


def test_without_noise_or_pilot_the_demos_are_exact_samples_of_the_intent():
    s = DemoSimSettings(duration_s=10.0, sensor_sigma=(0, 0, 0, 0), pilot_sigma_m=0.0)
    ds = simulate_demos("pull_up", n_demos=2, rng=np.random.default_rng(0), settings=s)
    for y, tau in zip(ds.demos, ds.tau_true):
        np.testing.assert_allclose(y, ds.intended[tau], atol=1e-12)


def test_the_references_fly_what_they_say_and_the_attitude_follows_the_flight_path():
    s = DemoSimSettings(duration_s=30.0)
    level, dth = intended_trajectory("level_turns", s)
    np.testing.assert_allclose(level[:, 2], -s.altitude_m, atol=1e-9)
    v = level[:, 3:5]
    # two 180° turns: the heading comes back round
    assert np.dot(v[0], v[-1]) > 0.99 * s.speed_mps ** 2
    assert np.min(v[:, 0]) < -0.99 * s.speed_mps
    pull, _ = intended_trajectory("pull_up", s)
    # ends climbing vertically and slowly (a hover-like pull-up)
    assert pull[-1, 5] < 0 and abs(pull[-1, 3]) < 1e-6 and np.linalg.norm(pull[-1, 3:6]) < 0.2 * s.speed_mps
    loop, _ = intended_trajectory("loop", s)
    assert np.min(loop[:, 3]) < -0.99 * s.speed_mps  # flying backwards at the top
    assert loop[:, 2].min() < -s.altitude_m - 20  # climbed through the loop
    for z in (level, pull, loop):
        x_body = quat_rotate(z[:, 9:13], np.array([1.0, 0.0, 0.0]))
        vel = z[:, 3:6] / np.linalg.norm(z[:, 3:6], axis=1, keepdims=True)
        np.testing.assert_allclose(np.einsum("ij,ij->i", x_body, vel), 1.0, atol=1e-9)
    # inverted at the top of the loop: body z points up
    top = np.argmin(loop[:, 3])
    assert quat_rotate(loop[top, 9:13], np.array([0.0, 0.0, 1.0]))[2] < -0.9


def test_bad_settings_and_references_are_refused_with_one_clear_line():
    with pytest.raises(ValueError, match="pilot_tau_s"):
        DemoSimSettings(pilot_tau_s=0.5)
    with pytest.raises(ValueError, match="step_probs"):
        DemoSimSettings(step_probs=(0.5, 0.5, 0.5))
    with pytest.raises(ValueError, match="unknown reference 'barrel'"):
        simulate_demos("barrel", rng=np.random.default_rng(0))


def test_the_yak54_references_fly_from_trim_and_their_demos_keep_17_columns_and_the_true_warp():
    from pipeline.estimate.aircraft import YAK54_COLUMNS
    from pipeline.simulate.demos import YAK54_REFERENCES, simulate_yak54_demos, yak54_intended
    s = DemoSimSettings(duration_s=12.0)
    level, dth = yak54_intended("yak54_level", s)
    assert dth == s.dt_s / 2 and level.shape == (int(round(12.0 / dth)) + 1, 17)
    # trimmed straight and level: height and speed hold (the simulator's lift balances weight)
    np.testing.assert_allclose(-level[:, 2], s.altitude_m, atol=0.05)
    np.testing.assert_allclose(np.linalg.norm(level[:, 3:6], axis=1), s.yak54_speed_mps, atol=0.01)
    up, _ = yak54_intended("yak54_pull_up", s)
    height = -up[:, 2]
    assert height.min() > s.altitude_m - 1.0 and height.max() > s.altitude_m + 30.0   # it climbs
    np.testing.assert_allclose(np.linalg.norm(up[:, 6:10], axis=1), 1.0, atol=1e-12)
    assert set(YAK54_REFERENCES) == {"yak54_level", "yak54_pull_up"}
    a = simulate_yak54_demos("yak54_pull_up", n_demos=3, rng=np.random.default_rng(4), settings=s)
    b = simulate_yak54_demos("yak54_pull_up", n_demos=3, rng=np.random.default_rng(4), settings=s)
    assert a.columns == YAK54_COLUMNS and a.intended.shape == up.shape
    for y, yb, tau in zip(a.demos, b.demos, a.tau_true):
        np.testing.assert_array_equal(y, yb)
        assert y.shape == (len(tau), 17) and tau[0] == 0 and set(np.unique(np.diff(tau))) <= {1, 2, 3}
        assert np.linalg.norm(y[:, :3] - up[tau, :3], axis=1).max() < 6.0
        np.testing.assert_allclose(y[:, 13:17].mean(axis=0), up[tau, 13:17].mean(axis=0), atol=0.01)
    with pytest.raises(ValueError, match="unknown reference 'barrel'"):
        simulate_yak54_demos("barrel", rng=np.random.default_rng(0), settings=s)
    with pytest.raises(ValueError, match="yak54_sensor_sigma"):
        DemoSimSettings(yak54_sensor_sigma=(0.1, 0.1))
