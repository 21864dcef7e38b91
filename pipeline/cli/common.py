"""What every ``uavpipe`` command shares for bad input: one line per problem, never a traceback.

* :func:`describe`: an exception as one line (the message alone for the project's own errors,
  which already say what and why; ``Type: message`` otherwise).
* :func:`nonnegative_int`: the argparse type of ``--seed``.
* :func:`table_problem`: whether a Parquet file is the kind of table an option expects
  (a ``segments`` file given as ``--state`` is named as such, not a ``KeyError: 't_ns'``).
* :func:`pairing_problem`: whether inputs paired by position (``INGEST_DIR``/``--state``/
  ``--segments``) say they hold one flight (a shell glob may order two lists differently).
* :func:`folder_problem`: an output folder that exists as something else, refused up front.
* :func:`q2_problem`, :func:`model_problem`: an ``estimate --q2`` file and ``--model`` folder
  checked once, before any flight, as the EKF+HMM will read them.
* :class:`Claims`: outputs claimed in one run, so a second input that would overwrite the
  first one's files is refused by name instead of silently replacing them.
* :func:`add_config_option`: every command's ``--config FILE``, with one help text for its default.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from ..io.stage import one_line

#: exception types whose message is already the whole story (no class name printed)
_OWN_ERRORS = ("ConfigError", "ModelError", "IngestError", "StudyError", "TrajectoryError", "BearingReplayError",
               "EkfHmmError", "ColumnMapError", "SchemaError")


#: where ``--config`` is read from when not given (:func:`pipeline.config.load_config`), said alike
#: by every command's help
CONFIG_DEFAULT = "default datasets/config.yaml of the current folder, else the project's"


def add_config_option(p: argparse.ArgumentParser, what: str = "dataset config") -> None:
    """``--config FILE`` on ``p``: ``what`` it is for, then the shared default (:data:`CONFIG_DEFAULT`)."""
    p.add_argument("--config", type=Path, default=None, metavar="FILE", help=f"{what} ({CONFIG_DEFAULT})")


def describe(exc: BaseException) -> str:
    """``exc`` as one line: its message (whitespace collapsed), prefixed by the exception type
    unless it is one of the project's own errors."""
    msg = one_line(exc) or "(no message)"
    name = type(exc).__name__
    if name in _OWN_ERRORS:
        return msg
    if isinstance(exc, KeyError):
        return f"missing column or key: {one_line(exc.args[0] if exc.args else '')}"
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


#: columns a table kind must have whatever else it lacks: every reader of the kind indexes them
_REQUIRED_COLUMNS = {"segments": ("segment_id", "t_start_ns", "t_end_ns", "label"), "state": ("t_ns",)}


def table_problem(path: str | os.PathLike, expected: tuple[str, ...], what: str) -> str | None:
    """``None`` if ``path`` is a Parquet table written as one of ``expected`` (its ``uavpipe``
    metadata ``table``, e.g. ``state`` or ``simulate_set``) with the columns every reader of
    that kind indexes (:data:`_REQUIRED_COLUMNS`), else why not, in a few words.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

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
        # a table without uavpipe metadata gets the benefit of the doubt on its kind, not on
        # the columns every reader of that kind indexes (an edited segments table without
        # t_end_ns failed deep inside as "'Pandas' object has no attribute 't_end_ns'")
        need = _REQUIRED_COLUMNS.get(table or expected[0], ())
        try:
            names = set(pq.read_schema(p).names) if need else set()
        except (pa.ArrowInvalid, OSError, ValueError) as exc:
            return f"not a readable Parquet table ({describe(exc)})"
        missing = [c for c in need if c not in names]
        if missing:
            return f"{what} without column(s) {', '.join(missing)}"
        return None
    if "simulate_set" in expected and _older_set(p, table):
        return (f"a simulated set written by an older uavpipe (its metadata names the table '{table}', "
                f"not 'simulate_set'): rerun `snakemake -R simulate_sets` to rebuild the sets")
    return f"not {what} (it is a '{table}' table)"


def _older_set(path: Path, table: str) -> bool:
    """Whether ``table`` is the metadata kind of a set written before sets recorded
    ``simulate_set``: the set's own name (its file stem) or, failing that, no table kind of
    :data:`pipeline.io.schema.TABLES` but the sets' ``runs`` count. Such sets stay in
    ``results/`` after an upgrade because the workflow sees nothing to rebuild."""
    from ..io import schema
    from ..io.parquet import read_table_meta

    if table in schema.TABLES:
        return False
    return table == path.stem or "runs" in read_table_meta(path)


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


def carried_flight_id(path: str | os.PathLike) -> str | None:
    """The flight id an input says it holds: an ingest folder's ``meta.json`` ``flight_id`` or a
    table's ``uavpipe`` metadata ``flight_id``; ``None`` when it says none or cannot be read (the
    other checks name an unreadable input; a simulated set has no flight)."""
    import pyarrow as pa

    from ..io.parquet import read_table_meta

    p = Path(path)
    try:
        if p.is_dir():
            meta = json.loads((p / "meta.json").read_text(encoding="utf-8"))
        else:
            meta = read_table_meta(p)
    except (pa.ArrowInvalid, OSError, ValueError):
        return None
    fid = meta.get("flight_id") if isinstance(meta, dict) else None
    return str(fid) if fid else None


def pairing_problem(columns: list[tuple[str, list]]) -> str | None:
    """``None`` if the inputs paired by position name one flight each, else the first mismatch.

    ``columns``: ``(option, paths)`` per input list (``""`` for the positional one), every list
    as long as the first (``None`` lists are left out). Only inputs that carry a flight id
    (:func:`carried_flight_id`) are compared: a table without one gets the benefit of the doubt.
    The reason names both files and both flights, e.g. ``ing/b (flight b) and --state
    pp/a/state.parquet (flight a) are paired by position but hold different flights``.
    """
    cols = [(opt, list(paths)) for opt, paths in columns if paths is not None]
    for k in range(len(cols[0][1]) if cols else 0):
        seen: tuple[str, str] | None = None
        for opt, paths in cols:
            fid = carried_flight_id(paths[k])
            if fid is None:
                continue
            name = f"{opt} {paths[k]}" if opt else str(paths[k])
            if seen is None:
                seen = (name, fid)
            elif fid != seen[1]:
                return (f"{seen[0]} (flight {seen[1]}) and {name} (flight {fid}) are paired by position "
                        f"but hold different flights")
    return None


def folder_problem(opt: str, path: str | os.PathLike) -> str | None:
    """``'<opt> <path>: exists and is not a folder'`` when an output folder is already a file
    (or ``'... <parent> is a file, not a folder'`` for a folder above it; ``opt`` ``""`` for a
    positional argument), else ``None``. Said once, before any work: an
    output written under it fails with ``Not a directory`` for every input."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        return f"{opt + ' ' if opt else ''}{p}: exists and is not a folder"
    for up in p.parents:      # a file where a folder above it must go
        if up.exists():
            if not up.is_dir():
                return f"{opt + ' ' if opt else ''}{p}: {up} is a file, not a folder"
            break
    return None


def q2_problem(path: str | os.PathLike, model_set: str | None = None) -> str | None:
    """``None`` if ``path`` is a usable ``run_q2`` output (of ``model_set`` when given), else
    why not, in a few words: the EKF+HMM's own reading
    (:func:`pipeline.estimate.run.read_q2`), made before any flight."""
    from ..estimate.run import read_q2

    bad = json_object_problem(path)
    return bad or read_q2(path, model_set)[0] or None


def model_problem(path: str | os.PathLike) -> str | None:
    """``None`` if ``path`` is a model set the EKF+HMM can load, else why not, naming the file.

    Loaded once (:meth:`pipeline.models.classifier.ManeuverModelSet.load`), as ``classify``
    does, so a damaged folder is said once and not once per flight; ``meta.json`` is read
    first so that its problems name it (the loader's ``JSONDecodeError`` does not).
    """
    from ..models.base import ModelError
    from ..models.classifier import ManeuverModelSet
    from ..models.features import GMR_FEATURE_SETS

    d = Path(path)
    if not d.is_dir():
        return "no such folder" if not d.exists() else "not a folder"
    meta = d / "meta.json"
    if not meta.is_file():
        return "not a model directory (no meta.json)"
    bad = json_object_problem(meta)
    if bad:
        return f"{meta}: {bad}"
    m = json.loads(meta.read_text(encoding="utf-8"))
    if m.get("status") == "failed":
        return f"{meta}: the model set failed to train ({m.get('error') or 'no reason given'})"
    if not (d / "params.npz").is_file():
        return f"no params.npz (beside {meta.name})"
    try:
        ms = ManeuverModelSet.load(d)
    except ModelError as exc:
        msg = describe(exc)
        msg = msg[len(f"{d}: "):] if msg.startswith(f"{d}: ") else msg
        # meta.json has been read above: what the loader cannot read is params.npz
        unreadable = "unreadable model files: "
        return f"{d / 'params.npz'}: {msg[len(unreadable):]}" if msg.startswith(unreadable) else msg
    fs = ms.config.feature_set
    if fs not in GMR_FEATURE_SETS:  # it would end as an ekf_hmm placeholder for every flight
        return f"has no GMR (feature set {fs}; the EKF+HMM needs one of {', '.join(GMR_FEATURE_SETS)})"
    return None


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
