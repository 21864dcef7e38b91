"""Gaussian Mixture Regression of velocity/acceleration increments (seed 000 §3.6, §7, §13.3).

General GMR (3.23–3.26) for input block ``k`` and output block ``u``:

.. math::
    \\hat\\xi_{u,m} = \\mu_{u,m} + \\Sigma_{uk,m}\\Sigma_{k,m}^{-1}(\\xi_k - \\mu_{k,m}), \\quad
    \\hat\\Sigma_{u,m} = \\Sigma_{u,m} - \\Sigma_{uk,m}\\Sigma_{k,m}^{-1}\\Sigma_{ku,m}

    \\beta_m = \\frac{p(\\xi_k | m)}{\\sum_i p(\\xi_k | i)}, \\quad
    \\hat\\xi_u = \\sum_m \\beta_m \\hat\\xi_{u,m}, \\quad \\hat\\Sigma_u = \\sum_m \\beta_m^2 \\hat\\Sigma_{u,m}

As used in the thesis (3.28), ``M = 1``: the Gaussian of the current Viterbi state of the
classified model, input the normalised position increment ``r_n``, outputs the normalised
velocity and acceleration increments. De-normalisation follows the corrected §13.3:
``Δv = v̂_n (v_max − v_min) + v_min``, ``â = Δv / dt``; likewise ``Δa`` and ``ĵ = Δa / dt``.
The outlier gate (§8) drops an estimate whose per-axis change from the previous accepted one
exceeds 15 m/s² per step.

**Time alignment** (``align``). The observation stamped ``t_k`` is ``x_k − x_{k−1}``, so
``Δv/dt`` is the *mean* acceleration over ``[t_{k−1}, t_k]``, i.e. ``a(t_{k−½})`` to second
order: as printed (``"interval"``) the estimate lags the current acceleration by half a sample.
The EKF+HMM uses ``â_HMM`` as the acceleration *at* ``t_k`` (``a_{k+1} = â + dt ĵ``, 4.2–4.3),
so ``"sample"`` moves it there with the model's own jerk, ``â_k = Δv̂/dt + (dt/2)·ĵ`` (exact for
piecewise-constant jerk); ``ĵ`` is unchanged. Neither uses data after ``t_k``.

**Inputs** (``inputs``). ``"pos"`` is (3.28): only ``r_n`` is conditioned on. ``"pos_vel"``
conditions on the position *and* velocity increments (the EKF state carries both), so ``Δv``
is the observed one and the regression supplies only ``Δa`` (hence ``ĵ`` and the alignment
term); this uses velocity information that a position-only finite difference does not have.
``"pos_fd"`` uses exactly the information of the finite difference from the last three
positions: it conditions on ``r_n`` and on the position-only velocity increment
``Δv̂_k = (Δr_k − Δr_{k−1})/dt`` (normalised with the frozen velocity statistics; see
:func:`fd_velocity_increments`). ``Δv̂_k/dt`` is the second difference of the positions, i.e.
``a(t_{k−1})``; the regression supplies ``ĵ`` from the Viterbi state's Gaussian, and the
acceleration is moved to the sample time with it, ``â_k = Δv̂_k/dt + dt·ĵ`` (``"sample"``) or
to ``t_{k−½}`` with ``(dt/2)·ĵ`` (``"interval"``). The first sample of a run, which has no
``Δr_{k−1}``, gets no estimate (as the finite difference).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .features import STATE9_ACC, STATE9_POS, STATE9_VEL, MinMaxNormaliser

F64 = NDArray[np.float64]


def gmr(means: F64, covars: F64, x_in: F64, in_idx, out_idx, weights: F64 | None = None,
        ) -> tuple[F64, F64]:
    """Conditional mean and covariance of the output block given the input block.

    Parameters
    ----------
    means : ndarray, shape (M, d)
    covars : ndarray, shape (M, d, d)
    x_in : ndarray, shape (n, len(in_idx)) or (len(in_idx),)
    in_idx, out_idx : sequence of int
    weights : ndarray, shape (n, M) or (M,), optional
        Component priors; ``None`` = equal priors. ``β_m`` is ``weights·p(ξ_k|m)``
        normalised; a one-hot ``weights`` selects one component (thesis M = 1).

    Returns
    -------
    mean : ndarray, shape (n, len(out_idx))
    cov : ndarray, shape (n, len(out_idx), len(out_idx))
    """
    means = np.asarray(means, dtype=np.float64)
    covars = np.asarray(covars, dtype=np.float64)
    x = np.atleast_2d(np.asarray(x_in, dtype=np.float64))
    i, o = list(in_idx), list(out_idx)
    mu_k, mu_u = means[:, i], means[:, o]
    s_kk = covars[:, i][:, :, i]
    s_uk = covars[:, o][:, :, i]
    s_uu = covars[:, o][:, :, o]
    gain = np.linalg.solve(s_kk, np.swapaxes(s_uk, 1, 2)).swapaxes(1, 2)   # Σ_uk Σ_kk⁻¹
    diff = x[:, None, :] - mu_k[None]                                       # (n, M, k)
    cond_mean = mu_u[None] + np.einsum("mok,nmk->nmo", gain, diff)
    cond_cov = s_uu - np.einsum("mok,mjk->moj", gain, s_uk)
    # β: responsibilities of the input under each component
    chol = np.linalg.cholesky(s_kk)
    y = np.linalg.solve(chol[None], diff[..., None])[..., 0]
    logp = -0.5 * np.sum(y * y, -1) - np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), -1)
    with np.errstate(divide="ignore"):
        lw = np.log(np.ones(len(means)) if weights is None else np.asarray(weights, dtype=np.float64))
    lp = logp + np.broadcast_to(lw, logp.shape)
    lp = lp - np.max(lp, axis=1, keepdims=True)
    beta = np.exp(lp)
    beta /= beta.sum(axis=1, keepdims=True)
    mean = np.einsum("nm,nmo->no", beta, cond_mean)
    cov = np.einsum("nm,moj->noj", beta ** 2, cond_cov)
    return mean, cov


GMR_INPUTS = ("pos", "pos_vel", "pos_fd")
GMR_ALIGN = ("interval", "sample")


def fd_velocity_increments(obs: F64, normaliser: MinMaxNormaliser, dt: float) -> F64:
    """Replace the velocity block of a run's observations by its position-only estimate.

    ``Δv̂_k = (Δr_k − Δr_{k−1})/dt`` from the de-normalised position increments of consecutive
    rows (one run, time order), re-normalised with the velocity statistics; row 0 becomes NaN.
    This is the input of ``inputs="pos_fd"`` (the finite difference of the last three
    positions, expressed as a velocity increment).
    """
    obs = np.array(np.atleast_2d(obs), dtype=np.float64)
    dr = normaliser.inverse(obs[:, list(STATE9_POS)], STATE9_POS)
    dv = np.full_like(dr, np.nan)
    dv[1:] = (dr[1:] - dr[:-1]) / dt
    obs[:, list(STATE9_VEL)] = (dv - normaliser.x_min[list(STATE9_VEL)]) / normaliser.span[list(STATE9_VEL)]
    return obs


def gmr_state9(means: F64, covars: F64, obs: F64, states, normaliser: MinMaxNormaliser,
               dt: float, *, inputs: str = "pos", align: str = "interval") -> tuple[F64, F64]:
    """HMM acceleration and jerk from single-Gaussian GMR on the current Viterbi state (3.28).

    Parameters
    ----------
    means : ndarray, shape (S, d)
        State means of the classified model (normalised ``state9`` increments).
    covars : ndarray, shape (S, d, d)
    obs : ndarray, shape (n, 9)
        Normalised observations; only the position increments are used.
    states : ndarray of int, shape (n,)
        Viterbi state per sample (the Gaussian used, M = 1).
    normaliser : MinMaxNormaliser
        The model's frozen statistics.
    dt : float
        Sample period, s.
    inputs : {"pos", "pos_vel", "pos_fd"}
        Conditioning block: position increments (thesis 3.28), position and velocity
        increments (then ``Δv`` is taken as observed), or position increments and the
        position-only velocity increment (``obs`` from :func:`fd_velocity_increments`).
    align : {"interval", "sample"}
        ``"interval"``: ``â = Δv/dt`` as printed (§13.3), centred half a sample back;
        ``"sample"``: ``â = Δv/dt + (dt/2)·ĵ``, the acceleration at the sample's own time.

    Returns
    -------
    acc : ndarray, shape (n, 3)
        ``â_HMM = Δv̂ / dt``, m/s² (NED).
    jerk : ndarray, shape (n, 3)
        ``ĵ_HMM = Δâ / dt``, m/s³ (NED).
    """
    if inputs not in GMR_INPUTS:
        raise ValueError(f"inputs must be one of {GMR_INPUTS}, got {inputs!r}")
    if align not in GMR_ALIGN:
        raise ValueError(f"align must be one of {GMR_ALIGN}, got {align!r}")
    obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
    states = np.asarray(states, dtype=np.int64)
    if states.shape != (len(obs),):
        raise ValueError(f"gmr_state9: states must have shape ({len(obs)},) like obs, got {states.shape}")
    n_states = len(means)
    if len(states) and states.max() >= n_states:
        # a state of another (larger) model: slicing means[s:s+1] would hand gmr an empty mixture
        raise ValueError(f"gmr_state9: state index {int(states.max())} out of range for a model with "
                         f"{n_states} states (negative means no state)")
    in_idx = STATE9_POS if inputs == "pos" else (*STATE9_POS, *STATE9_VEL)
    out_idx = (*STATE9_VEL, *STATE9_ACC) if inputs == "pos" else STATE9_ACC
    out = np.full((len(obs), 6), np.nan)
    ok = (states >= 0) & np.isfinite(obs).all(axis=1)
    for s in np.unique(states[ok]):
        rows = ok & (states == s)
        m, _ = gmr(means[s:s + 1], covars[s:s + 1], obs[rows][:, list(in_idx)], in_idx, out_idx)
        out[rows, 6 - len(out_idx):] = m
    if inputs != "pos":
        out[ok, :3] = obs[ok][:, list(STATE9_VEL)]
    acc = normaliser.inverse(out[:, :3], STATE9_VEL) / dt
    jerk = normaliser.inverse(out[:, 3:], STATE9_ACC) / dt
    # Δv/dt is centred at t_{k-1/2} (observed/regressed increment) or t_{k-1} (pos_fd)
    lag = (1.0 if inputs == "pos_fd" else 0.5) - (0.0 if align == "sample" else 0.5)
    if lag:
        acc = acc + lag * dt * jerk
    return acc, jerk


def gate(acc: F64, limit: float = 15.0) -> tuple[F64, NDArray[np.bool_]]:
    """Seed 000 §8 outlier gate, per axis: drop ``â_k`` when ``|â_k − â_{k−1}| > limit``.

    The comparison is with the previous raw estimate, as printed (a returning jump after an
    outlier is dropped too, but the gate can never lock out). Dropped entries become NaN (the
    EKF+HMM falls back to its CA prediction for that axis and step).

    Returns
    -------
    gated : ndarray, shape (n, 3)
    dropped : ndarray of bool, shape (n, 3)
    """
    acc = np.asarray(acc, dtype=np.float64)
    jump = np.zeros(acc.shape, dtype=bool)
    with np.errstate(invalid="ignore"):
        jump[1:] = np.abs(np.diff(acc, axis=0)) > limit
    return np.where(jump, np.nan, acc), jump
