"""Entry points of the estimate stage: the CA EKF, its RTS smoother and the EKF+HMM over one
flight (:func:`run_estimate`), and the EKF+HMM's Q₂ per model set (:func:`run_q2`).

The workflow's rules (``rules/estimate.smk``) and ``uavpipe estimate`` call the same functions.

**Radar.** A flight's radar is its ingest ``radar`` stream (the simulated ``.bin``/``.bag``/
``.mcap`` flights carry one; MAVLink has no radar message, so the ``.tlog`` flights do not),
with the site from the ingest ``meta.json`` ``radar`` entry (DataFlash ``RADR_*`` parameters),
else ``estimate.radar.site_ned_m``. For a vehicle of ``estimate.synthetic_radar`` the radar is
synthesised instead from the preprocessed ``state`` track (:func:`synthesise_radar`: the state
sample nearest each step of a regular ``rate_hz`` grid, seed-000 noise drawn from
``default_rng([seed, crc32("radar"), crc32(flight_id)])``), so the same seed gives the same
measurements and another flight gets independent noise.

**Steps and gaps.** The filters step on a regular grid at the radar's median period from the
first valid measurement to the last; a step holds the radar sample nearest to it (its own
time stamp) or, where the radar has no sample, the grid time and no measurement: a
predict-only step, counted as ``n_predict_only`` in every output's metadata.

**Radar rows not used** are counted, never lost in silence: every output's metadata holds
``n_radar_rows`` (the stream's rows, all instances; the synthetic radar's rows, gaps
included) and ``radar_dropped`` (:func:`radar_steps`: ``nan_field``, ``duplicate_stamp``,
``same_step``; and ``other_instance``, the rows of radar instances other than the lowest,
which the filters do not use), so ``n_steps - n_predict_only == n_radar_rows - sum(radar_dropped)``;
``notes`` says when other instances or duplicated stamps were set aside. Duplicated stamps
(ingest keeps them and only counts them) are data, not a failure: the first row of each is kept.

**Heading (EKF+HMM).** The classifier's heading is the attitude stream's yaw (else the state's
``yaw_rad``) interpolated to the steps and held beyond its ends; the ``ekf_hmm`` metadata counts
the steps whose heading was bridged over an attitude gap longer than :data:`YAW_GAP_LIMIT_S` or
held beyond the attitude's span (``yaw_filled``).

**Reference (NEES).** A simulated flight carries its truth (the ingest ``truth`` stream from
the ``<log>.truth.parquet`` side-car, 200 Hz, in the radar's NED frame): it is interpolated to
the steps and is the NEES reference. A synthetic-radar flight's reference is the preprocessed
state the radar was drawn from (its acceleration is itself a derivative estimate, so the NEES
there measures consistency with the state track, not with the true motion). Other flights have
no reference: ``nees`` is NaN. The initial state (``estimate.ekf.init: reference``, the thesis's
initialisation) is the reference at the first step, else it comes from the first measurement.

**Outputs** (``io.schema`` tables ``estimate``/``estimate_hmm``): ``results/estimate/ekf/``,
``ekf_rts/`` (the smoothed EKF; its ``nis`` is the filter's) and ``ekf_hmm/`` (the EKF+HMM's
own estimate with ``mode``, ``pred``, ``V_best``). Failures are placeholders, never crashes:
no radar (or no state track to synthesise it from), an unreadable input or any other error of
the flight's EKF (``estimate failed: <type>: <message> (at <file>:<line>)``) gives three empty
tables with ``status: failed`` and the one-line reason; a model set without GMR (feature set
other than :data:`~pipeline.estimate.ekf_hmm.GMR_FEATURE_SETS`, e.g. ``f3a``'s ``aero``), a
failed or unreadable model set or a failed Q₂ give an empty ``ekf_hmm`` table with the reason
beside complete EKF tables (``status: partial``), and so does any error of the EKF+HMM itself
(``EKF+HMM failed: <type>: <message> ...``).
"""

from __future__ import annotations

import json
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..io import schema
from ..io.parquet import read_flightlog, read_table, read_table_meta, write_json, write_table
from ..io.stage import declared, declared_list, exception_line, one_line, say
from .base import ConstantAcceleration, GaussianState
from .ekf import ExtendedKalmanFilter, run_filter
from .ekf_hmm import GMR_FEATURE_SETS, q2_from_runs, run_ekf_hmm
from .metrics import nees, rmse_groups
from .models import RADAR_FIELDS, STATE_COLUMNS, STATE_GROUPS, RadarModel, initial_cov
from .smoother import rts_smooth
from .table import estimate_frame

F64 = NDArray[np.float64]

#: the estimators of one flight job, in output order (``results/estimate/<estimator>/``)
ESTIMATORS: tuple[str, ...] = ("ekf", "ekf_rts", "ekf_hmm")

#: longest attitude gap (s) the EKF+HMM's heading is bridged across without being counted: the
#: linear fill is exact only at a constant turn rate, and rolling into or out of a turn takes
#: about a second, so a longer hole can hide a change of turn rate and a heading tens of
#: degrees off (the attitude streams run at 10 Hz or faster: a 1 s hole is many samples lost)
YAW_GAP_LIMIT_S: float = 1.0


@dataclass(frozen=True)
class EstimateResult:
    """What :func:`run_estimate` did.

    Attributes
    ----------
    flight_id : str or None
    status : str
        ``ok`` (all three estimates), ``partial`` (EKF and RTS; ``ekf_hmm`` a placeholder) or
        ``failed`` (three placeholders).
    error : str
        The reason when not ``ok`` (``ekf_hmm``'s when partial), one line.
    diagnostics : dict
        Steps, predict-only steps, radar rows and the rows not used (``n_radar_rows``,
        ``radar_dropped``), radar source and site, reference, RMSE per group, ``notes``; with
        the EKF+HMM run, also its heading's source and filled steps (``yaw_from``,
        ``yaw_filled``).
    """

    flight_id: str | None
    status: str
    error: str = ""
    diagnostics: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Q2Result:
    """What :func:`run_q2` did: ``status`` ``ok``/``failed``, the reason and the diagnostics."""

    model_set: str
    status: str
    error: str = ""
    diagnostics: dict = field(default_factory=dict)


def _say(msg: str, *, restated: bool = False) -> None:
    say("uavpipe estimate", msg, restated=restated)


def job_config(section: Mapping[str, Any], vehicle: str | None) -> dict:
    """The config one flight job takes from the ``estimate`` section: ``synthetic_radar`` = the
    vehicle's entry (``None`` when it flies with a radar stream), ``radar``, ``ekf``,
    ``ekf_hmm`` (so another vehicle's entry or the vehicle list never reruns the job)."""
    synth = dict(section.get("synthetic_radar") or {})
    return {"synthetic_radar": synth.get(vehicle) if vehicle else None,
            "radar": dict(section.get("radar") or {}), "ekf": dict(section.get("ekf") or {}),
            "ekf_hmm": dict(section.get("ekf_hmm") or {})}


# --- radar --------------------------------------------------------------------------------------

def radar_rng(seed: int, flight_id: str) -> np.random.Generator:
    """The synthetic radar's generator: ``default_rng([seed, crc32("radar"), crc32(flight_id)])``."""
    return np.random.default_rng([int(seed), zlib.crc32(b"radar"), zlib.crc32(str(flight_id).encode())])


def radar_model(site_ned_m: Sequence[float], *, tau_rd_s: float = 0.0, sigma_range_m: float = 1.5,
                sigma_dcos: float = 4.5e-5, sigma_range_rate_mps: float = 0.2,
                above_site: bool = False) -> RadarModel:
    """The seed-000 radar at ``site_ned_m`` with the given noise (defaults: Table 2.1);
    ``above_site``: the EKF takes the target above the site's plane (:meth:`RadarModel.fold`)."""
    return RadarModel(site_ned_m=tuple(float(v) for v in site_ned_m), tau_rd_s=float(tau_rd_s),
                      sigma=(float(sigma_range_m), float(sigma_dcos), float(sigma_dcos),
                             float(sigma_range_rate_mps)), above_site=bool(above_site))


def _grid(t0: int, t1: int, period_ns: int) -> NDArray[np.int64]:
    n = int(round((t1 - t0) / period_ns)) + 1
    return t0 + period_ns * np.arange(max(n, 1), dtype=np.int64)


def synthesise_radar(state: pd.DataFrame, model: RadarModel, rate_hz: float,
                     rng: np.random.Generator) -> pd.DataFrame:
    """Radar measurements of a state track (seed 000 §3 noise).

    Parameters
    ----------
    state : DataFrame
        ``t_ns`` and the ``state`` position/velocity columns (NED, the radar's frame).
    model : RadarModel
        Site, τ_RD and σ.
    rate_hz : float
        Measurement rate: one measurement per step of a regular grid from the first to the last
        state sample, of the state sample nearest to the step (at its own time).
    rng : numpy.random.Generator
        Noise source (:func:`radar_rng`); one draw per grid step whether or not it is measured,
        so a gap never shifts the noise of later steps.

    Returns
    -------
    DataFrame
        ``t_ns`` and :data:`~pipeline.estimate.models.RADAR_FIELDS`; NaN where the state has no
        position/velocity or is flagged ``gap`` (a radar gap).
    """
    t = state["t_ns"].to_numpy(dtype=np.int64)
    cols = list(STATE_COLUMNS[:6])
    if not len(t):
        return pd.DataFrame({"t_ns": np.zeros(0, np.int64), **{f: np.zeros(0) for f in RADAR_FIELDS}})
    grid = _grid(int(t[0]), int(t[-1]), int(round(1e9 / rate_hz)))
    idx = np.clip(np.searchsorted(t, grid), 0, len(t) - 1)
    prev = np.clip(idx - 1, 0, len(t) - 1)
    idx = np.where(np.abs(t[prev] - grid) <= np.abs(t[idx] - grid), prev, idx)
    idx = np.unique(idx)
    x = state[cols].to_numpy(dtype=np.float64)[idx]
    bad = ~np.isfinite(x).all(axis=1)
    if "gap" in state:
        bad |= state["gap"].to_numpy(dtype=bool)[idx]
    noise = rng.standard_normal((len(idx), 4)) * np.asarray(model.sigma)
    z = np.full((len(idx), 4), np.nan)
    if (~bad).any():
        z[~bad] = model.h(x[~bad]) + noise[~bad]
    return pd.DataFrame({"t_ns": t[idx], **dict(zip(RADAR_FIELDS, z.T))})


def _json_object(path: Path) -> tuple[dict | None, str]:
    """``(the JSON object in path, "")``, or ``(None, one-line reason naming the file)`` when it
    cannot be read, is not JSON or holds something other than an object (an ingest or model
    ``meta.json``)."""
    try:
        obj = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return None, f"{path}: not a readable JSON file ({exception_line(exc)})"
    if not isinstance(obj, dict):
        return None, f"{path}: holds a JSON {type(obj).__name__}, not an object"
    return obj, ""


def radar_steps(radar: pd.DataFrame) -> tuple[NDArray[np.int64], F64, int, dict[str, int]]:
    """The filter's steps from radar samples, and the rows it could not use.

    Steps are a regular grid at the median period between distinct sample times, from the first
    valid sample to the last; each step takes the first sample that rounds to it (its own time
    stamp), and a step without one keeps the grid time and a NaN measurement (predict only).

    Parameters
    ----------
    radar : DataFrame
        ``t_ns`` and :data:`~pipeline.estimate.models.RADAR_FIELDS`, one radar instance, in any
        order; duplicated time stamps allowed (ingest keeps them and only counts them).

    Returns
    -------
    t_ns : ndarray of int64, shape (T,)
        The steps.
    z : ndarray, shape (T, 4)
        The measurement of each step, NaN on a predict-only step.
    period_ns : int
        The grid period (0 with fewer than two usable samples).
    dropped : dict
        Rows not used, by reason, every key present: ``nan_field`` (a field NaN or infinite),
        ``duplicate_stamp`` (the time stamp of an earlier row, which is kept), ``same_step``
        (a later distinct time in a step already taken). ``T - (NaN rows of z)`` is
        ``len(radar) - sum(dropped.values())``.
    """
    fields = list(RADAR_FIELDS)
    # an infinite field would poison the filter's state for good, like a NaN one
    finite = np.isfinite(radar[fields].to_numpy(dtype=np.float64)).all(axis=1)
    r = radar[finite].sort_values("t_ns", kind="stable")
    t = r["t_ns"].to_numpy(dtype=np.int64)
    zr = r[fields].to_numpy(dtype=np.float64)
    # a repeated stamp: keep the first row (in stream order, the sort is stable) so the period
    # below is that of the distinct times and never zero
    dup = np.r_[False, t[1:] == t[:-1]] if len(t) else np.zeros(0, dtype=bool)
    dropped = {"nan_field": int((~finite).sum()), "duplicate_stamp": int(dup.sum()), "same_step": 0}
    t, zr = t[~dup], zr[~dup]
    if len(t) < 2:
        return t, zr, 0, dropped
    period = int(np.median(np.diff(t)))  # >= 1: the times now strictly increase
    grid = _grid(int(t[0]), int(t[-1]), period)
    k = np.rint((t - t[0]) / period).astype(np.int64)
    first = np.r_[True, k[1:] != k[:-1]]
    dropped["same_step"] = int((~first).sum())
    steps = grid.copy()
    steps[k[first]] = t[first]
    z = np.full((len(grid), 4), np.nan)
    z[k[first]] = zr[first]
    return steps, z, period, dropped


def radar_init(z: F64, model: RadarModel) -> F64:
    """A 9-state mean from one measurement ``[ρ + τρ̇, u, v, ρ̇]``: position along the line of
    sight (the target taken above the site, w = −√(1 − u² − v²)), velocity ρ̇ along it, no
    acceleration."""
    rr, u, v, rdot = (float(c) for c in z)
    w = -np.sqrt(max(0.0, 1.0 - u * u - v * v))
    los = np.array([u, v, w])
    rho = rr - model.tau_rd_s * rdot
    return np.r_[np.asarray(model.site_ned_m) + rho * los, rdot * los, np.zeros(3)]


def _interp(t_src: NDArray[np.int64], values: F64, t: NDArray[np.int64]) -> F64:
    """Columns of ``values`` linearly interpolated at ``t`` (NaN outside ``t_src``)."""
    out = np.full((len(t), values.shape[1]), np.nan)
    if len(t_src) < 2:
        return out
    inside = (t >= t_src[0]) & (t <= t_src[-1])
    for j in range(values.shape[1]):
        ok = np.isfinite(values[:, j])
        if ok.sum() >= 2:
            out[inside, j] = np.interp(t[inside], t_src[ok], values[ok, j])
    return out


def _yaw_at(log, state: pd.DataFrame | None, t: NDArray[np.int64]) -> tuple[F64 | None, dict]:
    """Heading (rad) at the steps, and how much of it was filled in.

    Parameters
    ----------
    log : FlightLog
        Its ``attitude`` stream (first instance) is the source, else ``state``.
    state : DataFrame or None
        The preprocessed state; its ``yaw_rad`` is the source without attitude.
    t : ndarray of int64, shape (T,)
        The steps.

    Returns
    -------
    yaw : ndarray, shape (T,), or None
        Unwrapped, linearly interpolated, held at the nearest heading before the first and
        after the last sample; None without two finite headings.
    info : dict
        ``yaw_from`` (``attitude``, ``state`` or None), ``yaw_gap_limit_s``
        (:data:`YAW_GAP_LIMIT_S`) and ``yaw_filled``: ``across_gap``, the steps interpolated
        between two headings more than the limit apart, and ``held``, the steps before the
        first or after the last heading (the filter gets these values all the same; the
        counts say how far to trust its classification there).
    """
    from ..frames.rotations import quat_to_euler

    info: dict[str, Any] = {"yaw_from": None, "yaw_gap_limit_s": YAW_GAP_LIMIT_S,
                            "yaw_filled": {"across_gap": 0, "held": 0}}
    att = log["attitude"]
    if len(att):
        att = att[att["instance"] == att["instance"].min()].dropna(subset=["q_w", "q_x", "q_y", "q_z"])
    if len(att) >= 2:
        ts, yaw = att["t_ns"].to_numpy(np.int64), quat_to_euler(att[["q_w", "q_x", "q_y", "q_z"]].to_numpy())[2]
        info["yaw_from"] = "attitude"
    elif state is not None and len(state) and state["yaw_rad"].notna().sum() >= 2:
        s = state.dropna(subset=["yaw_rad"])
        ts, yaw = s["t_ns"].to_numpy(np.int64), s["yaw_rad"].to_numpy(np.float64)
        info["yaw_from"] = "state"
    else:
        return None, info
    # one NaN heading (a degenerate quaternion) would turn every later unwrapped value NaN;
    # sorted, as np.interp needs
    ok = np.isfinite(yaw)
    order = np.argsort(ts[ok], kind="stable")
    ts, yaw = ts[ok][order], yaw[ok][order]
    if len(ts) < 2:
        info["yaw_from"] = None
        return None, info
    y = _interp(ts, np.unwrap(yaw)[:, None], t)[:, 0]
    # before the first / after the last heading: hold the nearest one
    ok = np.isfinite(y)
    if not ok.any():
        info["yaw_from"] = None
        return None, info
    held = (t < ts[0]) | (t > ts[-1])
    i = np.searchsorted(ts, t)
    on_sample = ts[np.clip(i, 0, len(ts) - 1)] == t
    i = np.clip(i, 1, len(ts) - 1)   # inside the span and off a sample: ts[i - 1] < t < ts[i]
    across = ~held & ~on_sample & (ts[i] - ts[i - 1] > YAW_GAP_LIMIT_S * 1e9)
    info["yaw_filled"] = {"across_gap": int(across.sum()), "held": int(held.sum())}
    return np.interp(np.arange(len(y)), np.flatnonzero(ok), y[ok]), info


# --- the stage ----------------------------------------------------------------------------------

def _placeholder(path, table: str, extra: dict) -> None:
    write_table(schema.empty(table), path, schema.columns(table), name=table, extra=extra)


def _paths(outputs) -> dict[str, str]:
    out = {e: declared(outputs, e) for e in ESTIMATORS}
    missing = [e for e, p in out.items() if not p]
    if missing:
        raise ValueError(f"run_estimate: outputs must declare {', '.join(ESTIMATORS)} (missing {missing})")
    return out


def _ekf_hmm_blocker(inputs, config: Mapping) -> tuple[str, Any, F64 | None]:
    """``(reason, model_set, Q2)``: why the EKF+HMM cannot run ('' when it can), in one line
    naming the file when one is unreadable."""
    from ..models.base import ModelError
    from ..models.classifier import ManeuverModelSet

    model = (config.get("ekf_hmm") or {}).get("model", "sim")
    params, q2_path = declared(inputs, "model_params"), declared(inputs, "q2")
    if not params or not Path(params).exists():
        return f"no model set {model} given", None, None
    mdir = Path(params).parent
    meta, why = _json_object(mdir / "meta.json")
    if meta is None:
        return why, None, None
    if meta.get("status") == "failed":
        return f"model set {model} failed: {meta.get('error')}", None, None
    try:
        ms = ManeuverModelSet.load(mdir)
    except ModelError as exc:   # its message names the folder and says what is wrong
        return one_line(exc), None, None
    fs = ms.config.feature_set
    if fs not in GMR_FEATURE_SETS:
        return (f"model set {model} has no GMR (feature set {fs}; the EKF+HMM needs one of "
                f"{', '.join(GMR_FEATURE_SETS)})"), None, None
    if not q2_path or not Path(q2_path).exists():
        return f"no Q2 for model set {model}", None, None
    problem, Q2 = read_q2(q2_path, meta.get("name") or model)
    if problem:
        return f"{q2_path}: {problem}", None, None
    return "", ms, Q2


def read_q2(path: str | Path, model_set: str | None = None) -> tuple[str, F64 | None]:
    """``("", Q2)`` from a :func:`run_q2` output, or ``(why not, None)`` in a few words.

    Usable: a JSON object with ``status`` ``ok`` and ``Q2`` a finite, symmetric, positive
    semidefinite 9 × 9 numeric matrix (state order pos/vel/acc NED; it is a covariance, and a
    negative one ends every flight's EKF+HMM in a non-positive-definite innovation), recorded
    for ``model_set`` when one is given (another set's Q₂ was taken in silence). A Q₂ that
    :func:`run_q2` recorded as failed gives its recorded reason. The ``uavpipe estimate --q2``
    check calls this before any flight."""
    try:
        q2 = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return f"not a readable JSON file ({type(exc).__name__}: {exc})", None
    if not isinstance(q2, dict) or "status" not in q2:
        return "not a Q2 file of run_q2 (no 'status')", None
    if q2["status"] != "ok":
        return f"records a failed Q2 (status {q2['status']!r}: {q2.get('error') or 'no reason given'})", None
    if "Q2" not in q2:
        return "not a Q2 file of run_q2 (no 'Q2')", None
    try:
        Q2 = np.asarray(q2["Q2"], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        return f"Q2 is not a numeric matrix ({type(exc).__name__}: {exc})", None
    if Q2.shape != (9, 9) or not np.isfinite(Q2).all():
        return f"Q2 is not a finite 9 x 9 matrix (shape {Q2.shape})", None
    size = max(float(np.abs(Q2).max()), np.finfo(float).tiny)
    if np.abs(Q2 - Q2.T).max() > 1e-9 * size:
        return "Q2 is not symmetric (a covariance is)", None
    low = float(np.linalg.eigvalsh(Q2).min())
    if low < -1e-9 * size:
        return f"Q2 is not positive semidefinite (smallest eigenvalue {low:.3g}; a covariance is)", None
    owner = q2.get("model_set")
    if model_set is not None and owner is not None and str(owner) != str(model_set):
        return f"is the Q2 of model set {owner}, not {model_set}", None
    return "", Q2


def _rmse(err: F64) -> dict[str, float]:
    """3-D RMSE per group (``pos``, ``vel``, ``acc``); rows with a NaN in the group left out."""
    return {g: v for g, v in rmse_groups(err).items() if g in STATE_GROUPS}


def _nees(ref: F64 | None, mean: F64, cov: F64) -> F64 | None:
    """NEES per step against ``ref`` (None without one; NaN where the reference is missing)."""
    if ref is None:
        return None
    err = mean - ref
    ok = np.isfinite(err).all(axis=1)
    out = np.full(len(err), np.nan)
    if ok.any():
        out[ok] = nees(err[ok], cov[ok])
    return out


def run_estimate(inputs, outputs, config: Mapping, *, flight_id: str | None = None,
                 vehicle: str | None = None, seed: int = 0) -> EstimateResult:
    """Estimate one flight: CA EKF, RTS smoother, EKF+HMM; write ``outputs.ekf``,
    ``outputs.ekf_rts``, ``outputs.ekf_hmm`` (see the module docstring).

    Parameters
    ----------
    inputs : mapping
        ``meta``: the ingest ``meta.json`` (its streams beside it: ``radar``, ``truth``,
        ``attitude``); ``state``: the preprocessed state; optional ``segments`` (classifier
        resets), ``model_params`` (``results/models/<model>/params.npz``, its ``meta.json``
        beside it) and ``q2`` (``results/estimate/q2/<model>.json``).
    outputs : mapping
        ``ekf``, ``ekf_rts``, ``ekf_hmm``: Parquet paths.
    config : mapping
        :func:`job_config` of the ``estimate`` section: ``synthetic_radar`` (the vehicle's
        entry or None), ``radar``, ``ekf``, ``ekf_hmm``.
    flight_id, vehicle : str, optional
        Recorded in the metadata; ``flight_id`` also seeds the synthetic radar (default: the
        ingest meta's).
    seed : int
        The master seed (synthetic radar noise).

    Returns
    -------
    EstimateResult
    """
    paths = _paths(outputs)
    meta_path = Path(declared(inputs, "meta"))
    ekf_cfg = {"q": 1.0, "p0_sigma": [1.0, 0.1, 0.01], "joseph": True, "init": "reference",
               "above_site": True, **dict(config.get("ekf") or {})}
    hmm_cfg = {"model": "sim", "q2_scale": 1.0, "reset_at_segments": False, "increments": "prior",
               "decision": "both", **dict(config.get("ekf_hmm") or {})}
    # the ingest folder is named after its flight: the name a placeholder gets when meta.json
    # cannot say it
    base = {"flight_id": flight_id or meta_path.parent.name, "vehicle": vehicle, "q": float(ekf_cfg["q"]),
            "model_set": hmm_cfg["model"]}
    known: dict[str, Any] = {}   # the radar counts once taken, kept by a later failure's placeholders
    try:
        return _estimate_flight(inputs, paths, config, meta_path, ekf_cfg, hmm_cfg, base, known,
                                flight_id=flight_id, seed=seed)
    except Exception as exc:  # one bad flight never stops the others: its placeholders say why
        return _fail(paths, base, f"estimate failed: {exception_line(exc)}", known)


def _fail(paths: Mapping[str, str], base: Mapping, reason: str, known: Mapping | None = None) -> EstimateResult:
    """Three placeholders with ``status: failed`` and the one-line ``reason`` (any table written
    before the failure is replaced: a flight's three outputs agree); ``known``: counts taken so
    far (radar rows and drops, notes), kept in their metadata."""
    fid = base["flight_id"]
    _say(f"{fid}: placeholder estimates ({reason})")
    diag = {"n_steps": 0, "n_predict_only": 0, **(known or {})}
    extra = {**base, "status": "failed", "error": reason, **diag}
    for e in ESTIMATORS:
        _placeholder(paths[e], "estimate_hmm" if e == "ekf_hmm" else "estimate", {**extra, "estimator": e})
    return EstimateResult(fid, "failed", reason, diag)


def _estimate_flight(inputs, paths: Mapping[str, str], config: Mapping, meta_path: Path, ekf_cfg: dict,
                     hmm_cfg: dict, base: dict, known: dict, *, flight_id: str | None,
                     seed: int) -> EstimateResult:
    """The work of :func:`run_estimate` from reading its inputs on: ``base`` gets the flight id
    and ``known`` the radar counts as they are learnt, for the placeholders of a failure
    raised here."""
    meta, why = _json_object(meta_path)
    if meta is None:
        return _fail(paths, base, why)
    fid = base["flight_id"] = flight_id or meta.get("flight_id")
    if meta.get("status") == "failed":
        return _fail(paths, base, f"ingest failed: {meta.get('error') or 'unknown reason'}")
    above = bool(ekf_cfg["above_site"])
    synth = config.get("synthetic_radar")
    state_path = declared(inputs, "state")
    try:
        state = read_table(state_path) if state_path and Path(state_path).exists() else None
        st_meta = read_table_meta(state_path) if state is not None else {}
    except (OSError, ValueError) as exc:     # a damaged state file (pyarrow's errors are ValueErrors)
        return _fail(paths, base, f"{state_path}: cannot read the state ({exception_line(exc)})")
    try:
        log = read_flightlog(meta_path.parent, streams=["radar", "truth", "attitude"])
    except (ValueError, OSError) as exc:     # a damaged or swapped stream file, named
        return _fail(paths, base, f"cannot read the ingested streams: {one_line(exc)}")
    # --- the radar and its model
    notes: list[str] = []
    n_other = 0
    if synth is not None:
        if state is None or not len(state) or not state["pos_n_m"].notna().any():
            why = st_meta.get("error") or "no position track"
            return _fail(paths, base, f"no state track to synthesise the radar from ({why})")
        model = radar_model(synth.get("site_ned_m", (0.0, 0.0, 0.0)), tau_rd_s=synth.get("tau_rd_s", 0.0),
                            sigma_range_m=synth.get("sigma_range_m", 1.5), sigma_dcos=synth.get("sigma_dcos", 4.5e-5),
                            sigma_range_rate_mps=synth.get("sigma_range_rate_mps", 0.2), above_site=above)
        radar = synthesise_radar(state, model, float(synth.get("rate_hz", 5.0)), radar_rng(seed, fid))
        source, site_from = "synthetic", "estimate.synthetic_radar"
    else:
        radar = log["radar"]
        if not len(radar):
            return _fail(paths, base, "no radar stream in the log (and the vehicle is not in estimate.synthetic_radar)")
        inst = radar["instance"].to_numpy()
        lowest = radar["instance"].min()
        mine = inst == lowest
        n_other = int((~mine).sum())
        if n_other:
            others = ", ".join(map(str, sorted(pd.unique(inst[~mine]), key=str)))
            notes.append(f"radar: instance {others} ignored ({n_other} rows); the filters use instance {lowest} only")
        radar = radar[mine]
        site_meta = (meta.get("radar") or {})
        if site_meta.get("site_ned_m") is not None:
            site, tau, site_from = site_meta["site_ned_m"], float(site_meta.get("tau_rd_s") or 0.0), "meta.json"
        else:
            site, tau = (config.get("radar") or {}).get("site_ned_m", (0.0, 0.0, 0.0)), 0.0
            site_from = "estimate.radar.site_ned_m"
        model = radar_model(site, tau_rd_s=tau, above_site=above)
        source = "stream"
    n_rows = len(radar) + n_other
    t, z, period, dropped = radar_steps(radar)
    if dropped["duplicate_stamp"]:
        notes.append(f"radar: {dropped['duplicate_stamp']} row(s) repeat an earlier time stamp; "
                     "the first row of each stamp is used")
    known.update(n_radar_rows=n_rows, radar_dropped={**dropped, "other_instance": n_other}, notes=notes)
    if len(t) < 2:
        return _fail(paths, base, f"{len(t)} valid radar sample(s): nothing to filter", known)
    # --- the reference (NEES) and the initial state
    truth = log["truth"]
    ref, ref_name = None, "none"
    if len(truth) and truth["pos_n_m"].notna().any():
        ref = _interp(truth["t_ns"].to_numpy(np.int64), truth[list(STATE_COLUMNS)].to_numpy(np.float64), t)
        ref_name = "truth"
    elif synth is not None:
        ref = _interp(state["t_ns"].to_numpy(np.int64), state[list(STATE_COLUMNS)].to_numpy(np.float64), t)
        ref_name = "state"
    if ekf_cfg["init"] == "reference" and ref is not None and np.isfinite(ref[0]).all():
        x0, init = ref[0].copy(), "reference"
    else:
        x0, init = radar_init(z[0], model), "radar"
    prior = GaussianState(x0, initial_cov(tuple(ekf_cfg["p0_sigma"])), int(t[0]))
    ekf = ExtendedKalmanFilter(ConstantAcceleration(float(ekf_cfg["q"])), model, joseph=bool(ekf_cfg["joseph"]))
    zz = z[:, None, :]
    track = run_filter(ekf, prior, t, zz, store="all")
    smooth = rts_smooth(track)
    n_po = int(track.n_predict_only[0])
    diag = {"n_steps": int(len(t)), "n_predict_only": n_po, "n_radar_rows": n_rows,
            "radar_dropped": known["radar_dropped"], "radar": source, "radar_site_ned_m": list(model.site_ned_m),
            "radar_site_from": site_from, "radar_period_s": period * 1e-9, "reference": ref_name, "init": init,
            "above_site": above, "notes": list(notes)}
    extra = {**base, **diag, "notes": list(notes), "status": "ok", "error": None}   # diag's notes grow below
    err = {}
    for name, mean, cov in (("ekf", track.mean[0], track.cov[0]), ("ekf_rts", smooth.mean[0], smooth.cov[0])):
        df = estimate_frame(t, mean, cov, nis=track.nis[0], nees=_nees(ref, mean, cov))
        write_table(df, paths[name], schema.ESTIMATE, name="estimate", extra={**extra, "estimator": name})
        if ref is not None:
            err[name] = _rmse(mean - ref)
    # --- the EKF+HMM: whatever stops it, the EKF tables above stand (status partial)
    status = "ok"
    try:
        reason, ms, Q2 = _ekf_hmm_blocker(inputs, config)
        if not reason:
            seg_path = declared(inputs, "segments")
            resets = None
            if hmm_cfg["reset_at_segments"] and seg_path and Path(seg_path).exists():
                seg = read_table(seg_path)
                resets = seg["t_start_ns"].to_numpy(np.int64) if len(seg) else None
            yaw, yaw_info = _yaw_at(log, state, t)
            diag.update(yaw_info)
            filled = yaw_info["yaw_filled"]
            if filled["across_gap"] or filled["held"]:
                diag["notes"].append(f"heading: {filled['across_gap']} step(s) interpolated across "
                                     f"{yaw_info['yaw_from']} gaps over {YAW_GAP_LIMIT_S:g} s, "
                                     f"{filled['held']} held beyond its span")
            box = float((meta.get("params") or {}).get("box_rotation_rad") or st_meta.get("box_rotation_rad") or 0.0)
            ht = run_ekf_hmm(ekf, prior, t, zz, ms, Q2, yaw_rad=None if yaw is None else yaw[None],
                             box_heading_rad=box, reset_t_ns=resets, store="filtered",
                             increments=hmm_cfg["increments"],
                             decision=None if hmm_cfg["decision"] == "model" else hmm_cfg["decision"])
            # the thesis's output (Ch. 4.1): the EKF+HMM estimate after a known classification,
            # the baseline EKF's after unknown (the filter itself runs on, unreset)
            out = ht.output
            hm, hc = out.mean[0], out.cov[0]
            df = estimate_frame(t, hm, hc, nis=out.nis[0], nees=_nees(ref, hm, hc))
            df["mode"] = np.asarray(ht.mode[0], dtype=bool)
            df["pred"] = pd.array([str(p) for p in ht.pred[0]], dtype="string")
            df["V_best"] = np.asarray(ht.V_best[0], dtype=np.float64)
            df = schema.conform("estimate_hmm", df)
            n_mode = int(df["mode"].sum())
            write_table(df, paths["ekf_hmm"], schema.ESTIMATE_HMM, name="estimate_hmm",
                        extra={**extra, **yaw_info, "notes": diag["notes"], "estimator": "ekf_hmm",
                               "n_hmm_steps": n_mode, "increments": hmm_cfg["increments"],
                               "n_predict_only": int(ht.hmm.n_predict_only[0])})
            diag["n_hmm_steps"] = n_mode
            if ref is not None:
                err["ekf_hmm"] = _rmse(hm - ref)
    except Exception as exc:  # ModelError, the classifier's numerical failures, anything else
        reason = f"EKF+HMM failed: {exception_line(exc)}"
    if reason:
        status = "partial"
        _placeholder(paths["ekf_hmm"], "estimate_hmm",
                     {**extra, "estimator": "ekf_hmm", "status": "failed", "error": reason})
    diag["rmse"] = err
    _say(f"{fid}: {len(t)} steps ({n_po} predict-only), radar {source}, reference {ref_name}"
         + (f"; ekf_hmm placeholder ({reason})" if reason else f"; {diag.get('n_hmm_steps', 0)} HMM steps"),
         restated=True)
    return EstimateResult(fid, status, reason, diag)


# --- Q₂ per model set -----------------------------------------------------------------------------

def _training_runs(inputs) -> pd.DataFrame:
    """The model set's training truth: simulated ``sets`` (run ids made unique per file) or the
    labelled segments of the training flights (``states``/``segments``, one run each)."""
    from ..models.run import flight_runs, read_sets

    sets = declared_list(inputs, "sets")
    if sets:
        return read_sets(sets)

    return flight_runs(declared_list(inputs, "states"), declared_list(inputs, "segments"))


def run_q2(inputs, outputs, config: Mapping, *, model_set: str) -> Q2Result:
    """Q₂ of the EKF+HMM for one model set: write ``outputs.q2`` (JSON).

    ``Q₂ = q2_from_runs(model_set, training truth, scale=q2_scale)``: the covariance of the
    A_H/B one-step errors of ``[r, v, a]`` on the set's training runs (digest §8, §13.7), once
    per model set rather than per flight.

    Parameters
    ----------
    inputs : mapping
        ``params`` (its ``meta.json`` beside it) and the set's training data: ``sets``
        (simulated bulk sets), or ``states`` and ``segments`` (training flights); for a model
        set trained on EKF estimates (``input: ekf``) also ``truth_sets``, the truth of the same
        runs: the classifier and GMR then see the estimates and the one-step errors are taken
        against the truth.
    outputs : mapping
        ``q2``: ``results/estimate/q2/<model_set>.json`` with ``status``, ``error``,
        ``scale``, ``n_runs`` and ``Q2`` (9×9, state order pos/vel/acc NED).
    config : mapping
        ``estimate.ekf_hmm`` (``q2_scale``).
    model_set : str
        Its name.
    """
    out = declared(outputs, "q2")
    scale = float((config or {}).get("q2_scale", 1.0))
    mdir = Path(declared(inputs, "params")).parent
    rec: dict[str, Any] = {"model_set": model_set, "scale": scale, "Q2": None, "n_runs": 0}
    meta = json.loads((mdir / "meta.json").read_text())
    reason = ""
    if meta.get("status") == "failed":
        reason = f"model set {model_set} failed: {meta.get('error')}"
    else:
        from ..models.classifier import ManeuverModelSet

        ms = ManeuverModelSet.load(mdir)
        if ms.config.feature_set not in GMR_FEATURE_SETS:
            reason = f"model set {model_set} has no GMR (feature set {ms.config.feature_set})"
        else:
            runs = _training_runs(inputs)
            truth_sets = declared_list(inputs, "truth_sets")
            # a model set trained on EKF estimates: the GMR sees those, the errors are the truth's
            truth = _training_runs({"sets": truth_sets}) if truth_sets else runs
            given = ", ".join(map(str, [*declared_list(inputs, "sets"), *declared_list(inputs, "states")])) or "none"
            if not len(runs):
                reason = f"no training runs (in {given})"
            else:
                try:
                    Q2 = q2_from_runs(ms, truth, scale=scale, input_state=runs if truth_sets else None)
                except ValueError as exc:
                    reason = f"Q2 failed on {given}: {type(exc).__name__}: {exc}"
                else:
                    rec.update(Q2=np.asarray(Q2, dtype=np.float64).tolist(), n_runs=int(runs["run_id"].nunique()))
    rec.update(status="failed" if reason else "ok", error=reason or None)
    write_json(rec, out)
    _say(f"Q2 of {model_set}: " + (reason or f"{rec['n_runs']} training runs, scale {scale:g}"), restated=True)
    return Q2Result(model_set, rec["status"], reason, {"n_runs": rec["n_runs"]})
