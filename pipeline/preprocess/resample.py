"""Time base: timestamp repair and gap-aware resampling onto a uniform grid.

Every later numerical step (Butterworth filtering, differentiation, DTW) assumes a uniform
sample period, while logged streams are jittery, multi-rate and have dropouts (seed 004 §11:
"resample it to a uniform grid before filtering, differentiation and DTW"). This module

* repairs a stream's time stamps (:func:`repair_timestamps`): non-monotonic rows are put in
  order, repeated stamps dropped and clock jumps closed, each counted;
* builds the grid (:func:`make_grid`) and resamples columns onto it (:func:`resample`) with a
  declared method per column: ``linear``, ``nearest``, ``previous`` (discrete values such as
  modes and switch positions), ``slerp`` (quaternions, four columns at once) or ``mean`` (the
  average over ±half a grid period of the samples' linear interpolant: a boxcar anti-alias
  filter centred on the grid time, for sources faster than the grid, e.g. a 200 Hz gyro on a
  25 Hz grid; in a cell without samples it equals the linear value).

A grid point is only filled from the two source samples that bracket it, and only when they
are at most ``max_gap_ns`` apart (:func:`bridge_limit_ns`: a configured multiple of the longer
of the source's median period and the grid period):

.. math:: x(g) = x_k + \\frac{g - t_k}{t_{k+1} - t_k}(x_{k+1} - x_k), \\quad
          t_k \\le g < t_{k+1},\\; t_{k+1} - t_k \\le \\Delta_{\\max}

Otherwise the point is NaN and flagged invalid (the ``gap`` column of ``state``), so nothing is
ever interpolated across a dropout. The limit follows the output grid for sources faster than
it: a 183 Hz IMU whose stamps jitter up to 3× its 5.5 ms median step would otherwise turn a fifth
of a 25 Hz grid into gaps, although every grid cell holds samples; what counts as a dropout is
decided at the resolution of the output, ``gap_multiple`` grid periods.
"""

from __future__ import annotations

from typing import Iterable, Mapping

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..frames.rotations import quat_continuity, quat_slerp

METHODS = ("linear", "nearest", "previous", "slerp", "mean")

#: Most grid points :func:`make_grid` builds: ``state`` holds about 40 float64 columns, so
#: 2e7 points are ~6 GiB, as much as one flight's job should take (9 days at 25 Hz, 2.3 days
#: at 100 Hz; real flights are hours). A longer grid means a corrupt time base.
MAX_GRID_SAMPLES = 20_000_000


class TimeBaseError(ValueError):
    """A flight's time stamps cannot be put on a grid (a span of days: a corrupt time base).
    ``str(err)`` is one line naming the span and the rate; the stage writes the flight's
    failure placeholder with it (:func:`pipeline.preprocess.run.run_preprocess`)."""


def median_period_ns(t_ns: NDArray[np.int64]) -> float:
    """Median positive step of a sorted time vector (ns); NaN with fewer than two samples."""
    t = np.asarray(t_ns, dtype=np.int64)
    d = np.diff(t)
    d = d[d > 0]
    return float(np.median(d)) if len(d) else float("nan")


def bridge_limit_ns(t_ns: NDArray[np.int64], grid_ns: NDArray[np.int64], gap_multiple: float = 3.0) -> float:
    """Longest source step bridged by interpolation (ns).

    .. math:: \\Delta_{\\max} = m \\cdot \\max(\\operatorname{median}\\Delta t_{src},\\;
              \\operatorname{median}\\Delta t_{grid})

    with ``m = gap_multiple``: a slow source (5 Hz GPS on a 25 Hz grid) is bridged over ``m`` of
    its own periods, a fast one (a 183 Hz IMU) over ``m`` grid periods, not ``m`` of its own
    jittery steps. 0 when neither period is known (fewer than two samples/grid points).
    """
    per = median_period_ns(t_ns)
    grid_per = median_period_ns(grid_ns)
    ps = [p for p in (per, grid_per) if np.isfinite(p)]
    return gap_multiple * max(ps) if ps else 0.0


def primary_instance(df: pd.DataFrame) -> pd.DataFrame:
    """Rows of the instance with most samples (lowest id on ties): one sensor per stream."""
    if not len(df) or "instance" not in df.columns or df["instance"].nunique() <= 1:
        return df
    counts = df["instance"].value_counts()
    best = min(counts.index[counts == counts.max()])
    return df[df["instance"] == best]


def repair_timestamps(df: pd.DataFrame, *, clock_jump_s: float | None = 3600.0
                      ) -> tuple[pd.DataFrame, dict[str, int]]:
    """Make one sensor's ``t_ns`` strictly increasing, counting every repair.

    Parameters
    ----------
    df : DataFrame
        Rows of one sensor instance in arrival order, with an int64 ``t_ns`` column.
    clock_jump_s : float or None
        A step larger than this (forward or backward, s) is a clock jump, not a dropout:
        every later sample is shifted by ``-step + median period`` so the sequence continues.
        ``None`` disables jump repair (long steps stay gaps).

    Returns
    -------
    (DataFrame, dict)
        Repaired rows (index reset) and counts ``{non_monotonic, duplicate, clock_jumps,
        stray}``: rows that stepped back in arrival order (put in order), rows with a repeated
        stamp (the first is kept: later ones carry no new time information), closed jumps and
        dropped stray stamps (:func:`stray_samples`).
    """
    diag = {"non_monotonic": 0, "duplicate": 0, "clock_jumps": 0, "stray": 0}
    if len(df) < 2:
        return df.reset_index(drop=True), diag
    t = df["t_ns"].to_numpy(dtype=np.int64).copy()
    # strays first: a lone record days away is dropped, not taken for a clock jump and moved
    order = np.argsort(t, kind="stable")
    stray = np.zeros(len(t), dtype=bool)
    stray[order] = stray_samples(t[order])
    if stray.any():
        diag["stray"] = int(stray.sum())
        df, t = df[~stray], t[~stray]
    d = np.diff(t)
    if clock_jump_s is not None:
        jump_ns = int(clock_jump_s * 1e9)
        jumps = np.flatnonzero(np.abs(d) > jump_ns)
        if len(jumps):
            normal = d[np.abs(d) <= jump_ns]
            per = np.median(normal[normal > 0]) if np.any(normal > 0) else 0
            shift = np.zeros(len(t), dtype=np.int64)
            for j in jumps:
                shift[j + 1:] += -d[j] + int(per)
            t = t + shift
            diag["clock_jumps"] = int(len(jumps))
            d = np.diff(t)
    diag["non_monotonic"] = int(np.sum(d < 0))
    out = df.assign(t_ns=t)
    if diag["non_monotonic"]:
        out = out.iloc[np.argsort(t, kind="stable")]
    ts = out["t_ns"].to_numpy()
    dup = np.concatenate([[False], ts[1:] == ts[:-1]])
    diag["duplicate"] = int(dup.sum())
    if dup.any():
        out = out[~dup]
    return out.reset_index(drop=True), diag


#: :func:`stray_samples`: a step longer than this many median periods (and :data:`STRAY_GAP_S`)
#: separates islands of samples
STRAY_GAP_PERIODS = 100
STRAY_GAP_S = 1800.0


def stray_samples(t_ns: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Samples whose stamps lie apart from the rest of a sorted stream: damaged time fields.

    The sorted stamps split into islands at every step longer than ``max(STRAY_GAP_S,
    STRAY_GAP_PERIODS × median step)``; an island of at most ``max(3, n / 1000)`` samples
    beside one ten times its size is stray. A bit flipped in one record's time puts that
    record far away (a 44 s ULog with 20 flipped bytes spanned 3,072 s on its grid, a tlog
    3,601 s instead of 867 s, 87–99 % of it gap). The gap is half an hour, longer than any
    telemetry dropout or disarmed pause a log of one flight holds (a 1 Hz tlog's 3 s after a
    2 min link loss is kept).
    """
    t = np.asarray(t_ns, dtype=np.int64)
    out = np.zeros(len(t), dtype=bool)
    if len(t) < 8:
        return out
    d = np.diff(t)
    pos = d[d > 0]
    if not len(pos):
        return out
    gap = max(STRAY_GAP_S * 1e9, STRAY_GAP_PERIODS * float(np.median(pos)))
    cuts = np.flatnonzero(d > gap) + 1
    if not len(cuts):
        return out
    starts, ends = np.r_[0, cuts], np.r_[cuts, len(t)]
    sizes = ends - starts
    small = max(3, len(t) // 1000)
    if sizes.max() < 10 * small:
        return out
    for a, b, n in zip(starts, ends, sizes):
        if n <= small:
            out[a:b] = True
    return out


def make_grid(t_start_ns: int, t_end_ns: int, rate_hz: float, *,
              max_samples: int = MAX_GRID_SAMPLES) -> NDArray[np.int64]:
    """Uniform grid ``t_start + round(k / rate)`` (ns) covering ``[t_start, t_end]``.

    Raises
    ------
    TimeBaseError
        The grid would hold more than ``max_samples`` points (:data:`MAX_GRID_SAMPLES`): the
        span is days long, which no flight is, so its time stamps are corrupt. Without this
        the allocation fails with a MemoryError (or takes the machine's memory).
    """
    if rate_hz <= 0 or not np.isfinite(rate_hz):
        raise ValueError(f"rate_hz must be positive, got {rate_hz}")
    if t_end_ns < t_start_ns:
        return np.empty(0, dtype=np.int64)
    span_s = (float(t_end_ns) - float(t_start_ns)) * 1e-9  # float: int64 spans can overflow
    n_float = np.floor(span_s * rate_hz + 1e-9) + 1
    if n_float > max_samples:
        raise TimeBaseError(
            f"time span {span_s:.6g} s ({span_s / 86400:.3g} days, t_ns {t_start_ns} to {t_end_ns}) at "
            f"{rate_hz:g} Hz would need {n_float:.3g} grid samples (limit {max_samples:.3g}): "
            "corrupt time stamps in the log?")
    n = int(np.floor((t_end_ns - t_start_ns) * rate_hz * 1e-9 + 1e-9)) + 1
    return t_start_ns + np.round(np.arange(n) * (1e9 / rate_hz)).astype(np.int64)


def _bracket(t: NDArray[np.int64], g: NDArray[np.int64], max_gap_ns: float):
    """Left index, interpolation weight and validity of each grid point."""
    n = len(t)
    k = np.searchsorted(t, g, side="right") - 1
    if n == 0:
        z = np.zeros(len(g), dtype=np.int64)
        return z, z, np.zeros(len(g)), np.zeros(len(g), dtype=bool), np.zeros(len(g), dtype=bool)
    kc = np.clip(k, 0, n - 1)
    exact = (k >= 0) & (t[kc] == g)
    if n == 1:
        return kc, kc, np.zeros(len(g)), exact, exact
    k0 = np.clip(k, 0, n - 2)
    t0, t1 = t[k0], t[k0 + 1]
    inside = (k >= 0) & (k < n - 1) & ((t1 - t0) <= max_gap_ns)
    w = np.where(inside, (g - t0) / np.maximum(t1 - t0, 1), 0.0)
    # an exact hit takes the sample itself (w = 0 on its left bracket): bit-exact on-grid values
    k0 = np.where(exact, kc, k0)
    w = np.where(exact, 0.0, w)
    k1 = np.minimum(k0 + 1, n - 1)
    return k0, k1, w, exact | inside, exact


def _cell_mean(t: NDArray, x: NDArray, g: NDArray) -> NDArray[np.float64]:
    """Mean over each cell ``[g - T/2, g + T/2]`` (T the grid period, the cell cut to the samples'
    span) of the piecewise-linear interpolant of the finite samples; NaN where the cut cell is
    empty. O(n) through the cumulative trapezoid integral.

    .. math:: \\bar x(g) = \\frac{1}{b - a}\\int_a^b \\tilde x(\\tau)\\,d\\tau

    A boxcar of the signal, centred on ``g``: the plain mean of the samples inside a half-open
    cell is centred on the samples' own times instead, up to half a source period early (a 50 Hz
    IMU on a 25 Hz grid: two samples a cell, 10 ms early when they sit on the cell edges).
    """
    if len(g) < 2 or not len(t):
        return np.full(len(g), np.nan)
    fin = np.isfinite(x)
    if fin.sum() < 2:
        return np.full(len(g), np.nan)
    t0 = int(t[fin][0])
    tf = (t[fin] - t0) * 1e-9  # s from the first finite sample: float64 keeps ns over days
    xf = x[fin]
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (xf[1:] + xf[:-1]) * np.diff(tf))])

    def integral(tau: NDArray) -> NDArray:
        k = np.clip(np.searchsorted(tf, tau, side="right") - 1, 0, len(tf) - 2)
        dt = np.maximum(tf[k + 1] - tf[k], 1e-12)
        u = tau - tf[k]
        xt = xf[k] + u / dt * (xf[k + 1] - xf[k])
        return cum[k] + 0.5 * u * (xf[k] + xt)

    half = 0.5 * float(np.median(np.diff(g))) * 1e-9
    gs = (g - t0) * 1e-9
    a = np.clip(gs - half, tf[0], tf[-1])
    b = np.clip(gs + half, tf[0], tf[-1])
    width = b - a
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(width > 0, (integral(b) - integral(a)) / np.where(width > 0, width, 1.0), np.nan)


def resample(df: pd.DataFrame, grid_ns: NDArray[np.int64], methods: Mapping[str, str], *,
             max_gap_ns: float | None = None, gap_multiple: float = 3.0
             ) -> tuple[pd.DataFrame, NDArray[np.bool_]]:
    """Resample columns of one (repaired, strictly increasing) stream onto ``grid_ns``.

    Parameters
    ----------
    df : DataFrame
        Source rows with ``t_ns`` strictly increasing (see :func:`repair_timestamps`).
    grid_ns : ndarray of int64
        Target times.
    methods : mapping
        ``{column: method}``; ``slerp`` must be given for all four ``q_w, q_x, q_y, q_z``
        (interpolated together; sign continuity enforced first). Absent columns give NaN.
    max_gap_ns : float, optional
        Longest source step bridged by interpolation; default :func:`bridge_limit_ns`
        (``gap_multiple`` × the longer of the median source period and the grid period).

    Returns
    -------
    (DataFrame, ndarray of bool)
        One column per ``methods`` key on the grid (float; NaN where invalid) and the
        validity mask of the stream (False in gaps and outside its time span).
    """
    g = np.asarray(grid_ns, dtype=np.int64)
    t = df["t_ns"].to_numpy(dtype=np.int64) if len(df) else np.empty(0, dtype=np.int64)
    if len(t) > 1 and np.any(np.diff(t) <= 0):
        raise ValueError("resample: t_ns must be strictly increasing (run repair_timestamps)")
    if max_gap_ns is None:
        max_gap_ns = bridge_limit_ns(t, g, gap_multiple)
    k0, k1, w, valid, exact = _bracket(t, g, max_gap_ns)
    out: dict[str, NDArray] = {}
    quat_cols = [c for c, m in methods.items() if m == "slerp"]
    for col, method in methods.items():
        if method not in METHODS:
            raise ValueError(f"resample: unknown method {method!r} for column {col!r}; "
                             f"choose from {METHODS}")
        if method == "slerp":
            continue
        if col not in df.columns or not len(t):
            out[col] = np.full(len(g), np.nan)
            continue
        x = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
        if method == "linear":
            y = x[k0] + w * (x[k1] - x[k0])
            y = np.where(exact | (w == 0.0), x[k0], y)
            y = np.where(valid, y, np.nan)
        elif method == "nearest":
            y = np.where(w < 0.5, x[k0], x[k1])
            y = np.where(valid, y, np.nan)
        elif method == "mean":
            lin = np.where(exact | (w == 0.0), x[k0], x[k0] + w * (x[k1] - x[k0]))
            y = _cell_mean(t, x, g)
            y = np.where(np.isfinite(y), y, lin)
            # NaN where linear interpolation gives NaN: the cell mean integrates the finite
            # samples only, so it drew a line across a run of missing values (a sensor's
            # implausible readings set to NaN) and filled it as if it had been measured
            y = np.where(valid & np.isfinite(lin), y, np.nan)
        else:  # previous: hold the last sample, at most max_gap after it
            k = np.searchsorted(t, g, side="right") - 1
            kc = np.clip(k, 0, len(t) - 1)
            ok = (k >= 0) & ((g - t[kc]) <= max_gap_ns)
            y = np.where(ok, x[kc], np.nan)
        out[col] = y
    if quat_cols:
        if sorted(quat_cols) != ["q_w", "q_x", "q_y", "q_z"]:
            raise ValueError(f"resample: slerp needs exactly q_w, q_x, q_y, q_z, got {quat_cols}")
        if all(c in df.columns for c in quat_cols) and len(t):
            q = df[["q_w", "q_x", "q_y", "q_z"]].to_numpy(dtype=np.float64, na_value=np.nan)
            norm = np.linalg.norm(q, axis=1, keepdims=True)
            q = quat_continuity(q / np.where(norm > 0, norm, np.nan))
            qq = quat_slerp(q[k0], q[k1], w)
            qq = np.where(exact[:, None], q[k0], qq)
            qq = np.where(valid[:, None], qq, np.nan)
        else:
            qq = np.full((len(g), 4), np.nan)
        for i, c in enumerate(("q_w", "q_x", "q_y", "q_z")):
            out[c] = qq[:, i]
    res = pd.DataFrame({c: out[c] for c in methods}, index=pd.RangeIndex(len(g)))
    return res, valid


def valid_segments(valid: Iterable[bool]) -> list[tuple[int, int]]:
    """Half-open index ranges ``[start, stop)`` of the runs of True in ``valid``."""
    v = np.asarray(valid, dtype=bool)
    if not len(v):
        return []
    dv = np.diff(np.concatenate([[0], v.astype(np.int8), [0]]))
    starts = np.flatnonzero(dv == 1)
    stops = np.flatnonzero(dv == -1)
    return list(zip(starts.tolist(), stops.tolist()))
