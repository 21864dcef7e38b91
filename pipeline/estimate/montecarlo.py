"""Monte Carlo over runs × time (no loop over runs), truth from the white-jerk CA model, and the
one-scalar q tuning (seed 000 §3, §9, §13.7).

Arrays are ordered runs × time × state: truth and estimates ``(n_runs, T, 9)``, errors
``x̂ − x`` likewise, covariances ``(n_runs, T, 9, 9)``; measurements enter the filter as
``(T, n_runs, n_z)`` (:func:`~pipeline.estimate.ekf.run_filter` steps through time).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .base import ConstantAcceleration, GaussianState, MeasurementModel
from .ekf import ExtendedKalmanFilter, FilterTrack, run_filter
from .metrics import nees as nees_of
from .metrics import rmse
from .models import ca_transition, initial_cov, white_jerk_q

F64 = NDArray[np.float64]


def simulate_white_jerk(n_runs: int, n_steps: int, dt: float, q: float, x0: ArrayLike,
                        P0: ArrayLike | None = None, *,
                        rng: np.random.Generator | int) -> F64:
    """Truth drawn from the filter's own model: ``x_{k+1} = A x_k + w_k``, ``w_k ~ N(0, Q(dt, q))``.

    Parameters
    ----------
    n_runs, n_steps : int
    dt : float
        Step (s).
    q : float
        Jerk spectral density (m²/s⁵).
    x0 : array_like, shape (9,) or (n_runs, 9)
        Mean initial state.
    P0 : array_like, shape (9, 9), optional
        Initial spread: ``x_0 ~ N(x0, P0)`` (default :func:`~pipeline.estimate.models.initial_cov`;
        then a filter started at ``x0`` with ``P0`` is consistent from the first step).
    rng : Generator or int
        The draws' generator, or a seed for one (required: every draw comes from the config's
        master seed, never from the operating system's entropy).

    Returns
    -------
    ndarray, shape (n_runs, n_steps, 9)

    Raises
    ------
    TypeError
        ``rng`` is None.
    ValueError
        ``n_runs`` or ``n_steps`` below 1, or ``dt`` or ``q`` not finite and positive.
    """
    rng = _required_rng(rng, "simulate_white_jerk")
    if int(n_runs) < 1 or int(n_steps) < 1:
        raise ValueError(f"simulate_white_jerk: n_runs and n_steps must be >= 1, got {n_runs}, {n_steps}")
    # q = 0 or dt <= 0 would reach cholesky as a bare LinAlgError
    if not (np.isfinite(dt) and dt > 0 and np.isfinite(q) and q > 0):
        raise ValueError(f"simulate_white_jerk: dt and q must be finite and > 0, got dt={dt}, q={q}")
    P0 = initial_cov() if P0 is None else np.asarray(P0, dtype=np.float64)
    A = ca_transition(dt)
    Lq = np.linalg.cholesky(white_jerk_q(dt, q))
    L0 = np.linalg.cholesky(P0)
    x = np.empty((n_runs, n_steps, 9))
    x[:, 0] = np.broadcast_to(np.asarray(x0, dtype=np.float64), (n_runs, 9)) + rng.standard_normal((n_runs, 9)) @ L0.T
    w = rng.standard_normal((n_steps - 1, n_runs, 9)) @ Lq.T
    for k in range(1, n_steps):
        x[:, k] = x[:, k - 1] @ A.T + w[k - 1]
    return x


def _required_rng(rng, who: str) -> np.random.Generator:
    """``rng`` as a Generator; None is refused (``default_rng(None)`` would draw from the
    operating system's entropy, breaking the explicit-seed rule)."""
    if rng is None:
        raise TypeError(f"{who}: rng is required: pass np.random.default_rng(seed)")
    return np.random.default_rng(rng)


def measure(model, truth: ArrayLike, rng: np.random.Generator | int) -> F64:
    """Measurements of ``truth`` (n_runs, T, n_x) through ``model.measure`` (e.g. the
    :class:`~pipeline.estimate.models.RadarModel`), returned as ``(T, n_runs, n_z)``.

    ``rng`` (a Generator or a seed) is required: None raises TypeError."""
    rng = _required_rng(rng, "measure")
    z = model.measure(np.asarray(truth, dtype=np.float64), rng)
    return np.ascontiguousarray(np.swapaxes(z, 0, 1))


@dataclass(frozen=True)
class MonteCarloResult:
    """Monte Carlo statistics (arrays runs × time × state; summaries over runs).

    Attributes
    ----------
    err : (R, T, 9) estimate − truth
    nees, nis : (R, T)
    mean_err, err_var : (T, 9) mean and variance of the error over runs
    filter_var : (T, 9) run-mean of the filter's variances (diag P)
    nees_avg : (T,) run-averaged NEES
    nis_avg : (T,) run-averaged NIS over the runs measured in full at that step (``dof ==
        nis_dof``; NaN where none is): a predict-only step has no NIS, and a partly measured
        run's NIS has fewer degrees of freedom
    nis_dof : int, the NIS's degrees of freedom: the most measured scalars of any run and step
    nis_count : (T,) int, the runs averaged in ``nis_avg`` (the ``n_runs`` of its χ² band,
        :func:`~pipeline.estimate.metrics.fraction_in_band`)
    track : the filter run
    """

    err: F64
    nees: F64
    nis: F64
    mean_err: F64
    err_var: F64
    filter_var: F64
    nees_avg: F64
    nis_avg: F64
    nis_dof: int
    track: FilterTrack
    nis_count: NDArray[np.int64] | None = None


def monte_carlo(ekf: ExtendedKalmanFilter, truth: ArrayLike, z: ArrayLike, t_ns: ArrayLike,
                prior: GaussianState, store: str = "filtered") -> MonteCarloResult:
    """Filter every run at once and summarise errors, NEES and NIS over runs (seed 000 §9).

    Parameters
    ----------
    ekf : ExtendedKalmanFilter
    truth : array_like, shape (R, T, 9)
    z : array_like, shape (T, R, n_z)
    t_ns : array_like of int, shape (T,)
    prior : GaussianState
        Batch (R,) or one state for every run, at ``t_ns[0]`` (first step: update only).
    store : {"filtered", "all"}
        ``"all"`` keeps what the RTS smoother needs (``"mean"`` is refused: NEES and the
        filter variances need the covariances).
    """
    if store not in ("filtered", "all"):
        raise ValueError(f"monte_carlo: store must be 'filtered' or 'all' (NEES needs the covariances), not {store!r}")
    truth = np.asarray(truth, dtype=np.float64)
    z_shape = np.shape(z)
    if truth.ndim != 3 or len(z_shape) < 3 or z_shape[:2] != (truth.shape[1], truth.shape[0]):
        raise ValueError(f"monte_carlo: truth shaped {truth.shape} (R, T, n_x) and z shaped {z_shape} "
                         "(T, R, ...) do not match")
    R_ = truth.shape[0]
    if prior.mean.ndim == 1:
        prior = GaussianState(np.broadcast_to(prior.mean, (R_, prior.n_x)),
                              np.broadcast_to(prior.cov, (R_, prior.n_x, prior.n_x)), prior.t_ns)
    track = run_filter(ekf, prior, t_ns, z, store=store)
    err = track.mean - truth
    ne = nees_of(err, track.cov)
    dof = int(track.dof.max()) if track.dof.size else 0
    # update_stats reports NIS 0 for a predict-only step: averaging those in biases the NIS low
    full = (track.dof == dof) & (dof > 0)
    count = full.sum(axis=0)
    nis_sum = np.where(full, track.nis, 0.0).sum(axis=0)
    nis_avg = np.divide(nis_sum, count, out=np.full(count.shape, np.nan), where=count > 0)
    return MonteCarloResult(err=err, nees=ne, nis=track.nis, mean_err=err.mean(axis=0),
                            err_var=err.var(axis=0, ddof=1) if R_ > 1 else np.zeros(err.shape[1:]),
                            filter_var=np.diagonal(track.cov, axis1=-2, axis2=-1).mean(axis=0),
                            nees_avg=ne.mean(axis=0), nis_avg=nis_avg, nis_dof=dof,
                            track=track, nis_count=count)


@dataclass(frozen=True)
class TunedQ:
    """The frozen outcome of :func:`tune_q`.

    Attributes
    ----------
    q : float
        The chosen jerk spectral density (m²/s⁵).
    grid : tuple of float
    score : tuple of float
        Normalised RMSE per grid value (lower is better).
    rmse : ndarray, shape (len(grid), 9)
        Per-component RMSE per grid value.
    """

    q: float
    grid: tuple[float, ...]
    score: tuple[float, ...]
    rmse: F64


def normalised_rmse(rmse_grid: ArrayLike, scale: ArrayLike | None = None) -> F64:
    """Score per grid row: the mean over components of ``RMSE_i / scale_i``.

    ``scale`` defaults to each component's median RMSE over the grid, so the score is
    unit-free and position, velocity and acceleration weigh alike.
    """
    r = np.asarray(rmse_grid, dtype=np.float64)
    s = np.median(r, axis=0) if scale is None else np.asarray(scale, dtype=np.float64)
    return np.mean(r / s, axis=-1)


def tune_q(truth: ArrayLike, z: ArrayLike, t_ns: ArrayLike, measurement: MeasurementModel,
           grid: Sequence[float], P0: ArrayLike | None = None, scale: ArrayLike | None = None,
           joseph: bool = True,
           transition: Callable[[float], object] = ConstantAcceleration) -> TunedQ:
    """Grid-search the one scalar ``q`` on training runs by normalised RMSE (seed 000 §3, §13.7).

    Every grid value filters all training runs at once (started at the truth's first state with
    ``P0``); the score is :func:`normalised_rmse` of the per-component RMSE over runs and time.
    The result is frozen: tune on training runs, then use ``TunedQ.q`` unchanged on test runs.

    Parameters
    ----------
    truth : array_like, shape (R, T, 9)
        Training truth.
    z : array_like, shape (T, R, n_z)
        Their measurements.
    t_ns : array_like of int, shape (T,)
    measurement : MeasurementModel
    grid : sequence of float
        Candidate ``q`` (m²/s⁵), > 0.
    P0 : array_like, optional
        Initial covariance (default :func:`~pipeline.estimate.models.initial_cov`).
    scale : array_like, shape (9,), optional
        Per-component RMSE scale (default: the grid median, see :func:`normalised_rmse`).
    transition : callable
        ``q -> TransitionModel`` (default the white-jerk CA model).
    """
    grid = tuple(float(g) for g in grid)
    if not grid or min(grid) <= 0:
        raise ValueError(f"tune_q: grid must hold positive values, got {grid}")
    truth = np.asarray(truth, dtype=np.float64)
    P0 = initial_cov() if P0 is None else np.asarray(P0, dtype=np.float64)
    R_, n_x = truth.shape[0], truth.shape[-1]
    t0 = int(np.asarray(t_ns)[0])
    prior = GaussianState(truth[:, 0], np.broadcast_to(P0, (R_, n_x, n_x)), t0)
    rm = np.empty((len(grid), n_x))
    for i, q in enumerate(grid):
        ekf = ExtendedKalmanFilter(transition(q), measurement, joseph=joseph)
        track = run_filter(ekf, prior, t_ns, z, store="mean")
        rm[i] = rmse(track.mean - truth)
    score = normalised_rmse(rm, scale)
    return TunedQ(q=grid[int(np.argmin(score))], grid=grid, score=tuple(float(s) for s in score), rmse=rm)
