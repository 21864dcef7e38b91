"""Seed-003 weave classifier: a hierarchical-Markov particle filter (``hmpf``).

Van de Kerkhof (2014) tracks one ship with a SIR particle filter whose particles each carry a
mode and, in the weave mode, a submode (digest 003 §1–§5):

========  ===========  ============================================================
mode m    meaning      leaf dynamics
========  ===========  ============================================================
0  S      straight     curvilinear motion (CM): CV with along/cross-track noise
1  L      left curve   augmented coordinated turn (ACT), **ω < 0 in NED**
2  R      right curve  ACT, **ω > 0 in NED**
3  W      weave        submode cycle CL → SL → CR → SR → CL (CL/CR: ACT, SL/SR: CM)
========  ===========  ============================================================

Sign convention (pinned by tests): NED with (x, y) = (N, E), bearing = atan2(E, N), ω > 0 a
**right** turn — the reverse of the thesis's printed convention (its x = East, y = North frame
makes its ω > 0 a left turn). The ACT step is :func:`~.models.ct_transition`.

Per particle and step k (digest 003 §5):

1. ``m_k ~ Π_m[m_{k−1}, ·]`` (eq. 4.2 by default, stationary distribution
   [0.7870, 0.0278, 0.0278, 0.1574]).
2. In weave, ``sm_k ~ Π_sm(δ_{k−1}, θ_{k−1})[sm_{k−1}, ·]`` with

   .. math::

       \\Pi_{sm} = \\begin{bmatrix}1-p_{cs}&p_{cs}&0&0\\\\0&1-p_{sc}&p_{sc}&0\\\\
       0&0&1-p_{cs}&p_{cs}\\\\p_{sc}&0&0&1-p_{sc}\\end{bmatrix}

   (order CL, SL, CR, SR), ``p_sc`` from the distance δ on the current straight and ``p_cs``
   from the angle |θ| turned in the current curve (digest A5), by the **if-else method**
   (``p = p1`` below the maximum, ``p2`` at or above it; thesis final 0.05/0.95) or the
   **min-method** (``p = min((x/x_max)^n, cap)``).
3. The leaf's dynamics draw the new state; entering a curve leaf draws ``|ω| ~ U[ω_lo, ω_hi]``
   signed by the leaf (digest A2); in a curve ω random-walks by σ_α per step.
4. δ and θ: ``δ += |Δ(N, E)|`` (eq. 2.3) and ``θ += ω T`` (eq. 2.4), restarting (``counters``)
   on every leaf change and on entering W (``leaf``, the default: digest A4's suggestion), or
   only when the particle's path begins a straight or enters a curve (``segment``: (2.3) as
   printed, "0 when beginning a straight segment, δ_k + … while already on a straight
   segment", so S → SL/SR continues the straight's δ; the study measures both).
5. Log-weight += ``log p(z_k | s_k)`` (GPS: Gaussian on (N, E); radar:
   :class:`~.models.Radar2DModel`, bearing residual wrapped); the **turn-sign guard** sets the
   weight of a curve particle whose ω has left its leaf's sign to zero (digest §2, A11).
6. Normalise (all weights zero: re-initialise around z_k, counted), estimate (weighted mean and
   covariance before resampling, digest A10), resample (every step by default, multinomial —
   the thesis; N_eff-triggered as an option) and report the mode fractions after it (§2.4.2:
   the class probability is the particle fraction).

The detector (§6): ``AF(k)`` is the mean of the weave fraction F over the last N = 80 steps
(over all steps so far while fewer than N), a weave declared while ``AF(k) ≥ τ = 0.269``; the
first 25 steps are left out of the average as well as the output (§6.3: the start-up's F is
not "take[n] in consideration"), so AF is NaN there and averages F from step 26 on. k counts
the filter's steps 1..T (index 1 on): index 0 is the initial cloud (modes uniform, no
measurement weighed), which the thesis does not output, so it is in neither the average nor
the start-up count (its ``af`` is NaN too).

Vectorised over runs and particles: arrays ``(R, N)``. The per-particle logic (mode and
submode draws, the leaf's noise, the counters, the guard, the weighted statistics) runs in
``@njit`` kernels fed with uniforms and normals drawn from the caller's one generator, so a
seed fixes the result; the turn step is :func:`~.models.ct_transition` and the resampling the
PF core's (:mod:`pipeline.estimate.resample`), each once.

API: :class:`HmpfConfig` (``estimate.pf.hmpf``), :func:`hmpf_filter` ``(z, sensor, cfg, rng)
-> HmpfTrack``, sensors :class:`GpsSensor` / :class:`RadarSensor`, and the exact parts
:func:`stationary_distribution`, :func:`switch_probability`, :func:`submode_matrix`,
:func:`leaf_of`, :func:`detector`. Real flights: :mod:`pipeline.estimate.weave_run`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from ..config import ConfigError, build, cfield, validate_section
from .markov import check_stochastic
from .models import Radar2DModel, ct_transition
from .resample import get_resampler

F64 = NDArray[np.float64]

#: modes and submodes, in index order
MODES: tuple[str, ...] = ("S", "L", "R", "W")
SUBMODES: tuple[str, ...] = ("CL", "SL", "CR", "SR")
S, L, R, W = range(4)
CL, SL, CR, SR = range(4)
#: leaves: the non-weave modes 0–2, then the weave submodes 3 + sm
LEAVES: tuple[str, ...] = ("S", "L", "R", "CL", "SL", "CR", "SR")
#: turn sign of each leaf in NED (0 straight, −1 left, +1 right)
LEAF_SIGN = np.array([0, -1, 1, -1, 0, 1, 0], dtype=np.int8)
#: state components
STATE: tuple[str, ...] = ("pos_n_m", "pos_e_m", "vel_n_mps", "vel_e_mps", "omega_radps")

_h = "estimate.pf.hmpf"
#: log of the smallest normal double: a likelihood below it is a zero weight
_LOG_TINY = float(np.log(np.finfo(np.float64).tiny))
#: keys of estimate.pf.hmpf that are not the filter's
_NOT_FILTER_KEYS = ("vehicles", "from_train", "noise_from_train", "turn_threshold_radps", "radar")


@dataclass(frozen=True, kw_only=True)
class HmpfConfig:
    """The filter's settings (``estimate.pf.hmpf``; defaults: seed 003 §4.3, §6, §7).

    See ``rules/schemas/config.schema.yaml`` for each key's description.
    """

    dt_s: float = cfield(_h, "dt_s")
    n_particles: int = cfield(_h, "n_particles")
    pi_m: tuple = cfield(_h, "pi_m", convert=lambda v: tuple(tuple(float(x) for x in r) for r in v))
    method: str = cfield(_h, "method")
    p1: float = cfield(_h, "p1")
    p2: float = cfield(_h, "p2")
    min_exponent: int = cfield(_h, "min_exponent")
    min_cap: float = cfield(_h, "min_cap")
    delta_max_m: float = cfield(_h, "delta_max_m")
    theta_max_rad: float = cfield(_h, "theta_max_rad")
    sigma_at_mps2: float = cfield(_h, "sigma_at_mps2")
    sigma_an_mps2: float = cfield(_h, "sigma_an_mps2")
    sigma_axy_mps2: float = cfield(_h, "sigma_axy_mps2")
    sigma_alpha_radps: float = cfield(_h, "sigma_alpha_radps")
    omega_init_radps: tuple = cfield(_h, "omega_init_radps", convert=lambda v: tuple(float(x) for x in v))
    init_k_sigma: float = cfield(_h, "init_k_sigma")
    enter_submode: str = cfield(_h, "enter_submode")
    counters: str = cfield(_h, "counters")
    resample: str = cfield(_h, "resample")
    ess_fraction: float = cfield(_h, "ess_fraction")
    detector_window: int = cfield(_h, "detector_window")
    tau: float = cfield(_h, "tau")
    startup_steps: int = cfield(_h, "startup_steps")
    gps_sigma_m: float = cfield(_h, "gps_sigma_m")

    @classmethod
    def from_config(cls, sec: Mapping[str, Any] | None, **override) -> "HmpfConfig":
        """From ``estimate.pf.hmpf`` (validated, defaulted; the ``vehicles``, ``from_train``,
        ``noise_from_train``, ``turn_threshold_radps`` and ``radar`` keys belong to the rule and the
        sensor), then ``override``."""
        sec = {k: v for k, v in validate_section(_h, sec).items() if k not in _NOT_FILTER_KEYS}
        return build(cls, {**sec, **override})   # __post_init__ checks the result (check_hmpf_config)

    def __post_init__(self) -> None:
        # every instance, however made (from_config, direct construction, with_()), is checked
        check_hmpf_config(self)

    def with_(self, **kw) -> "HmpfConfig":
        """A copy with some settings changed."""
        import dataclasses
        return dataclasses.replace(self, **kw)


def _plain_value(v: Any) -> Any:
    """A field value as the plain Python the config schema validates (numpy scalars and arrays
    unwrapped, tuples as lists)."""
    if isinstance(v, np.ndarray):
        return _plain_value(v.tolist())
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (list, tuple)):
        return [_plain_value(x) for x in v]
    return v


def _numbers(v: Any):
    if isinstance(v, (list, tuple)):
        for x in v:
            yield from _numbers(x)
    elif isinstance(v, (int, float)) and not isinstance(v, bool):
        yield v


def check_hmpf_config(cfg: "HmpfConfig") -> None:
    """The one check of the filter's settings, whatever made them (:meth:`HmpfConfig.from_config`,
    direct construction or :meth:`HmpfConfig.with_`, via ``__post_init__``): every value against
    the ``estimate.pf.hmpf`` schema (types, ranges, enums: p1/p2 in [0, 1], dt_s > 0,
    n_particles >= 10, counters, enter_submode, method, resample...), every number finite (the
    schema's bounds let NaN through), ``pi_m`` row-stochastic and ``omega_init_radps`` ordered.

    Raises
    ------
    ConfigError (a ValueError)
        One line naming the key and the value.
    """
    import dataclasses

    sec = {f.name: _plain_value(getattr(cfg, f.name)) for f in dataclasses.fields(cfg)}
    validate_section(_h, sec)
    for k, v in sec.items():
        bad = [x for x in _numbers(v) if not np.isfinite(x)]
        if bad:
            raise ConfigError(f"{_h}.{k}: {v!r} is not finite")
    check_stochastic(cfg.pi_m, f"{_h}.pi_m")
    lo, hi = cfg.omega_init_radps
    if not 0 < lo <= hi:
        raise ConfigError(f"{_h}.omega_init_radps: need 0 < low <= high, got {cfg.omega_init_radps}")


# -- the exact parts ---------------------------------------------------------------------------------

def stationary_distribution(Pi: ArrayLike) -> F64:
    """The stationary distribution π of a row-stochastic ``Pi`` (π Π = π, Σπ = 1), by the
    eigenvector of Πᵀ for eigenvalue 1 (seed 003 §4.3: [0.7870, 0.0278, 0.0278, 0.1574] for 4.2)."""
    P = check_stochastic(Pi, "Pi")
    vals, vecs = np.linalg.eig(P.T)
    v = np.real(vecs[:, np.argmin(np.abs(vals - 1.0))])
    return v / v.sum()


def switch_probability(x: ArrayLike, x_max: float, cfg: HmpfConfig) -> F64:
    """Probability to leave the current submode given its counter ``x`` (δ or |θ|), digest 003 §4.

    if-else: ``p1`` if ``x < x_max`` else ``p2``; min: ``min((x/x_max)^n, cap)``.
    """
    x = np.abs(np.asarray(x, dtype=np.float64))
    if cfg.method == "if_else":
        return np.where(x < x_max, cfg.p1, cfg.p2)
    if cfg.method == "min":
        return np.minimum((x / x_max) ** cfg.min_exponent, cfg.min_cap)
    raise ValueError(f"{_h}.method: {cfg.method!r} is not if_else or min")


def submode_matrix(delta: ArrayLike, theta: ArrayLike, cfg: HmpfConfig) -> F64:
    """``Π_sm(δ, θ)``, shape ``(..., 4, 4)`` (order CL, SL, CR, SR; module docstring): curves
    leave with ``p_cs(θ)``, straights with ``p_sc(δ)``; every row sums to 1."""
    p_sc = switch_probability(delta, cfg.delta_max_m, cfg)
    p_cs = switch_probability(theta, cfg.theta_max_rad, cfg)
    p_sc, p_cs = np.broadcast_arrays(p_sc, p_cs)
    P = np.zeros(p_sc.shape + (4, 4))
    for sm in range(4):
        p = p_cs if sm in (CL, CR) else p_sc
        P[..., sm, sm] = 1.0 - p
        P[..., sm, (sm + 1) % 4] = p
    return P


def leaf_of(mode: ArrayLike, submode: ArrayLike) -> NDArray[np.int8]:
    """Leaf index (:data:`LEAVES`) of (mode, submode): the mode outside W, ``3 + sm`` in W."""
    m = np.asarray(mode)
    return np.where(m == W, 3 + np.asarray(submode), m).astype(np.int8)


def _whole(v: Any, name: str, least: int) -> int:
    """``v`` as an int, or one ValueError unless it is a whole number >= ``least`` (an integral
    float such as 80.0 is taken; 1.9 or True is not)."""
    ok = not isinstance(v, (bool, np.bool_))
    if ok:
        try:
            f = float(v)
            ok = bool(np.isfinite(f)) and f.is_integer() and f >= least
        except (TypeError, ValueError):
            ok = False
    if not ok:
        raise ValueError(f"detector: {name} must be a whole number >= {least}, got {v!r}")
    return int(v)


def detector(F: ArrayLike, window: int = 80, tau: float = 0.269, startup: int = 25) -> tuple[F64, NDArray[np.bool_]]:
    """Seed-003 §6 detector over the last axis of the weave fraction ``F`` (..., T).

    The printed average (thesis §6.2), with ``k`` "the current time step" (1-based):

    .. math::

        AF(k) = \\frac{1}{\\min(k, N)} \\sum_{i=\\max(1, k-N+1)}^{k} F(i)

    and, during the start-up, "we do not take the fraction of particles in the mode weave in
    consideration during this startup time. We disregard the detector output during this
    period" (§6.3): F(1..``startup``) is left out of every sum (taken as 0) while ``k`` stays the
    track's step, so AF(26) = F(26)/26 and the average reaches its full 80-step window of
    post-start-up steps at k = 105. Declared where ``AF ≥ τ`` after the start-up. Returns
    ``(AF, declared)``; AF is NaN during the start-up.

    This reading keeps the printed formula and its normaliser. It replaced one that restarted the
    count at step 26 (AF(26) = F(26) alone, a one-sample "average"), after that one's results had
    been seen: at small size (20 seeds, 2,000 particles) straight tracks never flagged 16/20 → 19/20,
    π-turn 6/20 → 7/20, the weave flagged within 80 steps of its 3rd turn 17/20 → 16/20, and weave
    runs flagged on the lead straight before the weave began 7/20 → 0/20.

    Raises
    ------
    ValueError
        ``window`` not a whole number >= 1, ``startup`` not a whole number >= 0, or ``tau`` not
        finite.
    """
    window = _whole(window, "window", 1)
    startup = _whole(startup, "startup", 0)
    try:
        tau_ok = bool(np.isfinite(float(tau)))
    except (TypeError, ValueError):
        tau_ok = False
    if not tau_ok:
        raise ValueError(f"detector: tau must be a finite number, got {tau!r}")
    F = np.asarray(F, dtype=np.float64)
    T = F.shape[-1]
    s = min(startup, T)
    G = F.copy()
    G[..., :s] = 0.0                   # not taken into consideration
    c = np.cumsum(G, axis=-1)
    lagged = np.zeros_like(c)
    if T > window:
        lagged[..., window:] = c[..., :-window]
    k = np.arange(1, T + 1)            # the current time step (1-based)
    af = (c - lagged) / np.minimum(k, window)
    af[..., :s] = np.nan               # the output during the start-up is disregarded
    declared = np.zeros(F.shape, dtype=bool)
    declared[..., s:] = af[..., s:] >= tau
    return af, declared


# -- the filter ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class GpsSensor:
    """GPS position ``z = [N, E]`` with σ per axis (seed 003 §4.1: 1 m)."""

    sigma_m: float = 1.0

    def log_likelihood(self, z: ArrayLike, x: ArrayLike) -> F64:
        e = (np.asarray(z)[..., None, :] - np.asarray(x)[..., 0:2]) / self.sigma_m
        return -0.5 * np.sum(e * e, axis=-1)

    def position(self, z: ArrayLike) -> F64:
        return np.asarray(z, dtype=np.float64)[..., 0:2]

    def position_sigma(self, z: ArrayLike) -> F64:
        return np.full(np.shape(z)[:-1], self.sigma_m)


class RadarSensor:
    """The seed-003 2-D radar as the filter's sensor (:class:`~.models.Radar2DModel`)."""

    def __init__(self, model: Radar2DModel | None = None) -> None:
        self.model = model or Radar2DModel()

    def log_likelihood(self, z: ArrayLike, x: ArrayLike) -> F64:
        return self.model.log_likelihood(np.asarray(z)[..., None, :], x)

    def position(self, z: ArrayLike) -> F64:
        return self.model.position(z)

    def position_sigma(self, z: ArrayLike) -> F64:
        sr, sb, _ = self.model.sigma
        return np.hypot(sr, np.asarray(z)[..., 0] * sb)  # larger of range and cross-range, combined


@dataclass(frozen=True)
class HmpfTrack:
    """The ``hmpf`` output of R runs over T steps.

    Attributes
    ----------
    mean : ndarray (R, T, 5)
        Particle mean of ``[N, E, v_N, v_E, ω]`` (before resampling).
    cov : ndarray (R, T, 5, 5)
        Particle covariance.
    mode_p : ndarray (R, T, 4)
        Fractions of S, L, R, W (after resampling: the class probabilities).
    submode_p : ndarray (R, T, 4)
        Fractions of CL, SL, CR, SR among all particles (they sum to ``mode_p[..., 3]``).
    neff : ndarray (R, T)
        N_eff = 1/Σw² before resampling.
    resampled : ndarray of bool (R, T)
    af : ndarray (R, T)
        The detector's windowed weave fraction AF(k) over F at indices 1..k (NaN at index 0,
        the initial cloud).
    weave_detected : ndarray of bool (R, T)
    n_reinit : ndarray of int (R,)
        Steps where every weight was zero and the cloud was re-initialised around z_k.
    n_guarded : ndarray (R, T)
        Particles zeroed by the turn-sign guard.
    """

    mean: F64
    cov: F64
    mode_p: F64
    submode_p: F64
    neff: F64
    resampled: NDArray[np.bool_]
    af: F64
    weave_detected: NDArray[np.bool_]
    n_reinit: NDArray[np.int64]
    n_guarded: NDArray[np.int64]

    @property
    def F(self) -> F64:
        """The weave fraction F(k)."""
        return self.mode_p[..., W]


def _resample_rows(w: F64, rng: np.random.Generator, scheme: str) -> NDArray[np.int64]:
    """Ancestor indices (R, N) for normalised weights ``w`` (R, N): the PF core's resampler
    (:func:`pipeline.estimate.resample.get_resampler`) row by row."""
    draw = get_resampler(scheme)
    return np.stack([draw(w[r], rng) for r in range(w.shape[0])])


def _initial_cloud(z0: F64, z1: F64, sensor, cfg: HmpfConfig, N: int, rng: np.random.Generator):
    """Particles at step 0: uniform squares ±kσ about the first fix and the two-fix velocity
    (digest 003 A2), modes and submodes uniform (§2.4), ω signed by the leaf."""
    R_ = z0.shape[0]
    p0, p1 = sensor.position(z0), sensor.position(z1)
    sp = sensor.position_sigma(z0)[:, None]
    k = cfg.init_k_sigma
    x = np.zeros((R_, N, 5))
    x[..., 0:2] = p0[:, None, :] + k * sp[..., None] * rng.uniform(-1, 1, (R_, N, 2))
    v0 = (p1 - p0) / cfg.dt_s
    x[..., 2:4] = v0[:, None, :] + k * np.sqrt(2.0) * sp[..., None] / cfg.dt_s * rng.uniform(-1, 1, (R_, N, 2))
    m = rng.integers(0, 4, (R_, N))
    sm = rng.integers(0, 4, (R_, N))
    leaf = leaf_of(m, sm)
    lo, hi = cfg.omega_init_radps
    x[..., 4] = LEAF_SIGN[leaf] * rng.uniform(lo, hi, (R_, N))
    return x, m, sm, leaf


@njit(cache=True)
def _switch_p(x, x_max, method_min, p1, p2, n, cap):
    x = abs(x)
    if method_min:
        return min((x / x_max) ** n, cap)
    return p1 if x < x_max else p2


@njit(cache=True)
def _k_modes(m, sm, leaf, delta, theta, omega, u, Pi, leaf_sign, enter, method_min, p1, p2, n_exp, cap,
             delta_max, theta_max, w_lo, w_hi, segment):
    """Steps 1–3 of the module docstring per particle, in place: mode, submode (with the A3/A4
    entry rules), leaf and the turn rate this step uses. ``u`` (4, R, N) uniforms from the
    caller's generator. Returns the per-particle 'counters restart' flags: the leaf changed
    (``segment`` False, digest A4) or its segment kind did (``segment`` True: straight ↔ curve
    or the turn's sign, thesis (2.3)/(2.4))."""
    R_, N = m.shape
    changed = np.zeros((R_, N), dtype=np.bool_)
    for r in range(R_):
        for i in range(N):
            mo = m[r, i]
            c = 0.0
            mn = 3
            for j in range(4):
                c += Pi[mo, j]
                if u[0, r, i] < c:
                    mn = j
                    break
            s_ = sm[r, i]
            if mn == 3 and mo != 3:
                if enter == 1:
                    s_ = min(int(u[3, r, i] * 4.0), 3)
                elif enter == 2:
                    s_ = 2 * min(int(u[3, r, i] * 2.0), 1)
                if not segment:
                    delta[r, i] = 0.0
                    theta[r, i] = 0.0
            if mn == 3:
                if s_ == 0 or s_ == 2:
                    p = _switch_p(theta[r, i], theta_max, method_min, p1, p2, n_exp, cap)
                else:
                    p = _switch_p(delta[r, i], delta_max, method_min, p1, p2, n_exp, cap)
                if u[1, r, i] < p:
                    s_ = (s_ + 1) % 4
            lf = mn if mn < 3 else 3 + s_
            ch = lf != leaf[r, i]
            sg = leaf_sign[lf]
            w0 = omega[r, i]
            if sg != 0:
                if ch or np.sign(w0) != sg:
                    omega[r, i] = sg * (w_lo + (w_hi - w_lo) * u[2, r, i])
            else:
                omega[r, i] = 0.0
            m[r, i] = mn
            sm[r, i] = s_
            changed[r, i] = (sg != leaf_sign[leaf[r, i]]) if segment else ch
            leaf[r, i] = lf
    return changed


@njit(cache=True)
def _k_noise(x, pos_old, omega_used, leaf, changed, delta, theta, g, leaf_sign, dt, s_at, s_an, s_axy, s_alpha):
    """Steps 3–4 after the deterministic turn step: CM (along/cross-track) or ACT (N/E) noise,
    the ω random walk, the δ/θ counters, and the turn-sign guard. ``g`` (3, R, N) standard
    normals. Returns the guard mask."""
    R_, N = leaf.shape
    guard = np.zeros((R_, N), dtype=np.bool_)
    h = 0.5 * dt * dt
    for r in range(R_):
        for i in range(N):
            sg = leaf_sign[leaf[r, i]]
            if sg != 0:
                an = s_axy * g[0, r, i]
                ae = s_axy * g[1, r, i]
            else:
                vn, ve = x[r, i, 2], x[r, i, 3]
                sp = np.sqrt(vn * vn + ve * ve)
                if sp > 1e-9:
                    tn, te = vn / sp, ve / sp
                else:
                    tn, te = 1.0, 0.0
                aT, aN = s_at * g[0, r, i], s_an * g[1, r, i]
                an = aT * tn - aN * te   # n = (−t_E, t_N), the right-hand normal in NED
                ae = aT * te + aN * tn
            x[r, i, 0] += h * an
            x[r, i, 1] += h * ae
            x[r, i, 2] += dt * an
            x[r, i, 3] += dt * ae
            if sg != 0:
                x[r, i, 4] = omega_used[r, i] + s_alpha * g[2, r, i]
                guard[r, i] = np.sign(x[r, i, 4]) != sg
            else:
                x[r, i, 4] = 0.0
            if changed[r, i]:
                delta[r, i] = 0.0
                theta[r, i] = 0.0
            else:
                dn, de = x[r, i, 0] - pos_old[r, i, 0], x[r, i, 1] - pos_old[r, i, 1]
                delta[r, i] += np.sqrt(dn * dn + de * de)
                theta[r, i] += omega_used[r, i] * dt
    return guard


@njit(cache=True)
def _k_stats(x, w, m, sm, mean, cov, mode_p, submode_p):
    """Weighted mean and covariance of x (R, N, 5) and the mode/submode fractions, into the outputs."""
    R_, N, n = x.shape
    for r in range(R_):
        mu = np.zeros(n)
        mp = np.zeros(4)
        sp = np.zeros(4)
        for i in range(N):
            wi = w[r, i]
            for a in range(n):
                mu[a] += wi * x[r, i, a]
            mp[m[r, i]] += wi
            if m[r, i] == 3:
                sp[sm[r, i]] += wi
        C = np.zeros((n, n))
        for i in range(N):
            wi = w[r, i]
            for a in range(n):
                da = x[r, i, a] - mu[a]
                for b in range(a, n):
                    C[a, b] += wi * da * (x[r, i, b] - mu[b])
        for a in range(n):
            for b in range(a + 1, n):
                C[b, a] = C[a, b]
        # element copies: a row assignment (mean[r] = mu, cov[r] = C) pulls numba's shape-mismatch
        # error formatting into the kernel, most of its ~4 s cold compile
        for a in range(n):
            mean[r, a] = mu[a]
            for b in range(n):
                cov[r, a, b] = C[a, b]
        for j in range(4):
            mode_p[r, j] = mp[j]
            submode_p[r, j] = sp[j]


def _fractions(w, m, sm, mode_p, submode_p):
    for j in range(4):
        mode_p[:, j] = np.sum(w * (m == j), axis=1)
        submode_p[:, j] = np.sum(w * ((m == W) & (sm == j)), axis=1)


def hmpf_filter(z: ArrayLike, sensor, cfg: HmpfConfig, rng: np.random.Generator) -> HmpfTrack:
    """Run the weave classifier over measurements ``z`` (R, T, M) (or (T, M): one run).

    Parameters
    ----------
    z : array_like
        GPS ``[N, E]`` (M = 2) or radar ``[r, b, d]`` (M = 3) per step, T = ``cfg.dt_s`` apart; a
        row with a NaN is a predict-only step (the first two rows must be finite: they seed the
        cloud).
    sensor : GpsSensor or RadarSensor
        ``log_likelihood(z (R, M), x (R, N, 5)) -> (R, N)``, ``position(z)``, ``position_sigma(z)``.
    cfg : HmpfConfig
    rng : numpy.random.Generator
        The one source of randomness (the per-particle kernels take their uniforms and normals
        from it).

    Returns
    -------
    HmpfTrack
    """
    z = np.asarray(z, dtype=np.float64)
    if z.ndim == 2:
        z = z[None]
    R_, T, _ = z.shape
    if T < 2 or not np.all(np.isfinite(z[:, :2])):
        raise ValueError("hmpf: need at least two steps and finite first two measurements to seed the particles")
    N = int(cfg.n_particles)
    dt = float(cfg.dt_s)
    Pi_m = check_stochastic(cfg.pi_m, f"{_h}.pi_m")
    lo, hi = cfg.omega_init_radps
    if cfg.method not in ("if_else", "min"):
        raise ValueError(f"{_h}.method: {cfg.method!r} is not if_else or min")
    enter = {"keep": 0, "uniform": 1, "curve": 2}[cfg.enter_submode]
    sign_tab = LEAF_SIGN.astype(np.int64)

    x, m, sm, leaf = _initial_cloud(z[:, 0], z[:, 1], sensor, cfg, N, rng)
    m, sm, leaf = m.astype(np.int64), sm.astype(np.int64), leaf.astype(np.int64)
    delta = np.zeros((R_, N))
    theta = np.zeros((R_, N))
    logw = np.full((R_, N), -np.log(N))

    mean = np.empty((R_, T, 5))
    cov = np.empty((R_, T, 5, 5))
    mode_p = np.empty((R_, T, 4))
    submode_p = np.empty((R_, T, 4))
    neff = np.empty((R_, T))
    resampled = np.zeros((R_, T), dtype=bool)
    n_reinit = np.zeros(R_, dtype=np.int64)
    n_guarded = np.zeros((R_, T), dtype=np.int64)

    w = np.full((R_, N), 1.0 / N)
    m_, c_, mp_, sp_ = (np.empty((R_, 5)), np.empty((R_, 5, 5)), np.empty((R_, 4)), np.empty((R_, 4)))
    _k_stats(x, w, m, sm, m_, c_, mp_, sp_)
    mean[:, 0], cov[:, 0], mode_p[:, 0], submode_p[:, 0] = m_, c_, mp_, sp_
    neff[:, 0] = N
    for k in range(1, T):
        # 1–3. mode, submode, leaf and this step's ω (kernel), then the exact turn step
        omega = np.ascontiguousarray(x[..., 4])
        changed = _k_modes(m, sm, leaf, delta, theta, omega, rng.random((4, R_, N)), Pi_m, sign_tab, enter,
                           cfg.method == "min", cfg.p1, cfg.p2, float(cfg.min_exponent), cfg.min_cap,
                           cfg.delta_max_m, cfg.theta_max_rad, lo, hi, cfg.counters == "segment")
        x[..., 4] = omega
        pos_old = x[..., 0:2].copy()
        x = ct_transition(x, dt)
        # CM (seed 003 §4.2.2): Q = σ_T² t tᵀ + σ_N² n nᵀ about t = v/|v|; ACT keeps its noise in
        # N/E ("a turn can be entered in any direction"); then δ, θ and the turn-sign guard
        guard = _k_noise(x, pos_old, omega, leaf, changed, delta, theta, rng.standard_normal((3, R_, N)), sign_tab,
                         dt, cfg.sigma_at_mps2, cfg.sigma_an_mps2, cfg.sigma_axy_mps2, cfg.sigma_alpha_radps)
        n_guarded[:, k] = guard.sum(axis=1)
        # 5. weights
        zk = z[:, k]
        ok = np.all(np.isfinite(zk), axis=-1)
        ll = np.where(ok[:, None], sensor.log_likelihood(np.where(ok[:, None], zk, 0.0), x), 0.0)
        # a likelihood that underflows in linear terms (p(z|x) < the smallest normal double) is a zero
        # weight, so a measurement no particle can explain re-initialises instead of being followed
        logw = np.where(guard | (ll < _LOG_TINY), -np.inf, logw + ll)
        top = logw.max(axis=1, keepdims=True)
        dead = ~np.isfinite(top[:, 0])
        if dead.any():  # every weight zero: re-initialise around z_k (positions), modes uniform
            n_reinit[dead] += 1
            for r in np.flatnonzero(dead):
                zr = zk[r] if ok[r] else z[r, max(j for j in range(k) if np.all(np.isfinite(z[r, j])))]
                p = sensor.position(zr)
                spr = float(sensor.position_sigma(zr))
                x[r, :, 0:2] = p + cfg.init_k_sigma * spr * rng.uniform(-1, 1, (N, 2))
                m[r] = rng.integers(0, 4, N)
                sm[r] = rng.integers(0, 4, N)
                leaf[r] = leaf_of(m[r], sm[r])
                x[r, :, 4] = LEAF_SIGN[leaf[r]] * rng.uniform(lo, hi, N)
                delta[r] = theta[r] = 0.0
                logw[r] = -np.log(N)
            top = logw.max(axis=1, keepdims=True)
        w = np.exp(logw - top)
        w /= w.sum(axis=1, keepdims=True)
        neff[:, k] = 1.0 / np.sum(w * w, axis=1)
        _k_stats(x, w, m, sm, m_, c_, mp_, sp_)   # the estimate before resampling (digest A10)
        mean[:, k], cov[:, k] = m_, c_
        # 6. resample (every step by default) and report the fractions after it
        do = neff[:, k] < cfg.ess_fraction * N if cfg.ess_fraction < 1.0 else np.ones(R_, dtype=bool)
        if do.any():
            idx = _resample_rows(w[do], rng, cfg.resample)
            sel = np.flatnonzero(do)[:, None]
            x[do] = x[sel, idx]
            m[do], sm[do], leaf[do] = m[sel, idx], sm[sel, idx], leaf[sel, idx]
            delta[do], theta[do] = delta[sel, idx], theta[sel, idx]
            w[do] = 1.0 / N
            resampled[do, k] = True
        logw = np.log(np.maximum(w, 1e-300))
        _fractions(w, m, sm, mode_p[:, k], submode_p[:, k])
    # the detector runs over the filter's outputs F(1..T) (thesis §2.4 algorithm: "Output ... for
    # all time steps k = 1, 2, ..., T"), leaving the start-up steps out of its average (§6.3;
    # detector()): index 0 is the initial cloud, spread uniformly over the modes (F = 1/4 by
    # construction, no measurement weighed), so it enters neither the average nor the 25
    # start-up steps; its AF is NaN, never flagged
    af = np.full((R_, T), np.nan)
    flag = np.zeros((R_, T), dtype=bool)
    af[:, 1:], flag[:, 1:] = detector(mode_p[:, 1:, W], cfg.detector_window, cfg.tau, cfg.startup_steps)
    return HmpfTrack(mean=mean, cov=cov, mode_p=mode_p, submode_p=submode_p, neff=neff, resampled=resampled,
                     af=af, weave_detected=flag, n_reinit=n_reinit, n_guarded=n_guarded)
