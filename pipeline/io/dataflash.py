"""ArduPilot DataFlash ``.bin`` reader: a vectorised decoder plus the canonical-stream mapping.

A DataFlash log is a byte stream of records ``A3 95 <type> <body>``; the body layout of each
type is declared by an ``FMT`` record (type 128, 89 bytes: ``Type:B Length:B Name:n Format:N
Columns:Z``). Modern logs (ArduPilot ≥ 3.5) add ``FMTU`` (unit and multiplier ids per field),
``UNIT`` and ``MULT`` tables and time-stamp every record with ``TimeUS``; old logs (ArduCopter
3.1) use ``TimeMS`` and have untimed records (``MODE``, ``EV``, ``PARM``).

Decoding (:func:`decode`) is done in three vectorised passes instead of pymavlink's
record-at-a-time loop:

1. **FMT pass.** Every ``A3 95 80`` candidate is decoded at once with a structured dtype and
   validated (printable name, known format characters, ``Length == 3 + calcsize(Format)``).
2. **Boundary pass.** All ``A3 95 <known type>`` candidates are located with NumPy. Each
   candidate ``k`` ends at ``e_k = p_k + L(type_k)``; the record chain is the sequence that
   starts at the first candidate and continues with the first candidate at or after ``e_k``.
   Runs of back-to-back records (``e_k == p_{k+1}``) are found in one vector operation, so
   the Python loop only steps over *breaks* in the chain (garbage, false ``A3 95`` inside
   a body), which reproduces pymavlink's byte-wise resynchronisation
   (``DFReader_binary._parse_next``) exactly: bytes between chain records are skipped and
   counted, and a record that runs past the end of the file ends the chain (``truncated``).
3. **Per-type pass.** For each type the bodies are gathered into an ``(n, L-3)`` byte matrix
   and viewed through a NumPy structured dtype built from the FMT record (format characters
   ``a b B g h H i I f d n N Z c C e E L M q Q`` per the DataFlash specification). Scaled
   formats are divided as pymavlink does (``c C e E`` by 100, ``L`` by 10⁷: dividing by the
   inverse multiplier is what pymavlink does for accuracy, so values match it bit for bit);
   char fields are decoded UTF-8 (falling back to ISO-8859-1) and cut at the first NUL, once
   per distinct value. ``FMTU``/``MULT`` multipliers are attached to every format and applied
   on request (``apply_mult=True``).

The raw tables match pymavlink's ``recv_msg`` loop record for record and value for value on
clean logs (``tests/io/test_dataflash_reader.py``); :class:`DataFlashReader` maps them to the
canonical streams of :mod:`pipeline.io.schema`.

Canonical mapping (:func:`to_flightlog`; instance from an ``I``/``Instance``/``C`` field,
else the name suffix, ``IMU2`` -> 1):

==============  ===============================================================================
stream          source
==============  ===============================================================================
imu             IMU/IMU2/IMU3 ``Gyr*`` rad/s, ``Acc*`` m/s² (ArduPilot body axes are FRD), ``T``
gps             GPS/GPS2 ``Lat/Lng`` deg, ``Alt`` MSL, ``Spd``/``GCrs``/``VZ`` -> NED velocity,
                ``Status`` -> fix_type, ``NSats``; GPA ``HAcc``/``VAcc``, ``Und`` -> WGS-84 height
baro            BARO/BAR2/BAR3 ``Alt``, ``Press``, ``Temp``; old logs: CTUN ``BarAlt``
mag             MAG/MAG2/MAG3 mGauss × 10⁻⁷ -> T
attitude        ATT (instance 0) and AHR2 (instance 1) ZYX Euler deg -> quaternion
local_position  XKF1/XKF6/NKF1/NKF6/EKF1 ``PN PE PD VN VE VD`` (core 0 -> instance 0)
rangefinder     RFND ``Dist`` (m; unscaled integer fields are cm), else non-zero CTUN ``SAlt``
airspeed        ARSP/ASP2
control         RCIN/RCI2 ``C1..C16`` (old ``Chan1..8``) -> ``rc_i_us``; RCOU/RCO2/RCO3 -> servo
mode            MODE (``ModeNum``/``Mode`` -> pymavlink's mode names), EV 10/11 -> ``armed``
radar           RADR (simulation): ``Rng``, ``U``, ``V``, ``RR``, ``I``; PARM RADR_SN/SE/SD/TAU
==============  ===============================================================================

PARM -> ``meta['params']``; MSG -> ``meta['diagnostics']['messages']``; ORGN (else the first 3D
GPS fix, else POS) -> ``meta['ned_origin']``.

Time. ``t_ns = TimeUS·1000`` (``TimeMS·10⁶`` on old logs; old ``GPS`` uses its boot-time
field ``T``) minus ``t0``, the first boot time stamp of a record mapped to a canonical stream.
Untimed records take the time of the preceding timed record in file order. UTC of ``t_ns = 0``
comes from the first GPS record with a week number:

.. math:: t_{UTC} = 315964800 + 604800\\,\\mathrm{week} + \\mathrm{tow}_{ms}/1000 - 18

(the GPS epoch, 1980-01-06, in Unix seconds, and pymavlink's fixed 18 leap seconds,
``DFReader.py::_gpsTimeToTime``), recorded in ``meta['leap_seconds']``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from . import schema
from .base import FlightLog, IngestError, LogReader, Progress
from .registry import register

HEAD1, HEAD2 = 0xA3, 0x95
FMT_TYPE = 0x80
FMT_LEN = 89

#: DataFlash format character -> (NumPy dtype, divisor applied on decode or None).
#: Divisors mirror pymavlink's FORMAT_TO_STRUCT multipliers (1/0.01, 1/1e-7).
FORMAT_CHARS: dict[str, tuple[str | tuple, float | None]] = {
    "a": (("<i2", (32,)), None),
    "b": ("i1", None),
    "B": ("u1", None),
    "g": ("<f2", None),
    "h": ("<i2", None),
    "H": ("<u2", None),
    "i": ("<i4", None),
    "I": ("<u4", None),
    "f": ("<f4", None),
    "d": ("<f8", None),
    "n": ("S4", None),
    "N": ("S16", None),
    "Z": ("S64", None),
    "c": ("<i2", 1 / 0.01),
    "C": ("<u2", 1 / 0.01),
    "e": ("<i4", 1 / 0.01),
    "E": ("<u4", 1 / 0.01),
    "L": ("<i4", 1 / 1.0e-7),
    "M": ("i1", None),
    "q": ("<i8", None),
    "Q": ("<u8", None),
}
_STRING_CHARS = frozenset("nNZ")
_TIME_FIELDS = frozenset({"TimeUS", "TimeMS", "SampleUS"})

#: numpy dtype of the FMT record body
_FMT_DTYPE = np.dtype([("Type", "u1"), ("Length", "u1"), ("Name", "S4"), ("Format", "S16"),
                       ("Columns", "S64")])

GPS_EPOCH_UNIX_S = 315964800
LEAP_SECONDS = 18  # pymavlink's constant (DFReader._gpsTimeToTime); true since 2017-01-01
_LEAP18_FROM_UTC_S = 1483228800  # 2017-01-01T00:00:00Z

#: Stream -> message types it is built from (documentation and the "contains" checks).
STREAM_SOURCES: dict[str, tuple[str, ...]] = {
    "imu": ("IMU", "IMU2", "IMU3"),
    "gps": ("GPS", "GPS2"),
    "baro": ("BARO", "BAR2", "BAR3", "CTUN"),
    "mag": ("MAG", "MAG2", "MAG3"),
    "attitude": ("ATT", "AHR2"),
    "local_position": ("XKF1", "XKF6", "NKF1", "NKF6", "EKF1"),
    "rangefinder": ("RFND", "CTUN"),
    "airspeed": ("ARSP", "ASP2"),
    "control": ("RCIN", "RCI2", "RCOU", "RCO2", "RCO3"),
    "mode": ("MODE", "EV"),
    "radar": ("RADR",),
}


@dataclass
class MsgFormat:
    """One message type as declared by its FMT record (plus FMTU units/multipliers)."""

    type_id: int
    name: str
    length: int
    fmt: str
    columns: list[str]
    dtype: np.dtype
    units: list[str] | None = None
    mults: list[float | None] | None = None
    instance_field: str | None = None

    @property
    def time_field(self) -> str | None:
        """The boot-time field pymavlink's clock would use, or ``None`` (untimed record)."""
        if self.columns and self.columns[0] in ("TimeUS", "TimeMS"):
            return self.columns[0]
        return None


@dataclass
class DecodeResult:
    """Output of :func:`decode`.

    Attributes
    ----------
    tables : dict
        ``{message name: {column: ndarray}}``; unscaled numeric columns are read-only strided
        views into one record matrix per type, scaled ones float64, char fields object arrays
        of ``str`` (``bytes`` for ``FILE.Data``, as pymavlink), ``a`` fields
        ``(n, 32)`` int16.
    offsets : dict
        ``{message name: int64 byte offset of each record}`` (file order).
    formats : dict
        ``{message name: MsgFormat}``.
    diagnostics : dict
        ``bytes_skipped``, ``records_dropped``, ``record_counts``, ``warnings``, ``n_bytes``.
    type_formats : dict
        ``{type id: MsgFormat}`` for every valid FMT in the file, records or not.
    """

    tables: dict[str, dict[str, np.ndarray]]
    offsets: dict[str, np.ndarray]
    formats: dict[str, MsgFormat]
    diagnostics: dict = field(default_factory=dict)
    type_formats: dict[int, MsgFormat] = field(default_factory=dict)


def _null_term(b: bytes) -> str:
    """pymavlink's string rule: decode UTF-8 (else ISO-8859-1), then cut at the first NUL."""
    try:
        s = b.decode("utf-8")
    except UnicodeDecodeError:
        s = b.decode("ISO-8859-1")
    i = s.find("\0")
    return s if i < 0 else s[:i]


def _decode_strings(col: np.ndarray) -> np.ndarray:
    """Fixed-width byte strings -> object array of str, decoding each distinct value once."""
    if len(col) == 0:
        return np.empty(0, dtype=object)
    uniq, inv = np.unique(col, return_inverse=True)
    # np.unique strips trailing NULs from S-dtype values, which the NUL cut makes harmless
    dec = np.array([_null_term(bytes(u)) for u in uniq], dtype=object)
    return dec[inv.reshape(-1)]


def _format_dtype(fmt: str, columns: list[str]) -> np.dtype:
    names, seen = [], set()
    for i in range(len(fmt)):
        n = columns[i] if i < len(columns) and columns[i] else f"field{i}"
        if n in seen:
            n = f"{n}_{i}"
        seen.add(n)
        names.append(n)
    return np.dtype({"names": names, "formats": [FORMAT_CHARS[c][0] for c in fmt]})


def _parse_fmt_records(buf: np.ndarray, pos: np.ndarray,
                       warnings: list[str]) -> tuple[dict[int, MsgFormat], int]:
    """Decode and validate the FMT candidates at ``pos``; first valid definition per type wins.

    A well-formed FMT whose Length disagrees with its Format (a known ArduPilot 3.4 bug:
    ``BAR3`` declares 33 bytes for 29) leaves its type undecodable, as in pymavlink, and is
    noted in ``warnings``. Returns (formats by type id, number of invalid candidates)."""
    n = len(buf)
    pos = pos[pos + FMT_LEN <= n]
    formats: dict[int, MsgFormat] = {}
    bad = 0
    if not len(pos):
        return formats, bad
    mat = np.lib.stride_tricks.sliding_window_view(buf, FMT_LEN - 3)[pos + 3]
    recs = mat.view(_FMT_DTYPE).reshape(-1)
    for r in recs.tolist():
        tid, length, name_b, fmt_b, cols_b = r
        try:
            name = name_b.split(b"\0", 1)[0].decode("ascii")
            fmt = fmt_b.split(b"\0", 1)[0].decode("ascii")
            cols = cols_b.split(b"\0", 1)[0].decode("ascii")
        except UnicodeDecodeError:
            bad += 1
            continue
        if (not name or not name.isprintable() or not name.replace("_", "").isalnum()
                or any(c not in FORMAT_CHARS for c in fmt)):
            bad += 1
            continue
        columns = cols.split(",") if cols else []
        dt = _format_dtype(fmt, columns)
        if dt.itemsize + 3 != length:
            msg = (f"FMT {name} (type {tid}) declares {length} bytes but format {fmt!r} needs "
                   f"{dt.itemsize + 3}: type not decoded")
            if msg not in warnings:
                warnings.append(msg)
            continue
        if tid in formats:
            old = formats[tid]
            if (old.name, old.fmt, old.length) != (name, fmt, length):
                bad += 1  # a conflicting redefinition: keep the first (corruption is likelier)
            continue
        formats[tid] = MsgFormat(tid, name, length, fmt, columns, dt)
    return formats, bad


def _chain(cand: np.ndarray, ends: np.ndarray, n_bytes: int) -> tuple[np.ndarray, bool]:
    """Mask of the candidates on the record chain, and whether it ended on a truncated one.

    ``cand`` are sorted candidate start offsets, ``ends`` their end offsets (may exceed
    ``n_bytes``). The chain starts at ``cand[0]``; after candidate ``k`` comes the first
    candidate at or after ``ends[k]`` (pymavlink skips the bytes in between one by one).
    Back-to-back runs (``ends[k] == cand[k+1]``) are found in one vector operation; the loop
    below steps once per *break* (resync), not once per record.
    """
    m = len(cand)
    on = np.zeros(m, dtype=bool)
    if m == 0:
        return on, False
    brk = np.flatnonzero(ends[:-1] != cand[1:])  # record k is the last of its run
    run_last = np.append(brk, m - 1)
    truncated = False
    k = 0
    while k < m:
        last = int(run_last[np.searchsorted(run_last, k)])
        if ends[last] > n_bytes:  # a record running past EOF ends the chain ("out of data")
            over = np.flatnonzero(ends[k:last + 1] > n_bytes)
            on[k:k + int(over[0])] = True
            truncated = True
            break
        on[k:last + 1] = True
        k = int(np.searchsorted(cand, ends[last]))
    return on, truncated


_HEAD_U16 = HEAD1 | (HEAD2 << 8)


def _find_headers(buf: np.ndarray) -> np.ndarray:
    """Sorted offsets ``i`` with ``buf[i:i+2] == A3 95`` and a type byte after them.

    Compares 16-bit words at even and at odd offsets (two half-size boolean temporaries instead
    of a full-size one plus a gather)."""
    n = len(buf)
    if n < 3:
        return np.empty(0, dtype=np.int64)
    even = buf[: (n // 2) * 2].view("<u2")
    odd = buf[1: 1 + ((n - 1) // 2) * 2].view("<u2")
    pe = np.flatnonzero(even == _HEAD_U16) * 2
    po = np.flatnonzero(odd == _HEAD_U16) * 2 + 1
    hdr = np.concatenate([pe, po])
    hdr.sort(kind="stable")
    return hdr[hdr <= n - 3]


def _as_buffer(src) -> tuple[np.ndarray, str]:
    if isinstance(src, (bytes, bytearray, memoryview)):
        return np.frombuffer(src, dtype=np.uint8), "<bytes>"
    p = Path(src)
    try:
        data = np.fromfile(p, dtype=np.uint8)
    except OSError as exc:
        raise IngestError(p, f"cannot read: {exc.strerror or exc}") from None
    return data, str(p)


def _unit_tables(tables, formats_by_id: dict[int, MsgFormat]) -> None:
    """Attach FMTU unit labels and MULT multipliers to the formats they describe."""
    unit = tables.get("UNIT")
    mult = tables.get("MULT")
    fmtu = tables.get("FMTU")
    if fmtu is None or "FmtType" not in fmtu:
        return
    ulook = {}
    if unit is not None and "Id" in unit and "Label" in unit:
        ulook = {chr(int(i) & 0xFF): lab for i, lab in zip(unit["Id"].tolist(), unit["Label"].tolist())}
    mlook = {}
    if mult is not None and "Id" in mult and "Mult" in mult:
        # logged as doubles of single-precision values: round to 7 s.f. as pymavlink does
        mlook = {chr(int(i) & 0xFF): float("%.7g" % v) for i, v in zip(mult["Id"].tolist(), mult["Mult"].tolist())}
    uids = fmtu.get("UnitIds")
    mids = fmtu.get("MultIds")
    for k, ftype in enumerate(fmtu["FmtType"].tolist()):
        f = formats_by_id.get(int(ftype))
        if f is None:
            continue
        if uids is not None:
            u = uids[k]
            f.units = [ulook.get(u[i], "") if i < len(u) else "" for i in range(len(f.columns))]
            j = u.find("#")
            if 0 <= j < len(f.columns):
                f.instance_field = f.columns[j]
        if mids is not None:
            mm = mids[k]
            f.mults = [mlook.get(mm[i]) if i < len(mm) else None for i in range(len(f.columns))]


def decode(src, *, apply_mult: bool = False, types: set[str] | None = None,
           progress: Progress | None = None) -> DecodeResult:
    """Decode every message type of a DataFlash log at once (see the module docstring).

    Parameters
    ----------
    src : path-like or bytes
        The log file, or its bytes.
    apply_mult : bool
        Also multiply fields by their FMTU/MULT multiplier where the format character does not
        scale by itself (time fields excepted, which stay integer). Default ``False``: values
        as pymavlink returns them.
    types : set of str, optional
        Decode only these message names (plus FMT/FMTU/UNIT/MULT); boundaries are always
        found for all.
    progress : callable, optional
        ``progress(done, total)`` in bytes.

    Returns
    -------
    DecodeResult

    Raises
    ------
    IngestError
        No FMT record, or no decodable record at all.
    """
    buf, where = _as_buffer(src)
    n = len(buf)
    diag = {"n_bytes": n, "bytes_skipped": 0, "records_dropped": {}, "record_counts": {},
            "warnings": []}
    if n == 0:
        raise IngestError(None if where == "<bytes>" else where, "empty file (0 bytes)")
    hdr = _find_headers(buf)
    types_at = buf[hdr + 2]
    formats_by_id, bad_fmt = _parse_fmt_records(buf, hdr[types_at == FMT_TYPE], diag["warnings"])
    if not formats_by_id:
        raise IngestError(None if where == "<bytes>" else where,
                          "not a DataFlash log: no valid FMT record found")
    formats_by_id.setdefault(FMT_TYPE, MsgFormat(FMT_TYPE, "FMT", FMT_LEN, "BBnNZ",
                                                 ["Type", "Length", "Name", "Format", "Columns"],
                                                 _FMT_DTYPE))
    if bad_fmt:
        diag["records_dropped"]["bad_format"] = bad_fmt
    lengths = np.zeros(256, dtype=np.int64)
    for tid, f in formats_by_id.items():
        lengths[tid] = f.length
    known = lengths[types_at] > 0
    cand = hdr[known]
    ctype = types_at[known]
    ends = cand + lengths[ctype]
    on, truncated = _chain(cand, ends, n)
    pos = cand[on]
    ptype = ctype[on]
    used = int(lengths[ptype].sum())
    if truncated:
        diag["records_dropped"]["truncated"] = 1
    diag["bytes_skipped"] = n - used
    if progress:
        progress(n // 4, n)
    # A3 95 headers of types without a FMT record inside skipped bytes: records whose format
    # was lost (or never written). Counted per type id, they cannot be decoded.
    if diag["bytes_skipped"]:
        unk = hdr[~known]
        if len(unk):
            k = np.searchsorted(pos, unk, side="right") - 1
            inside = (k >= 0) & (unk < pos[np.maximum(k, 0)] + lengths[ptype[np.maximum(k, 0)]])
            lost = buf[unk[~inside] + 2]
            for t, c in zip(*np.unique(lost, return_counts=True)):
                diag["records_dropped"][f"format_lost:{int(t)}"] = int(c)
    del hdr, types_at, known, cand, ctype, ends, on  # keep the peak low (tracemalloc-checked)
    if not len(pos):
        raise IngestError(None if where == "<bytes>" else where,
                          "no decodable DataFlash record found")

    # group chain positions by type, in file order
    order = np.argsort(ptype, kind="stable")
    sorted_types = ptype[order]
    pos_by_type = pos[order]
    del pos, ptype, order
    bounds = np.flatnonzero(np.diff(sorted_types)) + 1
    starts = np.concatenate([[0], bounds])
    stops = np.concatenate([bounds, [len(pos_by_type)]])
    tables: dict[str, dict[str, np.ndarray]] = {}
    offsets: dict[str, np.ndarray] = {}
    formats: dict[str, MsgFormat] = {}
    meta_names = {"FMT", "FMTU", "UNIT", "MULT"}

    class _Windows(dict):
        def __missing__(self, width):
            v = np.lib.stride_tricks.sliding_window_view(buf, width)
            self[width] = v
            return v

    windows = _Windows()
    by_id = sorted(zip(starts.tolist(), stops.tolist()), key=lambda ab: int(sorted_types[ab[0]]))
    for done, (a, b) in enumerate(by_id):
        tid = int(sorted_types[a])
        f = formats_by_id[tid]
        name = f.name if f.name not in formats else f"{f.name}#{tid}"
        p = pos_by_type[a:b]
        diag["record_counts"][name] = diag["record_counts"].get(name, 0) + len(p)
        if types is not None and f.name not in types and f.name not in meta_names:
            continue
        # rows of a sliding-window view: the gather copies only the bodies (an index matrix
        # would cost 8 bytes per byte gathered)
        mat = windows[f.length - 3][p + 3] if f.length > 3 else np.zeros((len(p), 0), np.uint8)
        rec = mat.view(f.dtype).reshape(-1)
        cols: dict[str, np.ndarray] = {}
        for ch, cname in zip(f.fmt, f.dtype.names):
            v = rec[cname]
            div = FORMAT_CHARS[ch][1]
            if div is not None:
                v = v / div
            elif ch in _STRING_CHARS:
                if f.name == "FILE" and ch == "Z":  # raw bytes, NULs kept, as pymavlink
                    raw = np.ascontiguousarray(v).view(np.uint8).reshape(len(v), -1)
                    v = np.array([bytes(r) for r in raw], dtype=object) if len(v) else np.empty(0, object)
                else:
                    v = _decode_strings(v)
            # unscaled numeric fields stay strided views into the type's record matrix: no copy,
            # and the tables hold each record's bytes once
            cols[cname] = v
        tables[name] = cols
        offsets[name] = p
        formats[name] = f
        if progress and done % 16 == 0:
            progress(n // 4 + (3 * n // 4) * (done + 1) // len(by_id), n)
    _unit_tables(tables, formats_by_id)
    if apply_mult:
        for name, f in formats.items():
            if not f.mults:
                continue
            cols = tables[name]
            for ch, cname, m in zip(f.fmt, f.dtype.names, f.mults):
                if (m is None or m in (0.0, 1.0) or ch in _STRING_CHARS or ch == "a"
                        or FORMAT_CHARS[ch][1] is not None or cname in _TIME_FIELDS):
                    continue
                cols[cname] = cols[cname] * m
    if progress:
        progress(n, n)
    return DecodeResult(tables, offsets, formats, diag, formats_by_id)


def decode_all(src, *, apply_mult: bool = False) -> tuple[dict[str, dict[str, np.ndarray]], dict]:
    """Raw message tables of a DataFlash log: ``({name: {column: ndarray}}, diagnostics)``.

    Every message type present is decoded (see :func:`decode`); values are those pymavlink's
    ``recv_msg`` loop returns (format scaling applied, strings decoded).
    """
    res = decode(src, apply_mult=apply_mult)
    return res.tables, res.diagnostics


# --------------------------------------------------------------------------------------------
# canonical mapping
# --------------------------------------------------------------------------------------------

def _instance_of(name: str, base: str, cols: dict, n: int, field_names=("I", "Instance", "C")) -> np.ndarray:
    """Sensor instance: an ``I``/``Instance``/``C`` field, else the digit suffix (IMU2 -> 1)."""
    for fn in field_names:
        if fn in cols:
            return np.asarray(cols[fn]).astype(np.uint8)
    suffix = name[len(base):]
    k = int(suffix) - 1 if suffix.isdigit() else 0
    return np.full(n, max(k, 0), dtype=np.uint8)


class _Clock:
    """Boot time (µs, int64) of every record; untimed records take the preceding timed one's."""

    def __init__(self, res: DecodeResult):
        self.res = res
        offs, times = [], []
        for name, f in res.formats.items():
            t = self.own_time_us(name)
            if t is not None and len(t):
                offs.append(res.offsets[name])
                times.append(t)
        if offs:
            o = np.concatenate(offs)
            t = np.concatenate(times)
            k = np.argsort(o, kind="stable")
            self._off, self._t = o[k], t[k]
        else:
            self._off = np.empty(0, np.int64)
            self._t = np.empty(0, np.int64)

    def own_time_us(self, name: str) -> np.ndarray | None:
        f = self.res.formats[name]
        cols = self.res.tables.get(name)
        if cols is None:
            return None
        tf = f.time_field
        if tf == "TimeUS":
            return cols["TimeUS"].astype(np.int64)
        if tf == "TimeMS":
            return cols["TimeMS"].astype(np.int64) * 1000
        if f.name in ("GPS", "GPS2") and "T" in cols:  # old GPS: TimeMS is GPS time of week
            return cols["T"].astype(np.int64) * 1000
        return None

    def time_us(self, name: str) -> np.ndarray:
        t = self.own_time_us(name)
        if t is not None:
            return t
        off = self.res.offsets[name]
        if not len(self._off):
            return np.zeros(len(off), dtype=np.int64)
        k = np.searchsorted(self._off, off, side="right") - 1
        return self._t[np.maximum(k, 0)]


def _mode_names(res: DecodeResult) -> dict[int, str]:
    """Flight-mode number -> name for the vehicle type (pymavlink's mode mappings)."""
    try:
        from pymavlink import mavutil
    except ImportError:  # pragma: no cover - pymavlink is a core dependency
        return {}
    mav = mavutil.mavlink
    vtype = None
    ver = res.tables.get("VER")
    if ver is not None and "BU" in ver and len(ver["BU"]):
        vtype = {1: mav.MAV_TYPE_GROUND_ROVER, 2: mav.MAV_TYPE_QUADROTOR, 3: mav.MAV_TYPE_FIXED_WING,
                 4: mav.MAV_TYPE_ANTENNA_TRACKER, 7: mav.MAV_TYPE_SUBMARINE,
                 13: mav.MAV_TYPE_HELICOPTER}.get(int(ver["BU"][0]))
    if vtype is None:
        msgs = res.tables.get("MSG", {}).get("Message", [])
        text = " ".join(str(m) for m in list(msgs)[:50])
        if "Rover" in text:
            vtype = mav.MAV_TYPE_GROUND_ROVER
        elif "Plane" in text:
            vtype = mav.MAV_TYPE_FIXED_WING
        elif "Copter" in text:
            vtype = mav.MAV_TYPE_QUADROTOR
        elif "Sub" in text:
            vtype = mav.MAV_TYPE_SUBMARINE
    if vtype is None:
        # copter-only messages identify old copter logs that have no version text
        vtype = mav.MAV_TYPE_QUADROTOR if ("CTUN" in res.tables and "ThrIn" in res.tables["CTUN"]) \
            else mav.MAV_TYPE_FIXED_WING
    return dict(mavutil.mode_mapping_bynumber(vtype) or {})


def _rows(clock: _Clock, name: str, t0_us: int) -> dict[str, np.ndarray]:
    t_us = clock.time_us(name)
    return {"t_ns": (t_us - t0_us) * 1000, "t_boot_ns": t_us * 1000}


def _frame(parts: list[pd.DataFrame]) -> pd.DataFrame | None:
    parts = [p for p in parts if len(p)]
    if not parts:
        return None
    return pd.concat(parts, ignore_index=True) if len(parts) > 1 else parts[0]


def _find(res: DecodeResult, names) -> list[str]:
    return [n for n in names if n in res.tables and len(next(iter(res.tables[n].values()), []))]


def _streams(res: DecodeResult, clock: _Clock, t0_us: int, diag: dict) -> dict[str, pd.DataFrame | None]:
    from ..frames.rotations import euler_to_quat

    T = res.tables
    out: dict[str, pd.DataFrame | None] = {}

    def base(name, base_name, inst=None):
        cols = T[name]
        n = len(next(iter(cols.values())))
        d = _rows(clock, name, t0_us)
        d["instance"] = _instance_of(name, base_name, cols, n) if inst is None else np.full(n, inst, np.uint8)
        d["src"] = pd.Categorical([name] * n) if n else pd.Categorical([])
        return d, cols

    blocks = []  # (stream, builder): each builder fills out[stream]

    def _imu():  # IMU
        parts = []
        for name in _find(res, ("IMU", "IMU2", "IMU3")):
            d, c = base(name, "IMU")
            for ax in "XYZ":
                d[f"gyr_{ax.lower()}_radps"] = c[f"Gyr{ax}"].astype(np.float64)
                d[f"acc_{ax.lower()}_mps2"] = c[f"Acc{ax}"].astype(np.float64)
            for tn in ("T", "Temp"):
                if tn in c:
                    d["temp_degC"] = c[tn].astype(np.float64)
                    break
            parts.append(pd.DataFrame(d))
        out["imu"] = _frame(parts)

    blocks.append(("imu", _imu))

    def _gps():  # GPS (+ GPA accuracies matched on instance and time)
        parts = []
        for name in _find(res, ("GPS", "GPS2")):
            d, c = base(name, "GPS")
            d["lat_deg"] = c["Lat"]
            d["lon_deg"] = c["Lng"]
            d["alt_msl_m"] = c["Alt"].astype(np.float64)
            spd = c["Spd"].astype(np.float64)
            crs = np.deg2rad(c["GCrs"].astype(np.float64))
            d["vel_n_mps"] = spd * np.cos(crs)
            d["vel_e_mps"] = spd * np.sin(crs)
            if "VZ" in c:
                d["vel_d_mps"] = c["VZ"].astype(np.float64)  # ArduPilot logs NED velocity.z (down)
            d["fix_type"] = c["Status"].astype(np.float64)
            d["n_sats"] = c["NSats"].astype(np.float64)
            gpa_name = "GPA" if name == "GPS" else "GPA2"
            if gpa_name in T and "TimeUS" in c and "TimeUS" in T[gpa_name]:
                g = T[gpa_name]
                gi = _instance_of(gpa_name, "GPA", g, len(g["TimeUS"]))
                key_g = pd.MultiIndex.from_arrays([gi, g["TimeUS"]])
                key_s = pd.MultiIndex.from_arrays([d["instance"], c["TimeUS"]])
                if key_g.is_unique:
                    k = key_g.get_indexer(key_s)
                    ok = k >= 0
                    for src_c, dst in (("HAcc", "hacc_m"), ("VAcc", "vacc_m")):
                        if src_c in g:
                            v = np.full(len(k), np.nan)
                            v[ok] = g[src_c][k[ok]]
                            d[dst] = v
                    if "Und" in g:
                        # AP_GPS undulation = h_MSL - h_ellipsoid, so h_WGS84 = Alt - Und
                        und = np.full(len(k), np.nan)
                        und[ok] = g["Und"][k[ok]]
                        und[und == 0] = np.nan  # 0 = receiver gave none
                        d["alt_wgs84_m"] = d["alt_msl_m"] - und
            parts.append(pd.DataFrame(d))
        out["gps"] = _frame(parts)

    blocks.append(("gps", _gps))

    def _baro():  # baro (CTUN.BarAlt on old logs without BARO)
        parts = []
        for name in _find(res, ("BARO", "BAR2", "BAR3")):
            inst = {"BARO": 0, "BAR2": 1, "BAR3": 2}[name] if "I" not in T[name] else None
            d, c = base(name, "BARO", inst)
            d["alt_rel_m"] = c["Alt"].astype(np.float64)
            if "Press" in c:
                d["press_Pa"] = c["Press"].astype(np.float64)
            if "Temp" in c:
                d["temp_degC"] = c["Temp"].astype(np.float64)
            parts.append(pd.DataFrame(d))
        if not parts and _find(res, ("CTUN",)):
            c = T["CTUN"]
            key = "BarAlt" if "BarAlt" in c else ("BAlt" if "BAlt" in c else None)
            if key:
                d, _ = base("CTUN", "CTUN", 0)
                d["alt_rel_m"] = c[key].astype(np.float64)
                parts.append(pd.DataFrame(d))
        out["baro"] = _frame(parts)

    blocks.append(("baro", _baro))

    def _mag():  # magnetometer: mGauss -> T
        parts = []
        for name in _find(res, ("MAG", "MAG2", "MAG3")):
            d, c = base(name, "MAG")
            for ax in "XYZ":
                d[f"mag_{ax.lower()}_T"] = c[f"Mag{ax}"].astype(np.float64) * 1e-7
            parts.append(pd.DataFrame(d))
        out["mag"] = _frame(parts)

    blocks.append(("mag", _mag))

    def _attitude():  # attitude: ATT (instance 0), AHR2 (instance 1); ZYX Euler deg -> quaternion
        parts = []
        for name, inst in (("ATT", 0), ("AHR2", 1)):
            if not _find(res, (name,)):
                continue
            d, c = base(name, name, inst)
            q = euler_to_quat(np.deg2rad(c["Roll"].astype(np.float64)),
                              np.deg2rad(c["Pitch"].astype(np.float64)),
                              np.deg2rad(c["Yaw"].astype(np.float64)))
            for i, comp in enumerate("wxyz"):
                d[f"q_{comp}"] = q[:, i]
            parts.append(pd.DataFrame(d))
        out["attitude"] = _frame(parts)

    blocks.append(("attitude", _attitude))

    def _local_position():  # local position from the EKF (core 0 -> instance 0)
        parts = []
        for name, inst in (("XKF1", 0), ("XKF6", 1), ("NKF1", 0), ("NKF6", 1), ("EKF1", 0)):
            if not _find(res, (name,)):
                continue
            c = T[name]
            if not all(k in c for k in ("PN", "PE", "PD", "VN", "VE", "VD")):
                continue
            d, _ = base(name, name, None if "C" in c else inst)
            for k in "NED":
                d[f"pos_{k.lower()}_m"] = c[f"P{k}"].astype(np.float64)
                d[f"vel_{k.lower()}_mps"] = c[f"V{k}"].astype(np.float64)
            parts.append(pd.DataFrame(d))
        out["local_position"] = _frame(parts)

    blocks.append(("local_position", _local_position))

    def _rangefinder():  # rangefinder: RFND (Dist or Dist1/Dist2), else CTUN.SAlt when it holds data
        parts = []
        if _find(res, ("RFND",)):
            c = T["RFND"]
            f = res.formats["RFND"]
            fmt_of = dict(zip(f.dtype.names, f.fmt))
            pairs = [("Dist", "Orient")] if "Dist" in c else [(f"Dist{k}", f"Orient{k}") for k in (1, 2)]
            for k, (dn, on) in enumerate(pairs):
                if dn not in c:
                    continue
                d, _ = base("RFND", "RFND", None if "Instance" in c or "I" in c else k)
                dist = c[dn].astype(np.float64)
                if fmt_of[dn] in "hHiI":  # unscaled integer: centimetres (old logs)
                    dist = dist * 0.01
                d["dist_m"] = dist
                if on in c:
                    d["orientation"] = c[on].astype(np.float64)
                if "Stat" in c:
                    d["valid"] = c["Stat"] == 4  # RangeFinder::Status::Good
                else:
                    d["valid"] = dist > 0
                parts.append(pd.DataFrame(d))
        elif _find(res, ("CTUN",)) and "SAlt" in T["CTUN"]:
            salt = T["CTUN"]["SAlt"].astype(np.float64)
            if np.any(salt != 0):
                d, _ = base("CTUN", "CTUN", 0)
                d["dist_m"] = salt
                d["valid"] = salt > 0
                d["orientation"] = np.full(len(salt), 25.0)
                parts.append(pd.DataFrame(d))
            else:
                diag["warnings"].append("CTUN.SAlt is 0 throughout: no rangefinder data")
        out["rangefinder"] = _frame(parts)

    blocks.append(("rangefinder", _rangefinder))

    def _airspeed():  # airspeed
        parts = []
        for name in _find(res, ("ARSP", "ASP2")):
            d, c = base(name, "ARSP", None if "I" in T[name] else (0 if name == "ARSP" else 1))
            d["airspeed_mps"] = c["Airspeed"].astype(np.float64)
            if "DiffPress" in c:
                d["diff_press_Pa"] = c["DiffPress"].astype(np.float64)
            if "Temp" in c:
                d["temp_degC"] = c["Temp"].astype(np.float64)
            parts.append(pd.DataFrame(d))
        out["airspeed"] = _frame(parts)

    blocks.append(("airspeed", _airspeed))

    def _control():  # control: RC inputs and servo outputs, raw pulse widths
        parts = []
        for name, prefix, lim in (("RCIN", "rc", schema.N_RC), ("RCI2", "rc", schema.N_RC),
                                  ("RCOU", "servo", schema.N_SERVO), ("RCO2", "servo", schema.N_SERVO),
                                  ("RCO3", "servo", schema.N_SERVO)):
            if not _find(res, (name,)):
                continue
            d, c = base(name, name, 0)
            for col, v in c.items():
                for pre in ("Chan", "C"):
                    if col.startswith(pre) and col[len(pre):].isdigit():
                        i = int(col[len(pre):])
                        if 1 <= i <= lim:
                            d[f"{prefix}_{i}_us"] = v.astype(np.float64)
            parts.append(pd.DataFrame(d))
        out["control"] = _frame(parts)

    blocks.append(("control", _control))

    def _mode():  # mode and arming (EV 10 armed, 11 disarmed), state carried forward in file order
        ev = []
        names = _mode_names(res)
        if _find(res, ("MODE",)):
            c = T["MODE"]
            num = c["ModeNum"] if "ModeNum" in c else c["Mode"]
            labels = [names.get(int(x), str(int(x))) for x in num.tolist()]
            t = _rows(clock, "MODE", t0_us)
            for k in range(len(labels)):
                ev.append((int(res.offsets["MODE"][k]), int(t["t_ns"][k]), int(t["t_boot_ns"][k]), labels[k], None))
        if _find(res, ("EV",)):
            c = T["EV"]
            t = _rows(clock, "EV", t0_us)
            for k, i in enumerate(c["Id"].tolist()):
                if i in (10, 11):
                    ev.append((int(res.offsets["EV"][k]), int(t["t_ns"][k]), int(t["t_boot_ns"][k]), None, i == 10))
        if ev:
            ev.sort(key=lambda e: e[0])
            mode, armed = None, None
            rows = []
            for _, tn, tb, m, a in ev:
                mode = m if m is not None else mode
                armed = a if a is not None else armed
                rows.append((tn, tb, mode, armed))
            df = pd.DataFrame(rows, columns=["t_ns", "t_boot_ns", "mode", "armed"])
            df["src"] = ["MODE" if e[3] is not None else "EV" for e in ev]
            df["instance"] = np.zeros(len(df), np.uint8)
            df["armed"] = df["armed"].astype("boolean")
            df["mode"] = df["mode"].astype("string")
            out["mode"] = df
        else:
            out["mode"] = None

    blocks.append(("mode", _mode))

    def _radar():  # radar (simulation message RADR)
        if _find(res, ("RADR",)):
            d, c = base("RADR", "RADR")
            d["range_m"] = c["Rng"].astype(np.float64)
            d["dcos_u"] = c["U"].astype(np.float64)
            d["dcos_v"] = c["V"].astype(np.float64)
            d["range_rate_mps"] = c["RR"].astype(np.float64)
            d["sensor_id"] = c["I"].astype(np.float64) if "I" in c else np.zeros(len(d["t_ns"]))
            out["radar"] = pd.DataFrame(d)

    blocks.append(("radar", _radar))

    # a message lacking an expected field costs its stream, not the whole log
    for what, fn in blocks:
        try:
            fn()
        except (KeyError, ValueError, TypeError, IndexError) as exc:
            diag["warnings"].append(f"{what}: not mapped ({type(exc).__name__}: {exc})")
    return out

def _first_time_us(res: DecodeResult, clock: _Clock) -> int:
    """t0: boot time of the first (in file order) timed record of a canonically mapped type."""
    mapped = {n for names in STREAM_SOURCES.values() for n in names}
    best = None
    for names in (mapped, set(res.formats)):
        for name in names:
            if name not in res.tables:
                continue
            t = clock.own_time_us(name)
            if t is None or not len(t):
                continue
            off = int(res.offsets[name][0])
            if best is None or off < best[0]:
                best = (off, int(t[0]))
        if best is not None:
            return best[1]
    return 0


def _utc(res: DecodeResult, clock: _Clock, t0_us: int) -> tuple[int | None, dict | None]:
    """UTC (ns) of t_ns = 0 from the first GPS record with a week number."""
    g = res.tables.get("GPS")
    if g is None:
        return None, None
    if "GWk" in g and "GMS" in g and "TimeUS" in g:
        wk, tow, boot = g["GWk"], g["GMS"], g["TimeUS"].astype(np.int64)
    elif "Week" in g and "TimeMS" in g and "T" in g:
        wk, tow, boot = g["Week"], g["TimeMS"], g["T"].astype(np.int64) * 1000
    else:
        return None, None
    ok = np.flatnonzero((wk > 0) & (g["Status"] >= 3)) if "Status" in g else np.flatnonzero(wk > 0)
    if not len(ok):
        return None, None
    k = int(ok[0])
    utc_ns = ((GPS_EPOCH_UNIX_S + 604800 * int(wk[k]) - LEAP_SECONDS) * 1_000_000_000
              + int(tow[k]) * 1_000_000)
    t0_utc = utc_ns - (int(boot[k]) - t0_us) * 1000
    return t0_utc, {"gps_week": int(wk[k]), "gps_tow_ms": int(tow[k]), "boot_us": int(boot[k])}


def _origin(res: DecodeResult) -> dict | None:
    """NED origin: ORGN (EKF origin, type 0 first), else the first 3D GPS fix, else POS."""
    o = res.tables.get("ORGN")
    if o is not None and len(o.get("Lat", [])):
        typ = o.get("Type", np.zeros(len(o["Lat"])))
        k = np.flatnonzero(typ == 0)
        k = int(k[0]) if len(k) else 0
        return {"lat_deg": float(o["Lat"][k]), "lon_deg": float(o["Lng"][k]),
                "alt_wgs84_m": None, "alt_msl_m": float(o["Alt"][k]), "source": "ORGN"}
    g = res.tables.get("GPS")
    if g is not None and len(g.get("Lat", [])):
        good = np.flatnonzero((g["Status"] >= 3) & (g["Lat"] != 0)) if "Status" in g else np.arange(len(g["Lat"]))
        if len(good):
            k = int(good[0])
            return {"lat_deg": float(g["Lat"][k]), "lon_deg": float(g["Lng"][k]),
                    "alt_wgs84_m": None, "alt_msl_m": float(g["Alt"][k]), "source": "GPS"}
    p = res.tables.get("POS")
    if p is not None and len(p.get("Lat", [])):
        good = np.flatnonzero(p["Lat"] != 0)
        if len(good):
            k = int(good[0])
            return {"lat_deg": float(p["Lat"][k]), "lon_deg": float(p["Lng"][k]),
                    "alt_wgs84_m": None, "alt_msl_m": float(p["Alt"][k]), "source": "POS"}
    return None


def to_flightlog(res: DecodeResult) -> FlightLog:
    """Map decoded DataFlash tables to a canonical :class:`FlightLog` (see module docstring)."""
    diag = schema.new_diagnostics()
    diag["bytes_skipped"] = int(res.diagnostics["bytes_skipped"])
    diag["records_dropped"] = dict(res.diagnostics["records_dropped"])
    diag["record_counts"] = dict(res.diagnostics["record_counts"])
    diag["warnings"] = list(res.diagnostics["warnings"])
    clock = _Clock(res)
    t0_us = _first_time_us(res, clock)
    streams = _streams(res, clock, t0_us, diag)

    params: dict[str, float] = {}
    parm = res.tables.get("PARM")
    if parm is not None and "Name" in parm:
        for k, v in zip(parm["Name"].tolist(), parm["Value"].tolist()):
            params[k] = float(v)
    msg = res.tables.get("MSG")
    if msg is not None and "Message" in msg:
        t = _rows(clock, "MSG", t0_us)["t_ns"]
        diag["messages"] = [{"t_ns": int(a), "text": str(b)} for a, b in
                            zip(t[:1000].tolist(), msg["Message"][:1000].tolist())]
    try:
        t0_utc, gps_fix = _utc(res, clock, t0_us)
    except (KeyError, ValueError, OverflowError) as exc:
        t0_utc, gps_fix = None, None
        diag["warnings"].append(f"UTC not derived from GPS ({type(exc).__name__}: {exc})")
    try:
        origin = _origin(res)
    except (KeyError, ValueError) as exc:
        origin = None
        diag["warnings"].append(f"NED origin not derived ({type(exc).__name__}: {exc})")
    meta = schema.new_meta(
        source_format=DataFlashReader.source_format,
        reader=DataFlashReader.name,
        reader_version=DataFlashReader.version,
        t0_boot_ns=t0_us * 1000,
        t0_utc_ns=t0_utc,
        utc_source="gps" if t0_utc is not None else "none",
        leap_seconds=LEAP_SECONDS if t0_utc is not None else None,
        ned_origin=origin,
        params=params,
        diagnostics=diag,
    )
    if t0_utc is not None and t0_utc < _LEAP18_FROM_UTC_S * 1_000_000_000:
        diag["warnings"].append(
            "GPS->UTC uses 18 leap seconds (pymavlink's convention); the true offset before "
            "2017-01-01 was smaller (16 s in 2014), so t0_utc_ns may be up to 2 s late")
    if gps_fix:
        meta["utc_gps_fix"] = gps_fix
    meta["dataflash"] = {"old_format": not any(f.time_field == "TimeUS" for f in res.formats.values()),
                         "has_fmtu": "FMTU" in res.tables}
    if any(k in params for k in ("RADR_SN", "RADR_SE", "RADR_SD", "RADR_TAU")):
        meta["radar"] = {"site_ned_m": [params.get("RADR_SN", 0.0), params.get("RADR_SE", 0.0),
                                        params.get("RADR_SD", 0.0)],
                         "tau_rd_s": params.get("RADR_TAU", 0.0)}
    return FlightLog.from_streams(meta, streams)


def _plausible_density(head: bytes) -> bool:
    """Logs that start mid-stream: many ``A3 95`` headers, spaced like records."""
    if len(head) < 512:
        return False
    h = np.frombuffer(head, dtype=np.uint8)
    pos = np.flatnonzero((h[:-1] == HEAD1) & (h[1:] == HEAD2))
    if len(pos) < 16:
        return False
    # one header per <= 128 bytes on average, and most gaps shorter than an FMT record
    gaps = np.diff(pos)
    return len(pos) * 128 >= len(h) and np.median(gaps) <= FMT_LEN


@register
class DataFlashReader(LogReader):
    """ArduPilot DataFlash ``.bin`` logs (old TimeMS and modern TimeUS/FMTU formats)."""

    name = "dataflash"
    source_format = "ardupilot_dataflash"
    version = "1"
    priority = 20

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        if not head:
            return None
        if head[:3] == bytes((HEAD1, HEAD2, FMT_TYPE)) and head[3:4] == bytes((FMT_TYPE,)):
            return "DataFlash FMT-for-FMT record at offset 0 (A3 95 80 80)"
        if head[:3] == bytes((HEAD1, HEAD2, FMT_TYPE)):
            return "DataFlash FMT record at offset 0 (A3 95 80)"
        if _plausible_density(head):
            return "DataFlash record headers (A3 95) at record density"
        return None

    def read(self, path: Path, *, config: dict | None = None,
             progress: Progress | None = None) -> FlightLog:
        try:
            res = decode(path, progress=progress)
        except IngestError as exc:
            raise IngestError(path, exc.reason) from None
        return to_flightlog(res)
