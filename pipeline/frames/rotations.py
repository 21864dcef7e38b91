"""Rotations: quaternions, direction-cosine matrices, ZYX Euler angles, ENU/FLU <-> NED/FRD.

Conventions (style.md §3.2, seed 000 §1):

* Quaternions are Hamilton, scalar first, ``q = (w, x, y, z)``, and describe the attitude of the
  body frame (FRD) relative to the world frame (NED): ``v_world = R(q) v_body``. ``q`` and ``−q``
  are the same rotation; functions that *return* an attitude pick the canonical sign ``w ≥ 0``
  (except :func:`quat_slerp` and :func:`quat_continuity`, whose point is sign continuity).
* Euler angles are the aerospace ZYX sequence (yaw ψ about z, then pitch θ about the new y,
  then roll φ about the new x):

  .. math:: R = R_z(\\psi) R_y(\\theta) R_x(\\phi)

* ENU <-> NED swaps x/y and negates z; FLU <-> FRD negates y and z. Every reader converts
  ROS-convention data (REP 103) through :func:`enu_to_ned`, :func:`flu_to_frd` and
  :func:`quat_enu_flu_to_ned_frd`, so there is exactly one tested conversion.

Seed 004 (thesis §5.3, eqs. 5.6-5.8) converts the IMU's DCM to a quaternion with the
trace-only formula ``q_w = ½√(tr R + 1)``, which divides by ``q_w`` and fails as the rotation
angle approaches 180°; :func:`dcm_to_quat` implements Shepperd's branch-on-largest-component
method instead, as the seed notes recommend. The thesis's quaternion is Kuipers' passive
(inertial -> body) one, i.e. the conjugate of ours.

All functions are vectorised: quaternions ``(..., 4)``, vectors ``(..., 3)``, matrices
``(..., 3, 3)``, angles ``(...)``; leading dimensions broadcast. This module depends on NumPy only
(SciPy's ``Rotation`` is a test oracle).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]

#: half-angle magnitude below which ZYX Euler extraction treats the attitude as gimbal-locked
_LOCK_TOL = 4.0 * np.finfo(np.float64).eps


def _unit(q: ArrayLike) -> F64:
    """``q / |q|``; a zero (or NaN) quaternion becomes NaN instead of raising a warning, so a
    missing attitude sample propagates as missing rather than aborting a whole log."""
    q = np.asarray(q, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_normalize(q: ArrayLike) -> F64:
    """Unit quaternion(s) with the canonical sign ``w ≥ 0``.

    Parameters
    ----------
    q : array-like, shape (..., 4)
        Quaternion(s) ``(w, x, y, z)``, any non-zero norm.

    Returns
    -------
    ndarray, shape (..., 4)
        ``±q/|q|`` with non-negative scalar part (NaN rows for zero input).
    """
    q = _unit(q)
    return np.where(q[..., :1] < 0, -q, q)


def quat_multiply(p: ArrayLike, q: ArrayLike) -> F64:
    """Hamilton product ``p ⊗ q`` (rotation ``q`` applied first, then ``p``).

    .. math::

        p \\otimes q = \\big(p_w q_w - \\mathbf{p}\\cdot\\mathbf{q},\\;
        p_w\\mathbf{q} + q_w\\mathbf{p} + \\mathbf{p}\\times\\mathbf{q}\\big),
        \\qquad R(p \\otimes q) = R(p)\\,R(q)

    Parameters
    ----------
    p, q : array-like, shape (..., 4)
        Quaternions, broadcast together.

    Returns
    -------
    ndarray, shape (..., 4)
        The product (not re-normalised, sign not changed).
    """
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
    """Conjugate ``(w, −x, −y, −z)``, the inverse rotation of a unit quaternion.

    Parameters
    ----------
    q : array-like, shape (..., 4)

    Returns
    -------
    ndarray, shape (..., 4)
    """
    q = np.asarray(q, dtype=np.float64)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_to_dcm(q: ArrayLike) -> F64:
    """Rotation matrix ``R`` with ``v_world = R @ v_body`` (``q`` is normalised first).

    .. math::

        R = \\begin{bmatrix}
        1-2(y^2+z^2) & 2(xy-wz) & 2(xz+wy) \\\\
        2(xy+wz) & 1-2(x^2+z^2) & 2(yz-wx) \\\\
        2(xz-wy) & 2(yz+wx) & 1-2(x^2+y^2)
        \\end{bmatrix}

    Parameters
    ----------
    q : array-like, shape (..., 4)
        Body -> world quaternion(s).

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    q = _unit(q)
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
    """Unit quaternion (``w ≥ 0``) from a rotation matrix, by Shepperd's method.

    Of the four equivalent formulas, each starting from one of

    .. math::

        4w^2 = 1 + \\operatorname{tr}R,\\quad 4x^2 = 1 + R_{00} - R_{11} - R_{22},\\quad
        4y^2 = 1 - R_{00} + R_{11} - R_{22},\\quad 4z^2 = 1 - R_{00} - R_{11} + R_{22},

    the one with the largest left side is used per element (the divisor is then ≥ 1/2), and
    the other three components come from the off-diagonal sums/differences, e.g.
    ``w = (R21 − R12)/(4x)``. This keeps full precision at every angle, including 180°
    rotations where seed 004's trace formula (thesis eq. 5.6) divides by ``w → 0``.

    Parameters
    ----------
    r : array-like, shape (..., 3, 3)
        Rotation matrix (body -> world).

    Returns
    -------
    ndarray, shape (..., 4)
    """
    r = np.asarray(r, dtype=np.float64)
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    tr = m00 + m11 + m22
    k = np.argmax(np.stack([tr, m00, m11, m22], axis=-1), axis=-1)[..., None]
    # all four branches are evaluated on the whole array (cheap, vectorised) and then selected;
    # the floor only keeps the unselected branches finite and warning-free
    s0 = 2.0 * np.sqrt(np.maximum(1.0 + tr, 1e-300))
    b0 = np.stack([0.25 * s0, (r[..., 2, 1] - r[..., 1, 2]) / s0,
                   (r[..., 0, 2] - r[..., 2, 0]) / s0, (r[..., 1, 0] - r[..., 0, 1]) / s0], -1)
    s1 = 2.0 * np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 1e-300))
    b1 = np.stack([(r[..., 2, 1] - r[..., 1, 2]) / s1, 0.25 * s1,
                   (r[..., 0, 1] + r[..., 1, 0]) / s1, (r[..., 0, 2] + r[..., 2, 0]) / s1], -1)
    s2 = 2.0 * np.sqrt(np.maximum(1.0 + m11 - m00 - m22, 1e-300))
    b2 = np.stack([(r[..., 0, 2] - r[..., 2, 0]) / s2, (r[..., 0, 1] + r[..., 1, 0]) / s2,
                   0.25 * s2, (r[..., 1, 2] + r[..., 2, 1]) / s2], -1)
    s3 = 2.0 * np.sqrt(np.maximum(1.0 + m22 - m00 - m11, 1e-300))
    b3 = np.stack([(r[..., 1, 0] - r[..., 0, 1]) / s3, (r[..., 0, 2] + r[..., 2, 0]) / s3,
                   (r[..., 1, 2] + r[..., 2, 1]) / s3, 0.25 * s3], -1)
    q = np.where(k == 0, b0, np.where(k == 1, b1, np.where(k == 2, b2, b3)))
    return quat_normalize(q)


def euler_to_quat(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> F64:
    """Quaternion from ZYX Euler angles: ``q = q_z(ψ) ⊗ q_y(θ) ⊗ q_x(φ)``.

    .. math::

        q = \\begin{bmatrix}
        c_\\phi c_\\theta c_\\psi + s_\\phi s_\\theta s_\\psi \\\\
        s_\\phi c_\\theta c_\\psi - c_\\phi s_\\theta s_\\psi \\\\
        c_\\phi s_\\theta c_\\psi + s_\\phi c_\\theta s_\\psi \\\\
        c_\\phi c_\\theta s_\\psi - s_\\phi s_\\theta c_\\psi
        \\end{bmatrix}, \\quad c_\\phi = \\cos(\\phi/2),\\ s_\\phi = \\sin(\\phi/2),\\ \\ldots

    Parameters
    ----------
    roll, pitch, yaw : array-like
        ``φ, θ, ψ`` (rad), broadcast together.

    Returns
    -------
    ndarray, shape (..., 4)
        Body FRD -> world NED quaternion, ``w ≥ 0``.
    """
    hr, hp, hy = (0.5 * np.asarray(a, dtype=np.float64) for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(hr), np.sin(hr), np.cos(hp), np.sin(hp), np.cos(hy), np.sin(hy)
    q = np.stack(np.broadcast_arrays(
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ), axis=-1)
    return quat_normalize(q)


def quat_to_euler(q: ArrayLike) -> tuple[F64, F64, F64]:
    r"""ZYX Euler angles ``(roll, pitch, yaw)`` (rad) from a quaternion, exact at every attitude.

    Half-angle form (after Bernardes & Viollet 2022, specialised to ZYX). Expanding
    ``q = q_z(ψ) ⊗ q_y(θ) ⊗ q_x(φ)`` with ``c = cos(θ/2)``, ``s = sin(θ/2)`` gives

    .. math::

        w - y &= (c - s)\cos\tfrac{\phi+\psi}{2}, & x + z &= (c - s)\sin\tfrac{\phi+\psi}{2}, \\
        w + y &= (c + s)\cos\tfrac{\phi-\psi}{2}, & x - z &= (c + s)\sin\tfrac{\phi-\psi}{2},

    and ``c ∓ s = √2 cos/sin(θ/2 + π/4) ≥ 0`` for ``|θ| ≤ π/2``, hence

    .. math::

        \theta = 2\operatorname{atan2}\big(\|(w+y, x-z)\|, \|(w-y, x+z)\|\big) - \tfrac{\pi}{2},\quad
        \phi = \Sigma + \Delta,\quad \psi = \Sigma - \Delta,

    with ``Σ = atan2(x + z, w − y)``, ``Δ = atan2(x − z, w + y)``. Every attitude converts back
    (``euler_to_quat(*quat_to_euler(q)) == ±q`` to ~1e-15), including gimbal lock
    ``θ = ±90°``, where only ``φ ∓ ψ`` is defined and the convention ``roll = 0`` is used
    (when the vanishing half-angle norm is below 4ε).
    Near lock, roll and yaw individually lose ~``ε/cos θ`` precision (their sum or difference
    does not); computation downstream uses the quaternion.

    Parameters
    ----------
    q : array-like, shape (..., 4)

    Returns
    -------
    roll, pitch, yaw : ndarray
        roll and yaw in (−π, π], pitch in [−π/2, π/2].
    """
    q = _unit(q)
    w, x, y, z = np.moveaxis(q, -1, 0)
    a = np.hypot(w - y, x + z)  # √2 cos(θ/2 + π/4): zero at θ = +90°
    b = np.hypot(w + y, x - z)  # √2 sin(θ/2 + π/4): zero at θ = −90°
    pitch = 2.0 * np.arctan2(b, a) - 0.5 * np.pi
    sigma = np.arctan2(x + z, w - y)
    delta = np.arctan2(x - z, w + y)
    # at lock Σ (or Δ) is atan2 of rounding noise; only Δ (or Σ) carries the rotation, so the
    # roll = 0 convention costs at most ~|a| ≤ 4ε in the recomposed quaternion
    lock_up, lock_down = a <= _LOCK_TOL, b <= _LOCK_TOL
    roll = np.where(lock_up | lock_down, 0.0, sigma + delta)
    yaw = np.where(lock_up, -2.0 * delta, np.where(lock_down, 2.0 * sigma, sigma - delta))
    return _wrap_pi(roll), pitch, _wrap_pi(yaw)


def _wrap_pi(a: F64) -> F64:
    """Wrap angles in (−3π, 3π] to (−π, π] exactly (no trigonometric round trip)."""
    a = np.where(a > np.pi, a - 2.0 * np.pi, a)
    return np.where(a <= -np.pi, a + 2.0 * np.pi, a)


def euler_to_dcm(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> F64:
    """``R = R_z(ψ) R_y(θ) R_x(φ)`` (body FRD -> world NED).

    Parameters
    ----------
    roll, pitch, yaw : array-like
        ``φ, θ, ψ`` (rad).

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    return quat_to_dcm(euler_to_quat(roll, pitch, yaw))


def dcm_to_euler(r: ArrayLike) -> tuple[F64, F64, F64]:
    """ZYX Euler angles ``(roll, pitch, yaw)`` (rad) from a rotation matrix (see :func:`quat_to_euler`).

    Parameters
    ----------
    r : array-like, shape (..., 3, 3)

    Returns
    -------
    roll, pitch, yaw : ndarray
    """
    return quat_to_euler(dcm_to_quat(r))


def quat_rotate(q: ArrayLike, v: ArrayLike) -> F64:
    """Rotate body vector(s) into the world frame: ``R(q) @ v``.

    Parameters
    ----------
    q : array-like, shape (..., 4)
    v : array-like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    return np.einsum("...ij,...j->...i", quat_to_dcm(q), np.asarray(v, dtype=np.float64))


def quat_rotate_inverse(q: ArrayLike, v: ArrayLike) -> F64:
    """Rotate world vector(s) into the body frame: ``R(q)ᵀ @ v``.

    Parameters
    ----------
    q : array-like, shape (..., 4)
    v : array-like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    return np.einsum("...ji,...j->...i", quat_to_dcm(q), np.asarray(v, dtype=np.float64))


def quat_slerp(q0: ArrayLike, q1: ArrayLike, t: ArrayLike) -> F64:
    """Spherical linear interpolation along the shortest arc.

    With ``q1`` sign-flipped if ``q0·q1 < 0`` (so the arc is the short one, ≤ 180° of rotation)
    and ``Ω`` the angle between the two unit 4-vectors,

    .. math::

        \\operatorname{slerp}(q_0, q_1; t) = \\frac{\\sin((1-t)\\Omega)}{\\sin\\Omega} q_0
        + \\frac{\\sin(t\\Omega)}{\\sin\\Omega} q_1,
        \\qquad \\Omega = 2\\operatorname{atan2}(|q_1 - q_0|, |q_1 + q_0|)

    ``Ω`` comes from ``atan2`` (precise at any angle, unlike ``acos`` of the dot product) and the
    weights are written with ``sinc`` so ``Ω → 0`` degrades smoothly to linear interpolation.
    ``t`` outside [0, 1] extrapolates along the same great circle.

    Parameters
    ----------
    q0, q1 : array-like, shape (..., 4)
        End-point quaternions (normalised here).
    t : array-like, shape (...)
        Interpolation parameter; broadcast against the leading dimensions of ``q0``, ``q1``.

    Returns
    -------
    ndarray, shape (..., 4)
        Unit quaternions on the arc; ``t = 0`` gives ``q0`` with ``q0``'s sign (no canonical
        sign flip, so interpolated sequences stay continuous).
    """
    q0 = _unit(q0)
    q1 = _unit(q1)
    t = np.asarray(t, dtype=np.float64)[..., None]
    q1 = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -q1, q1)
    omega = 2.0 * np.arctan2(np.linalg.norm(q1 - q0, axis=-1, keepdims=True),
                             np.linalg.norm(q1 + q0, axis=-1, keepdims=True))
    # Ω ≤ π/2 after the sign flip, so sinc(Ω/π) ≥ 2/π: no division hazard
    s = np.sinc(omega / np.pi)
    w0 = (1.0 - t) * np.sinc((1.0 - t) * omega / np.pi) / s
    w1 = t * np.sinc(t * omega / np.pi) / s
    return _unit(w0 * q0 + w1 * q1)


# --- ROS (REP 103: ENU world, FLU body) <-> aerospace (NED world, FRD body) -----------------

#: ENU -> NED as a rotation matrix (its own inverse): (e, n, u) -> (n, e, -u)
C_NED_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
#: FLU -> FRD (its own inverse): (f, l, u) -> (f, -l, -u) = rotation by π about x
C_FRD_FLU = np.diag([1.0, -1.0, -1.0])
#: the same two rotations as quaternions: π about (x + y)/√2, and π about x
Q_NED_ENU = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])
Q_FLU_FRD = np.array([0.0, 1.0, 0.0, 0.0])


def enu_to_ned(v: ArrayLike) -> F64:
    """World vector(s) ENU -> NED: ``(e, n, u) -> (n, e, −u)`` (an involution: also NED -> ENU).

    Parameters
    ----------
    v : array-like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    v = np.asarray(v, dtype=np.float64)
    return np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)


ned_to_enu = enu_to_ned  # the map is an involution


def flu_to_frd(v: ArrayLike) -> F64:
    """Body vector(s) FLU -> FRD: ``(x, y, z) -> (x, −y, −z)`` (an involution: also FRD -> FLU).

    Parameters
    ----------
    v : array-like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    v = np.asarray(v, dtype=np.float64)
    return np.stack([v[..., 0], -v[..., 1], -v[..., 2]], axis=-1)


frd_to_flu = flu_to_frd  # the map is an involution


def quat_enu_flu_to_ned_frd(q: ArrayLike) -> F64:
    """Orientation body FLU -> world ENU (a ROS ``orientation``) to body FRD -> world NED (ours).

    .. math::

        q_{NED \\leftarrow FRD} = q_{NED \\leftarrow ENU} \\otimes q_{ENU \\leftarrow FLU}
        \\otimes q_{FLU \\leftarrow FRD}

    so that ``quat_rotate(result, flu_to_frd(v)) == enu_to_ned(quat_rotate(q, v))``. A level
    vehicle facing east in ROS (identity orientation) comes out with yaw 90° in NED.

    Parameters
    ----------
    q : array-like, shape (..., 4)
        ROS orientation, scalar first ``(w, x, y, z)`` (ROS messages store ``x, y, z, w``:
        reorder before calling).

    Returns
    -------
    ndarray, shape (..., 4)
        ``w ≥ 0``.
    """
    return quat_normalize(quat_multiply(quat_multiply(Q_NED_ENU, q), Q_FLU_FRD))


def quat_ned_frd_to_enu_flu(q: ArrayLike) -> F64:
    """Inverse of :func:`quat_enu_flu_to_ned_frd` (for writers and the simulator).

    Parameters
    ----------
    q : array-like, shape (..., 4)
        Body FRD -> world NED.

    Returns
    -------
    ndarray, shape (..., 4)
        Body FLU -> world ENU, scalar first, ``w ≥ 0``.
    """
    q_enu_frd = quat_multiply(quat_conj(Q_NED_ENU), q)
    return quat_normalize(quat_multiply(q_enu_frd, quat_conj(Q_FLU_FRD)))


def quat_continuity(q: ArrayLike) -> F64:
    """Flip signs along axis 0 so consecutive quaternions have a non-negative dot product.

    ``q`` and ``−q`` are the same rotation, but interpolation, differencing and filtering need
    a continuous sequence. The first sample keeps its sign; sample ``k`` is flipped iff an odd
    number of sign reversals occur between it and sample 0.

    Parameters
    ----------
    q : array-like, shape (n_samples, ..., 4)
        Time series along axis 0 (a single quaternion ``(4,)`` is returned unchanged).

    Returns
    -------
    ndarray, same shape
    """
    q = np.array(q, dtype=np.float64, copy=True)
    if q.ndim < 2 or len(q) < 2:
        return q
    d = np.sum(q[1:] * q[:-1], axis=-1)
    flips = np.concatenate([np.zeros_like(d[:1], dtype=bool), d < 0], axis=0)
    sign = np.where(np.logical_xor.accumulate(flips, axis=0), -1.0, 1.0)
    return q * sign[..., None]
