"""Motion and measurement models shared by the simulator and the estimators.

The simulator draws its radar measurements through :class:`RadarModel` and the EKF linearises
the very same :meth:`RadarModel.h` with :meth:`RadarModel.jacobian`, so the measurement model
exists exactly once (:meth:`RadarModel.h_and_jacobian`, the EKF's batched path, computes both
in one pass and is tested equal to them).

Radar (seed 000 §3, Strong 2021 eqs. 2.18–2.22, typos fixed per §13.2). A radar at the fixed
NED site :math:`R_n` measures the 9-state ``x = [r, v, a]`` (NED, m, m/s, m/s²) as

.. math::

    \\vec\\rho = r - R_n,\\quad \\rho = |\\vec\\rho|,\\quad
    \\dot\\rho = \\frac{v^T \\vec\\rho}{\\rho},\\quad
    h(x) = \\begin{bmatrix}\\rho + \\tau_{RD}\\dot\\rho & \\rho_1/\\rho & \\rho_2/\\rho & \\dot\\rho\\end{bmatrix}^T

with :math:`\\tau_{RD}` the range–Doppler coupling time (counted once; default 0) and white
Gaussian noise :math:`R = \\operatorname{diag}(\\sigma_\\rho^2, \\sigma_u^2, \\sigma_v^2,
\\sigma_{\\dot\\rho}^2)`, Table 2.1: σ_ρ = 1.5 m, σ_u = σ_v = 45 µrad, σ_ρ̇ = 0.2 m/s.

The Jacobian (4×9, acceleration columns zero):

.. math::

    \\partial\\rho/\\partial r = \\vec\\rho^T/\\rho,\\quad
    \\partial u/\\partial r = [\\rho^2-\\rho_1^2, -\\rho_1\\rho_2, -\\rho_1\\rho_3]/\\rho^3,\\quad
    \\partial v/\\partial r = [-\\rho_1\\rho_2, \\rho^2-\\rho_2^2, -\\rho_2\\rho_3]/\\rho^3,

    \\partial\\dot\\rho/\\partial r = v^T (I - \\vec\\rho\\vec\\rho^T/\\rho^2)/\\rho,\\quad
    \\partial\\dot\\rho/\\partial v = \\vec\\rho^T/\\rho .

The thesis drops :math:`\\tau_{RD}` from H (§13.2); here the first row is the full derivative
:math:`\\partial(\\rho + \\tau_{RD}\\dot\\rho)/\\partial x` (``include_tau_in_h=False`` restores
the thesis form).

Also here: the constant-acceleration transition ``A(dt)`` of seed 000 eq. 2.16 (per-axis
``[[1, dt, dt²/2], [0, 1, dt], [0, 0, 1]]``), used by the EKF later.
"""

from __future__ import annotations

import functools
import importlib.util
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import build, cfield, validate_section
from ..preprocess.smoother import white_jerk_q1

F64 = NDArray[np.float64]

#: radar measurement components, in order
RADAR_FIELDS: tuple[str, ...] = ("range_m", "dcos_u", "dcos_v", "range_rate_mps")

_radar = functools.partial(cfield, "simulate.sensors.radar")

#: how far above the radar site's horizontal plane :meth:`RadarModel.fold` lifts a state that
#: sits in it (m): far below any position noise, yet a Jacobian column that is not zero
FOLD_MARGIN_M = 1e-3


@dataclass(frozen=True, kw_only=True)
class RadarModel:
    """Seed-000 radar measurement model (see the module docstring).

    Parameters
    ----------
    site_ned_m : tuple of 3 float
        Radar position R_n in the flight's NED frame (m).
    tau_rd_s : float
        Range–Doppler coupling time τ_RD (s).
    sigma : tuple of 4 float
        Noise standard deviations (m, 1, 1, m/s).
    include_tau_in_h : bool
        Whether the Jacobian's range row includes ∂(τ_RD ρ̇)/∂x (True: exact).
    above_site : bool
        Take the target above the site's horizontal plane (see :meth:`fold`). Off by default,
        the thesis's EKF; the flights' EKF turns it on (``estimate.ekf.above_site``).
    """

    site_ned_m: tuple[float, float, float] = _radar("site_ned_m")
    tau_rd_s: float = _radar("tau_rd_s")
    sigma: tuple[float, float, float, float] = _radar(
        ("sigma_range_m", "sigma_dcos", "sigma_dcos", "sigma_range_rate_mps"))
    include_tau_in_h: bool = field(default=True, metadata={"config_key": None})
    above_site: bool = field(default=False, metadata={"config_key": None})
    rate_hz: float = _radar("rate_hz")
    sensor_id: int = _radar("sensor_id")
    extra: dict = field(default_factory=dict, compare=False, metadata={"config_key": None})

    @classmethod
    def from_config(cls, sec: Mapping[str, Any] | None) -> "RadarModel":
        """From ``simulate.sensors.radar`` (validated and defaulted by the config schema):
        ``site_ned_m``, ``tau_rd_s``, ``rate_hz``, ``sigma_range_m``, ``sigma_dcos`` (u and v),
        ``sigma_range_rate_mps``, ``sensor_id``."""
        return build(cls, validate_section("simulate.sensors.radar", sec))

    @property
    def R(self) -> F64:
        """Measurement noise covariance (4×4)."""
        return np.diag(np.square(self.sigma))

    def h(self, x: ArrayLike) -> F64:
        """Noise-free measurement ``[ρ + τρ̇, u, v, ρ̇]`` of state(s) ``x`` (..., ≥6)."""
        x = np.asarray(x, dtype=np.float64)
        rv = x[..., 0:3] - np.asarray(self.site_ned_m)
        v = x[..., 3:6]
        rho = np.linalg.norm(rv, axis=-1)
        rdot = np.einsum("...i,...i->...", v, rv) / rho
        return np.stack([rho + self.tau_rd_s * rdot, rv[..., 0] / rho, rv[..., 1] / rho, rdot], axis=-1)

    def jacobian(self, x: ArrayLike) -> F64:
        """∂h/∂x, shape (..., 4, n_x) for states (..., n_x), n_x = 9 (CA) or 6."""
        x = np.asarray(x, dtype=np.float64)
        n_x = x.shape[-1]
        rv = x[..., 0:3] - np.asarray(self.site_ned_m)
        v = x[..., 3:6]
        rho = np.linalg.norm(rv, axis=-1)[..., None]
        p1, p2, p3 = rv[..., 0:1], rv[..., 1:2], rv[..., 2:3]
        H = np.zeros(x.shape[:-1] + (4, n_x))
        drho_dr = rv / rho
        du = np.concatenate([rho ** 2 - p1 ** 2, -p1 * p2, -p1 * p3], axis=-1) / rho ** 3
        dv = np.concatenate([-p1 * p2, rho ** 2 - p2 ** 2, -p2 * p3], axis=-1) / rho ** 3
        vr = np.einsum("...i,...i->...", v, rv)[..., None]
        drd_dr = (v - vr * rv / rho ** 2) / rho
        drd_dv = rv / rho
        H[..., 0, 0:3] = drho_dr
        H[..., 1, 0:3] = du
        H[..., 2, 0:3] = dv
        H[..., 3, 0:3] = drd_dr
        H[..., 3, 3:6] = drd_dv
        if self.include_tau_in_h and self.tau_rd_s:
            H[..., 0, 0:3] += self.tau_rd_s * drd_dr
            H[..., 0, 3:6] += self.tau_rd_s * drd_dv
        return H

    def h_and_jacobian(self, x: ArrayLike) -> tuple[F64, F64]:
        """``(h(x), ∂h/∂x)`` at once, equal to :meth:`h` and :meth:`jacobian` to round-off.

        The EKF's path: one pass over scalar planes (one array per state component, each
        spanning the runs) sharing ρ, ρ̇ and ``1/ρ`` between the two; :meth:`h` and
        :meth:`jacobian` build them with a dozen small ``(..., 3)`` temporaries each, several
        times slower on a batch of runs.

        Returns
        -------
        hx : ndarray, shape (..., 4)
        H : ndarray, shape (..., 4, n_x)
        """
        x = np.asarray(x, dtype=np.float64)
        n_x = x.shape[-1]
        s = self.site_ned_m
        if HAVE_NUMBA and x.ndim == 2 and len(x) >= _RADAR_KERNEL_FROM:
            # a Monte Carlo's runs: the same expressions in one compiled pass (bit-for-bit equal)
            return _radar_h_jacobian_kernel(kernel_input(x), float(s[0]), float(s[1]), float(s[2]),
                                            float(self.tau_rd_s), bool(self.include_tau_in_h and self.tau_rd_s))
        p0, p1, p2 = x[..., 0] - s[0], x[..., 1] - s[1], x[..., 2] - s[2]
        v0, v1, v2 = x[..., 3], x[..., 4], x[..., 5]
        rho2 = p0 * p0 + p1 * p1 + p2 * p2
        rho = np.sqrt(rho2)
        irho = 1.0 / rho
        vr = v0 * p0 + v1 * p1 + v2 * p2
        rdot = vr * irho
        e0, e1, e2 = p0 * irho, p1 * irho, p2 * irho  # ρ⃗/ρ: ∂ρ/∂r = ∂ρ̇/∂v
        hx = np.empty(x.shape[:-1] + (4,))
        tau = self.tau_rd_s
        hx[..., 0] = rho + tau * rdot
        hx[..., 1] = e0
        hx[..., 2] = e1
        hx[..., 3] = rdot
        H = np.zeros(x.shape[:-1] + (4, n_x))
        irho3 = irho / rho2
        m01, m02, m12 = -p0 * p1 * irho3, -p0 * p2 * irho3, -p1 * p2 * irho3
        H[..., 1, 0] = (rho2 - p0 * p0) * irho3
        H[..., 1, 1] = m01
        H[..., 1, 2] = m02
        H[..., 2, 0] = m01
        H[..., 2, 1] = (rho2 - p1 * p1) * irho3
        H[..., 2, 2] = m12
        c = vr / rho2  # ∂ρ̇/∂r = (v − ρ̇ ρ⃗/ρ)/ρ = (v − c ρ⃗)/ρ
        d0, d1, d2 = (v0 - c * p0) * irho, (v1 - c * p1) * irho, (v2 - c * p2) * irho
        H[..., 3, 0], H[..., 3, 1], H[..., 3, 2] = d0, d1, d2
        H[..., 3, 3], H[..., 3, 4], H[..., 3, 5] = e0, e1, e2
        if self.include_tau_in_h and tau:
            H[..., 0, 0], H[..., 0, 1], H[..., 0, 2] = e0 + tau * d0, e1 + tau * d1, e2 + tau * d2
            H[..., 0, 3], H[..., 0, 4], H[..., 0, 5] = tau * e0, tau * e1, tau * e2
        else:
            H[..., 0, 0], H[..., 0, 1], H[..., 0, 2] = e0, e1, e2
        return hx, H

    def fold(self, mean: F64, cov: F64) -> tuple[F64, F64]:
        """Move an updated state at or below the site's horizontal plane above it (the EKF's hook).

        ``h`` sees the down offset ρ₃ only through ρ, so a state and its mirror image in the
        site's horizontal plane, :math:`S x` with :math:`S` negating the down components of
        r, v and a, give the same measurement (ρ̇ too: :math:`v^T\\vec\\rho` is unchanged),
        and the Jacobian's ρ₃ column vanishes at ρ₃ = 0. An EKF started there (a vehicle on the
        ground beside a ground radar, initialised from its reference) keeps ρ₃ = 0 for good,
        whatever height the direction cosines show (the simulated calibration flight: 12.1 m
        down RMS, NIS mean 22.8 for 4 components); one that strays below tracks the mirror
        image. With ``above_site`` (``estimate.ekf.above_site``, on by default for the flights;
        :func:`pipeline.estimate.run.radar_init` takes the same side) a state with ρ₃ > 0 is
        replaced by its mirror image,
        :math:`(S\\hat x, S P S)`, which explains the measurements equally well, and one
        within :data:`FOLD_MARGIN_M` of the plane is lifted to that margin, where the
        Jacobian no longer vanishes and the direction cosines move it (a Newton-like step:
        the same track from a 1 cm or a 1 m start). A target far above the site (every
        seed-000 set: ρ₃ ≤ −5.8 m) is never touched; a white-jerk random walk that wanders
        below the site (the filter tests' truth) would be, so it is off by default.

        Parameters
        ----------
        mean : ndarray (..., n_x)
        cov : ndarray (..., n_x, n_x)
            Changed in place where a state is mirrored (the EKF may hand a caller's buffer).

        Returns
        -------
        mean, cov : the folded state (``mean`` a new array only when a state changed).
        """
        if not self.above_site:
            return mean, cov
        rho3 = mean[..., 2] - self.site_ned_m[2]
        low = rho3 > -FOLD_MARGIN_M
        if not np.any(low):
            return mean, cov
        n_x = mean.shape[-1]
        down = np.zeros(n_x, dtype=bool)
        down[2::3] = True                      # the down components of r, v and a
        mirror = (rho3 > 0)[..., None] & down
        sgn = np.where(mirror, -1.0, 1.0)
        mean = mean * sgn
        mean[..., 2] += np.where(mirror[..., 2], 2.0 * self.site_ned_m[2], 0.0)
        cov *= sgn[..., :, None] * sgn[..., None, :]
        mean[..., 2] = np.where(low, np.minimum(mean[..., 2], self.site_ned_m[2] - FOLD_MARGIN_M), mean[..., 2])
        return mean, cov

    def measure(self, x: ArrayLike, rng: np.random.Generator) -> F64:
        """``h(x) + ν`` with ν ~ N(0, R) drawn from ``rng`` (one draw per row)."""
        y = self.h(x)
        return y + rng.standard_normal(y.shape) * np.asarray(self.sigma)


def ca_transition(dt: float, n_axes: int = 3) -> F64:
    """Constant-acceleration transition for state ``[r(3), v(3), a(3)]`` (seed 000 eq. 2.16)."""
    i = np.eye(n_axes)
    return np.block([[i, dt * i, 0.5 * dt * dt * i], [0 * i, i, dt * i], [0 * i, 0 * i, i]])


#: index of each group in the CA state ``[r(3), v(3), a(3)]`` (NED)
STATE_GROUPS: dict[str, slice] = {"pos": slice(0, 3), "vel": slice(3, 6), "acc": slice(6, 9)}

#: the 9 CA state columns, in state order (the ``state`` table's names)
STATE_COLUMNS: tuple[str, ...] = (
    *(f"pos_{a}_m" for a in "ned"), *(f"vel_{a}_mps" for a in "ned"), *(f"acc_{a}_mps2" for a in "ned"))


def white_jerk_q(dt: float, q: float, n_axes: int = 3) -> F64:
    """Process noise of the CA model driven by continuous white jerk (seed 000 §3 eq. 2.16, §13.7).

    The thesis leaves Q open (§3: "Bryson's trick", no values; §13.7 suggests a white-jerk
    discrete Q tuned by Monte Carlo). Per axis, with jerk ``w(t)`` white of spectral density
    ``q`` (m²/s⁵) and ``F = [[0,1,0],[0,0,1],[0,0,0]]``, the exact discretisation
    ``Q = ∫₀^dt e^{Fτ} G q Gᵀ e^{Fᵀτ} dτ`` with ``G = [0, 0, 1]ᵀ`` is

    .. math::

        Q_1(dt, q) = q\\begin{bmatrix} dt^5/20 & dt^4/8 & dt^3/6 \\\\
                                        dt^4/8 & dt^3/3 & dt^2/2 \\\\
                                        dt^3/6 & dt^2/2 & dt \\end{bmatrix}

    (Bar-Shalom, Li & Kirubarajan 2001, eq. 6.2.3-8). The axes are independent and the state
    is ordered by group (``[r, v, a]``, as :func:`ca_transition`), so ``Q = Q_1 ⊗ I_3``.

    Parameters
    ----------
    dt : float
        Step (s).
    q : float
        Jerk power spectral density (m²/s⁵), the one tuned scalar.
    n_axes : int
        Number of axes (3: NED).

    Returns
    -------
    ndarray, shape (3 n_axes, 3 n_axes)
    """
    # the one copy of Q₁ is preprocessing's (its GPS smoother runs the same model, compiled)
    return np.kron(white_jerk_q1.py_func(float(dt), float(q)), np.eye(n_axes))


def hmm_transition(dt: float, n_axes: int = 3) -> F64:
    """HMM-input transition ``A_H`` of the EKF+HMM (seed 000 §8, eq. 4.2).

    Per axis

    .. math::

        A_H = \\begin{bmatrix} 1 & dt & 0 \\\\ 0 & 1 & 0 \\\\ 0 & 0 & 0 \\end{bmatrix},\\qquad
        x_{k+1} = A_H x_k + B \\begin{bmatrix}\\hat a_{HMM} \\\\ \\hat\\jmath_{HMM}\\end{bmatrix}

    so the predicted acceleration is the GMR input only (the state's own ``a`` is dropped); the
    covariance is propagated as ``A_H C A_Hᵀ + Q₂`` (eq. 4.4 with the §13.2 fix). State ordered
    ``[r(3), v(3), a(3)]``: ``A_H = A_{H,1} ⊗ I_3``.

    Returns
    -------
    ndarray, shape (3 n_axes, 3 n_axes)
    """
    a1 = np.array([[1.0, dt, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    return np.kron(a1, np.eye(n_axes))


def hmm_input(dt: float, n_axes: int = 3) -> F64:
    """Input matrix ``B`` of the EKF+HMM (seed 000 §8, eq. 4.3).

    Per axis

    .. math::

        B = \\begin{bmatrix} dt^2/2 & dt^3/6 \\\\ dt & dt^2/2 \\\\ 1 & dt \\end{bmatrix}

    acting on ``u = [â_HMM; ĵ_HMM]``, so ``a_{k+1} = â + dt ĵ``, ``v_{k+1} = v_k + dt â +
    dt²/2 ĵ`` and ``r_{k+1} = r_k + dt v_k + dt²/2 â + dt³/6 ĵ`` (a constant-jerk step from
    ``â``). With the state ``[r(3), v(3), a(3)]`` and ``u = [â(3), ĵ(3)]``: ``B = B_1 ⊗ I_3``.

    Returns
    -------
    ndarray, shape (3 n_axes, 2 n_axes)
    """
    b1 = np.array([[dt ** 2 / 2, dt ** 3 / 6], [dt, dt ** 2 / 2], [1.0, dt]])
    return np.kron(b1, np.eye(n_axes))


#: seed-000 names of the EKF+HMM matrices (digest §8)
A_H = hmm_transition
B = hmm_input
Q = white_jerk_q


def initial_cov(sigma: tuple[float, float, float] = (1.0, 0.1, 0.01), n_axes: int = 3) -> F64:
    """Initial covariance ``P₀ = diag(σ_r², σ_v², σ_a²)`` per axis group (seed 000 §3,
    Ch. 2 MC initialisation ``[1·randn(3); 0.1·randn(3); 0.01·randn(3)]``)."""
    return np.diag(np.repeat(np.square(np.asarray(sigma, dtype=np.float64)), n_axes))


# --------------------------------------------------------------------------------------------
# Coordinated-turn helpers, safe at ω → 0 (shared by the bearing-only bank, the IMM and the
# particle filters, seeds 001/002/003). Convention (pinned by tests): NED with (x, y) = (N, E),
# course θ measured from N toward E, ω = dθ/dt > 0 a right turn, so the velocity rotates as
# v̇_N = −ω v_E, v̇_E = ω v_N.
# --------------------------------------------------------------------------------------------

#: below this |ω T| (rad) the turn coefficients use their Taylor series: the closed forms lose
#: all digits there (1 − cos ωT cancels) while the 4-term series is exact to round-off
TURN_SERIES_BELOW = 1e-3


def turn_coefficients(omega: ArrayLike, dt: float | ArrayLike) -> tuple[F64, F64]:
    """``s = sin(ωT)/ω`` and ``c = (1 − cos ωT)/ω``, finite and smooth through ω = 0.

    .. math::

        s(\\omega) = \\frac{\\sin\\omega T}{\\omega} \\to T - \\frac{\\omega^2T^3}{6},\\qquad
        c(\\omega) = \\frac{1-\\cos\\omega T}{\\omega} \\to \\frac{\\omega T^2}{2}
                     - \\frac{\\omega^3T^4}{24}

    (Bar-Shalom, Li & Kirubarajan 2001 §11.7.1; seed 002 §2 CPPV-CT, seed 003 §3 the turn
    modes). Vectorised over any broadcastable ``omega`` and ``dt``.
    """
    w = np.asarray(omega, dtype=np.float64)
    T = np.asarray(dt, dtype=np.float64)
    wT = w * T
    small = np.abs(wT) < TURN_SERIES_BELOW
    safe = np.where(small, 1.0, w)
    wT2 = wT * wT
    s = np.where(small, T * (1.0 - wT2 / 6.0 + wT2 * wT2 / 120.0), np.sin(wT) / safe)
    c = np.where(small, T * wT * (0.5 - wT2 / 24.0 + wT2 * wT2 / 720.0), (1.0 - np.cos(wT)) / safe)
    return s, c


def turn_coefficients_one(w: float, T: float) -> tuple[float, float]:
    """:func:`turn_coefficients` of one scalar ``ω``, ``T``, in plain arithmetic that numba
    compiles (the particle kernels of ``estimate.pf_fast`` inline it): the same closed forms,
    and the same Taylor series below :data:`TURN_SERIES_BELOW`."""
    wT = w * T
    if abs(wT) < TURN_SERIES_BELOW:
        wT2 = wT * wT
        return T * (1.0 - wT2 / 6.0 + wT2 * wT2 / 120.0), T * wT * (0.5 - wT2 / 24.0 + wT2 * wT2 / 720.0)
    return math.sin(wT) / w, (1.0 - math.cos(wT)) / w


def turn_coefficient_derivatives(omega: ArrayLike, dt: float | ArrayLike) -> tuple[F64, F64]:
    """``ds/dω`` and ``dc/dω`` of :func:`turn_coefficients`, finite through ω = 0.

    .. math::

        \\frac{ds}{d\\omega} = \\frac{T\\cos\\omega T - s}{\\omega} \\to -\\frac{\\omega T^3}{3},
        \\qquad
        \\frac{dc}{d\\omega} = \\frac{T\\sin\\omega T - c}{\\omega} \\to \\frac{T^2}{2}
                               - \\frac{\\omega^2 T^4}{8}

    The ω-column of every coordinated-turn Jacobian (EKF banks, IMM modes).
    """
    w = np.asarray(omega, dtype=np.float64)
    T = np.asarray(dt, dtype=np.float64)
    wT = w * T
    small = np.abs(wT) < TURN_SERIES_BELOW
    safe = np.where(small, 1.0, w)
    s, c = turn_coefficients(w, T)
    wT2 = wT * wT
    ds = np.where(small, -T * T * wT * (1.0 / 3.0 - wT2 / 30.0), (T * np.cos(wT) - s) / safe)
    dc = np.where(small, T * T * (0.5 - wT2 / 8.0 + wT2 * wT2 / 144.0), (T * np.sin(wT) - c) / safe)
    return ds, dc


def ct_transition(x: ArrayLike, dt: float) -> F64:
    """Coordinated-turn step of ``x = [N, E, v_N, v_E, ω, …]`` (any trailing components kept).

    .. math::

        \\begin{aligned}
        N' &= N + s\\,v_N - c\\,v_E, & v_N' &= \\cos(\\omega T) v_N - \\sin(\\omega T) v_E,\\\\
        E' &= E + c\\,v_N + s\\,v_E, & v_E' &= \\sin(\\omega T) v_N + \\cos(\\omega T) v_E,
        \\end{aligned}

    with ``s, c`` from :func:`turn_coefficients` and ω unchanged: the exact solution of
    ``v̇_N = −ω v_E, v̇_E = ω v_N`` over ``T``, reducing to constant velocity at ω = 0.
    ``x`` has shape (..., ≥ 5); the leading axes (particles, filters, runs) are vectorised.
    """
    x = np.asarray(x, dtype=np.float64)
    w = x[..., 4]
    s, c = turn_coefficients(w, dt)
    cw, sw = np.cos(w * dt), np.sin(w * dt)
    out = x.copy()
    vn, ve = x[..., 2], x[..., 3]
    out[..., 0] = x[..., 0] + s * vn - c * ve
    out[..., 1] = x[..., 1] + c * vn + s * ve
    out[..., 2] = cw * vn - sw * ve
    out[..., 3] = sw * vn + cw * ve
    return out


def ct_jacobian(x: ArrayLike, dt: float) -> F64:
    """Jacobian ``∂f/∂x`` of :func:`ct_transition` (shape (..., n, n), n = x.shape[-1]).

    The ω column uses :func:`turn_coefficient_derivatives`, so it stays exact through ω = 0
    (where it is ``[−T² v_E/2, T² v_N/2, −T v_E, T v_N]``).
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[-1]
    w, vn, ve = x[..., 4], x[..., 2], x[..., 3]
    s, c = turn_coefficients(w, dt)
    ds, dc = turn_coefficient_derivatives(w, dt)
    cw, sw = np.cos(w * dt), np.sin(w * dt)
    F = np.broadcast_to(np.eye(n), x.shape[:-1] + (n, n)).copy()
    F[..., 0, 2], F[..., 0, 3], F[..., 0, 4] = s, -c, ds * vn - dc * ve
    F[..., 1, 2], F[..., 1, 3], F[..., 1, 4] = c, s, dc * vn + ds * ve
    F[..., 2, 2], F[..., 2, 3], F[..., 2, 4] = cw, -sw, -dt * (sw * vn + cw * ve)
    F[..., 3, 2], F[..., 3, 3], F[..., 3, 4] = sw, cw, dt * (cw * vn - sw * ve)
    return F


def wrap_angle(a: ArrayLike) -> F64:
    """Wrap angles to ``[−π, π)`` (bearing residuals, headings)."""
    a = np.asarray(a, dtype=np.float64)
    return (a + np.pi) % (2.0 * np.pi) - np.pi


# --------------------------------------------------------------------------------------------
# seed 002: bearing-only (issue 16). Daugherty 2018 (digest §2, §3, §5), ⚠-corrected forms
# (D1). Conventions (pinned by tests): NED with (x, y) = (N, E); β = atan2(ΔE, ΔN); the course
# θ from N toward E; ω = dθ/dt > 0 a right turn; angles in rad (D6).
#   CPPV  x = [r_N, r_E, v, θ, ω]     relative position intruder − ownship, intruder polar velocity
#   CV    x = [r_N, r_E, v, θ]
#   MPC   y = [β̇, ṙ/r, β, 1/r, ω]    modified polar coordinates
# The ownship enters as its displacement u = v_o T (CPPV/CV, "x_k = Φ(x_{k−1}) − U_k") or its
# velocity v_o (MPC), each shaped (..., 2) = (N, E).
# --------------------------------------------------------------------------------------------

#: state names of the bearing-only models (used by the IMM to embed one mode in another, D3)
CPPV_STATE: tuple[str, ...] = ("r_n_m", "r_e_m", "v_mps", "theta_rad", "omega_rps")
CV_CPPV_STATE: tuple[str, ...] = CPPV_STATE[:4]
MPC_STATE: tuple[str, ...] = ("beta_dot_rps", "rdot_over_r_ps", "beta_rad", "inv_r_pm", "omega_rps")
#: numba is a runtime dependency; a broken install falls back to the numpy paths
HAVE_NUMBA = importlib.util.find_spec("numba") is not None


def lazy_njit(fn, **options):
    """``numba.njit(cache=True, **options)(fn)``, compiled (or loaded from the cache) on the
    first call: importing numba costs ~1 s, and most users of this module never call a kernel."""
    compiled = []

    @functools.wraps(fn)
    def call(*args):
        if not compiled:
            from numba import njit
            compiled.append(njit(cache=True, **options)(fn))
        return compiled[0](*args)

    call.py_func = fn
    return call


def kernel_input(a: ArrayLike) -> F64:
    """``a`` C-contiguous, as a read-only view (no copy unless ``a`` is not contiguous). Kernels
    take every array input this way: numba compiles a separate specialisation for a read-only
    array (a broadcast view, a :class:`~pipeline.estimate.base.GaussianState`'s arrays), so
    inputs that are sometimes writable and sometimes not cost a kernel one more cold compile
    (~0.5 s for a bank kernel, ~3.5 s for the EKF's Joseph update)."""
    v = np.ascontiguousarray(a).view()
    v.flags.writeable = False
    return v


#: components that are angles (wrapped deviations, circular means)
ANGLE_STATES: frozenset[str] = frozenset({"theta_rad", "beta_rad"})


def _ownship_step(u: ArrayLike | None, shape: tuple[int, ...]) -> F64:
    return np.zeros(shape + (2,)) if u is None else np.broadcast_to(np.asarray(u, dtype=np.float64), shape + (2,))


def _polar_increment(v, th, w, dt):
    """``∫₀ᵀ v(cos, sin)(θ + ωt) dt = v(s cosθ − c sinθ, c cosθ + s sinθ)`` with the ω → 0-safe
    :func:`turn_coefficients` (equal to the thesis's ``(2v/ω) sin(ωT/2)(cos, sin)(θ + ωT/2)``;
    at ω = 0 exactly ``vT(cosθ, sinθ)``, the D2 limit)."""
    s, c = turn_coefficients(w, dt)
    ct, st = np.cos(th), np.sin(th)
    return s, c, ct, st, v * (s * ct - c * st), v * (c * ct + s * st)


def cppv_transition(x: ArrayLike, dt: float | ArrayLike, u: ArrayLike | None = None) -> F64:
    """CPPV coordinated-turn step (digest §2, eq. 3.6–3.8 with the r_E sign fixed).

    .. math::

        \\Phi(x) = \\big[r_N + \\tfrac{2v}{\\omega}\\sin\\tfrac{\\omega T}{2}\\cos a,\\;
        r_E + \\tfrac{2v}{\\omega}\\sin\\tfrac{\\omega T}{2}\\sin a,\\; v,\\; \\theta+\\omega T,\\;
        \\omega\\big] - U,\\qquad a = \\theta + \\omega T/2

    exact through ω = 0 (D2: the increment becomes ``vT(cosθ, sinθ)``).

    Parameters
    ----------
    x : array_like, shape (..., 5)
    dt : float or array_like broadcastable to ``x[..., 0]``
    u : array_like, shape (..., 2), optional
        Ownship displacement ``U = v_o T`` over the step (N, E).
    """
    x = np.asarray(x, dtype=np.float64)
    v, th, w = x[..., 2], x[..., 3], x[..., 4]
    *_, dn, de = _polar_increment(v, th, w, dt)
    U = _ownship_step(u, x.shape[:-1])
    out = x.copy()
    out[..., 0] += dn - U[..., 0]
    out[..., 1] += de - U[..., 1]
    out[..., 3] = th + w * dt
    return out


def cppv_jacobian(x: ArrayLike, dt: float | ArrayLike) -> F64:
    """``F = ∂Φ/∂x`` of :func:`cppv_transition` (digest §2, C.1 with the missing factor s
    restored), shape (..., 5, 5); its ω column from :func:`turn_coefficient_derivatives`, so
    it equals the D2 limit ``[T cosθ, −vT sinθ, −½vT² sinθ]`` (row N) at ω = 0."""
    x = np.asarray(x, dtype=np.float64)
    v, th, w = x[..., 2], x[..., 3], x[..., 4]
    s, c, ct, st, dn, de = _polar_increment(v, th, w, dt)
    ds, dc = turn_coefficient_derivatives(w, dt)
    F = np.broadcast_to(np.eye(5), x.shape[:-1] + (5, 5)).copy()
    F[..., 0, 2], F[..., 0, 3], F[..., 0, 4] = s * ct - c * st, -de, v * (ds * ct - dc * st)
    F[..., 1, 2], F[..., 1, 3], F[..., 1, 4] = c * ct + s * st, dn, v * (dc * ct + ds * st)
    F[..., 3, 4] = dt
    return F



def _cppv_predict_kernel(x, dt, u, series_below):  # pragma: no cover - compiled by numba
    """:func:`cppv_transition` and :func:`cppv_jacobian` in one compiled pass over (M, 5)
    (the same closed forms and Taylor series as :func:`turn_coefficients`)."""
    M = x.shape[0]
    fx = np.empty((M, 5))
    F = np.zeros((M, 5, 5))
    T = dt
    for m in range(M):
        v, th, w = x[m, 2], x[m, 3], x[m, 4]
        wT = w * T
        wT2 = wT * wT
        if abs(wT) < series_below:
            s = T * (1.0 - wT2 / 6.0 + wT2 * wT2 / 120.0)
            c = T * wT * (0.5 - wT2 / 24.0 + wT2 * wT2 / 720.0)
            ds = -T * T * wT * (1.0 / 3.0 - wT2 / 30.0)
            dc = T * T * (0.5 - wT2 / 8.0 + wT2 * wT2 / 144.0)
        else:
            s = np.sin(wT) / w
            c = (1.0 - np.cos(wT)) / w
            ds = (T * np.cos(wT) - s) / w
            dc = (T * np.sin(wT) - c) / w
        ct, st = np.cos(th), np.sin(th)
        dn = v * (s * ct - c * st)
        de = v * (c * ct + s * st)
        fx[m, 0] = x[m, 0] + dn - u[m, 0]
        fx[m, 1] = x[m, 1] + de - u[m, 1]
        fx[m, 2] = v
        fx[m, 3] = th + wT
        fx[m, 4] = w
        for i in range(5):
            F[m, i, i] = 1.0
        F[m, 0, 2], F[m, 0, 3], F[m, 0, 4] = s * ct - c * st, -de, v * (ds * ct - dc * st)
        F[m, 1, 2], F[m, 1, 3], F[m, 1, 4] = c * ct + s * st, dn, v * (dc * ct + ds * st)
        F[m, 3, 4] = T
    return fx, F


_cppv_predict_kernel = lazy_njit(_cppv_predict_kernel)


#: from this many states on, :meth:`RadarModel.h_and_jacobian` runs :func:`_radar_h_jacobian_kernel`
_RADAR_KERNEL_FROM = 64


def _radar_h_jacobian_kernel(x, s0, s1, s2, tau, tau_in_h):  # pragma: no cover - compiled by numba
    """:meth:`RadarModel.h_and_jacobian` over (N, n_x), state by state: the same expressions in
    the same order as its scalar planes, so the same bits."""
    N, n_x = x.shape
    hx = np.empty((N, 4))
    H = np.zeros((N, 4, n_x))
    for r in range(N):
        p0, p1, p2 = x[r, 0] - s0, x[r, 1] - s1, x[r, 2] - s2
        v0, v1, v2 = x[r, 3], x[r, 4], x[r, 5]
        rho2 = p0 * p0 + p1 * p1 + p2 * p2
        rho = np.sqrt(rho2)
        irho = 1.0 / rho
        vr = v0 * p0 + v1 * p1 + v2 * p2
        rdot = vr * irho
        e0, e1, e2 = p0 * irho, p1 * irho, p2 * irho
        hx[r, 0] = rho + tau * rdot
        hx[r, 1] = e0
        hx[r, 2] = e1
        hx[r, 3] = rdot
        irho3 = irho / rho2
        m01, m02, m12 = -p0 * p1 * irho3, -p0 * p2 * irho3, -p1 * p2 * irho3
        H[r, 1, 0] = (rho2 - p0 * p0) * irho3
        H[r, 1, 1] = m01
        H[r, 1, 2] = m02
        H[r, 2, 0] = m01
        H[r, 2, 1] = (rho2 - p1 * p1) * irho3
        H[r, 2, 2] = m12
        c = vr / rho2
        d0, d1, d2 = (v0 - c * p0) * irho, (v1 - c * p1) * irho, (v2 - c * p2) * irho
        H[r, 3, 0], H[r, 3, 1], H[r, 3, 2] = d0, d1, d2
        H[r, 3, 3], H[r, 3, 4], H[r, 3, 5] = e0, e1, e2
        if tau_in_h:
            H[r, 0, 0], H[r, 0, 1], H[r, 0, 2] = e0 + tau * d0, e1 + tau * d1, e2 + tau * d2
            H[r, 0, 3], H[r, 0, 4], H[r, 0, 5] = tau * e0, tau * e1, tau * e2
        else:
            H[r, 0, 0], H[r, 0, 1], H[r, 0, 2] = e0, e1, e2
    return hx, H


_radar_h_jacobian_kernel = lazy_njit(_radar_h_jacobian_kernel)


def cppv_predict(x: ArrayLike, dt: float, u: ArrayLike | None = None) -> tuple[F64, F64]:
    """``(cppv_transition(x, dt, u), cppv_jacobian(x, dt))`` in one compiled pass (numba;
    numpy where numba is missing); ``x`` (..., 5), scalar ``dt``."""
    x = np.asarray(x, dtype=np.float64)
    if not HAVE_NUMBA:  # pragma: no cover
        return cppv_transition(x, dt, u), cppv_jacobian(x, dt)
    shape = x.shape[:-1]
    U = _ownship_step(u, shape)
    fx, F = _cppv_predict_kernel(kernel_input(x.reshape(-1, 5)), float(dt), kernel_input(U.reshape(-1, 2)),
                                 TURN_SERIES_BELOW)
    return fx.reshape(shape + (5,)), F.reshape(shape + (5, 5))

def cppv_process_noise(dt: float, sigma_v2: float, sigma_omega_dot2: float, *,
                       faithful: bool = False, v_dt_power: int = 2) -> F64:
    """CPPV process noise ``Q = diag(0₂ₓ₂, T^p σ_v², B_θω)`` (digest §4.1, D1, D6).

    ``B_θω = σ_ω̇² [[T³/3, T²/2], [T²/2, T]]`` (the symmetric, white-ω̇ form);
    ``faithful=True`` gives the printed, asymmetric ``[[T³σ²/3, T³σ²/2], [T²σ²/2, T²σ²]]``.
    ``v_dt_power`` (printed: 2) is the power of T on ``σ_v²``. Units assumed (D6): σ_v² in
    (m/s)²/s, σ_ω̇² in rad²/s³.
    """
    T = float(dt)
    Q = np.zeros((5, 5))
    Q[2, 2] = T ** v_dt_power * sigma_v2
    if faithful:
        Q[3:, 3:] = sigma_omega_dot2 * np.array([[T ** 3 / 3, T ** 3 / 2], [T ** 2 / 2, T ** 2]])
    else:
        Q[3:, 3:] = sigma_omega_dot2 * np.array([[T ** 3 / 3, T ** 2 / 2], [T ** 2 / 2, T]])
    return Q


def cv_cppv_transition(x: ArrayLike, dt: float | ArrayLike, u: ArrayLike | None = None) -> F64:
    """CV mode ``Φ = [r_N + vT cosθ, r_E + vT sinθ, v, θ] − U`` (digest §5, eq. 3.46); ``x`` (..., 4)."""
    x = np.asarray(x, dtype=np.float64)
    v, th = x[..., 2], x[..., 3]
    U = _ownship_step(u, x.shape[:-1])
    out = x.copy()
    out[..., 0] += v * dt * np.cos(th) - U[..., 0]
    out[..., 1] += v * dt * np.sin(th) - U[..., 1]
    return out


def cv_cppv_jacobian(x: ArrayLike, dt: float | ArrayLike) -> F64:
    """``F`` of :func:`cv_cppv_transition` (eq. 3.47), shape (..., 4, 4)."""
    x = np.asarray(x, dtype=np.float64)
    v, th = x[..., 2], x[..., 3]
    F = np.broadcast_to(np.eye(4), x.shape[:-1] + (4, 4)).copy()
    F[..., 0, 2], F[..., 0, 3] = dt * np.cos(th), -v * dt * np.sin(th)
    F[..., 1, 2], F[..., 1, 3] = dt * np.sin(th), v * dt * np.cos(th)
    return F


def cv_process_noise(dt: float, sigma_v2: float, sigma_theta_dot2: float, *, v_dt_power: int = 2) -> F64:
    """CV-mode process noise ``diag(0, 0, T^p σ_v², T σ_θ̇²)``. Q_CV is unstated in the thesis
    (§5): the speed term is the CPPV one, the heading a random walk of PSD ``σ_θ̇²`` (rad²/s),
    both config values."""
    T = float(dt)
    return np.diag([0.0, 0.0, T ** v_dt_power * sigma_v2, T * sigma_theta_dot2])


def mpc_derivative(y: ArrayLike, vo: ArrayLike) -> F64:
    """MPC dynamics ``ẏ = f(y, v_o)`` (digest §3, eq. 3.11), ``y`` (..., 5), ``v_o`` (..., 2).

    .. math::

        \\begin{aligned}
        \\dot y_1 &= -2y_1y_2 + y_4y_5 C + y_2y_5, &
        \\dot y_2 &= y_1^2 - y_2^2 + y_4y_5 S - y_1y_5,\\\\
        \\dot y_3 &= y_1,\\quad \\dot y_4 = -y_2y_4,\\quad \\dot y_5 = 0, &
        C &= v_N\\cos y_3 + v_E\\sin y_3,\\; S = v_N\\sin y_3 - v_E\\cos y_3 .
        \\end{aligned}
    """
    y = np.asarray(y, dtype=np.float64)
    vo = np.broadcast_to(np.asarray(vo, dtype=np.float64), y.shape[:-1] + (2,))
    y1, y2, y3, y4, y5 = np.moveaxis(y, -1, 0)
    C = vo[..., 0] * np.cos(y3) + vo[..., 1] * np.sin(y3)
    S = vo[..., 0] * np.sin(y3) - vo[..., 1] * np.cos(y3)
    return np.stack([-2 * y1 * y2 + y4 * y5 * C + y2 * y5,
                     y1 * y1 - y2 * y2 + y4 * y5 * S - y1 * y5,
                     y1, -y2 * y4, np.zeros_like(y1)], axis=-1)


def mpc_jacobian(y: ArrayLike, vo: ArrayLike) -> F64:
    """``J_Y = ∂f/∂y`` of :func:`mpc_derivative` (App. A with the two ⚠ fixes), (..., 5, 5)."""
    y = np.asarray(y, dtype=np.float64)
    vo = np.broadcast_to(np.asarray(vo, dtype=np.float64), y.shape[:-1] + (2,))
    y1, y2, y3, y4, y5 = np.moveaxis(y, -1, 0)
    C = vo[..., 0] * np.cos(y3) + vo[..., 1] * np.sin(y3)
    S = vo[..., 0] * np.sin(y3) - vo[..., 1] * np.cos(y3)
    J = np.zeros(y.shape[:-1] + (5, 5))
    J[..., 0, :] = np.stack([-2 * y2, -2 * y1 + y5, -y4 * y5 * S, y5 * C, y4 * C + y2], axis=-1)
    J[..., 1, :] = np.stack([2 * y1 - y5, -2 * y2, y4 * y5 * C, y5 * S, y4 * S - y1], axis=-1)
    J[..., 2, 0] = 1.0
    J[..., 3, 1], J[..., 3, 3] = -y4, -y2
    return J


def _mpc_euler_py(y, vo, dt_sub, n_sub):
    """Euler over ``n_sub`` substeps with the transition matrix ``Φ = Π(I + J dt)``; numpy,
    vectorised over the leading axis (the numba kernel's reference)."""
    Phi = np.broadcast_to(np.eye(5), y.shape[:-1] + (5, 5)).copy()
    eye = np.eye(5)
    for _ in range(n_sub):
        J = mpc_jacobian(y, vo)
        Phi = (eye + J * dt_sub) @ Phi
        y = y + mpc_derivative(y, vo) * dt_sub
    return y, Phi


def _mpc_euler_kernel(y, vo, dt_sub, n_sub):  # pragma: no cover - compiled by numba
    m = y.shape[0]
    yo = np.empty_like(y)
    Phi = np.zeros((m, 5, 5))
    for i in range(m):
        y1, y2, y3, y4, y5 = y[i, 0], y[i, 1], y[i, 2], y[i, 3], y[i, 4]
        vn, ve = vo[i, 0], vo[i, 1]
        P = np.eye(5)
        for _ in range(n_sub):
            c3, s3 = np.cos(y3), np.sin(y3)
            C = vn * c3 + ve * s3
            S = vn * s3 - ve * c3
            # J rows 0, 1 (dense), 2 (= e0), 3 (−y4 e1 − y2 e3), 4 (0): (I + J dt) P by rows
            j0 = (-2 * y2, -2 * y1 + y5, -y4 * y5 * S, y5 * C, y4 * C + y2)
            j1 = (2 * y1 - y5, -2 * y2, y4 * y5 * C, y5 * S, y4 * S - y1)
            for c in range(5):
                p0, p1, p2, p3, p4 = P[0, c], P[1, c], P[2, c], P[3, c], P[4, c]
                P[0, c] = p0 + dt_sub * (j0[0] * p0 + j0[1] * p1 + j0[2] * p2 + j0[3] * p3 + j0[4] * p4)
                P[1, c] = p1 + dt_sub * (j1[0] * p0 + j1[1] * p1 + j1[2] * p2 + j1[3] * p3 + j1[4] * p4)
                P[2, c] = p2 + dt_sub * p0
                P[3, c] = p3 + dt_sub * (-y4 * p1 - y2 * p3)
            d1 = -2 * y1 * y2 + y4 * y5 * C + y2 * y5
            d2 = y1 * y1 - y2 * y2 + y4 * y5 * S - y1 * y5
            d4 = -y2 * y4
            y3 = y3 + dt_sub * y1
            y1 = y1 + dt_sub * d1
            y2 = y2 + dt_sub * d2
            y4 = y4 + dt_sub * d4
        yo[i, 0], yo[i, 1], yo[i, 2], yo[i, 3], yo[i, 4] = y1, y2, y3, y4, y5
        # element by element: a row assignment (Phi[i] = P) pulls numba's shape-mismatch
        # message into the kernel, seconds of its compile on a fresh checkout
        for r in range(5):
            for c in range(5):
                Phi[i, r, c] = P[r, c]
    return yo, Phi


_mpc_euler_kernel = lazy_njit(_mpc_euler_kernel)


def mpc_transition(y: ArrayLike, vo: ArrayLike, dt: float, *, substep_s: float = 0.001,
                   engine: str = "numba") -> tuple[F64, F64]:
    """MPC prediction over one step ``dt``: Euler with ``n = max(1, round(dt/substep_s))``
    substeps (thesis: dt = 0.001 s, 50 per T = 0.05 s) and ``Φ = Π(I + J_Y dt_sub)`` (the
    digest's suggested P propagation, §3 ⚠).

    Parameters
    ----------
    y : array_like, shape (..., 5)
    vo : array_like, shape (..., 2)
        Ownship velocity (N, E), held over the step.
    engine : {"numba", "numpy"}

    Returns
    -------
    y_next : ndarray, shape (..., 5)
    Phi : ndarray, shape (..., 5, 5)
    """
    y = np.asarray(y, dtype=np.float64)
    shape = y.shape[:-1]
    vo = np.broadcast_to(np.asarray(vo, dtype=np.float64), shape + (2,))
    n_sub = max(1, int(round(float(dt) / substep_s)))
    h = float(dt) / n_sub
    yf, vf = kernel_input(y.reshape(-1, 5)), kernel_input(vo.reshape(-1, 2))
    if engine == "numba" and HAVE_NUMBA:
        yo, Phi = _mpc_euler_kernel(yf, vf, h, n_sub)
    elif engine in ("numba", "numpy"):
        yo, Phi = _mpc_euler_py(yf, vf, h, n_sub)
    else:
        raise ValueError(f"mpc_transition: engine must be 'numba' or 'numpy', not {engine!r}")
    return yo.reshape(shape + (5,)), Phi.reshape(shape + (5, 5))


def cppv_to_mpc(x: ArrayLike, vo: ArrayLike) -> F64:
    """The map ``G``: CPPV ``x`` (..., 5) → MPC ``y`` (digest §3, eq. 3.37 / B.4), with the
    ownship velocity ``v_o`` (..., 2): ``d = r²``, ``u = v cosθ − v_N``, ``w = v sinθ − v_E``,
    ``y = [(r_N w − r_E u)/d, (r_N u + r_E w)/d, atan2(r_E, r_N), d^{−½}, ω]``."""
    x = np.asarray(x, dtype=np.float64)
    vo = np.broadcast_to(np.asarray(vo, dtype=np.float64), x.shape[:-1] + (2,))
    x1, x2, x3, x4, x5 = np.moveaxis(x, -1, 0)
    d = x1 * x1 + x2 * x2
    u = x3 * np.cos(x4) - vo[..., 0]
    w = x3 * np.sin(x4) - vo[..., 1]
    return np.stack([(x1 * w - x2 * u) / d, (x1 * u + x2 * w) / d, np.arctan2(x2, x1),
                     1.0 / np.sqrt(d), x5], axis=-1)


def mpc_to_cppv(y: ArrayLike, vo: ArrayLike) -> F64:
    """The map ``G⁻¹``: MPC ``y`` → CPPV ``x`` (B.3, square root fixed): ``ρ = 1/y₄``,
    ``r = ρ(cos y₃, sin y₃)``, ``ṙ = ρ(y₂cos y₃ − y₁sin y₃, y₂sin y₃ + y₁cos y₃)``,
    ``v = |ṙ + v_o|``, ``θ = atan2`` of ``ṙ + v_o`` (E over N), ``ω = y₅``."""
    y = np.asarray(y, dtype=np.float64)
    vo = np.broadcast_to(np.asarray(vo, dtype=np.float64), y.shape[:-1] + (2,))
    y1, y2, y3, y4, y5 = np.moveaxis(y, -1, 0)
    rho = 1.0 / y4
    c3, s3 = np.cos(y3), np.sin(y3)
    vn = rho * (y2 * c3 - y1 * s3) + vo[..., 0]
    ve = rho * (y2 * s3 + y1 * c3) + vo[..., 1]
    return np.stack([rho * c3, rho * s3, np.hypot(vn, ve), np.arctan2(ve, vn), y5], axis=-1)



def mpc_to_cppv_jacobian(y: ArrayLike, vo: ArrayLike) -> F64:
    """``∂G⁻¹/∂y`` (..., 5, 5) of :func:`mpc_to_cppv` (the covariance of an MPC estimate in
    CPPV). With ``ρ = 1/y₄``, ``ṽ = v_i − v_o`` (the relative velocity) and ``∂ρ/∂y₄ = −ρ²``:
    ``∂r/∂y₃ = ρ(−sin y₃, cos y₃)``, ``∂r/∂y₄ = −ρ² (cos y₃, sin y₃)``,
    ``∂v_i/∂(y₁, y₂) = ρ[(−sin, cos), (cos, sin)]``, ``∂v_i/∂y₃ = (−ṽ_E, ṽ_N)``,
    ``∂v_i/∂y₄ = −ρ ṽ``, then ``v = |v_i|`` and ``θ = atan2(v_E, v_N)`` by the chain rule."""
    y = np.asarray(y, dtype=np.float64)
    vo = np.broadcast_to(np.asarray(vo, dtype=np.float64), y.shape[:-1] + (2,))
    y1, y2, y3, y4 = y[..., 0], y[..., 1], y[..., 2], y[..., 3]
    rho = 1.0 / y4
    c3, s3 = np.cos(y3), np.sin(y3)
    rn, re = rho * (y2 * c3 - y1 * s3), rho * (y2 * s3 + y1 * c3)
    vn, ve = rn + vo[..., 0], re + vo[..., 1]
    J = np.zeros(y.shape[:-1] + (5, 5))
    J[..., 0, 2], J[..., 0, 3] = -rho * s3, -rho * rho * c3
    J[..., 1, 2], J[..., 1, 3] = rho * c3, -rho * rho * s3
    dvn = (-rho * s3, rho * c3, -re, -rho * rn)
    dve = (rho * c3, rho * s3, rn, -rho * re)
    v2 = vn * vn + ve * ve
    v = np.sqrt(v2)
    for i in range(4):
        J[..., 2, i] = (vn * dvn[i] + ve * dve[i]) / v
        J[..., 3, i] = (vn * dve[i] - ve * dvn[i]) / v2
    J[..., 4, 4] = 1.0
    return J

def numerical_jacobian(fun, x: ArrayLike, eps: ArrayLike | float = 1e-6) -> F64:
    """Central-difference Jacobian of ``fun`` (vectorised over leading axes) at ``x`` (..., n),
    with a step ``eps·max(1, |x_i|)`` (``eps`` a scalar or one per component); returns
    (..., m, n). Used for the MPC bank's ``J_G P₀ J_Gᵀ`` (D7) and for the model tests."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[-1]
    eps = np.asarray(eps, dtype=np.float64)
    cols = []
    for i in range(n):
        h = (eps[i] if eps.ndim else eps) * np.maximum(1.0, np.abs(x[..., i]))
        dx = np.zeros_like(x)
        dx[..., i] = h
        cols.append((np.asarray(fun(x + dx)) - np.asarray(fun(x - dx))) / (2 * h[..., None]))
    return np.stack(cols, axis=-1)


@dataclass(frozen=True)
class BearingMeasurement:
    """The bearing ``β = atan2(ΔE, ΔN) + ε``, ``ε ~ N(0, σ_β²)`` (digest §2 eq. 3.9, §3 eq. 3.13),
    a measurement model for :class:`~pipeline.estimate.ekf.ExtendedKalmanFilter` with a
    wrapped residual (:meth:`residual`, ``wrap(z − h) ∈ [−π, π)``).

    Parameters
    ----------
    sigma_rad : float
        σ_β (rad).
    coords : {"cppv", "cv", "mpc"}
        ``cppv``/``cv``: ``h = atan2(r_E, r_N)``, ``H = [−r_E/r², r_N/r², 0, …]``;
        ``mpc``: ``h = y₃``, ``H = e₃``.
    """

    sigma_rad: float
    coords: str = "cppv"

    def __post_init__(self):
        if self.coords not in ("cppv", "cv", "mpc"):
            raise ValueError(f"BearingMeasurement: coords must be 'cppv', 'cv' or 'mpc', not {self.coords!r}")
        if not (self.sigma_rad > 0):
            raise ValueError(f"BearingMeasurement: sigma_rad must be > 0, got {self.sigma_rad}")

    @property
    def R(self) -> F64:
        return np.array([[float(self.sigma_rad) ** 2]])

    def h(self, x: ArrayLike) -> F64:
        x = np.asarray(x, dtype=np.float64)
        if self.coords == "mpc":
            return x[..., 2:3].copy()
        return np.arctan2(x[..., 1], x[..., 0])[..., None]

    def jacobian(self, x: ArrayLike) -> F64:
        x = np.asarray(x, dtype=np.float64)
        H = np.zeros(x.shape[:-1] + (1, x.shape[-1]))
        if self.coords == "mpc":
            H[..., 0, 2] = 1.0
        else:
            r2 = x[..., 0] ** 2 + x[..., 1] ** 2
            H[..., 0, 0] = -x[..., 1] / r2
            H[..., 0, 1] = x[..., 0] / r2
        return H

    def h_and_jacobian(self, x: ArrayLike) -> tuple[F64, F64]:
        return self.h(x), self.jacobian(x)

    def residual(self, z: ArrayLike, hx: ArrayLike) -> F64:
        """Innovation ``wrap(z − h(x)) ∈ [−π, π)`` (the EKF's residual hook)."""
        return wrap_angle(np.asarray(z, dtype=np.float64) - np.asarray(hx, dtype=np.float64))

    def measure(self, x: ArrayLike, rng: np.random.Generator, bias_rad: float = 0.0) -> F64:
        """A noisy bearing ``wrap(h(x) + bias + ε)`` (..., 1) from ``rng``."""
        y = self.h(x)
        return wrap_angle(y + bias_rad + self.sigma_rad * rng.standard_normal(y.shape))


# issue 17: particle-filter motion models (seed 001 §4, seed 003 §2). Each has a vectorised
# ``propagate(x (N, n), dt, rng) -> (N, n)`` for ``estimate.pf.ParticleFilter``; the modes of
# a jump-Markov filter share one horizontal state layout, PF_STATE = [N, E, v_N, v_E, ω, a_N,
# a_E] (NED, m, m/s, rad/s, m/s²), so ``ct_transition`` applies unchanged (ω at index 4). A
# model uses the leading components it needs (CV/curvilinear 4, CT/ACT 5, CA 7) and keeps the
# rest, except that a non-turning model zeroes ω and a non-accelerating one zeroes a (when
# present, ``zero_unused``): the components a mode does not drive carry no stale value into the
# mixed estimate. Process noise is the piecewise-constant white acceleration of seed 001 (3.15)
# with the B typo fixed (digest D3): ``p += a T²/2, v += a T``, ``a ~ N(0, σ_a²)`` per axis.
# --------------------------------------------------------------------------------------------

#: the shared particle-filter state (horizontal plane), in column order
PF_STATE: tuple[str, ...] = ("pos_n_m", "pos_e_m", "vel_n_mps", "vel_e_mps", "omega_radps",
                             "acc_n_mps2", "acc_e_mps2")
PF_IX_OMEGA = 4
PF_IX_ACC = (5, 6)


def _need(x: ArrayLike, n: int, who: str) -> F64:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] < n:
        raise ValueError(f"{who}: particles must have shape (N, >= {n}), got {x.shape}")
    return x


def _white_accel(x: F64, dt: float, sig: F64 | float, rng: np.random.Generator) -> None:
    """In place: ``p += a T²/2, v += a T`` with ``a ~ N(0, σ²)`` per horizontal axis."""
    a = rng.standard_normal((x.shape[0], 2)) * sig
    x[:, 0:2] += (0.5 * dt * dt) * a
    x[:, 2:4] += dt * a


def _zero(x: F64, omega: bool, acc: bool) -> None:
    n = x.shape[1]
    if omega and n > PF_IX_OMEGA:
        x[:, PF_IX_OMEGA] = 0.0
    if acc and n > PF_IX_ACC[1]:
        x[:, PF_IX_ACC[0]:PF_IX_ACC[1] + 1] = 0.0


@dataclass(frozen=True)
class PfConstantVelocity:
    """CV (seed 001 (3.14–3.15)): ``p += v T``, white acceleration ``σ_a`` (m/s²) per axis."""

    sigma_a: float = 1.0
    zero_unused: bool = True

    def propagate(self, x: ArrayLike, dt: float, rng: np.random.Generator) -> F64:
        out = _need(x, 4, "PfConstantVelocity").copy()
        out[:, 0:2] += dt * out[:, 2:4]
        _white_accel(out, dt, self.sigma_a, rng)
        if self.zero_unused:
            _zero(out, True, True)
        return out


@dataclass(frozen=True)
class PfConstantAcceleration:
    """CA (seed 001 (3.16–3.18), B_a typo fixed): ``a`` a random walk driven by white jerk.

    ``p += v T + a T²/2 + j T³/6``, ``v += a T + j T²/2``, ``a += j T`` with
    ``j ~ N(0, σ_j²)`` (m/s³) per axis (held over the step). On entering the mode
    (:meth:`enter`, digest D4: ACCEL/DECEL act along the velocity) the acceleration is drawn
    along the velocity, ``a = α v/|v|`` with ``α ~ N(0, acc_init_sigma²)``.
    """

    sigma_j: float = 1.0
    acc_init_sigma: float = 2.0
    zero_unused: bool = True

    def propagate(self, x: ArrayLike, dt: float, rng: np.random.Generator) -> F64:
        out = _need(x, 7, "PfConstantAcceleration").copy()
        a = out[:, 5:7].copy()
        j = rng.standard_normal((out.shape[0], 2)) * self.sigma_j
        out[:, 0:2] += dt * out[:, 2:4] + (0.5 * dt * dt) * a + (dt ** 3 / 6.0) * j
        out[:, 2:4] += dt * a + (0.5 * dt * dt) * j
        out[:, 5:7] = a + dt * j
        if self.zero_unused:
            _zero(out, True, False)
        return out

    def enter(self, x: ArrayLike, rng: np.random.Generator) -> F64:
        out = _need(x, 7, "PfConstantAcceleration").copy()
        v = out[:, 2:4]
        sp = np.hypot(v[:, 0], v[:, 1])
        u = np.where(sp[:, None] > 1e-9, v / np.where(sp > 1e-9, sp, 1.0)[:, None], np.array([1.0, 0.0]))
        out[:, 5:7] = u * (self.acc_init_sigma * rng.standard_normal(out.shape[0]))[:, None]
        return out


@dataclass(frozen=True)
class PfCoordinatedTurn:
    """CT (seed 001 (3.19–3.21)) by the shared :func:`ct_transition`, exact through ω → 0.

    ``omega`` None keeps each particle's own ω (no ω noise); a number sets it (a known-rate
    turn, ω > 0 right). White acceleration ``σ_a`` on position/velocity (seed 003 A6).
    """

    sigma_a: float = 1.0
    omega: float | None = None
    zero_unused: bool = True

    def propagate(self, x: ArrayLike, dt: float, rng: np.random.Generator) -> F64:
        x = _need(x, 5, "PfCoordinatedTurn")
        if self.omega is not None:
            x = x.copy()
            x[:, PF_IX_OMEGA] = self.omega
        out = ct_transition(x, dt)
        _white_accel(out, dt, self.sigma_a, rng)
        if self.zero_unused:
            _zero(out, False, True)
        return out


@dataclass(frozen=True)
class PfAugmentedCoordinatedTurn:
    """Augmented CT (seed 003 §2 ACT): CT with ω a random walk.

    ω gets ``σ_ω·√T`` (rad/s, a Wiener process in continuous time) or, with ``per_step=True``,
    ``σ_ω`` per step whatever T (seed 003's noise gain 1). On entering (:meth:`enter`) ω is
    drawn: ``|ω| ~ U[omega_init]`` (rad/s) with sign ``sign`` (+1 right, −1 left, 0 random) —
    seed 003 A2 — or ``N(0, omega_init_sigma²)`` when ``omega_init`` is None.
    """

    sigma_a: float = 1.0
    sigma_omega: float = 0.01
    per_step: bool = False
    omega_init: tuple[float, float] | None = None
    omega_init_sigma: float = 0.1
    sign: int = 0
    zero_unused: bool = True

    def propagate(self, x: ArrayLike, dt: float, rng: np.random.Generator) -> F64:
        out = ct_transition(_need(x, 5, "PfAugmentedCoordinatedTurn"), dt)
        _white_accel(out, dt, self.sigma_a, rng)
        g = self.sigma_omega if self.per_step else self.sigma_omega * np.sqrt(max(dt, 0.0))
        out[:, PF_IX_OMEGA] += g * rng.standard_normal(out.shape[0])
        if self.zero_unused:
            _zero(out, False, True)
        return out

    def enter(self, x: ArrayLike, rng: np.random.Generator) -> F64:
        out = _need(x, 5, "PfAugmentedCoordinatedTurn").copy()
        m = out.shape[0]
        if self.omega_init is None:
            w = self.omega_init_sigma * rng.standard_normal(m)
            if self.sign:
                w = np.sign(self.sign) * np.abs(w)
        else:
            lo, hi = self.omega_init
            w = rng.uniform(lo, hi, m)
            s = np.sign(self.sign) if self.sign else rng.choice([-1.0, 1.0], m)
            w = w * s
        out[:, PF_IX_OMEGA] = w
        return out


def curvilinear_axes(v: ArrayLike) -> tuple[F64, F64]:
    """Unit tangent ``t = v/|v|`` and right-hand normal ``n`` (NED: n = (−t_E, t_N)), (N, 2) each.

    A particle at rest gets ``t = (1, 0)`` (the noise is then isotropic only if σ_T = σ_N).
    """
    v = np.asarray(v, dtype=np.float64)
    sp = np.hypot(v[..., 0], v[..., 1])
    ok = sp > 1e-9
    t = np.where(ok[..., None], v / np.where(ok, sp, 1.0)[..., None], np.array([1.0, 0.0]))
    n = np.stack([-t[..., 1], t[..., 0]], axis=-1)
    return t, n


@dataclass(frozen=True)
class PfCurvilinear:
    """Curvilinear motion (seed 003 §2 CM): CV with along/cross-track noise.

    ``Q = R Q_TN Rᵀ``, ``Q_TN = diag(σ_T², σ_N²)``: the acceleration is
    ``a = σ_T ε₁ t + σ_N ε₂ n`` with ``t = v/|v|`` and ``n`` its right-hand normal
    (:func:`curvilinear_axes`); equals CV when σ_T = σ_N.
    """

    sigma_t: float = 2.0
    sigma_n: float = 0.1
    zero_unused: bool = True

    def propagate(self, x: ArrayLike, dt: float, rng: np.random.Generator) -> F64:
        out = _need(x, 4, "PfCurvilinear").copy()
        t, n = curvilinear_axes(out[:, 2:4])
        e = rng.standard_normal((out.shape[0], 2))
        a = (self.sigma_t * e[:, 0])[:, None] * t + (self.sigma_n * e[:, 1])[:, None] * n
        out[:, 0:2] += dt * out[:, 2:4] + (0.5 * dt * dt) * a
        out[:, 2:4] += dt * a
        if self.zero_unused:
            _zero(out, True, True)
        return out


# --------------------------------------------------------------------------------------------
# issue 17: seed 003 2-D radar
#
# The seed-003 radar (van de Kerkhof 2014 eq. 3.1, digest 003 §6) measures a ship's planar state
# ``[N, E, v_N, v_E, …]`` about a site as ``z = [r, b, d]``: range, bearing and Doppler. Frames:
# NED with (x, y) = (N, E) and bearing b = atan2(E, N) (from North toward East) — the thesis's
# ``arctan(x/y)`` in its own x = East, y = North frame, so the same angle. Doppler is positive
# when closing, ``d = −(ρ⃗ · v)/r``. Stored in the ``radar`` stream as ``range_m`` = r,
# ``dcos_u`` = cos b, ``dcos_v`` = sin b, ``range_rate_mps`` = −d (the stream's range rate is
# the opening rate).
# --------------------------------------------------------------------------------------------

#: the 2-D radar's measurement components, in order
RADAR2D_FIELDS: tuple[str, ...] = ("range_m", "bearing_rad", "doppler_mps")

_radar2d = functools.partial(cfield, "estimate.pf.hmpf.radar")


@dataclass(frozen=True, kw_only=True)
class Radar2DModel:
    """Seed-003 2-D radar ``[r, b, d]`` about a site (the section comment above).

    The likelihood is an independent Gaussian per component with the bearing residual wrapped
    to ``[−π, π)`` (:func:`wrap_angle`), so a target due South (b near ±π, where the raw
    difference jumps by 2π) is scored like any other.

    Parameters
    ----------
    site_ne_m : tuple of 2 float
        Radar site (N, E) in the local frame (m).
    sigma : tuple of 3 float
        Noise standard deviations of r (m), b (rad) and d (m/s); seed 003 §5.1: 10 m,
        0.005 rad, 3 m/s.
    """

    site_ne_m: tuple[float, float] = _radar2d("site_ne_m")
    sigma: tuple[float, float, float] = _radar2d(("sigma_range_m", "sigma_bearing_rad", "sigma_doppler_mps"))

    @classmethod
    def from_config(cls, sec: Mapping[str, Any] | None) -> "Radar2DModel":
        """From ``estimate.pf.hmpf.radar`` (validated and defaulted by the config schema):
        ``site_ne_m``, ``sigma_range_m``, ``sigma_bearing_rad``, ``sigma_doppler_mps``."""
        return build(cls, validate_section("estimate.pf.hmpf.radar", sec))

    @property
    def R(self) -> F64:
        """Measurement noise covariance (3×3)."""
        return np.diag(np.square(self.sigma))

    def h(self, x: ArrayLike) -> F64:
        """Noise-free ``[r, b, d]`` of planar state(s) ``x`` (..., ≥ 4) = ``[N, E, v_N, v_E, …]``."""
        x = np.asarray(x, dtype=np.float64)
        pn, pe = x[..., 0] - self.site_ne_m[0], x[..., 1] - self.site_ne_m[1]
        r = np.hypot(pn, pe)
        return np.stack([r, np.arctan2(pe, pn), -(pn * x[..., 2] + pe * x[..., 3]) / r], axis=-1)

    def residual(self, z: ArrayLike, hx: ArrayLike) -> F64:
        """``z − h`` with the bearing component wrapped to ``[−π, π)``."""
        d = np.asarray(z, dtype=np.float64) - np.asarray(hx, dtype=np.float64)
        d[..., 1] = wrap_angle(d[..., 1])
        return d

    def log_likelihood(self, z: ArrayLike, x: ArrayLike) -> F64:
        """``log p(z | x)`` up to a constant (the Gaussian's normaliser is dropped), shape ``x.shape[:-1]``.

        ``z`` (3,) or broadcastable to ``x.shape[:-1] + (3,)``; a NaN component contributes nothing.
        """
        e = self.residual(np.broadcast_to(np.asarray(z, dtype=np.float64), np.shape(x)[:-1] + (3,)), self.h(x))
        e = e / np.asarray(self.sigma)
        return -0.5 * np.nansum(e * e, axis=-1)

    def measure(self, x: ArrayLike, rng: np.random.Generator) -> F64:
        """``h(x) + ν``, ν ~ N(0, R) from ``rng`` (one draw per row), bearing wrapped."""
        z = self.h(x)
        z = z + rng.standard_normal(z.shape) * np.asarray(self.sigma)
        z[..., 1] = wrap_angle(z[..., 1])
        return z

    def position(self, z: ArrayLike) -> F64:
        """The (N, E) position of measurement(s) ``z`` (..., ≥ 2): ``site + r [cos b, sin b]``."""
        z = np.asarray(z, dtype=np.float64)
        return np.stack([self.site_ne_m[0] + z[..., 0] * np.cos(z[..., 1]),
                         self.site_ne_m[1] + z[..., 0] * np.sin(z[..., 1])], axis=-1)

    @staticmethod
    def to_stream(z: ArrayLike) -> dict[str, F64]:
        """``radar`` stream columns of ``z`` (T, 3): ``range_m`` = r, ``dcos_u`` = cos b,
        ``dcos_v`` = sin b, ``range_rate_mps`` = −d (opening rate)."""
        z = np.asarray(z, dtype=np.float64)
        return {"range_m": z[..., 0], "dcos_u": np.cos(z[..., 1]), "dcos_v": np.sin(z[..., 1]),
                "range_rate_mps": -z[..., 2]}

    @staticmethod
    def from_stream(cols: Mapping[str, ArrayLike]) -> F64:
        """``[r, b, d]`` (T, 3) back from ``radar`` stream columns (the inverse of :meth:`to_stream`)."""
        return np.stack([np.asarray(cols["range_m"], dtype=np.float64),
                         np.arctan2(np.asarray(cols["dcos_v"], dtype=np.float64),
                                    np.asarray(cols["dcos_u"], dtype=np.float64)),
                         -np.asarray(cols["range_rate_mps"], dtype=np.float64)], axis=-1)


def radar2d_range_criterion(delta_max_m: float, sigma_bearing_rad: float, k_sigma: float = 3.0) -> float:
    """The range beyond which a straight of length δ_max lies entirely within ±kσ_b (seed 003 §5.3.1).

    .. math:: r = \\frac{\\delta_{max}}{2\\tan(k\\sigma_b)}

    ≈ 16,665 m for δ_max = 500 m, σ_b = 0.005 rad, k = 3 (the thesis quotes ≈ 16,700 m):
    beyond it the radar cannot see a weave's straight bend at all.
    """
    return float(delta_max_m / (2.0 * np.tan(k_sigma * sigma_bearing_rad)))


# issue 17: seed 001 geo-location driving modes (digest 001 §7, D4). The five modes STOP, ACCEL,
# DECEL, COAST, TURN map onto the PF models above: STOP = CV held at v = 0, ACCEL/DECEL = CA
# with the acceleration drawn along ±v̂ on entering, COAST = CV, TURN = augmented CT. The state
# is PF_STATE with the target's D appended (GEO_IX_DOWN, the thesis estimates z), which every
# model above keeps; :class:`PfDownRandomWalk` adds its random walk.
# --------------------------------------------------------------------------------------------

#: the geo-location particle state: PF_STATE + the target's D (m) + the heading kept while at
#: rest (rad, from N toward E): digest §7 "acceleration acts along the velocity (or the heading
#: when stopped)", so a stopped particle must remember where it was pointing
GEO_STATE: tuple[str, ...] = (*PF_STATE, "pos_d_m", "rest_heading_rad")
GEO_IX_DOWN = 7
GEO_IX_HEADING = 8


def _remember_heading(x: F64, v: F64) -> None:
    """In place: particles that are moving (|v| > 1e-9) store ``atan2(v_E, v_N)`` in the heading
    column, when the state has one (GEO_STATE); resting particles keep theirs."""
    if x.shape[1] <= GEO_IX_HEADING:
        return
    moving = np.hypot(v[:, 0], v[:, 1]) > 1e-9
    x[moving, GEO_IX_HEADING] = np.arctan2(v[moving, 1], v[moving, 0])


def _heading_axes(x: F64) -> F64:
    """Unit along-track axis (N, 2): ``v/|v|``, or for a particle at rest its remembered heading
    (GEO_STATE), N when the state has none (the first version's behaviour for every state)."""
    t, _ = curvilinear_axes(x[:, 2:4])
    if x.shape[1] > GEO_IX_HEADING:
        rest = np.hypot(x[:, 2], x[:, 3]) <= 1e-9
        h = x[rest, GEO_IX_HEADING]
        t[rest] = np.column_stack([np.cos(h), np.sin(h)])
    return t
#: the seed-001 driving modes in the order of Π_d / Π_p (digest 001 §7)
DRIVING_MODES: tuple[str, ...] = ("STOP", "ACCEL", "DECEL", "COAST", "TURN")


@dataclass(frozen=True)
class PfStop:
    """STOP (digest D4: CV with v = 0): velocity, ω and a zeroed; white position jitter σ_a T²/2."""

    sigma_a: float = 0.05

    def propagate(self, x: ArrayLike, dt: float, rng: np.random.Generator) -> F64:
        out = _need(x, 4, "PfStop").copy()
        _remember_heading(out, out[:, 2:4])
        out[:, 2:4] = 0.0
        out[:, 0:2] += (0.5 * dt * dt * self.sigma_a) * rng.standard_normal((out.shape[0], 2))
        _zero(out, True, True)
        return out

    def enter(self, x: ArrayLike, rng: np.random.Generator) -> F64:
        out = _need(x, 4, "PfStop").copy()
        # the heading at the stop is kept (GEO_STATE), so a later ACCEL leaves along it
        _remember_heading(out, out[:, 2:4])
        out[:, 2:4] = 0.0
        return out


@dataclass(frozen=True)
class PfAlongTrackAcceleration:
    """ACCEL (``sign`` +1) or DECEL (−1): CA whose acceleration on entering is ``±|α| v̂``.

    ``|α| ~ U(accel[0], accel[1])`` (m/s²) along the velocity, or at rest along the heading
    remembered in GEO_STATE's ``rest_heading_rad`` (digest §7; N for a state without it);
    then :class:`PfConstantAcceleration` with white jerk ``σ_j``. DECEL does not reverse: a
    particle whose velocity turned against its acceleration is held at rest (the target
    simulator forces DECEL to STOP at v = 0, digest §7).
    """

    sign: int = 1
    accel: tuple[float, float] = (0.5, 2.0)
    sigma_j: float = 0.5

    def propagate(self, x: ArrayLike, dt: float, rng: np.random.Generator) -> F64:
        x = _need(x, 7, "PfAlongTrackAcceleration")
        v0 = x[:, 2:4].copy()
        out = PfConstantAcceleration(sigma_j=self.sigma_j).propagate(x, dt, rng)
        if self.sign < 0:
            rev = np.einsum("ij,ij->i", v0, out[:, 2:4]) < 0
            if np.any(rev):
                sub = out[rev]
                _remember_heading(sub, v0[rev])
                sub[:, 2:4] = 0.0
                sub[:, 5:7] = 0.0
                out[rev] = sub
        return out

    def enter(self, x: ArrayLike, rng: np.random.Generator) -> F64:
        out = _need(x, 7, "PfAlongTrackAcceleration").copy()
        t = _heading_axes(out)
        a = rng.uniform(self.accel[0], self.accel[1], out.shape[0]) * (1.0 if self.sign >= 0 else -1.0)
        out[:, 5:7] = t * a[:, None]
        return out


@dataclass(frozen=True)
class PfDownRandomWalk:
    """Wrap a mode model: the target's D (column ``index``) gets ``σ_d √T`` random walk."""

    model: Any
    sigma_d: float = 0.2
    index: int = GEO_IX_DOWN

    def propagate(self, x: ArrayLike, dt: float, rng: np.random.Generator) -> F64:
        out = self.model.propagate(x, dt, rng)
        out[:, self.index] += self.sigma_d * np.sqrt(max(dt, 0.0)) * rng.standard_normal(out.shape[0])
        return out

    def enter(self, x: ArrayLike, rng: np.random.Generator) -> F64:
        enter = getattr(self.model, "enter", None)
        return enter(x, rng) if enter is not None else np.asarray(x, dtype=np.float64)


@dataclass(frozen=True)
class PfBlocked:
    """Run a mode model's ``propagate``/``enter`` over blocks of ``block`` particles.

    The same model, applied block by block: each block's temporaries (a dozen (block, 9)
    arrays per step) stay in the CPU cache, so the cost per particle does not grow once N's
    arrays outgrow it (10⁶ particles cost ~45 % more per particle than 10⁵ unblocked). At
    N ≤ ``block`` it is the model itself (the same random draws).
    """

    model: Any
    block: int = 16384

    def _blocks(self, fn, x: ArrayLike, *args) -> F64:
        x = np.asarray(x, dtype=np.float64)
        if len(x) <= self.block:
            return fn(x, *args)
        out = np.empty_like(x)
        for i in range(0, len(x), self.block):
            out[i:i + self.block] = fn(x[i:i + self.block], *args)
        return out

    def propagate(self, x: ArrayLike, dt: float, rng: np.random.Generator) -> F64:
        return self._blocks(self.model.propagate, x, dt, rng)

    def enter(self, x: ArrayLike, rng: np.random.Generator) -> F64:
        enter = getattr(self.model, "enter", None)
        if enter is None:
            return np.asarray(x, dtype=np.float64)
        return self._blocks(enter, x, rng)


def driving_mode_models(*, stop_sigma_a: float = 0.05, accel_sigma_j: float = 0.5, coast_sigma_a: float = 0.3,
                        turn_sigma_a: float = 0.3, turn_sigma_omega: float = 0.05, down_sigma: float = 0.2,
                        accel: tuple[float, float] = (0.5, 2.0), omega: tuple[float, float] = (0.05, 0.3),
                        estimate_down: bool = True) -> list:
    """The five filter models of :data:`DRIVING_MODES` (digest D4), with the config's noise values."""
    models = [PfStop(stop_sigma_a),
              PfAlongTrackAcceleration(+1, tuple(accel), accel_sigma_j),
              PfAlongTrackAcceleration(-1, tuple(accel), accel_sigma_j),
              PfConstantVelocity(coast_sigma_a),
              PfAugmentedCoordinatedTurn(sigma_a=turn_sigma_a, sigma_omega=turn_sigma_omega,
                                         omega_init=tuple(omega), sign=0)]
    return [PfDownRandomWalk(m, down_sigma) for m in models] if estimate_down else models
