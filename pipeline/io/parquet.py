"""Parquet store for FlightLogs and derived tables.

Layout (style.md §3.3): ``DIR/<stream>.parquet`` (ZSTD) for every canonical stream plus
``DIR/meta.json``. Each Parquet file carries key-value metadata ``uavpipe`` = JSON with
``schema_version``, ``stream`` and ``columns`` (``{name: {unit, frame}}``); each field also
has ``unit``/``frame`` field metadata. Writes are atomic (temp file + rename) so a killed job
never leaves a half-written output that a cluster scheduler would take as done.
:func:`read_flightlog` round-trips :func:`write_flightlog` exactly (values and dtypes).

:func:`write_flightlog` writes the log's conformed Arrow tables as they are (no pandas, no
second conform); files also carry the ``pandas`` schema metadata ``pa.Table.from_pandas``
would write, so ``pd.read_parquet`` restores the same dtypes as for tables written from pandas.
"""

from __future__ import annotations

import json
import math
import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from . import schema
from .atomic import atomic_output, write_text_atomic
from .base import FlightLog
from .lazy import pandas as pd  # imported on first use: the FlightLog path needs none

META_KEY = b"uavpipe"


def _write_arrow(table: pa.Table, path: Path, meta: dict) -> None:
    """Atomic ZSTD write of ``table`` with ``meta`` as the ``uavpipe`` schema metadata."""
    md = dict(table.schema.metadata or {})
    md[META_KEY] = json.dumps(json_safe(meta), default=_json_default, allow_nan=False).encode()
    table = table.replace_schema_metadata(md)
    with atomic_output(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def write_table(df: pd.DataFrame, path: str | os.PathLike, cols: tuple[schema.Column, ...] | None = None,
                *, name: str = "", extra: dict | None = None) -> None:
    """Write one DataFrame as ZSTD Parquet with units/frames and ``schema_version`` metadata.

    Parameters
    ----------
    df : DataFrame
        The table. With ``cols`` given its columns must match them; without, ``name`` must be a
        table of :data:`pipeline.io.schema.TABLES` (the studies' result tables) and the columns
        ``df`` holds are cast to that declaration, in its order
        (:func:`pipeline.io.schema.layout`).
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
        # no free-form tables: a result table is declared in io/schema.py under its name, so
        # its file has the declared types, units and order whichever columns this run computed
        if name not in schema.TABLES:
            raise schema.SchemaError(f"{path.name}: table {name!r} is not declared in pipeline/io/schema.py")
        if len(df.columns) == 0:
            df = schema.empty(name)  # a part that did not run: its declared columns, no rows
        try:
            cols = schema.layout(name, df.columns)
            df = schema.conform(cols, df)
        except schema.SchemaError as exc:
            raise schema.SchemaError(f"{path.name}: {exc}") from None
        return write_table(df, path, cols, name=name, extra=extra)
    meta = {"schema_version": schema.SCHEMA_VERSION, "table": name, "columns": colmeta}
    if extra:
        meta.update(extra)
    _write_arrow(table, path, meta)


#: what reading a damaged, missing or foreign table raises (:func:`read_table`,
#: :func:`read_table_meta`): the OS's errors, pyarrow's (its ArrowInvalid is also a ValueError)
#: and the JSON metadata's; a stage catches these to make one flight's bad file its placeholder
READ_ERRORS: tuple[type[BaseException], ...] = (OSError, ValueError, pa.ArrowException)


def read_table_meta(path: str | os.PathLike) -> dict:
    """The ``uavpipe`` metadata of a Parquet file written by :func:`write_table`."""
    md = pq.read_schema(path).metadata or {}
    return json.loads(md.get(META_KEY, b"{}"))


def read_table(path: str | os.PathLike, cols: tuple[schema.Column, ...] | None = None) -> pd.DataFrame:
    """Read a table written by :func:`write_table`, restoring declared pandas dtypes."""
    table = pq.read_table(path)
    if cols is None:
        return table.to_pandas()
    return schema.frame_from_arrow(tuple(cols), table)


def json_safe(obj: Any) -> Any:
    """``obj`` with every non-finite float (Python or NumPy, at any depth) as ``None``.

    ``json.dumps`` writes NaN and Infinity as bare tokens that are not JSON: pyarrow, browsers
    and ``jq`` then refuse the metadata of an otherwise good table (a bearing bank whose
    heading never converged reports its convergence time as NaN). ``null`` is JSON's "no value".
    """
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray) and obj.dtype.kind == "f":
        return [json_safe(v) for v in obj.tolist()]
    return obj


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
    write_text_atomic(path, json.dumps(json_safe(obj), indent=1, sort_keys=True, default=_json_default,
                                       allow_nan=False))


def write_flightlog(log: FlightLog, out_dir: str | os.PathLike | None = None, *,
                    paths: dict[str, str | os.PathLike] | None = None) -> list[Path]:
    """Write every canonical stream and ``meta.json``; returns the paths written.

    Either ``out_dir`` (``<out_dir>/<stream>.parquet`` and ``<out_dir>/meta.json``) or
    ``paths``: ``{stream: path, ..., "meta": path}`` with every stream of
    ``schema.STREAM_NAMES`` (the workflow's declared outputs). Each stream's conformed Arrow
    table is written as it is (``FlightLog.table``), with the same units/frames/
    ``schema_version`` metadata as :func:`write_table`.
    """
    if paths is None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {**{name: out / f"{name}.parquet" for name in schema.STREAM_NAMES}, "meta": out / "meta.json"}
    def write_one(name: str) -> Path:
        cols = schema.columns(name)
        table = log.table(name)
        md = dict(table.schema.metadata or {})
        md[b"pandas"] = schema.pandas_metadata(cols, table)
        table = table.replace_schema_metadata(md)
        p = Path(paths[name])
        meta = {"schema_version": schema.SCHEMA_VERSION, "table": name,
                "columns": {c.name: {"unit": c.unit, "frame": c.frame} for c in cols},
                "flight_id": log.meta.get("flight_id")}
        _write_arrow(table, p, meta)
        return p

    for name in schema.STREAM_NAMES:
        log.table(name)  # build any stream held as a DataFrame here, not in the threads
    # Parquet encoding and ZSTD release the GIL: the streams are written in parallel
    with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
        written = list(pool.map(write_one, schema.STREAM_NAMES))
    mp = Path(paths["meta"])
    write_json(log.meta, mp)
    written.append(mp)
    return written


def read_flightlog(in_dir: str | os.PathLike, streams: list[str] | None = None) -> FlightLog:
    """Read a FlightLog written by :func:`write_flightlog` (all streams, or ``streams``).

    Streams are held as the Arrow tables read; ``log[name]`` converts one to pandas on first use.
    A stream file whose metadata names another table (a copied or renamed file) is a
    ``ValueError`` naming the file; a missing stream file reads as empty, and its name is listed
    in ``log.meta["missing_streams"]`` (ingest writes every stream, empty ones too, so a missing
    file is damage the caller should report)."""
    d = Path(in_dir)
    meta = json.loads((d / "meta.json").read_text())
    out, missing = {}, []
    for name in streams or schema.STREAM_NAMES:
        p = d / f"{name}.parquet"
        if not p.exists():
            out[name] = schema.empty_arrow(name)
            missing.append(name)
            continue
        table = pq.read_table(p)
        kind = json.loads((table.schema.metadata or {}).get(META_KEY, b"{}")).get("table")
        if kind not in (None, name):
            raise ValueError(f"{p}: not the {name} stream (it holds the '{kind}' table)")
        out[name] = table.replace_schema_metadata(None)
    if missing:
        meta = {**meta, "missing_streams": missing}
    return FlightLog(meta=meta, streams=out)
