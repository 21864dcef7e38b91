"""Input checks of the quadcopter simulator (pipeline.simulate.quadcopter.simulate): its FOH
integrator and finite differences need one uniform step of at least 2 samples."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.simulate.quadcopter import CommandSample, QuadParams, simulate, uniform_step
from pipeline.simulate.scenarios import time_grid


def _hover(t):
    n = len(t)
    return CommandSample(euler=np.zeros((n, 3)), euler_rate=np.zeros((n, 3)), thr=np.ones(n))


def _fly(t):
    return simulate(_hover(t), t, QuadParams(), yaw0=np.zeros(1), pos0=np.zeros((1, 3)), vel0=np.zeros((1, 3)))


def test_a_uniform_grid_from_the_rate_is_taken_with_its_first_step():
    t = time_grid(600.0, 400.0)                 # round-off of arange(n) / rate at large t
    assert uniform_step(t) == t[1] - t[0]
    tr = _fly(time_grid(1.0, 200.0))
    assert tr.pos.shape == (1, 201, 3) and np.all(np.isfinite(tr.pos))
    # weight thrust, level, from rest at the origin: it hovers, so every row stays put
    assert np.max(np.abs(tr.pos - tr.pos[..., :1, :])) < 1e-9 and np.max(np.abs(tr.pos[:, 0])) == 0.0
    assert np.max(np.abs(tr.vel)) < 1e-12 and np.max(np.abs(tr.acc)) < 1e-12


@pytest.mark.parametrize("t, match", [
    (np.array([0.0, 0.01, 0.02, 0.04, 0.05]), r"uniform grid; the step into row 3 is 0.02 s, the first 0.01 s"),
    (np.r_[np.arange(100) * 0.01, 0.99 + 0.01 * (1 + 1e-6)], r"uniform grid; the step into row 100"),
    (np.array([0.0]), r"at least 2 samples"),
    (np.array([]), r"at least 2 samples"),
    (np.array([0.0, 0.0, 0.0]), r"must increase"),
    (np.array([0.0, -0.01, -0.02]), r"must increase"),
    (np.array([0.0, 0.01, np.nan]), r"row 2 is not finite"),
])
def test_the_simulator_refuses_a_grid_it_would_integrate_with_the_wrong_step(t, match):
    with pytest.raises(ValueError, match=match):
        _fly(t)
