"""Motion and measurement models shared by the simulator and the estimators.

The simulator draws its radar measurements through :class:`RadarModel` and the EKF linearises
the very same :meth:`RadarModel.h` with :meth:`RadarModel.jacobian`, so the measurement model
exists exactly once.

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
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import build, cfield, validate_section

F64 = NDArray[np.float64]

#: radar measurement components, in order
RADAR_FIELDS: tuple[str, ...] = ("range_m", "dcos_u", "dcos_v", "range_rate_mps")

_radar = functools.partial(cfield, "simulate.sensors.radar")


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
    """

    site_ned_m: tuple[float, float, float] = _radar("site_ned_m")
    tau_rd_s: float = _radar("tau_rd_s")
    sigma: tuple[float, float, float, float] = _radar(
        ("sigma_range_m", "sigma_dcos", "sigma_dcos", "sigma_range_rate_mps"))
    include_tau_in_h: bool = field(default=True, metadata={"config_key": None})
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

    def measure(self, x: ArrayLike, rng: np.random.Generator) -> F64:
        """``h(x) + ν`` with ν ~ N(0, R) drawn from ``rng`` (one draw per row)."""
        y = self.h(x)
        return y + rng.standard_normal(y.shape) * np.asarray(self.sigma)


def ca_transition(dt: float, n_axes: int = 3) -> F64:
    """Constant-acceleration transition for state ``[r(3), v(3), a(3)]`` (seed 000 eq. 2.16)."""
    i = np.eye(n_axes)
    return np.block([[i, dt * i, 0.5 * dt * dt * i], [0 * i, i, dt * i], [0 * i, 0 * i, i]])
