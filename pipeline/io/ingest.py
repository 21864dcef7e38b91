"""Ingest one flight into the Parquet store — the function the workflow's ingest rule calls.

A log that cannot be decoded does not stop the workflow: :func:`run_ingest` writes every
stream empty (full schema) and a ``meta.json`` with ``status: failed`` and the one-line
``error``, so downstream rules write "failed" placeholders and the report index lists the
flight with its reason.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from .base import FlightLog, IngestError
from .parquet import write_flightlog
from .registry import read_log


def _run_ingest_old(log_path: str | os.PathLike, out_dir: str | os.PathLike, *, flight_id: str,
               fmt: str | None = None, labels: str | os.PathLike | None = None,
               config: dict | None = None) -> FlightLog:
    """Decode ``log_path`` and write ``out_dir/<stream>.parquet`` + ``out_dir/meta.json``.

    Parameters
    ----------
    log_path : path-like
        The flight log (file or ROS 2 bag directory).
    out_dir : path-like
        Output directory (``results/ingest/<flight>``).
    flight_id : str
        Manifest flight id.
    fmt : str, optional
        Forced reader name (manifest ``format`` column); detected from the bytes when empty.
    labels : path-like, optional
        A labels/truth side-car to attach (manifest ``labels`` column when it is a path).
    config : dict, optional
        The ``ingest`` config section.

    Returns
    -------
    FlightLog
        The decoded log, or an empty one with ``meta['status'] == 'failed'``.
    """
    kwargs = {"fmt": fmt or None, "flight_id": flight_id, "config": config}
    if labels:
        kwargs["labels"] = labels
    try:
        log = read_log(log_path, **kwargs)
    except IngestError as exc:
        print(f"uavpipe ingest: FAILED {exc}", file=sys.stderr)
        log = FlightLog.from_streams({"flight_id": flight_id, "source_path": str(log_path),
                                      "status": "failed", "error": exc.reason}, {})
    else:
        print(f"uavpipe ingest: {log_path} -> {out_dir} ({log.meta['source_format']}, "
              f"{log.duration_s:.1f} s, {log.meta['status']})", file=sys.stderr)
    write_flightlog(log, Path(out_dir))
    return log


def run_ingest(inputs, outputs, config=None, *, flight_id, fmt=None):  # TEMP shim until h-perf merge
    labels = list(inputs.labels) if hasattr(inputs, "labels") else list(inputs.get("labels", []))
    log = inputs.log if hasattr(inputs, "log") else inputs["log"]
    meta = outputs.meta if hasattr(outputs, "meta") else outputs["meta"]
    return _run_ingest_old(log, Path(meta).parent, flight_id=flight_id, fmt=fmt,
                           labels=labels[0] if labels else None, config=config)
