"""Particle resampling: systematic, stratified, multinomial and residual; the effective sample
size; the moves after resampling that separate the copies again (:func:`regularise`, the
regularised PF's kernel, and :func:`roughen`, Gordon's roughening).

Every scheme maps normalised weights ``w`` (shape (N,)) to ``N`` ancestor indices drawn so that
the expected number of copies of particle ``i`` is ``N w_i`` (unbiased resampling). They differ
in the variance of the copy counts (Douc, Cappé & Moulines 2005):

- **systematic** (seed 001 Table 2.1): one ``u ~ U(0, 1)``, positions ``(j + u)/N``; copies
  ``∈ {⌊N w_i⌋, ⌈N w_i⌉}``;
- **stratified**: one ``u_j ~ U(0, 1)`` per stratum, positions ``(j + u_j)/N``; ``|copies − N w_i| < 2``;
- **multinomial** (seed 003 §2.4): ``N`` i.i.d. draws from ``w``;
- **residual**: ``⌊N w_i⌋`` deterministic copies, the remaining ``N − Σ⌊N w_i⌋`` drawn
  multinomially from the residual weights.

The inverse-CDF searches run in a numba kernel (one linear merge of the sorted positions with
the cumulative weights, O(N)); the cumulative sum's last entry is forced to 1 so float shortfall
never indexes past the end. Randomness only through the explicit ``rng``.

.. math::

    N_{\\text{eff}} = 1 \\Big/ \\sum_i w_i^2 \\in [1, N]
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: the resampling schemes by name (``estimate.pf.resample``)
SCHEMES: tuple[str, ...] = ("systematic", "stratified", "multinomial", "residual")


@njit(cache=True)
def _merge_sorted(cdf: F64, positions: F64) -> I64:
    """For ascending ``positions``, the first ``i`` with ``cdf[i] > positions[j]`` (linear merge):
    particle ``i`` owns ``[cdf[i-1], cdf[i])``, so a zero-weight particle (an empty interval) is
    never drawn, not even by a position of exactly 0 (``rng.random()`` is in [0, 1))."""
    n = positions.shape[0]
    m = cdf.shape[0]
    out = np.empty(n, dtype=np.int64)
    i = 0
    for j in range(n):
        p = positions[j]
        while i < m - 1 and p >= cdf[i]:
            i += 1
        out[j] = i
    return out


def _cdf(w: F64) -> F64:
    c = np.cumsum(w)
    c[-1] = 1.0  # guard against float shortfall (seed 001 Table 2.1)
    return c


def _weights(w: ArrayLike) -> F64:
    w = np.asarray(w, dtype=np.float64)
    if w.ndim != 1 or w.size == 0:
        raise ValueError(f"resample: weights must be a non-empty 1-D array, got shape {w.shape}")
    s = w.sum()
    if not np.isfinite(s) or s <= 0 or np.any(w < 0):
        raise ValueError("resample: weights must be finite, non-negative and not all zero")
    return w / s


def _count(n: int | None, w: F64) -> int:
    """The number of draws: ``N`` by default; a negative ``n`` is refused (``systematic`` would
    return an empty array silently, ``residual`` fail inside ``np.repeat``)."""
    if n is None:
        return w.size
    if int(n) != n or n < 0:
        raise ValueError(f"resample: n must be a whole number >= 0, got {n}")
    return int(n)


def systematic(w: ArrayLike, rng: np.random.Generator, n: int | None = None) -> I64:
    """Systematic resampling: ancestor indices for positions ``(j + u)/n``, one ``u ~ U(0, 1)``.

    Parameters
    ----------
    w : array_like, shape (N,)
        Non-negative weights (normalised here).
    rng : numpy.random.Generator
    n : int, optional
        Number of draws (default ``N``), ≥ 0 (ValueError otherwise; 0 gives no index).

    Returns
    -------
    ndarray of int64, shape (n,)
        Ancestor indices, ascending.
    """
    w = _weights(w)
    n = _count(n, w)
    pos = (np.arange(n, dtype=np.float64) + rng.random()) / n
    return _merge_sorted(_cdf(w), pos)


def stratified(w: ArrayLike, rng: np.random.Generator, n: int | None = None) -> I64:
    """Stratified resampling: positions ``(j + u_j)/n`` with independent ``u_j ~ U(0, 1)``."""
    w = _weights(w)
    n = _count(n, w)
    pos = (np.arange(n, dtype=np.float64) + rng.random(n)) / n
    return _merge_sorted(_cdf(w), pos)


def multinomial(w: ArrayLike, rng: np.random.Generator, n: int | None = None) -> I64:
    """Multinomial resampling: ``n`` i.i.d. draws from ``w`` (returned ascending)."""
    w = _weights(w)
    n = _count(n, w)
    pos = np.sort(rng.random(n))
    return _merge_sorted(_cdf(w), pos)


def residual(w: ArrayLike, rng: np.random.Generator, n: int | None = None) -> I64:
    """Residual resampling: ``⌊n w_i⌋`` copies, the rest multinomial on ``n w_i − ⌊n w_i⌋``."""
    w = _weights(w)
    n = _count(n, w)
    nw = n * w
    base = np.floor(nw).astype(np.int64)
    det = np.repeat(np.arange(w.size, dtype=np.int64), base)
    rest = n - det.size
    if rest == 0:
        return det
    r = nw - base
    extra = multinomial(r, rng, rest)
    return np.sort(np.concatenate([det, extra]))


RESAMPLERS: dict[str, Callable[..., I64]] = {
    "systematic": systematic, "stratified": stratified,
    "multinomial": multinomial, "residual": residual,
}


def get_resampler(name: str) -> Callable[..., I64]:
    """The resampling function named ``name`` (one of :data:`SCHEMES`); a clear error otherwise."""
    try:
        return RESAMPLERS[name]
    except KeyError:
        raise ValueError(f"resample: unknown scheme {name!r}; expected one of {', '.join(SCHEMES)}") from None


def effective_sample_size(w: ArrayLike) -> float:
    """``N_eff = 1/Σ w_i²`` of normalised weights (the weights are normalised here)."""
    w = np.asarray(w, dtype=np.float64)
    s = w.sum()
    if not np.isfinite(s) or s <= 0:
        return 0.0
    w = w / s
    return float(1.0 / np.dot(w, w))


def copies(indices: ArrayLike, n: int) -> I64:
    """How many times each of ``n`` particles was drawn (``bincount`` of the ancestor indices)."""
    return np.bincount(np.asarray(indices, dtype=np.int64), minlength=n)


def roughen(x: ArrayLike, K: float, rng: np.random.Generator, index: ArrayLike | None = None) -> F64:
    """Roughening after resampling (Gordon, Salmond & Smith 1993; digest 001 §13 item 7).

    .. math::

        x^i_j \\leftarrow x^i_j + \\sigma_j \\varepsilon^i_j, \\qquad
        \\sigma_j = K E_j N^{-1/d}, \\quad \\varepsilon^i_j \\sim \\mathcal N(0, 1),

    ``E_j`` the particles' range in component ``j`` of ``index`` and ``d`` the number of those
    components that vary (``E_j > 0``): resampled copies of one particle separate again. A
    component held constant (the ground plane's D) is no dimension of the state being roughened
    (the first version counted it, d = 5 instead of 4). ``K <= 0`` or no varying component: a copy
    of ``x``.

    Parameters
    ----------
    x : (N, n) array
        Resampled particles; not modified.
    K : float
        Gordon's tuning constant (0.2 in their paper).
    rng : numpy.random.Generator
    index : sequence of int, optional
        The components to roughen (default all).
    """
    out = np.array(x, dtype=np.float64, copy=True)
    if K <= 0:
        return out
    idx = np.arange(out.shape[1]) if index is None else np.asarray(index, dtype=np.int64)
    X = out[:, idx]
    E = X.max(axis=0) - X.min(axis=0)
    d = int(np.count_nonzero(E > 0))
    if d == 0:
        return out
    sig = K * E * out.shape[0] ** (-1.0 / d)
    out[:, idx] = X + sig[None, :] * rng.standard_normal(X.shape)
    return out


def regularisation_bandwidth(n: int, d: int) -> float:
    """The Gaussian kernel's optimal bandwidth of the regularised particle filter.

    .. math::

        h_{\\text{opt}} = A\\,N^{-1/(d+4)}, \\qquad A = \\left(\\frac{4}{d+2}\\right)^{1/(d+4)}

    (Musso, Oudjane & Le Gland 2001; Arulampalam, Maskell, Gordon & Clapp 2002, eq. 77): the
    bandwidth that minimises the mean integrated squared error between the kernel density of
    ``N`` equally weighted samples and a Gaussian density in ``d`` dimensions. N = 50, d = 4: 0.583.
    """
    if n < 1 or d < 1:
        raise ValueError(f"regularisation_bandwidth: need n >= 1 and d >= 1, got n={n}, d={d}")
    return float((4.0 / (d + 2.0)) ** (1.0 / (d + 4.0)) * n ** (-1.0 / (d + 4.0)))


def regularise(x: ArrayLike, cov: ArrayLike, rng: np.random.Generator, index: ArrayLike | None = None) -> F64:
    """The regularised particle filter's move after resampling (Arulampalam et al. 2002, Alg. 6).

    Each resampled particle is drawn from the Gaussian kernel about it,

    .. math::

        x^i \\leftarrow x^i + h_{\\text{opt}}\\, D\\, \\varepsilon^i, \\qquad
        D D^\\top = S, \\quad \\varepsilon^i \\sim \\mathcal N(0, I_d),

    with ``S`` the weighted empirical covariance of the particles *before* resampling (``cov``,
    the filter's own estimate of the posterior spread) over the components ``index``, and ``d``
    the number of those components that vary (a component held constant, e.g. the ground plane's
    D, is no dimension of the kernel). Resampled copies of one particle separate again with the
    posterior's own shape and scale, so a small cloud keeps the spread the weights gave it
    instead of shrinking at every resampling (sample impoverishment). ``D = V Λ^{1/2}`` from
    ``S = V Λ Vᵀ`` (eigenvalues clipped at 0), a square root that exists for a singular ``S`` too.

    Parameters
    ----------
    x : (N, n) array
        Resampled particles (equal weights); not modified.
    cov : (n, n) array
        Weighted covariance of the particles before resampling.
    rng : numpy.random.Generator
    index : sequence of int, optional
        The components to move (default all).

    Returns
    -------
    (N, n) array
        The moved particles.
    """
    out = np.array(x, dtype=np.float64, copy=True)
    idx = np.arange(out.shape[1]) if index is None else np.asarray(index, dtype=np.int64)
    S = np.asarray(cov, dtype=np.float64)[np.ix_(idx, idx)]
    if not np.all(np.isfinite(S)):
        raise ValueError("regularise: the covariance has non-finite entries")
    S = 0.5 * (S + S.T)
    lam, V = np.linalg.eigh(S)
    lam = np.clip(lam, 0.0, None)
    # the kernel's dimension: the components that vary (a constant one adds nothing)
    d = int(np.count_nonzero(np.diag(S) > 0))
    if d == 0:
        return out
    h = regularisation_bandwidth(out.shape[0], d)
    D = V * np.sqrt(lam)[None, :]
    out[:, idx] += h * rng.standard_normal((out.shape[0], len(idx))) @ D.T
    return out
