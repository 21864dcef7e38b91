"""Entry point of the preprocessing stage: one ingested flight -> its derived tables.

:func:`run_preprocess` is what the workflow's ``preprocess_flight`` rule and ``uavpipe
preprocess`` both call, with the declared paths:

* ``inputs.meta``: the flight's ingest ``meta.json`` (its streams beside it, ``write_flightlog``
  layout; ``inputs.streams`` may list them, they are read from the same folder);
* ``outputs.state``, ``outputs.segments``, ``outputs.calibration``: Parquet tables;
  ``outputs.info``: the diagnostics as JSON.

A flight whose ingest failed (``meta.json`` ``status: failed``) gets *placeholder* outputs:
empty ``state``/``segments``/``calibration`` tables with the full schema and ``status: failed``
plus the ingest's reason in the table metadata and the JSON diagnostics, so every downstream job
still finds its inputs and reports the failure instead of crashing. So does a flight whose
preprocessing raises (a time base spanning days, :class:`~.resample.TimeBaseError`; a numerical
failure; out of memory): its reason is one line, ``preprocessing failed: ...``, and one bad
flight never stops the others. A configuration error (:class:`~pipeline.config.ConfigError`)
still raises: it is no flight's fault, and every flight would fail the same way.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

from ..config import ConfigError
from ..io import schema
from ..io.parquet import read_flightlog, write_json, write_table
from ..io.stage import declared, exception_line, one_line, say
from .calibrate import CALIBRATION
from .resample import TimeBaseError
from .state import PreprocessResult, preprocess_log, summary_line, write_outputs


@dataclass(frozen=True)
class PreprocessStageResult:
    """What :func:`run_preprocess` did: ``status`` (``ok``/``failed``) and the diagnostics."""

    flight_id: str | None
    status: str
    diagnostics: dict




def run_preprocess(inputs, outputs, config: Mapping | None = None, *,
                   vehicle: str | None = None) -> PreprocessStageResult:
    """Preprocess one ingested flight into the four declared outputs.

    Parameters
    ----------
    inputs : mapping
        ``meta``: the ingest ``meta.json`` (its ``<stream>.parquet`` files beside it).
    outputs : mapping
        ``state``, ``segments``, ``calibration`` (Parquet) and ``info`` (JSON diagnostics).
    config : mapping, optional
        The validated ``preprocess`` section.
    vehicle : str, optional
        The manifest's vehicle key (``preprocess.vehicles``).

    Returns
    -------
    PreprocessStageResult
    """
    meta_path = Path(declared(inputs, "meta"))
    paths = {k: declared(outputs, k) for k in ("state", "segments", "calibration", "info")}
    try:
        meta = json.loads(meta_path.read_text())
        if not isinstance(meta, dict):
            raise ValueError(f"expected a JSON object, got {type(meta).__name__}")
    except (OSError, ValueError) as exc:  # a damaged meta.json: this flight's placeholder, named
        return _placeholder(paths, meta_path.parent.name,
                            f"cannot read {meta_path}: {exception_line(exc, where=False)}")
    fid = meta.get("flight_id")
    if meta.get("status") == "failed":
        return _placeholder(paths, fid, f"ingest failed: {meta.get('error') or 'unknown reason'}")
    try:
        log = read_flightlog(meta_path.parent)
    except (ValueError, OSError) as exc:     # a damaged or swapped stream file, named
        return _placeholder(paths, fid, f"cannot read the ingested streams: {one_line(exc)}")
    missing = log.meta.get("missing_streams") or []
    if missing:
        # ingest writes every stream, empty ones too: a missing file is damage, read as empty
        say("uavpipe preprocess", f"{fid}: {', '.join(f'{s}.parquet' for s in missing)} missing from "
                                  f"{meta_path.parent}; read as empty")
    try:
        res = preprocess_log(log, config, vehicle=vehicle or None)
    except ConfigError:
        raise
    except Exception as exc:  # one bad flight never stops the others: its placeholder says why
        return _placeholder(paths, fid, f"preprocessing failed: {_one_line(exc)}")
    diag = {**res.diagnostics, "status": "ok", **({"missing_streams": missing} if missing else {})}
    res = PreprocessResult(state=res.state, segments=res.segments, calibration=res.calibration,
                           diagnostics=diag)
    write_outputs(res, state_path=paths["state"], segments_path=paths["segments"],
                  calibration_path=paths["calibration"], info_path=paths["info"])
    say("uavpipe preprocess", f"{fid}: {summary_line(diag)}", restated=True)
    return PreprocessStageResult(flight_id=fid, status="ok", diagnostics=diag)


def _one_line(exc: BaseException) -> str:
    """``exc`` as one line: the message alone for a :class:`TimeBaseError` (it says what and
    why); :func:`~pipeline.io.stage.exception_line` otherwise."""
    if isinstance(exc, TimeBaseError):
        return one_line(exc) or "(no message)"
    return exception_line(exc)


def _placeholder(paths: Mapping, fid: str | None, reason: str) -> PreprocessStageResult:
    """Write the failed flight's placeholder outputs (empty tables with the full schema,
    ``status: failed`` and ``reason`` in their metadata and the JSON diagnostics)."""
    diag = {"flight_id": fid, "status": "failed", "error": reason}
    extra = {"flight_id": fid, "status": "failed", "error": reason}
    write_table(schema.empty("state"), paths["state"], schema.STATE, name="state", extra=extra)
    write_table(schema.empty("segments"), paths["segments"], schema.SEGMENTS, name="segments", extra=extra)
    write_table(schema.empty("calibration"), paths["calibration"], CALIBRATION, name="calibration", extra=extra)
    write_json(diag, paths["info"])
    say("uavpipe preprocess", f"{fid}: placeholder outputs ({reason})", restated=True)
    return PreprocessStageResult(flight_id=fid, status="failed", diagnostics=diag)
