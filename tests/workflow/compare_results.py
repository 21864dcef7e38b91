"""Compare two ``results/`` trees of the main job as frames (before/after a refactoring).

Usage::

    python tests/workflow/compare_results.py BEFORE_RESULTS AFTER_RESULTS [--expect PATTERN=COLS ...]

Every Parquet file of BEFORE is matched with its counterpart in AFTER (paths that a release
renamed on purpose are mapped: ``classify/<flight>.parquet`` -> ``classify/<model_set>/<flight>.parquet``)
and compared with ``pandas.testing.assert_frame_equal`` (exact: values, dtypes, column order).
Files that differ are listed with the columns that differ; ``--expect 'classify/*=ll_background'``
declares a difference made on purpose (a glob over the AFTER path, and the columns allowed to
differ, comma-separated; ``*`` = any). JSON files (``meta.json``) are not compared: they carry
timings, paths and versions.

Prints ``RESULT compare_files_equal <n>``, ``RESULT compare_files_differ <n>`` (unexpected
differences), ``RESULT compare_files_missing <n>`` and exits 1 when any file differs unexpectedly
or is missing.
"""

from __future__ import annotations

import argparse
import fnmatch
import sys
from pathlib import Path

import pandas as pd


def counterpart(rel: Path, after: Path) -> Path | None:
    """The AFTER file for a BEFORE path (identity, or the renamed location)."""
    if (after / rel).exists():
        return after / rel
    if rel.parts[0] == "classify" and len(rel.parts) == 2:
        hits = sorted(after.glob(f"classify/*/{rel.name}"))
        if len(hits) == 1:
            return hits[0]
    return None


def differing_columns(a: pd.DataFrame, b: pd.DataFrame) -> list[str]:
    cols = []
    for c in sorted(set(a.columns) | set(b.columns)):
        if c not in a.columns or c not in b.columns:
            cols.append(c)
            continue
        try:
            pd.testing.assert_series_equal(a[c].reset_index(drop=True), b[c].reset_index(drop=True))
        except AssertionError:
            cols.append(c)
    return cols


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    ap.add_argument("--expect", action="append", default=[], metavar="GLOB=COLS",
                    help="differences made on purpose: AFTER-path glob = columns (comma-separated, * = any)")
    args = ap.parse_args(argv)
    expect = []
    for e in args.expect:
        glob, _, cols = e.partition("=")
        expect.append((glob, set(cols.split(",")) if cols else {"*"}))
    equal = differ = missing = expected = 0
    matched: set[Path] = set()
    for p in sorted(args.before.rglob("*.parquet")):
        rel = p.relative_to(args.before)
        q = counterpart(rel, args.after)
        if q is None:
            print(f"MISSING  {rel}")
            missing += 1
            continue
        matched.add(q)
        a, b = pd.read_parquet(p), pd.read_parquet(q)
        try:
            pd.testing.assert_frame_equal(a, b)
            equal += 1
            continue
        except AssertionError:
            pass
        cols = differing_columns(a, b) if len(a) == len(b) else ["<rows>"]
        qrel = q.relative_to(args.after).as_posix()
        allowed = [c for g, c in expect if fnmatch.fnmatch(qrel, g)]
        if allowed and all(any("*" in s or col in s for s in allowed) for col in cols):
            print(f"EXPECTED {rel} -> {qrel}: {', '.join(cols)}")
            expected += 1
        else:
            print(f"DIFFERS  {rel} -> {qrel}: {', '.join(cols) or 'dtypes/index'}")
            differ += 1
    new = sorted(q.relative_to(args.after) for q in args.after.rglob("*.parquet") if q not in matched)
    for n in new[:20]:
        print(f"NEW      {n}")
    print(f"RESULT compare_files_equal {equal}")
    print(f"RESULT compare_files_expected_differences {expected}")
    print(f"RESULT compare_files_differ {differ}")
    print(f"RESULT compare_files_missing {missing}")
    print(f"RESULT compare_files_new {len(new)}")
    return 1 if differ or missing else 0


if __name__ == "__main__":
    sys.exit(main())
