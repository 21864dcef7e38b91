"""CSV / Parquet importer driven by a column map -> canonical FlightLog.

A *column map* (YAML; shipped ones live in ``pipeline/io/columnmaps/``, more can be given in
the config under ``ingest: columnmaps: {name: <path or inline mapping>}``) says how the table's
columns become canonical streams::

    name: kd0aij_flightdata
    match: {columns: [time_actual, position_x, ...]}  # header must contain all of these
    time: {column: time_actual, unit: s, epoch: boot}  # unit s|ms|us|ns|iso8601; epoch boot|unix
    constant_is_absent: true        # a column constant over the whole file was not logged
    ned_origin: first_fix           # or {lat_deg, lon_deg, alt_msl_m, alt_wgs84_m}, or omitted
    ignore: [axis_rate_roll, ...]   # known columns deliberately left out
    columns:
      position_x: {stream: local_position, column: pos_n_m, unit: m, frame: NED}
      attitude_roll: {stream: attitude, column: roll, unit: rad}   # roll/pitch/yaw -> quaternion
      mode_0: {stream: mode, column: mode, values: {5: FBWA}}       # optional value names
      some_col: {stream: ..., column: ..., unit: ..., optional: true}  # may be missing

Each mapped value is converted from its source ``unit`` to the canonical column's unit
(:data:`UNITS`: ``x_canonical = (x * s_src + o_src - o_can) / s_can``), e.g. ``deg`` -> ``rad``,
``mbar`` -> ``Pa``, ``mG`` -> ``T``, ``g`` -> ``m/s^2``. Attitude given as ZYX Euler angles
(``roll``, ``pitch``, ``yaw``) becomes the quaternion
``q = q_z(yaw) ⊗ q_y(pitch) ⊗ q_x(roll)`` (:func:`pipeline.frames.rotations.euler_to_quat`);
``mode`` rows are kept where the value changes. Time: ``t_ns = round(t * s_unit) - min_k``
(ns since the first sample), ``t_boot_ns`` the source stamp for ``epoch: boot``; ``epoch: unix``
(and ISO-8601 text) sets ``meta['t0_utc_ns']`` instead (``utc_source = "file"``).

Errors (:class:`~pipeline.io.base.IngestError`, one line naming the file): empty file or no data
rows, malformed CSV/Parquet, no column map matching the header, a mapped (non-optional) column
missing from the file, a missing or unknown unit or one of the wrong dimension, no time column.
Rows without a finite time (or one beyond the int64 ns range, ±292 years) are dropped and counted
(``records_dropped['bad_time']``), non-numeric
cells of numeric columns become NaN and are counted (``records_dropped['bad_value:<column>']``).
CSV lines holding NUL bytes (a block of the file zeroed or lost on the card: text never has
them) are dropped before parsing, their bytes counted in ``bytes_skipped`` and the rows they
held in ``records_dropped['unparseable_row']`` (:func:`drop_nul_lines`), as are lines with
fewer fields than the header, a record cut short (:func:`drop_short_lines`); columns
constant over the file, unmapped columns and absent optional ones are listed in
``meta['columnmap']`` and the warnings.

Sniffing: Parquet by its ``PAR1`` magic (the map then must come from the config or match a
shipped one), CSV by a header line whose fields look like column names, followed by a data row
(both parsed as CSV, so quoted names and cells may hold the delimiter).
"""

from __future__ import annotations

import csv
import functools
import io
import math
import mmap
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from .lazy import pandas as pd  # imported on first use (see lazy.py)
import yaml

from . import schema
from .base import FlightLog, IngestError, LogReader, Progress
from .registry import register
from .stage import one_line

#: unit -> (dimension, scale to the dimension's base unit, offset to base). Base units are SI
#: (m, m/s, m/s^2, rad, rad/s, Pa, degC, T, s, 1).
UNITS: dict[str, tuple[str, float, float]] = {
    "m": ("length", 1.0, 0.0), "cm": ("length", 0.01, 0.0), "mm": ("length", 1e-3, 0.0),
    "km": ("length", 1e3, 0.0), "ft": ("length", 0.3048, 0.0),
    "m/s": ("speed", 1.0, 0.0), "cm/s": ("speed", 0.01, 0.0), "mm/s": ("speed", 1e-3, 0.0),
    "km/h": ("speed", 1 / 3.6, 0.0), "kn": ("speed", 1852 / 3600, 0.0),
    "ft/s": ("speed", 0.3048, 0.0),
    "m/s^2": ("accel", 1.0, 0.0), "m/s2": ("accel", 1.0, 0.0), "g": ("accel", 9.80665, 0.0),
    "mg": ("accel", 9.80665e-3, 0.0),
    "rad": ("angle", 1.0, 0.0), "deg": ("angle", math.pi / 180, 0.0),
    "cdeg": ("angle", math.pi / 18000, 0.0), "mrad": ("angle", 1e-3, 0.0),
    "deg*1e7": ("angle", math.pi / 180 * 1e-7, 0.0),
    "rad/s": ("angrate", 1.0, 0.0), "deg/s": ("angrate", math.pi / 180, 0.0),
    "Pa": ("pressure", 1.0, 0.0), "hPa": ("pressure", 100.0, 0.0), "mbar": ("pressure", 100.0, 0.0),
    "kPa": ("pressure", 1e3, 0.0),
    "degC": ("temperature", 1.0, 0.0), "cdegC": ("temperature", 0.01, 0.0),
    "K": ("temperature", 1.0, -273.15),
    "T": ("magnetic", 1.0, 0.0), "uT": ("magnetic", 1e-6, 0.0), "nT": ("magnetic", 1e-9, 0.0),
    "G": ("magnetic", 1e-4, 0.0), "mG": ("magnetic", 1e-7, 0.0),
    "s": ("time", 1.0, 0.0), "ms": ("time", 1e-3, 0.0), "us": ("time", 1e-6, 0.0),
    "ns": ("time", 1e-9, 0.0),
    "1": ("dimensionless", 1.0, 0.0),
}
#: time units of the time column (ns per unit); ``iso8601`` parses date-time text
TIME_UNITS = {"s": 1e9, "ms": 1e6, "us": 1e3, "ns": 1.0}
#: pseudo-columns of the attitude stream, turned into the quaternion
EULER = ("roll", "pitch", "yaw")

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_ .\-\[\]()/%#:]*$")


class ColumnMapError(ValueError):
    """A column map is malformed (raised as IngestError by the reader, naming the data file)."""


@dataclass(frozen=True)
class ColumnSpec:
    """How one source column maps onto a canonical column."""

    stream: str
    column: str
    unit: str | None = None
    frame: str = ""
    values: dict | None = None
    optional: bool = False


@dataclass(frozen=True, kw_only=True)
class ColumnMap:
    """A parsed column map (see the module docstring)."""

    name: str
    columns: dict[str, ColumnSpec]
    time_column: str
    time_unit: str = "s"
    time_epoch: str = "boot"
    match: tuple[str, ...] = ()
    constant_is_absent: bool = True
    ned_origin: Any = None
    ignore: tuple[str, ...] = ()
    description: str = ""
    origin: str = "config"
    extra: dict = field(default_factory=dict)

    @property
    def signature(self) -> tuple[str, ...]:
        """Columns a header must contain for this map to apply."""
        return self.match or (self.time_column, *[c for c, s in self.columns.items() if not s.optional])


def parse_columnmap(obj: Any, *, name: str | None = None, origin: str = "config") -> ColumnMap:
    """Validate a column-map mapping (as loaded from YAML) into a :class:`ColumnMap`.

    Raises
    ------
    ColumnMapError
        On a missing ``time``/``columns`` key or a malformed entry. Units are checked when the
        map is applied, so that the error names the data file as well.
    """
    if not isinstance(obj, dict):
        raise ColumnMapError(f"column map {name!r} must be a mapping, got {type(obj).__name__}")
    nm = str(obj.get("name") or name or "columnmap")
    time = obj.get("time")
    if not isinstance(time, dict) or not time.get("column"):
        raise ColumnMapError(f"column map {nm!r}: 'time: {{column, unit}}' is required")
    cols = obj.get("columns")
    if not isinstance(cols, dict) or not cols:
        raise ColumnMapError(f"column map {nm!r}: 'columns' must be a non-empty mapping")
    specs = {}
    for src, spec in cols.items():
        if not isinstance(spec, dict) or "stream" not in spec or "column" not in spec:
            raise ColumnMapError(f"column map {nm!r}: column {src!r} needs 'stream' and 'column'")
        unit = spec.get("unit")
        specs[str(src)] = ColumnSpec(stream=str(spec["stream"]), column=str(spec["column"]),
                                     unit=None if unit is None else str(unit),
                                     frame=str(spec.get("frame") or ""),
                                     values=spec.get("values"), optional=bool(spec.get("optional", False)))
    match = obj.get("match") or {}
    return ColumnMap(name=nm, columns=specs, time_column=str(time["column"]),
                     time_unit=str(time.get("unit", "s")), time_epoch=str(time.get("epoch", "boot")),
                     match=tuple(str(c) for c in (match.get("columns") or ())),
                     constant_is_absent=bool(obj.get("constant_is_absent", True)),
                     ned_origin=obj.get("ned_origin"), ignore=tuple(str(c) for c in obj.get("ignore") or ()),
                     description=str(obj.get("description") or ""), origin=origin)


def load_columnmap(path: str | Path) -> ColumnMap:
    """Load one column-map YAML file."""
    p = Path(path)
    try:
        obj = yaml.safe_load(p.read_text())
    except OSError as exc:
        raise ColumnMapError(f"column map {p}: cannot read: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise ColumnMapError(f"column map {p}: invalid YAML: {exc}") from None
    return parse_columnmap(obj, name=p.stem, origin=str(p))


@functools.lru_cache(maxsize=1)
def shipped_columnmaps() -> dict[str, ColumnMap]:
    """The column maps shipped in ``pipeline/io/columnmaps/*.yaml``, by name."""
    out = {}
    for entry in sorted(resources.files("pipeline.io.columnmaps").iterdir(), key=lambda e: e.name):
        if entry.name.endswith((".yaml", ".yml")):
            m = parse_columnmap(yaml.safe_load(entry.read_text()), name=entry.name.rsplit(".", 1)[0],
                                origin=f"shipped:{entry.name}")
            out[m.name] = m
    return out


def configured_columnmaps(config: dict | None) -> dict[str, ColumnMap]:
    """Column maps from the ``ingest`` config: ``columnmaps: {name: path | mapping}`` (or a list)."""
    raw = (config or {}).get("columnmaps") or {}
    items = raw.items() if isinstance(raw, dict) else enumerate(raw)
    out = {}
    for key, val in items:
        if isinstance(val, (str, Path)):
            m = load_columnmap(val)
        else:
            m = parse_columnmap(val, name=None if isinstance(key, int) else str(key))
        out[m.name] = m
    return out


def convert_unit(x: np.ndarray, src: str, dst: str) -> np.ndarray:
    """Convert values from unit ``src`` to unit ``dst`` (keys of :data:`UNITS`)."""
    if src not in UNITS:
        raise ColumnMapError(f"unknown unit {src!r} (known: {', '.join(UNITS)})")
    if dst not in UNITS:
        raise ColumnMapError(f"unknown canonical unit {dst!r}")
    ds, ss, os_ = UNITS[src]
    dd, sd, od = UNITS[dst]
    if ds != dd:
        raise ColumnMapError(f"unit {src!r} ({ds}) cannot convert to {dst!r} ({dd})")
    if src == dst:
        return x
    return (x * ss + os_ - od) / sd


def _canonical_unit(stream: str, column: str) -> str:
    if stream == "attitude" and column in EULER:
        return "rad"
    for c in schema.columns(stream):
        if c.name == column:
            return c.unit
    raise ColumnMapError(f"stream {stream!r} has no column {column!r}")


# --- sniffing ---------------------------------------------------------------------------------

def _header_fields(head: bytes) -> tuple[list[str], str, list[str]] | None:
    """(header fields, delimiter, fields of the first data line) if ``head`` looks like a
    delimited text table with a header line, else None."""
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError as exc:
        # a cut multi-byte char at the end of head is fine, and so are garbled bytes after the
        # header and the first data line (the reader drops and counts such lines)
        if exc.start < len(head) - 4 and head[:exc.start].count(b"\n") < 2:
            return None
        text = head[:exc.start].decode("utf-8")
    text = text.lstrip("\ufeff")
    lines = text.splitlines()
    if not lines:
        return None
    hdr = lines[0]
    delim = max((",", ";", "\t"), key=hdr.count)
    try:   # parsed as CSV: a quoted name or cell may hold the delimiter
        parsed = list(csv.reader(lines[:2], delimiter=delim))
    except csv.Error:
        return None
    fields = [f.strip() for f in parsed[0]] if parsed else []
    if len(fields) < 2 or not all(_NAME.match(f) for f in fields):
        return None
    row = parsed[1] if len(parsed) > 1 else []
    return fields, delim, row


def _best_map(header: list[str], maps: dict[str, ColumnMap]) -> ColumnMap | None:
    hs = set(header)
    ok = [m for m in maps.values() if set(m.signature) <= hs]
    return max(ok, key=lambda m: len(m.signature)) if ok else None


def _numeric_share(row: list[str]) -> float:
    n = 0
    for f in row:
        try:
            float(f)
            n += 1
        except ValueError:
            pass
    return n / max(len(row), 1)


@register
class TabularReader(LogReader):
    """CSV / Parquet tables through a column map (see the module docstring)."""

    name = "tabular"
    source_format = "table"
    # 2: CSV lines with NUL bytes dropped and counted (unparseable_row); 3: non-UTF-8 lines too;
    # 4: header and first row parsed as CSV (quoted cells holding the delimiter), short rows
    # counted under a quoted header too
    version = "4"
    priority = 80  # structural guess: after every magic-number format

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        if head[:4] == b"PAR1":
            return "Parquet file (PAR1 magic); column map from ingest: columnmaps"
        hf = _header_fields(head)
        if hf is None:
            return None
        fields, delim, row = hf
        m = _best_map(fields, shipped_columnmaps())
        if m is not None:
            return f"CSV header matches shipped column map {m.name!r} ({len(m.signature)} signature columns)"
        if len(row) == len(fields) and _numeric_share(row) >= 0.5:
            return f"delimited text table, header of {len(fields)} columns (column map from config)"
        return None

    def read(self, path: Path, *, config: dict | None = None,
             progress: Progress | None = None) -> FlightLog:
        config = config or {}
        df, kind, lost = _read_table(path)
        if progress:
            progress(1, 3)
        header = [str(c) for c in df.columns]
        try:
            maps = {**shipped_columnmaps(), **configured_columnmaps(config)}
        except ColumnMapError as exc:
            raise IngestError(path, str(exc)) from None
        forced = ((config.get("tabular") or {}).get("columnmap"))
        if forced:
            if forced not in maps:
                raise IngestError(path, f"column map {forced!r} (ingest: tabular: columnmap) not found; "
                                        f"known: {', '.join(sorted(maps))}")
            cmap = maps[forced]
        else:
            cmap = _best_map(header, maps)
            if cmap is None:
                near = max(maps.values(), key=lambda m: len(set(m.signature) & set(header)), default=None)
                hint = ""
                if near is not None and set(near.signature) & set(header):
                    miss = sorted(set(near.signature) - set(header))
                    hint = f"; closest map {near.name!r} lacks column(s) {miss[:8]}"
                raise IngestError(path, f"no column map matches this {kind} header ({len(header)} columns: "
                                        f"{', '.join(header[:6])}{', ...' if len(header) > 6 else ''}){hint}; "
                                        "add one under ingest: columnmaps")
        if not len(df):
            raise IngestError(path, f"{kind} has a header but no data rows"
                                    + (f" ({lost.text})" if lost is not None else ""))
        try:
            log = _apply(df, cmap, path)
        except ColumnMapError as exc:
            raise IngestError(path, f"column map {cmap.name!r}: {exc}") from None
        if lost is not None:
            d = log.meta["diagnostics"]
            d["bytes_skipped"] = int(d.get("bytes_skipped") or 0) + lost.bytes
            d["records_dropped"]["unparseable_row"] = d["records_dropped"].get("unparseable_row", 0) + lost.rows
            d["warnings"].append(lost.text)
        log.meta["source_format"] = f"{kind}:{cmap.name}"
        if progress:
            progress(3, 3)
        return log


@dataclass(frozen=True)
class LostLines:
    """What :func:`drop_nul_lines` removed: ``lines`` (text lines), their ``bytes``, the
    ``rows`` they held (at least ``lines``; see there) and a one-line ``text``."""

    lines: int
    bytes: int
    rows: int
    text: str


def drop_nul_lines(data: bytes) -> tuple[bytes, LostLines | None]:
    """``data`` (a CSV file's bytes) without the lines that hold NUL bytes.

    A NUL never occurs in text, so a line holding one is damaged (a block zeroed or lost on the
    card): parsed, it would be one row glued from the head of one record and the tail of
    another, some later, or make the parser fail on a wrong field count. Dropped instead, and
    counted: the block also swallowed the line breaks of the records it covered, so the rows
    lost are estimated as the dropped bytes over the median length of an intact line (never
    fewer than the lines dropped).

    Raises
    ------
    ValueError
        When the header line itself holds NUL bytes.
    """
    buf = np.frombuffer(data, dtype=np.uint8)
    nul = np.flatnonzero(buf == 0)
    if not len(nul):
        return data, None
    return _drop_lines(data, nul, "with NUL bytes", f"first NUL at byte {int(nul[0])}",
                       "the header line holds NUL bytes")


def drop_undecodable_lines(data: bytes) -> tuple[bytes, LostLines | None]:
    """``data`` without the lines that are not UTF-8 text (bytes garbled on the card, a binary
    block written into the file), counted as :func:`drop_nul_lines` counts its lines.

    Raises
    ------
    ValueError
        When the header line itself is not UTF-8.
    """
    bad, start = [], 0
    while True:
        try:
            data[start:].decode("utf-8")
            break
        except UnicodeDecodeError as exc:
            pos = start + exc.start
            bad.append(pos)
            nl = data.find(b"\n", pos)
            if nl < 0:
                break
            start = nl + 1
    if not bad:
        return data, None
    return _drop_lines(data, np.asarray(bad), "that are not UTF-8 text", f"first bad byte at {bad[0]}",
                       "the header line is not UTF-8 text")


def drop_short_lines(data: bytes, sep: str) -> tuple[bytes, LostLines | None]:
    """``data`` without the data lines that have fewer ``sep``-separated fields than the header
    (a record cut short: the card lost its tail, or the file ends mid-line), counted as
    :func:`drop_nul_lines` counts its lines. The CSV parser would fill the missing cells with
    NaN and keep the row, so its other columns passed as good data with nothing counted.

    Data lines' fields are counted by separators: a quoted separator in a data line only adds
    fields, so it never makes a good line short. The header's fields are parsed as CSV (a
    quoted column name may hold the separator, which would make every line look short). A file
    with a line of unbalanced quotes (a quoted field spanning lines, which the parser joins) is
    left as it is: its pieces would look short.
    """
    if len(sep) != 1 or not data:
        return data, None
    buf = np.frombuffer(data, dtype=np.uint8)
    nl = np.flatnonzero(buf == 0x0A)
    header_end = int(nl[0]) if len(nl) else len(buf)
    line_of_sep = np.searchsorted(nl, np.flatnonzero(buf == ord(sep)))
    fields = np.bincount(line_of_sep, minlength=len(nl) + 1) + 1
    quotes = np.flatnonzero(buf == 0x22)
    if len(quotes):
        if (np.bincount(np.searchsorted(nl, quotes), minlength=len(nl) + 1) % 2).any():
            return data, None
        try:
            header = bytes(buf[:header_end]).decode("utf-8").rstrip("\r")
        except UnicodeDecodeError:      # drop_undecodable_lines names a garbled header
            return data, None
        fields[0] = len(next(csv.reader([header], delimiter=sep)))
    starts = np.concatenate([[0], nl + 1])
    ends = np.concatenate([nl, [len(buf)]])
    content = ends - starts - (buf[np.maximum(ends - 1, 0)] == 0x0D)     # without '\r\n'
    short = np.flatnonzero((fields < fields[0]) & (content > 0))
    short = short[short > 0]

    def text(i: int) -> bool:
        try:
            bytes(buf[starts[i]:ends[i]]).decode("utf-8")
            return True
        except UnicodeDecodeError:    # garbled bytes: drop_undecodable_lines names those
            return False

    short = np.array([i for i in short.tolist() if text(i)], dtype=np.int64)
    if not len(short):
        return data, None
    i = int(short[0])
    return _drop_lines(data, starts[short], f"with fewer fields than the header ({int(fields[0])})",
                       f"first line {i + 1} with {int(fields[i])} field(s)", "")


def _merge_lost(a: LostLines | None, b: LostLines | None) -> LostLines | None:
    """Two :class:`LostLines` as one (either may be None)."""
    if a is None or b is None:
        return a or b
    return LostLines(lines=a.lines + b.lines, bytes=a.bytes + b.bytes, rows=a.rows + b.rows,
                     text=f"{a.text}; {b.text}")


def _drop_lines(data: bytes, positions: np.ndarray, what: str, where: str,
                header_error: str) -> tuple[bytes, LostLines]:
    """``data`` without every line holding one of the byte ``positions``; the rows lost are
    estimated as the dropped bytes over the median length of an intact line (never fewer than
    the lines dropped). ValueError(``header_error``) when the header line is one of them."""
    buf = np.frombuffer(data, dtype=np.uint8)
    nl = np.flatnonzero(buf == 0x0A)
    starts = np.concatenate([[0], nl + 1])           # line i is data[starts[i]:ends[i]]
    ends = np.concatenate([nl + 1, [len(buf)]])
    bad = np.unique(np.searchsorted(nl, positions))   # the line holding each position ('\n' included)
    if bad[0] == 0:
        raise ValueError(header_error)
    pieces, prev = [], 0
    for i in bad.tolist():
        pieces.append(data[prev:int(starts[i])])
        prev = int(ends[i])
    pieces.append(data[prev:])
    lengths = ends - starts
    good = np.ones(len(lengths), dtype=bool)
    good[bad] = False
    good[0] = False  # the header is no data row
    good &= lengths > 1  # blank lines and the empty piece after the last '\n'
    n_bytes = int(lengths[bad].sum())
    med = float(np.median(lengths[good])) if good.any() else 0.0
    rows = max(len(bad), int(round(n_bytes / med)) if med > 0 else 0)
    text = (f"{len(bad)} line(s) {what} dropped ({n_bytes} bytes from byte {int(starts[bad[0]])}, "
            f"{where}): about {rows} row(s) lost")
    return b"".join(pieces), LostLines(lines=len(bad), bytes=n_bytes, rows=rows, text=text)


def _read_table(path: Path) -> tuple[pd.DataFrame, str, LostLines | None]:
    try:
        with open(path, "rb") as fh:
            head = fh.read(65536)
    except OSError as exc:
        raise IngestError(path, f"cannot read: {exc.strerror or exc}") from None
    if head[:4] == b"PAR1":
        import pyarrow as pa
        import pyarrow.parquet as pq

        from .parquet import read_table_meta

        try:
            kind = read_table_meta(path).get("table")
        except (pa.ArrowException, OSError, ValueError):
            kind = None                     # pq.read_table below names what is wrong
        if kind:   # written by uavpipe (a state or classification table): an output, not a log
            raise IngestError(path, f"a uavpipe '{kind}' table (a pipeline output), not a flight log")
        try:
            return pq.read_table(path).to_pandas(), "parquet", None
        except (pa.ArrowException, OSError, ValueError) as exc:
            raise IngestError(path, f"unreadable Parquet: {exc}") from None
    if not head.strip():
        raise IngestError(path, "empty CSV (no header line)")
    hf = _header_fields(head)
    sep = hf[1] if hf else ","
    src, lost = path, None
    try:
        with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as m:
            if m.find(b"\0") >= 0:  # the rare damaged file: parse a cleaned copy
                cleaned, lost = drop_nul_lines(m[:])
                src = io.BytesIO(cleaned)
            whole = src.getvalue() if isinstance(src, io.BytesIO) else m
            kept, short = drop_short_lines(whole, sep)
            if short is not None:
                src, lost = io.BytesIO(kept), _merge_lost(lost, short)
    except OSError as exc:
        raise IngestError(path, f"cannot read: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise IngestError(path, f"malformed CSV: {exc}") from None
    try:
        try:
            df = pd.read_csv(src, sep=sep)
        except UnicodeDecodeError:
            # garbled lines in a text file: parse a copy without them, counted like NUL lines
            raw = src.getvalue() if isinstance(src, io.BytesIO) else Path(path).read_bytes()
            try:
                cleaned, more = drop_undecodable_lines(raw)
            except ValueError as exc:
                raise IngestError(path, f"CSV is not UTF-8 text: {exc}") from None
            lost = _merge_lost(lost, more)
            df = pd.read_csv(io.BytesIO(cleaned), sep=sep)
    except pd.errors.EmptyDataError:
        raise IngestError(path, "empty CSV (no header line)") from None
    except pd.errors.ParserError as exc:
        raise IngestError(path, f"malformed CSV: {one_line(exc)}") from None
    except UnicodeDecodeError as exc:
        raise IngestError(path, f"CSV is not UTF-8 text: {exc.reason} at byte {exc.start}") from None
    return df, "csv", lost


def _time_ns(df: pd.DataFrame, cmap: ColumnMap) -> np.ndarray:
    """Source time stamps in ns as float64 (NaN where missing/invalid)."""
    col = df[cmap.time_column]
    if cmap.time_unit == "iso8601":
        t = pd.to_datetime(col, utc=True, errors="coerce")
        ns = t.to_numpy(dtype="datetime64[ns]").astype(np.int64).astype(np.float64)
        return np.where(t.isna().to_numpy(), np.nan, ns)
    if cmap.time_unit not in TIME_UNITS:
        raise ColumnMapError(f"time column {cmap.time_column!r}: unknown time unit {cmap.time_unit!r} "
                             f"(known: {', '.join(TIME_UNITS)}, iso8601)")
    v = pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64)
    return v * TIME_UNITS[cmap.time_unit]


def _is_constant(s: pd.Series) -> bool:
    return s.nunique(dropna=True) <= 1


def _apply(df: pd.DataFrame, cmap: ColumnMap, path: Path) -> FlightLog:
    diag = schema.new_diagnostics()
    if cmap.time_column not in df.columns:
        raise ColumnMapError(f"time column {cmap.time_column!r} missing from the file")
    missing = [c for c, s in cmap.columns.items() if c not in df.columns and not s.optional]
    if missing:
        raise ColumnMapError(f"mapped column(s) missing from the file: {missing}")
    # check every unit before touching data, so one run reports the map's problem
    targets = {}
    for src, spec in cmap.columns.items():
        if spec.stream not in schema.STREAMS:
            raise ColumnMapError(f"column {src!r}: unknown stream {spec.stream!r}")
        can = _canonical_unit(spec.stream, spec.column)
        if can in ("", None):
            targets[src] = None
            continue
        unit = spec.unit if spec.unit not in (None, "") else None
        if unit is None:
            if can == "1":
                unit = "1"
            else:
                raise ColumnMapError(f"column {src!r} -> {spec.stream}.{spec.column}: no unit given "
                                     f"(canonical unit {can!r})")
        if unit not in UNITS:
            raise ColumnMapError(f"column {src!r}: unknown unit {unit!r} (known: {', '.join(UNITS)})")
        convert_unit(np.zeros(1), unit, can)  # dimension check
        targets[src] = (unit, can)

    t_src = _time_ns(df, cmap)
    ok = np.isfinite(t_src) & (np.abs(t_src) < 2.0 ** 63 - 1024)  # beyond int64 ns: not a time
    if not ok.any():
        raise ColumnMapError(f"time column {cmap.time_column!r} has no valid value")
    if not ok.all():
        diag["records_dropped"]["bad_time"] = int((~ok).sum())
        df = df.loc[ok].reset_index(drop=True)
        t_src = t_src[ok]
    t_src_ns = np.round(t_src).astype(np.int64)
    t0 = int(t_src_ns.min())
    t_ns = t_src_ns - t0
    n = len(df)
    meta = schema.new_meta()
    if cmap.time_epoch == "unix" or cmap.time_unit == "iso8601":
        meta["t0_utc_ns"], meta["utc_source"] = t0, "file"
        t_boot = pd.array([None] * n, dtype="Int64")
    else:
        meta["t0_boot_ns"] = t0
        t_boot = t_src_ns

    absent, constant = [], []
    values: dict[str, dict[str, np.ndarray | list]] = {}
    for src, spec in cmap.columns.items():
        if src not in df.columns:
            absent.append(src)
            continue
        s = df[src]
        # one sample cannot show that a column was never logged
        if cmap.constant_is_absent and n > 1 and _is_constant(s):
            constant.append(src)
            continue
        if targets[src] is None:
            vals = _labels_of(s, spec)
        else:
            num = pd.to_numeric(s, errors="coerce").to_numpy(dtype=np.float64)
            bad = int(np.sum(np.isnan(num) & s.notna().to_numpy()))
            if bad:  # text where a number belongs: the value is lost, so count it
                diag["records_dropped"][f"bad_value:{src}"] = bad
            vals = convert_unit(num, *targets[src])
        values.setdefault(spec.stream, {})[spec.column] = vals
    if absent:
        diag["warnings"].append(f"optional mapped column(s) absent: {absent}")
    if constant:
        diag["warnings"].append(f"{len(constant)} column(s) constant over the file treated as absent: {constant}")
    known = set(cmap.columns) | set(cmap.ignore) | {cmap.time_column}
    unmapped = [c for c in map(str, df.columns) if c not in known]
    if unmapped:
        diag["warnings"].append(f"unmapped column(s) not ingested: {unmapped}")

    base = {"t_ns": t_ns, "t_boot_ns": t_boot, "instance": np.zeros(n, np.uint8),
            "src": np.full(n, cmap.name, dtype=object)}
    streams: dict[str, pd.DataFrame] = {}
    for stream, cols in values.items():
        if stream == "attitude":
            cols = _attitude(cols, diag)
            if not cols:
                continue
        if stream == "mode":
            streams[stream] = _mode_rows(base, cols)
            continue
        frame = pd.DataFrame({**base, **cols})
        data_cols = list(cols)
        has = frame[data_cols].notna().any(axis=1).to_numpy()
        streams[stream] = frame[has].reset_index(drop=True)
    if not any(len(v) for v in streams.values()):
        raise ColumnMapError("no mapped column carries data (all absent, constant or empty)")
    meta["ned_origin"] = _origin(cmap, streams.get("gps"), diag)
    meta["columnmap"] = {"name": cmap.name, "origin": cmap.origin, "absent_columns": absent,
                         "constant_columns": constant, "unmapped_columns": unmapped}
    meta["frames"] = {"world": "NED", "body": "FRD",
                      **{f"{s.stream}.{s.column}": s.frame for s in cmap.columns.values() if s.frame}}
    diag["record_counts"]["rows"] = n + int(diag["records_dropped"].get("bad_time", 0))
    meta["diagnostics"] = diag
    return FlightLog.from_streams(meta, streams)


def _labels_of(s: pd.Series, spec: ColumnSpec) -> list:
    names = {str(k): str(v) for k, v in (spec.values or {}).items()}
    out = []
    for v in s.tolist():
        if v is None or (isinstance(v, float) and math.isnan(v)):
            out.append(None)
            continue
        key = str(int(v)) if isinstance(v, (int, float, np.integer, np.floating)) and float(v).is_integer() else str(v)
        out.append(names.get(key, key))
    return out


def _attitude(cols: dict, diag: dict) -> dict:
    eul = [c for c in EULER if c in cols]
    out = {k: v for k, v in cols.items() if k not in EULER}
    if not eul:
        return out
    if len(eul) < 3:
        diag["warnings"].append(f"attitude: only {eul} of roll/pitch/yaw present -> no quaternion")
        return out
    from ..frames.rotations import euler_to_quat

    r, p, y = (np.asarray(cols[c], dtype=np.float64) for c in EULER)
    good = np.isfinite(r) & np.isfinite(p) & np.isfinite(y)
    q = np.full((len(r), 4), np.nan)
    if good.any():
        q[good] = euler_to_quat(r[good], p[good], y[good])
    return {**out, **{f"q_{c}": q[:, i] for i, c in enumerate("wxyz")}}


def _mode_rows(base: dict, cols: dict) -> pd.DataFrame:
    frame = pd.DataFrame({**base, **{k: v for k, v in cols.items()}})
    m = frame["mode"].astype("string") if "mode" in frame else pd.Series(pd.array([None] * len(frame), dtype="string"))
    frame = frame[m.notna().to_numpy()].reset_index(drop=True)
    m = m.dropna().reset_index(drop=True)
    change = np.ones(len(m), bool)
    change[1:] = (m.to_numpy()[1:] != m.to_numpy()[:-1])
    return frame[change].reset_index(drop=True)


def _origin(cmap: ColumnMap, gps: pd.DataFrame | None, diag: dict) -> dict | None:
    spec = cmap.ned_origin
    if spec is None:
        return None
    if isinstance(spec, dict):
        return {"lat_deg": float(spec["lat_deg"]), "lon_deg": float(spec["lon_deg"]),
                "alt_wgs84_m": spec.get("alt_wgs84_m"), "alt_msl_m": spec.get("alt_msl_m"),
                "source": f"column map {cmap.name}"}
    if spec != "first_fix":
        raise ColumnMapError(f"ned_origin must be 'first_fix' or a mapping, got {spec!r}")
    if gps is None or not len(gps) or "lat_deg" not in gps or "lon_deg" not in gps:
        diag["warnings"].append("ned_origin: first_fix requested but the file has no GPS fix")
        return None
    lat, lon = gps["lat_deg"].to_numpy(np.float64), gps["lon_deg"].to_numpy(np.float64)
    ok = np.isfinite(lat) & np.isfinite(lon) & ~((lat == 0) & (lon == 0))
    if not ok.any():
        diag["warnings"].append("ned_origin: no valid GPS fix in the file")
        return None
    k = int(np.argmax(ok))

    def at(c):
        if c not in gps:
            return None
        v = float(gps[c].iloc[k])
        return v if np.isfinite(v) else None

    return {"lat_deg": float(lat[k]), "lon_deg": float(lon[k]), "alt_wgs84_m": at("alt_wgs84_m"),
            "alt_msl_m": at("alt_msl_m"), "source": f"first GPS fix (t_ns={int(gps['t_ns'].iloc[k])})"}
