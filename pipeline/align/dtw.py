"""Multi-dimensional dynamic time warping (seed 004 §1 "Generic DTW", eqs. 2.18–2.25).

Two sequences ``x`` (n, D) and ``y`` (m, D) are aligned by a monotone, continuous path
``c_k = (i_k, j_k)`` from ``(0, 0)`` to ``(n−1, m−1)`` (2.18–2.21) inside a Sakoe–Chiba window
``|i − j| ≤ r`` (2.22). The cumulative cost ``g`` follows one of three step patterns, with the
local cost ``d(i, j)`` of the (scaled) feature vectors:

=================  ==============================================================  ============
pattern            recursion                                                       normaliser
=================  ==============================================================  ============
``symmetric1``     ``g = d + min(g(i−1,j−1), g(i−1,j), g(i,j−1))``                  none (NaN)
``symmetric2``     ``min(g(i−1,j−1) + 2d, g(i−1,j) + d, g(i,j−1) + d)`` (2.25)     ``n + m``
``asymmetricP0``   ``min(g(i−1,j−1) + d, g(i−1,j) + d, g(i,j−1) + 0·d)`` (2.24)    ``n``
=================  ==============================================================  ============

with ``g(0, 0) = d(0, 0)``. The weights are the seed's: symmetric ``w_k = Δi + Δj`` (2.25),
asymmetric ``w_k = Δi`` (2.24); the normalised distance (2.23) is ``g(n−1, m−1) / Σ w_k`` with
``Σ w_k`` = ``n + m`` resp. ``n``, independent of the path. These are exactly dtw-python's
``symmetric1``, ``symmetric2`` and ``asymmetricP0`` (Giorgino 2009) with its ``sakoechiba``
window of ``window_size = r`` (the tests check distance, normalised distance and path against
it); symmetric1 has no path-independent normaliser, so its normalised distance is NaN, as in
dtw-python. With symmetric1 and the squared Euclidean local cost, ``√g`` is dtaidistance's
``dtw_ndim.distance`` with its ``window = r + 1`` (its window keeps ``|i − j| < w``) on equal
lengths, and without a window on any lengths; on unequal lengths dtaidistance widens its band
by ``|n − m|`` on the longer side, where this one (dtw-python's) stays ``|i − j| ≤ r``.

Implementation: numba kernels over the rows, each row's local costs computed first as a
vectorisable loop over the features (``y`` stored feature-major), then the serial recursion.
The distance kernel keeps two banded rows (O(window) memory); the path kernel additionally
stores one byte per cell (the step taken) and backtracks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]

#: step pattern -> (diagonal, vertical (i−1, j), horizontal (i, j−1)) weights
STEP_PATTERNS: dict[str, tuple[float, float, float]] = {
    "symmetric1": (1.0, 1.0, 1.0),
    "symmetric2": (2.0, 1.0, 1.0),
    "asymmetricP0": (1.0, 1.0, 0.0),
}
LOCAL_COSTS = ("euclidean", "sqeuclidean")


@dataclass(frozen=True)
class DtwResult:
    """Result of :func:`dtw`.

    Attributes
    ----------
    distance : float
        The cumulative cost ``g(n−1, m−1)`` of the optimal path.
    normalized_distance : float
        ``distance / Σ w_k`` (2.23): ``/(n + m)`` for symmetric2, ``/n`` for asymmetricP0, NaN
        for symmetric1 (no path-independent normaliser; dtw-python does the same).
    path : ndarray of int64, shape (K, 2), or None
        ``(i_k, j_k)`` from ``(0, 0)`` to ``(n−1, m−1)``; None when not asked for.
    """

    distance: float
    normalized_distance: float
    path: NDArray[np.int64] | None = None


# --------------------------------------------------------------------------- kernels
# Rows are banded: row i holds the columns lo[i]..hi[i], stored at offset 1 of a buffer of
# width W + 2 whose two pads stay +inf, so the diagonal / vertical predecessors of a band edge
# read +inf without a branch in the inner loop.

@njit(cache=True)
def _row_cost(x, yT, i, lo, hi, sq, out):
    """Local costs of row i for columns lo..hi into out[0 : hi−lo+1]."""
    # explicit slices: with indices offset by a runtime `lo` LLVM leaves the loops scalar
    # (5× slower); over slices they vectorise
    D = x.shape[1]
    w = hi - lo + 1
    o = out[:w]
    yd = yT[0, lo:hi + 1]
    xi = x[i, 0]
    for k in range(w):
        t = xi - yd[k]
        o[k] = t * t
    for d in range(1, D):
        yd = yT[d, lo:hi + 1]
        xi = x[i, d]
        for k in range(w):
            t = xi - yd[k]
            o[k] += t * t
    if not sq:
        for k in range(w):
            o[k] = np.sqrt(o[k])


@njit(cache=True)
def _band(n, m, r):
    lo = np.empty(n, np.int64)
    hi = np.empty(n, np.int64)
    for i in range(n):
        lo[i] = max(0, i - r)
        hi[i] = min(m - 1, i + r)
    return lo, hi


@njit(cache=True)
def _dtw_distance_kernel(x, yT, r, wd, wv, wh, sq):
    n = x.shape[0]
    m = yT.shape[1]
    lo, hi = _band(n, m, r)
    W = 0
    for i in range(n):
        W = max(W, hi[i] - lo[i] + 1)
    inf = np.inf
    prev = np.full(W + 2, inf)
    cur = np.full(W + 2, inf)
    cost = np.empty(W)
    # row 0: only horizontal steps
    # np.int64(0): a bare 0 types as Literal[int](0), a second compile of _row_cost
    _row_cost(x, yT, np.int64(0), lo[0], hi[0], sq, cost)
    g = cost[0]
    prev[1] = g
    for k in range(1, hi[0] - lo[0] + 1):
        g = g + wh * cost[k]
        prev[k + 1] = g
    plo, phi = lo[0], hi[0]
    for i in range(1, n):
        a, b = lo[i], hi[i]
        if a > b:
            return inf
        _row_cost(x, yT, i, a, b, sq, cost)
        left = inf
        s = a - plo  # prev index of (i−1, j−1) is j − 1 − plo + 1 = (j − a) + s
        for k in range(b - a + 1):
            c = cost[k]
            dg = prev[k + s] + wd * c
            up = prev[k + s + 1] + wv * c
            le = left + wh * c
            # selects, not branches (random data mispredicts them); min(dg, up) does not
            # depend on the carried `left`, so the serial chain is one add and one select
            m2 = dg if dg <= up else up
            v = le if le < m2 else m2
            cur[k + 1] = v
            left = v
        # the pads: the next row's band edges read them (a band never grows by more than one
        # column a row, so nothing beyond the right pad is read)
        cur[0] = inf
        cur[b - a + 2] = inf
        prev, cur = cur, prev
        plo, phi = a, b
    if phi != m - 1:
        return inf
    return prev[phi - plo + 1]


@njit(cache=True)
def _dtw_path_kernel(x, yT, r, wd, wv, wh, sq, hfirst):
    n = x.shape[0]
    m = yT.shape[1]
    lo, hi = _band(n, m, r)
    W = 0
    for i in range(n):
        W = max(W, hi[i] - lo[i] + 1)
    inf = np.inf
    # step taken into each cell: 0 diagonal, 1 vertical (from i−1), 2 horizontal (from j−1)
    steps = np.empty((n, W), np.uint8)
    prev = np.full(W + 2, inf)
    cur = np.full(W + 2, inf)
    cost = np.empty(W)
    # np.int64(0): a bare 0 types as Literal[int](0), a second compile of _row_cost
    _row_cost(x, yT, np.int64(0), lo[0], hi[0], sq, cost)
    g = cost[0]
    prev[1] = g
    steps[0, 0] = 0
    for k in range(1, hi[0] - lo[0] + 1):
        g = g + wh * cost[k]
        prev[k + 1] = g
        steps[0, k] = 2
    plo = lo[0]
    for i in range(1, n):
        a, b = lo[i], hi[i]
        if a > b:  # no admissible path (the API rejects such windows first)
            return inf, np.empty((0, 2), np.int64)
        _row_cost(x, yT, i, a, b, sq, cost)
        left = inf
        s = a - plo
        w = b - a + 1
        # the serial recursion first, exactly as the distance kernel ...
        for k in range(w):
            c = cost[k]
            dg = prev[k + s] + wd * c
            up = prev[k + s + 1] + wv * c
            m2 = dg if dg <= up else up
            le = left + wh * c
            v = le if le < m2 else m2
            cur[k + 1] = v
            left = v
        # ... then the step taken into each cell, in a second pass with no carried dependency
        # (it vectorises; folded into the recursion it made the loop 3× slower). Ties go to
        # the first of dtw-python's pattern order (diagonal, horizontal, vertical;
        # asymmetricP0: horizontal, diagonal, vertical); they are real for asymmetricP0, whose
        # free horizontal step makes "diagonal" and "horizontal then vertical" cost the same.
        # The candidates are recomputed with the same arithmetic, so they compare equal to
        # the recursion's.
        row = steps[i, :w]
        pd, pu, pl, cc = prev[s:s + w], prev[s + 1:s + 1 + w], cur[:w], cost[:w]  # slices vectorise
        for k in range(w):
            c = cc[k]
            dg = pd[k] + wd * c
            up = pu[k] + wv * c
            le = pl[k] + wh * c
            dwin = dg <= up
            m2 = dg if dwin else up
            s2 = np.uint8(0) if dwin else np.uint8(1)
            hwin = (le < m2) | ((le == m2) & (hfirst | (not dwin)))
            row[k] = np.uint8(2) if hwin else s2
        cur[0] = inf
        cur[b - a + 2] = inf
        prev, cur = cur, prev
        plo = a
    dist = prev[(m - 1) - plo + 1] if hi[n - 1] == m - 1 else inf
    if not dist < inf:
        return dist, np.empty((0, 2), np.int64)
    # backtrack from (n−1, m−1)
    buf = np.empty((n + m, 2), np.int64)
    i, j, K = n - 1, m - 1, 0
    while True:
        buf[K, 0] = i
        buf[K, 1] = j
        K += 1
        if i == 0 and j == 0:
            break
        st = steps[i, j - lo[i]]
        if st == 0:
            i -= 1
            j -= 1
        elif st == 1:
            i -= 1
        else:
            j -= 1
    out = np.empty((K, 2), np.int64)
    for k in range(K):
        out[k, 0] = buf[K - 1 - k, 0]
        out[k, 1] = buf[K - 1 - k, 1]
    return dist, out


# --------------------------------------------------------------------------- API

def _as_series(a: ArrayLike, name: str) -> F64:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise ValueError(f"dtw: {name} must be (n,) or (n, D), got shape {arr.shape}")
    if arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"dtw: {name} is empty (shape {arr.shape})")
    if not np.isfinite(arr).all():
        bad = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
        raise ValueError(f"dtw: {name} has a non-finite value (NaN or inf) in row {bad}")
    return arr


def feature_scale(scale: str | ArrayLike | None, *series: ArrayLike) -> F64 | None:
    """Per-feature divisors for DTW's local cost.

    Parameters
    ----------
    scale : None, "std" or array_like of shape (D,)
        None: no scaling. ``"std"``: the standard deviation of each feature pooled over all
        ``series`` (a constant feature gets 1, so it neither vanishes nor divides by zero).
        An array: the divisors themselves (positive, finite).
    *series : array_like, each (n_i, D) or (n_i,)
        The sequences that will be compared (all of them, so that every pairwise distance
        uses the same scaling).

    Returns
    -------
    ndarray, shape (D,), or None
    """
    if scale is None:
        return None
    if isinstance(scale, str):
        if scale != "std":
            raise ValueError(f"dtw: scale must be None, 'std' or an array of per-feature divisors, not {scale!r}")
        pooled = np.concatenate([_as_series(s, f"series {k}") for k, s in enumerate(series)], axis=0)
        sd = pooled.std(axis=0)
        return np.where(sd > 0, sd, 1.0)
    s = np.asarray(scale, dtype=np.float64).reshape(-1)
    if not (np.isfinite(s).all() and (s > 0).all()):
        raise ValueError(f"dtw: scale divisors must be positive and finite, got {s}")
    return s


def _prepare(x, y, step_pattern, window, scale, local):
    if step_pattern not in STEP_PATTERNS:
        raise ValueError(f"dtw: unknown step_pattern {step_pattern!r} (one of {', '.join(STEP_PATTERNS)})")
    if local not in LOCAL_COSTS:
        raise ValueError(f"dtw: unknown local cost {local!r} (one of {', '.join(LOCAL_COSTS)})")
    x, y = _as_series(x, "x"), _as_series(y, "y")
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"dtw: x has {x.shape[1]} features, y has {y.shape[1]}")
    n, m = len(x), len(y)
    if window is None:
        r = max(n, m)
    else:
        if isinstance(window, bool) or int(window) != window or window < 0:
            raise ValueError(f"dtw: window must be a non-negative integer (Sakoe–Chiba |i − j| ≤ r), not {window!r}")
        r = int(window)
        if abs(n - m) > r:
            raise ValueError(f"dtw: window r = {r} admits no path between lengths {n} and {m} "
                             f"(needs r ≥ |n − m| = {abs(n - m)})")
    s = feature_scale(scale, x, y)
    if s is not None:
        if s.shape != (x.shape[1],):
            raise ValueError(f"dtw: scale has {s.size} divisors for {x.shape[1]} features")
        x, y = x / s, y / s
    yT = np.ascontiguousarray(y.T)
    return np.ascontiguousarray(x), yT, r, STEP_PATTERNS[step_pattern], local == "sqeuclidean"


def _normalise(dist: float, step_pattern: str, n: int, m: int) -> float:
    if step_pattern == "symmetric2":
        return dist / (n + m)
    if step_pattern == "asymmetricP0":
        return dist / n
    return float("nan")


def dtw(x: ArrayLike, y: ArrayLike, *, step_pattern: str = "symmetric2", window: int | None = None,
        scale: str | ArrayLike | None = None, local: str = "euclidean", path: bool = True) -> DtwResult:
    """Dynamic time warping of ``x`` against ``y`` (see the module docstring).

    Parameters
    ----------
    x : array_like, shape (n, D) or (n,)
        Query (rows ``i``; asymmetricP0 normalises by its length).
    y : array_like, shape (m, D) or (m,)
        Reference (columns ``j``).
    step_pattern : {"symmetric2", "symmetric1", "asymmetricP0"}
        Step weights (2.25), unit weights, or (2.24).
    window : int, optional
        Sakoe–Chiba half width ``r``: only cells with ``|i − j| ≤ r`` (2.22); None: no window.
    scale : None, "std" or array_like (D,)
        Per-feature divisors applied to both sequences before the local cost
        (:func:`feature_scale`; ``"std"`` pools x and y).
    local : {"euclidean", "sqeuclidean"}
        Local cost ``d(i, j) = |x_i − y_j|`` or ``|x_i − y_j|²``.
    path : bool
        Also return the warping path (one byte of memory per cell in the window).

    Returns
    -------
    DtwResult

    Raises
    ------
    ValueError
        Bad shapes, non-finite values, an unknown pattern or local cost, a negative window, or
        a window narrower than ``|n − m|`` (no admissible path).
    """
    xs, yT, r, (wd, wv, wh), sq = _prepare(x, y, step_pattern, window, scale, local)
    n, m = xs.shape[0], yT.shape[1]
    if path:
        dist, p = _dtw_path_kernel(xs, yT, r, wd, wv, wh, sq, step_pattern == "asymmetricP0")
    else:
        dist, p = _dtw_distance_kernel(xs, yT, r, wd, wv, wh, sq), None
    dist = float(dist)
    return DtwResult(dist, _normalise(dist, step_pattern, n, m), p)


def dtw_distance(x: ArrayLike, y: ArrayLike, *, step_pattern: str = "symmetric2", window: int | None = None,
                 scale: str | ArrayLike | None = None, local: str = "euclidean") -> float:
    """The DTW distance ``g(n−1, m−1)`` only (no path, two banded rows of memory): the fastest
    call. Parameters as :func:`dtw`; the normalised distance is ``dtw(..., path=False)``."""
    xs, yT, r, (wd, wv, wh), sq = _prepare(x, y, step_pattern, window, scale, local)
    return float(_dtw_distance_kernel(xs, yT, r, wd, wv, wh, sq))
