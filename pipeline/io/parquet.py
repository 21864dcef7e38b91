"""Parquet store for FlightLogs and derived tables.

Layout (style.md §3.3): ``DIR/<stream>.parquet`` (ZSTD) for every canonical stream plus
``DIR/meta.json``. Each Parquet file carries key-value metadata ``uavpipe`` = JSON with
``schema_version``, ``stream`` and ``columns`` (``{name: {unit, frame}}``); each field also
has ``unit``/``frame`` field metadata. Writes are atomic (temp file + rename) so a killed job
never leaves a half-written output that a cluster scheduler would take as done.
:func:`read_flightlog` round-trips :func:`write_flightlog` exactly (values and dtypes).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from . import schema
from .base import FlightLog

META_KEY = b"uavpipe"


def _atomic_path(target: Path) -> Path:
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
    os.close(fd)
    return Path(tmp)


def write_table(df: pd.DataFrame, path: str | os.PathLike, cols: tuple[schema.Column, ...] | None = None,
                *, name: str = "", extra: dict | None = None) -> None:
    """Write one DataFrame as ZSTD Parquet with units/frames and ``schema_version`` metadata.

    Parameters
    ----------
    df : DataFrame
        The table. With ``cols`` given its columns must match them (canonical tables);
        otherwise (free-form result tables) units are taken from ``extra['units']`` if present.
    cols : tuple of Column, optional
        Declared columns (``schema.columns(stream)``, ``schema.STATE``...).
    name : str
        Table name recorded in the metadata.
    extra : dict, optional
        Additional JSON-able metadata merged into the ``uavpipe`` key.
    """
    path = Path(path)
    if cols is not None:
        arrow_schema = schema.arrow_schema_for(tuple(cols))
        table = pa.Table.from_pandas(df[[c.name for c in cols]], schema=arrow_schema, preserve_index=False)
        colmeta = {c.name: {"unit": c.unit, "frame": c.frame} for c in cols}
    else:
        table = pa.Table.from_pandas(df, preserve_index=False)
        colmeta = (extra or {}).get("units", {})
    meta = {"schema_version": schema.SCHEMA_VERSION, "table": name, "columns": colmeta}
    if extra:
        meta.update({k: v for k, v in extra.items() if k != "units"})
    md = dict(table.schema.metadata or {})
    md[META_KEY] = json.dumps(meta, default=_json_default).encode()
    table = table.replace_schema_metadata(md)
    tmp = _atomic_path(path)
    try:
        pq.write_table(table, tmp, compression="zstd")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def read_table_meta(path: str | os.PathLike) -> dict:
    """The ``uavpipe`` metadata of a Parquet file written by :func:`write_table`."""
    md = pq.read_schema(path).metadata or {}
    return json.loads(md.get(META_KEY, b"{}"))


def read_table(path: str | os.PathLike, cols: tuple[schema.Column, ...] | None = None) -> pd.DataFrame:
    """Read a table written by :func:`write_table`, restoring declared pandas dtypes."""
    df = pq.read_table(path).to_pandas()
    if cols is None:
        return df
    return pd.DataFrame({c.name: schema.cast(c, df[c.name]) for c in cols}) if len(df) else schema.empty(cols)


def _json_default(o: Any):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        f = float(o)
        return None if math.isnan(f) else f
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (Path,)):
        return str(o)
    if isinstance(o, (set, tuple)):
        return list(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def write_json(obj: Any, path: str | os.PathLike) -> None:
    """Atomic, deterministic (sorted keys) JSON write."""
    path = Path(path)
    tmp = _atomic_path(path)
    try:
        tmp.write_text(json.dumps(obj, indent=1, sort_keys=True, default=_json_default, allow_nan=False))
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_flightlog(log: FlightLog, out_dir: str | os.PathLike) -> list[Path]:
    """Write every canonical stream and ``meta.json`` into ``out_dir``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in schema.STREAM_NAMES:
        df = schema.conform(name, log.streams.get(name))
        p = out / f"{name}.parquet"
        write_table(df, p, schema.columns(name), name=name, extra={"flight_id": log.meta.get("flight_id")})
        paths.append(p)
    mp = out / "meta.json"
    write_json(log.meta, mp)
    paths.append(mp)
    return paths


def read_flightlog(in_dir: str | os.PathLike, streams: list[str] | None = None) -> FlightLog:
    """Read a FlightLog written by :func:`write_flightlog` (all streams, or ``streams``)."""
    d = Path(in_dir)
    meta = json.loads((d / "meta.json").read_text())
    out = {}
    for name in streams or schema.STREAM_NAMES:
        p = d / f"{name}.parquet"
        out[name] = read_table(p, schema.columns(name)) if p.exists() else schema.empty(name)
    return FlightLog(meta=meta, streams=out)
