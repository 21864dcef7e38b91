"""Baselines for trajectory learning (issue 15, Build item 3; seed 004 §10 items 2 and 5).

The learned trajectory (:mod:`pipeline.align.trajectory`) is judged against:

1. each single demonstration;
2. the DTW-aligned average, DBA (:func:`dba_average`);
3. that average smoothed by the RTS smoother (:func:`smooth` of the :func:`dba_average`);
4. a per-demo smoother (:func:`per_demo_smooth`): seed 004 §10 item 5, "the baseline is a
   per-demo EKF/EKS". Here the EKS's model is a per-feature constant-acceleration (or
   constant-velocity) model, the estimator framework's kinematic model generalised to D
   features, so the baseline needs no dynamics of the vehicle.

The smoother is the framework's, not a second Kalman filter:
:func:`~pipeline.estimate.ekf.run_filter` with a :class:`~pipeline.estimate.base.LinearTransition`
and :class:`~pipeline.estimate.base.LinearMeasurement`, then
:func:`~pipeline.estimate.smoother.rts_smooth`. The features are independent under the model,
so each feature is one *run* of a 3-state (CA) or 2-state (CV) filter: a (T, D) track is D runs
filtered at once.

Noise levels: the measurement std ``r`` and the white-noise spectral density ``q`` (jerk for
CA, acceleration for CV) are either given or, by default (``"auto"``), chosen per feature by
maximum likelihood (prediction-error decomposition over the innovations). For a fixed ratio
``λ = q / r²`` the filter run with ``R = 1``, ``Q = λ Q₁`` gives innovations ``e_k`` with
variances ``s_k`` in units of ``r²``, and the likelihood maximised over ``r²`` is

.. math::

    \\hat r^2 = \\frac{1}{N} \\sum_k \\frac{e_k^2}{s_k},\\qquad
    \\ell(\\lambda) = -\\tfrac12 \\Big(N \\log \\hat r^2 + \\sum_k \\log s_k + N\\Big)

(the concentrated likelihood; Harvey 1989, §3.4), maximised over a log grid of ``λ`` (all
grid values are runs of one filter pass). The first ``n_x`` innovations (those of the diffuse
prior) are left out. A baseline tuned this way needs no hand-set noise and is as good as a
per-demo smoother of this model can be, so the learner is not compared with a strawman.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..estimate.base import GaussianState, LinearMeasurement, LinearTransition
from ..estimate.ekf import ExtendedKalmanFilter, run_filter
from ..estimate.models import ca_transition, white_jerk_q
from ..estimate.smoother import rts_smooth
from .dtw import dtw, dtw_distance, feature_scale

F64 = NDArray[np.float64]

#: λ·dt^(2p−1) grid (dimensionless: the per-step process variance over r²) of the "auto" search
AUTO_GRID = 10.0 ** np.arange(-10.0, 2.01, 0.5)
MODELS = ("ca", "cv")


# --------------------------------------------------------------------------- smoother

@dataclass(frozen=True)
class SmoothResult:
    """Result of :func:`smooth_track`.

    Attributes
    ----------
    mean : ndarray, shape (T, D)
        Smoothed track (the model's position component of each feature).
    q : ndarray, shape (D,)
        Spectral density used per feature (jerk for CA, acceleration for CV; track units²/sⁿ).
    r : ndarray, shape (D,)
        Measurement standard deviation used per feature (track units).
    loglik : ndarray, shape (D,)
        Innovations log-likelihood per feature at (q, r) (first n_x innovations left out).
    """

    mean: F64
    q: F64
    r: F64
    loglik: F64


def _unit_model(model: str, dt: float) -> tuple[F64, F64, int]:
    """One feature's transition F₁ and unit-density noise Q₁, and the noise's order p
    (per-step position variance ∝ dt^(2p−1))."""
    if model == "ca":
        return ca_transition(dt, 1), white_jerk_q(dt, 1.0, 1), 3
    # white-acceleration CV (Bar-Shalom, Li & Kirubarajan 2001, eq. 6.2.2-12)
    F = np.array([[1.0, dt], [0.0, 1.0]])
    Q = np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
    return F, Q, 2


def _positive(v, D: int, name: str) -> F64:
    a = np.broadcast_to(np.asarray(v, dtype=np.float64), (D,)).copy() if np.ndim(v) == 0 else \
        np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (D,) or not (np.isfinite(a).all() and (a > 0).all()):
        raise ValueError(f"smooth: {name} must be 'auto', a positive number or {D} positive numbers, got {v!r}")
    return a


def _filter(z: F64, dt: float, F1: F64, Q: F64, keep: str):
    """Filter runs ``z`` (T, R) (unit measurement noise) with per-run ``Q`` (R, n, n)."""
    T, R_ = z.shape
    n = F1.shape[0]
    H = np.zeros((1, n))
    H[0, 0] = 1.0
    ekf = ExtendedKalmanFilter(LinearTransition(F1, Q), LinearMeasurement(H, np.eye(1)))
    # a diffuse prior scaled to the data: position at the first valid sample, velocity and
    # acceleration of unknown sign with 10× the track's typical step (its first n innovations
    # are not counted in the likelihood). The step's size is its RMS, not its spread: a steady
    # track has steps of near-zero spread, which would pin the velocity prior at N(0, ~0) and
    # lock the filter onto zero velocity (a straight line came back 42 samples off)
    valid = np.isfinite(z)
    first = np.argmax(valid, axis=0)
    x0 = np.zeros((R_, n))
    x0[:, 0] = z[first, np.arange(R_)]
    d = np.diff(z, axis=0)
    ok = np.isfinite(d)
    step = np.sqrt(np.where(ok, d * d, 0.0).sum(axis=0) / np.maximum(ok.sum(axis=0), 1))
    step = np.where(np.isfinite(step) & (step > 0), step, 1.0) * 10.0
    P0 = np.zeros((R_, n, n))
    P0[:, 0, 0] = (np.nanmax(np.abs(z - x0[:, 0]), axis=0) + step) ** 2
    for k in range(1, n):
        P0[:, k, k] = (step / dt ** k) ** 2
    dt_ns = int(round(dt * 1e9))
    t_ns = np.arange(T, dtype=np.int64) * dt_ns
    return run_filter(ekf, GaussianState(x0, P0, 0), t_ns, z[:, :, None], store=keep)


def _innovations(track, z: F64, n: int) -> tuple[F64, F64, F64]:
    """Innovations e (R, T), variances s (R, T) in units of R, and the counted mask."""
    e = z.T - track.pred_mean[..., 0]
    s = track.pred_cov[..., 0, 0] + 1.0
    counted = np.isfinite(e)
    # leave out the first n measured steps of each run (the diffuse prior's)
    counted &= np.cumsum(counted, axis=1) > n
    return np.where(counted, e, 0.0), np.where(counted, s, 1.0), counted


def smooth_track(track: ArrayLike, dt: float, *, q: float | ArrayLike | str = "auto",
                 r: float | ArrayLike | str = "auto", model: str = "ca") -> SmoothResult:
    """RTS-smooth a (T, D) track as position measurements of a per-feature CA/CV model.

    Parameters
    ----------
    track : array_like, shape (T, D) or (T,)
        Uniformly sampled track; a row with a NaN is a missing measurement (smoothed
        through).
    dt : float
        Sample step (s).
    q : "auto", float or array_like (D,)
        White-noise spectral density of the model (jerk for CA, units²/s⁵; acceleration for
        CV, units²/s³); "auto": maximum likelihood per feature over :data:`AUTO_GRID`.
    r : "auto", float or array_like (D,)
        Measurement standard deviation (track units); "auto" (needs ``q="auto"``): maximum
        likelihood jointly with q (concentrated likelihood, module docstring).
    model : {"ca", "cv"}
        Constant acceleration (white jerk, 3 states a feature) or constant velocity (white
        acceleration, 2 states).

    Returns
    -------
    SmoothResult

    Raises
    ------
    ValueError
        A bad shape, dt, model or noise value, fewer than 2 valid rows in a feature (with
        ``q="auto"``: no more than n_x + 1), or ``r="auto"`` with a given q.
    """
    z = np.asarray(track, dtype=np.float64)
    if z.ndim == 1:
        z = z[:, None]
    if z.ndim != 2 or z.shape[0] < 2 or z.shape[1] < 1:
        raise ValueError(f"smooth: track must be (T, D) with T ≥ 2, got shape {z.shape}")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"smooth: dt must be a positive number of seconds, got {dt!r}")
    if model not in MODELS:
        raise ValueError(f"smooth: unknown model {model!r} (one of {', '.join(MODELS)})")
    z = np.where(np.isnan(z).any(axis=1, keepdims=True), np.nan, z)  # a NaN row is missing
    if np.isinf(z).any():
        raise ValueError(f"smooth: track has an infinite value in row {int(np.flatnonzero(np.isinf(z).any(axis=1))[0])}")
    T, D = z.shape
    if np.isfinite(z[:, 0]).sum() < 2:
        raise ValueError("smooth: track has fewer than 2 rows without NaN")
    F1, Q1, p = _unit_model(model, dt)
    n = F1.shape[0]
    auto_q = isinstance(q, str)
    auto_r = isinstance(r, str)
    if (auto_q and q != "auto") or (auto_r and r != "auto"):
        raise ValueError(f"smooth: q and r are 'auto' or numbers, got q={q!r}, r={r!r}")
    if auto_r and not auto_q:
        raise ValueError("smooth: r='auto' needs q='auto' (they are estimated jointly)")
    if auto_q and np.isfinite(z[:, 0]).sum() <= n + 1:
        # the first n innovations belong to the diffuse prior: with no more rows nothing is left
        # to estimate the noise levels from (r came back 0 and the loglik NaN, the data unsmoothed)
        raise ValueError(f"smooth: q='auto' needs more than {n + 1} rows without NaN for the {model.upper()} "
                         f"model, got {int(np.isfinite(z[:, 0]).sum())}; give q and r")
    rr = None if auto_r else _positive(r, D, "r")
    if not auto_q:
        lam = _positive(q, D, "q") / rr ** 2
    else:
        # every (grid value, feature) pair is one run of one filter pass
        lam_grid = AUTO_GRID / dt ** (2 * p - 1)
        G = len(lam_grid)
        zn = z if rr is None else z / rr
        zg = np.tile(zn, (1, G))  # runs ordered (grid, feature)
        Qg = np.repeat(lam_grid, D)[:, None, None] * Q1
        tr = _filter(zg, dt, F1, Qg, "all")
        e, s, counted = _innovations(tr, zg, n)
        N = counted.sum(axis=1)
        if rr is None:
            r2 = (e * e / s).sum(axis=1) / np.maximum(N, 1)
            ll = -0.5 * (N * np.log(r2) + np.log(s).sum(axis=1) + N)
        else:
            ll = -0.5 * ((e * e / s).sum(axis=1) + np.log(s).sum(axis=1))
        best = np.argmax(ll.reshape(G, D), axis=0)
        lam = lam_grid[best]
        if rr is None:
            rr = np.sqrt(r2.reshape(G, D)[best, np.arange(D)])
            rr = np.where(rr > 0, rr, 1e-12)
    zn = z / rr
    tr = _filter(zn, dt, F1, lam[:, None, None] * Q1, "all")
    e, s, counted = _innovations(tr, zn, n)
    ll = -0.5 * ((e * e / s).sum(axis=1) + np.log(s).sum(axis=1)) - counted.sum(axis=1) * np.log(rr)
    sm = rts_smooth(tr)
    return SmoothResult(sm.mean[:, :, 0].T * rr, lam * rr ** 2, rr, ll)


def smooth(track: ArrayLike, dt: float, *, q: float | ArrayLike | str = "auto",
           r: float | ArrayLike | str = "auto", model: str = "ca") -> F64:
    """The smoothed (T, D) track of :func:`smooth_track` (same parameters): the RTS smoother
    of the estimator framework over a per-feature CA (or CV) model."""
    return smooth_track(track, dt, q=q, r=r, model=model).mean


def per_demo_smooth(demos: Sequence[ArrayLike], dt: float, *, q: float | ArrayLike | str = "auto",
                    r: float | ArrayLike | str = "auto", model: str = "ca") -> list[F64]:
    """:func:`smooth` of each demo on its own (seed 004 §10 item 5's per-demo smoother); the
    noise levels are chosen per demo and feature when "auto"."""
    return [smooth(d, dt, q=q, r=r, model=model) for d in demos]


# --------------------------------------------------------------------------- DBA

def _demo_list(demos: Sequence[ArrayLike]) -> list[F64]:
    if len(demos) < 1:
        raise ValueError("dba_average: no demos")
    out = []
    for k, d in enumerate(demos):
        a = np.asarray(d, dtype=np.float64)
        if a.ndim == 1:
            a = a[:, None]
        if a.ndim != 2 or len(a) < 1:
            raise ValueError(f"dba_average: demo {k} must be (T, D), got shape {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"dba_average: demo {k} has a non-finite value in row "
                             f"{int(np.flatnonzero(~np.isfinite(a).all(axis=1))[0])}")
        out.append(a)
    D = {a.shape[1] for a in out}
    if len(D) != 1:
        raise ValueError(f"dba_average: demos have different feature counts {sorted(D)}")
    return out


def _window_for(window: int | None, n: int, m: int) -> int | None:
    # a window narrower than the length difference admits no path; widen it to that (as
    # dtaidistance does) rather than fail on a demo of another length
    return None if window is None else max(int(window), abs(n - m))


def medoid_index(demos: Sequence[ArrayLike], *, window: int | None = None, scale=None,
                 step_pattern: str = "symmetric1", local: str = "sqeuclidean") -> int:
    """Index of the demo with the least summed DTW distance to the others (the first on ties)."""
    ds = _demo_list(demos)
    s = feature_scale(scale, *ds)
    M = len(ds)
    tot = np.zeros(M)
    for a in range(M):
        for b in range(a + 1, M):
            d = dtw_distance(ds[a], ds[b], step_pattern=step_pattern, local=local, scale=s,
                             window=_window_for(window, len(ds[a]), len(ds[b])))
            tot[a] += d
            tot[b] += d
    return int(np.argmin(tot))


def dba_average(demos: Sequence[ArrayLike], *, n_iter: int = 10, window: int | None = None,
                scale: str | ArrayLike | None = None, init: int | ArrayLike | None = None,
                step_pattern: str = "symmetric1", local: str = "sqeuclidean") -> F64:
    """DTW Barycenter Averaging (Petitjean, Ketterlin & Gançarski 2011).

    Starting from ``init`` (by default the medoid demo, :func:`medoid_index`), each iteration
    aligns every demo to the current average by DTW and replaces each average sample by the
    mean of all demo samples aligned to it; it stops after ``n_iter`` iterations or when the
    average no longer changes. Deterministic.

    Parameters
    ----------
    demos : sequence of array_like, each (T_i, D) or (T_i,)
    n_iter : int
        Maximum number of refinements.
    window : int, optional
        Sakoe–Chiba half width of the alignments (widened to ``|L − T_i|`` where narrower).
    scale : None, "std" or array_like (D,)
        Per-feature divisors of the DTW local cost (:func:`~pipeline.align.dtw.feature_scale`,
        pooled over all demos); the average itself stays in the demos' units.
    init : int or array_like (L, D), optional
        Index of the starting demo, or a starting sequence; its length L is the average's.
    step_pattern, local : str
        DTW step pattern and local cost (:func:`~pipeline.align.dtw.dtw`); DBA's own choice,
        symmetric1 with the squared Euclidean cost, makes the per-sample mean the exact
        minimiser of the within-cluster sum of squares each iteration.

    Returns
    -------
    ndarray, shape (L, D)
    """
    ds = _demo_list(demos)
    if int(n_iter) != n_iter or n_iter < 0:
        raise ValueError(f"dba_average: n_iter must be a non-negative integer, got {n_iter!r}")
    s = feature_scale(scale, *ds)
    if init is None:
        avg = ds[medoid_index(ds, window=window, scale=s, step_pattern=step_pattern, local=local)].copy()
    elif np.ndim(init) == 0:
        if not 0 <= int(init) < len(ds):
            raise ValueError(f"dba_average: init index {init} is not one of the {len(ds)} demos")
        avg = ds[int(init)].copy()
    else:
        avg = np.asarray(init, dtype=np.float64)
        avg = avg[:, None] if avg.ndim == 1 else avg.copy()
        if avg.ndim != 2 or avg.shape[1] != ds[0].shape[1] or not np.isfinite(avg).all():
            raise ValueError(f"dba_average: init must be a finite ({'L'}, {ds[0].shape[1]}) array, got shape {avg.shape}")
    L, D = avg.shape
    for _ in range(int(n_iter)):
        acc = np.zeros((L, D))
        cnt = np.zeros(L)
        for d in ds:
            p = dtw(avg, d, step_pattern=step_pattern, local=local, scale=s,
                    window=_window_for(window, L, len(d))).path
            np.add.at(acc, p[:, 0], d[p[:, 1]])
            np.add.at(cnt, p[:, 0], 1.0)
        new = acc / cnt[:, None]  # every average sample is on every path (cnt ≥ 1)
        if np.array_equal(new, avg):
            break
        avg = new
    return avg
