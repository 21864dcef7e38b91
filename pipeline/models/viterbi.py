"""Viterbi decoding in log space (seed 000 §6; Rabiner 1989).

.. math::
    \\delta_1(i) = \\log\\pi_i + \\log b_i(O_1), \\quad
    \\delta_t(j) = \\max_i[\\delta_{t-1}(i) + \\log a_{ij}] + \\log b_j(O_t), \\quad
    \\psi_t(j) = \\operatorname{argmax}_i[\\cdot]

Backtracking ``q_t^* = ψ_{t+1}(q_{t+1}^*)`` gives the offline path; online, the current state is
``argmax_j δ_t(j)`` (tracked for all models at once by
:class:`pipeline.models.online.OnlineClassifier`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .hmm import HMMParams, check_observations, safe_log

F64 = NDArray[np.float64]


def viterbi_log(log_startprob: F64, log_transmat: F64, log_b: F64) -> tuple[float, NDArray[np.int64]]:
    """Most likely state path.

    Parameters
    ----------
    log_startprob : ndarray, shape (S,)
    log_transmat : ndarray, shape (S, S)
    log_b : ndarray, shape (T, S)

    Returns
    -------
    log_prob : float
        ``max_q log P(O, q | λ)``.
    path : ndarray of int, shape (T,)
    """
    T, S = log_b.shape
    psi = np.zeros((T, S), dtype=np.int64)
    delta = log_startprob + log_b[0]
    for t in range(1, T):
        cand = delta[:, None] + log_transmat
        psi[t] = np.argmax(cand, axis=0)
        delta = cand[psi[t], np.arange(S)] + log_b[t]
    path = np.empty(T, dtype=np.int64)
    path[-1] = int(np.argmax(delta))
    for t in range(T - 1, 0, -1):
        path[t - 1] = psi[t, path[t]]
    return float(delta[path[-1]]), path


def viterbi(params: HMMParams, X: F64) -> tuple[float, NDArray[np.int64]]:
    """Viterbi path of one observation sequence ``X`` (n_samples, n_features); a non-finite or
    empty ``X`` is one :class:`~pipeline.models.base.ModelError`."""
    X = check_observations(X, params.n_features)
    return viterbi_log(safe_log(params.startprob), safe_log(params.transmat), params.log_emission(X))


def online_viterbi_states(params: HMMParams, X: F64) -> NDArray[np.int64]:
    """``argmax_j δ_t(j)`` at every t (the online current state, no backtracking); a non-finite
    or empty ``X`` is one :class:`~pipeline.models.base.ModelError`."""
    lb = params.log_emission(check_observations(X, params.n_features))
    lt = safe_log(params.transmat)
    delta = safe_log(params.startprob) + lb[0]
    out = np.empty(len(lb), dtype=np.int64)
    out[0] = int(np.argmax(delta))
    for t in range(1, len(lb)):
        delta = np.max(delta[:, None] + lt, axis=0) + lb[t]
        out[t] = int(np.argmax(delta))
    return out
