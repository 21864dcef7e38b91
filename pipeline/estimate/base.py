"""Estimator framework: the Gaussian state and the model protocols (style.md §2.4, Stone Soup).

Transition and measurement models are objects separate from the filter's ``predict`` /
``update``. Every array may carry leading batch axes: a Monte Carlo over runs holds means
``(n_runs, n_x)`` and covariances ``(n_runs, n_x, n_x)`` in one :class:`GaussianState`, so a
filter over runs × time loops over time only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .models import ca_transition, white_jerk_q

F64 = NDArray[np.float64]


def check_times(t_ns: ArrayLike, who: str, t0_ns: int | None = None) -> NDArray[np.int64]:
    """Step times (ns) as an int64 array (T,), checked with one clear error.

    Equal stamps are allowed (several updates at one instant); a step back in time is not:
    predicting over a negative ``dt`` gives a negative definite process noise in an EKF, and a
    particle filter would skip it, both silently.

    Parameters
    ----------
    t_ns : array_like, shape (T,)
        Integers, or floats holding whole nanoseconds (a fractional value is refused rather
        than truncated).
    who : str
        The caller, for the message.
    t0_ns : int, optional
        The prior's time, which must not be after ``t_ns[0]``.

    Raises
    ------
    ValueError
        ``t_ns`` not 1-D, a non-finite or fractional float, a decreasing step (naming its
        first row), or ``t0_ns > t_ns[0]``.
    """
    a = np.asarray(t_ns)
    if a.ndim != 1:
        raise ValueError(f"{who}: t_ns must be 1-D, got shape {a.shape}")
    if a.dtype.kind == "f":
        bad = ~np.isfinite(a) | (a != np.round(a))
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(f"{who}: t_ns must hold whole nanoseconds; row {k} is {a[k]!r} "
                             "(round or scale it explicitly)")
    t = np.asarray(a, dtype=np.int64)
    back = np.diff(t) < 0
    if back.any():
        k = int(np.argmax(back)) + 1
        raise ValueError(f"{who}: t_ns must be non-decreasing; row {k} ({int(t[k])}) is before row {k - 1} "
                         f"({int(t[k - 1])})")
    if t0_ns is not None and len(t) and int(t0_ns) > int(t[0]):
        raise ValueError(f"{who}: the prior time {int(t0_ns)} ns is after the first step t_ns[0] = {int(t[0])} ns")
    return t


@dataclass(frozen=True)
class GaussianState:
    """A Gaussian state estimate at one time.

    Parameters
    ----------
    mean : ndarray, shape (..., n_x)
        State mean (one row per run for a batch).
    cov : ndarray, shape (..., n_x, n_x)
        State covariance.
    t_ns : int
        Time of the estimate (ns), shared by every run of a batch.

    Notes
    -----
    Frozen, and its arrays are read-only views of the ones it was given, not copies: the
    filters write a posterior covariance straight into the run's stored history (``out=``) and
    wrap that. A caller that edits an array after handing it over edits the state too, so hand
    over arrays you no longer change.
    """

    mean: F64
    cov: F64
    t_ns: int = 0

    def __post_init__(self):
        m = np.asarray(self.mean, dtype=np.float64)
        c = np.asarray(self.cov, dtype=np.float64)
        if c.shape != m.shape + m.shape[-1:]:
            raise ValueError(f"GaussianState: cov shape {c.shape} does not match mean shape {m.shape}")
        # read-only views: a state is a value, never edited in place (a view costs no copy
        # and leaves the caller's array flags alone)
        m, c = m.view(), c.view()
        m.flags.writeable = False
        c.flags.writeable = False
        object.__setattr__(self, "mean", m)
        object.__setattr__(self, "cov", c)
        object.__setattr__(self, "t_ns", int(self.t_ns))

    @property
    def n_x(self) -> int:
        """State dimension."""
        return self.mean.shape[-1]

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading (run) axes, ``()`` for a single estimate."""
        return self.mean.shape[:-1]


@runtime_checkable
class TransitionModel(Protocol):
    """``x_{k+1} = F(dt) x_k + w``, ``w ~ N(0, Q(dt))``."""

    def matrix(self, dt: float) -> F64: ...

    def noise(self, dt: float) -> F64: ...


@runtime_checkable
class NonlinearTransitionModel(Protocol):
    """``x_{k+1} = f(x_k, dt) + w``, ``w ~ N(0, Q(dt))``, linearised about the posterior:
    ``F_k = ∂f/∂x`` (``jacobian``, ``(..., n_x, n_x)``), ``P⁻ = F_k P F_kᵀ + Q``. A model may also
    offer ``linearise(x, dt) -> (f(x), F)`` from one evaluation, which
    :func:`~pipeline.estimate.ekf.run_filter` then prefers.
    :class:`~pipeline.estimate.aircraft.Yak54Transition` is one."""

    def f(self, x: ArrayLike, dt: float) -> F64: ...

    def jacobian(self, x: ArrayLike, dt: float) -> F64: ...

    def noise(self, dt: float) -> F64: ...


@runtime_checkable
class MeasurementModel(Protocol):
    """``z = h(x) + ν``, ``ν ~ N(0, R)``; ``jacobian`` is ∂h/∂x (``(..., n_z, n_x)``).
    :class:`~pipeline.estimate.models.RadarModel` is one."""

    @property
    def R(self) -> F64: ...

    def h(self, x: ArrayLike) -> F64: ...

    def jacobian(self, x: ArrayLike) -> F64: ...


@dataclass(frozen=True)
class ConstantAcceleration:
    """The 9-state CA model in NED with white-jerk noise (seed 000 eq. 2.16; Q:
    :func:`~pipeline.estimate.models.white_jerk_q`).

    Parameters
    ----------
    q : float
        Jerk power spectral density (m²/s⁵).
    """

    q: float

    def matrix(self, dt: float) -> F64:
        """``A(dt)`` (9×9)."""
        return ca_transition(dt)

    def noise(self, dt: float) -> F64:
        """``Q(dt, q)`` (9×9)."""
        return white_jerk_q(dt, self.q)


@dataclass(frozen=True)
class LinearTransition:
    """A fixed linear transition ``F``, ``Q`` (independent of dt; tests and oracles)."""

    F: F64
    Q: F64

    def matrix(self, dt: float) -> F64:
        return np.asarray(self.F, dtype=np.float64)

    def noise(self, dt: float) -> F64:
        return np.asarray(self.Q, dtype=np.float64)


@dataclass(frozen=True)
class LinearMeasurement:
    """``z = H x + ν``, ``ν ~ N(0, R)``.

    Parameters
    ----------
    H : ndarray, shape (n_z, n_x)
    R : ndarray, shape (n_z, n_z)
    """

    H: F64
    R: F64

    def h(self, x: ArrayLike) -> F64:
        return np.asarray(x, dtype=np.float64) @ np.asarray(self.H, dtype=np.float64).T

    def jacobian(self, x: ArrayLike) -> F64:
        x = np.asarray(x, dtype=np.float64)
        H = np.asarray(self.H, dtype=np.float64)
        return np.broadcast_to(H, x.shape[:-1] + H.shape)

    def measure(self, x: ArrayLike, rng: np.random.Generator) -> F64:
        """``H x + ν`` with ν ~ N(0, R) from ``rng``."""
        y = self.h(x)
        L = np.linalg.cholesky(np.asarray(self.R, dtype=np.float64))
        return y + rng.standard_normal(y.shape) @ L.T


def position_measurement(sigma_m: float, n_axes: int = 3) -> LinearMeasurement:
    """Linear NED position measurement of the CA state, ``R = σ² I``."""
    H = np.zeros((n_axes, 3 * n_axes))
    H[:, :n_axes] = np.eye(n_axes)
    return LinearMeasurement(H, sigma_m ** 2 * np.eye(n_axes))
