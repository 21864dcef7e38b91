"""Scalar anchors of a learned trajectory (seed 004 digest §9, §10 item 7) and DTW distances.

* **peak pitch** (deg) and the **longest time within a pitch band** (default 55–89°; the hover's
  learned pitch peaks at 83° and stays within 55–89° for 5.5 s);
* **cross-track RMS** (m): the RMS horizontal distance from the track's own least-squares
  straight line (principal axis of the east–north positions), for the learned trajectory and for
  each demo ("the learned track is straighter than any demo", level flight);
* the **RMS distance of the learned path to each demo** (m): every demo sample to its nearest
  learned sample (3-D, box frame);
* :func:`dtw_rms`: the RMS 3-D position distance of two trajectories along their DTW path.
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


def anchors(x: F64, dt: float, band_deg: Sequence[float] = (55.0, 89.0)) -> dict[str, float]:
    """Peak pitch, time within the pitch band and cross-track RMS of one ``(N, 13)`` trajectory."""
    x = np.asarray(x, dtype=np.float64)
    pitch = pitch_deg(x[:, 9:13])
    return {"peak_pitch_deg": float(np.nanmax(pitch)) if np.isfinite(pitch).any() else float("nan"),
            "time_in_band_s": longest_within(pitch, float(band_deg[0]), float(band_deg[1]), dt),
            "cross_track_rms_m": cross_track_rms(x[:, :3])}
