"""Segments: maneuvers/demonstrations as time intervals (``schema.SEGMENTS``).

Seed 004 §6 step 1 segments demonstrations by hand from plots and video; we take them from,
in order of preference (``preprocess.segments.source: auto``, the first that gives any):

1. ``labels``: the ``labels`` stream (FlightCoach ``mans``, simulation truth), one segment per
   row, unchanged; a row without both times or ending before it starts (a hand-edited labels
   side-car) is dropped and counted in the flight's notes, never passed on;
2. ``truth``: runs of constant ``truth.label`` (simulated flights without a ``labels`` stream),
   each lasting until the next label change (the last until its final sample);
3. ``windows``: time windows listed for the flight in the dataset config
   (``preprocess.segments.windows.<flight_id>: [{start_s, end_s, label}]``, s since log start);
4. ``modes``: one segment per run of constant flight mode in the ``mode`` stream, labelled
   ``mode:<name>``, lasting until the next mode change (the last until the end of the log),
   clipped to the flight's end (``t_end_ns``).

``source`` may also name one of these, or ``all`` (their union).
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import pandas as pd

SOURCES = ("auto", "labels", "truth", "windows", "modes", "all")


def empty_segments() -> pd.DataFrame:
    return pd.DataFrame({"segment_id": np.empty(0, np.int64), "t_start_ns": np.empty(0, np.int64),
                         "t_end_ns": np.empty(0, np.int64), "label": pd.array([], dtype="string")})


def _frame(starts, ends, labels) -> pd.DataFrame:
    return pd.DataFrame({"t_start_ns": np.asarray(starts, dtype=np.int64),
                         "t_end_ns": np.asarray(ends, dtype=np.int64),
                         "label": pd.array([str(x) for x in labels], dtype="string")})


def from_labels(labels: pd.DataFrame, notes: list[str] | None = None) -> pd.DataFrame:
    """One segment per valid ``labels`` row.

    A row whose ``t_start_ns`` or ``t_end_ns`` is missing, or whose ``t_end_ns`` lies before its
    ``t_start_ns``, is dropped; the count and the first such row go to ``notes`` (a downstream
    maneuver slice of a negative interval would be silently empty). Without ``notes`` such a
    row is a ``ValueError`` naming it, never a silent drop."""
    if labels is None or not len(labels):
        return _frame([], [], [])
    t0 = pd.to_numeric(labels["t_start_ns"], errors="coerce")
    t1 = pd.to_numeric(labels["t_end_ns"], errors="coerce")
    ok = (t0.notna() & t1.notna() & (t1 >= t0)).to_numpy(dtype=bool)
    lab = labels["label"].astype("string").fillna("")
    if not ok.all():
        i = int(np.flatnonzero(~ok)[0])
        msg = (f"labels: {int((~ok).sum())} of {len(ok)} rows dropped: missing time or t_end_ns before "
               f"t_start_ns (first: row {i}, label {lab.iloc[i]!r}, {t0.iloc[i]} .. {t1.iloc[i]})")
        if notes is None:  # a caller with nowhere to count the drop gets the error instead
            raise ValueError(msg)
        notes.append(msg)
    return _frame(t0[ok].astype(np.int64), t1[ok].astype(np.int64), lab[ok].tolist())


def from_windows(windows: Sequence[Mapping] | None, flight_id: str | None = None) -> pd.DataFrame:
    """Segments from ``[{start_s, end_s, label}]`` (seconds since log start)."""
    if not windows:
        return _frame([], [], [])
    s, e, lab = [], [], []
    for i, w in enumerate(windows):
        try:
            a, b = float(w["start_s"]), float(w["end_s"])
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"preprocess.segments.windows[{flight_id}][{i}]: need numeric start_s and "
                             f"end_s, got {w!r}") from None
        if not b > a:
            raise ValueError(f"preprocess.segments.windows[{flight_id}][{i}]: end_s {b} <= start_s {a}")
        s.append(round(a * 1e9))
        e.append(round(b * 1e9))
        lab.append(w.get("label", f"window{i}"))
    return _frame(s, e, lab)


def _runs(df: pd.DataFrame | None, col: str, prefix: str, t_end_ns: int | None) -> pd.DataFrame:
    """One segment per run of constant ``df[col]`` (rows with a missing value are skipped)."""
    if df is None or not len(df) or col not in df.columns:
        return _frame([], [], [])
    m = df[df[col].notna()].sort_values("t_ns", kind="stable")
    if not len(m):
        return _frame([], [], [])
    t = m["t_ns"].to_numpy(dtype=np.int64)
    v = m[col].astype("string").to_numpy(dtype=object)
    change = np.concatenate([[True], v[1:] != v[:-1]])
    idx = np.flatnonzero(change)
    starts = t[idx]
    if t_end_ns is None:
        ends = np.concatenate([starts[1:], [int(t[-1])]])
    else:
        # the flight ends at t_end_ns: a mode stream logged past it gave segments after the
        # flight (zero-length or outside the state grid); clip them and drop the empty ones
        end = int(t_end_ns)
        ends = np.minimum(np.concatenate([starts[1:], [max(end, int(t[-1]))]]), end)
        keep = starts < ends
        starts, ends, idx = starts[keep], ends[keep], idx[keep]
    return _frame(starts, ends, [f"{prefix}{x}" for x in v[idx]])


def from_modes(mode: pd.DataFrame, t_end_ns: int | None = None) -> pd.DataFrame:
    """One segment per run of constant flight ``mode``, labelled ``mode:<name>``."""
    return _runs(mode, "mode", "mode:", t_end_ns)


def from_truth(truth: pd.DataFrame) -> pd.DataFrame:
    """One segment per run of constant ``truth.label`` (simulation ground truth)."""
    return _runs(truth, "label", "", None)


def build_segments(labels: pd.DataFrame | None, mode: pd.DataFrame | None, *,
                   windows: Sequence[Mapping] | None = None, source: str = "auto",
                   t_end_ns: int | None = None, flight_id: str | None = None,
                   truth: pd.DataFrame | None = None, notes: list[str] | None = None) -> pd.DataFrame:
    """The ``segments`` table: ``segment_id`` (0..n-1 in start order), ``t_start_ns``,
    ``t_end_ns``, ``label``; what was dropped on the way is appended to ``notes`` (without
    ``notes``, an invalid ``labels`` row raises ``ValueError``)."""
    if source not in SOURCES:
        raise ValueError(f"preprocess.segments.source must be one of {SOURCES}, got {source!r}")
    parts = {"labels": lambda: from_labels(labels, notes), "truth": lambda: from_truth(truth),
             "windows": lambda: from_windows(windows, flight_id), "modes": lambda: from_modes(mode, t_end_ns)}
    if source == "auto":
        seg = _frame([], [], [])
        for name in ("labels", "truth", "windows", "modes"):
            seg = parts[name]()
            if len(seg):
                break
    elif source == "all":
        seg = pd.concat([parts[k]() for k in ("labels", "truth", "windows", "modes")], ignore_index=True)
    else:
        seg = parts[source]()
    if not len(seg):
        return empty_segments()
    order = np.lexsort([seg["t_end_ns"].to_numpy(), seg["t_start_ns"].to_numpy()])
    seg = seg.iloc[order].reset_index(drop=True)
    seg.insert(0, "segment_id", np.arange(len(seg), dtype=np.int64))
    return seg
