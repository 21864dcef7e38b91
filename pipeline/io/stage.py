"""The declared paths a stage entry point receives: Snakemake's ``snakemake.input`` /
``snakemake.output`` (namedlists: key and attribute access) or a plain dict from the CLI.

Every ``run_<stage>(inputs, outputs, config, **job)`` reads its paths through these two
functions, so the two shapes behave the same everywhere. :func:`say` is how an entry point
reports a job on stderr (the workflow's log), and :func:`caller_restates` how the command line,
which prints its own line per input, keeps the job's summary from being said twice.
:func:`exception_line` is how a stage writes a failure's reason: one line.
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import sys
from collections.abc import Iterator, Mapping
from typing import Any

#: set while a caller prints each job's outcome itself (:func:`caller_restates`)
_RESTATED: contextvars.ContextVar[bool] = contextvars.ContextVar("uavpipe_restated", default=False)


def one_line(text: object) -> str:
    """``text`` with every run of whitespace (newlines included) as one space: a reason written
    into a table's metadata, a skipped entry or a log line stays one line."""
    return " ".join(str(text).split())


def exception_line(exc: BaseException, *, where: bool = True) -> str:
    """``exc`` as one line for a placeholder's reason, a skipped entry or a log line:
    ``Type: message (at file:line)``, whitespace collapsed (pyarrow and OS messages span
    several lines; a reason read in a table's metadata or a report has no room for a
    traceback). ``where=False`` leaves out the place it was raised (a file that cannot be read:
    the reader's line says nothing more). A :class:`MemoryError` says "out of memory"."""
    msg = one_line(exc) or "(no message)"
    if isinstance(exc, MemoryError):
        msg = f"out of memory ({msg})"
    at = ""
    if where:
        import traceback
        from pathlib import Path

        tb = traceback.extract_tb(exc.__traceback__)
        at = f" (at {Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
    return f"{type(exc).__name__}: {msg}{at}"


def say(prefix: str, msg: str, *, restated: bool = False) -> None:
    """One line ``<prefix>: <msg>`` on stderr. ``restated``: the job's summary or placeholder
    line, which a caller inside :func:`caller_restates` prints in its own words (one line per
    input, not two); every other notice is always said."""
    if restated and _RESTATED.get():
        return
    print(f"{prefix}: {msg}", file=sys.stderr, flush=True)


@contextlib.contextmanager
def caller_restates() -> Iterator[None]:
    """Within: the entry points leave their ``restated`` lines to the caller (the CLI)."""
    token = _RESTATED.set(True)
    try:
        yield
    finally:
        _RESTATED.reset(token)


def declared(paths: Any, name: str, default: Any = None) -> Any:
    """``paths[name]`` for a dict or a Snakemake namedlist, ``default`` when not declared."""
    if paths is None:
        return default
    if isinstance(paths, Mapping):
        return paths.get(name, default)
    try:
        return paths[name]
    except (KeyError, IndexError, TypeError, AttributeError):  # a namedlist raises AttributeError
        return getattr(paths, name, default)


def declared_list(paths: Any, name: str) -> list[str]:
    """A declared path or list of paths as a list of str (``[]`` when not declared)."""
    v = declared(paths, name)
    if v is None:
        return []
    return [str(v)] if isinstance(v, (str, os.PathLike)) else [str(x) for x in v]


def source_names(paths: Any) -> list[str]:
    """One short name per input file that tells the files apart, for run ids made unique per file.

    The file stems where they differ (the workflow's ``M1_train``, ``fc-p23-036``: names
    unchanged); else the last folders too, as few as make them differ (``a/state``, ``b/state``
    for the CLI's ``DIR/<flight>/state.parquet`` layout); the same file given twice gets ``#2``,
    ``#3``... on its repeats. Runs of different files therefore never share a run id, which
    would join them into one training sequence.

    >>> source_names(["out/a/state.parquet", "out/b/state.parquet"])
    ['a/state', 'b/state']
    >>> source_names(["sets/M1_train.parquet", "x/M1_train.parquet", "sets/M1_train.parquet"])
    ['sets/M1_train', 'x/M1_train', 'sets/M1_train#2']
    """
    from pathlib import PurePath

    parts = [PurePath(p).with_suffix("").parts for p in [str(x) for x in paths]]
    depth = max((len(p) for p in parts), default=1)
    for k in range(1, depth + 1):
        names = ["/".join(p[-k:]) for p in parts]
        if len(set(names)) == len(names):
            return names
    seen: dict[str, int] = {}
    out = []
    for n in names:
        seen[n] = seen.get(n, 0) + 1
        out.append(n if seen[n] == 1 else f"{n}#{seen[n]}")
    return out
