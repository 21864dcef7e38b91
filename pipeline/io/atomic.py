"""Atomic output files: written beside the target under a temporary name, then renamed onto it.

Every stage writes its outputs through :func:`atomic_output` (Parquet and JSON in
:mod:`pipeline.io.parquet`, model ``params.npz``, report pages, study texts), so a job killed
half-way never leaves a truncated file that Snakemake or a cluster scheduler would take as done:
the rename (``os.replace``) is atomic on one file system, and the temporary file is removed when
the write fails.

The temporary file gets the mode an ordinary ``open(path, "w")`` would give it, ``0o666 &
~umask`` (``rw-r--r--`` under the usual umask 022), not the ``rw-------`` of
:func:`tempfile.mkstemp`: results on a shared or cluster file system stay readable by the
group, as the reports written beside them are.
"""

from __future__ import annotations

import contextlib
import functools
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path


@functools.cache
def process_umask() -> int:
    """The process's umask, read once.

    Read from ``/proc/self/status`` where Linux gives it (no side effect); elsewhere by setting and
    restoring it, which this does once per process (cached) because a thread creating a file in
    between would get a zero mask.
    """
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_output(target: str | os.PathLike, *, suffix: str = ".tmp") -> Iterator[Path]:
    """A temporary path beside ``target``; renamed onto it when the block ends without an error.

    Parameters
    ----------
    target : path-like
        The output file; its folder is created if need be.
    suffix : str
        The temporary name's ending. Writers that append their own extension need it: ``np.savez``
        adds ``.npz`` to a name without it, so pass ``suffix=".npz"``.

    Yields
    ------
    Path
        A new, empty file in ``target``'s folder (unique name ``.<target name>.<random><suffix>``),
        mode ``0o666 & ~umask``. Write it completely inside the block.

    Examples
    --------
    >>> with atomic_output("results/x.json") as tmp:  # doctest: +SKIP
    ...     tmp.write_text("{}")
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=suffix, dir=target.parent)
    tmp = Path(name)
    try:
        try:
            os.fchmod(fd, 0o666 & ~process_umask())
        finally:
            os.close(fd)
        yield tmp
        os.replace(tmp, target)
    finally:
        # after a successful replace the temporary name is gone; after a failure it is removed
        tmp.unlink(missing_ok=True)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through :func:`atomic_output`."""
    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
