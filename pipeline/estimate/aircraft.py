"""Seed-004 Yak54 fixed-wing dynamics (Sevaldson 2012, thesis §3.3 and §4.1.1; digest §4, errata §12).

One model serves two users: the trajectory learner's EKF uses :class:`Yak54Transition` as its
process model ``f`` (``lift=False``: the thesis gives lift no formula, and the learner's bias
``β`` on the six accelerations, seed 004 §3.4, absorbs it), and the simulator flies it with
``lift=True``.

The 17-column state (:data:`YAK54_COLUMNS`) holds NED position and **NED** velocity, the
attitude quaternion (Hamilton, scalar first, body FRD -> NED), the body rates ``(p, q, r)``, the
control deflections ``(δa, δe, δr)`` (rad) and the thrust ``F`` (N). ``f`` works in body axes,
``(u, v, w) = Rᵀ v_NED`` (digest §4 "State bookkeeping"), with the equations of motion (3.15)

.. math::

    \\dot u &= vr - wq - d_x/m + g_x + F/m, &
    \\dot p &= \\big(qr(I_{yy}-I_{zz}) - B_x|p|p + M_a\\big)/I_{xx}, \\\\
    \\dot v &= wp - ur - d_y/m + g_y, &
    \\dot q &= \\big(pr(I_{zz}-I_{xx}) - B_y|q|q + M_e\\big)/I_{yy}, \\\\
    \\dot w &= uq - vp - d_z/m + g_z - l, &
    \\dot r &= \\big(pq(I_{xx}-I_{yy}) - B_z|r|r + M_r\\big)/I_{zz},

products of inertia taken as 0 (thesis §4.1.1). Errata applied (digest §12):

* gravity (3.16) uses roll φ, not yaw ψ: ``(g_x, g_y, g_z) = g(−sin θ, cos θ sin φ, cos θ cos φ)
  = Rᵀ [0, 0, g]`` (specific force; the thesis's ``g_x/m`` with ``g_x = −mg sin θ``);
* drag (4.3) keeps its sign: ``d_x = c_x u|u|`` etc. (the printed ``c_x u²`` always decelerates
  forwards, even when flying backwards);
* lift ``l`` in the ẇ equation has no formula and no ``/m`` in the thesis; here it is the
  specific force ``l = ½ρ S C_Lα α V² / m`` (:attr:`Yak54Params.cl_alpha_per_rad`), only with
  ``lift=True``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from ..frames.rotations import (
    euler_to_quat,
    quat_multiply,
    quat_rotate,
    quat_to_dcm,
)

F64 = NDArray[np.float64]

#: state columns, in order (NED position/velocity, body->NED quaternion, body rates, controls)
YAK54_COLUMNS: tuple[str, ...] = (
    "pos_n_m", "pos_e_m", "pos_d_m", "vel_n_mps", "vel_e_mps", "vel_d_mps",
    "q_w", "q_x", "q_y", "q_z", "rate_p_radps", "rate_q_radps", "rate_r_radps",
    "aileron_rad", "elevator_rad", "rudder_rad", "thrust_n")
#: columns whose rates are the six accelerations (u̇, v̇, ẇ, ṗ, q̇, ṙ): where the learner's
#: bias terms β_u … β_r (seed 004 §3.4, eq. 3.17) enter
YAK54_DRIVEN: tuple[int, ...] = (3, 4, 5, 10, 11, 12)
_N = len(YAK54_COLUMNS)


@dataclass(frozen=True)
class Yak54Params:
    """Yak54 constants (thesis Ch. 4; digest §4) plus the simulator's lift model (ours).

    Mass is Table 4.1's total (418 g); inertia Table 4.2 (products of inertia dropped, §4.1.1).
    Drag (4.3): ``d_x = drag_x u|u|`` (N), likewise y, z. Control moments (4.1), kept as printed:
    ``M_a = (a₂δa² + a₁δa)u²``, ``M_e = (e₂δe² + e₁δe)u²``, ``M_r = r₁δr u²`` (u = body-x
    speed). The thesis states that positive deflections give *negative* moments, while these
    polynomials are positive for small positive δ (digest §4, erratum 4.1): whoever maps PWM to
    δ must pick δ's sign to match the polynomial, not the text.

    Damping (4.2), flat plates with Table 4.3's ρ, C_D, l₁…R₃ (:attr:`b_x`, :attr:`b_y`,
    :attr:`b_z`). Lift (simulator only, **our choice**, the thesis has none): wing area
    ``S = span · l₂`` (mid-wing chord), thin-wing finite-span slope ``C_Lα = 2π/(1 + 2/AR)``,
    ``AR = span²/S``.
    """

    mass_kg: float = 0.418
    ixx_kgm2: float = 0.00222
    iyy_kgm2: float = 0.01676
    izz_kgm2: float = 0.01815
    g_mps2: float = 9.81
    drag_x: float = 0.03852  # N s²/m²
    drag_y: float = 0.114
    drag_z: float = 0.199
    aileron_poly: tuple[float, float] = (-0.03554, 0.04795)  # (a₂, a₁), N m s²/m² per rad^k
    elevator_poly: tuple[float, float] = (-0.02698, 0.03641)
    rudder_gain: float = 0.05490
    rho_kgpm3: float = 1.2041  # Table 4.3
    c_d: float = 1.28
    l1_m: float = 0.18  # fuselage height
    l2_m: float = 0.21  # wing chord at mid-wing
    l3_m: float = 0.14  # tail chord at mid-tail
    r1_m: float = 0.9  # body length
    r2_m: float = 0.4  # half wing
    r3_m: float = 0.2  # half tail
    span_m: float = 0.94  # thesis Ch. 4 airframe

    @property
    def b_x(self) -> float:
        """Roll damping ``B_x = ρC_D(0.0064 l₂ + 0.0004 l₃ + 0.000016402 R₁)`` (4.2), ≈ 0.0021805."""
        return self.rho_kgpm3 * self.c_d * (0.0064 * self.l2_m + 0.0004 * self.l3_m + 0.000016402 * self.r1_m)

    @property
    def b_y(self) -> float:
        """Pitch damping ``B_y = ρC_D(0.0001233 R₂ + 0.020042 R₃)`` (4.2), ≈ 0.0062540."""
        return self.rho_kgpm3 * self.c_d * (0.0001233 * self.r2_m + 0.020042 * self.r3_m)

    @property
    def b_z(self) -> float:
        """Yaw damping ``B_z = ½ρC_D · 0.0528678 · l₁`` (4.2), ≈ 0.0073334."""
        return 0.5 * self.rho_kgpm3 * self.c_d * 0.0528678 * self.l1_m

    @property
    def wing_area_m2(self) -> float:
        """``S = span · l₂`` (our choice; the thesis gives no wing area)."""
        return self.span_m * self.l2_m

    @property
    def cl_alpha_per_rad(self) -> float:
        """``C_Lα = 2π/(1 + 2/AR)``, ``AR = span²/S`` (our choice: thin wing, finite span)."""
        aspect = self.span_m ** 2 / self.wing_area_m2
        return 2.0 * np.pi / (1.0 + 2.0 / aspect)


def _state(x: ArrayLike) -> F64:
    x = np.asarray(x, dtype=np.float64)
    if x.shape[-1:] != (_N,):
        raise ValueError(f"Yak54 state must have {_N} columns (YAK54_COLUMNS), got shape {x.shape}")
    return x


def _accelerations(x: F64, vb: F64, down_b: F64, p: Yak54Params, lift: bool) -> F64:
    """(3.15) given the body velocity ``vb`` and the body components of NED down ``down_b``
    (``Rᵀ e_D``, the third row of R), so that :func:`yak54_step` builds R only once."""
    u, v, w = np.moveaxis(vb, -1, 0)
    pr, qr, rr = np.moveaxis(x[..., 10:13], -1, 0)
    da, de, dr = np.moveaxis(x[..., 13:16], -1, 0)
    m = p.mass_kg
    # (3.16) with the erratum (φ, not ψ): gravity is NED down seen from the body
    gb = p.g_mps2 * down_b
    du = v * rr - w * qr - p.drag_x * u * np.abs(u) / m + gb[..., 0] + x[..., 16] / m
    dv = w * pr - u * rr - p.drag_y * v * np.abs(v) / m + gb[..., 1]
    dw = u * qr - v * pr - p.drag_z * w * np.abs(w) / m + gb[..., 2]
    if lift:
        # along −z_body rather than normal to the airspeed: the small-α simplification that
        # matches where the thesis puts −l (the ẇ equation only)
        alpha = np.arctan2(w, u)
        dw = dw - 0.5 * p.rho_kgpm3 * p.wing_area_m2 * p.cl_alpha_per_rad * alpha * (u * u + v * v + w * w) / m
    u2 = u * u
    ma = (p.aileron_poly[0] * da * da + p.aileron_poly[1] * da) * u2
    me = (p.elevator_poly[0] * de * de + p.elevator_poly[1] * de) * u2
    mr = p.rudder_gain * dr * u2
    ix, iy, iz = p.ixx_kgm2, p.iyy_kgm2, p.izz_kgm2
    dp = (qr * rr * (iy - iz) - p.b_x * np.abs(pr) * pr + ma) / ix
    dq = (pr * rr * (iz - ix) - p.b_y * np.abs(qr) * qr + me) / iy
    dr_ = (pr * qr * (ix - iy) - p.b_z * np.abs(rr) * rr + mr) / iz
    return np.stack([du, dv, dw, dp, dq, dr_], axis=-1)


def yak54_accelerations(x: ArrayLike, params: Yak54Params = Yak54Params(), *, lift: bool = False) -> F64:
    """Body accelerations ``(u̇, v̇, ẇ, ṗ, q̇, ṙ)`` of seed 004 eq. (3.15) (see the module docstring).

    ``(u, v, w) = Rᵀ v_NED`` with ``R`` the state's body->NED rotation; gravity ``Rᵀ[0, 0, g]``
    (erratum 3.16: roll φ, not ψ); thrust ``F`` along +x_body; drag ``c u|u|`` (sign kept);
    with ``lift``, ``ẇ −= ½ρ S C_Lα α V²/m``, ``α = atan2(w, u)``, ``V = |(u, v, w)|``.

    Parameters
    ----------
    x : array-like, shape (..., 17)
        States (:data:`YAK54_COLUMNS`).
    params : Yak54Params
    lift : bool
        Add the simulator's lift term (the learner leaves it to its bias β).

    Returns
    -------
    ndarray, shape (..., 6)
        ``(u̇, v̇, ẇ)`` in m/s² (body axes, i.e. the rate of the body components as in 3.15,
        transport terms included) and ``(ṗ, q̇, ṙ)`` in rad/s².
    """
    x = _state(x)
    R = quat_to_dcm(x[..., 6:10])
    return _accelerations(x, np.einsum("...ji,...j->...i", R, x[..., 3:6]), R[..., 2, :], params, lift)


def yak54_step(x: ArrayLike, dt: float, params: Yak54Params = Yak54Params(), *, lift: bool = False) -> F64:
    """One explicit Euler step of the Yak54 model ("simple Euler integration", seed 004 §4).

    .. math::

        \\mathbf v_b' = \\mathbf v_b + \\Delta t\\,\\dot{\\mathbf v}_b,\\quad
        q' = \\frac{q \\otimes [1, \\tfrac12\\boldsymbol\\omega\\Delta t]}{|\\cdot|},\\quad
        \\mathbf v' = R(q')\\,\\mathbf v_b',\\quad
        \\mathbf r' = \\mathbf r + \\Delta t\\,\\mathbf v,\\quad
        \\boldsymbol\\omega' = \\boldsymbol\\omega + \\Delta t\\,\\dot{\\boldsymbol\\omega}

    (``q ⊗ [1, ½ωΔt]`` is the digest's ``q⊗[½ωΔt, 1]`` written scalar first). The new body
    velocity goes back to NED with the **updated** attitude ``q'``: (3.15)'s transport terms
    ``−ω×v_b`` only cancel against the frame's rotation that way, so ``v'_NED = v_NED +
    Δt R a + O(Δt²)``; the current attitude would leave an O(Δt) spurious turn of the velocity.
    The position uses the **current** NED velocity (plain forward Euler: the state at ``k``
    alone). The quaternion is renormalised but its sign is not canonicalised (continuity, no
    kink in the Jacobian). Controls and thrust are held: under the process noise they are
    random walks (digest §4 "State bookkeeping"). Stability: the quadratic roll damping makes
    the explicit step diverge once ``|p| > I_xx/(B_x Δt)`` (≈ 20 rad/s at Δt = 0.05 s), which a
    0.3 rad aileron at 10 m/s reaches (steady ``p = √(M_a/B_x)`` ≈ 25 rad/s); take smaller steps.

    Parameters
    ----------
    x : array-like, shape (..., 17)
    dt : float
        Step (s); the digest derives ≈ 0.05 s for the learner's hidden time axis.
    params : Yak54Params
    lift : bool

    Returns
    -------
    ndarray, shape (..., 17)
    """
    x = _state(x)
    q = x[..., 6:10]
    R = quat_to_dcm(q)
    vb = np.einsum("...ji,...j->...i", R, x[..., 3:6])
    acc = _accelerations(x, vb, R[..., 2, :], params, lift)
    omega = x[..., 10:13]
    dq = np.concatenate([np.ones_like(omega[..., :1]), 0.5 * dt * omega], axis=-1)
    q_new = quat_multiply(q, dq)
    q_new = q_new / np.linalg.norm(q_new, axis=-1, keepdims=True)
    out = x.copy()
    out[..., 0:3] = x[..., 0:3] + dt * x[..., 3:6]
    out[..., 3:6] = quat_rotate(q_new, vb + dt * acc[..., :3])
    out[..., 6:10] = q_new
    out[..., 10:13] = omega + dt * acc[..., 3:]
    return out


def yak54_jacobian(x: ArrayLike, dt: float, params: Yak54Params = Yak54Params(), *, lift: bool = False,
                   eps: ArrayLike | None = None) -> F64:
    """``∂ yak54_step / ∂x`` by central differences, all 2×17 perturbed states in one batched call.

    .. math:: J_{:,j} = \\frac{f(x + h_j e_j) - f(x - h_j e_j)}{(x_j + h_j) - (x_j - h_j)}

    (the denominator as actually represented, not ``2h_j``). The digest (§11) allows analytic
    or finite-difference Jacobians; the model's non-smooth points (``|u|u``, ``|p|p``) are C¹,
    so central differences are O(h²) accurate everywhere. The quaternion columns include the
    step's renormalisation (a radial perturbation of ``q`` has ~zero effect).

    Parameters
    ----------
    x : array-like, shape (..., 17)
    dt, params, lift
        As for :func:`yak54_step`.
    eps : array-like, broadcastable to (..., 17), optional
        Absolute steps ``h``; default ``1e-6 · max(1, |x_j|)`` (relative for large components).

    Returns
    -------
    ndarray, shape (..., 17, 17)
        ``J[..., i, j] = ∂f_i/∂x_j``.
    """
    return yak54_linearise(x, dt, params, lift=lift, eps=eps)[1]


def yak54_linearise(x: ArrayLike, dt: float, params: Yak54Params = Yak54Params(), *, lift: bool = False,
                    eps: ArrayLike | None = None) -> tuple[F64, F64]:
    """``(yak54_step(x), yak54_jacobian(x))`` from one batched call of 2×17 + 1 states (the EKF
    needs both at every step; one call halves the per-step overhead)."""
    x = _state(x)
    h = 1e-6 * np.maximum(1.0, np.abs(x)) if eps is None else np.broadcast_to(np.asarray(eps, float), x.shape)
    d = h[..., :, None] * np.eye(_N)  # row j: h_j e_j
    plus, minus = x[..., None, :] + d, x[..., None, :] - d
    fs = yak54_step(np.concatenate([plus, minus, x[..., None, :]], axis=-2), dt, params, lift=lift)
    den = np.diagonal(plus - minus, axis1=-2, axis2=-1)[..., :, None]
    return fs[..., 2 * _N, :], np.swapaxes((fs[..., :_N, :] - fs[..., _N:2 * _N, :]) / den, -1, -2)


def yak54_trim(speed_mps: float, params: Yak54Params = Yak54Params(), *, heading_rad: float = 0.0,
               altitude_m: float = 50.0) -> F64:
    """Steady straight-and-level flight of the model **with lift**.

    Level flight path, so pitch ``θ = α`` and ``(u, w) = V(cos α, sin α)``; wings level, no
    rates, ``δa = δr = 0`` and ``δe = 0``: ``M_e(0) = 0`` and the model has no pitch stiffness
    (no ``C_mα``), so any ``θ`` is a pitch equilibrium: pitch is neutrally stable, and the trim
    is the one whose ``α`` balances the forces. ``α`` solves ``ẇ = g cos α − d_z/m − l = 0``
    (bracketed in [0, π/2] by ``ẇ(0) = g > 0`` and ``ẇ(π/2) < 0``); then ``u̇ = 0`` is linear
    in ``F``: ``F = d_x + m g sin α``. Both are evaluated through :func:`yak54_accelerations`, so
    the trim is exact for the model as coded. (The thesis's motor gives at most 10 N.)

    Parameters
    ----------
    speed_mps : float
        Airspeed = ground speed ``V > 0`` (no wind).
    params : Yak54Params
    heading_rad, altitude_m : float
        Course ψ (rad from north, towards east); height above the NED origin (``pos_d = −h``).

    Returns
    -------
    ndarray, shape (17,)
    """
    if not speed_mps > 0:
        raise ValueError(f"yak54_trim: speed must be positive, got {speed_mps}")

    def state(alpha: float, thrust: float) -> F64:
        x = np.zeros(_N)
        x[2] = -altitude_m
        x[3:5] = speed_mps * np.cos(heading_rad), speed_mps * np.sin(heading_rad)
        x[6:10] = euler_to_quat(0.0, alpha, heading_rad)
        x[16] = thrust
        return x

    alpha = brentq(lambda a: yak54_accelerations(state(a, 0.0), params, lift=True)[2], 0.0, 0.5 * np.pi,
                   xtol=1e-15)
    thrust = -params.mass_kg * yak54_accelerations(state(alpha, 0.0), params, lift=True)[0]
    return state(alpha, thrust)


class Yak54Transition:
    """The Yak54 model as a nonlinear EKF transition (``NonlinearTransitionModel``).

    ``x_{k+1} = f(x_k, dt) + w``, ``w ~ N(0, Q)``, ``f`` = :func:`yak54_step`, ``F_k`` =
    :func:`yak54_jacobian`. ``Q`` is the learner's Σ^(z) (seed 004 §3.2), one fixed matrix per
    hidden step, so :meth:`noise` ignores ``dt``. :meth:`matrix` raises TypeError.

    Parameters
    ----------
    Q : array-like, shape (17, 17)
        Process-noise covariance.
    params : Yak54Params
    lift : bool
        False for the learner, which leaves lift to its bias β.
    """

    def __init__(self, Q: ArrayLike, params: Yak54Params = Yak54Params(), lift: bool = False) -> None:
        Q = np.array(Q, dtype=np.float64)
        if Q.shape != (_N, _N):
            raise ValueError(f"Yak54Transition: Q must be ({_N}, {_N}), got {Q.shape}")
        Q.setflags(write=False)  # handed out by noise(); shared, so not writable
        self.Q, self.params, self.lift = Q, params, lift

    def f(self, x: ArrayLike, dt: float) -> F64:  # (R, 17) -> (R, 17)
        return yak54_step(x, dt, self.params, lift=self.lift)

    def jacobian(self, x: ArrayLike, dt: float) -> F64:  # (R, 17) -> (R, 17, 17)
        return yak54_jacobian(x, dt, self.params, lift=self.lift)

    def linearise(self, x: ArrayLike, dt: float) -> tuple[F64, F64]:  # f and its Jacobian at once
        return yak54_linearise(x, dt, self.params, lift=self.lift)

    def noise(self, dt: float) -> F64:  # Q, read-only
        return self.Q

    def matrix(self, dt: float) -> F64:
        raise TypeError("Yak54Transition is nonlinear and has no transition matrix; use f(x, dt) and "
                        "jacobian(x, dt) (the NonlinearTransitionModel protocol)")
