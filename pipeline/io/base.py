"""The canonical :class:`FlightLog`, the :class:`LogReader` interface and :class:`IngestError`.

A reader turns one source (file or bag directory) into a ``FlightLog``: ``meta`` (see
:func:`pipeline.io.schema.new_meta`) plus one DataFrame per canonical stream. Readers build
loose frames with whatever subset of columns their source has and hand them to
:meth:`FlightLog.from_streams`, which conforms them to ``schema.py``, counts timestamp
anomalies in arrival order and fills every absent stream with an empty, fully typed table.
"""

from __future__ import annotations

import abc
import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import pandas as pd

from . import schema

#: progress callback: ``progress(done_units, total_units)``
Progress = Callable[[int, int], None]


class IngestError(Exception):
    """A log could not be ingested. ``str(err)`` is one line naming the file and the reason."""

    def __init__(self, path: str | os.PathLike | None, reason: str):
        self.path = None if path is None else str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}" if self.path else reason)


@dataclass
class FlightLog:
    """One flight in the canonical schema (style.md §3.2).

    Attributes
    ----------
    meta : dict
        Flight metadata (``schema.new_meta`` keys).
    streams : dict of str to pandas.DataFrame
        Every stream of ``schema.STREAM_NAMES``, conformed; absent ones empty with full schema.
    """

    meta: dict[str, Any] = field(default_factory=schema.new_meta)
    streams: dict[str, pd.DataFrame] = field(default_factory=dict)

    @classmethod
    def from_streams(cls, meta: dict, streams: dict[str, pd.DataFrame | None]) -> "FlightLog":
        """Conform reader output: canonical columns/dtypes, all streams, sorted, anomalies counted.

        Timestamp anomalies (backwards jumps, duplicates) are counted per stream in the order
        the reader produced the rows (= file order) and stored in
        ``meta['diagnostics']['timestamp_anomalies']``; the samples are kept.
        """
        meta = {**schema.new_meta(), **meta}
        diag = {**schema.new_diagnostics(), **(meta.get("diagnostics") or {})}
        meta["diagnostics"] = diag
        unknown = [s for s in streams if s not in schema.STREAM_NAMES]
        if unknown:
            raise schema.SchemaError(f"unknown stream(s) {unknown}")
        out: dict[str, pd.DataFrame] = {}
        anomalies = dict(diag.get("timestamp_anomalies") or {})
        for name in schema.STREAM_NAMES:
            df = streams.get(name)
            if df is not None and len(df) and name != "labels":
                if "instance" not in df.columns:
                    df = df.assign(instance=0)
                a = schema.timestamp_anomalies(df)
                if a["backwards"] or a["duplicate"]:
                    anomalies[name] = a
            out[name] = schema.conform(name, df)
        diag["timestamp_anomalies"] = anomalies
        return cls(meta=meta, streams=out)

    def __getitem__(self, name: str) -> pd.DataFrame:
        return self.streams[name] if name in self.streams else schema.empty(name)

    @property
    def duration_s(self) -> float:
        """Span of ``t_ns`` over all time-stamped streams, in seconds (0 when empty)."""
        lo, hi = None, None
        for name, df in self.streams.items():
            if name == "labels" or not len(df):
                continue
            t = df["t_ns"]
            lo = t.min() if lo is None else min(lo, t.min())
            hi = t.max() if hi is None else max(hi, t.max())
        return 0.0 if lo is None else float(hi - lo) * 1e-9

    def summary(self) -> dict[str, dict[str, float]]:
        """Per non-empty stream: rows, instances, mean rate (Hz, per instance)."""
        res = {}
        for name, df in self.streams.items():
            if not len(df):
                continue
            if name == "labels":
                res[name] = {"rows": len(df), "instances": 0, "rate_hz": float("nan")}
                continue
            rates = []
            for _, g in df.groupby("instance", observed=True):
                span = (g["t_ns"].max() - g["t_ns"].min()) * 1e-9
                rates.append((len(g) - 1) / span if span > 0 else float("nan"))
            res[name] = {
                "rows": len(df),
                "instances": int(df["instance"].nunique()),
                "rate_hz": float(pd.Series(rates).mean()),
            }
        return res


class LogReader(abc.ABC):
    """One source format. Subclasses are registered with :func:`pipeline.io.registry.register`.

    Class attributes
    ----------------
    name : str
        Registry name (``dataflash``, ``tlog``, ...); also ``meta['reader']``.
    source_format : str
        Value of ``meta['source_format']``.
    version : str
        Reader version, bumped when decoded output changes (``meta['reader_version']``).
    priority : int
        Lower sniffs first (specific magic numbers before structural guesses).
    """

    name: str = ""
    source_format: str = ""
    version: str = "1"
    priority: int = 50

    @classmethod
    @abc.abstractmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        """Return a one-line reason if this reader can open ``path`` (``head``: first 64 KiB,
        ``b""`` for a directory), else ``None``. Must not raise and must not read the whole file."""

    @abc.abstractmethod
    def read(self, path: Path, *, config: dict | None = None,
             progress: Progress | None = None) -> FlightLog:
        """Decode ``path`` into a FlightLog.

        Must raise :class:`IngestError` (never a library exception) when nothing usable can be
        decoded; partial decodes return the valid records with drops counted in
        ``meta['diagnostics']``.
        """


def sha256_of(path: Path, chunk: int = 1 << 20) -> str:
    """sha256 of a file, or of a directory's files in sorted relative-path order."""
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for f in files:
        if path.is_dir():
            h.update(str(f.relative_to(path)).encode() + b"\0")
        with open(f, "rb") as fh:
            while b := fh.read(chunk):
                h.update(b)
    return h.hexdigest()


def source_size(path: Path) -> int:
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size
