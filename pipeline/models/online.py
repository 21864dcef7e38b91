"""Online maneuver classification: a log-space forward recursion per model, vectorised across
models and runs, with O(n_states²) work per model, run and sample (seed 000 §5).

The prefix is never re-scored: each step updates ``log α_t`` of every (run, model) pair from
``log α_{t-1}``. The sum over predecessors uses the max-shift identity

.. math:: \\operatorname{logsumexp}_i(\\ell_i + \\log a_{ij}) = m + \\log \\sum_i e^{\\ell_i - m} a_{ij},
          \\quad m = \\max_i \\ell_i

so it is one batched matrix product per step with every exponent ≤ 0 (no overflow, and a term
that underflows is below 1e-300 of the sum).

Scores, per model ``m`` (``LL_m``):

``cumulative`` (thesis-faithful)
    ``LL_m(t) = log P(O_{1:t} | λ_m)`` from t = 1 (or from an external reset).
``windowed``
    The sum of the last ``W`` predictive increments
    ``ℓ_m(τ) = log P(O_τ | O_{1:τ-1}, λ_m)`` of a forward pass whose transition matrix has a
    restart term, ``A' = (1-ε) A + ε 1 πᵀ``, so a model can re-enter its first state when a new
    maneuver begins; old evidence leaves the score after ``W`` samples.
``reset``
    The cumulative score, restarted at a change point detected online: when the windowed label
    (with ``V < -1``) disagrees with the cumulative one for ``confirm`` samples, the change
    point is the arg-min of the CUSUM ``Σ (ℓ_new − ℓ_old)`` over the buffered increments, and the
    cumulative pass is replayed from there over the buffer (a bounded one-off cost).

Confidence (Lee & Xu; seed 000 §5):

.. math:: V_j = \\log_{10} \\sum_{i \\ne j} \\exp(LL_i - LL_j)

and the label is ``c = argmax LL`` when ``V_c < -1`` (``confidence``), when ``LL_c`` is above the
one-class threshold at the same elapsed time (``oneclass``), or when both hold (``both``);
otherwise "unknown" (index ``-1``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from .hmm import LOG2PI, HMMParams, logsumexp, safe_log

F64 = NDArray[np.float64]
UNKNOWN = -1
LN10 = np.log(10.0)


@dataclass(frozen=True)
class StackedModels:
    """Several HMMs padded to common ``(S, K)`` so one einsum serves all of them.

    Padded states have ``π = 0`` and no transitions in or out; padded mixture components
    have weight 0.
    """

    log_pi: F64          # (M, S)
    trans: F64           # (M, S, S) linear, padded with 0
    pi: F64              # (M, S)
    means: F64           # (M, S, K, d)
    chol_inv: F64        # (M, S, K, d, d)
    logdet: F64          # (M, S, K)
    log_w: F64           # (M, S, K)
    n_states: tuple[int, ...]

    @classmethod
    def build(cls, models: Sequence[HMMParams]) -> "StackedModels":
        """Stack ``M`` models padded to the largest state count ``S`` and mixture size ``K``
        (``ValueError`` when their feature dimensions differ)."""
        M = len(models)
        S = max(p.n_states for p in models)
        K = max(p.n_mix for p in models)
        d = models[0].n_features
        pi = np.zeros((M, S))
        trans = np.zeros((M, S, S))
        means = np.zeros((M, S, K, d))
        chol_inv = np.broadcast_to(np.eye(d), (M, S, K, d, d)).copy()
        logdet = np.zeros((M, S, K))
        w = np.zeros((M, S, K))
        for m, p in enumerate(models):
            if p.n_features != d:
                raise ValueError("all models must share the feature dimension")
            s, k = p.n_states, p.n_mix
            pi[m, :s] = p.startprob
            trans[m, :s, :s] = p.transmat
            means[m, :s, :k] = p.means
            ci, ld = p.cholesky_inv()
            chol_inv[m, :s, :k] = ci
            logdet[m, :s, :k] = ld
            w[m, :s, :k] = p.weights
        return cls(safe_log(pi), trans, pi, means, chol_inv, logdet, safe_log(w),
                   tuple(p.n_states for p in models))

    @property
    def n_models(self) -> int:
        return self.pi.shape[0]

    def log_emission(self, X: F64) -> F64:
        """``log b_{m,j}(x_r)`` for ``X`` of shape ``(R, d)``: shape ``(R, M, S)`` (padded: -inf)."""
        d = self.means.shape[-1]
        diff = X[:, None, None, None, :] - self.means[None]           # (R, M, S, K, d)
        y = np.einsum("mskij,rmskj->rmski", self.chol_inv, diff)
        comp = -0.5 * (d * LOG2PI + self.logdet + np.einsum("rmski,rmski->rmsk", y, y))
        return logsumexp(comp + self.log_w, axis=-1)

    def restart_trans(self, eps: float) -> F64:
        """``(1-ε) A + ε 1 πᵀ`` on the real states of each model."""
        if eps == 0:
            return self.trans
        real = (self.pi > 0) | (self.trans.sum(-1) > 0)               # (M, S)
        mix = (1.0 - eps) * self.trans + eps * self.pi[:, None, :]
        return np.where(real[:, :, None], mix, 0.0)


def _fwd_step(la: F64, trans: F64, logb: F64) -> F64:
    """One log-space forward step for ``la``, ``logb`` of shape ``(R, M, S)``."""
    m = np.max(la, axis=-1, keepdims=True)
    m = np.where(np.isfinite(m), m, 0.0)
    p = np.exp(la - m)
    s = np.einsum("rmi,mij->rmj", p, trans)
    with np.errstate(divide="ignore"):
        return np.log(s) + m + logb


def _vit_step(ld: F64, log_trans: F64, logb: F64) -> F64:
    return np.max(ld[..., :, None] + log_trans[None], axis=-2) + logb


def confidence(scores: F64) -> F64:
    """``V_j = log10 Σ_{i≠j} exp(LL_i − LL_j)`` for scores of shape ``(..., M)``.

    ``-inf`` for a single model (no rival); ``nan`` where ``LL_j`` itself is ``-inf``.
    """
    scores = np.asarray(scores, dtype=np.float64)
    M = scores.shape[-1]
    eye = np.eye(M, dtype=bool)
    others = np.where(eye, -np.inf, scores[..., None, :])            # (..., M, M)
    with np.errstate(invalid="ignore"):
        return (logsumexp(others, axis=-1) - scores) / LN10


def extend_threshold(curve: F64, n: NDArray[np.int64], stationary: bool) -> F64:
    """Threshold at elapsed samples ``n`` (1-based) from a curve for n = 1..T; beyond T a
    cumulative curve is extended linearly (slope of its last tenth), a windowed one by its
    last value."""
    T = curve.shape[-1]
    idx = np.clip(n - 1, 0, T - 1)
    out = curve[..., idx] if curve.ndim == 1 else np.take_along_axis(curve, idx[None, :], axis=1)
    if not stationary:
        k = max(1, T // 10)
        slope = (curve[..., -1] - curve[..., -1 - k]) / k if T > k else np.zeros(curve.shape[:-1])
        extra = np.maximum(n - T, 0)
        out = out + (slope[..., None] * extra if curve.ndim > 1 else slope * extra)
    return out


@dataclass
class StepResult:
    """One classification step for ``R`` runs and ``M`` models (label ``-1`` = unknown)."""

    scores: F64          # (R, M) the LL used for the decision
    V: F64               # (R, M)
    best: NDArray        # (R,) argmax model
    label: NDArray       # (R,) model index or -1
    state: NDArray       # (R,) online Viterbi state of the best model
    oneclass_ok: NDArray  # (R,) bool
    change: NDArray      # (R,) bool: a change point was declared at this step (reset mode)
    change_at: NDArray   # (R,) samples since start of the declared change point, -1 if none


class OnlineClassifier:
    """Vectorised online forward classifier over ``M`` models and ``R`` runs.

    Parameters
    ----------
    models : sequence of HMMParams
    mode : {"cumulative", "windowed", "reset"}
    window : int
        Window length in samples (``windowed``/``reset``).
    restart_prob : float
        ``ε`` of the restart transition (``windowed``/``reset`` windowed pass).
    confirm : int
        Samples of disagreement before a change is declared (``reset``).
    confidence_threshold : float
        ``V_c`` must be below this (thesis: −1).
    decision : {"confidence", "oneclass", "both"}
    thresholds : ndarray, shape (M, T), optional
        One-class threshold of each model at elapsed samples 1..T (needed for ``oneclass``/
        ``both``); ``thresholds_stationary`` says how to extend it beyond T.
    viterbi : bool
        Track the online Viterbi state (``argmax_j δ_t(j)``) of every model.
    background : bool
        The last model is a background hypothesis: it counts in ``V`` like any rival but is
        never a label (a step where it is the best hypothesis is unknown).
    """

    def __init__(self, models: Sequence[HMMParams], *, mode: str = "cumulative", window: int = 20,
                 restart_prob: float = 0.02, confirm: int = 5, confidence_threshold: float = -1.0,
                 decision: str = "confidence", thresholds: F64 | None = None,
                 thresholds_stationary: bool = False, viterbi: bool = True, background: bool = False):
        if mode not in ("cumulative", "windowed", "reset"):
            raise ValueError(f"unknown mode {mode!r}")
        if decision not in ("confidence", "oneclass", "both"):
            raise ValueError(f"unknown decision {decision!r}")
        if decision != "confidence" and thresholds is None:
            raise ValueError(f"decision {decision!r} needs one-class thresholds")
        self.stack = StackedModels.build(models)
        self.mode = mode
        self.window = int(window)
        self.eps = float(restart_prob) if mode != "cumulative" else 0.0
        self.confirm = int(confirm)
        self.cthr = float(confidence_threshold)
        self.decision = decision
        self.thresholds = None if thresholds is None else np.asarray(thresholds, dtype=np.float64)
        self.thr_stationary = thresholds_stationary
        self.viterbi = viterbi
        self.background = bool(background)
        self.trans_cum = self.stack.trans
        self.trans_win = self.stack.restart_trans(self.eps)
        self.logtrans_cum = safe_log(self.trans_cum)
        self.logtrans_win = safe_log(self.trans_win)

    # -- state -----------------------------------------------------------------------------
    def start(self, n_runs: int) -> "OnlineClassifier":
        """Allocate state for ``n_runs`` runs (all before their first sample)."""
        R, M = n_runs, self.stack.n_models
        S = self.stack.pi.shape[1]
        self.t = np.zeros(R, dtype=np.int64)          # samples since start
        self.n_cum = np.zeros(R, dtype=np.int64)      # samples since the last (re)start of cum
        self.la_cum = np.full((R, M, S), np.nan)
        self.ll_cum = np.zeros((R, M))
        self.ld = np.full((R, M, S), np.nan)
        if self.mode != "cumulative":
            B = self.window + (self.confirm if self.mode == "reset" else 0)
            self.B = B
            self.la_win = np.full((R, M, S), np.nan)
            self.ll_win = np.zeros((R, M))
            self.inc = np.zeros((R, B, M))            # ring buffer of windowed increments
            if self.mode == "reset":
                self.logb_buf = np.zeros((R, B, M, S))
                self.streak = np.zeros(R, dtype=np.int64)
        return self

    def reset(self, mask) -> None:
        """Restart the forward passes of the runs in ``mask`` at their next sample (an external
        reset, e.g. at a labelled segment start)."""
        mask = np.asarray(mask, dtype=bool)
        self.n_cum[mask] = 0
        self.t[mask] = 0
        if self.mode != "cumulative":
            self.inc[mask] = 0.0
            if self.mode == "reset":
                self.streak[mask] = 0

    # -- one sample --------------------------------------------------------------------------
    def step(self, obs: F64, active=None) -> StepResult:
        """Consume one observation per run.

        Parameters
        ----------
        obs : ndarray, shape (R, d)
            Normalised observations; rows of inactive runs are ignored.
        active : ndarray of bool, shape (R,), optional
            Runs that have a sample at this step (default: rows without NaN).
        """
        obs = np.asarray(obs, dtype=np.float64)
        if active is None:
            active = np.isfinite(obs).all(axis=1)
        act = np.asarray(active, dtype=bool)
        X = np.where(act[:, None], obs, 0.0)
        logb = self.stack.log_emission(X)                              # (R, M, S)
        first = act & (self.n_cum == 0)
        # cumulative pass
        la_new = _fwd_step(np.nan_to_num(self.la_cum, nan=-np.inf), self.trans_cum, logb)
        la_new[first] = self.stack.log_pi + logb[first]
        self.la_cum = np.where(act[:, None, None], la_new, self.la_cum)
        self.ll_cum = np.where(act[:, None], logsumexp(self.la_cum, axis=-1), self.ll_cum)
        if self.viterbi:
            lt = self.logtrans_cum if self.mode != "windowed" else self.logtrans_win
            ld_new = _vit_step(np.nan_to_num(self.ld, nan=-np.inf), lt, logb)
            ld_new[first] = self.stack.log_pi + logb[first]
            self.ld = np.where(act[:, None, None], ld_new, self.ld)
        change = np.zeros(len(act), dtype=bool)
        change_at = np.full(len(act), -1, dtype=np.int64)
        if self.mode != "cumulative":
            first_w = act & (self.t == 0)
            lw = _fwd_step(np.nan_to_num(self.la_win, nan=-np.inf), self.trans_win, logb)
            lw[first_w] = self.stack.log_pi + logb[first_w]
            ll_prev = np.where(first_w[:, None], 0.0, self.ll_win)
            self.la_win = np.where(act[:, None, None], lw, self.la_win)
            ll_w = logsumexp(self.la_win, axis=-1)
            inc = ll_w - ll_prev
            slot = self.t % self.B
            r = np.nonzero(act)[0]
            self.inc[r, slot[r]] = inc[r]
            self.ll_win = np.where(act[:, None], ll_w, self.ll_win)
            if self.mode == "reset":
                self.logb_buf[r, slot[r]] = logb[r]
        self.t[act] += 1
        self.n_cum[act] += 1
        if self.mode == "cumulative":
            scores = self.ll_cum
        else:
            scores_w = self._window_scores()
            if self.mode == "windowed":
                scores = scores_w
            else:
                change, change_at = self._detect(scores_w, act)
                scores = self.ll_cum
        return self._decide(scores, change, change_at)

    def _window_scores(self) -> F64:
        W, B = self.window, self.B
        # the newest W slots of the ring buffer (slot (t-1) % B backwards)
        k = np.arange(W)
        slots = (self.t[:, None] - 1 - k[None, :]) % B                 # (R, W)
        valid = k[None, :] < self.t[:, None]
        vals = np.take_along_axis(self.inc, slots[:, :, None], axis=1)  # (R, W, M)
        return np.sum(np.where(valid[:, :, None], vals, 0.0), axis=1)

    def _detect(self, scores_w: F64, act) -> tuple[NDArray, NDArray]:
        V_w = confidence(scores_w)
        bw = np.argmax(scores_w, axis=1)
        ok_w = np.take_along_axis(V_w, bw[:, None], axis=1)[:, 0] < self.cthr
        bc = np.argmax(self.ll_cum, axis=1)
        dis = act & ok_w & (bw != bc) & (self.n_cum >= self.window)
        self.streak = np.where(dis, self.streak + 1, np.where(act, 0, self.streak))
        fire = self.streak >= self.confirm
        change = np.zeros(len(act), dtype=bool)
        change_at = np.full(len(act), -1, dtype=np.int64)
        for r in np.nonzero(fire)[0]:
            L = int(min(self.B, self.n_cum[r], self.t[r]))
            slots = (self.t[r] - L + np.arange(L)) % self.B             # oldest -> newest
            d = self.inc[r, slots, bw[r]] - self.inc[r, slots, bc[r]]
            cus = np.concatenate([[0.0], np.cumsum(d)])
            k0 = int(np.argmin(cus))                                   # change after k0 samples
            if k0 >= L:
                continue
            # replay the cumulative (and Viterbi) pass from the change point over the buffer
            lb = self.logb_buf[r, slots[k0:]]                           # (L-k0, M, S)
            la = self.stack.log_pi + lb[0]
            ld = la.copy()
            for j in range(1, len(lb)):
                la = _fwd_step(la[None], self.trans_cum, lb[j][None])[0]
                if self.viterbi:
                    ld = _vit_step(ld[None], self.logtrans_cum, lb[j][None])[0]
            self.la_cum[r] = la
            self.ll_cum[r] = logsumexp(la, axis=-1)
            if self.viterbi:
                self.ld[r] = ld
            self.n_cum[r] = L - k0
            self.streak[r] = 0
            change[r] = True
            change_at[r] = self.t[r] - (L - k0)
        return change, change_at

    def threshold_now(self) -> F64:
        """One-class threshold of every model at each run's elapsed samples, shape (R, M)."""
        n = self.n_cum if self.mode != "windowed" else self.t
        thr = extend_threshold(self.thresholds, n, self.thr_stationary)  # (M, R)
        return thr.T

    def _decide(self, scores, change, change_at) -> StepResult:
        V = confidence(scores)
        best = np.argmax(scores, axis=1)
        Vc = np.take_along_axis(V, best[:, None], axis=1)[:, 0]
        conf_ok = Vc < self.cthr
        if self.thresholds is not None:
            thr = self.threshold_now()
            oc_ok = np.take_along_axis(scores - thr, best[:, None], axis=1)[:, 0] >= 0
        else:
            oc_ok = np.ones(len(best), dtype=bool)
        ok = {"confidence": conf_ok, "oneclass": oc_ok, "both": conf_ok & oc_ok}[self.decision]
        if self.background:
            ok = ok & (best != scores.shape[1] - 1)
        label = np.where(ok, best, UNKNOWN)
        if self.viterbi:
            state = np.argmax(np.take_along_axis(self.ld, best[:, None, None], axis=1)[:, 0], axis=-1)
        else:
            state = np.zeros(len(best), dtype=np.int64)
        return StepResult(scores.copy(), V, best, label, state, oc_ok, change, change_at)


def classify_batch(clf: OnlineClassifier, X: F64, resets=None) -> dict[str, np.ndarray]:
    """Run the classifier over padded sequences.

    Parameters
    ----------
    clf : OnlineClassifier
    X : ndarray, shape (R, T, d)
        Normalised observations, NaN rows where a run has ended.
    resets : ndarray of bool, shape (R, T), optional
        Restart the forward passes of run r just before sample t.

    Returns
    -------
    dict of arrays with a leading ``(R, T)``: ``scores`` (R, T, M), ``V`` (R, T, M), ``best``,
    ``label``, ``state``, ``oneclass_ok``, ``change``, ``change_at``; entries past a run's end
    hold ``label = -2``.
    """
    X = np.asarray(X, dtype=np.float64)
    R, T, _ = X.shape
    M = clf.stack.n_models
    clf.start(R)
    out = {"scores": np.full((R, T, M), np.nan), "V": np.full((R, T, M), np.nan),
           "best": np.full((R, T), -2, dtype=np.int64), "label": np.full((R, T), -2, dtype=np.int64),
           "state": np.full((R, T), -1, dtype=np.int64), "oneclass_ok": np.zeros((R, T), dtype=bool),
           "change": np.zeros((R, T), dtype=bool), "change_at": np.full((R, T), -1, dtype=np.int64)}
    for t in range(T):
        if resets is not None and resets[:, t].any():
            clf.reset(resets[:, t])
        act = np.isfinite(X[:, t]).all(axis=1)
        res = clf.step(X[:, t], act)
        for k in out:
            v = getattr(res, k)
            out[k][act, t] = v[act]
    return out
