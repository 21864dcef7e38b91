"""Reader registry: one reader per format, chosen from the file's bytes, never its extension.

Every reader module in :data:`READER_MODULES` defines a :class:`~pipeline.io.base.LogReader`
subclass decorated with :func:`register`. :func:`detect` offers the first 64 KiB of a file
(or ``b""`` for a directory) to each reader's ``sniff`` in priority order; the first that
claims it wins, and its one-line reason is recorded (``uavpipe info`` prints it).

:func:`read_log` is the one entry point for decoding: detection, reading, ``meta`` bookkeeping
(sha256, size, reader, flight id) and the guarantee that failures surface as
:class:`~pipeline.io.base.IngestError` naming the file and the reason, never as a library
traceback. A file is read once: the sniffers see its first 64 KiB, and readers that decode
from memory (``reads_bytes``) get the whole file, whose sha256 is computed from the same bytes
(in a thread, while the reader decodes: hashlib releases the GIL).
"""

from __future__ import annotations

import importlib
import os
import re
import traceback
from pathlib import Path

import hashlib
import threading

from .base import FlightLog, IngestError, LogReader, losses_text, Progress, read_file, sha256_of, source_size

#: Reader modules, imported on first use (each registers its reader class).
READER_MODULES: tuple[str, ...] = ("dataflash", "tlog", "rosbag", "mcap_reader", "ulog", "flightcoach",
                                  "tabular")

_READERS: dict[str, type[LogReader]] = {}
_loaded = False

HEAD_BYTES = 64 * 1024


def register(cls: type[LogReader]) -> type[LogReader]:
    """Class decorator: add a reader to the registry under ``cls.name``."""
    if not cls.name:
        raise ValueError(f"{cls.__name__} has no name")
    _READERS[cls.name] = cls
    return cls


def readers() -> list[type[LogReader]]:
    """Registered readers in sniffing order."""
    global _loaded
    if not _loaded:
        for mod in READER_MODULES:
            importlib.import_module(f"{__package__}.{mod}")
        _loaded = True
    return sorted(_READERS.values(), key=lambda r: (r.priority, r.name))


def get_reader(name: str) -> type[LogReader]:
    readers()
    try:
        return _READERS[name]
    except KeyError:
        raise IngestError(None, f"unknown format {name!r}; known: {', '.join(sorted(_READERS))}") from None


def detect(path: str | os.PathLike) -> tuple[type[LogReader], str]:
    """Choose the reader for ``path`` from its content.

    Returns
    -------
    (reader class, reason)

    Raises
    ------
    IngestError
        Missing, unreadable or empty file, or no reader recognises the content.
    """
    p = Path(path)
    if not p.exists():
        raise IngestError(p, "no such file or directory")
    head = b""
    if p.is_file():
        try:
            with open(p, "rb") as fh:
                head = fh.read(HEAD_BYTES)
        except OSError as exc:
            raise IngestError(p, f"cannot read: {exc.strerror or exc}") from None
        if not head:
            raise IngestError(p, "empty file (0 bytes)")
    for r in readers():
        try:
            reason = r.sniff(p, head)
        except Exception:  # a sniffer bug must not hide the other readers
            reason = None
        if reason:
            return r, reason
    if p.is_dir():
        raise IngestError(p, _folder_problem(p))
    if not p.is_file():   # a device, a FIFO, a socket: nothing was read from it
        raise IngestError(p, "not a regular file (a device, pipe or socket); give a log file")
    cut = [r for r in readers() if r.magic and len(head) < len(r.magic) and r.magic.startswith(head)]
    if cut:  # a log cut inside its fixed header (a 10-byte '#ROSBAG V2' is no unknown format)
        raise IngestError(p, f"truncated: its {len(head)} byte(s) are the start of a {cut[0].name} "
                             f"file's {len(cut[0].magic)}-byte header, and nothing follows")
    raise IngestError(p, f"unrecognised log format (file starting {head[:8].hex(' ')}); known formats: "
                      f"{', '.join(r.name for r in readers())}")


def _folder_problem(p: Path) -> str:
    """Why a folder is no log: the only folder format is a ROS 2 bag (``metadata.yaml`` beside
    its storage files); say what the folder holds instead, or why it cannot be listed."""
    try:
        names = sorted(x.name for x in p.iterdir())
    except OSError as exc:
        return f"cannot list the folder: {exc.strerror or exc}"
    if not names:
        return "an empty folder, not a log"
    shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
    return (f"a folder without metadata.yaml, so not a ROS 2 bag (it holds {shown}); "
            f"give a log file itself, or the bag's folder")


_ID_BAD = re.compile(r"[^A-Za-z0-9-]+")


def flight_id_for(path: str | os.PathLike) -> str:
    """Default flight id: the file (or bag directory) stem with characters outside
    ``[A-Za-z0-9-]`` replaced by ``-`` (the workflow's wildcard alphabet)."""
    p = Path(path)
    stem = p.name if p.is_dir() else p.stem
    return _ID_BAD.sub("-", stem).strip("-") or "flight"


def read_log(path: str | os.PathLike, *, fmt: str | None = None, flight_id: str | None = None,
             config: dict | None = None, progress: Progress | None = None,
             labels: str | os.PathLike | None = None) -> FlightLog:
    """Ingest one log into a :class:`FlightLog`.

    Parameters
    ----------
    path : path-like
        Log file or bag directory.
    fmt : str, optional
        Force a reader by name instead of detecting from the bytes.
    flight_id : str, optional
        Defaults to :func:`flight_id_for`.
    config : dict, optional
        The ``ingest`` section of the dataset config (topic maps, column maps, ...).
    progress : callable, optional
        ``progress(done, total)`` for long decodes.
    labels : path-like, optional
        A truth/labels side-car to attach (:mod:`pipeline.io.sidecar`); without it,
        ``<log>.truth.parquet`` beside the log is attached when present.

    Raises
    ------
    IngestError
        One line naming the file and the reason; library exceptions are wrapped.
    """
    p = Path(path)
    if fmt:
        reader_cls, reason = get_reader(fmt), f"format {fmt!r} forced by the caller"
        if not p.exists():
            raise IngestError(p, "no such file or directory")
    else:
        reader_cls, reason = detect(p)
    digest: dict[str, str] = {}
    hasher = None
    try:
        if reader_cls.reads_bytes and p.is_file():
            try:
                data = read_file(p)
            except OSError as exc:
                raise IngestError(p, f"cannot read: {exc.strerror or exc}") from None
            hasher = threading.Thread(target=lambda: digest.setdefault("sha256", hashlib.sha256(data).hexdigest()),
                                      daemon=True)
            hasher.start()
            log = reader_cls().read(p, config=config, progress=progress, data=data)
        else:
            log = reader_cls().read(p, config=config, progress=progress)
    except IngestError:
        raise
    except MemoryError:
        raise IngestError(p, f"out of memory while decoding as {reader_cls.name}") from None
    except Exception as exc:  # last line of defence: never leak a deep library traceback
        where = traceback.extract_tb(exc.__traceback__)[-1]
        raise IngestError(
            p, f"{reader_cls.name} reader failed: {type(exc).__name__}: {exc} "
               f"(at {Path(where.filename).name}:{where.lineno})") from exc
    finally:
        if hasher is not None:
            hasher.join()
    from .origin import check_gps
    from .sidecar import attach_sidecar, find_sidecar

    side = Path(labels) if labels else find_sidecar(p)
    step = "checking time stamps"
    try:
        log.drop_absurd_times()  # whatever the reader: no sample centuries away from the flight
        if side is not None:
            step = f"attaching the side-car {side.name}"
            attach_sidecar(log, side)  # raises IngestError naming the side-car
        step = "checking the GPS"
        check_gps(log)  # lat = lon = 0 never a position; why the NED origin is null
    except IngestError:
        raise
    except Exception as exc:  # the same last line of defence as around the reader
        raise IngestError(p, f"{step} failed: {type(exc).__name__}: {exc}") from exc
    if not any(log.n_rows().values()):
        # a log cut to its headers, or with nothing mapped: 'partial' would hide that it is empty
        lost = losses_text(log.meta.get("diagnostics") or {})
        raise IngestError(p, f"no data: every stream is empty after decoding as {reader_cls.name}"
                             + (f"; {lost}" if lost else ""))
    m = log.meta
    m["flight_id"] = flight_id or m.get("flight_id") or flight_id_for(p)
    m["source_path"] = str(p)
    m["source_format"] = m.get("source_format") or reader_cls.source_format
    m["reader"] = reader_cls.name
    m["reader_version"] = reader_cls.version
    m["detected_by"] = reason
    m["source_sha256"] = digest["sha256"] if hasher is not None else sha256_of(p)
    m["source_size_bytes"] = source_size(p)
    if m.get("status") == "ok" and (m["diagnostics"].get("bytes_skipped")
                                    or m["diagnostics"].get("records_dropped")):
        m["status"] = "partial"
    return log
