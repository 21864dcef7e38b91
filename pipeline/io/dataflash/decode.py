"""ArduPilot DataFlash ``.bin`` decoder: every message type into column tables, vectorised.

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
   Each break is a damaged span: counted in ``records_dropped['damaged']`` and named in a
   warning (:func:`_note_damage`), which pymavlink does not do.
3. **Per-type pass.** For each type the bodies are gathered into an ``(n, L-3)`` byte matrix
   and viewed through a NumPy structured dtype built from the FMT record (format characters
   ``a b B g h H i I f d n N Z c C e E L M q Q`` per the DataFlash specification). Scaled
   formats are divided as pymavlink does (``c C e E`` by 100, ``L`` by 10⁷: dividing by the
   inverse multiplier is what pymavlink does for accuracy, so values match it bit for bit);
   char fields are decoded UTF-8 (falling back to ISO-8859-1) and cut at the first NUL, once
   per distinct value. ``FMTU``/``MULT`` multipliers are attached to every format and applied
   on request (``apply_mult=True``).

The raw tables match pymavlink's ``recv_msg`` loop record for record and value for value on
clean logs (``tests/io/test_dataflash_reader.py``); :mod:`pipeline.io.dataflash.streams` maps
them to the canonical streams of :mod:`pipeline.io.schema`.

Cost. Everything above is a handful of whole-buffer NumPy operations plus one Python step per
message *type* (a few dozen per log), never per record; structured dtypes are built only for
types that have records, and ASCII char columns are decoded as one fixed-width array.
"""

from __future__ import annotations

from collections.abc import MutableMapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from ..base import IngestError, Progress, read_file

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
#: body size of each format character (validates a FMT's Length without building its dtype)
_CHAR_SIZE: dict[str, int] = {c: np.dtype(d).itemsize for c, (d, _) in FORMAT_CHARS.items()}
_FORMAT_SET = frozenset(FORMAT_CHARS)


@dataclass
class MsgFormat:
    """One message type as declared by its FMT record (plus FMTU units/multipliers).

    ``dtype`` (the NumPy structured dtype of the body, :func:`format_dtype`) is built on first
    use: a log declares ~80 types but has records of about half of them.
    """

    type_id: int
    name: str
    length: int
    fmt: str
    columns: list[str]
    units: list[str] | None = None
    mults: list[float | None] | None = None
    instance_field: str | None = None
    _dtype: np.dtype | None = field(default=None, repr=False, compare=False)

    @property
    def dtype(self) -> np.dtype:
        if self._dtype is None:
            self._dtype = format_dtype(self.fmt, self.columns)
        return self._dtype

    @property
    def time_field(self) -> str | None:
        """The boot-time field pymavlink's clock would use, or ``None`` (untimed record)."""
        if self.columns and self.columns[0] in ("TimeUS", "TimeMS"):
            return self.columns[0]
        return None


class Columns(MutableMapping):
    """One message type's columns, ``{field name: ndarray}`` in format order.

    Char columns are decoded to ``str`` on first access (then cached): most of them (FMT
    columns, STAK names, FILE data) are never read by the stream mapping, and decoding is the
    one per-value Python step of the decoder. Everything else is an ordinary mapping.
    """

    __slots__ = ("_data", "_lazy", "_order")

    def __init__(self):
        self._data: dict[str, np.ndarray] = {}
        self._lazy: dict[str, Callable[[], np.ndarray]] = {}
        self._order: list[str] = []

    def set_lazy(self, key: str, make: Callable[[], np.ndarray]) -> None:
        """Set ``key`` to ``make()``, computed on first access."""
        if key not in self:
            self._order.append(key)
        self._data.pop(key, None)
        self._lazy[key] = make

    def __getitem__(self, key: str) -> np.ndarray:
        try:
            return self._data[key]
        except KeyError:
            make = self._lazy.pop(key)  # KeyError for an unknown column, as a dict
            v = self._data[key] = make()
            return v

    def __setitem__(self, key: str, value: np.ndarray) -> None:
        if key not in self:
            self._order.append(key)
        self._lazy.pop(key, None)
        self._data[key] = value

    def __delitem__(self, key: str) -> None:
        if key not in self:
            raise KeyError(key)
        self._data.pop(key, None)
        self._lazy.pop(key, None)
        self._order.remove(key)

    def __contains__(self, key) -> bool:
        return key in self._data or key in self._lazy

    def __iter__(self) -> Iterator[str]:
        return iter(list(self._order))

    def __len__(self) -> int:
        return len(self._order)

    def __repr__(self) -> str:
        return f"Columns({self._order})"


@dataclass
class DecodeResult:
    """Output of :func:`decode`.

    Attributes
    ----------
    tables : dict
        ``{message name: Columns}`` (a mapping ``{column: ndarray}``); unscaled numeric
        columns are strided views into one record matrix per type, scaled ones float64, char
        fields object arrays of ``str`` (``bytes`` for ``FILE.Data``, as pymavlink) decoded on
        first access, ``a`` fields ``(n, 32)`` int16.
    offsets : dict
        ``{message name: int64 byte offset of each record}`` (file order).
    formats : dict
        ``{message name: MsgFormat}``.
    diagnostics : dict
        ``bytes_skipped``, ``records_dropped``, ``record_counts``, ``warnings``, ``n_bytes``.
    type_formats : dict
        ``{type id: MsgFormat}`` for every valid FMT in the file, records or not.
    """

    tables: dict[str, Columns]
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
    """Fixed-width byte strings -> object array of ``str`` by :func:`_null_term`'s rule.

    Up to a few thousand values (every real log's PARM/FMT/MSG) a plain loop is fastest: ASCII
    is decoded directly, anything else by :func:`_null_term`. Longer columns (concatenated
    logs) are cut at their first NUL in the byte matrix and converted as one fixed-width array,
    the values with a byte >= 0x80 decoded one distinct value at a time."""
    n = len(col)
    if n == 0:
        return np.empty(0, dtype=object)
    if n <= 8192:
        out = []
        for b in col.tolist():  # bytes, trailing NULs already stripped by NumPy
            try:
                s = b.decode("ascii")
            except UnicodeDecodeError:
                out.append(_null_term(b))
                continue
            i = s.find("\0")
            out.append(s if i < 0 else s[:i])
        res = np.empty(n, dtype=object)
        res[:] = out
        return res
    width = col.dtype.itemsize
    mat = np.ascontiguousarray(col).view(np.uint8).reshape(n, width)
    high = (mat >= 0x80).any(axis=1)
    # zero everything from the first NUL on (the S -> U conversion drops trailing NULs), and
    # the non-ASCII rows, which are decoded below
    cut = np.logical_or.accumulate(mat == 0, axis=1)
    if high.any():
        cut |= high[:, None]
    if cut.any():
        mat = np.where(cut, np.uint8(0), mat)
    res = mat.view(f"S{width}").reshape(n).astype(f"U{width}").astype(object)
    if high.any():
        k = np.flatnonzero(high)
        uniq, inv = np.unique(col[k], return_inverse=True)
        # np.unique strips trailing NULs from S-dtype values, which the NUL cut makes harmless
        dec = np.array([_null_term(bytes(u)) for u in uniq], dtype=object)
        res[k] = dec[inv.reshape(-1)]
    return res


def _strings(col: np.ndarray) -> Callable[[], np.ndarray]:
    return lambda: _decode_strings(col)


def _file_bytes(col: np.ndarray) -> Callable[[], np.ndarray]:
    """``FILE.Data``: raw bytes, NULs kept, as pymavlink returns them."""
    def make() -> np.ndarray:
        raw = np.ascontiguousarray(col).view(np.uint8).reshape(len(col), -1)
        return np.array([bytes(r) for r in raw], dtype=object) if len(col) else np.empty(0, object)
    return make


def format_dtype(fmt: str, columns: list[str]) -> np.dtype:
    """NumPy structured dtype of a record body with DataFlash format ``fmt`` (FMT ``Format``).

    Field names are ``columns`` (FMT ``Columns``); a missing or empty name becomes
    ``field<i>`` and a repeated one ``<name>_<i>``. Scaled characters (``c C e E L``) keep
    their stored integer type; the caller divides (:data:`FORMAT_CHARS`).
    """
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
    body = _gather(buf, pos + 3, _FMT_DTYPE)
    if len(body) > 256:
        # more FMT records than type ids: a log written in pieces or concatenated logs. Identical
        # records are judged once and weighted by their count: a record's verdict depends only
        # on its bytes and on the definitions before its first copy, which later copies cannot
        # change.
        _, first, count = np.unique(body.view(np.dtype((np.void, FMT_LEN - 3))),
                                    return_index=True, return_counts=True)
        order = np.argsort(first, kind="stable")
        recs, counts = body[first[order]], count[order].tolist()
    else:
        recs, counts = body, [1] * len(body)
    for r, cnt in zip(recs.tolist(), counts):
        tid, length, name_b, fmt_b, cols_b = r
        try:
            name = name_b.split(b"\0", 1)[0].decode("ascii")
            fmt = fmt_b.split(b"\0", 1)[0].decode("ascii")
            cols = cols_b.split(b"\0", 1)[0].decode("ascii")
        except UnicodeDecodeError:
            bad += cnt
            continue
        if (not name or not name.isprintable() or not name.replace("_", "").isalnum()
                or not _FORMAT_SET.issuperset(fmt)):
            bad += cnt
            continue
        size = sum(map(_CHAR_SIZE.__getitem__, fmt))
        if size + 3 != length:
            msg = (f"FMT {name} (type {tid}) declares {length} bytes but format {fmt!r} needs "
                   f"{size + 3}: type not decoded")
            if msg not in warnings:
                warnings.append(msg)
            continue
        if tid in formats:
            old = formats[tid]
            if (old.name, old.fmt, old.length) != (name, fmt, length):
                bad += cnt  # a conflicting redefinition: keep the first (corruption is likelier)
            continue
        formats[tid] = MsgFormat(tid, name, length, fmt, cols.split(",") if cols else [])
    return formats, bad


def _gather(buf: np.ndarray, starts: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """Contiguous records of ``dtype`` copied from ``buf`` at byte offsets ``starts``.

    ``buf`` is viewed as overlapping records of ``dtype`` at every byte offset (stride 1), so
    the gather moves each record as one item: no index matrix, no per-byte loop."""
    if dtype.itemsize == 0:
        return np.zeros(len(starts), dtype=dtype)
    w = dtype.itemsize
    view = np.ndarray(shape=(max(len(buf) - w + 1, 0),), dtype=np.dtype((np.void, w)), buffer=buf,
                      strides=(1,))
    return view[starts].view(dtype)


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


#: damaged spans described one by one in the warnings; the rest are summed in one more line
MAX_DAMAGE_WARNINGS = 5


def _note_damage(diag: dict, pos: np.ndarray, lens: np.ndarray, ptype: np.ndarray,
                 formats: dict[int, MsgFormat], n_bytes: int, truncated: bool) -> None:
    """Count and describe the bytes the record chain steps over (``diag`` is edited).

    A healthy log is one unbroken chain (every real log of ``../shared/realdata`` is, up to a
    cut end). Each gap inside it is a damaged span: the records there cannot be told apart,
    so the span is counted once in ``records_dropped['damaged']`` (at least one record lost,
    as the ULog reader counts its ``corrupt`` spans) and named in a warning with its byte
    range, the record types either side and the records it would hold at the log's mean
    record length. Without this the loss showed only in ``bytes_skipped`` (pymavlink skips
    such bytes silently too).
    """
    if not len(pos):
        return
    ends = pos + lens
    gap = np.flatnonzero(ends[:-1] != pos[1:])
    spans = [(0, int(pos[0]), -1, 0)] if pos[0] > 0 else []
    spans += [(int(ends[i]), int(pos[i + 1]), int(i), int(i) + 1) for i in gap]

    def name(k: int) -> str:
        f = formats.get(int(ptype[k]))
        return f.name if f is not None else f"type {int(ptype[k])}"

    mean_len = float(lens.mean())
    for a, b, before, after in spans[:MAX_DAMAGE_WARNINGS]:
        where = (f"records either side: {name(before)}, {name(after)}" if before >= 0
                 else f"before the first record, a {name(after)}")
        diag["warnings"].append(f"DataFlash damaged at bytes {a}-{b}: {b - a} byte(s) not decoded ({where}; "
                                f"about {max(1, round((b - a) / mean_len))} record(s) at this log's mean "
                                f"record length); decoding resumed at byte {b}")
    if len(spans) > MAX_DAMAGE_WARNINGS:
        rest = spans[MAX_DAMAGE_WARNINGS:]
        diag["warnings"].append(f"DataFlash damaged in {len(rest)} more span(s) ({sum(b - a for a, b, *_ in rest)} "
                                f"byte(s) in all, the last at byte {rest[-1][0]})")
    if spans:
        diag["records_dropped"]["damaged"] = len(spans)
    tail = n_bytes - int(ends[-1])
    if truncated and tail:
        diag["warnings"].append(f"DataFlash log cut short: its last {tail} byte(s) are an incomplete record "
                                f"(the file ends at byte {n_bytes})")
    elif tail:
        diag["warnings"].append(f"DataFlash log ends in {tail} byte(s) that hold no record")


_HEADER_CHUNK = 1 << 23  # 8 MiB: the comparison temporary stays small and is reused


def _find_headers(buf: np.ndarray) -> np.ndarray:
    """Sorted offsets ``i`` with ``buf[i:i+2] == A3 95`` and a type byte after them.

    The ``A3`` bytes are found in one pass (in 8 MiB pieces, so the boolean temporary is not
    the size of the file); the candidates are then checked for the ``95`` after them."""
    n = len(buf)
    if n < 3:
        return np.empty(0, dtype=np.int64)
    pieces = [np.flatnonzero(buf[a:min(a + _HEADER_CHUNK, n - 2)] == HEAD1) + a
              for a in range(0, n - 2, _HEADER_CHUNK)]
    a3 = pieces[0] if len(pieces) == 1 else np.concatenate(pieces)
    return a3[buf[a3 + 1] == HEAD2]


def _as_buffer(src) -> tuple[np.ndarray, str]:
    if isinstance(src, np.ndarray):
        return src.reshape(-1).view(np.uint8), "<bytes>"
    if isinstance(src, (bytes, bytearray, memoryview)):
        return np.frombuffer(src, dtype=np.uint8), "<bytes>"
    p = Path(src)
    try:
        data = read_file(p)
    except OSError as exc:
        raise IngestError(p, f"cannot read: {exc.strerror or exc}") from None
    return data, str(p)


def _unit_tables(tables, formats_by_id: dict[int, MsgFormat], decoded: set[int]) -> None:
    """Attach FMTU unit labels and MULT multipliers to the formats they describe.

    Only types with records (``decoded`` type ids) get them: the others have no column to
    scale, and skipping them halves the cost on a modern log (~160 FMTU rows)."""
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
        if ftype not in decoded:
            continue
        f = formats_by_id[ftype]
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
                                                 _dtype=_FMT_DTYPE))
    if bad_fmt:
        diag["records_dropped"]["bad_format"] = bad_fmt
    lengths = np.zeros(256, dtype=np.int64)
    for tid, f in formats_by_id.items():
        lengths[tid] = f.length
    lens = lengths[types_at]
    known = lens > 0
    cand = hdr[known]
    ctype = types_at[known]
    ends = cand + lens[known]
    del lens
    on, truncated = _chain(cand, ends, n)
    pos = cand[on]
    ptype = ctype[on]
    used = int(lengths[ptype].sum())
    if truncated:
        diag["records_dropped"]["truncated"] = 1
    diag["bytes_skipped"] = n - used
    _note_damage(diag, pos, lengths[ptype], ptype, formats_by_id, n, truncated)
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
    tables: dict[str, Columns] = {}
    offsets: dict[str, np.ndarray] = {}
    formats: dict[str, MsgFormat] = {}
    meta_names = {"FMT", "FMTU", "UNIT", "MULT"}

    by_id = sorted(zip(starts.tolist(), stops.tolist()), key=lambda ab: int(sorted_types[ab[0]]))
    for done, (a, b) in enumerate(by_id):
        tid = int(sorted_types[a])
        f = formats_by_id[tid]
        name = f.name if f.name not in formats else f"{f.name}#{tid}"
        p = pos_by_type[a:b]
        diag["record_counts"][name] = diag["record_counts"].get(name, 0) + len(p)
        if types is not None and f.name not in types and f.name not in meta_names:
            continue
        rec = _gather(buf, p + 3, f.dtype)
        cols = Columns()
        for ch, cname in zip(f.fmt, f.dtype.names):
            v = rec[cname]
            div = FORMAT_CHARS[ch][1]
            if div is not None:
                cols[cname] = v / div
            elif ch in _STRING_CHARS:
                cols.set_lazy(cname, _file_bytes(v) if f.name == "FILE" and ch == "Z" else _strings(v))
            else:
                # unscaled numeric fields stay strided views into the type's record matrix: no
                # copy, and the tables hold each record's bytes once
                cols[cname] = v
        tables[name] = cols
        offsets[name] = p
        formats[name] = f
        if progress and done % 16 == 0:
            progress(n // 4 + (3 * n // 4) * (done + 1) // len(by_id), n)
    _unit_tables(tables, formats_by_id, {f.type_id for f in formats.values()})
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


def decode_all(src, *, apply_mult: bool = False) -> tuple[dict[str, Columns], dict]:
    """Raw message tables of a DataFlash log: ``({name: {column: ndarray}}, diagnostics)``.

    Every message type present is decoded (see :func:`decode`); values are those pymavlink's
    ``recv_msg`` loop returns (format scaling applied, strings decoded on first access).
    """
    res = decode(src, apply_mult=apply_mult)
    return res.tables, res.diagnostics
