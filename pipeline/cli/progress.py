"""Progress reporting for long work: a tqdm bar on a terminal, silent otherwise."""

from __future__ import annotations

import sys
from contextlib import contextmanager


@contextmanager
def progress_bar(desc: str, total: int, unit: str = "B", enable: bool | None = None):
    """Yield a ``progress(done, total)`` callback driving a tqdm bar (stderr).

    Enabled by default only when stderr is a terminal, so logs and CI stay clean.
    """
    if enable is None:
        enable = sys.stderr.isatty()
    if not enable:
        yield None
        return
    from tqdm import tqdm

    bar = tqdm(total=total, desc=desc, unit=unit, unit_scale=True, leave=False, file=sys.stderr)
    state = {"last": 0}

    def cb(done: int, tot: int) -> None:
        if tot != bar.total:
            bar.total = tot
        bar.update(max(0, done - state["last"]))
        state["last"] = done

    try:
        yield cb
    finally:
        bar.close()
