"""Range-parameterised EKF bank for bearing-only ranging (seed 002 §4, Daugherty 2018 §3.2).

A bank of ``N = N_r·N_ω·N_θ`` EKFs over the initial range, heading and turn rate, each
running its own predict and update on every bearing; the weights (3.18–3.20), kept as
log-weights,

.. math::

    \\log W_k^{(i)} = \\log W_{k-1}^{(i)} - \\tfrac12\\big(\\log 2\\pi S_i + \\tilde y_i^2/S_i\\big)
    + \\text{const},\\qquad \\tilde y_i = \\operatorname{wrap}(z_k - h(\\hat x_i^-))

and the combination (3.21–3.22) ``x̂ = ΣW x̂ᵢ``, ``P = ΣW(Pᵢ + dᵢdᵢᵀ)`` with a circular mean
and wrapped deviations ``dᵢ`` on the angle components (θ; β in MPC). No pruning (§4).

Every array is batched over **runs × filters**: means ``(R, N, n)``, covariances
``(R, N, n, n)``, log-weights ``(R, N)``; the only Python loop is over time. The filter
arithmetic is :class:`~pipeline.estimate.ekf.ExtendedKalmanFilter` (its ``fx`` predict hook
for the nonlinear mean, its ``residual`` hook for the wrapped bearing) with ``algebra="ekf"``;
the default ``algebra="numba"`` runs the same algebra for the scalar bearing in two compiled
kernels (tested equal; ~5× faster at runs × filters). The CPPV predict is numpy, the MPC
predict (Euler, 1 ms substeps) numba (:func:`~pipeline.estimate.models.mpc_transition`).

Public API (stable; the study, the replay and :mod:`pipeline.estimate.imm` use it)
-------------------------------------------------------------------------------
``BankSettings`` (frozen; ``.n_filters``, ``.replace(**kw)``, ``.metadata()``,
``BankSettings.from_mapping(d)`` with an optional ``preset`` key) and ``PRESETS`` (name →
settings: Table 4.1's ``cppv_25_1_6``, ``mpc_15_5_2``, the Table 4.2 cases ``cppv_<Nr>_<Nω>_<Nθ>``,
Tables 5.1–5.3 ``table5_1_ft20_ft29``, ``table5_2_ft10``, ``table5_3_ft50``);
``settings_for(name_or_settings) -> BankSettings``;
``range_grid(n_r, r_min, r_max) -> (r, σ_r)``, ``omega_grid(s)``, ``theta_grid(s)``;
``bank_prior(settings, beta0 (R,), sigma_rad, vo0 (R, 2)) -> Components``;
``model_for(settings) -> CppvModel | MpcModel``, ``CvModel(...)`` (the IMM's CV mode);
``components_step(model, comp, dt, vo (R, 2), z (R,), sigma_rad, *, gate, gate_chi2,
algebra="numba") -> (Components, StepStats)``; ``combine(mean, cov, logw, angle_idx) -> (mean, cov)`` (numba; ``combine_numpy`` the reference);
``weight_entropy(logw)``; ``check_inputs(t_s, z_rad, ownship)``; ``first_bearing(z)``;
``logsumexp(a, axis)``; ``angle_index(names)``; ``mpc_components_to_cppv(mean, cov, vo)``;
``run_bank(settings, t_s (T,), z_rad (T,) | (R, T), sigma_rad=None, ownship=None, *, gate=None,
store_cov=True, store_weights=True, store_components=False, engine="numba", algebra="numba")
-> BankTrack``.

Conventions: NED with (x, y) = (N, E); β = atan2(ΔE, ΔN); θ the course from N toward E; ω > 0
a right turn; angles in rad; ``ownship`` rows ``(N, E, v_N, v_E)`` (or ``(v_N, v_E)``).

Choices where the thesis is silent (recorded in :meth:`BankSettings.metadata`):

- the ownship displacement over a step is ``T·(v_o[k−1] + v_o[k])/2`` (the thesis's
  ``v_o T`` for a CV ownship; a variable ownship velocity and a variable T, D9, stay exact to
  second order); the MPC predict holds that mean velocity over the step;
- the filters start at ``t[0]`` from the run's first finite bearing β₀ (3.34), with no
  update at the initialising step;
- a bearing that is NaN is a predict-only step (weights unchanged); the optional gate
  rejects a bearing for the whole bank (predict-only) when the NIS of the bank's mixture
  prediction exceeds ``gate_chi2`` (χ²₁(0.99) = 6.635), so the weights stay comparable;
- a filter whose mean or covariance stops being finite (or whose covariance loses a
  positive diagonal, or whose innovation variance is not positive) is flagged diverged at
  that step, frozen at its last finite estimate, and leaves the mixture (weight 0); the run
  goes on;
- an MPC bank's CPPV output maps every filter through ``G⁻¹`` (covariance by the central-
  the analytic Jacobian) and combines there (``cppv_mean``/``cppv_cov``); ``mean``/``cov``
  are the combination in the filters' own coordinates.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .base import GaussianState, LinearTransition
from .ekf import ExtendedKalmanFilter
from .models import (ANGLE_STATES, CPPV_STATE, CV_CPPV_STATE, HAVE_NUMBA, MPC_STATE, BearingMeasurement,
                     kernel_input, lazy_njit,
                     cppv_predict, cppv_process_noise, cppv_to_mpc, cv_cppv_jacobian,
                     cv_cppv_transition, cv_process_noise, mpc_to_cppv, mpc_to_cppv_jacobian,
                     mpc_transition, numerical_jacobian, wrap_angle)

F64 = NDArray[np.float64]

#: χ²₁(0.99), the digest's outlier gate (§12 item 6)
GATE_CHI2_1_099 = 6.634896601021214
_DEG = np.pi / 180.0
_LOG2PI = float(np.log(2 * np.pi))


@dataclass(frozen=True, kw_only=True)
class BankSettings:
    """One bank parameterisation (digest §4, Table 4.1 defaults; units: m, s, rad).

    Parameters
    ----------
    coords : {"cppv", "mpc"}
    n_r, n_omega, n_theta : int
        Grid sizes ``(N_r, N_ω, N_θ)``.
    r_min_m, r_max_m : float
        Range grid bounds (Table 4.1: 1–10 km).
    omega_min_rps, omega_max_rps : float
        Turn-rate grid bounds (±8°/s).
    theta_min_rad, theta_max_rad : float
        Heading grid bounds (0–2π).
    v_init_mps : float
        Initial speed ``v₀`` of every filter ("the ownship velocity", 40 m/s).
    sigma_v0_mps : float
        Initial speed std (``(v_max − v_min)/√12``, 40/√12 = 11.55 m/s).
    sigma_v2 : float
        Speed process noise σ_v² ((m/s)²/s assumed, D6; 1e-3).
    sigma_omega_dot2 : float
        Turn-rate process noise σ_ω̇² (rad²/s³ assumed, D6; 5e-6).
    q_mpc : float
        MPC process noise ``Q = q I₅`` added once per step (1e-12).
    sigma_beta_rad : float
        The table's bearing std (0.2°), used where :func:`run_bank` is given none.
    mpc_substep_s : float
        MPC Euler substep (0.001 s: 50 per 0.05 s).
    mpc_p0 : {"faithful", "jacobian"}
        MPC initial covariance: the digest's diagonal (3.40) or ``J_G P₀ J_Gᵀ`` (D7).
    q_faithful : bool
        The printed asymmetric ``B_θω`` (D1); default the symmetric form.
    sigma_omega_faithful : bool
        The printed σ_ω (``(N_ω ω_max − ω_min)/(2(N_ω−1))``; N_ω = 1: ``(ω_max+ω_min)/2``);
        default the half-spacing and, for N_ω = 1, ``(ω_max−ω_min)/2`` (D1, D2).
    v_dt_power : int
        Power of T on σ_v² in Q (printed: 2).
    gate : bool
        Apply the NIS gate by default (off).
    gate_chi2 : float
        Gate threshold (χ²₁(0.99) = 6.635).
    name : str
        Preset name (metadata only).
    """

    coords: str = "cppv"
    n_r: int = 25
    n_omega: int = 1
    n_theta: int = 6
    r_min_m: float = 1000.0
    r_max_m: float = 10000.0
    omega_min_rps: float = -8 * _DEG
    omega_max_rps: float = 8 * _DEG
    theta_min_rad: float = 0.0
    theta_max_rad: float = 2 * np.pi
    v_init_mps: float = 40.0
    sigma_v0_mps: float = 40.0 / np.sqrt(12.0)
    sigma_v2: float = 1e-3
    sigma_omega_dot2: float = 5e-6
    q_mpc: float = 1e-12
    sigma_beta_rad: float = 0.2 * _DEG
    mpc_substep_s: float = 0.001
    mpc_p0: str = "faithful"
    q_faithful: bool = False
    sigma_omega_faithful: bool = False
    v_dt_power: int = 2
    gate: bool = False
    gate_chi2: float = GATE_CHI2_1_099
    name: str = ""

    def __post_init__(self):
        bad = None
        if self.coords not in ("cppv", "mpc"):
            bad = f"coords must be 'cppv' or 'mpc', not {self.coords!r}"
        elif min(self.n_r, self.n_omega, self.n_theta) < 1:
            bad = f"grid sizes must be >= 1, got ({self.n_r}, {self.n_omega}, {self.n_theta})"
        elif not (0 < self.r_min_m < self.r_max_m):
            bad = f"need 0 < r_min_m < r_max_m, got {self.r_min_m}, {self.r_max_m}"
        elif self.mpc_p0 not in ("faithful", "jacobian"):
            bad = f"mpc_p0 must be 'faithful' or 'jacobian', not {self.mpc_p0!r}"
        elif self.omega_max_rps < self.omega_min_rps:
            bad = f"omega_max_rps {self.omega_max_rps} < omega_min_rps {self.omega_min_rps}"
        if bad:
            raise ValueError(f"BankSettings {self.name or ''}: {bad}".replace("  ", " "))

    @property
    def n_filters(self) -> int:
        """``N_t = N_r N_ω N_θ``."""
        return self.n_r * self.n_omega * self.n_theta

    @property
    def state_names(self) -> tuple[str, ...]:
        return CPPV_STATE if self.coords == "cppv" else MPC_STATE

    def replace(self, **kw) -> "BankSettings":
        return dataclasses.replace(self, **kw)

    @classmethod
    def from_mapping(cls, d: Mapping[str, Any] | None) -> "BankSettings":
        """Settings from a config mapping: an optional ``preset`` (a :data:`PRESETS` name) and
        any field overrides; an unknown key is one clear error."""
        d = dict(d or {})
        base = settings_for(d.pop("preset")) if "preset" in d else cls()
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise ValueError(f"bank settings: unknown key(s) {unknown} (known: {sorted(names)} and 'preset')")
        return dataclasses.replace(base, **d)

    def metadata(self) -> dict[str, Any]:
        """Every setting plus the assumptions of this implementation (for output metadata)."""
        out: dict[str, Any] = dataclasses.asdict(self)
        out.update({
            "n_filters": self.n_filters,
            "units": "m, s, rad; sigma_v2 (m/s)^2/s and sigma_omega_dot2 rad^2/s^3 assumed (D6)",
            "ownship_step": "T*(v_o[k-1]+v_o[k])/2",
            "init": "t[0] from the first finite bearing, no update at the initialising step",
            "diverged": "non-finite mean/cov, non-positive cov diagonal or S: frozen, weight 0",
            "gate_on": "NIS of the bank's mixture prediction (whole bank predict-only)",
            "grid_index": "i = j + N_r*(k + N_omega*l) (range fastest, then omega, then theta)",
            "mpc_cppv_output": "each filter mapped by G^-1 (and its Jacobian), then combined",
        })
        return out


def _case(coords: str, n_r: int, n_omega: int, n_theta: int, **kw) -> BankSettings:
    return BankSettings(coords=coords, n_r=n_r, n_omega=n_omega, n_theta=n_theta,
                        name=kw.pop("name", f"{coords}_{n_r}_{n_omega}_{n_theta}"), **kw)


#: named parameterisations: Table 4.1/4.2 (simulation) and Tables 5.1–5.3 (flight tests)
PRESETS: dict[str, BankSettings] = {
    s.name: s for s in [
        _case("cppv", 25, 1, 6),                      # Table 4.1, the chosen bank (Cases 3-5)
        _case("mpc", 15, 5, 2),                       # Case 5
        # Table 4.2 (seed text: "The heading and angular velocity intervals are kept as 1,
        # N_θ = 1, N_ω = 1 for each variation" in Case 1; Case 2 keeps N_θ = 1; Case 3 N_ω = 1)
        _case("cppv", 10, 1, 1), _case("cppv", 25, 1, 1), _case("cppv", 150, 1, 1),   # Case 1 (N_r)
        _case("cppv", 25, 3, 1), _case("cppv", 25, 6, 1),    # Case 2 (N_ω), with (25,1,1)
        _case("cppv", 25, 1, 3),                             # Case 3 (N_θ), with (25,1,1), (25,1,6)
        _case("cppv", 25, 2, 3), _case("cppv", 15, 2, 5), _case("cppv", 16, 3, 3),  # Case 4
        # not Table 4.2 cases: smaller banks the tests use (kept by name)
        _case("cppv", 10, 1, 6), _case("cppv", 25, 3, 2),
        # Table 5.1: FT20, FT29 (vision bearings); σ_ω² read as the process σ_ω̇²
        _case("cppv", 10, 4, 3, name="table5_1_ft20_ft29", v_init_mps=50.0,
              sigma_v0_mps=50.0 / np.sqrt(12.0), sigma_v2=0.5, sigma_omega_dot2=2.5e-2,
              sigma_beta_rad=np.sqrt(0.025) * _DEG),
        # Table 5.2: FT10 (ω range printed min/max swapped: −10…−1 °/s)
        _case("cppv", 15, 4, 1, name="table5_2_ft10", r_max_m=8000.0, omega_min_rps=-10 * _DEG,
              omega_max_rps=-1 * _DEG, v_init_mps=35.0, sigma_v0_mps=45.0 / np.sqrt(12.0),
              sigma_v2=5.0, sigma_omega_dot2=5e-2),
        # Table 5.3: FT50, 180 filters
        _case("cppv", 15, 4, 3, name="table5_3_ft50", r_max_m=12000.0, omega_min_rps=1 * _DEG,
              omega_max_rps=10 * _DEG, v_init_mps=35.0, sigma_v0_mps=45.0 / np.sqrt(12.0),
              sigma_v2=1.0, sigma_omega_dot2=5e-2),
    ]
}


def settings_for(s: "BankSettings | str | Mapping[str, Any]") -> BankSettings:
    """A :class:`BankSettings` from itself, a :data:`PRESETS` name or a mapping
    (:meth:`BankSettings.from_mapping`)."""
    if isinstance(s, BankSettings):
        return s
    if isinstance(s, str):
        if s not in PRESETS:
            raise ValueError(f"bank preset {s!r} is unknown (known: {sorted(PRESETS)})")
        return PRESETS[s]
    if isinstance(s, Mapping):
        return BankSettings.from_mapping(s)
    raise TypeError(f"bank settings: expected BankSettings, a preset name or a mapping, got {type(s).__name__}")


# ----------------------------------------------------------------------------- grids (§4)

def range_grid(n_r: int, r_min: float, r_max: float) -> tuple[F64, F64]:
    """``r⁽ʲ⁾ = (r_min/2)(ρʲ + ρʲ⁻¹)``, ``σ_r⁽ʲ⁾ = C_R r⁽ʲ⁾`` with ``ρ = (r_max/r_min)^{1/N_r}``
    and ``C_R = 2(ρ−1)/(√12(ρ+1))`` (eq. 3.23–3.24), j = 1..N_r."""
    rho = (r_max / r_min) ** (1.0 / n_r)
    j = np.arange(1, n_r + 1)
    r = 0.5 * r_min * (rho ** j + rho ** (j - 1))
    cr = 2 * (rho - 1) / (np.sqrt(12.0) * (rho + 1))
    return r, cr * r


def omega_grid(s: BankSettings) -> tuple[F64, float]:
    """Turn-rate grid and its σ_ω (eq. 3.25; D1/D2 corrections unless ``sigma_omega_faithful``)."""
    lo, hi, n = s.omega_min_rps, s.omega_max_rps, s.n_omega
    if n == 1:
        sig = (hi + lo) / 2 if s.sigma_omega_faithful else (hi - lo) / 2
        return np.array([(hi + lo) / 2]), float(sig)
    w = lo + np.arange(n) * (hi - lo) / (n - 1)
    sig = (n * hi - lo) / (2 * (n - 1)) if s.sigma_omega_faithful else (hi - lo) / (2 * (n - 1))
    return w, float(sig)


def theta_grid(s: BankSettings) -> tuple[F64, float]:
    """Heading grid ``θ⁽ˡ⁾ = θ_min + (ℓ−1)(θ_max−θ_min)/N_θ``, ``σ_θ = ½(θ_max−θ_min)/N_θ``;
    N_θ = 1: θ = 0, σ_θ = π/√3 (3.29–3.32)."""
    if s.n_theta == 1:
        return np.array([0.0]), float(np.pi / np.sqrt(3.0))
    span = s.theta_max_rad - s.theta_min_rad
    return s.theta_min_rad + np.arange(s.n_theta) * span / s.n_theta, float(0.5 * span / s.n_theta)


# ------------------------------------------------------------------- component sets

@dataclass(frozen=True)
class Components:
    """Gaussian components over runs × filters (a bank; an EKF is one component).

    Attributes
    ----------
    mean : (R, C, n)
    cov : (R, C, n, n)
    logw : (R, C)
        Normalised log-weights (−inf: out of the mixture).
    diverged : (R, C) bool
    """

    mean: F64
    cov: F64
    logw: F64
    diverged: NDArray[np.bool_]


@dataclass(frozen=True)
class StepStats:
    """One bank step: ``loglik`` (R,) = ``log Σ W_{k−1} N(ỹ; 0, S)`` (the IMM's Λ, D4; 0
    where not measured), ``nis`` (R,) of the mixture prediction (NaN where no bearing),
    ``measured`` (R,) a bearing was used, ``gated`` (R,) rejected by the gate, ``new_diverged``
    (R, C); ``ymix``/``Smix`` (R,) the mean and variance of the mixture's predicted
    innovation (``nis = ymix²/Smix``; the IMM combines them over modes)."""

    loglik: F64
    nis: F64
    measured: NDArray[np.bool_]
    gated: NDArray[np.bool_]
    new_diverged: NDArray[np.bool_]
    ymix: F64 | None = None
    Smix: F64 | None = None


@dataclass(frozen=True)
class CppvModel:
    """CPPV-CT transition (digest §2) for :func:`components_step`."""

    settings: BankSettings
    names: tuple[str, ...] = CPPV_STATE
    coords: str = "cppv"

    def predict(self, mean: F64, dt: float, vo: F64) -> tuple[F64, F64]:
        return cppv_predict(mean, dt, vo * dt)

    def noise(self, dt: float) -> F64:
        s = self.settings
        return cppv_process_noise(dt, s.sigma_v2, s.sigma_omega_dot2, faithful=s.q_faithful,
                                  v_dt_power=s.v_dt_power)

    def safe_mean(self) -> F64:
        return np.array([1000.0, 0.0, 50.0, 0.0, 0.0])


@dataclass(frozen=True)
class MpcModel:
    """MPC transition (digest §3; numba Euler) for :func:`components_step`."""

    settings: BankSettings
    engine: str = "numba"
    names: tuple[str, ...] = MPC_STATE
    coords: str = "mpc"

    def predict(self, mean: F64, dt: float, vo: F64) -> tuple[F64, F64]:
        return mpc_transition(mean, vo, dt, substep_s=self.settings.mpc_substep_s, engine=self.engine)

    def noise(self, dt: float) -> F64:
        return self.settings.q_mpc * np.eye(5)

    def safe_mean(self) -> F64:
        return np.array([0.0, 0.0, 0.0, 1e-3, 0.0])


@dataclass(frozen=True)
class CvModel:
    """The IMM's CV mode (digest §5): ``x = [r_N, r_E, v, θ]``; Q_CV is unstated, so
    ``diag(0, 0, T^p σ_v², T σ_θ̇²)`` (config values)."""

    sigma_v2: float = 1e-3
    sigma_theta_dot2: float = 1e-6
    v_dt_power: int = 2
    names: tuple[str, ...] = CV_CPPV_STATE
    coords: str = "cv"

    def predict(self, mean: F64, dt: float, vo: F64) -> tuple[F64, F64]:
        return cv_cppv_transition(mean, dt, vo * dt), cv_cppv_jacobian(mean, dt)

    def noise(self, dt: float) -> F64:
        return cv_process_noise(dt, self.sigma_v2, self.sigma_theta_dot2, v_dt_power=self.v_dt_power)

    def safe_mean(self) -> F64:
        return np.array([1000.0, 0.0, 50.0, 0.0])


def model_for(settings: BankSettings, engine: str = "numba") -> CppvModel | MpcModel:
    """The transition model of a bank's coordinates."""
    return CppvModel(settings) if settings.coords == "cppv" else MpcModel(settings, engine)


def angle_index(names: tuple[str, ...]) -> tuple[int, ...]:
    """Positions of the angle components (circular combination)."""
    return tuple(i for i, n in enumerate(names) if n in ANGLE_STATES)


def bank_prior(settings: BankSettings, beta0: ArrayLike, sigma_rad: float,
               vo0: ArrayLike | None = None) -> Components:
    """The bank's initial components for runs with first bearings ``beta0`` (R,)
    (eq. 3.34–3.36; MPC: ``y₀ = G(x₀)`` with ``P₀`` per 3.40 or ``J_G P₀ J_Gᵀ``, D7).

    Parameters
    ----------
    beta0 : array_like, shape (R,)
    sigma_rad : float
        σ_β (the cross-range std ``r σ_β``).
    vo0 : array_like, shape (R, 2), optional
        Ownship velocity at the start (MPC only; default 0).
    """
    s = settings
    beta0 = np.atleast_1d(np.asarray(beta0, dtype=np.float64))
    R_ = len(beta0)
    r, sr = range_grid(s.n_r, s.r_min_m, s.r_max_m)
    w, sw = omega_grid(s)
    th, sth = theta_grid(s)
    # i = j + N_r (k + N_ω ℓ): range fastest, then ω, then θ (3.33, any fixed enumeration)
    L, K, J = np.meshgrid(np.arange(s.n_theta), np.arange(s.n_omega), np.arange(s.n_r), indexing="ij")
    J, K, L = J.ravel(), K.ravel(), L.ravel()
    N = len(J)
    rj, srj = r[J][None, :], sr[J][None, :]
    cb, sb = np.cos(beta0)[:, None], np.sin(beta0)[:, None]
    x0 = np.empty((R_, N, 5))
    x0[..., 0], x0[..., 1] = rj * cb, rj * sb
    x0[..., 2] = s.v_init_mps
    x0[..., 3] = th[L][None, :]
    x0[..., 4] = w[K][None, :]
    # P_pos = R diag(σ_r², (r σ_β)²) Rᵀ, R the rotation by β₀
    a, b = srj ** 2, (rj * sigma_rad) ** 2
    P0 = np.zeros((R_, N, 5, 5))
    P0[..., 0, 0] = a * cb ** 2 + b * sb ** 2
    P0[..., 1, 1] = a * sb ** 2 + b * cb ** 2
    P0[..., 0, 1] = P0[..., 1, 0] = (a - b) * cb * sb
    P0[..., 2, 2] = s.sigma_v0_mps ** 2
    P0[..., 3, 3] = sth ** 2
    P0[..., 4, 4] = sw ** 2
    if s.coords == "mpc":
        vo = np.zeros((R_, 2)) if vo0 is None else np.broadcast_to(np.asarray(vo0, dtype=np.float64), (R_, 2))
        vb = np.broadcast_to(vo[:, None, :], (R_, N, 2))
        y0 = cppv_to_mpc(x0, vb)
        if s.mpc_p0 == "jacobian":
            JG = numerical_jacobian(lambda x: cppv_to_mpc(x, vb), x0)
            P0 = JG @ P0 @ np.swapaxes(JG, -1, -2)
            P0 = 0.5 * (P0 + np.swapaxes(P0, -1, -2))
        else:
            sv = s.sigma_v0_mps / rj
            P0 = np.zeros((R_, N, 5, 5))
            P0[..., 0, 0] = sv ** 2
            P0[..., 1, 1] = sv ** 2
            P0[..., 2, 2] = sigma_rad ** 2
            P0[..., 3, 3] = (srj / rj ** 2) ** 2
            P0[..., 4, 4] = sw ** 2
        x0 = y0
    logw = np.full((R_, N), -np.log(N))
    return Components(x0, P0, logw, np.zeros((R_, N), dtype=bool))


# ----------------------------------------------------------------------------- step

_EKF_CACHE: dict[tuple[float, str], ExtendedKalmanFilter] = {}


def _ekf(sigma_rad: float, coords: str) -> ExtendedKalmanFilter:
    key = (float(sigma_rad), coords)
    if key not in _EKF_CACHE:
        # the transition is never consulted: predict always passes F, Q and fx
        _EKF_CACHE[key] = ExtendedKalmanFilter(LinearTransition(np.eye(1), np.zeros((1, 1))),
                                               BearingMeasurement(float(sigma_rad), coords))
    return _EKF_CACHE[key]


def logsumexp(a: F64, axis: int = -1) -> F64:
    """``log Σ exp(a)`` along ``axis`` (−inf where every entry is −inf)."""
    m = np.max(a, axis=axis, keepdims=True)
    m = np.where(np.isfinite(m), m, 0.0)
    with np.errstate(divide="ignore"):
        return np.log(np.sum(np.exp(a - m), axis=axis)) + np.squeeze(m, axis)


def _bad(mean: F64, cov: F64) -> NDArray[np.bool_]:
    return ~(np.isfinite(mean).all(axis=-1) & np.isfinite(cov).all(axis=(-1, -2))
             & (np.diagonal(cov, axis1=-2, axis2=-1) > 0).all(axis=-1))


# ------------------------------------------------------------ fused scalar-bearing kernels
# The runs × filters study steps ~10⁵ filters of 5 states a step; numpy's stacked 5×5
# products there cost ~1 µs a filter-step. These two kernels do exactly the
# ExtendedKalmanFilter algebra for one scalar bearing (P⁻ = F P Fᵀ + Q; S = H P⁻ Hᵀ + σ²;
# Joseph update) per filter in compiled loops; tests hold them equal to the EKF path
# (``algebra="ekf"``).

def _predict_innov_kernel(fx, F, P, Q, z, sigma2, coords):  # pragma: no cover - numba
    M, n = fx.shape
    pc = np.empty((M, n, n))
    pht = np.empty((M, n))
    S = np.empty(M)
    yt = np.empty(M)
    bad = np.zeros(M, dtype=np.bool_)
    FP = np.empty((n, n))
    H = np.zeros(n)
    two_pi = 2.0 * np.pi
    for m in range(M):
        for i in range(n):
            for j in range(n):
                acc = 0.0
                for k in range(n):
                    acc += F[m, i, k] * P[m, k, j]
                FP[i, j] = acc
        for i in range(n):
            for j in range(i, n):
                acc = Q[i, j]
                for k in range(n):
                    acc += FP[i, k] * F[m, j, k]
                pc[m, i, j] = acc
                pc[m, j, i] = acc
        x0, x1 = fx[m, 0], fx[m, 1]
        if coords == 0:
            r2 = x0 * x0 + x1 * x1
            H[0], H[1] = -x1 / r2, x0 / r2
            h = np.arctan2(x1, x0)
            for i in range(n):
                pht[m, i] = pc[m, i, 0] * H[0] + pc[m, i, 1] * H[1]
            s = H[0] * pht[m, 0] + H[1] * pht[m, 1] + sigma2
        else:
            h = fx[m, 2]
            for i in range(n):
                pht[m, i] = pc[m, i, 2]
            s = pht[m, 2] + sigma2
        S[m] = s
        d = z[m] - h
        yt[m] = d - two_pi * np.floor((d + np.pi) / two_pi)
        ok = s > 0.0 and np.isfinite(s)
        for i in range(n):
            if not (np.isfinite(fx[m, i]) and pc[m, i, i] > 0.0):
                ok = False
            for j in range(n):
                if not np.isfinite(pc[m, i, j]):
                    ok = False
        bad[m] = not ok
    return pc, pht, S, yt, bad


def _update_kernel(pm, pc, pht, S, yt, use, sigma2, coords):  # pragma: no cover - numba
    M, n = pm.shape
    m1 = pm.copy()
    c1 = pc.copy()
    bad = np.zeros(M, dtype=np.bool_)
    K = np.empty(n)
    H = np.zeros(n)
    A = np.empty((n, n))
    AP = np.empty((n, n))
    for m in range(M):
        if not use[m]:
            continue
        x0, x1 = pm[m, 0], pm[m, 1]
        for i in range(n):
            H[i] = 0.0
        if coords == 0:
            r2 = x0 * x0 + x1 * x1
            H[0], H[1] = -x1 / r2, x0 / r2
        else:
            H[2] = 1.0
        for i in range(n):
            K[i] = pht[m, i] / S[m]
            m1[m, i] = pm[m, i] + K[i] * yt[m]
        for i in range(n):
            for j in range(n):
                A[i, j] = (1.0 if i == j else 0.0) - K[i] * H[j]
        for i in range(n):
            for j in range(n):
                acc = 0.0
                for k in range(n):
                    acc += A[i, k] * pc[m, k, j]
                AP[i, j] = acc
        ok = True
        for i in range(n):
            for j in range(i, n):
                acc = sigma2 * K[i] * K[j]
                for k in range(n):
                    acc += AP[i, k] * A[j, k]
                c1[m, i, j] = acc
                c1[m, j, i] = acc
                if not np.isfinite(acc):
                    ok = False
            if not (c1[m, i, i] > 0.0 and np.isfinite(m1[m, i])):
                ok = False
        bad[m] = not ok
    return m1, c1, bad


_predict_innov_kernel = lazy_njit(_predict_innov_kernel)
_update_kernel = lazy_njit(_update_kernel)


def _flat(a, n_tail):
    return kernel_input(a.reshape((-1,) + a.shape[a.ndim - n_tail:]))


def components_step(model, comp: Components, dt: float, vo: ArrayLike, z: ArrayLike,
                    sigma_rad: float, *, gate: bool = False, gate_chi2: float = GATE_CHI2_1_099,
                    algebra: str = "numba") -> tuple[Components, StepStats]:
    """Predict every component over ``dt`` and update it with the bearing ``z``.

    Parameters
    ----------
    model : CppvModel, MpcModel or CvModel
    comp : Components
        Batch (R, C).
    dt : float
        Step (s), > 0.
    vo : array_like, shape (R, 2) or (2,)
        Ownship velocity (N, E) over the step.
    z : array_like, shape (R,)
        Bearings (rad); NaN: predict only.
    sigma_rad : float
    gate, gate_chi2 :
        NIS gate on the mixture prediction (module docstring).
    algebra : {"numba", "ekf"}
        The covariance algebra: the fused scalar-bearing kernels (fast at runs × filters) or
        :class:`~pipeline.estimate.ekf.ExtendedKalmanFilter` (the reference; equal to round-off).
    """
    if algebra not in ("numba", "ekf"):
        raise ValueError(f"components_step: algebra must be 'numba' or 'ekf', not {algebra!r}")
    mean, cov, logw, div = comp.mean, comp.cov, comp.logw, comp.diverged
    R_, C, n = mean.shape
    vo = np.broadcast_to(np.asarray(vo, dtype=np.float64), (R_, 2))
    vb = np.broadcast_to(vo[:, None, :], (R_, C, 2))
    z = np.broadcast_to(np.asarray(z, dtype=np.float64), (R_,))
    any_div = bool(div.any())
    if any_div:  # frozen filters step a benign stand-in; their values are restored below
        mean = np.where(div[..., None], model.safe_mean(), mean)
        cov = np.where(div[..., None, None], np.eye(n), cov)
    fast = algebra == "numba" and HAVE_NUMBA
    ekf = _ekf(sigma_rad, model.coords)
    fx, F = model.predict(mean, dt, vb)
    coords = 1 if model.coords == "mpc" else 0
    s2 = float(sigma_rad) ** 2
    with np.errstate(invalid="ignore", over="ignore"):
        if fast:
            zf = kernel_input(np.broadcast_to(z[:, None], (R_, C)).reshape(-1))
            pc, pht, S, ytil, badp = _predict_innov_kernel(_flat(fx, 1), _flat(F, 2), _flat(cov, 2),
                                                           kernel_input(model.noise(dt)), zf, s2, coords)
            pm = fx
            pc, pht = pc.reshape(R_, C, n, n), pht.reshape(R_, C, n)
            S, ytil = S.reshape(R_, C), ytil.reshape(R_, C)
            new_div = badp.reshape(R_, C) & ~div
        else:
            pred = ekf.predict(GaussianState(mean, cov, 0), 1, F=F, Q=model.noise(dt), fx=fx)
            pm, pc = pred.mean, pred.cov
            meas = ekf.measurement
            hx, H = meas.h_and_jacobian(pm)
            h0 = H[..., 0, :]
            S = np.einsum("...i,...ij,...j->...", h0, pc, h0) + s2
            ytil = meas.residual(z[:, None], hx[..., 0])
            new_div = (_bad(pm, pc) | ~(S > 0)) & ~div
    div = div | new_div
    has_z = np.isfinite(z)
    ll_c = -0.5 * (_LOG2PI + np.log(np.where(div, 1.0, S)) + np.where(div, 0.0, ytil) ** 2 / np.where(div, 1.0, S))
    lw_prior = np.where(div, -np.inf, logw)
    lw_prior = lw_prior - logsumexp(lw_prior)[:, None]
    w = np.exp(lw_prior)
    w = np.where(np.isfinite(w), w, 0.0)
    ym = np.sum(w * np.where(div, 0.0, ytil), axis=1)
    Sm = np.sum(w * (np.where(div, 1.0, S) + (np.where(div, 0.0, ytil) - ym[:, None]) ** 2), axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        nis = np.where(has_z, ym ** 2 / Sm, np.nan)
    gated = has_z & (nis > gate_chi2) if gate else np.zeros(R_, dtype=bool)
    use = has_z & ~gated
    upd = use[:, None] & ~div
    if div.any():
        pm = np.where(div[..., None], model.safe_mean(), pm)
        pc = np.where(div[..., None, None], np.eye(n), pc)
    if fast:
        m1, c1, badu = _update_kernel(_flat(pm, 1), _flat(pc, 2), _flat(pht, 1), kernel_input(S.reshape(-1)),
                                      kernel_input(ytil.reshape(-1)), kernel_input(upd.reshape(-1)), s2, coords)
        m1, c1 = m1.reshape(R_, C, n), c1.reshape(R_, C, n, n)
        bad_post = badu.reshape(R_, C) & ~div
    else:
        zz = np.where(upd, z[:, None], np.nan)[..., None]
        post, _ = ekf.update_stats(GaussianState(pm, pc, 1), zz)
        m1, c1 = post.mean, post.cov
        bad_post = _bad(m1, c1) & ~div
    if bad_post.any():
        new_div |= bad_post
        div = div | bad_post
    if div.any():  # frozen at the last finite estimate
        m1 = np.where(div[..., None], comp.mean, m1)
        c1 = np.where(div[..., None, None], comp.cov, c1)
    loglik = np.where(use, logsumexp(lw_prior + ll_c), 0.0)
    lw = np.where(use[:, None], lw_prior + ll_c, lw_prior)
    lw = np.where(div, -np.inf, lw)
    norm = logsumexp(lw)
    lw = lw - np.where(np.isfinite(norm), norm, 0.0)[:, None]
    return Components(m1, c1, lw, div), StepStats(loglik, nis, use, gated, new_div, ym, Sm)


def _combine_kernel(mean, cov, w, is_angle):  # pragma: no cover - compiled by numba
    """:func:`combine_numpy` for (M, C, n) means, (M, C, n, n) covariances, (M, C) weights
    (finite, ≥ 0), in one compiled pass per mixture (the IMM mixes ~7 times a step)."""
    M, C, n = mean.shape
    m_out = np.zeros((M, n))
    P_out = np.zeros((M, n, n))
    mw = np.empty((C, n))
    two_pi = 2.0 * np.pi
    for q in range(M):
        best, wbest = 0, w[q, 0]
        for c in range(1, C):
            if w[q, c] > wbest:
                best, wbest = c, w[q, c]
        for c in range(C):
            for i in range(n):
                mw[c, i] = mean[q, c, i] if w[q, c] > 0 else 0.0
        for i in range(n):
            if is_angle[i]:
                ref = mw[best, i]
                for c in range(C):
                    d = mw[c, i] - ref
                    mw[c, i] = ref + ((d + np.pi) % two_pi - np.pi)
        for c in range(C):
            for i in range(n):
                m_out[q, i] += w[q, c] * mw[c, i]
        for c in range(C):
            wc = w[q, c]
            if wc > 0:
                for i in range(n):
                    di = mw[c, i] - m_out[q, i]
                    for j in range(n):
                        P_out[q, i, j] += wc * (cov[q, c, i, j] + di * (mw[c, j] - m_out[q, j]))
    return m_out, P_out


_combine_kernel = lazy_njit(_combine_kernel)


def combine(mean: F64, cov: F64 | None, logw: F64, angle_idx: tuple[int, ...] = ()) -> tuple[F64, F64 | None]:
    """Mixture moments (3.21–3.22) with wrapped deviations on the angle components ``angle_idx``.

    An angle's mean is ``θ_ref + Σ W wrap(θᵢ − θ_ref)`` about the heaviest component's ``θ_ref``
    (the linear mean of the thesis wherever no component sits across the ±π cut, and correct
    across it); deviations ``dᵢ`` are wrapped too. The mean is not wrapped (a component's θ
    accumulates ωT; :func:`wrap_angle` it for output). With a covariance and numba, one
    compiled kernel (tested equal to :func:`combine_numpy`, the reference).

    Parameters
    ----------
    mean : (..., C, n)
    cov : (..., C, n, n) or None (then only the mean)
    logw : (..., C) normalised log-weights (−inf: excluded)
    """
    if cov is None or not HAVE_NUMBA or mean.ndim < 2:
        return combine_numpy(mean, cov, logw, angle_idx)
    lead, (C, n) = mean.shape[:-2], mean.shape[-2:]
    cov = np.broadcast_to(cov, lead + (C, n, n))
    logw = np.broadcast_to(logw, lead + (C,))
    with np.errstate(over="ignore"):
        w = np.exp(logw)
    w = np.where(np.isfinite(w), w, 0.0)
    is_angle = np.zeros(n, dtype=np.bool_)
    is_angle[list(angle_idx)] = True
    m, P = _combine_kernel(kernel_input(mean.reshape(-1, C, n).astype(np.float64, copy=False)),
                           kernel_input(cov.reshape(-1, C, n, n).astype(np.float64, copy=False)),
                           kernel_input(w.reshape(-1, C)), kernel_input(is_angle))
    return m.reshape(lead + (n,)), P.reshape(lead + (n, n))


def combine_numpy(mean: F64, cov: F64 | None, logw: F64, angle_idx: tuple[int, ...] = ()) -> tuple[F64, F64 | None]:
    """:func:`combine` in numpy (the reference of its compiled kernel; the mean-only path)."""
    w = np.exp(logw)
    w = np.where(np.isfinite(w), w, 0.0)
    mw = np.where((w > 0)[..., None], mean, 0.0)
    if angle_idx:
        ref = np.take_along_axis(mw, np.argmax(w, axis=-1)[..., None, None], axis=-2)  # (..., 1, n)
        mw = mw.copy()
        for a in angle_idx:
            mw[..., a] = ref[..., a] + wrap_angle(mw[..., a] - ref[..., a])
    m = np.einsum("...c,...cn->...n", w, mw)
    if cov is None:
        return m, None
    d = mw - m[..., None, :]
    cw = np.where((w > 0)[..., None, None], cov, 0.0)
    P = np.einsum("...c,...cij->...ij", w, cw) + np.einsum("...c,...ci,...cj->...ij", w, d, d)
    return m, P


def weight_entropy(logw: F64) -> F64:
    """``−Σ W log W`` (nats) over the last axis (0: one filter holds all the weight;
    ``log N``: uniform)."""
    w = np.exp(logw)
    with np.errstate(invalid="ignore"):
        t = np.where(w > 0, w * logw, 0.0)
    return -np.sum(t, axis=-1)


def mpc_components_to_cppv(mean: F64, cov: F64 | None, vo: F64) -> tuple[F64, F64 | None]:
    """Map MPC components (..., n) to CPPV by ``G⁻¹`` at ownship velocity ``vo`` (..., 2),
    covariances by the Jacobian of ``G⁻¹`` (:func:`~pipeline.estimate.models.mpc_to_cppv_jacobian`)."""
    vo = np.broadcast_to(vo, mean.shape[:-1] + (2,))
    x = mpc_to_cppv(mean, vo)
    if cov is None:
        return x, None
    Jg = mpc_to_cppv_jacobian(mean, vo)
    return x, Jg @ cov @ np.swapaxes(Jg, -1, -2)


# ----------------------------------------------------------------------------- run

@dataclass(frozen=True)
class BankTrack:
    """A bank run over runs × time × filters (arrays ordered runs, time, ...).

    Attributes
    ----------
    settings : BankSettings
    t_s : (T,)
    state_names : tuple of str
        Of ``mean``/``cov`` (the filters' coordinates); ``cppv_*`` are in :data:`CPPV_STATE`.
    mean, cov : (R, T, n), (R, T, n, n) or None
        Combined estimate in the filters' own coordinates (wrapped deviations on angles;
        angles in the output wrapped to [−π, π)).
    cppv_mean, cppv_cov : (R, T, 5), (R, T, 5, 5) or None
        Combined estimate in CPPV (the same arrays as ``mean``/``cov`` for a CPPV bank).
    ml_index : (R, T) int
        The max-weight filter.
    ml_mean, ml_cov : (R, T, 5), (R, T, 5, 5) or None
        Its estimate in CPPV.
    weights : (R, T, N) or None
    entropy : (R, T)
        Weight entropy (nats).
    loglik : (R, T)
        ``log Σ W_{k−1} N(ỹ; 0, S)`` (0 where no bearing was used).
    nis : (R, T)
        NIS of the mixture prediction (NaN where no bearing).
    measured, gated : (R, T) bool
    diverged : (R, N) bool
    diverged_step : (R, N) int
        Step at which each filter was frozen (−1: never).
    component_mean : (R, T, N, n) or None (``store_components``)
    metadata : dict
    """

    settings: BankSettings
    t_s: F64
    state_names: tuple[str, ...]
    mean: F64
    cov: F64 | None
    cppv_mean: F64
    cppv_cov: F64 | None
    ml_index: NDArray[np.int64]
    ml_mean: F64
    ml_cov: F64 | None
    weights: F64 | None
    entropy: F64
    loglik: F64
    nis: F64
    measured: NDArray[np.bool_]
    gated: NDArray[np.bool_]
    diverged: NDArray[np.bool_]
    diverged_step: NDArray[np.int64]
    component_mean: F64 | None = None
    metadata: dict = field(default_factory=dict)

    @property
    def n_predict_only(self) -> NDArray[np.int64]:
        """Steps per run without a used bearing (NaN or gated; the initialising step counts)."""
        return (~self.measured).sum(axis=1)


def check_inputs(t_s: ArrayLike, z_rad: ArrayLike, ownship: ArrayLike | None,
                 who: str = "run_bank") -> tuple[F64, F64, F64]:
    """``(t (T,), z (R, T), v_o (R, T, 2))`` from :func:`run_bank`'s inputs, each checked with
    one clear error."""
    t = np.asarray(t_s, dtype=np.float64)
    if t.ndim != 1 or len(t) < 1:
        raise ValueError(f"{who}: t_s must be 1-D with >= 1 step, got shape {t.shape}")
    if len(t) > 1 and not np.all(np.diff(t) > 0):
        raise ValueError(f"{who}: t_s must be strictly increasing")
    z = np.asarray(z_rad, dtype=np.float64)
    if z.ndim == 1:
        z = z[None]
    if z.ndim != 2 or z.shape[1] != len(t):
        raise ValueError(f"{who}: z_rad shaped {np.shape(z_rad)}, expected ({len(t)},) or (R, {len(t)})")
    R_, T = z.shape
    if ownship is None:
        vo = np.zeros((R_, T, 2))
    else:
        o = np.asarray(ownship, dtype=np.float64)
        if o.shape[-1] not in (2, 4) or o.shape[-2] != T or o.ndim not in (2, 3):
            raise ValueError(f"{who}: ownship shaped {o.shape}, expected (T, 4|2) or (R, T, 4|2) with T={T}")
        if o.ndim == 3 and o.shape[0] not in (1, R_):
            raise ValueError(f"{who}: ownship has {o.shape[0]} runs, the bearings {R_}")
        vo = np.broadcast_to(o[..., -2:], (R_, T, 2))
        if not np.isfinite(vo).all():
            raise ValueError(f"{who}: the ownship velocity has non-finite values")
    return t, z, vo


def first_bearing(z: F64, who: str = "run_bank") -> F64:
    """Each run's bearing at the first step (R,), the one the prior is built from at ``t_s[0]``.

    A run whose first bearing is missing is an error naming the runs and how many steps they
    lack: a later bearing stamped at ``t_s[0]`` would start the bank from the wrong line of
    sight (the ownship moves meanwhile) and then be used a second time at its own step."""
    z = np.asarray(z, dtype=np.float64)
    ok = np.isfinite(z)
    if not ok.any(axis=1).all():
        raise ValueError(f"{who}: run(s) {np.flatnonzero(~ok.any(axis=1)).tolist()} have no finite bearing")
    late = np.flatnonzero(~ok[:, 0])
    if len(late):
        lead = ok[late].argmax(axis=1)
        raise ValueError(f"{who}: run(s) {late[:10].tolist()} start with {lead[:10].tolist()} missing bearing(s); "
                         f"the prior is built from the bearing at t_s[0]: start the runs at their first bearing")
    return z[:, 0]


def run_bank(settings: "BankSettings | str | Mapping[str, Any]", t_s: ArrayLike, z_rad: ArrayLike,
             sigma_rad: float | None = None, ownship: ArrayLike | None = None, *,
             gate: bool | None = None, store_cov: bool = True, store_weights: bool = True,
             store_components: bool = False, engine: str = "numba",
             algebra: str = "numba") -> BankTrack:
    """Run a bank over runs × time (module docstring).

    Parameters
    ----------
    settings : BankSettings, a :data:`PRESETS` name, or a mapping
    t_s : array_like, shape (T,)
        Step times (s), strictly increasing; variable steps allowed (D9).
    z_rad : array_like, shape (T,) or (R, T)
        Bearings ``atan2(ΔE, ΔN)`` (rad); NaN: predict only.
    sigma_rad : float, optional
        σ_β (default ``settings.sigma_beta_rad``).
    ownship : array_like, shape (T, 4|2) or (R, T, 4|2), optional
        ``(N, E, v_N, v_E)`` or ``(v_N, v_E)`` per step (only the velocity is used).
    gate : bool, optional
        The NIS gate (default ``settings.gate``).
    store_cov, store_weights, store_components : bool
        Keep the (R, T, n, n) covariances, the (R, T, N) weights, the (R, T, N, n) filter means
        (a 500-run study wants the first two off).
    engine : {"numba", "numpy"}
        MPC predict.
    algebra : {"numba", "ekf"}
        Covariance algebra (:func:`components_step`).

    Returns
    -------
    BankTrack
    """
    s = settings_for(settings)
    sigma = float(s.sigma_beta_rad if sigma_rad is None else sigma_rad)
    if not (sigma > 0):
        raise ValueError(f"run_bank: sigma_rad must be > 0, got {sigma_rad}")
    gate = s.gate if gate is None else bool(gate)
    t, z, vo = check_inputs(t_s, z_rad, ownship)
    R_, T = z.shape
    model = model_for(s, engine)
    comp = bank_prior(s, first_bearing(z), sigma, vo[:, 0])
    N, n = s.n_filters, comp.mean.shape[-1]
    aidx = angle_index(model.names)
    mean = np.empty((T, R_, n))
    cov = np.empty((T, R_, n, n)) if store_cov else None
    mpc = s.coords == "mpc"
    cm = np.empty((T, R_, 5)) if mpc else mean
    cc = (np.empty((T, R_, 5, 5)) if store_cov else None) if mpc else cov
    mli = np.empty((T, R_), dtype=np.int64)
    mlm = np.empty((T, R_, 5))
    mlc = np.empty((T, R_, 5, 5)) if store_cov else None
    W = np.empty((T, R_, N)) if store_weights else None
    comps = np.empty((T, R_, N, n)) if store_components else None
    ent, ll, nis = np.empty((T, R_)), np.zeros((T, R_)), np.full((T, R_), np.nan)
    measured, gated = np.zeros((T, R_), dtype=bool), np.zeros((T, R_), dtype=bool)
    div_step = np.full((R_, N), -1, dtype=np.int64)
    rr = np.arange(R_)
    for k in range(T):
        if k:
            dt = t[k] - t[k - 1]
            comp, st = components_step(model, comp, dt, 0.5 * (vo[:, k - 1] + vo[:, k]), z[:, k], sigma,
                                       gate=gate, gate_chi2=s.gate_chi2, algebra=algebra)
            ll[k], nis[k], measured[k], gated[k] = st.loglik, st.nis, st.measured, st.gated
            div_step[st.new_diverged] = k
        m, P = combine(comp.mean, comp.cov if store_cov else None, comp.logw, aidx)
        for a in aidx:
            m[..., a] = wrap_angle(m[..., a])
        mean[k] = m
        if store_cov:
            cov[k] = P
        i = np.argmax(comp.logw, axis=1)
        mli[k] = i
        xm, Pm = comp.mean[rr, i].copy(), comp.cov[rr, i]
        if mpc:
            xc, Pc = mpc_components_to_cppv(comp.mean, comp.cov if store_cov else None, vo[:, k][:, None, :])
            m2, P2 = combine(xc, Pc, comp.logw, angle_index(CPPV_STATE))
            m2[..., 3] = wrap_angle(m2[..., 3])
            cm[k] = m2
            if store_cov:
                cc[k] = P2
            xm, Pm = xc[rr, i], (Pc[rr, i] if store_cov else None)
        xm[..., 3] = wrap_angle(xm[..., 3])
        mlm[k] = xm
        if store_cov:
            mlc[k] = Pm
        if store_weights:
            W[k] = np.exp(comp.logw)
        if store_components:
            comps[k] = comp.mean
        ent[k] = weight_entropy(comp.logw)

    def rt(a):
        return None if a is None else np.swapaxes(a, 0, 1)

    meta = s.metadata()
    meta.update({"sigma_beta_rad": sigma, "gate": gate, "n_runs": R_, "n_steps": T})
    return BankTrack(s, t, model.names, rt(mean), rt(cov), rt(cm), rt(cc), rt(mli), rt(mlm), rt(mlc),
                     rt(W), rt(ent), rt(ll), rt(nis), rt(measured), rt(gated), comp.diverged.copy(),
                     div_step, None if comps is None else np.swapaxes(comps, 0, 1), meta)
