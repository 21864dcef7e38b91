"""Rotations: closed forms, SciPy's ``Rotation`` as oracle, ROS ENU/FLU <-> NED/FRD cases.

Hypothesis round trips live in ``tests/properties/test_frames_properties.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation, Slerp

from pipeline.frames import rotations as rot

DEG = np.pi / 180.0


def _random_quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _same_rotation(q, p, atol=1e-12):
    """|q·p| == 1 (q and -q are the same rotation)."""
    dot = np.abs(np.sum(rot.quat_normalize(q) * rot.quat_normalize(p), axis=-1))
    assert_allclose(dot, 1.0, atol=atol, rtol=0)


# --- closed forms ---------------------------------------------------------------------------

def test_elementary_rotations_closed_form():
    a = 0.3
    c, s = np.cos(a), np.sin(a)
    rx = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    ry = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert_allclose(rot.euler_to_dcm(a, 0, 0), rx, atol=1e-15)
    assert_allclose(rot.euler_to_dcm(0, a, 0), ry, atol=1e-15)
    assert_allclose(rot.euler_to_dcm(0, 0, a), rz, atol=1e-15)
    # ZYX: R = Rz(yaw) Ry(pitch) Rx(roll)
    assert_allclose(rot.euler_to_dcm(0.1, 0.2, 0.3),
                    rot.euler_to_dcm(0, 0, 0.3) @ rot.euler_to_dcm(0, 0.2, 0) @ rot.euler_to_dcm(0.1, 0, 0),
                    atol=1e-15)


def test_yaw_90_maps_body_forward_to_east():
    q = rot.euler_to_quat(0.0, 0.0, np.pi / 2)
    assert_allclose(rot.quat_rotate(q, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-15)
    assert_allclose(rot.quat_rotate_inverse(q, [0.0, 1.0, 0.0]), [1.0, 0.0, 0.0], atol=1e-15)
    # positive pitch lifts the nose: body forward gets a negative down component
    q = rot.euler_to_quat(0.0, 0.2, 0.0)
    assert_allclose(rot.quat_rotate(q, [1.0, 0.0, 0.0]), [np.cos(0.2), 0.0, -np.sin(0.2)], atol=1e-15)


def test_hamilton_product_table():
    one, i, j, k = np.eye(4)
    assert_allclose(rot.quat_multiply(i, j), k)
    assert_allclose(rot.quat_multiply(j, k), i)
    assert_allclose(rot.quat_multiply(k, i), j)
    assert_allclose(rot.quat_multiply(i, i), -one)
    assert_allclose(rot.quat_multiply(j, i), -k)


def test_dcm_to_quat_is_exact_for_half_turns():
    # 180° rotations have w = 0: the thesis's trace formula (eq. 5.6) divides by zero here
    axes = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, -2, 3]], float)
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    q = np.concatenate([np.zeros((len(axes), 1)), axes], axis=1)
    back = rot.dcm_to_quat(rot.quat_to_dcm(q))
    _same_rotation(back, q, atol=1e-15)
    assert np.all(np.isfinite(back))


def test_gimbal_lock_pitch_is_exact():
    for p in (np.pi / 2, -np.pi / 2):
        _, pitch, _ = rot.quat_to_euler(rot.euler_to_quat(0.3, p, -1.1))
        assert abs(pitch - p) < 1e-15


def test_gimbal_lock_euler_recomposes_exactly():
    # 180° about (x + z)/√2 has pitch exactly -90°: only roll + yaw is defined; convention roll = 0
    for q in ([0.0, np.sqrt(0.5), 0.0, np.sqrt(0.5)], rot.euler_to_quat(0.4, np.pi / 2, 1.0)):
        roll, pitch, yaw = rot.quat_to_euler(q)
        assert abs(abs(pitch) - np.pi / 2) < 1e-15 and roll == 0.0
        _same_rotation(rot.euler_to_quat(roll, pitch, yaw), np.asarray(q), atol=1e-15)
    _, _, yaw = rot.quat_to_euler(rot.euler_to_quat(0.4, np.pi / 2, 1.0))
    assert yaw == pytest.approx(1.0 - 0.4, abs=1e-15)  # at +90° the rotation depends on yaw - roll


def test_zero_quaternion_gives_nan_without_warning():
    out = rot.quat_normalize(np.array([[0.0, 0, 0, 0], [2.0, 0, 0, 0]]))
    assert np.all(np.isnan(out[0]))
    assert_allclose(out[1], [1, 0, 0, 0])


def test_shapes_broadcast(rng):
    q = _random_quats(rng, 24).reshape(2, 3, 4, 4)
    assert rot.quat_to_dcm(q).shape == (2, 3, 4, 3, 3)
    assert rot.dcm_to_quat(rot.quat_to_dcm(q)).shape == (2, 3, 4, 4)
    assert rot.quat_rotate(q, [1.0, 2.0, 3.0]).shape == (2, 3, 4, 3)
    r, p, y = rot.quat_to_euler(q)
    assert r.shape == p.shape == y.shape == (2, 3, 4)
    assert rot.euler_to_quat(r, p, 0.0).shape == (2, 3, 4, 4)
    assert rot.quat_slerp(q, q[..., ::-1], 0.5).shape == (2, 3, 4, 4)


# --- SciPy oracle -----------------------------------------------------------------------------

def test_against_scipy_rotation(rng):
    q = _random_quats(rng, 500)
    ref = Rotation.from_quat(q, scalar_first=True)
    assert_allclose(rot.quat_to_dcm(q), ref.as_matrix(), atol=1e-14)
    v = rng.normal(size=(500, 3))
    assert_allclose(rot.quat_rotate(q, v), ref.apply(v), atol=1e-13)
    assert_allclose(rot.quat_rotate_inverse(q, v), ref.inv().apply(v), atol=1e-13)
    p = _random_quats(rng, 500)
    prod = rot.quat_multiply(p, q)
    assert_allclose(rot.quat_to_dcm(prod), (Rotation.from_quat(p, scalar_first=True) * ref).as_matrix(),
                    atol=1e-14)
    # ZYX intrinsic = scipy "ZYX" with angles (yaw, pitch, roll)
    roll, pitch, yaw = rot.quat_to_euler(q)
    assert_allclose(np.stack([yaw, pitch, roll], 1), ref.as_euler("ZYX"), atol=1e-10)
    _same_rotation(rot.euler_to_quat(roll, pitch, yaw),
                   Rotation.from_euler("ZYX", np.stack([yaw, pitch, roll], 1)).as_quat(scalar_first=True))
    _same_rotation(rot.dcm_to_quat(ref.as_matrix()), q)


def test_slerp_against_scipy(rng):
    q0, q1 = _random_quats(rng, 2)
    t = np.linspace(0.0, 1.0, 11)
    ref = Slerp([0.0, 1.0], Rotation.from_quat(np.stack([q0, q1]), scalar_first=True))(t)
    _same_rotation(rot.quat_slerp(q0, q1, t), ref.as_quat(scalar_first=True), atol=1e-13)


def test_slerp_takes_shortest_arc_and_constant_speed():
    q0 = rot.euler_to_quat(0.0, 0.0, np.radians(170.0))
    q1 = rot.euler_to_quat(0.0, 0.0, np.radians(-170.0))  # 20° away across ±180°, not 340°
    t = np.linspace(0, 1, 5)
    _, _, yaw = rot.quat_to_euler(rot.quat_slerp(q0, q1, t))
    expect = np.radians(170.0 + 20.0 * t)
    assert_allclose(np.angle(np.exp(1j * (yaw - expect))), 0.0, atol=1e-12)
    # sign of q1 does not matter; t=0 returns q0 with q0's own sign (continuity)
    assert_allclose(rot.quat_slerp(q0, -q1, t), rot.quat_slerp(q0, q1, t), atol=1e-15)
    assert_allclose(rot.quat_slerp(-q0, q1, 0.0), -q0, atol=1e-15)
    # identical end points: no division by zero, result is the quaternion itself
    assert_allclose(rot.quat_slerp(q0, q0, t), np.broadcast_to(q0, (5, 4)), atol=1e-15)


def test_quat_continuity_removes_sign_flips(rng):
    t = np.linspace(0, 4 * np.pi, 200)
    q = rot.euler_to_quat(0.3 * np.sin(t), 0.2 * np.cos(t), t)  # yaw wraps, canonical sign flips
    assert np.any(np.sum(q[1:] * q[:-1], axis=1) < 0)
    flipped = q * rng.choice([-1.0, 1.0], size=(200, 1))
    c = rot.quat_continuity(flipped)
    assert np.all(np.sum(c[1:] * c[:-1], axis=1) > 0)
    assert_allclose(c[0], flipped[0])
    _same_rotation(c, q)
    assert_allclose(rot.quat_continuity(q[0]), q[0])


# --- ROS REP 103 (ENU world, FLU body) <-> NED/FRD -------------------------------------------

def test_enu_flu_vector_maps():
    assert_allclose(rot.enu_to_ned([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0])
    assert_allclose(rot.ned_to_enu(rot.enu_to_ned([1.0, 2.0, 3.0])), [1.0, 2.0, 3.0])
    assert_allclose(rot.flu_to_frd([1.0, 2.0, 3.0]), [1.0, -2.0, -3.0])
    assert_allclose(rot.C_NED_ENU, rot.quat_to_dcm(rot.Q_NED_ENU), atol=1e-15)
    assert_allclose(rot.C_FRD_FLU, rot.quat_to_dcm(rot.Q_FLU_FRD), atol=1e-15)


@pytest.mark.parametrize(
    ("ros_rpy_deg", "ned_rpy_deg"),
    [
        ((0, 0, 0), (0, 0, 90)),      # ROS identity: level, nose east -> yaw 90° in NED
        ((0, 0, 90), (0, 0, 0)),      # nose north in ENU -> identity-ish, yaw 0 in NED
        ((0, 0, 180), (0, 0, -90)),   # nose west
        ((0, -10, 90), (0, 10, 0)),   # ROS pitch about +y (left) is nose-down positive
        ((20, 0, 90), (20, 0, 0)),    # roll about the forward axis keeps its sign
    ],
)
def test_ros_orientation_to_ned_frd(ros_rpy_deg, ned_rpy_deg):
    q_ros = rot.euler_to_quat(*np.radians(ros_rpy_deg))  # REP 103 uses the same ZYX composition
    q_ned = rot.quat_enu_flu_to_ned_frd(q_ros)
    got = np.degrees(rot.quat_to_euler(q_ned))
    assert_allclose(got, ned_rpy_deg, atol=1e-12)
    _same_rotation(rot.quat_ned_frd_to_enu_flu(q_ned), q_ros)


def test_ros_forward_axis_east_is_yaw_90():
    # the body FLU x axis pointing east in ENU is the identity ROS orientation
    q_ned = rot.quat_enu_flu_to_ned_frd([1.0, 0.0, 0.0, 0.0])
    assert_allclose(rot.quat_rotate(q_ned, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-15)
    assert_allclose(rot.quat_rotate(q_ned, [0.0, 0.0, 1.0]), [0.0, 0.0, 1.0], atol=1e-15)  # FRD down = NED down
