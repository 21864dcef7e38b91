"""Truth/labels side-cars: ``<log>.truth.parquet`` next to a (simulated) flight log.

A side-car is one Parquet file holding the canonical ``truth`` stream (``schema.STREAMS['truth']``:
position, velocity, acceleration, jerk, attitude, body rates and the maneuver label per sample)
written with :func:`pipeline.io.parquet.write_table`; the ``labels`` table (maneuver segments)
and the flight's UTC start ``t0_utc_ns`` travel in its ``uavpipe`` metadata. Its ``t_ns`` is
relative to the flight start; when the log's own ``meta['t0_utc_ns']`` is known and differs,
:func:`attach_sidecar` shifts the truth onto the log's time base (and says so in the
diagnostics).

A simulated flight's side-car also records the frame of its truth: ``ned_origin`` (the origin
its positions are about) and the ``radar`` site. :func:`attach_sidecar` makes that origin the
flight's when the log has none or one more than :data:`ORIGIN_TOLERANCE_M` away (a ROS bag or
MCAP file carries no navigation origin, so its reader takes the first fix: the state was 440 m
north and 354 m east of the truth on the simulated M1 flight), so the preprocessed state and
the truth share one frame; a log with the same origin (DataFlash ``ORGN``, MAVLink
``GPS_GLOBAL_ORIGIN``) keeps its own. The radar site fills a log that has none.

Naming: for ``flight.bin`` the side-car is ``flight.bin.truth.parquet`` (the full file or bag
directory name plus ``.truth.parquet``); :func:`find_sidecar` also accepts
``flight.truth.parquet``. The workflow passes the side-car to ingest explicitly (the
manifest's ``labels`` column); the CLI finds it by name.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from .lazy import pandas as pd  # imported on first use (see lazy.py)

from ..frames.geodesy import geodetic_to_ned
from . import schema
from .base import FlightLog, IngestError
from .parquet import read_table, read_table_meta, write_table

SUFFIX = ".truth.parquet"

#: a log's own NED origin this close (m, horizontal) to its side-car's is kept
ORIGIN_TOLERANCE_M = 1.0


def _origin_gap_m(a: dict, b: dict) -> float:
    """Horizontal distance (m) of origin ``a`` from origin ``b``: north and east of ``a`` in the
    NED frame about ``b`` (:func:`pipeline.frames.geodesy.geodetic_to_ned`, both at height 0)."""
    n, e, _ = geodetic_to_ned(float(a["lat_deg"]), float(a["lon_deg"]), 0.0,
                              float(b["lat_deg"]), float(b["lon_deg"]), 0.0)
    return float(np.hypot(n, e))


def _adopt_frame(log: FlightLog, meta: dict) -> None:
    """The side-car's ``ned_origin`` and ``radar`` into ``log.meta`` (module docstring)."""
    org = meta.get("ned_origin")
    if isinstance(org, dict) and org.get("lat_deg") is not None and org.get("lon_deg") is not None:
        own = log.meta.get("ned_origin")
        gap = _origin_gap_m(own, org) if own and own.get("lat_deg") is not None else None
        if gap is None or gap > ORIGIN_TOLERANCE_M:
            log.meta["ned_origin"] = {**org, "source": "truth side-car"}
            log.meta["ned_origin_reason"] = None
            log.meta.setdefault("diagnostics", schema.new_diagnostics())["warnings"].append(
                "NED origin from the truth side-car (the frame of its positions)"
                + ("" if gap is None else f"; the log's own, {gap:.0f} m away, is not used"))
    radar = meta.get("radar")
    if isinstance(radar, dict) and radar.get("site_ned_m") is not None and not log.meta.get("radar"):
        log.meta["radar"] = {"site_ned_m": [float(v) for v in radar["site_ned_m"]],
                             "tau_rd_s": float(radar.get("tau_rd_s") or 0.0)}


def sidecar_path(log_path: str | os.PathLike) -> Path:
    """The side-car name written for ``log_path``: ``<name>.truth.parquet`` beside it."""
    p = Path(log_path)
    return p.with_name(p.name + SUFFIX)


def find_sidecar(log_path: str | os.PathLike) -> Path | None:
    """The side-car of ``log_path`` if one exists (``<name>.truth.parquet``, else
    ``<stem>.truth.parquet``), otherwise ``None``."""
    p = Path(log_path)
    for cand in (sidecar_path(p), p.with_name(p.stem + SUFFIX)):
        if cand.is_file() and cand != p:
            return cand
    return None


def write_sidecar(path: str | os.PathLike, truth: pd.DataFrame, labels: pd.DataFrame | None = None,
                  *, t0_utc_ns: int | None = None, extra: dict | None = None) -> Path:
    """Write a side-car: ``truth`` rows (canonical truth stream) + ``labels`` in the metadata."""
    path = Path(path)
    t = schema.conform("truth", truth)
    lab = schema.conform("labels", labels)
    rows = [{"t_start_ns": int(r.t_start_ns), "t_end_ns": int(r.t_end_ns), "label": str(r.label),
             "source": None if pd.isna(r.source) else str(r.source)} for r in lab.itertuples()]
    write_table(t, path, schema.columns("truth"), name="truth",
                extra={"labels": rows, "t0_utc_ns": t0_utc_ns, **(extra or {})})
    return path


def read_sidecar(path: str | os.PathLike) -> tuple[pd.DataFrame, pd.DataFrame, dict]:
    """``(truth, labels, metadata)`` of a side-car; :class:`IngestError` naming it when unreadable."""
    p = Path(path)
    if not p.is_file():
        raise IngestError(p, "labels side-car not found")
    try:
        meta = read_table_meta(p)
    except Exception as exc:  # pyarrow raises several types for a corrupt or foreign file
        raise IngestError(p, f"not a readable truth side-car: {type(exc).__name__}: {exc}") from None
    if meta.get("table") != "truth":
        raise IngestError(p, f"not a truth side-car (table {meta.get('table')!r})")
    try:
        truth = read_table(p, schema.columns("truth"))
    except Exception as exc:
        raise IngestError(p, f"truth side-car unreadable: {type(exc).__name__}: {exc}") from None
    rows, bad = _label_rows(meta.get("labels"))
    labels = pd.DataFrame({
        "t_start_ns": np.array([r[0] for r in rows], np.int64),
        "t_end_ns": np.array([r[1] for r in rows], np.int64),
        "label": pd.array([r[2] for r in rows], dtype="string"),
        "source": pd.array([r[3] for r in rows], dtype="string"),
    })
    meta["labels_dropped"] = bad
    return truth, schema.conform("labels", labels), meta


def _label_rows(rows) -> tuple[list[tuple], list[str]]:
    """The side-car's label rows as ``(t_start_ns, t_end_ns, label, source)``, and one reason
    per row that cannot be one (``"row 3: no t_end_ns"``): a hand-edited side-car with a
    missing or non-integer time, or an end before its start, loses that row only."""
    if rows is None:
        return [], []
    if not isinstance(rows, list):
        return [], [f"labels: expected a list of rows, got {type(rows).__name__}"]
    good, bad = [], []
    for i, r in enumerate(rows):
        if not isinstance(r, dict):
            bad.append(f"row {i}: not a mapping")
            continue
        missing = [k for k in ("t_start_ns", "t_end_ns", "label") if r.get(k) is None]
        if missing:
            bad.append(f"row {i}: no {', '.join(missing)}")
            continue
        try:
            t0, t1 = int(r["t_start_ns"]), int(r["t_end_ns"])
        except (TypeError, ValueError, OverflowError):
            bad.append(f"row {i}: time not an integer ({r['t_start_ns']!r}, {r['t_end_ns']!r})")
            continue
        if t1 < t0:
            bad.append(f"row {i}: ends before it starts")
            continue
        src = r.get("source")
        good.append((t0, t1, str(r["label"]), None if src is None else str(src)))
    return good, bad


def attach_sidecar(log: FlightLog, path: str | os.PathLike) -> FlightLog:
    """Put a side-car's ``truth`` and ``labels`` into ``log`` (in place; also returned).

    The truth is shifted by ``sidecar t0_utc_ns − log t0_utc_ns`` when both are known, so it
    shares the log's ``t_ns`` base. ``meta['labels_path']`` records the side-car. A side-car
    whose truth then shares no time with the log's sensor streams is an :class:`IngestError`
    naming it (another flight's side-car). The side-car's ``ned_origin`` and ``radar`` fill
    or replace the log's as the module docstring says.
    """
    truth, labels, meta = read_sidecar(path)
    t0_sc, t0_log = meta.get("t0_utc_ns"), log.meta.get("t0_utc_ns")
    if t0_sc is not None and t0_log is not None and int(t0_sc) != int(t0_log):
        shift = int(t0_sc) - int(t0_log)
        truth = truth.assign(t_ns=truth["t_ns"] + shift)
        labels = labels.assign(t_start_ns=labels["t_start_ns"] + shift, t_end_ns=labels["t_end_ns"] + shift)
        log.meta.setdefault("diagnostics", schema.new_diagnostics())["warnings"].append(
            f"truth side-car shifted by {shift * 1e-9:+.6f} s onto the log's UTC start")
    # another flight's side-car: after the shift its truth must share some time with the log
    # (a ULog given a simulated flight's truth reported a 6.6-year flight)
    own = [s for s in schema.SENSOR_STREAMS if s != "truth"]
    lo, hi = log.span_ns(own)
    if lo is not None and len(truth):
        t = truth["t_ns"].to_numpy()
        t_lo, t_hi = int(t.min()), int(t.max())
        if t_hi < lo or t_lo > hi:
            raise IngestError(path, f"truth side-car spans {t_lo * 1e-9:.1f} to {t_hi * 1e-9:.1f} s on the log's "
                                    f"time base, the log {lo * 1e-9:.1f} to {hi * 1e-9:.1f} s: no overlap "
                                    "(the side-car of another flight?)")
    log.streams["truth"] = schema.conform("truth", truth)
    log.streams["labels"] = labels
    log.meta["labels_path"] = str(path)
    bad = meta.get("labels_dropped") or []
    if bad:
        diag = log.meta.setdefault("diagnostics", schema.new_diagnostics())
        diag["records_dropped"]["bad_label"] = diag["records_dropped"].get("bad_label", 0) + len(bad)
        diag["warnings"].append(f"truth side-car {Path(path).name}: {len(bad)} label row(s) dropped "
                                f"({'; '.join(bad[:3])}{'; ...' if len(bad) > 3 else ''})")
    _adopt_frame(log, meta)
    return log
