"""The comparison page of one vehicle's flights (issue 13, item 5; PX4 Flight Review's oldest
open request): the parameters that differ between the flights, and altitude, speed and attitude
of every flight overlaid on one time-from-takeoff axis.

Takeoff (:func:`takeoff_t_ns`) is the first sample of the preprocessed state from which the
vehicle stays more than :data:`TAKEOFF_HEIGHT_M` above its starting height, or faster than
:data:`TAKEOFF_SPEED_MPS` horizontally, for :data:`TAKEOFF_HOLD_S`; a flight that does
neither is aligned at its first sample. The page says so above the plots.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd
import plotly.graph_objects as go

from ..io import schema
from ..io.base import last_params
from ..io.parquet import read_table, read_table_meta
from . import plots
from .flight_summary import utc_date
from .pages import count_text, figure_divs, render, write_page

#: takeoff: this far above the start height [m] ...
TAKEOFF_HEIGHT_M = 2.0
#: ... or this fast horizontally [m/s], whichever comes first
TAKEOFF_SPEED_MPS = 2.0
#: ... or, for a ground vehicle, its first motion: faster than this [m/s] (the Husky drives at ~1)
GROUND_MOTION_MPS = 0.5
#: ... held for this long [s]
TAKEOFF_HOLD_S = 1.0
#: display points per flight and panel (min/max decimation; the page holds many flights)
POINTS_PER_TRACE = 1500

#: flight colours of the overlays, in page order
FLIGHT_COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
                  "#bcbd22", "#17becf")

TAKEOFF_RULE = (f"t = 0 is each flight's takeoff: the first sample of its preprocessed state from which it "
                f"stays more than {TAKEOFF_HEIGHT_M:g} m above its starting height, or faster than "
                f"{TAKEOFF_SPEED_MPS:g} m/s horizontally, for {TAKEOFF_HOLD_S:g} s (a flight that does "
                f"neither starts at its first sample; a ground vehicle at its first motion, faster than "
                f"{GROUND_MOTION_MPS:g} m/s)")


def takeoff_t_ns(state: pd.DataFrame, ground: bool = False) -> tuple[int | None, str]:
    """Takeoff time of a state table and how it was found (``"height"``, ``"speed"`` or
    ``"first sample"``); ``(None, "no state")`` for an empty table.

    Height above start is ``d₀ − d`` with ``d₀`` the first finite ``pos_d_m``; horizontal speed
    ``√(v_n² + v_e²)``; a condition counts from sample k when it holds at samples
    k … k + n − 1, n = :data:`TAKEOFF_HOLD_S` / median step. A ``ground`` vehicle (the state's
    ``ground_vehicle``) starts at its first motion: speed alone, its GPS height is noise."""
    if state is None or not len(state):
        return None, "no state"
    t = state["t_ns"].to_numpy(np.int64)
    d = state["pos_d_m"].to_numpy(np.float64)
    # a condition counts from a sample when it holds for the next TAKEOFF_HOLD_S (noisy GPS
    # heights and differentiated speeds cross a threshold for a sample or two on the ground)
    n_hold = 1
    if len(t) > 1:
        dt = np.median(np.diff(t)) * 1e-9
        n_hold = max(1, int(round(TAKEOFF_HOLD_S / dt))) if dt > 0 else 1

    def held(c: np.ndarray) -> np.ndarray:
        run = np.convolve(c.astype(np.int64), np.ones(n_hold, np.int64))[n_hold - 1:]
        return run == n_hold if len(c) >= n_hold else np.zeros(len(c), bool)

    hit = np.zeros(len(t), bool)
    why = np.full(len(t), "", object)
    fin = np.isfinite(d)
    if fin.any() and not ground:   # a rover's GPS height swings tens of metres: only its motion counts
        up = held((d[fin][0] - d) > TAKEOFF_HEIGHT_M)
        hit |= up
        why[up] = "height"
    v = np.hypot(state["vel_n_mps"].to_numpy(np.float64), state["vel_e_mps"].to_numpy(np.float64))
    fast = held(v > (GROUND_MOTION_MPS if ground else TAKEOFF_SPEED_MPS))
    why[fast & ~hit] = "speed"
    hit |= fast
    if hit.any():
        k = int(np.argmax(hit))
        return int(t[k]), str(why[k])
    return int(t[0]), "first sample"


def differing_params(per_flight: Mapping[str, Mapping[str, float]]) -> tuple[list[str], list[list[str]]]:
    """The parameters whose last value differs between flights (or that some flights lack), as
    ``(headers, rows)``: name, then one value per flight (``–`` where it is not logged). Values
    are compared as logged, bit for bit (NaN equals NaN), and written so that values which
    differ always read differently (:func:`pipeline.report.plots.param_texts`: integers as
    integers, floats to their shortest round-trip text)."""
    flights = list(per_flight)
    headers = ["parameter", *flights]
    names = sorted(set().union(*(set(p) for p in per_flight.values()))) if per_flight else []
    rows = []
    for n in names:
        vals = [per_flight[f].get(n) for f in flights]
        keys = {("–",) if v is None else ("nan",) if v != v else ("v", float(v)) for v in vals}
        if len(keys) > 1:
            present = [v for v in vals if v is not None]
            texts = iter(plots.param_texts(present))
            rows.append([n, *("–" if v is None else next(texts) for v in vals)])
    return headers, rows


#: the overlays open at this many seconds before takeoff: a flight's minutes on the ground before
#: it (phoenix-mission1: 295 s) would squeeze the flights into a corner; autoscale shows them
PRE_TAKEOFF_S = 30.0


def overlay_range(tracks: Mapping[str, pd.DataFrame], cols: Sequence[str]) -> list[float] | None:
    """The overlays' opening time range: from :data:`PRE_TAKEOFF_S` before takeoff (or the
    earliest sample, if later) to the last sample of any flight with a value in ``cols``."""
    lo, hi = np.inf, -np.inf
    for d in tracks.values():
        if d is None or not len(d):
            continue
        ok = d[[c for c in cols if c in d]].notna().any(axis=1).to_numpy()
        if ok.any():
            t = d["t_s"].to_numpy(np.float64)[ok]
            lo, hi = min(lo, float(t.min())), max(hi, float(t.max()))
    return [max(lo, -PRE_TAKEOFF_S), hi] if np.isfinite(lo) and hi > max(lo, -PRE_TAKEOFF_S) else None


def _overlay(tracks: Mapping[str, pd.DataFrame], col: str, title: str, ylabel: str,
             x_range: list[float] | None = None, *, wraps: bool = False) -> go.Figure | None:
    fig = go.Figure()
    for i, (f, d) in enumerate(tracks.items()):
        if d is None or col not in d or not d[col].notna().any():
            continue
        dd = plots.decimate(d[["t_s", col]], POINTS_PER_TRACE, cols=[col], breaks=True)
        if wraps:     # an angle through ±180° (an aerobatic roll): a hole, not a stroke
            dd = plots.break_wraps(dd, col)
        # one colour per flight, by its place on the page (the same on every panel)
        fig.add_trace(go.Scatter(x=dd["t_s"], y=dd[col], mode="lines", name=f,
                                 line=dict(color=FLIGHT_COLOURS[i % len(FLIGHT_COLOURS)])))
    if not fig.data:
        return None
    fig.update_xaxes(title="t from takeoff [s]", **({"range": x_range} if x_range else {}))
    fig.update_yaxes(title=ylabel)
    return plots.layout(fig, title, height=320)


def build_compare_page(vehicle: str, flights: Sequence[str], out_html: str | os.PathLike, *,
                       metas: Sequence[str | os.PathLike], states: Sequence[str | os.PathLike],
                       params: Sequence[str | os.PathLike], template: str | os.PathLike,
                       plotly_js: str, index_href: str = "../../index.html",
                       flight_links: Mapping[str, str] | None = None) -> pd.DataFrame:
    """Render the comparison page of ``vehicle``'s ``flights``; returns the per-flight takeoff
    table (flight, date, takeoff [s], found by, status).

    ``metas``, ``states``, ``params``: per flight (in ``flights`` order) the ingest
    ``meta.json``, the preprocessed ``state`` table and the ingest ``params`` stream. A failed
    flight keeps its row with the reason and adds no trace."""
    tracks: dict[str, pd.DataFrame] = {}
    per_flight: dict[str, dict[str, float]] = {}
    rows = []
    for f, m, s, p in zip(flights, metas, states, params):
        meta = json.loads(Path(m).read_text()) if Path(m).exists() else {"status": "failed", "error": "no meta.json"}
        row = {"flight": f, "date": utc_date(meta) or "–", "takeoff [s]": "–", "takeoff found by": "–",
               "status": meta.get("status") or "?"}
        if meta.get("status") == "failed":
            row["status"] = f"failed: {meta.get('error') or 'unknown reason'}"
            rows.append(row)
            continue
        if Path(p).exists():
            logged = last_params(read_table(p, schema.columns("params")))
            if logged:   # a flight without a parameter dump has nothing to compare
                per_flight[f] = logged
        st = read_table(s) if Path(s).exists() else None
        if st is None or not len(st):
            err = read_table_meta(s).get("error") if Path(s).exists() else "no state table"
            row["status"] = f"no state ({err or 'empty'})"
            rows.append(row)
            continue
        t0, how = takeoff_t_ns(st, bool((read_table_meta(s).get("preprocess") or {}).get("ground_vehicle")))
        row["takeoff [s]"], row["takeoff found by"] = f"{t0 * 1e-9:.1f}", how
        d0 = st["pos_d_m"].dropna()
        tracks[f] = pd.DataFrame({
            "t_s": (st["t_ns"].to_numpy(np.int64) - t0) * 1e-9,
            "alt_m": (d0.iloc[0] if len(d0) else np.nan) - st["pos_d_m"].to_numpy(np.float64),
            "speed_mps": np.hypot(st["vel_n_mps"], st["vel_e_mps"]).to_numpy(np.float64),
            "roll_deg": np.degrees(st["roll_rad"].to_numpy(np.float64)),
            "pitch_deg": np.degrees(st["pitch_rad"].to_numpy(np.float64)),
        })
        rows.append(row)
    # one opening range for every panel (their time axes are linked)
    xr = overlay_range(tracks, ["alt_m", "speed_mps", "roll_deg", "pitch_deg"])
    figs = [("Altitude above start", _overlay(tracks, "alt_m", "Altitude above start", "altitude [m, up]", xr)),
            ("Horizontal speed", _overlay(tracks, "speed_mps", "Horizontal speed", "speed [m/s]", xr)),
            ("Roll", _overlay(tracks, "roll_deg", "Roll (state: body FRD, mount-corrected)", "roll [°]", xr, wraps=True)),
            ("Pitch", _overlay(tracks, "pitch_deg", "Pitch (state: body FRD, mount-corrected)", "pitch [°]", xr))]
    if len(per_flight) >= 2:
        p_headers, p_rows = differing_params(per_flight)
        p_note = (f"{len(p_rows)} of {count_text(len(set().union(*(set(v) for v in per_flight.values()))), 'parameter')} "
                  f"differ between the {len(per_flight)} flights that log parameters") if p_rows else None
    else:
        p_headers, p_rows = [], []
        p_note = None
    # a value changed between flights is what an engineer looks for; a parameter that only
    # some flights log (another firmware version, another feature enabled) comes second
    p_changed = [r for r in p_rows if "–" not in r[1:]]
    p_partial = [r for r in p_rows if "–" in r[1:]]
    p_absent = ("fewer than two of these flights log parameters" if len(per_flight) < 2
                else "every logged parameter has the same value in every flight")
    links = flight_links or {}
    table = pd.DataFrame(rows)
    page = render(template, vehicle=vehicle, flights=rows, links=links, plots=figure_divs(figs),
                  linked=[f"plot-{i}" for i, (_, f) in enumerate(figs) if f is not None],
                  takeoff_rule=TAKEOFF_RULE, param_headers=p_headers, param_rows=p_rows,
                  param_changed=p_changed, param_partial=p_partial,
                  param_note=p_note, param_absent=p_absent, pre_takeoff_s=f"{PRE_TAKEOFF_S:g}", plotly_js=plotly_js, index_href=index_href)
    write_page(page, out_html)
    return table
