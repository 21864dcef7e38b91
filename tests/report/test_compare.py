"""The per-vehicle comparison page (issue 13, item 5): differing parameters, overlays on a
time-from-takeoff axis, and the index's date, vehicle and skipped-row columns."""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.io.base import last_params
from pipeline.report import compare

ROOT = Path(__file__).resolve().parents[2]


def _state(n: int, climb_at: int, rate_hz: float = 10.0) -> pd.DataFrame:
    from pipeline.io import schema

    t = (np.arange(n) * 1e9 / rate_hz).astype(np.int64)
    d = np.where(np.arange(n) < climb_at, -1.0, -1.0 - 0.5 * (np.arange(n) - climb_at))
    df = schema.empty("state").reindex(range(n))
    df["t_ns"] = t
    df["pos_n_m"], df["pos_e_m"], df["pos_d_m"] = 0.0, 0.0, d
    df["vel_n_mps"], df["vel_e_mps"] = 0.0, 0.0
    df["roll_rad"], df["pitch_rad"] = 0.0, 0.1
    df["gap"] = False
    return df


def test_takeoff_is_the_first_sample_above_the_height_or_the_speed_threshold():
    st = _state(100, climb_at=30)
    t0, how = compare.takeoff_t_ns(st)
    # d0 - d > 2 m first at 0.5 (k - 30) > 2, k = 35
    assert (t0, how) == (35 * 10**8, "height")
    st.loc[20:, "vel_e_mps"] = 2.5
    st.loc[5, "vel_e_mps"] = 9.0              # one noisy sample on the ground: not a takeoff
    assert compare.takeoff_t_ns(st) == (20 * 10**8, "speed")
    still = _state(10, climb_at=99)
    assert compare.takeoff_t_ns(still) == (0, "first sample")
    assert compare.takeoff_t_ns(still.iloc[:0]) == (None, "no state")


def test_only_parameters_that_differ_or_are_missing_somewhere_are_listed():
    per = {"a": {"P1": 1.0, "P2": 2.0, "P3": 0.1, "P4": 7.0}, "b": {"P1": 1.0, "P2": 3.0, "P4": 7.0},
           "c": {"P1": 1.0, "P2": 2.0, "P4": 7.0}}
    headers, rows = compare.differing_params(per)
    assert headers == ["parameter", "a", "b", "c"]
    assert rows == [["P2", "2", "3", "2"], ["P3", "0.1", "–", "–"]]
    p = pd.DataFrame({"t_ns": [2, 1, 3], "name": ["X", "X", "Y"], "value": [5.0, 4.0, 1.0]})
    assert last_params(p) == {"X": 5.0, "Y": 1.0}


def test_the_comparison_page_and_the_index_columns(tmp_path):
    from pipeline.io import schema
    from pipeline.io.parquet import write_table
    from pipeline.report.index import build_index

    flights, metas, states, params = ["f1", "f2", "bad"], [], [], []
    for f, climb, vals in (("f1", 30, {"ATC_RAT_RLL_P": 0.135, "BATT_CAPACITY": 5000.0}),
                           ("f2", 50, {"ATC_RAT_RLL_P": 0.150, "BATT_CAPACITY": 5000.0, "AVOID_MARGIN": 2.0}),
                           ("bad", 0, {})):
        d = tmp_path / f
        d.mkdir()
        failed = f == "bad"
        meta = schema.new_meta(flight_id=f, t0_utc_ns=None if failed else 1432235497988949113,
                               status="failed" if failed else "ok", error="bad magic" if failed else None)
        (d / "meta.json").write_text(json.dumps(meta))
        write_table(_state(0 if failed else 120, climb), d / "state.parquet", schema.STATE, name="state")
        p = pd.DataFrame({"t_ns": np.zeros(len(vals), np.int64), "instance": np.zeros(len(vals), np.uint8),
                          "src": "PARM", "name": list(vals), "value": list(vals.values())})
        write_table(schema.conform("params", p) if len(p) else schema.empty("params"), d / "params.parquet",
                    schema.columns("params"), name="params")
        metas.append(d / "meta.json"), states.append(d / "state.parquet"), params.append(d / "params.parquet")
    page = tmp_path / "report" / "compare" / "copter.html"
    table = compare.build_compare_page("copter", flights, page, metas=metas, states=states, params=params,
                                       template=ROOT / "reports" / "templates" / "compare.html.j2",
                                       plotly_js="../assets/plotly.min.js")
    assert list(table["takeoff [s]"]) == ["3.5", "5.5", "–"]
    text = html.unescape(page.read_text())
    assert "<td>ATC_RAT_RLL_P</td><td>0.135</td><td>0.15</td>" in text and "BATT_CAPACITY" not in text
    assert "2 of 3 parameters differ between the 2 flights" in text
    # a changed value first, a parameter only one flight logs after it; the plots above both
    changed, partial = text.index("<h3>Different values</h3>"), text.index("<h3>Logged by only some")
    assert text.index("<h2>Overlays</h2>") < changed < text.index("<td>ATC_RAT_RLL_P</td>") < partial
    assert partial < text.index("<td>AVOID_MARGIN</td><td>–</td><td>2</td>")
    assert compare.TAKEOFF_RULE in text and "failed: bad magic" in text
    for title in ("Altitude above start", "Horizontal speed", "Roll (state", "Pitch (state"):
        assert title in text, title
    assert "t from takeoff [s]" in text

    idx = tmp_path / "index.html"
    build_index(flights, metas, idx, links={f: f"report/flights/{f}.html" for f in flights},
                vehicles={f: "copter" for f in flights}, compare={"copter": "report/compare/copter.html"},
                skipped={"lost": "logs/lost.bin not found"})
    t = idx.read_text()
    assert "<th>date (UTC)</th><th>vehicle</th>" in t
    assert '<td>2015-05-21</td><td><a href="report/compare/copter.html">copter</a></td>' in t
    assert "Skipped manifest rows" in t and "<td>lost</td><td class=\"reason\">logs/lost.bin not found</td>" in t
    assert "1 manifest row skipped" in t
    # the vehicles list says how many flights each comparison holds
    assert f'<a href="report/compare/copter.html">copter</a> <span class="absent">({len(flights)} flights)</span>' in t


def test_a_parameter_is_listed_whenever_its_values_differ_and_integers_read_as_integers():
    per = {"a": {"SEED": 20261120.0, "GAIN": 1.0, "SAME": 0.25}, "b": {"SEED": 20261121.0, "GAIN": 1.0000000001,
                                                                    "SAME": 0.25}}
    headers, rows = compare.differing_params(per)
    # 7 significant digits read both seeds as 2.026112e+07 and both gains as 1: both hidden
    assert rows == [["GAIN", "1", "1.0000000001"], ["SEED", "20261120", "20261121"]]
    # a float32 value and the float64 whose repr is the float32's short text stay apart
    x32 = float(np.float32(0.1))
    assert compare.differing_params({"a": {"P": 0.1}, "b": {"P": x32}})[1] == [["P", "0.1", repr(x32)]]


def test_the_parameters_table_writes_integers_as_integers_and_floats_to_their_shortest_exact_text():
    from pipeline.report import plots

    p = pd.DataFrame({"t_ns": [0, 0, 0, 0], "name": ["SEED", "ATC_RAT_RLL_P", "TINY", "THIRD"],
                      "value": [20261120.0, float(np.float32(0.135)), 1.25e-7, 1 / 3]})
    values = {r[0]: r[1] for r in plots.params_table(p)[1]}
    assert values == {"SEED": "20261120", "ATC_RAT_RLL_P": "0.135", "TINY": "1.25e-07",
                      "THIRD": "0.3333333333333333"}
    for text, v in zip(map(values.get, p["name"]), p["value"]):
        assert float(text) == v or float(np.float32(text)) == v       # every text reads back exactly


def test_a_ground_vehicle_starts_at_its_first_motion_not_at_a_gps_height_swing():
    # a rover whose GPS height wanders 6 m up at 2 s and drives off at 6 s
    n, dt = 250, 0.04
    t = (np.arange(n) * dt * 1e9).astype(np.int64)
    st = pd.DataFrame({"t_ns": t, "pos_d_m": np.where(np.arange(n) >= 50, -6.0, 0.0),
                       "vel_n_mps": np.where(np.arange(n) >= 150, 1.0, 0.0), "vel_e_mps": 0.0})
    assert compare.takeoff_t_ns(st) == (t[50], "height")
    assert compare.takeoff_t_ns(st, ground=True) == (t[150], "speed")


def test_the_overlays_open_30_s_before_takeoff_however_long_a_flight_sat_on_the_ground():
    long_wait = pd.DataFrame({"t_s": np.arange(-295.0, 500.0, 1.0), "alt_m": 1.0, "speed_mps": np.nan,
                              "roll_deg": 0.0, "pitch_deg": 0.0})
    short = pd.DataFrame({"t_s": np.arange(-10.0, 120.0, 1.0), "alt_m": 1.0, "speed_mps": 1.0,
                          "roll_deg": 0.0, "pitch_deg": 0.0})
    cols = ["alt_m", "speed_mps", "roll_deg", "pitch_deg"]
    assert compare.overlay_range({"a": long_wait, "b": short}, cols) == [-30.0, 499.0]
    assert compare.overlay_range({"b": short}, cols) == [-10.0, 119.0]     # nothing earlier to hide
    assert compare.overlay_range({"x": None}, cols) is None
