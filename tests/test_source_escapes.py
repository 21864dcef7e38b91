"""Every source file compiles without an invalid escape sequence: a LaTeX docstring written in a
plain string loses ``\\t``/``\\b``/``\\f`` of ``\\tau``/``\\beta``/``\\frac`` to control
characters, and Python 3.12 turns the others into SyntaxWarnings (errors under ``-W error``)."""

from __future__ import annotations

import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_no_source_file_has_an_invalid_escape_sequence():
    bad = []
    for folder in ("pipeline", "tests", "benchmarks", "rules"):
        for p in sorted((ROOT / folder).rglob("*.py")):
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                compile(p.read_text(encoding="utf-8"), str(p), "exec")
            bad += [f"{p.relative_to(ROOT)}:{w.lineno}: {w.message}" for w in caught]
    assert not bad, bad
