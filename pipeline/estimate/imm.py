"""Interacting multiple model filter whose modes are EKFs or EKF banks (seed 002 §6, D3–D5).

Standard IMM (Watson & Blair; Daugherty 2018 eqs. 2.19–2.24) with ``p_ij = P(i → j)``:

.. math::

    \\bar c_j = \\sum_i p_{ij}\\mu_{k-1}(i),\\quad \\mu(i|j) = p_{ij}\\mu_{k-1}(i)/\\bar c_j,\\quad
    \\mu_k(j) = \\Lambda_j \\bar c_j / \\textstyle\\sum_i \\Lambda_i \\bar c_i

Every mode is a set of Gaussian components (:class:`~pipeline.estimate.bank.Components`):
one for an EKF, N for a bank. The mixed input of component ``c`` of mode ``j`` (3.41–3.44,
⚠-corrected) is

.. math::

    X^{0j,c} = \\mu(j|j) X^{j,c} + \\sum_{i\\ne j}\\mu(i|j)\\bar X^{i\\to j,c},\\qquad
    P^{0j,c} = \\sum_i \\mu(i|j)\\big[P^{i\\to j,c} + (X^{i\\to j,c} - X^{0j,c})(\\cdot)^T\\big]

where a source mode ``i ≠ j`` enters with its combined moments ``X̄ⁱ, P̄ⁱ`` embedded in mode
``j``'s state (D3, by state name): shared states from ``i``; states ``i`` lacks (the CT bank's ω
seen from CV) from component ``c``'s own mean and variance block, with zero cross-covariance;
states ``j`` lacks are dropped. Angles mix by wrapped deviations (:func:`~pipeline.estimate.bank.combine`). A bank keeps its weights ``W_n``
through mixing (D4) and its likelihood is ``Λ = Σ_n W_{k−1}ⁿ N(ỹ_n; 0, S_n)``.

Mixing runs every ``mix_every`` steps (the thesis's rate ``T_d``: ``mix_every =
round(1/(T_d T))``, 20 Hz at T = 0.05 s is every step); between mixes the modes run
separately and μ is still updated every step with ``c̄ = μ_{k−1}`` (D5); μ₀ uniform (D5:
[0.5, 0.5]). There is no NIS gate in the IMM (a per-mode gate would make the Λ_j
incomparable). The output combines the modes over ``output_names`` (default the CPPV state);
a state a mode lacks comes from the first mode that has every output state (ω from the CT
bank, D3).

Public API (stable)
-------------------
``ImmMode(name, model, prior: Components)``;
``bank_mode(settings, beta0 (R,), sigma_rad, vo0=None, name="ct", engine="numba") -> ImmMode``;
``cv_mode_from(mode, cv_model=CvModel(), name="cv") -> ImmMode`` (the bank's combined moments
without ω, §4.2); ``ekf_mode(name, model, mean (R, n), cov (R, n, n)) -> ImmMode``;
``switching_matrix(delta, K=2)``; ``mode_metadata(mode)``; ``mix_interval(T_d_hz, dt_s)``;
``mixing_probabilities(mu (R, K), Pi) -> (cbar (R, K), mu_ij (R, K, K))``;
``embed(mean, cov, names_src, names_dst, fill_mean, fill_cov)``;
``mix_components(modes, comps, mu_ij) -> list[Components]`` (one mixing stage);
``run_imm(modes, transition, t_s, z_rad, sigma_rad, ownship=None, *, mix_every=None, mu0=None,
output_names=CPPV_STATE, store_cov=True, store_weights=False, algebra="numba") -> ImmTrack`` with
``transition`` a (K, K) matrix or ``(T_d_hz, delta)``.

A saved HMM's ``transmat`` enters through :func:`pipeline.estimate.markov.hmm_to_step`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import markov
from .bank import (BankSettings, Components, CvModel, angle_index, bank_prior, check_inputs,
                   combine, components_step, first_bearing, logsumexp, model_for, settings_for)
from .models import CPPV_STATE, wrap_angle

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class ImmMode:
    """One IMM mode: a transition model (:class:`~pipeline.estimate.bank.CppvModel`,
    ``MpcModel`` or ``CvModel``) and its initial components (R, C, n)."""

    name: str
    model: Any
    prior: Components

    @property
    def names(self) -> tuple[str, ...]:
        return self.model.names


def bank_mode(settings: BankSettings | str, beta0: ArrayLike, sigma_rad: float,
              vo0: ArrayLike | None = None, name: str = "ct", engine: str = "numba") -> ImmMode:
    """A CT bank mode from its settings and each run's first bearing ``beta0`` (R,)."""
    s = settings_for(settings)
    return ImmMode(name, model_for(s, engine), bank_prior(s, beta0, sigma_rad, vo0))


def ekf_mode(name: str, model, mean: ArrayLike, cov: ArrayLike) -> ImmMode:
    """A single-EKF mode from its prior ``mean`` (R, n) and ``cov`` (R, n, n)."""
    m = np.asarray(mean, dtype=np.float64)
    P = np.asarray(cov, dtype=np.float64)
    if m.ndim == 1:
        m, P = m[None], P[None]
    R_ = m.shape[0]
    return ImmMode(name, model, Components(m[:, None].copy(), P[:, None].copy(), np.zeros((R_, 1)),
                                           np.zeros((R_, 1), dtype=bool)))


def cv_mode_from(mode: ImmMode, cv_model: CvModel | None = None, name: str = "cv") -> ImmMode:
    """The CV EKF initialised from a bank mode's combined moments, dropping the states CV
    lacks (ω; digest §5, §4.2)."""
    cv_model = CvModel() if cv_model is None else cv_model
    p = mode.prior
    m, P = combine(p.mean, p.cov, p.logw, angle_index(mode.names))
    idx = [mode.names.index(n) for n in cv_model.names]
    return ekf_mode(name, cv_model, m[:, idx], P[:, idx][:, :, idx])


def mode_metadata(mode: ImmMode) -> dict[str, Any]:
    """A mode's settings for the output metadata (a bank's :meth:`BankSettings.metadata`, a
    CV model's noise parameters)."""
    model = mode.model
    s = getattr(model, "settings", None)
    out: dict[str, Any] = {"coords": model.coords, "n_components": int(mode.prior.mean.shape[1])}
    if s is not None:
        out.update(s.metadata())
    else:
        out.update({k: v for k, v in dataclasses.asdict(model).items() if k != "names"})
    return out


def switching_matrix(delta: float, K: int = 2) -> F64:
    """``p = [[1−δ, δ], [δ, 1−δ]]`` (K = 2; K > 2: δ spread evenly over the other modes)."""
    if not (0 <= delta <= 1):
        raise ValueError(f"switching_matrix: delta must lie in [0, 1], got {delta}")
    P = np.full((K, K), delta / max(K - 1, 1))
    np.fill_diagonal(P, 1 - delta if K > 1 else 1.0)
    return P


def mix_interval(T_d_hz: float, dt_s: float) -> int:
    """Steps between mixes, ``round(1/(T_d T))`` ≥ 1 (20 Hz at 0.05 s: 1; 1 Hz: 20)."""
    if not (T_d_hz > 0 and dt_s > 0):
        raise ValueError(f"mix_interval: need T_d_hz > 0 and dt_s > 0, got {T_d_hz}, {dt_s}")
    return max(1, int(round(1.0 / (T_d_hz * dt_s))))


def mixing_probabilities(mu: ArrayLike, Pi: ArrayLike) -> tuple[F64, F64]:
    """``c̄_j = Σ_i p_ij μ_i`` (R, K) and ``μ(i|j) = p_ij μ_i / c̄_j`` (R, K_i, K_j)."""
    mu = np.asarray(mu, dtype=np.float64)
    Pi = np.asarray(Pi, dtype=np.float64)
    joint = mu[..., :, None] * Pi  # (R, i, j)
    cbar = joint.sum(axis=-2)
    with np.errstate(invalid="ignore", divide="ignore"):
        mij = np.where(cbar[..., None, :] > 0, joint / cbar[..., None, :], 0.0)
    return cbar, mij


def embed(mean: F64, cov: F64, names_src: Sequence[str], names_dst: Sequence[str],
          fill_mean: F64, fill_cov: F64) -> tuple[F64, F64]:
    """Carry moments from the state ``names_src`` to ``names_dst`` (D3): shared states from
    the source, the others from ``fill_*`` (same shapes as the destination) with zero
    cross-covariance to the shared ones."""
    shared_d = [i for i, n in enumerate(names_dst) if n in names_src]
    shared_s = [names_src.index(names_dst[i]) for i in shared_d]
    miss = [i for i, n in enumerate(names_dst) if n not in names_src]
    m = np.array(np.broadcast_to(fill_mean, np.broadcast_shapes(fill_mean.shape, mean.shape[:-1] + (len(names_dst),))))
    m[..., shared_d] = mean[..., shared_s]
    P = np.zeros(m.shape + (len(names_dst),))
    di, dj = np.ix_(shared_d, shared_d)
    si, sj = np.ix_(shared_s, shared_s)
    P[..., di, dj] = cov[..., si, sj]
    if miss:
        fc = np.broadcast_to(fill_cov, P.shape)
        ii, jj = np.ix_(miss, miss)
        P[..., ii, jj] = fc[..., ii, jj]
    return m, P


@dataclass(frozen=True)
class ImmTrack:
    """An IMM run over runs × time.

    Attributes
    ----------
    t_s : (T,)
    state_names : tuple of str (the output state)
    mean, cov : (R, T, n), (R, T, n, n) or None
        The combined output.
    mode_names : tuple of str
    mode_p : (R, T, K)
        Posterior mode probabilities μ_k.
    mode_mean : tuple of (R, T, n_j)
        Each mode's combined estimate in its own state.
    loglik : (R, T)
        ``log Σ_j c̄_j Λ_j`` (0 where no bearing was used).
    nis : (R, T)
        NIS of the IMM's predicted bearing (a moment-matched mixture over modes and components).
    measured : (R, T) bool
    mixed : (T,) bool
        Steps whose predict started from a mixing stage.
    diverged : tuple of (R, C_j) bool
    weights : tuple of (R, T, C_j) or None
    metadata : dict
    """

    t_s: F64
    state_names: tuple[str, ...]
    mean: F64
    cov: F64 | None
    mode_names: tuple[str, ...]
    mode_p: F64
    mode_mean: tuple[F64, ...]
    loglik: F64
    nis: F64
    measured: NDArray[np.bool_]
    mixed: NDArray[np.bool_]
    diverged: tuple[NDArray[np.bool_], ...]
    weights: tuple[F64, ...] | None = None
    metadata: dict = field(default_factory=dict)


def mix_components(modes: Sequence[ImmMode], comps: Sequence[Components], mij: F64) -> list[Components]:
    """Mixed inputs of every component of every mode (module docstring).

    A mode ``j`` with no predicted probability in a run (``c̄_j = 0``, so ``μ(·|j)`` is all
    zero there; e.g. a one-hot ``mu0`` with an identity transmat) keeps its own unmixed
    components in that run: its μ_j stays 0, so its input has no weight in the output.
    """
    K = len(modes)
    moments = [combine(c.mean, c.cov, c.logw, angle_index(m.names)) for m, c in zip(modes, comps)]
    out = []
    for j, (mj, cj) in enumerate(zip(modes, comps)):
        R_, C, n = cj.mean.shape
        src_m = np.empty((R_, C, K, n))
        src_P = np.empty((R_, C, K, n, n))
        for i in range(K):
            if i == j:
                src_m[:, :, i], src_P[:, :, i] = cj.mean, cj.cov
            else:
                mi, Pi_ = moments[i]
                src_m[:, :, i], src_P[:, :, i] = embed(mi[:, None], Pi_[:, None], modes[i].names, mj.names,
                                                       cj.mean, cj.cov)
        with np.errstate(divide="ignore"):
            lw = np.log(np.broadcast_to(mij[:, None, :, j], (R_, C, K)))
        m0, P0 = combine(src_m, src_P, lw, angle_index(mj.names))
        # c̄_j = 0: mixing with all-zero weights would zero every mean and covariance (and the
        # NaN loglik would then poison μ); keep the mode's own components instead.
        dead = ~(mij[:, :, j].sum(axis=1) > 0)  # (R,)
        if dead.any():
            m0 = np.where(dead[:, None, None], cj.mean, m0)
            P0 = np.where(dead[:, None, None, None], cj.cov, P0)
        if cj.diverged.any():  # a frozen component stays frozen
            m0 = np.where(cj.diverged[..., None], cj.mean, m0)
            P0 = np.where(cj.diverged[..., None, None], cj.cov, P0)
        out.append(Components(m0, P0, cj.logw, cj.diverged))
    return out


def _check_mu0(mu0: ArrayLike, R: int, K: int) -> F64:
    """Initial mode probabilities ``mu0`` (K,) or (R, K) as a normalised (R, K) array.

    Raises
    ------
    ValueError
        A wrong shape, a non-finite or negative entry, or a run whose entries sum to 0.
    """
    m = np.asarray(mu0, dtype=np.float64)
    if m.shape not in ((K,), (R, K)):
        raise ValueError(f"run_imm: mu0 must have shape ({K},) or ({R}, {K}), got {m.shape}")
    if not np.isfinite(m).all() or (m < 0).any():
        raise ValueError(f"run_imm: mu0 must be finite and >= 0, got {m.tolist()}")
    m = np.array(np.broadcast_to(m, (R, K)))
    tot = m.sum(axis=1, keepdims=True)
    if not (tot > 0).all():
        raise ValueError(f"run_imm: mu0 must have a positive sum (run {int(np.argmin(tot[:, 0]))} sums to 0)")
    return m / tot


def run_imm(modes: Sequence[ImmMode], transition: ArrayLike | tuple[float, float], t_s: ArrayLike,
            z_rad: ArrayLike, sigma_rad: float, ownship: ArrayLike | None = None, *,
            mix_every: int | None = None, mu0: ArrayLike | None = None,
            output_names: Sequence[str] = CPPV_STATE, store_cov: bool = True,
            store_weights: bool = False, algebra: str = "numba") -> ImmTrack:
    """Run the IMM over runs × time (module docstring).

    Parameters
    ----------
    modes : sequence of ImmMode
        Their priors share the run batch R and start at ``t_s[0]`` (no update there).
    transition : array_like (K, K) or tuple ``(T_d_hz, delta)``
        A row-stochastic ``p_ij`` per step (e.g. :func:`~pipeline.estimate.markov.hmm_to_step`
        of a saved ``transmat``), or the thesis's mixing rate and δ (2 modes).
    t_s, z_rad, sigma_rad, ownship :
        As :func:`~pipeline.estimate.bank.run_bank`.
    mix_every : int, optional
        Steps between mixes (default: from ``T_d`` and the median step, else 1).
    mu0 : array_like (K,) or (R, K), optional
        Initial mode probabilities (default uniform): finite, ≥ 0, with a positive sum per run;
        normalised to sum 1. A mode may start at 0 (:func:`mix_components`).
    output_names : sequence of str
        The combined output's state.
    store_cov, store_weights : bool
        Keep the output covariances (R, T, n, n) and every mode's weights (R, T, C_j).
    algebra : {"numba", "ekf"}
        As :func:`~pipeline.estimate.bank.components_step`.
    """
    K = len(modes)
    if K < 1:
        raise ValueError("run_imm: need at least one mode")
    t, z, vo = check_inputs(t_s, z_rad, ownship, who="run_imm")
    R_, T = z.shape
    first_bearing(z, who="run_imm")
    meta: dict[str, Any] = {}
    if isinstance(transition, tuple):
        T_d, delta = float(transition[0]), float(transition[1])
        Pi = switching_matrix(delta, K)
        dtn = float(np.median(np.diff(t))) if T > 1 else 1.0
        every = mix_interval(T_d, dtn) if mix_every is None else int(mix_every)
        meta.update({"T_d_hz": T_d, "delta": delta})
    else:
        Pi = markov.check_stochastic(transition, "IMM transition matrix")
        every = 1 if mix_every is None else int(mix_every)
    if Pi.shape != (K, K):
        raise ValueError(f"run_imm: transition matrix shaped {Pi.shape} for {K} modes")
    if every < 1:
        raise ValueError(f"run_imm: mix_every must be >= 1, got {every}")
    for a in range(K):
        for b_ in range(a + 1, K):
            if not set(modes[a].names) & set(modes[b_].names):
                raise ValueError(f"run_imm: modes {modes[a].name!r} and {modes[b_].name!r} share no state, so they "
                                 "cannot mix (D3 embeds by state name; use CPPV-coordinate modes)")
    for m in modes:
        if m.prior.mean.shape[0] != R_:
            raise ValueError(f"run_imm: mode {m.name!r} has {m.prior.mean.shape[0]} runs, the bearings {R_}")
    mu = np.full((R_, K), 1.0 / K) if mu0 is None else _check_mu0(mu0, R_, K)
    out_names = tuple(output_names)
    donor = next((i for i, m in enumerate(modes) if set(out_names) <= set(m.names)), None)
    if donor is None:
        raise ValueError(f"run_imm: no mode carries every output state {out_names}")
    comps = [m.prior for m in modes]
    n_out = len(out_names)
    mean = np.empty((T, R_, n_out))
    cov = np.empty((T, R_, n_out, n_out)) if store_cov else None
    mode_p = np.empty((T, R_, K))
    mode_mean = [np.empty((T, R_, len(m.names))) for m in modes]
    W = [np.empty((T, R_, m.prior.mean.shape[1])) for m in modes] if store_weights else None
    ll, nis = np.zeros((T, R_)), np.full((T, R_), np.nan)
    measured = np.zeros((T, R_), dtype=bool)
    mixed = np.zeros(T, dtype=bool)
    out_angles = angle_index(out_names)
    for k in range(T):
        if k:
            dt = t[k] - t[k - 1]
            if (k - 1) % every == 0:
                cbar, mij = mixing_probabilities(mu, Pi)
                comps = mix_components(modes, comps, mij)
                mixed[k] = True
            else:
                cbar = mu  # D5: no mixing, c̄ = μ_{k−1}
            v = 0.5 * (vo[:, k - 1] + vo[:, k])
            lls, yms, Sms = [], [], []
            for j, m in enumerate(modes):
                comps[j], st = components_step(m.model, comps[j], dt, v, z[:, k], sigma_rad, algebra=algebra)
                lls.append(st.loglik)
                yms.append(st.ymix)
                Sms.append(st.Smix)
                use = st.measured
            L = np.stack(lls, axis=1)  # (R, K); 0 where not measured
            with np.errstate(divide="ignore"):
                lc = np.log(cbar) + L
            norm = logsumexp(lc)
            mu = np.exp(lc - norm[:, None])
            ll[k] = np.where(use, norm, 0.0)
            ym = np.einsum("rk,rk->r", cbar, np.stack(yms, 1))
            Sm = np.einsum("rk,rk->r", cbar, np.stack(Sms, 1) + (np.stack(yms, 1) - ym[:, None]) ** 2)
            with np.errstate(invalid="ignore", divide="ignore"):
                nis[k] = np.where(use, ym ** 2 / Sm, np.nan)
            measured[k] = use
        mode_p[k] = mu
        moms = [combine(c.mean, c.cov, c.logw, angle_index(m.names)) for m, c in zip(modes, comps)]
        for j in range(K):
            mm = moms[j][0].copy()
            for a in angle_index(modes[j].names):
                mm[..., a] = wrap_angle(mm[..., a])
            mode_mean[j][k] = mm
            if W is not None:
                W[j][k] = np.exp(comps[j].logw)
        dm, dP = moms[donor]
        dm, dP = embed(dm, dP, modes[donor].names, out_names, dm, dP)
        em = np.empty((R_, K, n_out))
        eP = np.empty((R_, K, n_out, n_out))
        for j in range(K):
            em[:, j], eP[:, j] = embed(moms[j][0], moms[j][1], modes[j].names, out_names, dm, dP)
        with np.errstate(divide="ignore"):
            m_, P_ = combine(em, eP if store_cov else None, np.log(mu), out_angles)
        for a in out_angles:
            m_[..., a] = wrap_angle(m_[..., a])
        mean[k] = m_
        if store_cov:
            cov[k] = P_

    def rt(a):
        return None if a is None else np.swapaxes(a, 0, 1)

    meta.update({"transition": Pi.tolist(), "mix_every": every,
                 "modes": [m.name for m in modes], "output_names": list(out_names),
                 "between_mixes": "mu updated every step with cbar = mu_{k-1} (D5)",
                 "bank_weights": "kept through mixing (D4)"})
    meta["mu0"] = (np.full(K, 1.0 / K) if mu0 is None else np.asarray(mu0, dtype=np.float64)).tolist()
    meta["mode_models"] = {m.name: mode_metadata(m) for m in modes}
    return ImmTrack(t, out_names, rt(mean), rt(cov), tuple(m.name for m in modes), rt(mode_p),
                    tuple(rt(a) for a in mode_mean), rt(ll), rt(nis), rt(measured), mixed,
                    tuple(c.diverged.copy() for c in comps),
                    None if W is None else tuple(rt(a) for a in W), meta)
