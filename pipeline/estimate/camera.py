"""Pinhole camera, the camera→UAV→world chain and the multi-observer image likelihood (seed 001 §3, §6).

Frames (NED world, digest 001 §13 item 4)
-----------------------------------------
- **world**: local NED, ``(x, y) = (N, E)``; seed-001's ENU converts as ``N = y, E = x, D = −z``
  (:func:`enu_to_ned`), headings as ``ψ_NED = π/2 − ψ_ENU`` (:func:`yaw_enu_to_ned`).
- **body** (UAV): FRD, attitude ``R_U = Rz(ψ) Ry(θ) Rx(φ)`` body→NED (ZYX, seed 001 (3.9)).
- **gimbal**: FRD-like with its x axis along the optical axis, ``R_G = Rz(ψ_g) Ry(θ_g)`` relative
  to the body (no roll, φ_C = 0, digest §3); ``θ_g = −π/2`` looks straight down.
- **camera**: the computer-vision frame x right, y down, z along the optical axis. The thesis's
  camera frame has +y up; ours is the same up to the sign of the image y, which we take *down*
  so that pixel rows grow downward. ``p_gimbal = M p_camera`` with ``M`` = :data:`CAMERA_TO_GIMBAL`
  (forward = z, right = x, down = y), so ``R_C = R_G M``.

The chain (seed 001 (3.7)/(3.32)) is ``p^W = T_U R_U T_C R_C p^C = T̄ p^C`` as 4×4 homogeneous
matrices (:func:`camera_to_world`), and world→camera is the inverse ``T̄⁻¹`` (digest D10: the
printed (3.33) repeats the U factors; :func:`invert_pose` inverts the 4×4 exactly).

Pinhole (seed 001 (3.2)–(3.3)) in pixels: ``u = c_u + f x_C/z_C``, ``v = c_v + f y_C/z_C`` with
the principal point ``(c_u, c_v)`` the image centre; a point with ``z_C ≤ 0`` is behind the
camera (projection NaN).

Likelihood (seed 001 (3.34)–(3.35), (3.42))
-------------------------------------------
Independent observers factorise, so ``log p(z | x) = Σ_o log N(h_o(x); z_o, σ_o² I₂)``:
:class:`CameraLikelihood` implements the PF core's ``Likelihood`` protocol over packed
per-step measurement rows (:func:`pack_detections`): per observer ``[valid, u, v, σ_px,
c_N, c_E, c_D, R_wc (9, row-major)]`` where ``c`` is the camera centre and ``R_wc`` the
camera→world rotation of that step. An observer without a detection has ``valid = 0``; a step
with none is an all-NaN row (predict-only in :class:`~pipeline.estimate.pf.ParticleFilter`).
The weighting is a numba kernel, parallel over particles, linear in particles × observers.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numba
import numpy as np
from numba import njit, prange
from numpy.typing import ArrayLike, NDArray

from ..frames.rotations import quat_continuity, quat_to_dcm
from .models import wrap_angle

F64 = NDArray[np.float64]

#: fields per observer in a packed measurement row (see the module docstring)
OBS_FIELDS = 16
#: camera (x right, y down, z optical axis) → gimbal (forward, right, down): columns are the
#: camera axes expressed in the gimbal frame
CAMERA_TO_GIMBAL: F64 = np.array([[0.0, 0.0, 1.0],
                                  [1.0, 0.0, 0.0],
                                  [0.0, 1.0, 0.0]])


# --- frames -------------------------------------------------------------------------------------
def enu_to_ned(p: ArrayLike) -> F64:
    """Seed-001 ENU ``(x E, y N, z Up)`` → NED: ``N = y, E = x, D = −z`` (last axis of size 3 or 2)."""
    p = np.asarray(p, dtype=np.float64)
    out = np.empty_like(p)
    out[..., 0] = p[..., 1]
    out[..., 1] = p[..., 0]
    if p.shape[-1] > 2:
        out[..., 2] = -p[..., 2]
    return out


def ned_to_enu(p: ArrayLike) -> F64:
    """The inverse of :func:`enu_to_ned` (the map is its own inverse)."""
    return enu_to_ned(p)


def yaw_enu_to_ned(yaw: ArrayLike) -> F64:
    """Heading from E toward N (ENU, CCW) → from N toward E (NED, CW): ``π/2 − ψ``, wrapped."""
    return wrap_angle(np.pi / 2 - np.asarray(yaw, dtype=np.float64))


def rot_zyx(yaw: ArrayLike, pitch: ArrayLike, roll: ArrayLike = 0.0) -> F64:
    """``Rz(ψ) Ry(θ) Rx(φ)`` (body→world, seed 001 (3.9)), broadcast over leading axes → (..., 3, 3)."""
    y, p, r = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (yaw, pitch, roll)))
    cy, sy, cp, sp, cr, sr = np.cos(y), np.sin(y), np.cos(p), np.sin(p), np.cos(r), np.sin(r)
    R = np.empty(y.shape + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def quat_to_rot(q: ArrayLike) -> F64:
    """Hamilton quaternion ``[w, x, y, z]`` (the ``attitude`` stream, FRD→NED) → (..., 3, 3):
    :func:`pipeline.frames.rotations.quat_to_dcm`, the project's one quaternion→matrix."""
    return quat_to_dcm(q)


def homogeneous(R: ArrayLike | None = None, t: ArrayLike | None = None) -> F64:
    """4×4 ``[[R, t], [0, 1]]`` (seed 001 (3.8): ``T(d)`` is ``R = I, t = d``), broadcast → (..., 4, 4)."""
    R = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
    t = np.zeros(3) if t is None else np.asarray(t, dtype=np.float64)
    shape = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros(shape + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def invert_pose(T: ArrayLike) -> F64:
    """Exact inverse of a rigid 4×4 ``[[R, t], [0, 1]]``: ``[[Rᵀ, −Rᵀt], [0, 1]]`` (digest D10)."""
    T = np.asarray(T, dtype=np.float64)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    return homogeneous(Rt, -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3]))


def gimbal_rotation(gimbal_yaw: ArrayLike, gimbal_pitch: ArrayLike) -> F64:
    """``R_C = Rz(ψ_g) Ry(θ_g) M``: camera (CV axes) → UAV body (module docstring)."""
    return rot_zyx(gimbal_yaw, gimbal_pitch, 0.0) @ CAMERA_TO_GIMBAL


def camera_to_world(uav_pos_ned: ArrayLike, uav_rot: ArrayLike, gimbal_yaw: ArrayLike,
                    gimbal_pitch: ArrayLike, offset_body: ArrayLike = (0.0, 0.0, 0.0)) -> F64:
    """``T̄ = T_U R_U T_C R_C`` (seed 001 (3.7)): camera → NED world, (..., 4, 4).

    Parameters
    ----------
    uav_pos_ned : (..., 3)
        UAV position ``T_U`` (m, NED).
    uav_rot : (..., 3, 3)
        UAV attitude ``R_U`` body (FRD) → NED (:func:`rot_zyx` or :func:`quat_to_rot`).
    gimbal_yaw, gimbal_pitch : (...,)
        Gimbal angles relative to the body (rad), ``R_C`` by :func:`gimbal_rotation`.
    offset_body : (3,)
        Camera centre in the body frame ``T_C`` (m, FRD).
    """
    TU = homogeneous(None, uav_pos_ned)
    RU = homogeneous(uav_rot, None)
    TC = homogeneous(None, offset_body)
    RC = homogeneous(gimbal_rotation(gimbal_yaw, gimbal_pitch), None)
    return TU @ RU @ TC @ RC


def look_at_angles(uav_pos_ned: ArrayLike, uav_rot: ArrayLike, target_ned: ArrayLike) -> tuple[F64, F64]:
    """Gimbal yaw and pitch that put ``target`` on the optical axis (seed 001 (4.44)–(4.46)).

    ``η̄ = R_Uᵀ (p_t − p)/‖p_t − p‖`` in the body frame; ``ψ_g = atan2(η̄_y, η̄_x)`` and
    ``θ_g = −atan2(η̄_z, √(η̄_x² + η̄_y²))`` (the printed (4.46) drops the norm, digest D9; the
    sign because FRD's z is down, so a target below has θ_g < 0).
    """
    d = np.asarray(target_ned, dtype=np.float64) - np.asarray(uav_pos_ned, dtype=np.float64)
    eta = np.einsum("...ji,...j->...i", np.asarray(uav_rot, dtype=np.float64), d)
    yaw = np.arctan2(eta[..., 1], eta[..., 0])
    pitch = -np.arctan2(eta[..., 2], np.hypot(eta[..., 0], eta[..., 1]))
    return yaw, pitch


# --- pinhole ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PinholeCamera:
    """A pinhole camera: focal length and image size in pixels, principal point at the centre.

    ``sigma_px`` of a bearing error ``σ_ψ`` on the optical axis is ``f tan σ_ψ``
    (:meth:`sigma_px_from_bearing`; digest D1: an angular error gives a ~constant pixel error).
    """

    focal_px: float = 800.0
    width_px: int = 1280
    height_px: int = 960

    @property
    def principal(self) -> tuple[float, float]:
        return 0.5 * self.width_px, 0.5 * self.height_px

    def sigma_px_from_bearing(self, sigma_psi_rad: float) -> float:
        return float(self.focal_px * np.tan(sigma_psi_rad))

    def project_camera(self, p_cam: ArrayLike) -> F64:
        """``W(P p)`` (seed 001 (3.3)) in pixels: (..., 3) camera points → (..., 2); NaN behind."""
        p = np.asarray(p_cam, dtype=np.float64)
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            zi = np.where(z > 0, 1.0 / z, np.nan)
        cu, cv = self.principal
        return np.stack([cu + self.focal_px * p[..., 0] * zi, cv + self.focal_px * p[..., 1] * zi], axis=-1)

    def in_image(self, uv: ArrayLike) -> NDArray[np.bool_]:
        uv = np.asarray(uv, dtype=np.float64)
        return ((uv[..., 0] >= 0) & (uv[..., 0] <= self.width_px) & (uv[..., 1] >= 0)
                & (uv[..., 1] <= self.height_px))

    def project(self, points_ned: ArrayLike, T_wc: ArrayLike) -> F64:
        """World points (N, 3) seen by observers with camera→world poses ``T_wc`` (O, 4, 4) → (O, N, 2).

        ``p^C = T̄⁻¹ p^W`` per observer (digest §5 step 3), vectorised over points × observers.
        """
        P = np.asarray(points_ned, dtype=np.float64)
        T = np.asarray(T_wc, dtype=np.float64).reshape(-1, 4, 4)
        R, c = T[:, :3, :3], T[:, :3, 3]
        pc = np.einsum("oji,onj->oni", R, P[None, :, :] - c[:, None, :])
        return self.project_camera(pc)

    def ray(self, uv: ArrayLike, T_wc: ArrayLike) -> tuple[F64, F64]:
        """Back-projection (digest §3): camera centre (…, 3) and unit line-of-sight (…, 3) in the world."""
        uv = np.asarray(uv, dtype=np.float64)
        T = np.asarray(T_wc, dtype=np.float64)
        cu, cv = self.principal
        d_c = np.stack([(uv[..., 0] - cu) / self.focal_px, (uv[..., 1] - cv) / self.focal_px,
                        np.ones(uv.shape[:-1])], axis=-1)
        d_w = np.einsum("...ij,...j->...i", T[..., :3, :3], d_c)
        return T[..., :3, 3], d_w / np.linalg.norm(d_w, axis=-1, keepdims=True)


def ground_intersection(origin: ArrayLike, direction: ArrayLike, ground_d: float = 0.0) -> F64:
    """Where rays meet the plane ``D = ground_d`` (…, 3); NaN for rays not pointing down to it."""
    o = np.asarray(origin, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (ground_d - o[..., 2]) / d[..., 2]
    s = np.where(np.isfinite(s) & (s > 0), s, np.nan)
    return o + s[..., None] * d


def ray_intersection(origins: ArrayLike, directions: ArrayLike) -> F64:
    """Least-squares point nearest to ≥ 2 rays: ``(Σ(I − uuᵀ))⁻¹ Σ(I − uuᵀ) o`` (digest §3, not in the source)."""
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    u = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    P = np.eye(3)[None] - u[:, :, None] * u[:, None, :]
    return np.linalg.solve(P.sum(axis=0), np.einsum("kij,kj->i", P, o))


def sample_fixes(row: ArrayLike, camera: PinholeCamera, n: int, rng: np.random.Generator, *,
                 ground_d: float = 0.0, on_ground: bool = True, max_tries: int = 50) -> F64:
    """``n`` target positions drawn from one step's detections: the "rough distribution built
    from the first measurement(s)" of seed 001 §2.1 (digest §1 *Init*), also used to re-initialise.

    Each draw perturbs every valid detection of the packed ``row`` (:func:`pack_detections`) by
    its own measurement noise ``N(0, σ_px² I₂)``, back-projects the rays (:meth:`PinholeCamera.ray`)
    and takes their least-squares intersection ``p* = (Σ(I − uuᵀ))⁻¹ Σ(I − uuᵀ) o`` (digest §3,
    "for initialization"); with ``on_ground`` (digest D7) ``p*`` is restricted to the plane
    ``D = ground_d``, which for a single ray is its ground intersection. A draw whose point is
    behind one of the cameras (a ray pointing above the horizon, say) is drawn again, up to
    ``max_tries`` times; rows still without a point are NaN.

    The spread of the draws is thus the spread of a fix from these detections: at a 0.3 rad
    bearing error and grazing rays it is hundreds of metres, which a fixed spread around the
    mean ray–ground intersection (the first version) did not cover, so the filter started far
    from the target with no particle near it.

    Returns
    -------
    (n, 3) float, NED.
    """
    obs = np.asarray(row, dtype=np.float64).reshape(-1, OBS_FIELDS)
    obs = obs[obs[:, 0] > 0.5] if np.all(np.isfinite(obs[:, 0])) else obs[:0]
    out = np.full((int(n), 3), np.nan)
    if len(obs) == 0 or n <= 0:
        return out
    T = homogeneous(obs[:, 7:16].reshape(-1, 3, 3), obs[:, 4:7])           # (O, 4, 4)
    axis = T[:, :3, 2]                                                        # optical axes (O, 3)
    plane = bool(on_ground) or len(obs) == 1
    todo = np.arange(int(n))
    for _ in range(int(max_tries)):
        m = len(todo)
        uv = obs[None, :, 1:3] + obs[None, :, 3:4] * rng.standard_normal((m, len(obs), 2))
        o, u = camera.ray(uv, np.broadcast_to(T, (m,) + T.shape))          # (m, O, 3)
        P = np.eye(3) - u[..., :, None] * u[..., None, :]                    # (m, O, 3, 3)
        if plane:
            og = o.copy()
            og[..., 2] -= ground_d
            A = P[..., :2, :2].sum(axis=1)
            b = np.einsum("moij,moj->mi", P[..., :2, :], og)
            with np.errstate(all="ignore"):
                ok = np.abs(np.linalg.det(A)) > 1e-12
                q = np.full((m, 2), np.nan)
                q[ok] = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
            p = np.column_stack([q, np.full(m, float(ground_d))])
        else:
            A = P.sum(axis=1)
            b = np.einsum("moij,moj->mi", P, o)
            with np.errstate(all="ignore"):
                ok = np.abs(np.linalg.det(A)) > 1e-12
                p = np.full((m, 3), np.nan)
                p[ok] = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
        front = np.all(np.einsum("moj,oj->mo", p[:, None, :] - T[None, :, :3, 3], axis) > 0, axis=1)
        good = np.all(np.isfinite(p), axis=1) & front
        out[todo[good]] = p[good]
        todo = todo[~good]
        if len(todo) == 0:
            break
    return out


# --- packed measurement rows ----------------------------------------------------------------------
def pack_detections(uv: ArrayLike, sigma_px: ArrayLike, T_wc: ArrayLike) -> F64:
    """One PF measurement row from O observers' detections (module docstring).

    Parameters
    ----------
    uv : (O, 2)
        Detections (pixels); a NaN row = that observer saw nothing this step.
    sigma_px : (O,) or float
        Pixel noise standard deviation per observer.
    T_wc : (O, 4, 4)
        Camera→world poses of the step (:func:`camera_to_world`).

    Returns
    -------
    (O * OBS_FIELDS,) float; all-NaN when no observer detected the target (predict-only).
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    O = len(uv)
    T = np.asarray(T_wc, dtype=np.float64).reshape(O, 4, 4)
    sig = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64), (O,))
    valid = np.all(np.isfinite(uv), axis=1) & np.isfinite(sig) & (sig > 0) & np.all(np.isfinite(T), axis=(1, 2))
    if not np.any(valid):
        return np.full(O * OBS_FIELDS, np.nan)
    row = np.zeros((O, OBS_FIELDS))
    row[:, 0] = valid
    row[valid, 1:3] = uv[valid]
    row[:, 3] = np.where(valid, sig, 1.0)
    row[valid, 4:7] = T[valid, :3, 3]
    row[valid, 7:16] = T[valid, :3, :3].reshape(-1, 9)
    return row.reshape(-1)


#: particles from which the weighting runs on numba's thread pool (below it the thread start-up
#: and, on a loaded machine, the wait for idle cores cost more than the work)
PARALLEL_FROM = 50_000


@njit(cache=True, inline="always")
def _half_r2(dn, de, dd, p, f, cu, cv):
    """½ r² of a particle at offset (dn, de, dd) from the camera (normalised pixel residual);
    +∞ behind it. ``p`` holds the observer's hoisted constants: R_wc's columns (p^C = R_wcᵀ d),
    the detection (u0, v0) and 1/σ_px."""
    zc = p[6] * dn + p[7] * de + p[8] * dd
    if zc <= 0.0:
        return np.inf
    iz = f / zc
    ru = (cu + (p[0] * dn + p[1] * de + p[2] * dd) * iz - p[9]) * p[11]
    rv = (cv + (p[3] * dn + p[4] * de + p[5] * dd) * iz - p[10]) * p[11]
    return 0.5 * (ru * ru + rv * rv)


@njit(cache=True)
def _observer_constants(obs, o):
    """Camera centre and :func:`_half_r2`'s constants of observer ``o`` (row-major R_wc at 7 + 3r + j)."""
    p = np.empty(12)
    p[0], p[1], p[2] = obs[o, 7], obs[o, 10], obs[o, 13]
    p[3], p[4], p[5] = obs[o, 8], obs[o, 11], obs[o, 14]
    p[6], p[7], p[8] = obs[o, 9], obs[o, 12], obs[o, 15]
    p[9], p[10], p[11] = obs[o, 1], obs[o, 2], 1.0 / obs[o, 3]
    return obs[o, 4], obs[o, 5], obs[o, 6], p


@njit(cache=True)
def _loglik_const(obs):
    """Σ over detecting observers of −2 log σ − log 2π, and the first detecting observer (−1: none)."""
    const = 0.0
    first = -1
    for o in range(obs.shape[0]):
        if obs[o, 0] > 0.5:
            const += -2.0 * np.log(obs[o, 3]) - np.log(2.0 * np.pi)
            if first < 0:
                first = o
    return const, first


@njit(cache=True)
def _camera_loglik_serial(x, ip, ie, idd, ground_d, obs, f, cu, cv, out):
    # observers outer, particles inner: one streaming pass per observer, so the cost is
    # proportional to the observer count (the thesis's weight update, Fig. 6.19); the first
    # detecting observer's pass writes ``out``, so there is no separate fill pass either
    n = x.shape[0]
    const, first = _loglik_const(obs)
    if first < 0:
        for i in range(n):
            out[i] = 0.0
        return
    cn, ce, cd, p = _observer_constants(obs, first)
    for i in range(n):
        dd = (x[i, idd] if idd >= 0 else ground_d) - cd
        out[i] = const - _half_r2(x[i, ip] - cn, x[i, ie] - ce, dd, p, f, cu, cv)
    for o in range(first + 1, obs.shape[0]):
        if obs[o, 0] > 0.5:
            cn, ce, cd, p = _observer_constants(obs, o)
            for i in range(n):
                dd = (x[i, idd] if idd >= 0 else ground_d) - cd
                out[i] -= _half_r2(x[i, ip] - cn, x[i, ie] - ce, dd, p, f, cu, cv)


@njit(cache=True, parallel=True)
def _camera_loglik_parallel(x, ip, ie, idd, ground_d, obs, f, cu, cv, out):
    # the serial kernel on numba's thread pool (the same arithmetic in the same order per particle)
    n = x.shape[0]
    const, first = _loglik_const(obs)
    if first < 0:
        for i in prange(n):
            out[i] = 0.0
        return
    cn, ce, cd, p = _observer_constants(obs, first)
    for i in prange(n):
        dd = (x[i, idd] if idd >= 0 else ground_d) - cd
        out[i] = const - _half_r2(x[i, ip] - cn, x[i, ie] - ce, dd, p, f, cu, cv)
    for o in range(first + 1, obs.shape[0]):
        if obs[o, 0] > 0.5:
            cn, ce, cd, p = _observer_constants(obs, o)
            for i in prange(n):
                dd = (x[i, idd] if idd >= 0 else ground_d) - cd
                out[i] -= _half_r2(x[i, ip] - cn, x[i, ie] - ce, dd, p, f, cu, cv)


def camera_loglik(x: ArrayLike, row: ArrayLike, camera: PinholeCamera, *, pos_index: tuple[int, int] = (0, 1),
                  d_index: int | None = None, ground_d: float = 0.0, parallel: bool | None = None) -> F64:
    """``Σ_o log N(h_o(x); z_o, σ_o² I₂)`` per particle (seed 001 (3.42)); −∞ behind a camera.

    ``parallel`` None runs on numba's thread pool from :data:`PARALLEL_FROM` particles on
    (when the pool has more than one thread);
    True/False forces it (the result is the same).
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    obs = np.ascontiguousarray(np.asarray(row, dtype=np.float64).reshape(-1, OBS_FIELDS))
    out = np.empty(len(x))
    cu, cv = camera.principal
    # one numba thread: the parallel kernel is the serial loop plus the pool's start-up, so the
    # kernel (and the per-particle cost) does not change at PARALLEL_FROM
    par = (len(x) >= PARALLEL_FROM and numba.get_num_threads() > 1) if parallel is None else bool(parallel)
    kernel = _camera_loglik_parallel if par else _camera_loglik_serial
    kernel(x, int(pos_index[0]), int(pos_index[1]), -1 if d_index is None else int(d_index), float(ground_d),
           obs, float(camera.focal_px), float(cu), float(cv), out)
    return out


def camera_loglik_per_observer(x: ArrayLike, row: ArrayLike, camera: PinholeCamera, *,
                               pos_index: tuple[int, int] = (0, 1), d_index: int | None = None,
                               ground_d: float = 0.0) -> F64:
    """The numpy oracle: (O, N) per-observer log-likelihoods (NaN for an observer without a detection)."""
    x = np.asarray(x, dtype=np.float64)
    obs = np.asarray(row, dtype=np.float64).reshape(-1, OBS_FIELDS)
    d = x[:, d_index] if d_index is not None else np.full(len(x), float(ground_d))
    P = np.stack([x[:, pos_index[0]], x[:, pos_index[1]], d], axis=1)
    out = np.full((len(obs), len(x)), np.nan)
    for o, ob in enumerate(obs):
        if ob[0] <= 0.5:
            continue
        T = homogeneous(ob[7:16].reshape(3, 3), ob[4:7])
        uv = camera.project(P, T[None])[0]
        r = (uv - ob[1:3]) / ob[3]
        ll = -0.5 * np.sum(r * r, axis=1) - 2 * np.log(ob[3]) - np.log(2 * np.pi)
        out[o] = np.where(np.isfinite(ll), ll, -np.inf)
    return out


class CollapseWindow:
    r"""A χ² test of the best particle's pixel residuals over the last ``steps`` steps with
    detections (digest 001 §13 item 7, "re-init … when the max log-likelihood collapses").

    Each step with detections pushes the best particle's squared normalised residual sum
    ``Σ_o r_o²`` and its degrees of freedom ``2m`` (m detecting observers). Once the window is
    full the test fires when

    .. math::

        \sum_{k \in W} \sum_o r_{k,o}^2 > \chi^2_{1-\alpha}\Big(\sum_{k \in W} 2 m_k\Big),

    the upper-α quantile of the χ² law the sum would follow if the cloud held the target (the
    best particle's residual is at most the truth's). α is the false-alarm probability of one
    test; once the window is full it is tested at every step, over overlapping windows, so the
    false alarms over one window's length can reach about ``steps·α``.
    Why a window: with σ_ψ = 0.3 rad one detection's σ_px (247 px at f = 800) is so large that a
    per-step test cannot fire while the target is in the image (5 σ_px is wider than it), but a
    bias of one σ per image coordinate kept over one second of 3 cameras at 40 Hz (240 degrees
    of freedom: a sum near 480 against the α = 1e-6 quantile 359) always fires. The
    window empties when it fires, so the re-initialised cloud gets a full window before the next
    test. This is the one stateful part of the likelihood: one window per filter.
    """

    def __init__(self, steps: int, alpha: float) -> None:
        if int(steps) < 1 or not 0.0 < float(alpha) < 1.0:
            raise ValueError(f"CollapseWindow: need steps >= 1 and 0 < alpha < 1, got {steps}, {alpha}")
        self.steps, self.alpha = int(steps), float(alpha)
        self._buf: deque[tuple[float, int]] = deque()
        self._sq, self._dof = 0.0, 0
        self._limit: dict[int, float] = {}
        #: how many times the test fired
        self.fired = 0

    def push(self, sq: float, dof: int) -> bool:
        """Add one step's residual sum; whether the full window now rejects (then it empties)."""
        self._buf.append((float(sq), int(dof)))
        self._sq += float(sq)
        self._dof += int(dof)
        if len(self._buf) > self.steps:
            old_sq, old_dof = self._buf.popleft()
            self._sq -= old_sq
            self._dof -= old_dof
        if len(self._buf) < self.steps:
            return False
        lim = self._limit.get(self._dof)
        if lim is None:
            from scipy.stats import chi2     # once per degrees-of-freedom count, not per step

            lim = self._limit[self._dof] = float(chi2.isf(self.alpha, self._dof))
        if self._sq > lim:
            self.clear()
            self.fired += 1
            return True
        return False

    def __len__(self) -> int:
        """The steps the window holds now."""
        return len(self._buf)

    def clear(self) -> None:
        self._buf.clear()
        self._sq, self._dof = 0.0, 0


@dataclass(frozen=True)
class CameraLikelihood:
    """The PF core's ``Likelihood`` for packed camera rows (module docstring), product over observers.

    Attributes
    ----------
    camera : PinholeCamera
    pos_index : (int, int)
        The particle state's N and E components.
    d_index : int or None
        The state's D component; None puts the target on the plane ``D = ground_d`` (digest D7).
    ground_d : float
    reinit_sigma_m : float
        On re-initialisation (every weight zero) the particles' N/E are drawn around the mean
        ground intersection of the step's rays with this spread; velocity etc. are kept.
    collapse_sigma : float or None
        The collapse test of :meth:`collapsed` (digest 001 §13 item 7: "re-init from the ray
        intersection when the max log-likelihood collapses"): the step collapses when even the
        best particle's RMS normalised pixel residual exceeds this many σ_px. None: only the
        all-zero-weight guard re-initialises.
    window : CollapseWindow or None
        The same collapse judged over a window of steps (:class:`CollapseWindow`); either test
        firing re-initialises.
    """

    camera: PinholeCamera
    pos_index: tuple[int, int] = (0, 1)
    d_index: int | None = None
    ground_d: float = 0.0
    reinit_sigma_m: float = 10.0
    collapse_sigma: float | None = None
    window: CollapseWindow | None = None

    def __call__(self, x: F64, z: F64) -> F64:
        return camera_loglik(x, z, self.camera, pos_index=self.pos_index, d_index=self.d_index,
                             ground_d=self.ground_d)

    def collapsed(self, ll: ArrayLike, z: ArrayLike) -> bool:
        """Whether the maximum log-likelihood over the particles has collapsed (§13 item 7).

        With ``m`` detecting observers the log-likelihood of a particle is
        ``ℓ = Σ_o [−½ r_o² − 2 log σ_o − log 2π]`` (``r_o`` its normalised pixel residual, 2-D),
        so the best particle's mean squared residual per image coordinate is
        ``ρ² = −2 (max ℓ − Σ_o [−2 log σ_o − log 2π]) / (2m)``. The step collapses when
        ``ρ > collapse_sigma``: no particle explains the detections (the cloud has lost the
        target; with σ-sized noise ``ρ`` is near 1), or when the :attr:`window` test fires on
        the step's ``2m ρ²``. Without detections or without either test it never collapses.
        """
        if self.collapse_sigma is None and self.window is None:
            return False
        obs = np.asarray(z, dtype=np.float64).reshape(-1, OBS_FIELDS)
        ok = obs[:, 0] > 0.5
        m = int(np.count_nonzero(ok))
        if m == 0:
            return False
        best = float(np.max(np.asarray(ll, dtype=np.float64)))
        if np.isfinite(best):
            const = float(np.sum(-2.0 * np.log(obs[ok, 3]) - np.log(2.0 * np.pi)))
            sq = -2.0 * (best - const)
            fired = ((self.collapse_sigma is not None and sq / (2.0 * m) > float(self.collapse_sigma) ** 2)
                     or (self.window is not None and self.window.push(sq, 2 * m)))
        else:
            fired = True
        if fired and self.window is not None:
            self.window.clear()     # its residuals were the lost cloud's
        return bool(fired)

    def ground_fix(self, z: ArrayLike) -> F64:
        """Mean ground-plane intersection of the step's valid rays (N, E, D); NaN if none points down."""
        obs = np.asarray(z, dtype=np.float64).reshape(-1, OBS_FIELDS)
        ok = obs[:, 0] > 0.5
        if not np.any(ok):
            return np.full(3, np.nan)
        T = homogeneous(obs[ok, 7:16].reshape(-1, 3, 3), obs[ok, 4:7])
        o, d = self.camera.ray(obs[ok, 1:3], T)
        g = ground_intersection(o, d, self.ground_d)
        g = g[np.all(np.isfinite(g), axis=1)]
        return g.mean(axis=0) if len(g) else np.full(3, np.nan)

    def sample_positions(self, z: ArrayLike, n: int, rng: np.random.Generator) -> F64:
        """(n, 3) positions drawn from the step's detections by :func:`sample_fixes` (on the
        ground plane when the state has no D)."""
        return sample_fixes(z, self.camera, n, rng, ground_d=self.ground_d, on_ground=self.d_index is None)

    def reinit(self, x: F64, z: F64, rng: np.random.Generator) -> F64:
        """Particles re-drawn from the step's detections (:meth:`sample_positions`) plus
        ``N(0, reinit_sigma_m²)`` per horizontal axis; draws without a fix take the mean ground
        intersection (:meth:`ground_fix`); velocity etc. are kept (digest §13 item 7). The
        :attr:`window` empties: its residuals were the old cloud's."""
        if self.window is not None:
            self.window.clear()
        out = np.array(x, dtype=np.float64, copy=True)
        p = self.sample_positions(z, len(out), rng)
        g = self.ground_fix(z)
        bad = ~np.all(np.isfinite(p), axis=1)
        if np.any(bad):
            if not np.all(np.isfinite(g)):
                if np.all(bad):
                    return out
                g = np.nanmean(p, axis=0)
            p[bad] = g
        out[:, list(self.pos_index)] = p[:, :2] + self.reinit_sigma_m * rng.standard_normal((len(out), 2))
        if self.d_index is not None:
            out[:, self.d_index] = p[:, 2]
        return out


def observers_from_streams(camera_det, local_position, attitude, *, offset_body=(0.0, 0.0, 0.0)) -> F64:
    """Camera→world poses (K, 4, 4) of ``camera_det`` rows from the observers' pose streams.

    Each detection's observer (``instance``) takes its position from ``local_position`` and its
    attitude from ``attitude`` of the same instance, linearly interpolated in time (quaternions
    normalised after interpolation); the gimbal angles are the row's own. An instance without
    a pose fails with one line naming it.
    """
    det = camera_det
    out = np.full((len(det), 4, 4), np.nan)
    inst = np.asarray(det["instance"]).astype(int)
    for k in np.unique(inst):
        lp = local_position[np.asarray(local_position["instance"]).astype(int) == k]
        at = attitude[np.asarray(attitude["instance"]).astype(int) == k]
        missing = [name for name, d in (("local_position", lp), ("attitude", at)) if len(d) == 0]
        if missing:
            raise ValueError(f"camera_det: observer instance {k} has no pose ({' and '.join(missing)} "
                             f"has no rows for instance {k})")
        sel = inst == k
        t = np.asarray(det["t_ns"])[sel].astype(np.float64)
        lt = np.asarray(lp["t_ns"]).astype(np.float64)
        at_t = np.asarray(at["t_ns"]).astype(np.float64)
        pos = np.stack([np.interp(t, lt, np.asarray(lp[f"pos_{a}_m"], dtype=np.float64)) for a in "ned"], axis=1)
        # q and -q are one attitude and logs often keep q_w >= 0, so the stored sign flips where the
        # yaw crosses 180 deg: made continuous first, or the component-wise interpolation between
        # two such samples collapses towards another rotation (yaw 170/190 deg gave 0 deg)
        q_at = quat_continuity(np.stack([np.asarray(at[f"q_{c}"], dtype=np.float64) for c in "wxyz"], axis=1))
        q = np.stack([np.interp(t, at_t, q_at[:, j]) for j in range(4)], axis=1)
        out[sel] = camera_to_world(pos, quat_to_rot(q), np.asarray(det["gimbal_yaw_rad"])[sel],
                                   np.asarray(det["gimbal_pitch_rad"])[sel], offset_body)
    return out
