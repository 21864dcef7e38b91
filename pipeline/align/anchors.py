"""Scalar anchors of a learned trajectory (seed 004 digest §9, §10 item 7) and DTW distances.

* **peak pitch** (deg) and the **longest time within a pitch band** (default 55–89°; the hover's
  learned pitch peaks at 83° and stays within 55–89° for 5.5 s);
* **cross-track RMS** (m): the RMS horizontal distance from the track's own least-squares
  straight line (principal axis of the east–north positions), for the learned trajectory and for
  each demo ("the learned track is straighter than any demo", level flight);
* the **RMS distance of the learned path to each demo** (m): every demo sample to its nearest
  learned sample (3-D, box frame);
* :func:`dtw_rms`: the RMS 3-D position distance of two trajectories along their DTW path;
  :func:`dense_dtw_rms` the same between the two paths as curves (:func:`densify` first), so that
  it does not depend on how densely, or with what phase, either one is sampled.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from ..frames.rotations import quat_to_euler

F64 = NDArray[np.float64]


def pitch_deg(q: F64) -> F64:
    """ZYX pitch (deg) of body→frame quaternions ``(N, 4)`` (scalar first)."""
    q = np.asarray(q, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):  # a zero quaternion reads NaN
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        return np.degrees(quat_to_euler(q)[1])


def longest_within(x: F64, lo: float, hi: float, dt: float) -> float:
    """Longest contiguous time (s) with ``lo <= x <= hi`` on a grid of step ``dt``."""
    inside = (np.asarray(x) >= lo) & (np.asarray(x) <= hi)
    best = run = 0
    for v in inside:
        run = run + 1 if v else 0
        best = max(best, run)
    return best * float(dt)


def cross_track_rms(pos: F64) -> float:
    """RMS horizontal distance (m) of positions ``(N, >=2)`` from their principal straight line."""
    p = np.asarray(pos, dtype=np.float64)[:, :2]
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) < 2:
        return float("nan")
    c = p - p.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    return float(np.sqrt(np.mean((c @ vt[1]) ** 2)))


def nearest_rms(path: F64, points: F64) -> float:
    """RMS over ``points`` of the 3-D distance to the nearest sample of ``path`` (m)."""
    a = np.asarray(path, dtype=np.float64)[:, :3]
    b = np.asarray(points, dtype=np.float64)[:, :3]
    d2 = ((b[:, None, :] - a[None, :, :]) ** 2).sum(axis=2).min(axis=1)
    return float(np.sqrt(d2.mean()))


def dtw_rms(a: F64, b: F64, path: NDArray[np.int64]) -> float:
    """RMS 3-D position distance (m) of ``a`` and ``b`` along a DTW ``path`` ``(K, 2)``."""
    p = np.asarray(path, dtype=np.int64)
    d = np.asarray(a, dtype=np.float64)[p[:, 0], :3] - np.asarray(b, dtype=np.float64)[p[:, 1], :3]
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


#: spacing (m) of :func:`densify` in :func:`dense_dtw_rms`
DENSE_STEP_M = 0.5


def densify(pos: F64, step_m: float = DENSE_STEP_M) -> F64:
    """Positions ``(N, >=3)`` as a polyline with points at most ``step_m`` apart: every segment
    of the track is split into ``ceil(length / step_m)`` equal parts (the samples are kept)."""
    p = np.asarray(pos, dtype=np.float64)[:, :3]
    if len(p) < 2:
        return p.copy()
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    parts = np.maximum(1, np.ceil(seg / float(step_m)).astype(np.int64))
    knots = np.concatenate([[0], np.cumsum(parts)]).astype(np.float64)
    s = np.interp(np.arange(knots[-1] + 1), knots, np.arange(len(p), dtype=np.float64))
    i = np.minimum(np.floor(s).astype(np.int64), len(p) - 2)
    w = (s - i)[:, None]
    return (1.0 - w) * p[i] + w * p[i + 1]


def dense_dtw_rms(a: F64, b: F64, step_m: float = DENSE_STEP_M) -> float:
    """RMS 3-D position distance (m) of two trajectories along their DTW path (symmetric2,
    squared Euclidean cost), both first :func:`densify`-ed to ``step_m``.

    On the demos' own samples (3 Hz at ~28 m/s: 9 m apart) the DTW path pairs samples that are
    up to half a spacing apart even for one path sampled twice: a trajectory with other sample
    times (the learned one on its τ-warped hidden axis) reads 3-5 m away from the demo it was
    learned from. As curves, the RMS is that of the paths, whatever their sampling.
    """
    from .dtw import dtw  # noqa: PLC0415 (kept lazy: numba compiles on first use)

    x, y = densify(a, step_m), densify(b, step_m)
    return dtw_rms(x, y, dtw(x, y, step_pattern="symmetric2").path)


def anchors(x: F64, dt: float, band_deg: Sequence[float] = (55.0, 89.0)) -> dict[str, float]:
    """Peak pitch, time within the pitch band and cross-track RMS of one ``(N, 13)`` trajectory."""
    x = np.asarray(x, dtype=np.float64)
    pitch = pitch_deg(x[:, 9:13])
    return {"peak_pitch_deg": float(np.nanmax(pitch)) if np.isfinite(pitch).any() else float("nan"),
            "time_in_band_s": longest_within(pitch, float(band_deg[0]), float(band_deg[1]), dt),
            "cross_track_rms_m": cross_track_rms(x[:, :3])}
