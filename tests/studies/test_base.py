"""Shared study plumbing (pipeline/studies/base.py)."""

from __future__ import annotations

import os

import pytest

from pipeline.studies.base import run_calls


def _power(base: int, exp: int) -> tuple[int, int]:
    return os.getpid(), base ** exp


def _fail_on_one(x: int) -> int:
    if x == 1:
        raise ValueError(f"call {x} failed")
    return x


def test_run_calls_yields_in_the_planned_order_here_or_on_worker_processes_and_a_worker_error_reaches_the_caller():
    calls = [{"base": b, "exp": 3} for b in range(7)]
    here = list(run_calls(_power, calls, 1))
    assert [v for _, v in here] == [b ** 3 for b in range(7)] and {p for p, _ in here} == {os.getpid()}
    cost = {i: float(i % 3) for i in range(7)}                  # submission order differs from the plan
    pooled = list(run_calls(_power, calls, 2, cost=cost.__getitem__))
    assert [v for _, v in pooled] == [v for _, v in here]
    assert os.getpid() not in {p for p, _ in pooled}
    got = []
    with pytest.raises(ValueError, match="call 1 failed"):
        got.extend(run_calls(_fail_on_one, [{"x": 0}, {"x": 1}, {"x": 2}], 2))
    assert got == [0]


def test_a_study_tables_flags_read_yes_or_no_and_a_missing_number_a_dash():
    import numpy as np
    import pandas as pd

    from pipeline.studies.base import md_table

    df = pd.DataFrame({"maneuver": ["tHat", "upL"], "better": [True, False], "rms_m": [33.3, np.nan]})
    assert md_table(df).splitlines()[2:] == ["| tHat | yes | 33.30 |", "| upL | no | – |"]
