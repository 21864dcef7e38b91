"""The seed-004 Yak54 dynamics model (thesis eqs. 3.15, 4.1–4.3; digest §4, errata §12)."""

from dataclasses import replace

import numpy as np
import pytest

from pipeline.estimate.aircraft import (
    YAK54_COLUMNS,
    YAK54_DRIVEN,
    Yak54Params,
    Yak54Transition,
    yak54_accelerations,
    yak54_jacobian,
    yak54_step,
    yak54_trim,
)
from pipeline.frames.rotations import euler_to_quat, quat_to_euler

P = Yak54Params()
I = {name: k for k, name in enumerate(YAK54_COLUMNS)}


def state(vel_ned=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0), rates=(0.0, 0.0, 0.0), controls=(0.0, 0.0, 0.0),
          thrust=0.0):
    x = np.zeros(17)
    x[3:6], x[6:10], x[10:13], x[13:16], x[16] = vel_ned, euler_to_quat(*rpy), rates, controls, thrust
    return x


def flying_states(n, seed=4):
    """Generic states: ~10 m/s forward, any attitude, moderate rates, small deflections, thrust.
    (Small: the flat-plate roll damping is weak, so a 0.3 rad aileron at 10 m/s drives p towards
    ~25 rad/s, where the explicit Euler step at 0.05 s is unstable, see yak54_step.)"""
    rng = np.random.default_rng(seed)
    x = np.zeros((n, 17))
    x[:, :3] = rng.normal(0, 20, (n, 3))
    x[:, 3:6] = rng.normal(0, 1, (n, 3)) + [10.0, 0.0, 0.0]
    x[:, 6:10] = euler_to_quat(*rng.uniform(-1.0, 1.0, (3, n)))
    x[:, 10:13] = rng.normal(0, 1.0, (n, 3))
    x[:, 13:16] = rng.uniform(-0.05, 0.05, (n, 3))
    x[:, 16] = rng.uniform(0, 8, n)
    return x


def test_the_layout_has_17_columns_and_the_driven_ones_are_the_ned_velocity_and_body_rates():
    assert len(YAK54_COLUMNS) == 17
    assert [YAK54_COLUMNS[k] for k in YAK54_DRIVEN] == [
        "vel_n_mps", "vel_e_mps", "vel_d_mps", "rate_p_radps", "rate_q_radps", "rate_r_radps"]


def test_the_flat_plate_damping_totals_match_the_digest():
    assert P.rho_kgpm3 * P.c_d == pytest.approx(1.541248, rel=1e-12)
    assert P.b_x == pytest.approx(0.0021805, rel=1e-4)
    assert P.b_y == pytest.approx(0.0062540, rel=1e-4)
    assert P.b_z == pytest.approx(0.0073334, rel=1e-4)


def test_at_rest_and_level_gravity_is_straight_down_the_body_z_axis():
    np.testing.assert_allclose(yak54_accelerations(state(), P), [0, 0, 9.81, 0, 0, 0], atol=1e-15)


def test_rolled_90_degrees_right_gravity_points_along_body_y_so_the_formula_uses_roll_not_yaw():
    np.testing.assert_allclose(yak54_accelerations(state(rpy=(np.pi / 2, 0, 0)), P)[:3], [0, 9.81, 0],
                               atol=1e-12)
    # the thesis's ψ in (3.16) would put a yawed, level aircraft's gravity sideways: it must not
    np.testing.assert_allclose(yak54_accelerations(state(rpy=(0, 0, 1.0)), P)[:3], [0, 0, 9.81], atol=1e-12)


def test_pitched_up_gravity_decelerates_along_body_x():
    np.testing.assert_allclose(yak54_accelerations(state(rpy=(0, 0.3, 0)), P)[:3],
                               [-9.81 * np.sin(0.3), 0, 9.81 * np.cos(0.3)], atol=1e-12)


def test_drag_keeps_the_sign_of_the_velocity():
    fwd = yak54_accelerations(state(vel_ned=(5.0, 0, 0)), P)[0]
    back = yak54_accelerations(state(vel_ned=(-5.0, 0, 0)), P)[0]
    assert fwd == pytest.approx(-0.03852 * 25 / 0.418, rel=1e-12)  # level: no gravity along x
    assert back == pytest.approx(-fwd, rel=1e-12)
    side = yak54_accelerations(state(vel_ned=(0, -3.0, 0)), P)[1]
    assert side == pytest.approx(0.114 * 9 / 0.418, rel=1e-12)


def test_thrust_accelerates_along_body_x():
    assert yak54_accelerations(state(thrust=2.0), P)[0] == pytest.approx(2.0 / 0.418, rel=1e-12)


@pytest.mark.parametrize("p", [2.0, -2.0])
def test_roll_damping_alone_decays_the_roll_rate(p):
    acc = yak54_accelerations(state(rates=(p, 0, 0)), P)
    np.testing.assert_allclose(acc[3:], [-P.b_x * abs(p) * p / P.ixx_kgm2, 0, 0], rtol=1e-12, atol=1e-15)
    assert np.sign(acc[3]) == -np.sign(p)


def test_the_gyroscopic_and_transport_terms_match_eq_3_15_on_a_hand_example():
    # at rest in the air (no control moments, no drag) with p, q, r = 0.3, −0.4, 0.5
    p, q, r = 0.3, -0.4, 0.5
    acc = yak54_accelerations(state(rates=(p, q, r)), P)
    ix, iy, iz = 0.00222, 0.01676, 0.01815
    expected_pqr = [(q * r * (iy - iz) - P.b_x * abs(p) * p) / ix,
                    (p * r * (iz - ix) - P.b_y * abs(q) * q) / iy,
                    (p * q * (ix - iy) - P.b_z * abs(r) * r) / iz]
    np.testing.assert_allclose(acc[3:], expected_pqr, rtol=1e-12)
    # written out: q̇ = (pr(I_zz − I_xx) − B_y|q|q)/I_yy = (0.15·0.01593 + 0.0062540·0.16)/0.01676
    assert acc[4] == pytest.approx((0.15 * 0.01593 + 0.006253952834560001 * 0.16) / 0.01676, rel=1e-9)
    # transport terms: body velocity (10, 0, 1) with the same rates, level (vel_ned = body)
    acc = yak54_accelerations(state(vel_ned=(10.0, 0, 1.0), rates=(p, q, r)), P)
    u, v, w = 10.0, 0.0, 1.0
    np.testing.assert_allclose(acc[:3], [v * r - w * q - 0.03852 * u * u / 0.418,
                                         w * p - u * r,
                                         u * q - v * p - 0.199 * w * w / 0.418 + 9.81], rtol=1e-12)


def test_the_control_moments_follow_the_printed_polynomials_in_body_x_speed():
    acc = yak54_accelerations(state(vel_ned=(10.0, 0, 0), controls=(0.0, 0.1, 0.0)), P)
    m_e = (-0.02698 * 0.1 ** 2 + 0.03641 * 0.1) * 10.0 ** 2
    assert m_e == pytest.approx(0.33712)
    assert acc[4] == pytest.approx(m_e / 0.01676, rel=1e-12)
    acc = yak54_accelerations(state(vel_ned=(10.0, 0, 0), controls=(-0.2, 0.0, 0.05)), P)
    assert acc[3] == pytest.approx((-0.03554 * 0.04 - 0.04795 * 0.2) * 100 / 0.00222, rel=1e-12)
    assert acc[5] == pytest.approx(0.05490 * 0.05 * 100 / 0.01815, rel=1e-12)


@pytest.mark.parametrize("speed", [10.0, 12.5, 15.0])
def test_the_trim_state_is_an_equilibrium_with_a_few_degrees_of_angle_of_attack(speed):
    x = yak54_trim(speed, P, heading_rad=0.7, altitude_m=40.0)
    acc = yak54_accelerations(x, P, lift=True)
    assert np.all(np.abs(acc) < 1e-8)
    roll, pitch, yaw = quat_to_euler(x[6:10])
    assert roll == pytest.approx(0.0, abs=1e-12) and yaw == pytest.approx(0.7, abs=1e-12)
    assert 1.0 < np.degrees(pitch) < 6.0
    np.testing.assert_allclose(x[3:6], speed * np.array([np.cos(0.7), np.sin(0.7), 0.0]), atol=1e-12)
    assert x[2] == -40.0 and 0 < x[16] < 10.0  # the motor's 10 N
    # without lift the same state sinks: lift is what holds it up
    assert yak54_accelerations(x, P)[2] > 9.0


def test_stepping_the_trim_state_for_two_seconds_stays_level():
    x0 = x = yak54_trim(12.0, P)
    for _ in range(40):
        x = yak54_step(x, 0.05, P, lift=True)
    assert abs(x[2] - x0[2]) < 0.1
    np.testing.assert_allclose(x[3:], x0[3:], atol=1e-9)
    assert x[0] == pytest.approx(24.0, rel=1e-9)


def test_a_step_keeps_the_quaternion_unit_and_the_controls_constant():
    x = flying_states(50)
    for _ in range(20):
        x = yak54_step(x, 0.05, P, lift=True)
    np.testing.assert_allclose(np.linalg.norm(x[:, 6:10], axis=1), 1.0, atol=1e-14)
    np.testing.assert_array_equal(x[:, 13:], flying_states(50)[:, 13:])


def test_a_constant_roll_rate_for_one_second_rolls_by_rate_times_one_second():
    undamped = replace(P, c_d=0.0)  # C_D = 0 switches the flat-plate damping off: p stays constant
    x = state(rates=(0.5, 0, 0))
    for _ in range(100):
        x = yak54_step(x, 0.01, undamped)
    assert x[10] == 0.5
    roll, pitch, yaw = quat_to_euler(x[6:10])
    assert roll == pytest.approx(0.5, abs=1e-4) and abs(pitch) < 1e-12 and abs(yaw) < 1e-12


def test_the_position_advances_with_the_current_velocity_and_the_velocity_turns_with_the_attitude():
    # level, u = 10, pitching up at q = 0.2: after one step the NED velocity is the *new*
    # attitude applied to the new body velocity (u̇ = −d_x/m, ẇ = uq + g)
    x = state(vel_ned=(10.0, 0, 0), rates=(0, 0.2, 0))
    dt = 0.05
    x1 = yak54_step(x, dt, P)
    np.testing.assert_allclose(x1[:3], [0.5, 0, 0], atol=1e-15)
    ub, wb = 10.0 + dt * (-0.03852 * 100 / 0.418), dt * (10.0 * 0.2 + 9.81)
    th = 2 * np.arctan(0.5 * 0.2 * dt)  # the normalised q ⊗ [1, ½ωΔt]
    np.testing.assert_allclose(x1[3:6], [ub * np.cos(th) + wb * np.sin(th), 0, -ub * np.sin(th) + wb * np.cos(th)],
                               rtol=1e-12, atol=1e-14)


def test_the_jacobian_is_a_first_order_model_of_the_step():
    x = flying_states(1, seed=11)[0]
    rng = np.random.default_rng(7)
    d = rng.normal(size=17)
    d /= np.linalg.norm(d)
    J = yak54_jacobian(x, 0.05, P, lift=True)
    f0 = yak54_step(x, 0.05, P, lift=True)
    ratio = []
    for s in (1e-2, 1e-3, 1e-4):
        h = s * d
        ratio.append(np.linalg.norm(yak54_step(x + h, 0.05, P, lift=True) - f0 - J @ h) / s)
    assert ratio[1] < 0.2 * ratio[0] and ratio[2] < 0.2 * ratio[1] and ratio[2] < 1e-3


def test_batched_jacobians_equal_the_per_state_ones():
    x = flying_states(6, seed=3).reshape(2, 3, 17)
    J = yak54_jacobian(x, 0.05, P)
    assert J.shape == (2, 3, 17, 17)
    for i in range(2):
        for j in range(3):
            np.testing.assert_allclose(J[i, j], yak54_jacobian(x[i, j], 0.05, P), rtol=1e-13, atol=1e-13)
    # controls are held: their rows are identity
    np.testing.assert_allclose(J[..., 13:, :], np.broadcast_to(np.eye(17)[13:], (2, 3, 4, 17)), atol=1e-9)
    # f and its Jacobian from one batched call are the two separate ones, for the transition too
    from pipeline.estimate.aircraft import yak54_linearise, yak54_step
    f, J2 = yak54_linearise(x, 0.05, P)
    np.testing.assert_array_equal(J2, J)
    np.testing.assert_allclose(f, yak54_step(x, 0.05, P), rtol=1e-15, atol=1e-15)
    f3, J3 = Yak54Transition(np.eye(17), P).linearise(x[0], 0.05)
    np.testing.assert_array_equal(J3, J[0])
    np.testing.assert_array_equal(f3, f[0])


def test_the_transition_is_nonlinear_and_batches_over_runs():
    Q = np.diag(np.linspace(0.01, 0.17, 17))
    tr = Yak54Transition(Q)
    x = flying_states(3)
    assert tr.f(x, 0.05).shape == (3, 17)
    np.testing.assert_array_equal(tr.f(x, 0.05), yak54_step(x, 0.05, P))
    assert tr.jacobian(x, 0.05).shape == (3, 17, 17)
    np.testing.assert_array_equal(tr.noise(0.05), Q)
    with pytest.raises(TypeError, match="nonlinear"):
        tr.matrix(0.05)
    with pytest.raises(ValueError):
        Yak54Transition(np.eye(9))
