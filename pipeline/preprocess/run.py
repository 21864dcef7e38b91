"""Workflow entry point of the preprocessing stage: one ingested flight -> its derived tables.

A flight whose ingest failed (``meta.json`` ``status: failed``) gets *placeholder* outputs:
empty ``state``/``segments``/``calibration`` tables with the full schema and
``status: failed`` plus the ingest's reason in the table metadata and the JSON diagnostics, so
every downstream job still finds its inputs and reports the failure instead of crashing.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Mapping

import pandas as pd

from ..io import schema
from ..io.parquet import read_flightlog, write_json, write_table
from .calibrate import CALIBRATION
from .state import run_preprocess, summary_line, write_outputs


def _empty(cols) -> pd.DataFrame:
    return schema.empty(cols)


def run_preprocess_flight(ingest_dir: str | os.PathLike, *, state_path, segments_path,
                          calibration_path, info_path, config: Mapping | None = None,
                          vehicle: str | None = None) -> dict:
    """Preprocess ``ingest_dir`` (``write_flightlog`` layout) into the four declared outputs.

    Returns the diagnostics dict (``status`` is ``ok`` or ``failed``).
    """
    meta = json.loads((Path(ingest_dir) / "meta.json").read_text())
    fid = meta.get("flight_id")
    if meta.get("status") == "failed":
        reason = f"ingest failed: {meta.get('error') or 'unknown reason'}"
        diag = {"flight_id": fid, "status": "failed", "error": reason}
        extra = {"flight_id": fid, "status": "failed", "error": reason}
        write_table(_empty(schema.STATE), state_path, schema.STATE, name="state", extra=extra)
        write_table(_empty(schema.SEGMENTS), segments_path, schema.SEGMENTS, name="segments", extra=extra)
        write_table(_empty(CALIBRATION), calibration_path, CALIBRATION, name="calibration", extra=extra)
        write_json(diag, info_path)
        print(f"uavpipe preprocess: {fid}: placeholder outputs ({reason})", file=sys.stderr)
        return diag
    state, seg, cal = run_preprocess(read_flightlog(ingest_dir), config, vehicle=vehicle or None)
    state.attrs["preprocess"]["status"] = "ok"
    write_outputs(state, seg, cal, state_path=state_path, segments_path=segments_path,
                  calibration_path=calibration_path, info_path=info_path)
    diag = state.attrs["preprocess"]
    print(f"uavpipe preprocess: {fid}: {summary_line(diag)}", file=sys.stderr)
    return diag
