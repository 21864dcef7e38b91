"""Ingest one flight into the Parquet store: the stage's one entry point, :func:`run_ingest`.

The workflow's rule and ``uavpipe ingest`` both call it, so both write the same files:
``<stream>.parquet`` for every stream of :data:`pipeline.io.schema.STREAM_NAMES` and
``meta.json``. A log that cannot be decoded does not stop the workflow: :func:`run_ingest`
writes every stream empty (full schema) and a ``meta.json`` with ``status: failed`` and the
one-line ``error``, says so in one line on stderr, so downstream rules write "failed"
placeholders and the report index lists the flight with its reason.

Rule adapter::

    run_ingest(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)

with inputs ``log`` (path) and ``labels`` (list of 0 or 1 side-car paths), outputs ``meta``
(``meta.json``) and ``streams`` (one ``<dir>/<stream>.parquet`` per stream), ``config`` the
``ingest`` section and job values ``flight_id`` and ``fmt``.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import schema
from .base import FlightLog, IngestError, Progress, losses_text
from .parquet import write_flightlog
from .stage import declared
from .registry import read_log


@dataclass(frozen=True)
class IngestResult:
    """What one ingest did.

    Attributes
    ----------
    status : str
        ``ok``, ``partial`` (records dropped or bytes skipped) or ``failed``.
    diagnostics : dict
        ``meta['diagnostics']`` as written (counts, warnings, timestamp anomalies).
    duration_s : float
        Flight duration (span of ``t_ns``), 0 when failed.
    source_format : str or None
        ``meta['source_format']``.
    error : str or None
        The one-line reason when failed.
    paths : tuple of Path
        The files written (streams, then ``meta.json``).
    """

    status: str
    diagnostics: dict = field(default_factory=dict)
    duration_s: float = 0.0
    source_format: str | None = None
    error: str | None = None
    paths: tuple[Path, ...] = ()




def _one(v) -> str | None:
    """A single path from a path or a list of 0 or 1 paths."""
    if v is None or isinstance(v, (str, os.PathLike)):
        return None if v in (None, "") else str(v)
    v = list(v)
    if len(v) > 1:
        raise ValueError(f"expected at most one path, got {len(v)}: {v}")
    return str(v[0]) if v else None


def stream_paths(outputs) -> dict[str, Path]:
    """``{stream: path, ..., "meta": path}`` from the declared outputs (``meta``, ``streams``).

    Each stream path is matched by its file name ``<stream>.parquet``; every stream of
    ``schema.STREAM_NAMES`` must be declared, and nothing else."""
    streams = [Path(p) for p in declared(outputs, "streams")]
    by_name = {p.name.removesuffix(".parquet"): p for p in streams}
    missing = [s for s in schema.STREAM_NAMES if s not in by_name]
    extra = [s for s in by_name if s not in schema.STREAM_NAMES]
    if missing or extra or len(by_name) != len(streams):
        raise ValueError(f"outputs.streams must name each of {', '.join(schema.STREAM_NAMES)}.parquet once"
                         + (f"; missing {missing}" if missing else "") + (f"; unknown {extra}" if extra else ""))
    return {**by_name, "meta": Path(declared(outputs, "meta"))}


def outputs_for(out_dir: str | os.PathLike) -> dict:
    """The declared outputs of one flight's ingest in ``out_dir``: ``{"meta": <out_dir>/meta.json,
    "streams": [<out_dir>/<stream>.parquet for each stream]}`` (the workflow's layout)."""
    d = Path(out_dir)
    return {"meta": str(d / "meta.json"), "streams": [str(d / f"{s}.parquet") for s in schema.STREAM_NAMES]}


def run_ingest(inputs, outputs, config: dict | None, *, flight_id: str, fmt: str | None = None,
               labels_embedded: bool = False, progress: Progress | None = None) -> IngestResult:
    """Decode ``inputs.log`` and write exactly the declared ``outputs``.

    Parameters
    ----------
    inputs : mapping or namedlist
        ``log``: the flight log (file or ROS 2 bag directory); ``labels``: a list of 0 or 1
        labels/truth side-car paths (a single path is accepted too).
    outputs : mapping or namedlist
        ``meta``: the ``meta.json`` path; ``streams``: one ``<dir>/<stream>.parquet`` per
        stream of ``schema.STREAM_NAMES``.
    config : dict or None
        The ``ingest`` config section (topic maps, column maps, ...).
    flight_id : str
        Manifest flight id.
    fmt : str, optional
        Forced reader name (manifest ``format`` column); detected from the bytes when empty.
    labels_embedded : bool
        The manifest says ``labels: embedded``: a log that carries none gets a warning (its
        segments would otherwise come out empty with nothing said).
    progress : callable, optional
        ``progress(done, total)`` while decoding (the CLI's progress bar).

    Returns
    -------
    IngestResult
        ``status`` ``failed`` (with ``error``) when the log could not be decoded; the files
        are written either way.
    """
    log_path = declared(inputs, "log")
    log_path = _one(log_path) if not isinstance(log_path, (str, os.PathLike)) else str(log_path)
    labels = _one(declared(inputs, "labels"))
    paths = stream_paths(outputs)
    kwargs: dict[str, Any] = {"fmt": fmt or None, "flight_id": flight_id, "config": config or None,
                              "progress": progress}
    if labels:
        kwargs["labels"] = labels
    try:
        log = read_log(log_path, **kwargs)
    except IngestError as exc:
        print(f"uavpipe ingest: FAILED {exc}", file=sys.stderr)  # the one line; no traceback
        # the log is named beside the reason everywhere; another file (a labels side-car) is not
        other = exc.path and Path(exc.path).resolve() != Path(log_path).resolve()
        log = FlightLog.from_streams({"flight_id": flight_id, "source_path": str(log_path), "status": "failed",
                                      "error": f"{exc.path}: {exc.reason}" if other else exc.reason}, {})
    if labels_embedded and log.meta.get("status") != "failed" and not len(log["labels"]):
        log.meta.setdefault("diagnostics", {}).setdefault("warnings", []).append(
            "manifest labels 'embedded', but the log carries no labelled segment (FlightCoach JSON "
            "'mans', a labels stream): its segments come from modes or windows instead")
    written = write_flightlog(log, paths=paths)
    m = log.meta
    duration = log.duration_s
    if m["status"] != "failed":
        lost = losses_text(m["diagnostics"] or {}) if m["status"] == "partial" else ""
        print(f"uavpipe ingest: {log_path} -> {paths['meta'].parent} ({m['source_format']}, "
              f"{duration:.1f} s, {m['status']}{': ' + lost if lost else ''})", file=sys.stderr)
    return IngestResult(status=m["status"], diagnostics=m["diagnostics"], duration_s=duration,
                        source_format=m.get("source_format"), error=m.get("error"), paths=tuple(written))
