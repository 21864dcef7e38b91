"""Atomic outputs (pipeline/io/atomic.py): renamed into place whole, removed on failure, and with
the mode an ordinary write would have (umask), not mkstemp's owner-only 0600."""

from __future__ import annotations

import os
import stat

import numpy as np
import pandas as pd
import pytest

from pipeline.io import atomic
from pipeline.io.atomic import atomic_output, write_text_atomic
from pipeline.io.parquet import write_json, write_table


@pytest.fixture
def umask():
    """Set the process umask for one test (and the cached reading of it); restore both after."""
    old = os.umask(0o022)
    os.umask(old)

    def set_(mask: int) -> None:
        os.umask(mask)
        atomic.process_umask.cache_clear()

    yield set_
    os.umask(old)
    atomic.process_umask.cache_clear()


def _mode(p) -> int:
    return stat.S_IMODE(os.stat(p).st_mode)


def test_the_umask_is_read_as_the_process_has_it(umask):
    umask(0o027)
    assert atomic.process_umask() == 0o027
    umask(0o002)
    assert atomic.process_umask() == 0o002


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o027, 0o640), (0o002, 0o664)])
def test_outputs_get_the_mode_an_ordinary_write_would_give(tmp_path, umask, mask, mode):
    umask(mask)
    write_table(pd.DataFrame({"t_ns": np.arange(3, dtype="int64")}), tmp_path / "a.parquet", name="state")
    write_json({"k": 1}, tmp_path / "a.json")
    write_text_atomic(tmp_path / "a.html", "<p>é</p>")
    with atomic_output(tmp_path / "params.npz", suffix=".npz") as tmp:
        np.savez(tmp, x=np.zeros(2))
    (tmp_path / "plain.txt").write_text("x")  # what open() gives under this umask
    assert _mode(tmp_path / "plain.txt") == mode
    for name in ("a.parquet", "a.json", "a.html", "params.npz"):
        assert _mode(tmp_path / name) == mode, name
    assert (tmp_path / "a.html").read_text(encoding="utf-8") == "<p>é</p>"
    assert np.load(tmp_path / "params.npz")["x"].shape == (2,)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.html", "a.json", "a.parquet", "params.npz", "plain.txt"]


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "sub" / "out.txt"
    write_text_atomic(target, "old")
    with pytest.raises(RuntimeError):
        with atomic_output(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed")
    assert target.read_text() == "old"
    assert [p.name for p in target.parent.iterdir()] == ["out.txt"]


def test_the_temporary_lies_beside_the_target_with_the_suffix_asked_for(tmp_path):
    with atomic_output(tmp_path / "new" / "params.npz", suffix=".npz") as tmp:
        assert tmp.parent == tmp_path / "new" and tmp.name.startswith(".params.npz.") and tmp.suffix == ".npz"
        assert tmp.exists() and tmp.stat().st_size == 0
        np.savez(tmp, a=np.ones(1))
    assert not tmp.exists() and (tmp_path / "new" / "params.npz").exists()
