"""Rotations: quaternions, direction-cosine matrices, ZYX Euler angles, ENU/FLU <-> NED/FRD.

Conventions (style.md §3.2, seed 000 §1):

* Quaternions are Hamilton, scalar first, ``q = (w, x, y, z)``, and describe the attitude of the
  body frame (FRD) relative to the world frame (NED): ``v_world = R(q) v_body``.
* Euler angles are the aerospace ZYX sequence (yaw ψ about z, then pitch θ about the new y,
  then roll φ about the new x):

  .. math:: R = R_z(\\psi) R_y(\\theta) R_x(\\phi)

* ENU <-> NED swaps x/y and negates z; FLU <-> FRD negates y and z. Every reader converts
  ROS-convention data through :func:`enu_to_ned`, :func:`flu_to_frd` and
  :func:`quat_enu_flu_to_ned_frd`, so there is exactly one tested conversion.

All functions are vectorised: quaternions ``(..., 4)``, vectors ``(..., 3)``, matrices
``(..., 3, 3)``, angles ``(...)``. This module depends on NumPy only.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]


def quat_normalize(q: ArrayLike) -> F64:
    """Unit quaternion(s) with non-negative scalar part (the canonical sign)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


def quat_multiply(p: ArrayLike, q: ArrayLike) -> F64:
    """Hamilton product ``p ⊗ q`` (apply ``q`` first, then ``p``)."""
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack([
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ], axis=-1)


def quat_conj(q: ArrayLike) -> F64:
    """Conjugate (= inverse for unit quaternions)."""
    q = np.asarray(q, dtype=np.float64)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_to_dcm(q: ArrayLike) -> F64:
    """Rotation matrix ``R`` with ``v_world = R @ v_body`` from a unit quaternion (normalised here)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def dcm_to_quat(r: ArrayLike) -> F64:
    """Unit quaternion (scalar part ≥ 0) from a rotation matrix; Shepperd's method, branch per
    element on the largest of (w², x², y², z²) for full precision everywhere."""
    r = np.asarray(r, dtype=np.float64)
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack([tr, m00, m11, m22], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(r.shape[:-2] + (4,))
    # each branch computed on the whole array (cheap), then selected
    s0 = np.sqrt(np.maximum(1.0 + tr, 1e-300)) * 2
    b0 = np.stack([0.25 * s0, (r[..., 2, 1] - r[..., 1, 2]) / s0,
                   (r[..., 0, 2] - r[..., 2, 0]) / s0, (r[..., 1, 0] - r[..., 0, 1]) / s0], -1)
    s1 = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 1e-300)) * 2
    b1 = np.stack([(r[..., 2, 1] - r[..., 1, 2]) / s1, 0.25 * s1,
                   (r[..., 0, 1] + r[..., 1, 0]) / s1, (r[..., 0, 2] + r[..., 2, 0]) / s1], -1)
    s2 = np.sqrt(np.maximum(1.0 + m11 - m00 - m22, 1e-300)) * 2
    b2 = np.stack([(r[..., 0, 2] - r[..., 2, 0]) / s2, (r[..., 0, 1] + r[..., 1, 0]) / s2,
                   0.25 * s2, (r[..., 1, 2] + r[..., 2, 1]) / s2], -1)
    s3 = np.sqrt(np.maximum(1.0 + m22 - m00 - m11, 1e-300)) * 2
    b3 = np.stack([(r[..., 1, 0] - r[..., 0, 1]) / s3, (r[..., 0, 2] + r[..., 2, 0]) / s3,
                   (r[..., 1, 2] + r[..., 2, 1]) / s3, 0.25 * s3], -1)
    kk = k[..., None]
    q = np.where(kk == 0, b0, np.where(kk == 1, b1, np.where(kk == 2, b2, b3)))
    return quat_normalize(q)


def euler_to_quat(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> F64:
    """Quaternion from ZYX Euler angles (rad): ``q = q_z(yaw) ⊗ q_y(pitch) ⊗ q_x(roll)``."""
    hr = 0.5 * np.asarray(roll, dtype=np.float64)
    hp = 0.5 * np.asarray(pitch, dtype=np.float64)
    hy = 0.5 * np.asarray(yaw, dtype=np.float64)
    cr, sr, cp, sp, cy, sy = np.cos(hr), np.sin(hr), np.cos(hp), np.sin(hp), np.cos(hy), np.sin(hy)
    q = np.stack([
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ], axis=-1)
    return quat_normalize(q)


def quat_to_euler(q: ArrayLike) -> tuple[F64, F64, F64]:
    """ZYX Euler angles ``(roll, pitch, yaw)`` in rad from a quaternion; roll, yaw in (−π, π],
    pitch in [−π/2, π/2]. Near gimbal lock (|pitch| → 90°) roll and yaw are not separable;
    computation downstream uses the quaternion."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    # pitch via atan2 of (sin, cos) keeps full precision near ±90° (asin does not)
    sp = 2 * (w * y - x * z)
    cp = np.hypot(1 - 2 * (y * y + z * z) , 2 * (x * y + w * z))
    pitch = np.arctan2(sp, cp)
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def euler_to_dcm(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> F64:
    """``R = R_z(yaw) R_y(pitch) R_x(roll)`` (body FRD -> world NED)."""
    return quat_to_dcm(euler_to_quat(roll, pitch, yaw))


def dcm_to_euler(r: ArrayLike) -> tuple[F64, F64, F64]:
    """ZYX Euler angles from a rotation matrix."""
    return quat_to_euler(dcm_to_quat(r))


def quat_rotate(q: ArrayLike, v: ArrayLike) -> F64:
    """Rotate body vectors into the world frame: ``R(q) @ v``."""
    r = quat_to_dcm(q)
    return np.einsum("...ij,...j->...i", r, np.asarray(v, dtype=np.float64))


def quat_rotate_inverse(q: ArrayLike, v: ArrayLike) -> F64:
    """Rotate world vectors into the body frame: ``R(q)ᵀ @ v``."""
    r = quat_to_dcm(q)
    return np.einsum("...ji,...j->...i", r, np.asarray(v, dtype=np.float64))


# --- ROS (REP 103: ENU world, FLU body) <-> aerospace (NED world, FRD body) -----------------

#: ENU -> NED as a rotation matrix (its own inverse): (e, n, u) -> (n, e, -u)
C_NED_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
#: FLU -> FRD (its own inverse): (f, l, u) -> (f, -l, -u) = rotation by π about x
C_FRD_FLU = np.diag([1.0, -1.0, -1.0])
#: the same two rotations as quaternions
Q_NED_ENU = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])
Q_FLU_FRD = np.array([0.0, 1.0, 0.0, 0.0])


def enu_to_ned(v: ArrayLike) -> F64:
    """World vector(s) ENU -> NED: ``(e, n, u) -> (n, e, −u)``."""
    v = np.asarray(v, dtype=np.float64)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


ned_to_enu = enu_to_ned  # the map is an involution


def flu_to_frd(v: ArrayLike) -> F64:
    """Body vector(s) FLU -> FRD: ``(x, y, z) -> (x, −y, −z)``."""
    v = np.asarray(v, dtype=np.float64)
    return np.stack([v[..., 0], -v[..., 1], -v[..., 2]], axis=-1)


frd_to_flu = flu_to_frd  # the map is an involution


def quat_enu_flu_to_ned_frd(q: ArrayLike) -> F64:
    """Orientation FLU->ENU (a ROS ``orientation``) to FRD->NED (ours):
    ``q_ned_frd = q_ned_enu ⊗ q_enu_flu ⊗ q_flu_frd``."""
    return quat_normalize(quat_multiply(quat_multiply(Q_NED_ENU, q), Q_FLU_FRD))


def quat_ned_frd_to_enu_flu(q: ArrayLike) -> F64:
    """Inverse of :func:`quat_enu_flu_to_ned_frd` (for writers)."""
    return quat_normalize(quat_multiply(quat_multiply(quat_conj(Q_NED_ENU), q), quat_conj(Q_FLU_FRD)))


def quat_continuity(q: ArrayLike) -> F64:
    """Flip signs along axis 0 so consecutive quaternions have a non-negative dot product
    (``q`` and ``−q`` are the same rotation; interpolation and filtering need continuity)."""
    q = np.array(q, dtype=np.float64, copy=True)
    if len(q) < 2:
        return q
    d = np.einsum("ij,ij->i", q[1:], q[:-1])
    flips = np.concatenate([[False], d < 0])
    sign = np.where(np.logical_xor.accumulate(flips), -1.0, 1.0)
    return q * sign[:, None]
