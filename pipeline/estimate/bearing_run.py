"""Bearing-only replay of two real flights (issue 16, seed 002 §12 item 5: the FT10/50 recipe).

One *pair* of ``estimate.bearing_only.replay`` names an ownship and an intruder flight of the
manifest. :func:`synthesise_pair` builds the encounter from their tracks:

* **tracks**: the ownship's ingest ``local_position`` stream (NED about its origin; DataFlash
  ``NTUN``) where it has samples, else its preprocessed ``state`` track (GPS-derived); the
  intruder's ``state`` track. The ownship velocity is always the ``state``'s ``vel_n/e``.
* **common origin**: both tracks are taken in their own NED frames about their own origins and
  the intruder's is shifted by ``offset_m`` (N, E): the pair's flights were flown at different
  sites, so the common origin is the ownship's and the geometry is the configured one.
* **time**: ownship time since its first sample ``t``; the intruder is interpolated (linearly) at
  its own ``t + t_offset_s``; the span is the first ``duration_s`` where both exist, thinned to
  at most ``rate_hz`` bearings per second; the step T varies with the timestamps (D9).
* **bearings**: ``β = atan2(ΔE, ΔN) + bias + N(0, σ_β²)`` from
  ``default_rng([seed, crc32("bearing"), crc32(pair)])``, written as a ``bearing`` stream
  (``src`` ``synthetic``) in memory.
* **truth** (for the scores): ``r = Δ_NE``, ``v = |v_i|``, ``θ = atan2(v_E, v_N)`` and
  ``ω = dθ/dt``, Butterworth-filtered (3rd order, 0.5 Hz, zero phase).

:func:`run_bearing_replay` then runs the CPPV bank, the MPC bank and the CV/CT IMM
(``estimate.bank``/``estimate.imm``, the pair's ``preset``) and writes
``results/estimate/{bank_cppv,bank_mpc,imm}/<pair>.parquet`` (``io.schema`` table
``bearing_estimate``) with the bank weights beside each in ``<pair>.weights.parquet``
(``bearing_weights``, every ``weights_every_s``). A pair whose flight is missing (no real logs
under ``../shared``) writes empty tables with ``status: skipped`` and the reason, and prints one
notice: the main job goes on. The page ``results/report/bearing/<pair>.html`` is the report
stage's (:func:`pipeline.report.bearing.run_bearing_report` runs this replay with its page
writer as ``write_page``): estimate does not import report.

Scores (printed as ``RESULT`` lines and kept in the metadata): the heading convergence time
(the first time after which the combined course 1-sigma stays below 30°, digest §8) and the
relative range error at 60 s.
"""

from __future__ import annotations

import sys
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..io import schema
from ..io.parquet import read_table, write_table
from ..io.stage import declared
from .models import wrap_angle
from .table import upper_triangle

F64 = NDArray[np.float64]

#: the replay's estimators, one output folder each
ESTIMATORS: tuple[str, ...] = ("bank_cppv", "bank_mpc", "imm")
#: heading convergence: the course 1-sigma below this (digest §8, flight tests)
CONVERGED_SIGMA_DEG = 30.0


class BearingReplayError(ValueError):
    """A pair cannot be replayed (missing flight, no overlap); the message names it."""


@dataclass(frozen=True)
class BearingPair:
    """A synthesised encounter of two flights (arrays over K bearing times).

    Attributes
    ----------
    t_ns : ndarray (K,)
        Bearing times, ns since the ownship's first sample.
    ownship_pos, ownship_vel, intruder_pos, intruder_vel : ndarray (K, 2)
        NED (N, E) about the common origin (m, m/s).
    bearing, bearing_true : ndarray (K,)
        Measured and true bearing (rad).
    sigma_rad : float
        Bearing noise 1-sigma.
    truth : ndarray (K, 5)
        Relative CPPV truth ``[r_N, r_E, v, θ, ω]``.
    meta : dict
        Sources and settings.
    """

    t_ns: NDArray[np.int64]
    ownship_pos: F64
    ownship_vel: F64
    intruder_pos: F64
    intruder_vel: F64
    bearing: F64
    bearing_true: F64
    sigma_rad: float
    truth: F64
    meta: dict = field(default_factory=dict)

    @property
    def t_s(self) -> F64:
        return (self.t_ns - self.t_ns[0]) / 1e9

    def bearing_stream(self) -> pd.DataFrame:
        """The bearings as a canonical ``bearing`` stream (observer instance 0)."""
        n = len(self.t_ns)
        return schema.conform("bearing", pd.DataFrame({
            "t_ns": self.t_ns, "instance": np.zeros(n, np.uint8), "src": "synthetic",
            "az_rad": self.bearing, "sigma_rad": np.full(n, self.sigma_rad)}))


@dataclass(frozen=True)
class BearingReplayResult:
    """What :func:`run_bearing_replay` did: ``status`` ``ok``/``skipped``/``failed``, the reason,
    the scores per estimator and the diagnostics."""

    status: str
    reason: str | None = None
    scores: dict[str, dict[str, float]] = field(default_factory=dict)
    diagnostics: dict[str, Any] = field(default_factory=dict)


def _say(msg: str) -> None:
    print(f"uavpipe: bearing replay: {msg}", file=sys.stderr, flush=True)


def pair_rng(seed: int, pair: str) -> np.random.Generator:
    """The bearing noise of one pair: ``default_rng([seed, crc32("bearing"), crc32(pair)])``."""
    return np.random.default_rng([int(seed), zlib.crc32(b"bearing"), zlib.crc32(pair.encode())])


def _track(df: pd.DataFrame | None, what: str) -> pd.DataFrame | None:
    if df is None or len(df) == 0:
        return None
    need = ["t_ns", "pos_n_m", "pos_e_m", "vel_n_mps", "vel_e_mps"]
    miss = [c for c in need if c not in df.columns]
    if miss:
        raise BearingReplayError(f"{what}: no column(s) {miss}")
    d = df[need].dropna()
    d = d[np.r_[True, np.diff(d["t_ns"].to_numpy()) > 0]]
    return d if len(d) >= 2 else None


def _thin(t_s: F64, rate_hz: float) -> NDArray[np.intp]:
    """Indices of samples at least ``1/rate_hz`` apart (the first always kept)."""
    keep, last, gap = [], -np.inf, 1.0 / rate_hz - 1e-9
    for i, t in enumerate(t_s):
        if t - last >= gap:
            keep.append(i)
            last = t
    return np.asarray(keep, dtype=np.intp)


def truth_turn_rate(t_s: F64, course: F64, *, cutoff_hz: float = 0.5) -> F64:
    """``ω = dθ/dt`` of a course history (unwrapped, central differences on the variable
    grid), low-passed by a zero-phase 3rd-order Butterworth at the median rate."""
    from ..preprocess.filters import butterworth

    w = np.gradient(np.unwrap(course), t_s)
    fs = 1.0 / float(np.median(np.diff(t_s)))
    if len(w) < 20 or cutoff_hz >= fs / 2:
        return w
    y, _ = butterworth(w, fs, order=3, cutoff_hz=cutoff_hz)
    return np.where(np.isfinite(y), y, w)


def synthesise_pair(ownship: pd.DataFrame, intruder: pd.DataFrame, *, pair: str, seed: int,
                    offset_m=(3000.0, 0.0), t_offset_s: float = 0.0, duration_s: float = 180.0,
                    rate_hz: float = 10.0, sigma_bearing_deg: float = 0.2, bias_deg: float = 0.0,
                    ownship_vel: pd.DataFrame | None = None) -> BearingPair:
    """Bearings from the ownship to the intruder (module docstring: the recipe).

    Parameters
    ----------
    ownship, intruder : DataFrame
        Tracks with ``t_ns``, ``pos_n_m``, ``pos_e_m``, ``vel_n_mps``, ``vel_e_mps`` (NED about
        each flight's own origin).
    ownship_vel : DataFrame, optional
        Where the ownship velocity comes from (the ``state`` track) when ``ownship`` is the
        ``local_position`` stream; default ``ownship`` itself.
    pair, seed : str, int
        Name the noise stream (:func:`pair_rng`).
    offset_m, t_offset_s, duration_s, rate_hz, sigma_bearing_deg, bias_deg
        The pair's settings (``estimate.bearing_only.replay.<pair>``).
    """
    own = _track(ownship, f"pair {pair}: ownship track")
    intr = _track(intruder, f"pair {pair}: intruder track")
    if own is None or intr is None:
        raise BearingReplayError(f"pair {pair}: {'ownship' if own is None else 'intruder'} track is empty")
    vel = _track(ownship_vel, f"pair {pair}: ownship state") if ownship_vel is not None else own
    to = (own["t_ns"].to_numpy() - own["t_ns"].iat[0]) / 1e9
    ti = (intr["t_ns"].to_numpy() - intr["t_ns"].iat[0]) / 1e9
    tq = to + t_offset_s                                        # intruder time of each ownship sample
    ok = (tq >= ti[0]) & (tq <= ti[-1]) & (to <= to[0] + duration_s)
    if ok.sum() < 10:
        raise BearingReplayError(f"pair {pair}: the flights overlap in fewer than 10 samples "
                                 f"(t_offset_s {t_offset_s}, intruder span {ti[-1]:.0f} s)")
    idx = np.flatnonzero(ok)
    idx = idx[_thin(to[idx], rate_hz)]
    t, tqi = to[idx], tq[idx]
    opos = own[["pos_n_m", "pos_e_m"]].to_numpy()[idx]
    tv = (vel["t_ns"].to_numpy() - own["t_ns"].iat[0]) / 1e9
    ovel = np.stack([np.interp(t, tv, vel[c].to_numpy()) for c in ("vel_n_mps", "vel_e_mps")], axis=1)
    ipos = np.stack([np.interp(tqi, ti, intr[c].to_numpy()) for c in ("pos_n_m", "pos_e_m")], axis=1)
    ipos = ipos + np.asarray(offset_m, dtype=np.float64)[None, :]
    ivel = np.stack([np.interp(tqi, ti, intr[c].to_numpy()) for c in ("vel_n_mps", "vel_e_mps")], axis=1)
    rel = ipos - opos
    beta = np.arctan2(rel[:, 1], rel[:, 0])
    sig = sigma_bearing_deg * np.pi / 180
    z = wrap_angle(beta + bias_deg * np.pi / 180 + sig * pair_rng(seed, pair).standard_normal(len(t)))
    course = np.arctan2(ivel[:, 1], ivel[:, 0])
    truth = np.column_stack([rel, np.hypot(ivel[:, 0], ivel[:, 1]), course, truth_turn_rate(t, course)])
    t_ns = np.round(t * 1e9).astype(np.int64)
    meta = {"pair": pair, "offset_m": [float(x) for x in offset_m], "t_offset_s": float(t_offset_s),
            "duration_s": float(duration_s), "rate_hz": float(rate_hz), "sigma_bearing_deg": float(sigma_bearing_deg),
            "bias_deg": float(bias_deg), "n_bearings": int(len(t)),
            "median_dt_s": float(np.median(np.diff(t))) if len(t) > 1 else None,
            "truth_omega": "d(course)/dt, Butterworth 3rd order 0.5 Hz zero phase",
            "noise_seed": f"default_rng([{int(seed)}, crc32('bearing'), crc32({pair!r})])"}
    return BearingPair(t_ns=t_ns, ownship_pos=opos, ownship_vel=ovel, intruder_pos=ipos, intruder_vel=ivel,
                       bearing=z, bearing_true=beta, sigma_rad=sig, truth=truth, meta=meta)


# --------------------------------------------------------------------------------------------
# scores


def heading_converged_s(t_s: F64, course_sigma_rad: F64, limit_deg: float = CONVERGED_SIGMA_DEG) -> float:
    """First time after which the course 1-sigma stays below ``limit_deg`` (NaN if never)."""
    above = ~(np.asarray(course_sigma_rad) < limit_deg * np.pi / 180)
    if above[-1]:
        return float("nan")
    k = np.flatnonzero(above)
    return float(t_s[0] if len(k) == 0 else t_s[min(k[-1] + 1, len(t_s) - 1)])


def range_error_pct_at(t_s: F64, est_range: F64, true_range: F64, at_s: float = 60.0) -> float:
    """Relative range error |r̂ − r|/r (%) at the step nearest ``at_s`` (NaN past the end)."""
    if t_s[-1] < at_s - 1.0:
        return float("nan")
    k = int(np.argmin(np.abs(t_s - at_s)))
    return float(100.0 * abs(est_range[k] - true_range[k]) / true_range[k])


# --------------------------------------------------------------------------------------------
# tables


def estimate_table(t_ns: NDArray[np.int64], mean: F64, cov: F64, *, nis: F64 | None = None,
                   mode_p: F64 | None = None, n_diverged: NDArray | None = None) -> pd.DataFrame:
    """A ``bearing_estimate`` table from CPPV means (K, 5) and covariances (K, 5, 5)."""
    k = len(t_ns)
    names = [c.name for c in schema.BEARING_ESTIMATE[1:6]]
    r = np.hypot(mean[:, 0], mean[:, 1])
    g = mean[:, :2] / np.where(r > 0, r, 1.0)[:, None]
    var_r = np.einsum("ki,kij,kj->k", g, cov[:, :2, :2], g)
    df = pd.DataFrame({"t_ns": np.asarray(t_ns, np.int64), **{n: mean[:, i] for i, n in enumerate(names)},
                       **upper_triangle(cov, 5), "range_m": r, "range_sigma_m": np.sqrt(np.maximum(var_r, 0.0)),
                       "nis": np.full(k, np.nan) if nis is None else nis,
                       "mode_p_cv": np.full(k, np.nan) if mode_p is None else mode_p[:, 0],
                       "mode_p_ct": np.full(k, np.nan) if mode_p is None else mode_p[:, 1],
                       "n_diverged": np.zeros(k, np.int64) if n_diverged is None else np.asarray(n_diverged, np.int64)})
    return df[[c.name for c in schema.BEARING_ESTIMATE]]


def weights_table(t_ns: NDArray[np.int64], weights: F64, grid: F64, every_s: float) -> pd.DataFrame:
    """A long ``bearing_weights`` table: weights (K, N) at steps ``every_s`` apart; ``grid`` (N, 3)
    the filters' initial (range, course, turn rate)."""
    t_s = (np.asarray(t_ns) - t_ns[0]) / 1e9
    keep = _thin(t_s, 1.0 / every_s) if len(t_s) else np.zeros(0, np.intp)
    n = weights.shape[1]
    return pd.DataFrame({"t_ns": np.repeat(np.asarray(t_ns, np.int64)[keep], n),
                         "filter": np.tile(np.arange(n, dtype=np.int64), len(keep)),
                         "weight": weights[keep].ravel(),
                         "r0_m": np.tile(grid[:, 0], len(keep)), "course0_rad": np.tile(grid[:, 1], len(keep)),
                         "omega0_radps": np.tile(grid[:, 2], len(keep))})


def output_paths(outputs: Mapping | Any, pair: str) -> dict[str, Path]:
    """The declared outputs ``{bank_cppv, bank_cppv_weights, ..., page}`` (default: under
    ``results/``)."""
    out = {}
    for e in ESTIMATORS:
        out[e] = Path(declared(outputs, e, f"results/estimate/{e}/{pair}.parquet"))
        out[f"{e}_weights"] = Path(declared(outputs, f"{e}_weights", f"results/estimate/{e}/{pair}.weights.parquet"))
    out["page"] = Path(declared(outputs, "page", f"results/report/bearing/{pair}.html"))
    return out


def _placeholders(paths: Mapping[str, Path], extra: dict) -> None:
    for e in ESTIMATORS:
        write_table(schema.empty("bearing_estimate"), paths[e], schema.BEARING_ESTIMATE, name="bearing_estimate",
                    extra={**extra, "estimator": e})
        write_table(schema.empty("bearing_weights"), paths[f"{e}_weights"], schema.BEARING_WEIGHTS,
                    name="bearing_weights", extra={**extra, "estimator": e})


def _read_track(path) -> pd.DataFrame | None:
    if path is None or not Path(str(path)).is_file():
        return None
    return read_table(path)


#: ``write_page(path, pair, pair_or_None, tracks, reason, info)``: writes the pair's page
#: (:func:`pipeline.report.bearing.build_bearing_page`); ``info`` holds the pair's settings,
#: flights, track source and ``status``
PageWriter = Callable[[Path, str, "BearingPair | None", Mapping[str, "BearingTrack"], "str | None", dict], None]


def run_bearing_replay(inputs: Mapping | Any, outputs: Mapping | Any, config: Mapping | None, *, pair: str,
                       seed: int = 0, write_page: PageWriter | None = None, **_job) -> BearingReplayResult:
    """Replay one pair of ``estimate.bearing_only.replay`` (module docstring).

    Parameters
    ----------
    inputs : mapping
        ``ownship_state``, ``intruder_state`` (preprocess ``state`` tables) and optionally
        ``ownship_local_position`` (the ownship's ingest ``local_position`` stream). A missing
        or absent input skips the pair (placeholders, one notice).
    outputs : mapping
        ``bank_cppv``, ``bank_mpc``, ``imm`` and their ``*_weights``, ``page``.
    config : mapping
        The ``estimate.bearing_only`` section (validated: ``replay``, ``bank``, ``imm``, ``gate``).
    pair : str
        The pair's name (a key of ``config['replay']``).
    seed : int
        Master seed (bearing noise).
    write_page : callable, optional
        Writes ``outputs.page`` (:data:`PageWriter`; the report stage passes its own); without
        it no page is written.
    """
    from ..config import validate_section

    def page(bp: BearingPair | None, tracks: Mapping[str, BearingTrack], reason: str | None, info: dict) -> None:
        if write_page is not None:
            write_page(paths["page"], pair, bp, tracks, reason, info)

    cfg = validate_section("estimate.bearing_only", dict(config or {}))
    paths = output_paths(outputs, pair)
    if pair not in cfg["replay"]:
        raise BearingReplayError(f"estimate.bearing_only.replay: no pair {pair!r} (pairs: {', '.join(cfg['replay'])})")
    spec = cfg["replay"][pair]
    base = {"pair": pair, "ownship": spec["ownship"], "intruder": spec["intruder"], "settings": spec}
    own_p, intr_p = declared(inputs, "ownship_state"), declared(inputs, "intruder_state")
    missing = [f"{spec[k]} ({k})" for k, p in (("ownship", own_p), ("intruder", intr_p))
               if p is None or not Path(str(p)).is_file()]
    if missing:
        reason = f"flight(s) {', '.join(missing)} not available (no real logs under realdata_dir?)"
        _say(f"skipping pair {pair}: {reason}")
        _placeholders(paths, {**base, "status": "skipped", "error": reason})
        page(None, {}, reason, {**base, "status": "skipped"})
        return BearingReplayResult(status="skipped", reason=reason, diagnostics=base)
    state = _read_track(own_p)
    lp = _read_track(declared(inputs, "ownship_local_position"))
    lp = lp if lp is not None and len(lp) and lp[["pos_n_m", "pos_e_m"]].notna().any().all() else None
    try:
        opts = {k: v for k, v in spec.items()
                if k not in ("ownship", "intruder", "preset", "mpc_preset", "weights_every_s")}
        bp = synthesise_pair(lp if lp is not None else state, _read_track(intr_p), pair=pair, seed=seed,
                             ownship_vel=state, **opts)
    except BearingReplayError as exc:
        _say(f"skipping pair {pair}: {exc}")
        _placeholders(paths, {**base, "status": "failed", "error": str(exc)})
        page(None, {}, str(exc), {**base, "status": "failed"})
        return BearingReplayResult(status="failed", reason=str(exc), diagnostics=base)
    base["track"] = "local_position" if lp is not None else "state"
    base["synthesis"] = bp.meta
    tracks = run_estimators(bp.t_s, bp.bearing, bp.ownship_vel, bp.sigma_rad, cfg, preset=spec["preset"],
                            mpc_preset=spec["mpc_preset"])
    scores: dict[str, dict[str, float]] = {}
    for e, tr in tracks.items():
        sc = {"heading_converged_s": heading_converged_s(bp.t_s, np.sqrt(tr.cov[:, 3, 3])),
              "range_err_60s_pct": range_error_pct_at(bp.t_s, np.hypot(tr.mean[:, 0], tr.mean[:, 1]),
                                                     np.hypot(bp.truth[:, 0], bp.truth[:, 1]))}
        scores[e] = sc
        extra = {**base, "status": "ok", "error": None, "estimator": e, "scores": sc, **tr.meta}
        write_table(estimate_table(bp.t_ns, tr.mean, tr.cov, nis=tr.nis, mode_p=tr.mode_p, n_diverged=tr.n_diverged),
                    paths[e], schema.BEARING_ESTIMATE, name="bearing_estimate", extra=extra)
        wt = (weights_table(bp.t_ns, tr.weights, tr.grid, spec["weights_every_s"]) if tr.weights is not None
              else schema.empty("bearing_weights"))
        write_table(wt, paths[f"{e}_weights"], schema.BEARING_WEIGHTS, name="bearing_weights", extra=extra)
    head = scores.get("bank_cppv", {})
    for k in ("heading_converged_s", "range_err_60s_pct"):
        print(f"RESULT bearing_replay_{k} {head.get(k, float('nan')):.2f}", file=sys.stderr, flush=True)
    page(bp, tracks, None, {**base, "status": "ok", "scores": scores})
    return BearingReplayResult(status="ok", scores=scores, diagnostics=base)


# --------------------------------------------------------------------------------------------
# the estimators (the bank and IMM of pipeline.estimate.bank / .imm)


@dataclass(frozen=True)
class BearingTrack:
    """One estimator's output over K steps, in CPPV coordinates.

    ``mean`` (K, 5), ``cov`` (K, 5, 5), ``nis`` (K,), ``mode_p`` (K, 2) [CV, CT] or None,
    ``weights`` (K, N) bank weights or None, ``grid`` (N, 3) initial (r, θ, ω) per filter,
    ``n_diverged`` (K,), ``meta`` (settings and the assumptions of D6)."""

    mean: F64
    cov: F64
    nis: F64
    mode_p: F64 | None
    weights: F64 | None
    grid: F64 | None
    n_diverged: NDArray
    meta: dict = field(default_factory=dict)


def run_estimators(t_s: F64, bearing: F64, ownship_vel: F64, sigma_rad: float, cfg: Mapping, *,
                   preset: str | None = None, mpc_preset: str = "mpc_15_5_2") -> dict[str, BearingTrack]:
    """The CPPV bank, the MPC bank and the IMM over one bearing history (variable T).

    Filled in from :mod:`pipeline.estimate.bank` and :mod:`pipeline.estimate.imm`."""
    from . import bearing_filters

    return bearing_filters.replay_tracks(t_s, bearing, ownship_vel, sigma_rad, cfg, preset=preset,
                                         mpc_preset=mpc_preset)
