"""A small ingested flight with radar and truth, and its state (the estimate and report tests)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from helpers_maneuvers import synth_run
from pipeline.estimate.models import RADAR_FIELDS, STATE_COLUMNS, RadarModel
from pipeline.io import schema
from pipeline.io.base import FlightLog
from pipeline.io.parquet import write_flightlog, write_table

#: radar site of the test flights (2 km north-west of the origin, 300 m below)
SITE = (2000.0, -1500.0, 300.0)


def ingested_flight(tmp: Path, *, radar=True, drop=(), truth=True, fid="f1") -> dict:
    """An ingested flight: M1-like truth at 5 Hz for 30 s, its radar (site :data:`SITE`,
    seed-000 noise) without rows ``drop``, level attitude; and its preprocessed state (the
    truth). Returns the estimate inputs ``{"meta", "state"}``."""
    run = synth_run("M1", np.random.default_rng(7), duration_s=30.0).drop(columns="label")
    t = run["t_ns"].to_numpy()
    model = RadarModel(site_ned_m=SITE)
    z = model.measure(run[list(STATE_COLUMNS)].to_numpy(), np.random.default_rng(8))
    keep = np.setdiff1d(np.arange(len(t)), np.asarray(drop, dtype=int))
    streams = {"attitude": pd.DataFrame({"t_ns": t, "q_w": 1.0, "q_x": 0.0, "q_y": 0.0, "q_z": 0.0})}
    if radar:
        streams["radar"] = pd.DataFrame({"t_ns": t[keep], **dict(zip(RADAR_FIELDS, z[keep].T))})
    if truth:
        streams["truth"] = run[["t_ns", *STATE_COLUMNS]]
    meta = {"flight_id": fid, "radar": {"site_ned_m": list(SITE), "tau_rd_s": 0.0}}
    d = tmp / "ingest" / fid
    write_flightlog(FlightLog.from_streams(meta, streams), d)
    state = tmp / "state" / f"{fid}.parquet"
    state.parent.mkdir(parents=True, exist_ok=True)
    write_table(schema.conform("state", run), state, schema.STATE, name="state")
    return {"meta": d / "meta.json", "state": state}
