"""Bootstrap (SIR) particle filter with a Markov mode per particle (seed 001 §1–§2, §13 items 1–2).

A generic, vectorised core that the jump-Markov PF on real logs (``estimate.pf_run``), the
hierarchical weave classifier (seed 003) and camera geo-location build on.

Model
-----
Each particle ``i`` carries a state ``x_i`` (row of an (N, n) array), a mode ``r_i ∈ {0..K−1}``
and a log-weight ``ℓ_i``. One step over ``Δt`` with measurement ``z_k``:

1. **mode** (digest D6, sampled *before* propagation): ``r_i ~ Π(Δt)[r_i, :]`` where ``Π`` is
   row-stochastic for a reference step ``Δt_ref`` and re-timed by
   :func:`pipeline.estimate.markov.retime` (``Π(Δt) = expm(logm(Π) Δt/Δt_ref)``, digest D5);
   a particle that changed mode is passed through the new model's optional ``enter`` hook
   (e.g. draw a turn rate on entering CT, digest D4);
2. **propagate**: ``x_i ← f_{r_i}(x_i, Δt) + v`` by each mode model's vectorised ``propagate``;
3. **weight** (bootstrap proposal, seed 001 (2.10)): ``ℓ_i ← ℓ_i + log p(z_k | x_i)``,
   normalised with log-sum-exp; ``N_eff = 1/Σ w_i²``;
4. **estimate** before resampling: weighted mean, covariance and mode fractions
   ``P(r = m) = Σ_{r_i = m} w_i``;
5. **resample** (systematic by default, :mod:`pipeline.estimate.resample`) when
   ``N_eff < threshold·N`` (default N/3, seed 001 §1) or at every step (``every_step=True``,
   seed 003 §2.4); modes travel with their particles; weights reset to ``1/N``.

Bad input: a measurement with a NaN component is a **predict-only** step (no weighting, no
resampling). If every weight underflows to zero (or is −∞/NaN) the particles are
**re-initialised around z_k** by the likelihood's ``reinit`` (or the ``reinit`` argument) with
uniform weights and the step is counted in ``n_reinit``. A likelihood with a
``collapsed(ll, z) -> bool`` method can also call a step with some weight left collapsed (the
camera's, seed 001 §13 item 7); it is re-initialised the same way and counted in ``n_collapse``
as well.

API
---
``ModeModel`` (protocol): ``propagate(x (N, n), dt, rng) -> (N, n)``; optional
``enter(x (M, n), rng) -> (M, n)``.

``Likelihood`` (protocol): ``__call__(x (N, n), z (m,)) -> log p(z | x) (N,)``; optional
``reinit(x (N, n), z, rng) -> (N, n)``. :class:`GaussianPositionLikelihood` is the standard one.

``ParticleFilter(models, Pi, likelihood, *, n_particles, resample="systematic",
threshold=1/3, every_step=False, dt_ref=None, rng, reinit=None)`` with

- ``.init(x0 | mean, cov, *, modes=None, mode_p=None)`` — particles from an (N, n) array or a
  Gaussian; modes given, drawn from ``mode_p`` or uniform;
- ``.predict(dt)``, ``.update(z) -> (reinit: bool)``, ``.estimate() -> (mean, cov, mode_p)``,
  ``.resample_if_needed() -> bool`` — the parts of a step, public so that a caller can act
  between them (the weave classifier's turn-sign guard zeroes log-weights after ``predict``);
- ``.step(dt, z) -> StepStats``; attributes ``x``, ``mode``, ``logw`` (writable), ``weights``,
  ``neff``, ``n_reinit``, and ``aux`` (a dict of per-particle arrays, leading axis N, that
  resampling carries along with the particles; set it after ``init``).

``Pi`` may be a (K, K) row-stochastic array or a callable ``(mode (N,), dt, rng) -> mode (N,)``
(hierarchical or state-dependent chains); ``K = len(models)``.

``run_pf(pf, t_ns, z, *, t0_ns=None) -> PfTrack`` runs an initialised filter over a track
(``z`` of shape (T, m), NaN rows predict-only) and returns ``PfTrack(t_ns, mean (T, n),
cov (T, n, n), mode_p (T, K), neff, resampled, predict_only, reinit, loglik, n_reinit,
n_particles)``.

``dwell_transition(dwell_s, dt, *, to=None)`` builds a row-stochastic Π from mean dwell times
(a continuous-time chain, so its re-timing is exact); ``track_meta(track)`` the counts an output
table records. The fused numba kernels of :mod:`pipeline.estimate.pf_fast` run the same CV and
CV/CA/CT jump-Markov filters at 10⁵ particles for the benchmark (``benchmarks/pf.py``).

Example
-------
>>> from pipeline.estimate.models import PfConstantVelocity, PfAugmentedCoordinatedTurn
>>> pf = ParticleFilter([PfConstantVelocity(0.5), PfAugmentedCoordinatedTurn(0.5, 0.05)],
...                     dwell_transition([10.0, 5.0], 0.1), GaussianPositionLikelihood(1.0),
...                     n_particles=1000, dt_ref=0.1, rng=0)
>>> pf = pf.init(mean=[0, 0, 5, 0, 0], cov=np.eye(5))
>>> s = pf.step(0.1, [0.5, 0.0])
>>> round(float(s.mode_p.sum()), 12)
1.0
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Protocol, Sequence, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from numba import njit

from .base import check_times
from .markov import check_stochastic, retime
from .resample import SCHEMES, get_resampler, regularise

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@runtime_checkable
class ModeModel(Protocol):
    """One motion mode: a vectorised stochastic transition (see the module docstring)."""

    def propagate(self, x: F64, dt: float, rng: np.random.Generator) -> F64: ...


@runtime_checkable
class Likelihood(Protocol):
    """``log p(z | x)`` per particle (see the module docstring)."""

    def __call__(self, x: F64, z: F64) -> F64: ...


@dataclass(frozen=True)
class GaussianPositionLikelihood:
    """Independent Gaussian measurement of state components ``index`` (e.g. N, E position).

    .. math::

        \\log p(z\\mid x) = -\\tfrac12 \\sum_j \\big((z_j - x_{\\text{index}_j})/\\sigma_j\\big)^2
                          - \\sum_j \\log(\\sqrt{2\\pi}\\,\\sigma_j)

    Attributes
    ----------
    sigma : float or tuple of float
        Standard deviation per measured component (m).
    index : tuple of int
        The measured state components, default ``(0, 1)``.
    reinit_spread : float
        On re-initialisation the measured components are drawn ``z + reinit_spread·σ·N(0, 1)``;
        the others are kept from the (degenerate) particles.
    gate : float, optional
        A particle whose normalised residual ``|(z − x)/σ|`` exceeds ``gate`` gets weight
        exactly zero (``−∞``): without it log-weights never underflow, so a filter that lost
        the track would never re-initialise (seed 001 §13 item 7).
    """

    sigma: float | tuple[float, ...] = 1.0
    index: tuple[int, ...] = (0, 1)
    reinit_spread: float = 3.0
    gate: float | None = None

    def _sig(self) -> F64:
        s = np.broadcast_to(np.asarray(self.sigma, dtype=np.float64), (len(self.index),))
        return s

    def check_width(self, n_z: int) -> None:
        """Refuse a measurement of ``n_z`` components where the likelihood measures
        ``len(index)`` (a (1,) z would broadcast against both N and E)."""
        if n_z != len(self.index):
            raise ValueError(f"GaussianPositionLikelihood: z has {n_z} component(s), the likelihood measures "
                             f"{len(self.index)} (state components {tuple(self.index)})")

    def _z(self, z: F64) -> F64:
        z = np.atleast_1d(np.asarray(z, dtype=np.float64))
        if z.ndim != 1:
            raise ValueError(f"GaussianPositionLikelihood: z must be one measurement (m,), got shape {z.shape}")
        self.check_width(len(z))
        return z

    def __call__(self, x: F64, z: F64) -> F64:
        s = self._sig()
        r = (self._z(z)[None, :] - x[:, list(self.index)]) / s
        d2 = np.einsum("ij,ij->i", r, r)
        ll = -0.5 * d2 - float(np.sum(np.log(np.sqrt(2 * np.pi) * s)))
        if self.gate is not None:
            ll[d2 > self.gate * self.gate] = -np.inf
        return ll

    def reinit(self, x: F64, z: F64, rng: np.random.Generator) -> F64:
        out = np.array(x, dtype=np.float64, copy=True)
        s = self._sig()
        idx = list(self.index)
        z = self._z(z)
        noise = rng.standard_normal((len(x), len(idx)))
        out[:, idx] = z[None, :] + self.reinit_spread * s * noise
        return out


@dataclass(frozen=True)
class StepStats:
    """One filter step: the estimate (before resampling) and what happened."""

    mean: F64
    cov: F64
    mode_p: F64
    neff: float
    resampled: bool
    predict_only: bool
    reinit: bool
    loglik: float


@dataclass(frozen=True)
class PfTrack:
    """A particle-filter run over ``T`` steps (see :func:`run_pf`).

    Attributes
    ----------
    t_ns : (T,) int64
    mean : (T, n); cov : (T, n, n)
        Weighted mean and covariance of the particles before resampling.
    mode_p : (T, K)
        Weighted mode fractions.
    neff : (T,)
        Effective sample size before resampling (after a predict-only step: the carried one).
    resampled, predict_only, reinit : (T,) bool
    loglik : (T,)
        ``log Σ_i w_{k−1,i} p(z_k | x_i)`` (NaN on predict-only steps).
    n_reinit : int
        All-zero-weight re-initialisations.
    n_particles : int
    """

    t_ns: NDArray[np.int64]
    mean: F64
    cov: F64
    mode_p: F64
    neff: F64
    resampled: NDArray[np.bool_]
    predict_only: NDArray[np.bool_]
    reinit: NDArray[np.bool_]
    loglik: F64
    n_reinit: int
    n_particles: int


#: rows per block of the covariance sum in :meth:`ParticleFilter.estimate`
_BLOCK = 16384


def _logsumexp(a: F64) -> float:
    m = np.max(a)
    if not np.isfinite(m):
        return float(m) if m == np.inf else -np.inf
    return float(m + np.log(np.sum(np.exp(a - m))))


@njit(cache=True)
def _draw_from_cdf(mode, F, u, out):  # pragma: no cover - compiled by numba
    # out[i] = searchsorted(F[mode[i]], u[i], side="left"): the count of the row's entries
    # below u[i] (the last entry is 1 > u, so at most K − 1)
    K = F.shape[1]
    for i in range(mode.shape[0]):
        r = mode[i]
        j = 0
        while j < K - 1 and F[r, j] < u[i]:
            j += 1
        out[i] = j


class ParticleFilter:
    """Bootstrap SIR filter with a Markov mode per particle (module docstring).

    Parameters
    ----------
    models : sequence of ModeModel
        One per mode (``K = len(models)``); a single model gives a plain bootstrap PF.
    Pi : (K, K) array_like, callable or None
        Row-stochastic mode transition matrix over ``dt_ref`` (re-timed to each step's Δt), or a
        callable ``(mode, dt, rng) -> mode``; ``None`` keeps the modes (required when K > 1
        unless the modes are meant to be fixed).
    likelihood : Likelihood
        ``log p(z | x)`` per particle.
    n_particles : int
    resample : str
        ``systematic`` (default), ``stratified``, ``multinomial`` or ``residual``.
    threshold : float
        Resample when ``N_eff < threshold·N`` (default 1/3).
    every_step : bool
        Resample after every measurement update regardless of ``N_eff``.
    dt_ref : float, optional
        The step ``Pi`` is given for; ``None`` uses ``Pi`` as is at every step.
    rng : numpy.random.Generator or int
        Every draw's generator, or a seed for one (required: no unseeded default).
    reinit : callable, optional
        ``(x, z, rng) -> x`` for the all-zero-weight guard; default ``likelihood.reinit``.
    regularise_index : sequence of int, optional
        After each resampling in :meth:`step`, move these state components by the regularised
        particle filter's kernel (:func:`~pipeline.estimate.resample.regularise`, with the
        step's weighted covariance before resampling), so resampled copies separate with the
        posterior's own spread instead of narrowing the cloud at every resampling. ``None``
        (default): the plain bootstrap filter.
    """

    def __init__(self, models: Sequence[ModeModel], Pi: ArrayLike | Callable | None,
                 likelihood: Likelihood, *, n_particles: int = 1000, resample: str = "systematic",
                 threshold: float = 1.0 / 3.0, every_step: bool = False,
                 dt_ref: float | None = None, rng: np.random.Generator | int,
                 reinit: Callable[[F64, F64, np.random.Generator], F64] | None = None,
                 regularise_index: Sequence[int] | None = None) -> None:
        self.models = list(models)
        if not self.models:
            raise ValueError("ParticleFilter: need at least one mode model")
        for k, m in enumerate(self.models):
            if not callable(getattr(m, "propagate", None)):
                raise ValueError(f"ParticleFilter: mode model {k} ({type(m).__name__}) has no "
                                 "propagate(x, dt, rng)")
        self.K = len(self.models)
        if Pi is None or callable(Pi):
            self._Pi = None
            self._transition = Pi
        else:
            P = check_stochastic(Pi, "ParticleFilter Pi")
            if P.shape[0] != self.K:
                raise ValueError(f"ParticleFilter: Pi is {P.shape[0]}x{P.shape[0]} but there are "
                                 f"{self.K} mode models")
            self._Pi = P
            self._transition = None
        if resample not in SCHEMES:
            raise ValueError(f"ParticleFilter: unknown resample scheme {resample!r}; expected one of "
                             f"{', '.join(SCHEMES)}")
        if int(n_particles) < 1:
            raise ValueError(f"ParticleFilter: n_particles must be >= 1, got {n_particles}")
        if not (0.0 <= threshold <= 1.0):
            raise ValueError(f"ParticleFilter: threshold must be in [0, 1], got {threshold}")
        self.N = int(n_particles)
        self.scheme = resample
        self._resampler = get_resampler(resample)
        self.threshold = float(threshold)
        self.every_step = bool(every_step)
        self.dt_ref = None if dt_ref is None else float(dt_ref)
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.likelihood = likelihood
        self._reinit = reinit if reinit is not None else getattr(likelihood, "reinit", None)
        self._pi_cache: dict[float, F64] = {}
        self.x: F64 | None = None
        self.mode: I64 = np.zeros(self.N, dtype=np.int64)
        self.logw: F64 = np.full(self.N, -np.log(self.N))
        self.neff = float(self.N)
        self.n_reinit = 0
        #: re-initialisations called by the likelihood's collapse test (counted in n_reinit too)
        self.n_collapse = 0
        #: per-particle side arrays (leading axis N) resampled with the particles, e.g. the
        #: weave classifier's submode and segment counters δ, θ
        self.aux: dict[str, np.ndarray] = {}
        self.regularise_index = None if regularise_index is None else tuple(int(i) for i in regularise_index)

    # --- set-up -------------------------------------------------------------------------------
    def init(self, x0: ArrayLike | None = None, *, mean: ArrayLike | None = None,
             cov: ArrayLike | None = None, modes: ArrayLike | None = None,
             mode_p: ArrayLike | None = None) -> "ParticleFilter":
        """Particles from ``x0`` (N, n) or ``N(mean, cov)``; modes given, from ``mode_p`` or uniform."""
        if x0 is not None:
            x = np.array(x0, dtype=np.float64, copy=True)
            if x.ndim != 2 or x.shape[0] != self.N:
                raise ValueError(f"ParticleFilter.init: x0 must have shape ({self.N}, n), got {x.shape}")
        else:
            if mean is None:
                raise ValueError("ParticleFilter.init: give x0 or mean (and cov)")
            mu = np.asarray(mean, dtype=np.float64).ravel()
            C = np.zeros((mu.size, mu.size)) if cov is None else np.asarray(cov, dtype=np.float64)
            # a symmetric square root, so a singular (e.g. partly zero) covariance is fine
            ev, V = np.linalg.eigh(0.5 * (C + C.T))
            L = V * np.sqrt(np.clip(ev, 0.0, None))
            x = mu[None, :] + self.rng.standard_normal((self.N, mu.size)) @ L.T
        self.x = x
        if modes is not None:
            self.mode = np.broadcast_to(np.asarray(modes, dtype=np.int64), (self.N,)).copy()
        else:
            p = np.full(self.K, 1.0 / self.K) if mode_p is None else np.asarray(mode_p, dtype=np.float64)
            self.mode = self.rng.choice(self.K, size=self.N, p=p / p.sum()).astype(np.int64)
        if np.any((self.mode < 0) | (self.mode >= self.K)):
            raise ValueError(f"ParticleFilter.init: modes must be in 0..{self.K - 1}")
        self.logw = np.full(self.N, -np.log(self.N))
        self.neff = float(self.N)
        self.aux = {}
        return self

    # --- the parts of a step --------------------------------------------------------------------
    @property
    def weights(self) -> F64:
        """Normalised weights ``exp(logw)``."""
        return np.exp(self.logw - _logsumexp(self.logw))

    def transition_matrix(self, dt: float) -> F64:
        """``Π(Δt)``: the matrix re-timed from ``dt_ref`` (cached per Δt to 1 ns)."""
        if self._Pi is None:
            raise ValueError("ParticleFilter: no transition matrix (Pi is a callable or None)")
        if self.dt_ref is None:
            return self._Pi
        key = round(float(dt), 9)
        P = self._pi_cache.get(key)
        if P is None:
            P = retime(self._Pi, key, self.dt_ref, "ParticleFilter Pi")
            if len(self._pi_cache) < 4096:
                self._pi_cache[key] = P
        return P

    def _draw_modes(self, dt: float) -> None:
        if self.K == 1:
            return
        if self._transition is not None:
            new = np.asarray(self._transition(self.mode, dt, self.rng), dtype=np.int64)
        elif self._Pi is not None:
            F = np.cumsum(self.transition_matrix(dt), axis=1)
            F[:, -1] = 1.0
            u = self.rng.random(self.N)
            # r = j where F[r, j−1] < u ≤ F[r, j] (seed 001 (2.21)): the count of F[r, :] below u,
            # in one compiled pass (no (N, K) temporary: at 10⁶ particles its fresh pages cost
            # more kernel time than the draw; no mask per from-mode: at 10⁴ particles those
            # small calls made the step's fixed cost)
            new = np.empty(self.N, dtype=np.int64)
            _draw_from_cdf(np.ascontiguousarray(self.mode, dtype=np.int64), np.ascontiguousarray(F), u, new)
        else:
            return
        switched = new != self.mode
        self.mode = new
        for k, m in enumerate(self.models):
            enter = getattr(m, "enter", None)
            if enter is None:
                continue
            sel = switched & (new == k)
            if np.any(sel):
                self.x[sel] = enter(self.x[sel], self.rng)

    def predict(self, dt: float) -> None:
        """Draw each particle's mode from ``Π(Δt)`` then propagate it by its mode's model."""
        if self.x is None:
            raise ValueError("ParticleFilter: call init() before predict()")
        if dt < 0:
            raise ValueError(f"ParticleFilter.predict: negative step {dt}")
        self._draw_modes(dt)
        if self.K == 1:
            self.x = self.models[0].propagate(self.x, dt, self.rng)
            return
        for k, m in enumerate(self.models):
            sel = np.flatnonzero(self.mode == k)
            if sel.size:
                self.x[sel] = m.propagate(self.x[sel], dt, self.rng)

    def update(self, z: ArrayLike) -> tuple[bool, float]:
        """Weight by ``p(z | x)``; returns ``(reinitialised, loglik)``; NaN ``z`` does nothing."""
        z = np.asarray(z, dtype=np.float64)
        if np.any(~np.isfinite(z)):
            return False, float("nan")
        ll = np.asarray(self.likelihood(self.x, z), dtype=np.float64)
        lw = self.logw + ll
        lw[np.isnan(lw)] = -np.inf
        tot = _logsumexp(lw)
        # a likelihood may also call a step collapsed while some weight is left (seed 001 §13
        # item 7: the best particle explains the measurement no better than a lost track would)
        collapsed = getattr(self.likelihood, "collapsed", None)
        if np.isfinite(tot) and collapsed is not None and self._reinit is not None and collapsed(ll, z):
            self.n_collapse += 1
            tot = -np.inf
        if not np.isfinite(tot):
            if self._reinit is None:
                raise ValueError("ParticleFilter: every weight is zero and the likelihood has no reinit")
            self.x = np.asarray(self._reinit(self.x, z, self.rng), dtype=np.float64)
            self.logw = np.full(self.N, -np.log(self.N))
            self.neff = float(self.N)
            self.n_reinit += 1
            return True, float("-inf")
        self.logw = lw - tot
        w = np.exp(self.logw)
        self.neff = float(1.0 / np.dot(w, w))
        return False, tot

    def estimate(self) -> tuple[F64, F64, F64]:
        """Weighted mean (n,), covariance (n, n) and mode fractions (K,)."""
        w = self.weights
        mean = w @ self.x
        # in blocks of rows: the same sum, without two (N, n) temporaries per step
        cov = np.zeros((self.x.shape[1], self.x.shape[1]))
        for i in range(0, len(w), _BLOCK):
            d = self.x[i:i + _BLOCK] - mean
            cov += (d * w[i:i + _BLOCK, None]).T @ d
        mode_p = np.bincount(self.mode, weights=w, minlength=self.K)
        return mean, cov, mode_p

    def resample(self) -> None:
        """Resample now (modes travel with their particles); weights reset to 1/N."""
        idx = self._resampler(self.weights, self.rng)
        self.x = self.x[idx]
        self.mode = self.mode[idx]
        for k, v in self.aux.items():
            self.aux[k] = np.asarray(v)[idx]
        self.logw = np.full(self.N, -np.log(self.N))
        self.neff = float(self.N)

    def resample_if_needed(self) -> bool:
        """Resample when ``every_step`` or ``N_eff < threshold·N``; whether it did."""
        if self.every_step or self.neff < self.threshold * self.N:
            self.resample()
            return True
        return False

    def step(self, dt: float, z: ArrayLike) -> StepStats:
        """Predict over ``dt`` (skipped when 0), update with ``z``, estimate, maybe resample.

        Raises
        ------
        ValueError
            ``dt`` negative or NaN (it used to skip the predict silently).
        """
        if not dt >= 0:
            raise ValueError(f"ParticleFilter.step: dt must be >= 0 (time runs forward), got {dt}")
        if dt > 0:
            self.predict(dt)
        z = np.asarray(z, dtype=np.float64)
        predict_only = bool(np.any(~np.isfinite(z)))
        reinit, ll = (False, float("nan")) if predict_only else self.update(z)
        mean, cov, mode_p = self.estimate()
        neff = self.neff
        resampled = False if predict_only or reinit else self.resample_if_needed()
        if resampled and self.regularise_index is not None:
            self.x = regularise(self.x, cov, self.rng, self.regularise_index)
        return StepStats(mean, cov, mode_p, neff, resampled, predict_only, reinit, ll)


def run_pf(pf: ParticleFilter, t_ns: ArrayLike, z: ArrayLike, *, t0_ns: int | None = None) -> PfTrack:
    """Run an initialised filter over ``t_ns`` (T,) with measurements ``z`` (T, m).

    The first step predicts over ``t_ns[0] − t0_ns`` (nothing when ``t0_ns`` is None); a row
    with a NaN is a predict-only step. ``t_ns`` must be non-decreasing (equal stamps: an update
    without a predict), whole nanoseconds, and not before ``t0_ns``
    (:func:`~pipeline.estimate.base.check_times`). T = 0 gives an empty track.

    Raises
    ------
    ValueError
        A bad ``t_ns`` (naming the first bad row), lengths that differ, no ``init``, or ``z``
        of another width than the likelihood measures (where it says, like
        :class:`GaussianPositionLikelihood`).
    """
    t = check_times(t_ns, "run_pf", t0_ns)
    Z = np.asarray(z, dtype=np.float64)
    if Z.ndim == 1:
        Z = Z[:, None]
    if len(Z) != len(t):
        raise ValueError(f"run_pf: {len(t)} times but {len(Z)} measurements")
    if pf.x is None:
        raise ValueError("run_pf: initialise the filter first (pf.init)")
    check = getattr(pf.likelihood, "check_width", None)
    if check is not None:
        check(Z.shape[1])  # up front: a predict-only (NaN) first row would hide it
    T, n = len(t), pf.x.shape[1]
    mean = np.full((T, n), np.nan)
    cov = np.full((T, n, n), np.nan)
    mode_p = np.full((T, pf.K), np.nan)
    neff = np.full(T, np.nan)
    res = np.zeros(T, dtype=bool)
    po = np.zeros(T, dtype=bool)
    ri = np.zeros(T, dtype=bool)
    ll = np.full(T, np.nan)
    prev = (t[0] if len(t) else 0) if t0_ns is None else int(t0_ns)
    n0 = pf.n_reinit
    for k in range(T):
        s = pf.step((t[k] - prev) * 1e-9, Z[k])
        prev = t[k]
        mean[k], cov[k], mode_p[k] = s.mean, s.cov, s.mode_p
        neff[k], res[k], po[k], ri[k], ll[k] = s.neff, s.resampled, s.predict_only, s.reinit, s.loglik
    return PfTrack(t, mean, cov, mode_p, neff, res, po, ri, ll, pf.n_reinit - n0, pf.N)


def dwell_transition(dwell_s: Sequence[float], dt: float, *, to: ArrayLike | None = None) -> F64:
    """Row-stochastic Π over ``dt`` from mean dwell times per mode (a continuous-time chain).

    Mode ``i`` is left at rate ``1/τ_i`` to the others in proportion to row ``i`` of ``to``
    (default: uniformly), so ``Π(Δt) = expm(G Δt)`` with ``G_ii = −1/τ_i``,
    ``G_ij = to_ij/(τ_i Σ_{l≠i} to_il)``; this is exactly the D5 re-timing of any one step.

    Raises
    ------
    ValueError
        A dwell time not positive and finite, a row of ``to`` with nowhere to go, or ``dt``
        negative or not finite (a negative step used to come back as the identity).
    """
    from scipy.linalg import expm

    tau = np.asarray(dwell_s, dtype=np.float64)
    K = tau.size
    if K == 0 or np.any(~np.isfinite(tau)) or np.any(tau <= 0):
        raise ValueError(f"dwell_transition: dwell times must be positive and finite, got {tau.tolist()}")
    if not (np.isfinite(dt) and dt >= 0):
        raise ValueError(f"dwell_transition: dt must be finite and >= 0, got {dt}")
    if K == 1:
        return np.ones((1, 1))
    A = np.ones((K, K)) if to is None else np.asarray(to, dtype=np.float64).copy()
    np.fill_diagonal(A, 0.0)
    rs = A.sum(axis=1)
    if np.any(rs <= 0):
        raise ValueError("dwell_transition: every mode needs somewhere to go (a row of `to` is all zero)")
    G = A / rs[:, None] / tau[:, None]
    np.fill_diagonal(G, -1.0 / tau)
    P = expm(G * float(dt))
    P = np.clip(P, 0.0, None)
    return P / P.sum(axis=1, keepdims=True)


def track_meta(track: PfTrack, **extra: Any) -> dict:
    """Metadata of a run for the output table: particles, reinits, resampling and predict-only counts."""
    return {"n_particles": int(track.n_particles), "n_reinit": int(track.n_reinit),
            "n_resampled": int(np.sum(track.resampled)), "n_predict_only": int(np.sum(track.predict_only)),
            **extra}
