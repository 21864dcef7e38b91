"""Every reader's summary of its fixture logs equals the golden file (pyulog style): a reader
change shows as a readable diff, without ../shared. Regenerate after an intended change with
``PYTHONPATH=. .venv/bin/python tests/regen_golden.py`` and review the diff of
tests/data/golden/."""

from __future__ import annotations

import json

import pandas as pd
import pytest

import regen_golden as rg


@pytest.fixture(scope="module")
def fixture_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("golden")


@pytest.mark.parametrize("name", list(rg.FIXTURES))
def test_reader_summary_equals_its_golden_file(fixture_dir, name):
    p = rg.golden_path(name)
    assert p.exists(), f"no golden file {p}: run tests/regen_golden.py {name}"
    current = rg.build(name, fixture_dir)
    changes = rg.diff(json.loads(p.read_text()), current)
    assert not changes, (f"{name}: the reader's summary differs from {p.name} "
                         f"(if intended, run tests/regen_golden.py {name}):\n  " + "\n  ".join(changes[:60]))


def test_every_golden_file_belongs_to_a_fixture():
    assert sorted(p.stem for p in rg.GOLDEN.glob("*.json")) == sorted(rg.FIXTURES)


def test_the_diff_is_readable_and_ignores_last_digit_rounding():
    g = {"streams": {"imu": {"rows": 10, "stats": {"acc_x_mps2": {"mean": 1.23456}}}}}
    c = {"streams": {"imu": {"rows": 11, "stats": {"acc_x_mps2": {"mean": 1.234561}}}, "gps": {"rows": 1}}}
    assert rg.diff(g, c) == ["streams/gps: (new) -> {\"rows\": 1}", "streams/imu/rows: 10 -> 11"]
    assert rg.summarise_frame(pd.DataFrame({"t_ns": [5, 7], "x": [1 / 3, None]})) == {
        "rows": 2, "columns": ["t_ns", "x"], "t_ns_first": 5, "t_ns_last": 7,
        "stats": {"t_ns": {"n": 2, "mean": 6.0, "min": 5.0, "max": 7.0},
                  "x": {"n": 1, "mean": 0.333333, "min": 0.333333, "max": 0.333333}}}
