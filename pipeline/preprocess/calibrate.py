"""BPM (barometric altitude) calibration against a rangefinder, with automatic gating.

Seed 004 §6 step 3 calibrates the filtered barometric altitude with a piecewise-constant offset
``offset = sonar − BPM`` taken at hand-picked samples, the sonar counting as valid only at
0.17–6 m and near-level attitude. Here the points are chosen automatically: every rangefinder
sample is a candidate and is rejected, with the reason recorded, when

* ``range``: outside ``[min_range_m, max_range_m]`` or flagged invalid by the reader;
* ``orientation``: not facing down (MAV_SENSOR_ORIENTATION 25) where the source says so;
* ``tilt``: |roll| or |pitch| above ``max_tilt_deg`` (the beam no longer measures height);
* ``spike``: further than ``spike_m`` from the running median of its neighbours;
* ``rate``: changing faster than ``max_rate_mps`` (unstable reading);
* ``no_baro``: no barometric sample there;
* ``outlier``: rejected by the robust fit (residual beyond ``outlier_k`` robust σ).

The height reference is the tilt-compensated range :math:`h_{ref} = d\\cos\\phi\\cos\\theta`.
Accepted points are grouped into regions (split where consecutive points are more than
``region_gap_s`` apart, or where the offset steps by more than ``step_m`` (binary segmentation:
the barometer's error changes between flight phases, e.g. lag in a descent, ground effect on
landing), and runs longer than ``region_max_s`` cut into equal pieces); per region the offset :math:`o = h_{ref} - h_{baro}` is fitted as a
constant (a line when it alone spans ``min_drift_span_s``) by least squares with iterated MAD
outlier rejection. With ``drift`` and calibration points spanning ``min_drift_span_s``, one drift
rate :math:`\\dot o` is pooled from the within-region trends (fixed-effects regression) and
:math:`o_r(t) = \\bar o_r + \\dot o (t - \\bar t_r)`; between regions the offset is linearly
interpolated and beyond the first/last region extrapolated at :math:`\\dot o`. Without ``drift``
it is piecewise constant, switching halfway between regions (the thesis's scheme).
Then :math:`h_{cal}(t) = h_{baro}(t) + o(t)`.

Fallbacks: no usable rangefinder -> the GPS altitude above the NED origin is the reference
(method ``gps``, one region over the flight); no GPS either -> ``uncalibrated`` (the filtered
barometric altitude); no barometer -> method ``none`` and NaN.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..config import cfield
from ..io.schema import CALIBRATION  # noqa: F401  (declared with every table in io.schema)

_bpm = functools.partial(cfield, "preprocess.bpm")


@dataclass(frozen=True, kw_only=True)
class BPMConfig:
    """Gating and fitting thresholds (``preprocess.bpm`` in the dataset config); defaults from
    the config schema, built by ``pipeline.config.build`` (nested in ``PreprocessConfig``)."""

    min_range_m: float = _bpm("min_range_m")
    max_range_m: float = _bpm("max_range_m")
    max_tilt_deg: float = _bpm("max_tilt_deg")
    max_rate_mps: float = _bpm("max_rate_mps")
    spike_m: float = _bpm("spike_m")
    spike_window: int = _bpm("spike_window")
    outlier_k: float = _bpm("outlier_k")
    region_gap_s: float = _bpm("region_gap_s")
    region_max_s: float | None = _bpm("region_max_s")
    step_m: float | None = _bpm("step_m")
    min_points: int = _bpm("min_points")
    min_region_points: int = _bpm("min_region_points")
    drift: bool = _bpm("drift")
    min_drift_span_s: float = _bpm("min_drift_span_s")
    tilt_compensate: bool = _bpm("tilt_compensate")
    down_orientations: tuple[int, ...] = _bpm("down_orientations")
    gps_min_fix: int = _bpm("gps_min_fix")
    gps_fallback: bool = _bpm("gps_fallback")
    p0_Pa: float = _bpm("p0_Pa")


@dataclass
class Calibration:
    """Result of :func:`calibrate_baro`."""

    method: str
    alt_cal_m: NDArray[np.float64]
    points: pd.DataFrame
    regions: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def info(self) -> dict:
        return {"method": self.method, "regions": self.regions, "notes": self.notes,
                "n_candidates": int(len(self.points)),
                "n_used": int(self.points["used"].sum()) if len(self.points) else 0}


def pressure_altitude(p_Pa, p0_Pa: float = 101325.0):
    """International barometric formula (seed 004 eq. 4.4): ``44330 (1 − (p/p0)^(1/5.255))``."""
    return 44330.0 * (1.0 - (np.asarray(p_Pa, dtype=np.float64) / p0_Pa) ** (1.0 / 5.255))


def empty_points() -> pd.DataFrame:
    return pd.DataFrame({
        "t_ns": np.empty(0, np.int64), "h_ref_m": np.empty(0), "h_baro_m": np.empty(0),
        "offset_m": np.empty(0), "region": np.empty(0, np.int64), "used": np.empty(0, bool),
        "reason": pd.array([], dtype="string"), "method": pd.array([], dtype="string")})


def _interp_on_grid(t_grid: NDArray, y: NDArray, t: NDArray) -> NDArray:
    """Linear interpolation of a gridded signal (NaN in gaps propagates) at times ``t``."""
    if len(t_grid) == 0:
        return np.full(len(t), np.nan)
    k = np.clip(np.searchsorted(t_grid, t, side="right") - 1, 0, max(len(t_grid) - 2, 0))
    if len(t_grid) == 1:
        return np.where(t == t_grid[0], y[0], np.nan)
    t0, t1 = t_grid[k], t_grid[k + 1]
    w = (t - t0) / (t1 - t0)
    out = y[k] + w * (y[k + 1] - y[k])
    out = np.where(w == 0, y[k], out)
    return np.where((t >= t_grid[0]) & (t <= t_grid[-1]), out, np.nan)


def _robust_fit(t_s: NDArray, o: NDArray, linear: bool, k: float, max_iter: int = 10):
    """Least-squares constant or line with MAD-based rejection; returns (coef, t_ref, inliers)."""
    inl = np.ones(len(o), dtype=bool)
    t_ref = float(np.mean(t_s))
    coef = np.array([np.median(o), 0.0])
    for _ in range(max_iter):
        tt, oo = t_s[inl] - t_ref, o[inl]
        if linear and inl.sum() >= 3:
            A = np.c_[np.ones(len(tt)), tt]
            coef = np.linalg.lstsq(A, oo, rcond=None)[0]
        else:
            coef = np.array([np.mean(oo), 0.0])
        r = o - (coef[0] + coef[1] * (t_s - t_ref))
        med = np.median(r[inl])
        s = max(1.4826 * np.median(np.abs(r[inl] - med)), 0.02)
        new = np.abs(r) <= k * s
        if new.sum() < 2 or np.array_equal(new, inl):
            break
        inl = new
    return coef, t_ref, inl


def _offset_function(t_grid_s: NDArray, regions: list[dict], drift: bool) -> NDArray:
    """Evaluate the piecewise offset on the grid (see module docstring)."""
    o = np.full(len(t_grid_s), np.nan)
    if not regions:
        return o
    starts = np.array([r["t_start_s"] for r in regions])
    ends = np.array([r["t_end_s"] for r in regions])

    def val(r, t):
        return r["offset_m"] + r["drift_mps"] * (t - r["t_ref_s"])

    for r in regions:
        m = (t_grid_s >= r["t_start_s"]) & (t_grid_s <= r["t_end_s"])
        o[m] = val(r, t_grid_s[m])
    # beyond the first/last region the fitted drift continues (zero when not estimated)
    before, after = t_grid_s < starts[0], t_grid_s > ends[-1]
    o[before] = val(regions[0], t_grid_s[before])
    o[after] = val(regions[-1], t_grid_s[after])
    for a, b in zip(regions[:-1], regions[1:]):
        m = (t_grid_s > a["t_end_s"]) & (t_grid_s < b["t_start_s"])
        ya, yb = val(a, a["t_end_s"]), val(b, b["t_start_s"])
        if drift:
            w = (t_grid_s[m] - a["t_end_s"]) / (b["t_start_s"] - a["t_end_s"])
            o[m] = ya + w * (yb - ya)
        else:
            mid = 0.5 * (a["t_end_s"] + b["t_start_s"])
            o[m] = np.where(t_grid_s[m] <= mid, ya, yb)
    return o


def _change_points(o: NDArray, step_m: float, min_len: int) -> NDArray:
    """Binary segmentation of the offset series: split where the best two-mean split (largest
    reduction of the squared error) separates means by more than ``step_m``, recursively.
    Returns the start indices of the new pieces."""
    out: list[int] = []
    stack = [(0, len(o))]
    while stack:
        a, b = stack.pop()
        x = o[a:b]
        n = len(x)
        if n < 2 * min_len:
            continue
        c = np.cumsum(x)
        k = np.arange(min_len, n - min_len + 1)
        m1 = c[k - 1] / k
        m2 = (c[-1] - c[k - 1]) / (n - k)
        gain = k * (n - k) / n * (m1 - m2) ** 2
        j = int(np.argmax(gain))
        # the step must also be significant against the scatter (z > 5 on the mean difference)
        resid = np.concatenate([x[:k[j]] - m1[j], x[k[j]:] - m2[j]])
        sig = 1.4826 * np.median(np.abs(resid)) * np.sqrt(1.0 / k[j] + 1.0 / (n - k[j]))
        if abs(m1[j] - m2[j]) > max(step_m, 5.0 * sig):
            out.append(a + int(k[j]))
            stack += [(a, a + int(k[j])), (a + int(k[j]), b)]
    return np.array(sorted(out), dtype=np.int64)


def _fit_regions(t_ns: NDArray, offset: NDArray, ok: NDArray, cfg: BPMConfig, gap_s: float | None,
                 h_ref: NDArray | None = None) -> tuple[list[dict], NDArray, NDArray]:
    """Group accepted points into regions and fit each; returns (regions, region id, inliers)."""
    region = np.full(len(t_ns), -1, dtype=np.int64)
    inlier = np.zeros(len(t_ns), dtype=bool)
    idx = np.flatnonzero(ok)
    regions: list[dict] = []
    if not len(idx):
        return regions, region, inlier
    t_s = t_ns[idx] * 1e-9
    brk = np.flatnonzero(np.diff(t_s) > gap_s) if gap_s is not None else np.empty(0, int)
    if cfg.step_m:
        brk = np.union1d(brk, _change_points(offset[idx], cfg.step_m, cfg.min_region_points) - 1)
    brk = brk + 1
    groups = []
    for grp in np.split(np.arange(len(idx)), brk):
        span = t_s[grp[-1]] - t_s[grp[0]]
        if cfg.region_max_s and span > cfg.region_max_s:
            # long runs are cut into equal pieces: the barometer's error is not constant over
            # a climb or a landing (lag, ground effect), so a local offset tracks it
            k = int(np.ceil(span / cfg.region_max_s))
            edges = t_s[grp[0]] + span * np.arange(1, k) / k
            groups.extend(g for g in np.split(grp, np.searchsorted(t_s[grp], edges)) if len(g))
        else:
            groups.append(grp)
    for grp in groups:
        if len(grp) < cfg.min_region_points:
            continue
        ii = idx[grp]
        ts = t_ns[ii] * 1e-9
        linear = cfg.drift and (ts[-1] - ts[0]) >= cfg.min_drift_span_s
        coef, t_ref, inl = _robust_fit(ts, offset[ii], linear, cfg.outlier_k)
        rid = len(regions)
        region[ii[inl]] = rid
        inlier[ii[inl]] = True
        regions.append({"region": rid, "t_start_s": float(ts[inl][0]), "t_end_s": float(ts[inl][-1]),
                        "t_ref_s": t_ref, "offset_m": float(coef[0]), "drift_mps": float(coef[1]),
                        "n_points": int(inl.sum()),
                        "rms_m": float(np.sqrt(np.mean((offset[ii][inl] - coef[0] - coef[1] * (ts[inl] - t_ref)) ** 2)))})
    if cfg.drift and regions and regions[-1]["t_end_s"] - regions[0]["t_start_s"] >= cfg.min_drift_span_s:
        # one drift rate for the flight, pooled from the within-region trends (fixed-effects
        # regression: steps between regions do not bias it):
        # b = sum_r sum_i (t_i - tbar_r)(o_i - obar_r) / sum_r sum_i (t_i - tbar_r)^2
        num = den = 0.0
        for r in regions:
            m = region == r["region"]
            ts, oo = t_ns[m] * 1e-9, offset[m]
            num += float(np.sum((ts - ts.mean()) * (oo - oo.mean())))
            den += float(np.sum((ts - ts.mean()) ** 2))
        if den > 0:
            b = num / den
            for r in regions:
                m = region == r["region"]
                ts, oo = t_ns[m] * 1e-9, offset[m]
                r.update(t_ref_s=float(ts.mean()), offset_m=float(oo.mean()), drift_mps=b,
                         rms_m=float(np.sqrt(np.mean((oo - oo.mean() - b * (ts - ts.mean())) ** 2))))
    return regions, region, inlier


def _rangefinder_points(t_grid, baro, rf: pd.DataFrame, roll, pitch, cfg: BPMConfig) -> pd.DataFrame:
    t = rf["t_ns"].to_numpy(dtype=np.int64)
    dist = pd.to_numeric(rf["dist_m"], errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
    n = len(t)
    reason = np.full(n, "ok", dtype=object)
    valid_col = rf["valid"] if "valid" in rf.columns else pd.Series(pd.NA, index=rf.index)
    flagged_bad = valid_col.fillna(True).astype(bool).to_numpy() == False  # noqa: E712
    in_range = np.isfinite(dist) & (dist >= cfg.min_range_m) & (dist <= cfg.max_range_m) & ~flagged_bad
    reason[~in_range] = "range"
    if "orientation" in rf.columns:
        ori = pd.to_numeric(rf["orientation"], errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
        bad_ori = np.isfinite(ori) & ~np.isin(ori, cfg.down_orientations)
        reason[(reason == "ok") & bad_ori] = "orientation"
    hb = _interp_on_grid(t_grid, baro, t)
    tilt_cos = np.ones(n)
    if roll is not None and pitch is not None:
        r = _interp_on_grid(t_grid, roll, t)
        p = _interp_on_grid(t_grid, pitch, t)
        tilted = ~(np.isfinite(r) & np.isfinite(p)) | (np.maximum(np.abs(r), np.abs(p)) > np.radians(cfg.max_tilt_deg))
        reason[(reason == "ok") & tilted] = "tilt"
        if cfg.tilt_compensate:
            tilt_cos = np.where(np.isfinite(r) & np.isfinite(p), np.cos(r) * np.cos(p), 1.0)
    # stability: each in-range reading against the running median of all its time neighbours
    # (an isolated in-range reading among out-of-range ones is a spike, not a calibration point)
    fin = np.flatnonzero(np.isfinite(dist))
    med = np.full(n, np.nan)
    med[fin] = pd.Series(dist[fin]).rolling(cfg.spike_window, center=True, min_periods=1).median().to_numpy()
    spike = in_range & (np.abs(dist - med) > cfg.spike_m)
    reason[(reason == "ok") & spike] = "spike"
    keep = np.flatnonzero(in_range & ~spike)
    if len(keep) >= 2:
        rate = np.abs(np.gradient(dist[keep], t[keep] * 1e-9))
        sel = keep[rate > cfg.max_rate_mps]
        reason[sel[reason[sel] == "ok"]] = "rate"
    reason[(reason == "ok") & ~np.isfinite(hb)] = "no_baro"
    h_ref = dist * tilt_cos
    return pd.DataFrame({"t_ns": t, "h_ref_m": h_ref, "h_baro_m": hb, "offset_m": h_ref - hb,
                         "region": np.full(n, -1, np.int64), "used": np.zeros(n, bool),
                         "reason": pd.array(reason.astype(str), dtype="string"),
                         "method": pd.array(["rangefinder"] * n, dtype="string")})


def calibrate_baro(t_grid_ns, baro_alt_m, *, rangefinder: pd.DataFrame | None = None,
                   roll_rad=None, pitch_rad=None, gps_t_ns=None, gps_up_m=None,
                   cfg: BPMConfig | None = None) -> Calibration:
    """Calibrate a gridded, filtered barometric altitude (positive up) to a height reference.

    Parameters
    ----------
    t_grid_ns : ndarray of int64, shape (n,)
        The grid of ``baro_alt_m``, ``roll_rad``, ``pitch_rad``.
    baro_alt_m : ndarray, shape (n,)
        Filtered barometric altitude on the grid (NaN in gaps); all-NaN or ``None``: no barometer.
    rangefinder : DataFrame, optional
        Repaired down-facing rangefinder samples (``t_ns``, ``dist_m``, ``valid``, ``orientation``).
    roll_rad, pitch_rad : ndarray, optional
        Attitude on the grid, for gating and tilt compensation.
    gps_t_ns, gps_up_m : ndarray, optional
        GPS samples (3D fix or better) and their altitude above the NED origin, for the fallback.
    cfg : BPMConfig

    Returns
    -------
    Calibration
        ``alt_cal_m`` on the grid, the candidate points with use/reject reasons, the regions
        (``offset_m``, ``drift_mps``, span, ``n_points``) and the method.
    """
    cfg = cfg or BPMConfig()
    t_grid = np.asarray(t_grid_ns, dtype=np.int64)
    n = len(t_grid)
    baro = None if baro_alt_m is None else np.asarray(baro_alt_m, dtype=np.float64)
    if baro is None or not np.any(np.isfinite(baro)):
        return Calibration("none", np.full(n, np.nan), empty_points(), notes=["no barometer"])
    notes = []
    tg_s = t_grid * 1e-9
    if rangefinder is not None and len(rangefinder):
        if roll_rad is None or pitch_rad is None:
            notes.append("no attitude: tilt gate and compensation skipped")
        pts = _rangefinder_points(t_grid, baro, rangefinder, roll_rad, pitch_rad, cfg)
        ok = (pts["reason"] == "ok").to_numpy()
        if ok.sum() >= cfg.min_points:
            regions, region, inl = _fit_regions(pts["t_ns"].to_numpy(), pts["offset_m"].to_numpy(),
                                                ok, cfg, cfg.region_gap_s, pts["h_ref_m"].to_numpy())
            if inl.sum() >= cfg.min_points and regions:
                reason = pts["reason"].to_numpy(dtype=object)
                reason[ok & ~inl] = "outlier"
                pts = pts.assign(region=region, used=inl, reason=pd.array(reason.astype(str), dtype="string"))
                o = _offset_function(tg_s, regions, cfg.drift)
                return Calibration("rangefinder", baro + o, pts, regions, notes)
        notes.append(f"rangefinder: only {int(ok.sum())} usable point(s) (< {cfg.min_points})")
    else:
        notes.append("no rangefinder")
    if cfg.gps_fallback and gps_t_ns is not None and len(gps_t_ns):
        gt = np.asarray(gps_t_ns, dtype=np.int64)
        gu = np.asarray(gps_up_m, dtype=np.float64)
        hb = _interp_on_grid(t_grid, baro, gt)
        ok = np.isfinite(gu) & np.isfinite(hb)
        pts = pd.DataFrame({"t_ns": gt, "h_ref_m": gu, "h_baro_m": hb, "offset_m": gu - hb,
                            "region": np.full(len(gt), -1, np.int64), "used": np.zeros(len(gt), bool),
                            "reason": pd.array(np.where(ok, "ok", np.where(np.isfinite(gu), "no_baro", "range")).astype(str), dtype="string"),
                            "method": pd.array(["gps"] * len(gt), dtype="string")})
        if ok.sum() >= cfg.min_points:
            # GPS altitude is continuous but noisy: one region over the whole flight. The
            # rangefinder's region splitting (offset steps, region_max_s pieces) would follow the
            # GPS vertical error piece by piece (38 pieces and 5 m/s offset steps on a real log)
            one = replace(cfg, step_m=None, region_max_s=None)
            regions, region, inl = _fit_regions(gt, pts["offset_m"].to_numpy(), ok, one, None)
            if regions:
                reason = pts["reason"].to_numpy(dtype=object)
                reason[ok & ~inl] = "outlier"
                pts = pts.assign(region=region, used=inl, reason=pd.array(reason.astype(str), dtype="string"))
                o = _offset_function(tg_s, regions, cfg.drift)
                return Calibration("gps", baro + o, pts, regions, notes)
        notes.append("gps: too few samples with a fix")
    return Calibration("uncalibrated", baro.copy(), empty_points(), notes=notes)
