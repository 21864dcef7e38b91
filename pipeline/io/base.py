"""The canonical :class:`FlightLog`, the :class:`LogReader` interface and :class:`IngestError`.

A reader turns one source (file or bag directory) into a ``FlightLog``: ``meta`` (see
:func:`pipeline.io.schema.new_meta`) plus one table per canonical stream. Readers build loose
tables with whatever subset of columns their source has -- pandas DataFrames, mappings of NumPy
arrays (or lists of such parts), or Arrow tables -- and hand them to
:meth:`FlightLog.from_streams`, which conforms each stream once to ``schema.py``, counts
timestamp anomalies in arrival order and fills every absent stream with an empty, fully typed
table.

A FlightLog holds one conformed ``pyarrow.Table`` per stream (what the Parquet store writes, as
it is); ``log.streams[name]`` and ``log[name]`` give pandas DataFrames, converted on first use
and cached, so DataFlash and tlog ingest never import pandas.
"""

from __future__ import annotations

import abc
import hashlib
import os
from collections.abc import Mapping, MutableMapping
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import numpy as np
import pyarrow as pa

from . import schema

#: progress callback: ``progress(done_units, total_units)``
Progress = Callable[[int, int], None]


class IngestError(Exception):
    """A log could not be ingested. ``str(err)`` is one line naming the file and the reason."""

    def __init__(self, path: str | os.PathLike | None, reason: str):
        self.path = None if path is None else str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}" if self.path else reason)


def _is_frame(x) -> bool:
    """A pandas DataFrame, recognised without importing pandas."""
    return hasattr(x, "iloc") and hasattr(x, "columns")


class StreamFrames(MutableMapping):
    """``log.streams``: stream name -> pandas DataFrame, backed by the log's Arrow tables.

    Reading converts the stream's conformed table once (cached); assigning a DataFrame (a
    side-car's truth, a test's edit) replaces the stream, whose table is rebuilt from it when
    next written.
    """

    def __init__(self, log: "FlightLog"):
        self._log = log

    def __getitem__(self, name: str):
        log = self._log
        if name in log._frames:
            return log._frames[name]
        if name not in log._tables:
            raise KeyError(name)
        df = schema.frame_from_arrow(schema.columns(name), log._tables[name])
        log._frames[name] = df
        return df

    def __setitem__(self, name: str, df) -> None:
        if name not in schema.STREAM_NAMES:
            raise schema.SchemaError(f"unknown stream {name!r}")
        self._log._frames[name] = df
        self._log._tables[name] = None  # rebuilt from the frame when needed

    def __delitem__(self, name: str) -> None:
        self._log._tables.pop(name)
        self._log._frames.pop(name, None)

    def __iter__(self) -> Iterator[str]:
        return iter(list(self._log._tables))

    def __len__(self) -> int:
        return len(self._log._tables)

    def __contains__(self, name) -> bool:
        return name in self._log._tables


#: Half-width of the window around a log's median time stamp outside which a sample cannot
#: belong to the flight (ns): 3 days, the window the tlog reader and pymavlink's tlog resync use,
#: widened to 4 interquartile ranges of the stamps for a log that is itself days long.
TIME_WINDOW_NS = 3 * 24 * 3600 * 1_000_000_000
_TIME_WINDOW_IQRS = 4.0
_TIME_SAMPLE = 1 << 20  # stamps pooled for the quantiles (every k-th of each stream)


def last_params(params) -> dict[str, float]:
    """``{name: the last value set}`` of a ``params`` stream (a DataFrame; a parameter set in
    flight is logged again when it changes; a value that is no number is NaN)."""
    import pandas as pd  # here, not at the top: DataFlash and tlog ingest never import pandas

    if params is None or not len(params) or "name" not in params:
        return {}
    p = params.dropna(subset=["name"]).sort_values("t_ns", kind="stable")
    v = pd.to_numeric(p["value"], errors="coerce").to_numpy(np.float64)
    return {str(k): float(x) for k, x in zip(p["name"].astype(str), v)}


#: more kinds of one drop reason than this (``format_lost:<type>``) are said as one phrase
MAX_DROP_KINDS = 3


def grouped_drops(dropped: Mapping[str, int] | None) -> list[tuple[str, int]]:
    """``records_dropped`` as ``(reason, count)``: the kinds of one reason (``format_lost:131``,
    ``format_lost:42``, ... one per message type a damaged log lost) folded into one entry,
    ``("format_lost, 48 kinds: 131, 42, 200, ...", total)``, when there are more than
    :data:`MAX_DROP_KINDS`; a damaged DataFlash log listed 50 of them in one line."""
    by: dict[str, list[tuple[str, int]]] = {}
    for reason, n in (dropped or {}).items():
        head, _, kind = str(reason).partition(":")
        by.setdefault(head if kind else str(reason), []).append((kind or str(reason), int(n)))
    out = []
    for head, kinds in by.items():
        if len(kinds) > MAX_DROP_KINDS:
            kinds.sort(key=lambda k: -k[1])
            shown = ", ".join(k for k, _ in kinds[:MAX_DROP_KINDS])
            out.append((f"{head}, {len(kinds)} kinds: {shown}, ...", sum(n for _, n in kinds)))
        else:
            out += [(f"{head}:{k}" if k != head else head, n) for k, n in kinds]
    return out


def losses_text(diag: Mapping[str, Any]) -> str:
    """What decoding lost, from a log's ``diagnostics``: ``"3 bytes skipped, 1 records dropped
    (truncated)"``; ``""`` when nothing was lost."""
    parts = []
    if diag.get("bytes_skipped"):
        parts.append(f"{diag['bytes_skipped']} bytes skipped")
    dropped = diag.get("records_dropped") or {}
    if isinstance(dropped, dict) and dropped:  # {record type: count}
        n = sum(v for v in dropped.values() if isinstance(v, (int, float)))
        parts.append(f"{n} records dropped ({'; '.join(r for r, _ in sorted(grouped_drops(dropped)))})")
    return ", ".join(parts)


class FlightLog:
    """One flight in the canonical schema (style.md §3.2).

    Parameters
    ----------
    meta : dict, optional
        Flight metadata (``schema.new_meta`` keys); default ``schema.new_meta()``.
    streams : dict, optional
        Stream name -> *conformed* table (pyarrow.Table or pandas DataFrame), as
        :func:`pipeline.io.parquet.read_flightlog` builds it. Readers use :meth:`from_streams`.

    Attributes
    ----------
    meta : dict
    streams : StreamFrames
        Every stream of ``schema.STREAM_NAMES`` as a pandas DataFrame (lazily converted).
    """

    def __init__(self, meta: dict[str, Any] | None = None, streams: dict | None = None):
        self.meta = schema.new_meta() if meta is None else meta
        self._tables: dict[str, pa.Table | None] = {}
        self._frames: dict[str, Any] = {}
        for name, t in (streams or {}).items():
            if isinstance(t, pa.Table):
                self._tables[name] = t
            else:
                self._tables[name] = None
                self._frames[name] = t

    @property
    def streams(self) -> StreamFrames:
        return StreamFrames(self)

    def __repr__(self) -> str:
        return (f"FlightLog(flight_id={self.meta.get('flight_id')!r}, "
                f"streams={ {n: r for n, r in self.n_rows().items() if r} })")

    def n_rows(self) -> dict[str, int]:
        """Rows per stream the log holds (streams never set are absent)."""
        return {n: (t.num_rows if t is not None else len(self._frames[n])) for n, t in self._tables.items()}

    def table(self, name: str) -> pa.Table:
        """The conformed Arrow table of stream ``name`` (empty with full schema when absent)."""
        t = self._tables.get(name)
        if t is None:
            if name in self._frames:
                t = schema.conform_arrow(name, self._frames[name])
                self._tables[name] = t
            else:
                t = schema.empty_arrow(name)
        return t

    def set_table(self, name: str, table: pa.Table) -> None:
        """Replace stream ``name`` by a conformed Arrow table (its schema is checked)."""
        if not table.schema.equals(schema.arrow_schema(name)):
            raise schema.SchemaError(f"set_table({name!r}): schema differs from the canonical one")
        self._tables[name] = table
        self._frames.pop(name, None)

    @classmethod
    def from_streams(cls, meta: dict, streams: dict) -> "FlightLog":
        """Conform reader output: canonical columns/dtypes, all streams, sorted, anomalies counted.

        ``streams`` maps stream names (a mapping, or an iterable of ``(name, data)`` pairs,
        consumed one at a time) to a pandas DataFrame, a mapping of columns (NumPy or Arrow
        arrays, or one scalar for all rows), a list of such mappings (parts, in file order), a
        pyarrow.Table, or ``None``. Each is conformed once
        (:func:`pipeline.io.schema.conform_arrow`). Timestamp anomalies (backwards jumps,
        duplicates) are counted per stream in the order the reader produced the rows (= file
        order) and stored in ``meta['diagnostics']['timestamp_anomalies']``; the samples are kept.
        Event streams (``schema.EVENT_STREAMS``: messages, params) are not counted.
        """
        meta = {**schema.new_meta(), **meta}
        diag = {**schema.new_diagnostics(), **(meta.get("diagnostics") or {})}
        meta["diagnostics"] = diag
        pairs = streams.items() if isinstance(streams, Mapping) else streams
        out: dict[str, pa.Table] = {}
        anomalies = dict(diag.get("timestamp_anomalies") or {})
        for name, data in pairs:
            if name not in schema.STREAM_NAMES:
                raise schema.SchemaError(f"unknown stream(s) {[name]}")
            if _is_frame(data):
                if len(data) and name != "labels" and name not in schema.EVENT_STREAMS:
                    if "instance" not in data.columns:
                        data = data.assign(instance=0)
                    a = schema.timestamp_anomalies(data)
                    if a["backwards"] or a["duplicate"]:
                        anomalies[name] = a
                out[name] = schema.arrow_table(name, data)  # conform() sorted it already
                continue
            table, a = schema.conform_arrow_counted(name, data)
            data = None  # drop the loose columns before the next stream
            if (a["backwards"] or a["duplicate"]) and name not in schema.EVENT_STREAMS:
                anomalies[name] = a
            out[name] = table
        out = {name: out[name] if name in out else schema.empty_arrow(name) for name in schema.STREAM_NAMES}
        diag["timestamp_anomalies"] = anomalies
        return cls(meta=meta, streams=out)

    def __getitem__(self, name: str):
        return self.streams[name] if name in self._tables else schema.empty(name)

    def drop_absurd_times(self) -> int:
        """Drop the samples whose ``t_ns`` cannot belong to this flight; return how many.

        The safety net of every reader (:func:`pipeline.io.registry.read_log` calls it): a
        sample farther than ``max(TIME_WINDOW_NS, 4 IQR)`` from the median ``t_ns`` of all
        time-stamped streams pooled is dropped and counted in
        ``meta['diagnostics']['records_dropped']['bad_timestamp']``, with a warning naming the
        streams. A corrupt stamp that decoded anyway (a flipped high bit: years, or
        ``-9.2e18``) would otherwise stretch the flight over centuries and make every later
        stage that grids time allocate terabytes. The window is robust (median, quartiles: a
        few corrupt stamps cannot move it) and wide (no flight spans days around its median),
        so it never cuts a real sample; corruption inside the flight's span is each reader's
        to find, where the file order is known (DataFlash: ``dataflash.streams.time_outliers``;
        tlog: framing times).
        """
        arrays = [(name, t) for name, t, _ in self._time_arrays()]
        total = sum(len(t) for _, t in arrays)
        if total < 3:
            return 0
        stride = max(1, -(-total // _TIME_SAMPLE))
        pool = np.concatenate([t[::stride] for _, t in arrays]).astype(np.float64)
        q1, med, q3 = np.quantile(pool, [0.25, 0.5, 0.75])
        half = max(float(TIME_WINDOW_NS), _TIME_WINDOW_IQRS * float(q3 - q1))
        per_stream = {}
        for name, t in arrays:
            if not np.any(np.abs(t.astype(np.float64) - med) > half):
                continue
            table = self.table(name)  # the conformed rows (a frame-backed stream is conformed here)
            far = np.abs(schema.arrow_to_np(table.column("t_ns")).astype(np.float64) - med) > half
            per_stream[name] = int(far.sum())
            self.set_table(name, table.filter(pa.array(~far)))
        n = sum(per_stream.values())
        if n:
            diag = self.meta.setdefault("diagnostics", schema.new_diagnostics())
            dropped = diag.setdefault("records_dropped", {})
            dropped["bad_timestamp"] = dropped.get("bad_timestamp", 0) + n
            diag.setdefault("warnings", []).append(
                f"{n} sample(s) with an absurd time stamp dropped (farther than {half * 1e-9 / 86400:.3g} days "
                f"from the log's median time): " + ", ".join(f"{k} {v}" for k, v in sorted(per_stream.items())))
        return n

    def _time_arrays(self) -> Iterator[tuple[str, np.ndarray, np.ndarray]]:
        """(name, t_ns, instance) of every non-empty time-stamped stream, without pandas."""
        for name in list(self._tables):
            if name == "labels":
                continue
            t = self._tables[name]
            if t is None:
                df = self._frames[name]
                if not len(df):
                    continue
                yield name, df["t_ns"].to_numpy(np.int64), df["instance"].to_numpy()
            elif t.num_rows:
                yield name, schema.arrow_to_np(t.column("t_ns")), schema.arrow_to_np(t.column("instance"))

    @property
    def duration_s(self) -> float:
        """Span of ``t_ns`` over all time-stamped streams, in seconds (0 when empty)."""
        lo, hi = self.span_ns()
        return 0.0 if lo is None else float(hi - lo) * 1e-9

    def span_ns(self, streams: Iterable[str] | None = None) -> tuple[int | None, int | None]:
        """First and last ``t_ns`` over the non-empty time-stamped ``streams`` (all when None);
        ``(None, None)`` when they hold no rows."""
        keep = None if streams is None else set(streams)
        lo, hi = None, None
        for name, t, _ in self._time_arrays():
            if keep is not None and name not in keep:
                continue
            lo = int(t.min()) if lo is None else min(lo, int(t.min()))
            hi = int(t.max()) if hi is None else max(hi, int(t.max()))
        return lo, hi

    def summary(self) -> dict[str, dict[str, float]]:
        """Per non-empty stream: rows, instances, mean rate (Hz, per instance; NaN-skipping mean)."""
        res = {}
        timed = {name: (t, inst) for name, t, inst in self._time_arrays()}
        for name in list(self._tables):
            if name == "labels":
                t = self._tables[name]
                rows = len(self._frames[name]) if t is None else t.num_rows
                if rows:
                    res[name] = {"rows": rows, "instances": 0, "rate_hz": float("nan")}
                continue
            if name not in timed:
                continue
            t, inst = timed[name]
            rates = []
            for i in np.unique(inst):
                g = t[inst == i]
                span = (g.max() - g.min()) * 1e-9
                rates.append((len(g) - 1) / span if span > 0 else float("nan"))
            ok = [r for r in rates if r == r]
            res[name] = {
                "rows": len(t),
                "instances": int(len(np.unique(inst))),
                "rate_hz": float(sum(ok) / len(ok)) if ok else float("nan"),
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
    reads_bytes : bool
        The reader decodes the whole file from memory: :func:`~pipeline.io.registry.read_log`
        reads the file once, hashes those bytes and passes them as ``read(..., data=buffer)``
        (a read-only ``uint8`` NumPy array), so the file is read once per ingest.
    magic : bytes
        The fixed bytes every file of the format starts with (``b""``: none). A file shorter
        than them that is their beginning is reported as cut inside its header, not as an
        unknown format.
    """

    name: str = ""
    source_format: str = ""
    version: str = "1"
    priority: int = 50
    reads_bytes: bool = False
    magic: bytes = b""

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


def read_file(path: str | os.PathLike) -> np.ndarray:
    """The whole file as a read-only ``uint8`` array.

    Memory-mapped with the pages populated at once (``MAP_POPULATE``, Linux): the bytes come
    from the page cache without a copy or a page fault per 4 KiB, and the mapping goes away
    with the last array viewing it. Elsewhere, or for an empty file, one ``readinto``.
    """
    import mmap

    with open(path, "rb", buffering=0) as fh:
        size = os.fstat(fh.fileno()).st_size
        populate = getattr(mmap, "MAP_POPULATE", None)
        if size and populate is not None and hasattr(mmap, "MAP_PRIVATE"):
            m = mmap.mmap(fh.fileno(), size, flags=mmap.MAP_PRIVATE | populate, prot=mmap.PROT_READ)
            return np.frombuffer(m, dtype=np.uint8)
        buf = np.empty(size, dtype=np.uint8)
        view = memoryview(buf)
        got = 0
        while got < size:
            k = fh.readinto(view[got:])
            if not k:
                break
            got += k
    buf = buf[:got]
    buf.flags.writeable = False
    return buf


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
