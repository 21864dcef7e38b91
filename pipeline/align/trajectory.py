"""Learning the intended trajectory from several demonstrations: nested EM over a hidden
trajectory and the demos' time indices (seed 004 §3, after Coates, Abbeel & Ng 2008).

Generative model (seed 004 §2, eqs. 3.1–3.3, with τ₀ ≡ 0 from Coates et al. eq. 4):

.. math::

    z_{t+1} = f(z_t) + \\beta_t + \\omega^{(z)},\\quad \\omega^{(z)} \\sim N(0, \\Sigma^{(z)}),
    \\qquad y^k_j = h(z_{\\tau^k_j}) + \\omega^{(y)},\\quad \\omega^{(y)} \\sim N(0, \\Sigma^{(y)}),

    P(\\tau^k_{j+1} - \\tau^k_j = i) = d^k_i,\\ i \\in \\{1, 2, 3\\},\\qquad \\tau^k_0 = 0,

with ``t = 0..T−1`` and ``T = 2 × mean N^k`` ("T = 2 × mean N^k", §2). Note the seed's
names: Σ^(z) is the *process* noise of the hidden trajectory, Σ^(y) the *observation* noise
(sensor and pilot error, "The noise covers both sensor error and pilot error").

One EM iteration (§3, steps 2–5):

1. **E-step** (hidden trajectory): with τ fixed, the samples mapped to hidden step t are 0..M
   stacked measurements of ``z_t`` ("one hidden step can receive 0..M observations", Fig. 3.2);
   the estimator framework's :class:`~pipeline.estimate.ekf.ExtendedKalmanFilter` /
   :func:`~pipeline.estimate.ekf.run_filter` (NaN rows: no measurement) and
   :func:`~pipeline.estimate.smoother.rts_smooth` give ``μ_{t|T−1}``, ``Σ_{t|T−1}`` and the
   smoother gains ``L_t``; the log-likelihood ``log p(y | τ)`` is the prediction-error
   decomposition of the filter's innovations.
2. **M-step** (eqs. 3.5–3.8, as corrected in the digest's errata): with ``A = Df``,
   ``δμ_t = μ_{t+1} − f(μ_t) − β_t`` and ``P_t = Σ_{t+1} − Σ_{t+1} L_tᵀ Aᵀ − A L_t Σ_{t+1}``,

   .. math::

       \\Sigma^{(z)} = \\frac{1}{T-1} \\sum_t \\left[\\delta\\mu_t \\delta\\mu_t^T + A \\Sigma_t A^T + P_t\\right],
       \\qquad
       \\Sigma^{(y)} = \\frac{1}{N_{obs}} \\sum_{k, j} \\left[\\delta y\\, \\delta y^T + C \\Sigma_{\\tau^k_j} C^T\\right],

   ``δy = y^k_j − h(μ_{τ^k_j})`` ("(3.8) prints δμδμᵀ in R; it should be δyδyᵀ"; "(3.6) ... it
   should be y_j^k = h(z_{τ_j^k})"; "use T−1 transitions for Q, and the count of all
   observations for R"). Diagonal (default) or full; both shared by the demos.
3. **Bias** (§3.4, eq. 3.17): ``β_t`` is the model-prediction error on the driven components
   (accelerations, and the attitude quaternion of the 13-D model), shrunk by a ridge penalty
   ``(ridge/2) βᵀ Σ^(z)⁻¹ β`` (prior ``β ~ N(0, Σ^(z)/ridge)``): ``β_t = MPE_t / (1 + ridge)``,
   recomputed every iteration ("Regularize it, or it absorbs all error and Q collapses", §11).
4. **Time alignment** (eqs. 3.9–3.14, with ``y_s`` for the printed ``y_0``): per demo, the
   max-product DP ``Q(s, t) = ℓ(y_s | z_t) + max_{i∈{1,2,3}} [log d_i + Q(s−1, t−i)]``,
   ``Q(0, t) = ℓ(y_0 | z_0)`` at ``t = 0`` only (τ₀ = 0), computed only inside the band
   ``c_s − C ≤ t ≤ c_s + C``; backtracked from the best ``t ≤ T−1`` of the last sample (free end).
   ``c_s = s (T−1)/(N^k−1)``, which is the seed's ``2s`` when ``N^k`` is the mean length (the
   slope 2 "comes from T≈2N"); a demo longer or shorter than the mean keeps its end inside the
   band.
5. **d** by ML (§3, step 5): ``d^k_i = #{j: τ_{j+1} − τ_j = i}/(N^k − 1)``, floored.

Initialisation (step 1): ``Σ^(y)`` from the demos' second differences, ``Σ^(z)`` from the
model-prediction error of the demos' average on the hidden axis, ``d_i = 1/3`` ("d_i^k=1/3"),
τ from DTW to the median-length demo (or the seed's linear stretch, ``init_tau="linear"``);
``z_0 ~ N(μ_0, Σ_0)`` from the demos' first samples, held fixed.

Stops at a relative change of the objective ``log p(y | τ) + log P(τ | d)`` below ``tol`` or
after ``max_iter`` E-steps.

Dynamics: the generic kinematic model (linear, so the EKF is the exact Kalman filter here):
NED position, velocity and acceleration with ``p += v Δt + a Δt²/2``, ``v += a Δt`` and a
random-walk acceleration, and (13-D) the attitude quaternion (scalar first) as a random walk,
made sign-continuous in the demos before fitting (q ≡ −q, §11). The hidden step is ``Δt/2``.
Or (``dynamics="yak54"``, simulated demos only) the seed's airframe model z = [s; u] (§2:
"Hidden trajectory: z_t=[s_t;u_t]"): NED position and velocity, attitude quaternion, body rates
and the four controls (:mod:`pipeline.estimate.aircraft`), Euler-integrated, without the lift
that the thesis never gives a formula for ("Either model it ... or let β absorb it"): the bias
terms β on the six accelerations absorb it (§3.4: "Without providing the bias terms the learning
algorithm was unable to learn the intended trajectory"); A_t = Df(μ_t) per step.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from ..frames.rotations import quat_continuity
from ..estimate.aircraft import YAK54_COLUMNS, YAK54_DRIVEN, Yak54Params, Yak54Transition, yak54_linearise
from ..estimate.base import GaussianState, LinearMeasurement, LinearTransition
from ..estimate.ekf import ExtendedKalmanFilter, run_filter
from ..estimate.smoother import rts_smooth
from .dtw import dtw

try:  # installed with scikit-learn (hmmlearn's dependency); without it BLAS is left alone
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover
    threadpool_limits = None

F64 = NDArray[np.float64]

#: the 13 columns of the kinematic model's demos and hidden state (STATE table names)
COLUMNS: tuple[str, ...] = (
    "pos_n_m", "pos_e_m", "pos_d_m", "vel_n_mps", "vel_e_mps", "vel_d_mps",
    "acc_n_mps2", "acc_e_mps2", "acc_d_mps2", "q_w", "q_x", "q_y", "q_z",
)
#: the hidden-state models: the generic kinematic one, and the seed's Yak54 airframe (simulated
#: demos with its 17 columns only; no lift term, β absorbs it)
DYNAMICS: tuple[str, ...] = ("kinematic", "yak54")
#: observed columns (of :data:`COLUMNS`) by demo width D: position only, position–velocity–
#: acceleration, everything
DIMS: dict[int, tuple[int, ...]] = {3: (0, 1, 2), 9: tuple(range(9)), 13: tuple(range(13))}
#: default ridge of the bias terms (β = MPE / (1 + ridge))
DEFAULT_RIDGE = 1.0
#: floor on d_i (a step never seen stays possible, so the band never becomes infeasible)
D_FLOOR = 1e-4
#: relative floor on the noise variances (of the data's own scale)
VAR_FLOOR = 1e-10


class TrajectoryError(ValueError):
    """Bad demonstrations or settings for the trajectory learner (one clear line)."""


def _real(v) -> bool:
    """A real number (not a bool, a string or None)."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


def _whole_number(v, least: int) -> bool:
    """``v`` is a whole number >= ``least`` (an integral float such as 20.0 counts; 1.9 does not)."""
    return _real(v) and bool(np.isfinite(v)) and float(v).is_integer() and v >= least


def kinematic_transition(dt: float, n_x: int) -> F64:
    """The kinematic model's ``F`` (``n_x`` = 9: position–velocity–acceleration, 13: plus the
    random-walk quaternion), Euler-integrated (seed 004 §4: "simple Euler integration") with the
    exact ``a Δt²/2`` position term."""
    F = np.eye(n_x)
    for a in range(3):
        F[a, 3 + a] = dt
        F[a, 6 + a] = 0.5 * dt * dt
        F[3 + a, 6 + a] = dt
    return F


def quaternion_continuous(q: ArrayLike, reference: ArrayLike | None = None) -> F64:
    """Flip the sign of quaternion rows (``(N, 4)``) so that each has a non-negative dot product
    with the previous one (q ≡ −q, digest §11 "Enforce sign continuity";
    :func:`~pipeline.frames.rotations.quat_continuity`), the first row first made to agree with
    ``reference`` where given (so that every demo starts on the same sheet)."""
    q = np.array(q, dtype=np.float64)
    if len(q) == 0:
        return q
    if reference is not None and float(q[0] @ np.asarray(reference, dtype=np.float64)) < 0:
        q = -q
    return quat_continuity(q)


@njit(cache=True)
def _align_dp(emis, lo, logd, T):  # pragma: no cover - compiled
    """Banded max-product DP of one demo: ``emis[s, w]`` is ℓ(y_s | z_{lo[s]+w}); returns τ."""
    N, W = emis.shape
    Q = np.full((N, W), -np.inf)
    back = np.zeros((N, W), dtype=np.int64)
    # τ_0 ≡ 0
    if lo[0] <= 0 < lo[0] + W:
        Q[0, -lo[0]] = emis[0, -lo[0]]
    for s in range(1, N):
        for w in range(W):
            t = lo[s] + w
            if t < 0 or t > T - 1:
                continue
            best = -np.inf
            arg = -1
            for i in range(1, 4):
                wp = t - i - lo[s - 1]
                if 0 <= wp < W:
                    v = Q[s - 1, wp] + logd[i - 1]
                    if v > best:
                        best = v
                        arg = wp
            if arg >= 0:
                Q[s, w] = best + emis[s, w]
                back[s, w] = arg
    w = 0
    best = -np.inf
    for ww in range(W):
        if Q[N - 1, ww] > best:
            best = Q[N - 1, ww]
            w = ww
    tau = np.empty(N, dtype=np.int64)
    if best == -np.inf:
        tau[:] = -1
        return tau
    for s in range(N - 1, -1, -1):
        tau[s] = lo[s] + w
        w = back[s, w]
    return tau


def _tau_indices(tk: ArrayLike, k: int) -> NDArray[np.int64]:
    """Demo ``k``'s given τ as int64: integers, or floats holding whole numbers (a fractional,
    NaN or infinite index is refused rather than truncated)."""
    a = np.asarray(tk)
    if a.dtype.kind not in "iuf":
        raise TrajectoryError(f"TrajectoryLearner.fit: tau[{k}] must hold integer hidden indices, got dtype {a.dtype}")
    if a.size == 0:
        raise TrajectoryError(f"TrajectoryLearner.fit: tau[{k}] is empty")
    if a.dtype.kind == "f":
        bad = (~np.isfinite(a) | (a != np.round(a))).ravel()
        if bad.any():
            j = int(np.argmax(bad))
            raise TrajectoryError(f"TrajectoryLearner.fit: tau[{k}] must hold integer hidden indices; sample {j} "
                                  f"is {a.ravel()[j].item()!r} (refused rather than truncated)")
    return np.asarray(a, dtype=np.int64)


def alignment_band(N: int, T: int, C: int) -> NDArray[np.int64]:
    """Lowest hidden index of each sample's alignment band (the band is ``lo .. lo + 2C``):
    ``round(c_s) − C`` with the centre ``c_s = s(T−1)/(N−1)`` (``2s`` for a demo of the mean length)."""
    slope = (T - 1) / max(N - 1, 1)
    return np.round(np.arange(N) * slope).astype(np.int64) - int(C)


@dataclass(frozen=True)
class _Fit:
    """One E-step's result (internal)."""

    mean: F64  # (T, n_x) smoothed
    cov: F64  # (T, n_x, n_x)
    gain: F64  # (T, n_x, n_x)
    loglik_y: float


class TrajectoryLearner:
    """The nested-EM trajectory learner of seed 004 §3 (see the module docstring).

    Parameters
    ----------
    dt : float
        Sample interval of the demos (s); the hidden step is ``dt/2`` (``T = 2 N``).
    window_C : int
        Half-width C of the alignment band (hidden steps; config ``align.window_C``).
    max_iter : int
        Most E-steps (seed: none given; Coates et al.: "5–20 is a guess", §11).
    tol : float
        Stop at a relative objective change below this.
    ridge : float
        Ridge penalty of the bias terms, ``β = MPE/(1 + ridge)``.
    dynamics : {"kinematic", "yak54"}
        The generic kinematic model (9-D hidden state for 3/9-D demos, 13-D for 13-D demos), or
        the seed's Yak54 airframe (:mod:`pipeline.estimate.aircraft`, §4 eqs. 3.15, 4.1–4.3 with
        the §12 errata, no lift term: β absorbs it) for 17-column demos (state and controls,
        :data:`~pipeline.estimate.aircraft.YAK54_COLUMNS`); its E-step is an EKF and extended RTS
        smoother and its M-step linearises at each smoothed step.
    fix_tau : bool
        Keep τ at its initial value (``init_tau``, or ``fit(..., tau=)``), d fitted once from it.
    use_bias : bool
        Estimate the bias terms β (False: β ≡ 0).
    cov_type : {"diag", "full"}
        Σ^(z) and Σ^(y) diagonal (the default: the state mixes m, m/s, m/s² and unit
        quaternions) or full; shared by the demos.
    hidden_factor : float
        T = round(hidden_factor × mean N) (seed: 2).
    d_prior : float
        Symmetric Dirichlet pseudo-count on each d_i (0: the seed's ML update).
    learn_d : bool
        Update d from τ after each alignment (False: d stays at its initial 1/3).
    init_tau : {"dtw", "linear"}
        Initial τ: each demo's DTW alignment (positions, symmetric2) to the demo of median
        length, that demo linearly stretched (default), or the seed's linear stretch
        ``τ_j = j(T−1)/(N−1)`` for every demo. The hard-EM alignment moves τ only a few hidden
        steps per iteration, so from the linear stretch 30 iterations leave demos whose timing
        drifts by more than that misaligned (simulated level flight, 30 s: position RMSE 1.6 m
        from the stretch, 1.1 m from DTW, 0.9 m with the true τ).

    Attributes
    ----------
    mean_ : ndarray (T, D)
        Learned trajectory (smoothed mean ``μ_{t|T−1}`` of the observed columns; quaternion
        columns renormalised).
    var_ : ndarray (T, D)
        Diagonal of ``Σ_{t|T−1}``.
    state_mean_, state_var_ : ndarray (T, n_x)
        The whole hidden state (9 or 13 columns of :data:`COLUMNS`).
    tau_ : list of int arrays
        Hidden index of each demo sample.
    d_ : ndarray (M, 3)
        Step probabilities ``d^k_1..3``.
    loglik_ : list of float
        Objective ``log p(y|τ) + log P(τ|d)`` per iteration (prediction-error decomposition).
    loglik_y_ : list of float
        ``log p(y | τ)`` alone per iteration.
    sigma_z_, sigma_y_ : ndarray (n_x, n_x), (D, D)
        Final process / observation noise; ``sigma_z_trace_``, ``sigma_y_trace_`` per iteration.
    beta_ : ndarray (T−1, n_x)
        Bias terms (0 where ``use_bias`` is off and on the non-driven components).
    model_error_ : ndarray (T−1, n_x)
        Model-prediction error ``μ_{t+1} − f(μ_t)`` on the final smoothed trajectory.
    n_iter_ : int
    converged_ : bool
    dt_hidden_ : float
    """

    def __init__(self, *, dt: float, window_C: int = 20, max_iter: int = 30, tol: float = 1e-6,
                 ridge: float = DEFAULT_RIDGE, dynamics: str = "kinematic", fix_tau: bool = False,
                 use_bias: bool = True, cov_type: str = "diag", hidden_factor: float = 2.0,
                 d_prior: float = 0.0, learn_d: bool = True, init_tau: str = "dtw"):
        self.dt = dt
        self.window_C = window_C
        self.max_iter = max_iter
        self.tol = tol
        self.ridge = ridge
        self.dynamics = dynamics
        self.fix_tau = fix_tau
        self.use_bias = use_bias
        self.cov_type = cov_type
        self.hidden_factor = hidden_factor
        self.d_prior = d_prior
        self.learn_d = learn_d
        self.init_tau = init_tau

    # ---------------------------------------------------------------- checks
    def _check(self, demos) -> list[F64]:
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise TrajectoryError(f"TrajectoryLearner: dt must be a positive number, not {self.dt!r}")
        if self.dynamics not in DYNAMICS:
            raise TrajectoryError(f"TrajectoryLearner: dynamics {self.dynamics!r} is not known; known: "
                                  f"{', '.join(DYNAMICS)}")
        if self.init_tau not in ("dtw", "linear"):
            raise TrajectoryError(f"TrajectoryLearner: init_tau must be 'dtw' or 'linear', not {self.init_tau!r}")
        if self.cov_type not in ("diag", "full"):
            raise TrajectoryError(f"TrajectoryLearner: cov_type must be 'diag' or 'full', not {self.cov_type!r}")
        for name in ("window_C", "max_iter"):
            if not _whole_number(getattr(self, name), 1):
                raise TrajectoryError(f"TrajectoryLearner: {name} must be a whole number >= 1, not "
                                      f"{getattr(self, name)!r}")
        if not self.ridge >= 0 or not self.tol >= 0:
            raise TrajectoryError("TrajectoryLearner: ridge and tol must be >= 0")
        if not (_real(self.d_prior) and np.isfinite(self.d_prior) and self.d_prior >= 0):
            raise TrajectoryError(f"TrajectoryLearner: d_prior (a Dirichlet pseudo-count) must be a finite "
                                  f"number >= 0, not {self.d_prior!r}")
        for name in ("learn_d", "fix_tau", "use_bias"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise TrajectoryError(f"TrajectoryLearner: {name} must be True or False, not "
                                      f"{getattr(self, name)!r}")
        # T = round(hidden_factor · mean N) hidden steps of dt/hidden_factor, and τ rises by 1..3
        # hidden steps a sample: a demo of the mean length spans the axis with a mean step of
        # hidden_factor, so 1 < hidden_factor <= 3 (1 leaves no room to warp time at all, above 3
        # the alignment band c_s = s(T−1)/(N−1) outruns τ)
        if not (_real(self.hidden_factor) and np.isfinite(self.hidden_factor) and 1 < self.hidden_factor <= 3):
            raise TrajectoryError(f"TrajectoryLearner: hidden_factor must be a finite number in (1, 3] (τ steps "
                                  f"1..3 hidden steps a sample), not {self.hidden_factor!r}")
        demos = list(demos)
        if len(demos) < 2:
            raise TrajectoryError(f"TrajectoryLearner.fit: needs at least 2 demos, got {len(demos)}")
        out = []
        for k, y in enumerate(demos):
            y = np.asarray(y, dtype=np.float64)
            if self.dynamics == "yak54" and (y.ndim != 2 or y.shape[1] != len(YAK54_COLUMNS)):
                raise TrajectoryError(f"TrajectoryLearner.fit: demo {k} shaped {y.shape}; the yak54 dynamics "
                                      f"need (N, {len(YAK54_COLUMNS)}) demos (columns {', '.join(YAK54_COLUMNS)})")
            if self.dynamics == "kinematic" and (y.ndim != 2 or y.shape[1] not in DIMS):
                raise TrajectoryError(f"TrajectoryLearner.fit: demo {k} shaped {y.shape}; expected (N, D) "
                                      f"with D in {sorted(DIMS)} (columns {', '.join(COLUMNS)})")
            if y.shape[1] != np.shape(demos[0])[1]:
                raise TrajectoryError(f"TrajectoryLearner.fit: demo {k} has {y.shape[1]} columns, demo 0 has "
                                      f"{np.shape(demos[0])[1]}")
            if len(y) < 3:
                raise TrajectoryError(f"TrajectoryLearner.fit: demo {k} has {len(y)} samples (< 3)")
            bad = ~np.isfinite(y).all(axis=1)
            if bad.any():
                raise TrajectoryError(f"TrajectoryLearner.fit: demo {k} has non-finite values in row "
                                      f"{int(np.argmax(bad))} ({int(bad.sum())} rows)")
            out.append(y)
        return out

    # ---------------------------------------------------------------- pieces
    def _estep(self, Y: list[F64], tau: list[NDArray[np.int64]], Qz: F64, Ry: F64, beta: F64,
               prior: GaussianState) -> _Fit:
        T, M, D = self._T, len(Y), Y[0].shape[1]
        z = np.full((T, 1, M, D), np.nan)
        for k in range(M):
            z[tau[k], 0, k] = Y[k]
        trans = (LinearTransition(self._F, Qz) if self._F is not None
                 else Yak54Transition(Qz, self._params, lift=False))
        ekf = ExtendedKalmanFilter(trans, LinearMeasurement(self._H, Ry))
        t_ns = np.arange(T, dtype=np.int64) * self._step_ns
        track = run_filter(ekf, prior, t_ns, z, store="all", bu=np.vstack([np.zeros((1, self._n_x)), beta]))
        sm = rts_smooth(track)
        return _Fit(sm.mean[0], sm.cov[0], sm.gain[0], float(track.loglik()[0]))

    def _mstep(self, Y, tau, fit: _Fit, beta_on: bool) -> tuple[F64, F64, F64]:
        mu, P, L = fit.mean, fit.cov, fit.gain
        fmu, F = self._lin(mu[:-1])       # f(μ_t) and A_t = Df(μ_{t|T−1}): (n, n) shared or (T−1, n, n)
        mpe = mu[1:] - fmu                # model-prediction error μ_{t+1} − f(μ_t)
        beta = np.zeros_like(mpe)
        if beta_on:
            beta[:, self._driven] = mpe[:, self._driven] / (1.0 + float(self.ridge))
        dmu = mpe - beta
        # Σ_{t+1} L_tᵀ Aᵀ: the smoothed cross-covariance Cov(z_{t+1}, z_t) times Aᵀ
        Ft = np.swapaxes(F, -1, -2)
        cross = P[1:] @ np.swapaxes(L[:-1], -1, -2) @ Ft
        APA = F @ P[:-1] @ Ft
        terms = dmu[:, :, None] * dmu[:, None, :] + APA + P[1:] - cross - np.swapaxes(cross, -1, -2)
        Qz = terms.mean(axis=0)
        # Σ^(y): every observation δy δyᵀ + C Σ_τ Cᵀ, over the count of observations
        idx = np.asarray(self._obs)
        Rsum = np.zeros((len(idx), len(idx)))
        n = 0
        for k, y in enumerate(Y):
            dy = y - mu[tau[k]][:, idx]
            Rsum += dy.T @ dy + P[tau[k]][:, idx][:, :, idx].sum(axis=0)
            n += len(y)
        Ry = Rsum / n
        Qz, Ry = self._shape_cov(Qz, self._qfloor), self._shape_cov(Ry, self._rfloor)
        return Qz, Ry, beta

    def _shape_cov(self, S: F64, floor: F64) -> F64:
        S = 0.5 * (S + S.T)
        if self.cov_type == "diag":
            return np.diag(np.maximum(np.diagonal(S), floor))
        # full: floor the eigenvalues (keeps Σ positive definite when a direction collapses)
        w, V = np.linalg.eigh(S)
        return (V * np.maximum(w, floor.min())) @ V.T

    def _align(self, Y, mu: F64, Ry: F64, logd: F64) -> list[NDArray[np.int64]]:
        T, C = self._T, int(self.window_C)
        Hmu = mu[:, np.asarray(self._obs)]
        Lr = np.linalg.cholesky(Ry)
        out = []
        for k, y in enumerate(Y):
            N = len(y)
            lo = alignment_band(N, T, C)
            t = lo[:, None] + np.arange(2 * C + 1)[None, :]
            ok = (t >= 0) & (t <= T - 1)
            diff = y[:, None, :] - Hmu[np.clip(t, 0, T - 1)]
            # ℓ(y|z) = log N(y; h(z), Σ^(y)) up to a constant shared by every cell
            wd = np.linalg.solve(Lr, diff.reshape(-1, diff.shape[-1]).T).T.reshape(diff.shape)
            emis = np.where(ok, -0.5 * np.einsum("swd,swd->sw", wd, wd), -np.inf)
            tk = _align_dp(np.ascontiguousarray(emis), lo, np.ascontiguousarray(logd[k]), T)
            if tk[0] < 0:
                raise TrajectoryError(f"TrajectoryLearner.fit: demo {k} ({N} samples) cannot be aligned to "
                                      f"T={T} hidden steps within the band C={C}")
            out.append(tk)
        return out

    def _d_from_tau(self, tau) -> F64:
        d = np.empty((len(tau), 3))
        a = float(self.d_prior)
        for k, tk in enumerate(tau):
            steps = np.diff(tk)
            cnt = np.array([(steps == i).sum() for i in (1, 2, 3)], dtype=np.float64)
            # ML (seed §3 step 5), or the MAP under a symmetric Dirichlet of a pseudo-counts
            dk = np.maximum((cnt + a) / max(len(steps) + 3 * a, 1), D_FLOOR)
            d[k] = dk / dk.sum()
        return d

    @staticmethod
    def _logp_tau(tau, d) -> float:
        return float(sum(np.log(d[k][np.diff(tk) - 1]).sum() for k, tk in enumerate(tau)))

    def _initial_taus(self, Y) -> list[NDArray[np.int64]]:
        """Initial τ of every demo: the seed's linear stretch (``init_tau="linear"``), or each
        demo's DTW alignment (positions) to the demo of median length, itself stretched
        linearly (``"dtw"``)."""
        if self.init_tau == "linear":
            return [self._initial_tau(len(y)) for y in Y]
        r = int(np.argsort([len(y) for y in Y], kind="stable")[(len(Y) - 1) // 2])
        ref = Y[r][:, :3]
        scale = (self._T - 1) / (len(ref) - 1)
        out = []
        for k, y in enumerate(Y):
            if k == r:
                out.append(self._initial_tau(len(y)))
                continue
            p = dtw(y[:, :3], ref, step_pattern="symmetric2", path=True).path
            acc = np.zeros(len(y))
            cnt = np.zeros(len(y))
            np.add.at(acc, p[:, 0], p[:, 1])
            np.add.at(cnt, p[:, 0], 1.0)
            out.append(self._initial_tau(len(y), acc / cnt * scale))
        return out

    def _initial_tau(self, N: int, target: F64 | None = None) -> NDArray[np.int64]:
        """``target`` (default the linear stretch ``τ_j = round(j(T−1)/(N−1))``, seed §3 step 1)
        rounded, kept inside the band and to steps of 1..3."""
        T, C = self._T, int(self.window_C)
        lo = alignment_band(N, T, C)
        if target is None:
            target = np.arange(N) * (T - 1) / (N - 1)
        tau = np.round(target).astype(np.int64)
        tau[0] = 0
        for j in range(1, N):
            # the last bound leaves room for the remaining samples at one step each
            tau[j] = min(max(tau[j], tau[j - 1] + 1, lo[j]), tau[j - 1] + 3, lo[j] + 2 * C, T - N + j)
        if np.any(np.diff(tau) < 1):
            raise TrajectoryError(f"TrajectoryLearner.fit: a demo of {N} samples does not fit T={T} hidden steps")
        return tau

    def _check_tau(self, tau, Y) -> list[NDArray[np.int64]]:
        if len(tau) != len(Y):
            raise TrajectoryError(f"TrajectoryLearner.fit: tau has {len(tau)} entries for {len(Y)} demos")
        out = []
        for k, (tk, y) in enumerate(zip(tau, Y)):
            tk = _tau_indices(tk, k)
            st = np.diff(tk)
            if (tk.shape != (len(y),) or tk[0] != 0 or tk[-1] > self._T - 1 or np.any(st < 1)
                    or np.any(st > 3)):
                raise TrajectoryError(f"TrajectoryLearner.fit: tau[{k}] must start at 0, rise by 1..3 and stay "
                                      f"below T={self._T} for its {len(y)} samples")
            out.append(tk)
        return out

    # ---------------------------------------------------------------- API
    def fit(self, demos: Sequence[ArrayLike], tau: Sequence[ArrayLike] | None = None) -> "TrajectoryLearner":
        """Learn the intended trajectory from ``demos`` by nested EM (seed 004 §3, steps 1–5).

        Parameters
        ----------
        demos : sequence of array_like, each (N_k, D)
            At least 2 finite demos of at least 3 samples, sampled at ``dt``. ``kinematic``:
            D = 3 (NED position, m), 9 (+ velocity, m/s, and acceleration, m/s²) or 13
            (+ quaternion ``q_w, q_x, q_y, q_z``), columns as :data:`COLUMNS`; ``yak54``: the 17
            columns of :data:`~pipeline.estimate.aircraft.YAK54_COLUMNS`.
        tau : sequence of int arrays, optional
            Initial hidden index of each demo sample (starting at 0, steps of 1..3; default from
            ``init_tau``); with ``fix_tau`` kept throughout. T is then at least ``max τ + 1``.

        Returns
        -------
        self
            With the fitted attributes (``mean_``, ``var_``, ``tau_``, ``d_``, ``sigma_z_``, …).
        """
        # one BLAS thread: every product here is ≤ 65×65, where a threaded BLAS only adds
        # hand-offs (~1 ms a call on a loaded 2-core machine, 100× the work)
        with threadpool_limits(1) if threadpool_limits is not None else contextlib.nullcontext():
            return self._fit(demos, tau)

    def _fit(self, demos: Sequence[ArrayLike], tau: Sequence[ArrayLike] | None = None) -> "TrajectoryLearner":
        """:meth:`fit`'s work, under one BLAS thread (parameters and result as there)."""
        Y = self._check(demos)
        D = Y[0].shape[1]
        yak = self.dynamics == "yak54"
        qc = slice(6, 10) if yak else slice(9, 13)   # the quaternion columns
        if yak or D == 13:
            ref = None
            for k in range(len(Y)):
                Y[k] = Y[k].copy()
                Y[k][:, qc] = quaternion_continuous(Y[k][:, qc], ref)
                ref = Y[0][0, qc]
        self._obs = tuple(range(D)) if yak else DIMS[D]
        n_x = self._n_x = D if yak else (13 if D == 13 else 9)
        # β on the driven components: the kinematic model's accelerations (and quaternion), the
        # Yak54's six accelerations u̇..ṙ (seed §3.4: "β=(β_u,β_v,β_w,β_p,β_q,β_r)")
        self._driven = np.asarray(YAK54_DRIVEN) if yak else np.arange(6, n_x)
        T = int(round(self.hidden_factor * np.mean([len(y) for y in Y])))
        if tau is not None:
            tau = [_tau_indices(tk, k) for k, tk in enumerate(tau)]
            # a given τ (e.g. the truth) may reach past 2 × mean N: the axis then ends at its end
            T = max(T, max(int(np.max(tk)) + 1 for tk in tau))
        self._T = T
        if any(len(y) > T for y in Y):
            raise TrajectoryError(f"TrajectoryLearner.fit: a demo has more samples than T={T} hidden steps "
                                  f"(lengths {[len(y) for y in Y]})")
        self.dt_hidden_ = dth = float(self.dt) / self.hidden_factor
        self._step_ns = max(int(round(dth * 1e9)), 1)
        self._params = Yak54Params()
        self._F = None if yak else kinematic_transition(dth, n_x)
        self._H = np.eye(n_x)[list(self._obs)]
        tau = self._initial_taus(Y) if tau is None else self._check_tau(tau, Y)

        # initial noise: Σ^(y) from the second differences of each demo (Δ² of white noise has
        # variance 6σ²; a smooth signal adds little), Σ^(z) from the MPE of the demos' average
        # on the hidden axis (gaps interpolated, unobserved components by finite differences)
        d2 = np.concatenate([np.diff(y, 2, axis=0) for y in Y])
        scale = np.concatenate([y for y in Y]).var(axis=0) + np.concatenate([np.diff(y, axis=0) for y in Y]).var(axis=0)
        self._rfloor = VAR_FLOOR * np.maximum(scale, 1e-12)
        R0 = np.maximum(d2.var(axis=0) / 6.0, self._rfloor)
        z0 = self._initial_trajectory(Y, tau)
        mpe0 = z0[1:] - self._lin(z0[:-1])[0]
        q0 = np.maximum(mpe0.var(axis=0), 1e-12)
        self._qfloor = VAR_FLOOR * q0
        Qz, Ry = np.diag(q0), np.diag(R0)
        # z_0 ~ N(μ_0, Σ_0) from the demos' first samples (τ₀ ≡ 0): their spread plus the
        # sensor noise, and for unobserved components the spread of the initial guess; held
        # fixed (a partial M-step, so EM stays monotone)
        p0 = z0.var(axis=0) + q0
        first = np.array([y[0] for y in Y])
        p0[list(self._obs)] = first.var(axis=0) + R0 + q0[list(self._obs)]
        P0 = np.diag(p0)
        prior = GaussianState(z0[0], P0, 0)

        beta = np.zeros((T - 1, n_x))
        # d starts at 1/3 each (seed §3 step 1, "d_i^k=1/3"); learned from τ after each alignment
        # (with fix_tau: fitted once from the fixed τ)
        d = self._d_from_tau(tau) if self.fix_tau else np.full((len(Y), 3), 1.0 / 3.0)
        self.loglik_, self.loglik_y_, self.sigma_z_trace_, self.sigma_y_trace_ = [], [], [], []
        self.converged_ = False
        fit = None
        for it in range(int(self.max_iter)):
            fit = self._estep(Y, tau, Qz, Ry, beta, prior)
            ll = fit.loglik_y + self._logp_tau(tau, d)
            self.loglik_.append(ll)
            self.loglik_y_.append(fit.loglik_y)
            self.sigma_z_trace_.append(Qz)
            self.sigma_y_trace_.append(Ry)
            if it > 0 and abs(ll - self.loglik_[-2]) < self.tol * abs(self.loglik_[-2]):
                self.converged_ = True
                break
            if it == int(self.max_iter) - 1:
                break
            Qz, Ry, beta = self._mstep(Y, tau, fit, self.use_bias)
            if not self.fix_tau:
                tau = self._align(Y, fit.mean, Ry, np.log(d))
                if self.learn_d:
                    d = self._d_from_tau(tau)
        self.n_iter_ = len(self.loglik_)
        self.state_mean_ = fit.mean
        self.state_var_ = np.diagonal(fit.cov, axis1=-2, axis2=-1).copy()
        mean = fit.mean[:, list(self._obs)].copy()
        if yak or D == 13:
            mean[:, qc] /= np.linalg.norm(mean[:, qc], axis=1, keepdims=True)
        self.mean_ = mean
        self.var_ = self.state_var_[:, list(self._obs)]
        self.tau_ = tau
        self.d_ = d
        self.sigma_z_ = self.sigma_z_trace_[-1]
        self.sigma_y_ = self.sigma_y_trace_[-1]
        self.model_error_ = fit.mean[1:] - self._lin(fit.mean[:-1])[0]
        self.beta_ = beta
        self.demos_ = Y
        self.T_ = T
        return self

    def _lin(self, z: F64) -> tuple[F64, F64]:
        """``f(z)`` and ``Df`` at hidden states ``z`` (T, n_x): the shared F of the linear model,
        or one per step."""
        if self._F is not None:
            return z @ self._F.T, self._F
        return yak54_linearise(z, self.dt_hidden_, self._params, lift=False)

    def _initial_trajectory(self, Y, tau) -> F64:
        T, n_x, obs = self._T, self._n_x, list(self._obs)
        acc = np.zeros((T, len(obs)))
        cnt = np.zeros(T)
        for y, tk in zip(Y, tau):
            acc[tk] += y
            cnt[tk] += 1
        t = np.arange(T)
        has = cnt > 0
        mean = acc[has] / cnt[has, None]
        z = np.zeros((T, n_x))
        for c in range(len(obs)):
            z[:, obs[c]] = np.interp(t, t[has], mean[:, c])
        dth = self.dt_hidden_
        if len(obs) == 3:
            for a in range(3):
                z[:, 3 + a] = np.gradient(z[:, a], dth)
                z[:, 6 + a] = np.gradient(z[:, 3 + a], dth)
        return z

    def demo_on_hidden(self, i: int) -> F64:
        """Demo ``i`` on the hidden time axis, ``(T, D)``, NaN where it has no sample."""
        out = np.full((self.T_, self.demos_[i].shape[1]), np.nan)
        out[self.tau_[i]] = self.demos_[i]
        return out
