"""The flight manifest (``datasets/flights.tsv``), checked before anything runs.

The workflow (``rules/common.smk``) calls :func:`check_manifest` at start-up, so a mistake in the
manifest stops the run in seconds with one line naming the manifest file, the 1-based line of
the file and the flight id, e.g.::

    datasets/flights.tsv:4: flight crash-0036: unknown vehicle 'coptr' (known: generic, copter, ...)

Checked per row, in file order (the first failure is raised):

- ``flight_id`` is unique (a duplicate names the line of the first one);
- ``vehicle`` has an entry in the config's ``preprocess.vehicles`` or is ``generic`` (no
  vehicle-specific settings: the ``default`` entry where the config has one, else the schema's
  built-in defaults). A vehicle with no entry is an error, never a silent default;
- ``format`` is blank (detect from the bytes) or a reader name of :mod:`pipeline.io.registry`;
- ``labels`` is ``embedded``, ``none``, blank, or an existing file. Paths under ``results/`` are
  written by the workflow and count as existing; ``{realdata}`` expands to ``realdata_dir`` and a
  leading ``~`` to the home folder (:func:`expand_path`). The labels of a row whose log is absent
  are not checked: that row is skipped with a notice anyway;
- a ``results/sim/logs/`` path names a log the simulate stage writes with this config (when the
  caller passes ``simulated_logs``: the workflow does, from ``simulate.run.planned_logs``).

- ``flight_id`` is letters, digits and ``-`` (:data:`FLIGHT_ID`), ``role`` one of
  :data:`ROLES`, ``path`` non-empty and free of braces other than ``{realdata}`` (Snakemake
  would read them as wildcards).

These repeat what the JSON schema ``rules/schemas/flights.schema.yaml`` types, so a mistake is
one line with the file's line number instead of the schema validator's multi-line dump with a
0-based row; the schema validation that follows stays as the declaration.
"""

from __future__ import annotations

import os
import re
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

from ..config import ConfigError, read_text_file

#: the vehicle name that means "no vehicle-specific settings" (needs no config entry)
GENERIC_VEHICLE = "generic"

#: the manifest's columns, in order
COLUMNS: tuple[str, ...] = ("flight_id", "path", "vehicle", "role", "labels", "format", "notes")

#: what a flight id may be: it becomes a file name and a Snakemake wildcard value
FLIGHT_ID = re.compile(r"[A-Za-z0-9-]+")

#: ``role`` values (which model sets train on or test with the flight)
ROLES = ("train", "test", "none")

#: ``labels`` values that are not paths
LABEL_WORDS = ("embedded", "none", "")

#: where the simulate stage writes its log-file flights (manifest paths below it are checked)
SIM_LOG_DIR = "results/sim/logs/"


def expand_path(path: str, realdata_dir: str | None) -> str:
    """A manifest path with ``{realdata}`` replaced by the config's ``realdata_dir`` and a leading
    ``~`` (or ``~user``) by that home folder, as a shell would (``~/logs/f.bin``)."""
    return os.path.expanduser(path.replace("{realdata}", str(realdata_dir or "").rstrip("/")))


def log_available(path: str, base: str | os.PathLike | None = None) -> bool:
    """Whether an expanded manifest path can be read: it exists (relative to ``base``, default the
    working directory), or lies under ``results/``, which the workflow writes itself (the simulated
    and demo flights)."""
    # str.startswith, not Path: "results/..." is the workflow's own relative output tree
    return path.startswith("results/") or (Path(base or ".") / path).exists()


def reader_names() -> list[str]:
    """The reader names a manifest ``format`` may give (sorted)."""
    from .registry import readers

    return sorted(r.name for r in readers())


def check_manifest(path: str | os.PathLike, config: Mapping[str, Any], *,
                   base: str | os.PathLike | None = None,
                   simulated_logs: Collection[str] | None = None) -> list[dict[str, str]]:
    """Read and check a flight manifest; the rows as dicts of the columns, in file order.

    Parameters
    ----------
    path : path-like
        The tab-separated manifest (header line first; ``#`` lines and blank lines are skipped
        but counted, so line numbers are those of the file).
    config : mapping
        The validated dataset config (``preprocess.vehicles``, ``realdata_dir``).
    base : path-like, optional
        The folder relative paths are resolved against (default: the working directory, as the
        workflow's).
    simulated_logs : collection of str, optional
        The log names (``sim-M1-000.bin``, ``sim-M1-000-mcap``) the simulate stage writes under
        ``results/sim/logs/`` with this config; a row naming another one there is an error. ``None``
        (the default) leaves such paths unchecked.

    Returns
    -------
    list of dict
        One dict per row, every column a string.

    Raises
    ------
    ConfigError
        One line ``<path>:<line>: flight <id>: <reason>`` per bad row (every one, in file
        order, joined by newlines), or ``<path>: <reason>`` when the file or its header is
        unusable.
    """
    src = str(path)
    root = Path(base) if base is not None else Path.cwd()
    text = read_text_file(root / path, "manifest", source=src)  # root / absolute = absolute
    vehicles = dict((config.get("preprocess") or {}).get("vehicles") or {})
    realdata = config.get("realdata_dir")
    known_vehicles = [GENERIC_VEHICLE, *sorted(v for v in vehicles if v != GENERIC_VEHICLE)]

    header: list[str] | None = None
    rows: list[dict[str, str]] = []
    problems: list[str] = []
    first_line: dict[str, int] = {}
    for lineno, raw in enumerate(text.splitlines(), start=1):
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        cells = raw.split("\t")
        if header is None:
            header = [c.strip() for c in cells]
            missing = [c for c in COLUMNS if c not in header]
            if missing:
                hint = " (the line has commas and no tab: the manifest is tab-separated)" \
                    if len(cells) == 1 and raw.count(",") >= len(COLUMNS) - 2 else ""
                raise ConfigError(f"{src}:{lineno}: header lacks column(s) {', '.join(missing)} "
                                  f"(expected: {', '.join(COLUMNS)}){hint}")
            # as the config refuses an unknown key: a column no stage reads is a typo or a
            # misunderstanding, and free text has its own column
            unknown = [c for c in header if c not in COLUMNS]
            twice = sorted({c for c in header if header.count(c) > 1})
            if unknown or twice:
                raise ConfigError(f"{src}:{lineno}: header has "
                                  + (f"unknown column(s) {', '.join(map(repr, unknown))}" if unknown else "")
                                  + (" and " if unknown and twice else "")
                                  + (f"column(s) {', '.join(twice)} twice" if twice else "")
                                  + f" (expected: {', '.join(COLUMNS)}; free text goes in notes)")
            continue
        if len(cells) > len(header):
            problems.append(f"{src}:{lineno}: {len(cells)} tab-separated fields, the header has {len(header)}")
            continue
        row = dict(zip(header, cells + [""] * (len(header) - len(cells))))
        why = _row_problem(row, lineno, first_line, vehicles, known_vehicles, realdata, root, simulated_logs)
        if why is None:
            rows.append(row)
            continue
        fid = row["flight_id"]
        short = f" (the row has {len(cells)} of the header's {len(header)} fields: a missing tab shifts " \
                "the columns after it)" if len(cells) < len(header) and len(cells) > 1 else ""
        problems.append(f"{src}:{lineno}: " + (why if why.startswith("flight_id ") else
                                               f"flight {fid or '(no id)'}: {why}") + short)
    if header is None:
        raise ConfigError(f"{src}: empty manifest (no header line)")
    if problems:
        raise ConfigError("\n".join(problems))
    return rows


def _row_problem(row: dict[str, str], lineno: int, first_line: dict[str, int], vehicles: Mapping,
                 known_vehicles: list[str], realdata: str | None, root: Path,
                 simulated_logs: Collection[str] | None) -> str | None:
    """What is wrong with one manifest row (``None``: nothing); records its id in ``first_line``."""
    fid = row["flight_id"]
    if not FLIGHT_ID.fullmatch(fid):
        return (f"flight_id {fid!r} must be letters, digits and '-' only "
                "(it becomes a file name and a workflow wildcard)")
    if fid in first_line:
        return f"duplicate flight_id (first on line {first_line[fid]})"
    first_line[fid] = lineno
    if not row["path"].strip():
        return "empty path"
    if any(b in expand_path(row[c], realdata or "") for b in "{}" for c in ("path", "labels")):
        return "braces in a path are read as workflow wildcards; only {realdata} may appear (rename the file or link it)"
    if row["role"] not in ROLES:
        return f"role {row['role']!r} must be one of {', '.join(ROLES)}"
    veh = row["vehicle"]
    if veh != GENERIC_VEHICLE and veh not in vehicles:
        return (f"unknown vehicle {veh!r}: add it to preprocess.vehicles or "
                f"write {GENERIC_VEHICLE!r} (known: {', '.join(known_vehicles)})")
    fmt = row["format"]
    if fmt:
        formats = reader_names()
        if fmt not in formats:
            return f"unknown format {fmt!r} (readers: {', '.join(formats)}; blank = detect from the file's bytes)"
    lab = row["labels"]
    log = expand_path(row["path"], realdata)
    if (simulated_logs is not None and log.startswith(SIM_LOG_DIR)
            and log.rstrip("/")[len(SIM_LOG_DIR):] not in simulated_logs):
        return (f"{row['path']} is not written by the simulate stage with "
                f"this config (simulate.datasets: sizes, log_formats)")
    if lab not in LABEL_WORDS and log_available(log, root):
        lab_path = expand_path(lab, realdata)
        if not log_available(lab_path, root) or not (
                lab_path.startswith("results/") or (root / lab_path).is_file()):
            return f"labels {lab!r} is neither 'embedded', 'none' nor an existing file"
    return None
