"""Physics of the seed-000 quadcopter: hover, exact integration, limits on 100-run samples."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.simulate import maneuvers as mv
from pipeline.simulate.quadcopter import (
    CommandSample, QuadParams, _foh_coefficients, body_rates, gauss_markov, integrate, simulate)
from pipeline.simulate.scenarios import SimSettings, run_named, time_grid

N_RUNS = 100


@pytest.fixture(scope="module")
def settings():
    return SimSettings()


@pytest.fixture(scope="module")
def batches(settings):
    """100 disturbed runs of each maneuver (one batch each), seeded."""
    return {m: run_named("maneuver", settings, N_RUNS, np.random.default_rng([7, i]), m)
            for i, m in enumerate(mv.MANEUVERS)}


def test_hover_needs_weight_thrust():
    p = QuadParams()
    t = time_grid(10.0, 200.0)
    cmd = CommandSample(np.ones(len(t)), np.zeros((len(t), 3)), np.zeros((len(t), 3)))
    tr = simulate(cmd, t, p, yaw0=np.array([0.3]), pos0=np.array([[1.0, 2.0, -10.0]]))
    np.testing.assert_allclose(tr.thrust_N, p.mass_kg * p.g_mps2, rtol=1e-15)
    assert np.max(np.abs(tr.acc)) < 1e-12
    assert np.max(np.abs(tr.pos[0] - [1.0, 2.0, -10.0])) < 1e-9
    # 1 % more thrust climbs: the sign of thrust along -z_B in NED
    cmd2 = CommandSample(np.full(len(t), 1.01), cmd.euler, cmd.euler_rate)
    tr2 = simulate(cmd2, t, p, yaw0=np.zeros(1), pos0=np.zeros((1, 3)), vel0=np.zeros((1, 3)))
    assert tr2.acc[0, 0, 2] == pytest.approx(-0.01 * p.g_mps2, rel=1e-12)
    assert tr2.pos[0, -1, 2] < -1.0


def test_integration_matches_closed_form_step_response():
    """Constant forcing f from rest: v = f(1−e^{−kt})/k, r = f t/k − f(1−e^{−kt})/k²."""
    p = QuadParams(drag_kgps=(0.25, 0.1, 0.0))
    t = time_grid(5.0, 100.0)
    f = np.broadcast_to(np.array([1.5, -2.0, 3.0]), (1, len(t), 3)).copy()
    pos, vel, acc = integrate(f, np.zeros((1, 3)), np.zeros((1, 3)), 0.01, p)
    for ax, k in enumerate(p.k):
        fa = f[0, 0, ax]
        if k == 0:
            v_ref, r_ref = fa * t, 0.5 * fa * t * t
        else:
            v_ref = fa * (1 - np.exp(-k * t)) / k
            r_ref = fa * t / k - fa * (1 - np.exp(-k * t)) / k ** 2
        np.testing.assert_allclose(vel[0, :, ax], v_ref, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(pos[0, :, ax], r_ref, rtol=1e-9, atol=1e-10)


def test_foh_ramp_exact():
    """A ramp f = c t is reproduced exactly by the first-order hold (any step)."""
    k, h = 0.7, 0.05
    e, b0, b1 = _foh_coefficients(k, h)
    c = 2.0
    t = np.arange(0, 3.0, h)
    v_ref = c * (t / k - (1 - np.exp(-k * t)) / k ** 2)
    v = np.zeros_like(t)
    for n in range(len(t) - 1):
        v[n + 1] = e * v[n] + b0 * c * t[n] + b1 * c * t[n + 1]
    np.testing.assert_allclose(v, v_ref, rtol=1e-11, atol=1e-13)


def test_body_rates_from_euler_rates():
    """p, q, r against the angular velocity from finite differences of the DCM (ω× = Rᵀ Ṙ)."""
    from pipeline.frames.rotations import euler_to_dcm

    rng = np.random.default_rng(3)
    e = rng.uniform(-0.8, 0.8, (50, 3))
    de = rng.uniform(-1, 1, (50, 3))
    h = 1e-6
    rp, rm = euler_to_dcm(*(e + h * de).T), euler_to_dcm(*(e - h * de).T)
    r = euler_to_dcm(*e.T)
    w = np.einsum("nji,njk->nik", r, (rp - rm) / (2 * h))
    w_ref = np.stack([w[:, 2, 1], w[:, 0, 2], w[:, 1, 0]], axis=-1)
    np.testing.assert_allclose(body_rates(e, de), w_ref, atol=1e-8)


def test_gauss_markov_statistics():
    """Knot values: stationary σ and e^{-Δ/τ} autocorrelation; smooth in between; clipped norm."""
    rng = np.random.default_rng(11)
    dt, knot = 0.01, 0.1
    d = gauss_markov(200, 4001, dt, 2.0, 0.3, rng, knot_s=knot)
    dk = d[:, ::10]  # the knots themselves
    assert np.std(dk) == pytest.approx(0.3, rel=0.05)
    lag = 20  # 2 s = tau -> correlation e^-1
    c = np.mean(dk[:, :-lag] * dk[:, lag:]) / np.var(dk)
    assert c == pytest.approx(np.exp(-1), abs=0.04)
    # C1: second differences are O(dt^2) small compared with the knot increments
    assert np.max(np.abs(np.diff(d, 2, axis=1))) < 0.2 * np.max(np.abs(np.diff(dk, axis=1)))
    dc = gauss_markov(5, 4000, 0.01, 0.5, 0.3, np.random.default_rng(1), clip_mps2=0.4)
    assert np.linalg.norm(dc, axis=-1).max() <= 0.4 + 1e-12
    assert np.linalg.norm(dc, axis=-1).max() > 0.3


@pytest.mark.parametrize("man", mv.MANEUVERS)
def test_limits_hold_on_every_run(batches, man):
    """|angle| ≤ 50°, |v| ≤ 40 m/s, |a| ≤ 10 m/s² (vector norms, disturbance included)."""
    tr = batches[man]
    # 25 s maneuver, after the 3 s low-dynamic transition except for M2 (seed 000 §2.4)
    assert tr.n_runs == N_RUNS and tr.t_s[-1] == pytest.approx(25.0 + tr.meta["maneuver_start_s"])
    assert np.max(np.abs(np.rad2deg(tr.euler[..., :2]))) <= 50.0
    assert np.max(np.linalg.norm(tr.vel, axis=-1)) <= 40.0
    assert np.max(np.linalg.norm(tr.acc, axis=-1)) <= 10.0
    assert np.max(np.abs(tr.dist)) > 0  # the disturbance is really in there


@pytest.mark.parametrize("man", mv.MANEUVERS)
def test_velocity_differences_equal_acceleration(batches, man):
    tr = batches[man]
    dt = tr.t_s[1] - tr.t_s[0]
    fd = (tr.vel[:, 2:] - tr.vel[:, :-2]) / (2 * dt)
    # central differences of the integrator's output: the worst relative error is ~6.6e-4 (acc)
    # and ~3.9e-5 (vel) over the maneuvers, so 2e-3 and 1e-4 leave ~3x headroom
    rel = np.max(np.abs(fd - tr.acc[:, 1:-1])) / np.max(np.abs(tr.acc))
    assert rel <= 2e-3, (man, rel)
    # and positions difference to velocity
    fdp = (tr.pos[:, 2:] - tr.pos[:, :-2]) / (2 * dt)
    rel_v = np.max(np.abs(fdp - tr.vel[:, 1:-1])) / np.max(np.abs(tr.vel))
    assert rel_v <= 1e-4, (man, rel_v)


def test_commands_smooth(settings):
    """Commands C1: Euler-rate channel equals the derivative of the angles, and is continuous."""
    for man, cmd in mv.default_maneuvers().items():
        t = time_grid(25.0, 1000.0)
        c = cmd.sample(t)
        fd = np.gradient(c.euler, t, axis=0)
        assert np.max(np.abs(fd - c.euler_rate)) < 2e-3, man
        # continuity: halving the step halves the largest increment (a jump would not shrink)
        c2 = cmd.sample(time_grid(25.0, 2000.0))
        for a1, a2 in ((c.euler_rate, c2.euler_rate), (c.thr, c2.thr), (c.euler, c2.euler)):
            m1, m2 = np.max(np.abs(np.diff(a1, axis=0))), np.max(np.abs(np.diff(a2, axis=0)))
            assert m2 < 0.6 * m1, man


def test_rate_config_floor():
    from pipeline.config import ConfigError

    with pytest.raises(ConfigError, match="rate_hz"):
        SimSettings.from_config({"rate_hz": 50})
    with pytest.raises(ConfigError, match="unknown key"):
        SimSettings.from_config({"vehicle": {"mass": 1.0}})
    st = SimSettings.from_config({"vehicle": {"mass_kg": 1.2, "drag_kgps": 0.3}})
    assert st.vehicle.mass_kg == 1.2 and st.vehicle.drag_kgps == (0.3, 0.3, 0.3)
