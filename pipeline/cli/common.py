"""What every ``uavpipe`` command shares for bad input: one line per problem, never a traceback.

* :func:`describe`: an exception as one line (the message alone for the project's own errors,
  which already say what and why; ``Type: message`` otherwise).
* :func:`nonnegative_int`: the argparse type of ``--seed``.
* :func:`table_problem`: whether a Parquet file is the kind of table an option expects
  (a ``segments`` file given as ``--state`` is named as such, not a ``KeyError: 't_ns'``).
* :class:`Claims`: outputs claimed in one run, so a second input that would overwrite the
  first one's files is refused by name instead of silently replacing them.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

#: exception types whose message is already the whole story (no class name printed)
_OWN_ERRORS = ("ConfigError", "ModelError", "IngestError", "StudyError", "TrajectoryError", "BearingReplayError",
               "EkfHmmError", "ColumnMapError", "SchemaError")


def describe(exc: BaseException) -> str:
    """``exc`` as one line: its message (whitespace collapsed), prefixed by the exception type
    unless it is one of the project's own errors."""
    msg = " ".join(str(exc).split()) or "(no message)"
    name = type(exc).__name__
    if name in _OWN_ERRORS:
        return msg
    if isinstance(exc, KeyError):
        return f"missing column or key: {' '.join(str(exc.args[0] if exc.args else '').split())}"
    if isinstance(exc, OSError) and exc.filename is not None:
        return f"{exc.strerror or name}: {exc.filename}"
    return f"{name}: {msg}"


def nonnegative_int(text: str) -> int:
    """argparse ``type=`` for seeds: an integer ≥ 0 (NumPy's generators refuse negative seeds)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative (a seed is an integer >= 0)")
    return value


def table_problem(path: str | os.PathLike, expected: tuple[str, ...], what: str) -> str | None:
    """``None`` if ``path`` is a Parquet table written as one of ``expected`` (its ``uavpipe``
    metadata ``table``, e.g. ``state`` or ``simulate_set``), else why not, in a few words.
    """
    import pyarrow as pa

    from ..io.parquet import read_table_meta

    p = Path(path)
    if not p.exists():
        return "no such file"
    if not p.is_file():
        return "not a file"
    try:
        table = read_table_meta(p).get("table")
    except (pa.ArrowInvalid, OSError, ValueError) as exc:
        return f"not a readable Parquet table ({describe(exc)})"
    if table is None or table in expected:
        return None  # a table without uavpipe metadata gets the benefit of the doubt
    return f"not {what} (it is a '{table}' table)"


def vehicle_problem(vehicle: str | None, config: dict) -> str | None:
    """Why ``--vehicle`` is refused, as the workflow's manifest check refuses it: a vehicle with
    no ``preprocess.vehicles`` entry is an error, never a silent default (``None``: accepted)."""
    from ..io.manifest import GENERIC_VEHICLE

    known = (config.get("preprocess") or {}).get("vehicles") or {}
    if not vehicle or vehicle == GENERIC_VEHICLE or vehicle in known:
        return None
    return (f"unknown vehicle {vehicle!r}: add it to preprocess.vehicles or give {GENERIC_VEHICLE!r} "
            f"(known: {', '.join([GENERIC_VEHICLE, *sorted(known)])})")


def ingest_flight_id(d: Path) -> str:
    """The flight id of an ingest folder (its ``meta.json`` ``flight_id``, else the folder name);
    ``ValueError`` naming the folder when it is not one (preprocess and estimate read their
    flights so)."""
    meta = d / "meta.json"
    try:
        m = json.loads(meta.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ValueError(f"{d}: not an ingest folder ({meta}: {describe(exc)})") from None
    if not isinstance(m, dict):
        raise ValueError(f"{d}: not an ingest folder ({meta} holds a JSON {type(m).__name__}, not an object)")
    return str(m.get("flight_id") or d.name)


def json_object_problem(path: str | os.PathLike) -> str | None:
    """``None`` if ``path`` holds a JSON object, else why not, in a few words."""
    try:
        obj = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return f"not a readable JSON file ({describe(exc)})"
    return None if isinstance(obj, dict) else f"holds a JSON {type(obj).__name__}, not an object"


class Claims:
    """The outputs one command run has written, and from which input: a later input that would
    overwrite them is skipped. Only a success claims its outputs, so a failed input's placeholder
    never blocks a good input of the same flight."""

    def __init__(self) -> None:
        self._by: dict[str, str] = {}

    def clash(self, name: str | os.PathLike) -> str | None:
        """``None`` when no input of this run has written ``name`` yet, else the reason to skip."""
        key = os.path.normpath(str(name))
        first = self._by.get(key)
        return None if first is None else f"would overwrite {key}, written from {first} in this run; skipped"

    def claim(self, name: str | os.PathLike, source: str | os.PathLike) -> None:
        """Record that ``source`` wrote ``name``."""
        self._by[os.path.normpath(str(name))] = str(source)
