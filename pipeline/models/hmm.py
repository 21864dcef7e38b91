"""One hidden Markov model per maneuver, trained on top of hmmlearn (seed 000 §3.3, §4).

:class:`ManeuverHMM` follows the scikit-learn/hmmlearn contract (``__init__`` stores keyword
hyperparameters, ``fit(X, lengths) -> self``, fitted attributes end in ``_``). Training is

1. **Calinon pre-training**: a Gaussian mixture fitted by EM (with restarts) to *one* random
   training run (extended with further random runs when it is shorter than
   ``init_min_samples``); each component becomes one state's Gaussian, states ordered by the
   mean time of their responsibilities so that state 0 is the maneuver's beginning.
2. ``π = 1/Q`` and a diagonal-dominant ``A`` with *non-zero* off-diagonals (the thesis's
   ``A = I/Q`` would freeze every transition at zero, §13.1).
3. Multi-sequence Baum-Welch (hmmlearn ``fit(X, lengths)``), ``n_iter`` cap and ``tol``.

The fitted model is kept as plain arrays (:class:`HMMParams`: ``startprob``, ``transmat``,
per-state mixture ``weights``, ``means``, full ``covars``), which persist as npz and drive the
vectorised forward/Viterbi code; the hmmlearn object is rebuilt on demand as the oracle.

Emission density of state ``j`` (``K`` = ``n_mix`` components; thesis: K = 1):

.. math:: b_j(o) = \\sum_{k} w_{jk} \\, \\mathcal{N}(o; \\mu_{jk}, \\Sigma_{jk})

Forward recursion in log space (seed 000 §5; Rabiner 1989):

.. math::
    \\log\\alpha_1(j) = \\log\\pi_j + \\log b_j(O_1), \\quad
    \\log\\alpha_{t+1}(j) = \\operatorname{logsumexp}_i[\\log\\alpha_t(i) + \\log a_{ij}]
    + \\log b_j(O_{t+1}), \\quad LL(t) = \\operatorname{logsumexp}_j \\log\\alpha_t(j)
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from .base import ModelError

F64 = NDArray[np.float64]
LOG2PI = np.log(2.0 * np.pi)


def safe_log(p) -> F64:
    """``log(p)`` with ``log(0) = -inf`` and no warning."""
    with np.errstate(divide="ignore"):
        return np.log(np.asarray(p, dtype=np.float64))


def logsumexp(a: F64, axis: int = -1) -> F64:
    """``log Σ exp(a)`` along ``axis``; all ``-inf`` gives ``-inf`` without a warning."""
    m = np.max(a, axis=axis, keepdims=True)
    m = np.where(np.isfinite(m), m, 0.0)
    with np.errstate(divide="ignore"):
        s = np.log(np.sum(np.exp(a - m), axis=axis, keepdims=True)) + m
    return np.squeeze(s, axis=axis)


@dataclass(frozen=True)
class HMMParams:
    """A fitted HMM as plain arrays.

    Parameters
    ----------
    startprob : ndarray, shape (n_states,)
    transmat : ndarray, shape (n_states, n_states)
        ``transmat[i, j] = a_ij = P(q_{t+1} = j | q_t = i)``.
    weights : ndarray, shape (n_states, n_mix)
    means : ndarray, shape (n_states, n_mix, n_features)
    covars : ndarray, shape (n_states, n_mix, n_features, n_features)
    """

    startprob: F64
    transmat: F64
    weights: F64
    means: F64
    covars: F64

    @property
    def n_states(self) -> int:
        return self.startprob.shape[0]

    @property
    def n_mix(self) -> int:
        return self.weights.shape[1]

    @property
    def n_features(self) -> int:
        return self.means.shape[2]

    def to_arrays(self, prefix: str = "") -> dict[str, F64]:
        """The five arrays keyed ``<prefix><field>`` (npz persistence, no pickles)."""
        return {f"{prefix}{f.name}": getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_arrays(cls, arrays, prefix: str = "") -> "HMMParams":
        """Inverse of :meth:`to_arrays` (``arrays``: a mapping such as an open npz)."""
        return cls(*(arrays[f"{prefix}{f.name}"] for f in fields(cls)))

    def n_parameters(self) -> int:
        """Free parameters (for BIC)."""
        s, k, d = self.n_states, self.n_mix, self.n_features
        return (s - 1) + s * (s - 1) + s * (k - 1) + s * k * (d + d * (d + 1) // 2)

    def cholesky_inv(self) -> tuple[F64, F64]:
        """``(L⁻¹, log|Σ|)`` per component, shapes ``(S, K, d, d)`` and ``(S, K)``."""
        chol = np.linalg.cholesky(self.covars)
        logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
        return np.linalg.inv(chol), logdet

    def log_emission(self, X: F64) -> F64:
        """``log b_j(x_t)``, shape ``(n_samples, n_states)``."""
        return log_emission(X, self.means, *self.cholesky_inv(), safe_log(self.weights))

    def to_hmmlearn(self, *, implementation: str = "log"):
        """Equivalent hmmlearn model (GaussianHMM for K = 1, else GMMHMM), the test oracle."""
        from hmmlearn import hmm

        if self.n_mix == 1:
            m = hmm.GaussianHMM(n_components=self.n_states, covariance_type="full",
                                init_params="", implementation=implementation)
            m.means_ = self.means[:, 0]
            m.covars_ = self.covars[:, 0]
        else:
            m = hmm.GMMHMM(n_components=self.n_states, n_mix=self.n_mix, covariance_type="full",
                           init_params="", implementation=implementation)
            m.weights_ = self.weights
            m.means_ = self.means
            m.covars_ = self.covars
        m.startprob_ = self.startprob
        m.transmat_ = self.transmat
        m.n_features = self.n_features
        return m

    @classmethod
    def from_hmmlearn(cls, m) -> "HMMParams":
        """Copy the arrays of a fitted hmmlearn ``GaussianHMM`` (as ``n_mix`` = 1, covariances as
        full matrices) or full-covariance ``GMMHMM``; inverse of :meth:`to_hmmlearn`. Sets
        ``m.n_features`` when missing."""
        if not hasattr(m, "n_features"):
            m.n_features = np.asarray(m.means_).shape[-1]
        if hasattr(m, "weights_"):
            return cls(np.array(m.startprob_), np.array(m.transmat_), np.array(m.weights_),
                       np.array(m.means_), np.array(m.covars_))
        return cls(np.array(m.startprob_), np.array(m.transmat_),
                   np.ones((m.n_components, 1)), np.array(m.means_)[:, None, :],
                   np.array(m.covars_)[:, None, :, :])


def log_emission(X: F64, means: F64, chol_inv: F64, logdet: F64, log_w: F64) -> F64:
    """Log emission densities of a Gaussian-mixture HMM.

    Parameters
    ----------
    X : ndarray, shape (..., d)
    means : ndarray, shape (S, K, d)
    chol_inv, logdet : from :meth:`HMMParams.cholesky_inv`
    log_w : ndarray, shape (S, K)

    Returns
    -------
    ndarray, shape (..., S)
        :math:`\\log \\sum_k w_{jk} \\mathcal{N}(x; \\mu_{jk}, \\Sigma_{jk})`.
    """
    X = np.asarray(X, dtype=np.float64)
    d = means.shape[-1]
    diff = X[..., None, None, :] - means                      # (..., S, K, d)
    y = np.einsum("skij,...skj->...ski", chol_inv, diff)
    comp = -0.5 * (d * LOG2PI + logdet + np.einsum("...i,...i->...", y, y))
    return logsumexp(comp + log_w, axis=-1)


def forward_log(log_startprob: F64, log_transmat: F64, log_b: F64) -> tuple[F64, float]:
    """Offline log-space forward pass for any emission model.

    Parameters
    ----------
    log_startprob : ndarray, shape (S,)
    log_transmat : ndarray, shape (S, S)
    log_b : ndarray, shape (T, S)
        ``log b_j(O_t)``; for a categorical emission matrix ``B`` this is ``log B[:, O_t].T``.

    Returns
    -------
    log_alpha : ndarray, shape (T, S)
    log_likelihood : float
        ``log P(O_{1:T} | λ)``.
    """
    log_b = np.asarray(log_b, dtype=np.float64)
    la = np.empty_like(log_b)
    la[0] = log_startprob + log_b[0]
    for t in range(1, len(log_b)):
        la[t] = logsumexp(la[t - 1][:, None] + log_transmat, axis=0) + log_b[t]
    return la, float(logsumexp(la[-1]))


def forward_categorical(startprob, transmat, emissionprob, obs) -> float:
    """``P(O | λ)`` of a discrete HMM (seed 004 §1 anchors), through :func:`forward_log`."""
    B = np.asarray(emissionprob, dtype=np.float64)
    log_b = safe_log(B[:, np.asarray(obs, dtype=int)].T)
    _, ll = forward_log(safe_log(startprob), safe_log(transmat), log_b)
    return float(np.exp(ll))


def _fast_gaussian_hmm_class():
    """hmmlearn's GaussianHMM with the full-covariance emission density evaluated by
    :func:`log_emission` (Cholesky inverse cached per EM iteration). hmmlearn's own routine calls
    ``scipy.linalg.solve_triangular`` per state and sequence, whose per-call overhead dominates
    training on thousands of short runs. EM itself (forward-backward, M-step) is hmmlearn's; the
    density is the same formula (checked against stock hmmlearn in the tests)."""
    from hmmlearn import hmm

    class FastGaussianHMM(hmm.GaussianHMM):
        def _compute_log_likelihood(self, X):
            cov = self._covars_
            key = getattr(self, "_ll_key", None)
            if key is None or key[0].shape != cov.shape or not np.array_equal(key[0], cov) \
                    or not np.array_equal(key[1], self.means_):
                chol = np.linalg.cholesky(cov)
                logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
                self._ll_key = (cov.copy(), np.array(self.means_), np.linalg.inv(chol)[:, None],
                                logdet[:, None])
            _, mu, ci, ld = self._ll_key
            return log_emission(X, mu[:, None, :], ci, ld, np.zeros((len(mu), 1)))

        def _do_mstep(self, stats):
            super()._do_mstep(stats)
            # hmmlearn applies min_covar only at initialisation; a state that collapses onto a
            # near-constant feature (real logs) would become singular. Floor the smallest
            # eigenvalue at min_covar: states already above it are untouched, so EM stays
            # the plain (monotone) Baum-Welch wherever no floor is needed
            if "c" in self.params:
                cov = self._covars_
                lam = np.linalg.eigvalsh(cov)[:, 0]
                lift = np.maximum(self.min_covar - lam, 0.0)
                if np.any(lift > 0):
                    self._covars_ = cov + lift[:, None, None] * np.eye(cov.shape[-1])

        def _compute_posteriors_log(self, fwdlattice, bwdlattice):
            # hmmlearn normalises with scipy.special.logsumexp, whose per-call overhead is
            # large for short sequences; same normalisation, NumPy only
            log_gamma = fwdlattice + bwdlattice
            log_gamma -= logsumexp(log_gamma, axis=1)[:, None]
            with np.errstate(under="ignore"):
                return np.exp(log_gamma)

    return FastGaussianHMM


def check_observations(X, n_features: int | None = None) -> F64:
    """``X`` as a (T ≥ 1, d) float array of finite observations, or one :class:`ModelError`.

    Why: a NaN row makes every later δ/α NaN and ``argmax`` then answers state 0 at every step,
    a path that looks like a result; an empty sequence has no likelihood at all."""
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2 or len(X) == 0:
        raise ModelError(f"observations must be a non-empty (n_samples, n_features) array, got shape {X.shape}")
    if n_features is not None and X.shape[1] != n_features:
        raise ModelError(f"observations have {X.shape[1]} features, the model {n_features}")
    bad = ~np.isfinite(X).all(axis=1)
    if bad.any():
        raise ModelError(f"observation row {int(np.flatnonzero(bad)[0])} is not finite "
                         f"({int(bad.sum())} of {len(X)} rows)")
    return X


def _split(X: F64, lengths) -> list[F64]:
    if lengths is None:
        return [X]
    lengths = np.asarray(lengths)
    if lengths.ndim != 1 or len(lengths) == 0 or (lengths <= 0).any():
        raise ModelError(f"lengths must be positive sequence lengths, got {lengths.tolist()}")
    ends = np.cumsum(lengths)
    if ends[-1] != len(X):
        raise ModelError(f"lengths sum to {ends[-1]} but X has {len(X)} rows")
    return np.split(X, ends[:-1])


class ManeuverHMM:
    """One maneuver's HMM (full-covariance Gaussian or GMM emissions) trained with hmmlearn.

    Parameters
    ----------
    n_states : int or "auto"
        ``auto`` picks the BIC-best count in ``n_states_range``.
    n_states_range : tuple of int
    n_mix : int
        Gaussians per state.
    n_iter, tol : Baum-Welch cap and tolerance.
    min_covar : float
    self_prob : float
        Initial diagonal of ``A``; off-diagonals ``(1 - self_prob)/(S - 1)``.
    gmm_restarts : int
    init_min_samples : int
    hmm_restarts : int
        Independent initialisations (each from a different random run); the one with the
        highest final training log-likelihood is kept (guards against the local optimum of a
        run that under-represents a state).
    seed : int

    Attributes
    ----------
    params_ : HMMParams
    n_states_ : int
    n_iter_ : int
        Baum-Welch iterations run.
    converged_ : bool
    history_ : list of float
        Training log-likelihood per iteration (non-decreasing up to round-off).
    bic_ : dict
        ``{n_states: BIC}`` (only the chosen count unless ``auto``).
    init_runs_ : list of int
        Index of the training run(s) used for the GMM pre-training.
    """

    def __init__(self, *, n_states=5, n_states_range=(3, 10), n_mix=1, n_iter=100, tol=1e-2,
                 min_covar=1e-4, self_prob=0.9, gmm_restarts=3, init_min_samples=60,
                 hmm_restarts=1, seed=0):
        self.n_states = n_states
        self.n_states_range = n_states_range
        self.n_mix = n_mix
        self.n_iter = n_iter
        self.tol = tol
        self.min_covar = min_covar
        self.self_prob = self_prob
        self.gmm_restarts = gmm_restarts
        self.init_min_samples = init_min_samples
        self.hmm_restarts = hmm_restarts
        self.seed = seed

    # -- training ------------------------------------------------------------------------
    def fit(self, X: F64, lengths=None) -> "ManeuverHMM":
        """Train on normalised observations.

        Parameters
        ----------
        X : array-like, shape (n_samples, n_features)
            Concatenated observation sequences.
        lengths : array-like of int, optional
            Sequence lengths (sum = n_samples); ``None`` = one sequence.
        """
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2 or len(X) < 2:
            raise ModelError("need at least two observations to train an HMM")
        if not np.isfinite(X).all():
            raise ModelError("training observations contain NaN/inf")
        lengths = np.array([len(X)] if lengths is None else lengths, dtype=int)
        if self.n_states == "auto":
            lo, hi = self.n_states_range
            cands = list(range(lo, hi + 1))
        else:
            cands = [int(self.n_states)]
        best = None
        self.bic_ = {}
        for s in cands:
            fitted = ll = None
            for r in range(max(1, int(self.hmm_restarts))):
                f = self._fit_one(X, lengths, s, r)
                # restarts and the BIC compare the log-likelihood of the parameters returned:
                # hmmlearn's last history entry is that of the parameters before its last
                # M-step (off by 50 nats when n_iter stops it early)
                f_ll = self._score(f[0], X, lengths)
                if fitted is None or f_ll > ll:
                    fitted, ll = f, f_ll
            bic = -2.0 * ll + fitted[0].n_parameters() * np.log(len(X))
            self.bic_[s] = float(bic)
            if best is None or bic < best[0]:
                best = (bic, s, fitted)
        _, s, (params, history, n_iter, converged, init_runs) = best
        self.params_ = params
        self.n_states_ = s
        self.history_ = history
        self.n_iter_ = n_iter
        self.converged_ = converged
        self.init_runs_ = init_runs
        return self

    def _fit_one(self, X, lengths, n_states, restart=0):
        from hmmlearn import hmm
        from sklearn.exceptions import ConvergenceWarning
        from sklearn.mixture import GaussianMixture

        rng = np.random.default_rng([self.seed, n_states, restart])
        seqs = _split(X, lengths)
        order = rng.permutation(len(seqs))
        init_runs, n = [], 0
        need = max(self.init_min_samples, 3 * n_states)
        for i in order:
            init_runs.append(int(i))
            n += len(seqs[i])
            if n >= need:
                break
        Xi = np.concatenate([seqs[i] for i in init_runs])
        ti = np.concatenate([np.linspace(0.0, 1.0, len(seqs[i])) for i in init_runs])
        if len(Xi) < n_states:
            raise ModelError(f"{len(X)} observations are too few for {n_states} states")
        seed_int = int(rng.integers(2**31 - 1))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            gmm = GaussianMixture(n_components=n_states, covariance_type="full",
                                  reg_covar=max(self.min_covar, 1e-6), n_init=self.gmm_restarts,
                                  random_state=seed_int).fit(Xi)
        resp = gmm.predict_proba(Xi)
        t_mean = (resp * ti[:, None]).sum(0) / np.maximum(resp.sum(0), 1e-12)
        perm = np.argsort(t_mean, kind="stable")
        means, covs = gmm.means_[perm], gmm.covariances_[perm]
        d = X.shape[1]
        covs = covs + self.min_covar * np.eye(d)
        S = n_states
        trans = np.full((S, S), (1.0 - self.self_prob) / max(S - 1, 1))
        np.fill_diagonal(trans, self.self_prob if S > 1 else 1.0)
        start = np.full(S, 1.0 / S)
        if self.n_mix == 1:
            m = _fast_gaussian_hmm_class()(n_components=S, covariance_type="full", min_covar=self.min_covar,
                                n_iter=self.n_iter, tol=self.tol, init_params="", params="stmc",
                                random_state=seed_int, implementation="log")
            m.means_, m.covars_ = means, covs
        else:
            K = self.n_mix
            jitter = rng.standard_normal((S, K, d)) * np.sqrt(np.diagonal(covs, axis1=1, axis2=2))[:, None]
            m = hmm.GMMHMM(n_components=S, n_mix=K, covariance_type="full", min_covar=self.min_covar,
                           n_iter=self.n_iter, tol=self.tol, init_params="", params="stmcw",
                           random_state=seed_int, implementation="log")
            m.weights_ = np.full((S, K), 1.0 / K)
            m.means_ = means[:, None, :] + 0.5 * jitter
            m.covars_ = np.repeat(covs[:, None], K, axis=1)
        m.startprob_, m.transmat_ = start, trans
        m.n_features = d
        # the min_covar regularisation can lower the LL by round-off-sized amounts at
        # convergence; hmmlearn logs each as "not converging" — keep the console quiet and
        # record the history instead
        log = logging.getLogger("hmmlearn")
        level = log.level
        log.setLevel(logging.ERROR)
        try:
            m.fit(X, lengths)
        finally:
            log.setLevel(level)
        mon = m.monitor_
        params = HMMParams.from_hmmlearn(m)
        if self.n_mix > 1:
            # GMMHMM's M-step can leave a component singular; keep every density proper
            params = HMMParams(params.startprob, params.transmat, params.weights, params.means,
                               params.covars + self.min_covar * np.eye(d))
        hist = [float(h) for h in mon.history]
        # hmmlearn's ``converged`` is also True when the iteration cap is hit; record the
        # tolerance criterion itself
        converged = len(hist) >= 2 and hist[-1] - hist[-2] < self.tol
        return (params, hist, int(mon.iter), bool(converged), init_runs)

    @staticmethod
    def _score(params: HMMParams, X, lengths) -> float:
        ls, lt = safe_log(params.startprob), safe_log(params.transmat)
        return float(sum(forward_log(ls, lt, params.log_emission(x))[1] for x in _split(X, lengths)))

    # -- inference -----------------------------------------------------------------------
    def score(self, X: F64, lengths=None) -> float:
        """Total log-likelihood ``Σ log P(O^(r) | λ)`` by the log-space forward pass."""
        return self._score(self.params_, check_observations(X, self.params_.n_features), lengths)

    def score_prefixes(self, X: F64) -> F64:
        """``LL(t) = log P(O_{1:t} | λ)`` for every t of one sequence, shape (T,)."""
        p = self.params_
        X = check_observations(X, p.n_features)
        la, _ = forward_log(safe_log(p.startprob), safe_log(p.transmat), p.log_emission(X))
        return logsumexp(la, axis=1)

    # -- persistence (no pickles) ----------------------------------------------------------
    def to_arrays(self, prefix: str = "") -> dict[str, F64]:
        """:meth:`HMMParams.to_arrays` of the fitted :attr:`params_` (npz persistence)."""
        return self.params_.to_arrays(prefix)

    def training_meta(self) -> dict:
        """JSON-ready training record: ``n_states``, ``n_iter``, ``converged``, ``history``,
        ``bic`` (string keys) and ``init_runs``; the model set extends it into its label's
        ``training`` entry of ``meta.json``."""
        return {"n_states": int(self.n_states_), "n_iter": int(self.n_iter_),
                "converged": bool(self.converged_), "history": self.history_,
                "bic": {str(k): v for k, v in self.bic_.items()}, "init_runs": self.init_runs_}

    @classmethod
    def from_params(cls, params: HMMParams, **hyper) -> "ManeuverHMM":
        """A fitted model from stored ``params`` (no training; empty history, ``converged_``
        True); ``hyper`` are :meth:`__init__` keywords."""
        m = cls(**hyper)
        m.params_ = params
        m.n_states_ = params.n_states
        m.history_, m.n_iter_, m.converged_, m.bic_, m.init_runs_ = [], 0, True, {}, []
        return m
