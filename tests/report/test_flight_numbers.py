"""The flight's headline numbers (duration, distance, speed): one computation for the flight page
and the index, a duration that stale records do not stretch, and a path length that position
noise does not inflate (closed forms: a straight line, a circle, a hover)."""

from __future__ import annotations

import html
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline.io import schema
from pipeline.io.base import FlightLog
from pipeline.io.parquet import write_flightlog, write_table
from pipeline.report import flight_summary as fs

ROOT = Path(__file__).resolve().parents[2]
TEMPLATE = ROOT / "reports" / "templates" / "flight.html.j2"


def _stream(stream: str, t_s, **cols) -> pd.DataFrame:
    t_s = np.asarray(t_s, np.float64)
    df = pd.DataFrame({"t_ns": np.round(t_s * 1e9).astype(np.int64), "instance": np.zeros(len(t_s), np.uint8),
                       "src": "X", **cols})
    for c in schema.STREAMS[stream]:
        if c.name not in df:
            df[c.name] = np.nan
    return df


def _noisy_line(t_s, speed_mps: float, sigma_m: float, seed: int):
    rng = np.random.default_rng(seed)
    return (speed_mps * t_s + sigma_m * rng.standard_normal(len(t_s)), sigma_m * rng.standard_normal(len(t_s)))


def _ekf_failure_like(tmp_path: Path, *, with_state: bool) -> tuple[Path, Path | None]:
    """A log shaped like PX4's ``ekf_failure.ulg``: sensors 0 … 79.6 s, a stale ``control`` record
    at t = −46.2 s (PX4 logs the previous flight's last one), modes MANUAL then POSCTL at 61.5 s,
    a noisy local position flying 2 m/s north; with a preprocessed state (other noise) on request."""
    t = np.arange(0.0, 79.6 + 1e-9, 0.1)
    n, e = _noisy_line(t, 2.0, 0.5, seed=1)
    streams = {
        "imu": _stream("imu", t, acc_z_mps2=np.full(len(t), -9.81)),
        "local_position": _stream("local_position", t, pos_n_m=n, pos_e_m=e, pos_d_m=np.full(len(t), -10.0),
                                  vel_n_mps=np.full(len(t), 2.0), vel_e_mps=np.zeros(len(t)),
                                  vel_d_mps=np.zeros(len(t))),
        "control": _stream("control", np.r_[-46.2, t[::10]], rc_1_us=np.full(len(t[::10]) + 1, 1500.0)),
        "mode": pd.DataFrame({"t_ns": np.array([0, 61_500_000_000], np.int64), "instance": np.zeros(2, np.uint8),
                              "src": "X", "mode": ["MANUAL", "POSCTL"]}),
    }
    log = FlightLog.from_streams(schema.new_meta(flight_id="ekf", status="ok", source_format="px4_ulog",
                                                 reader="ulog", reader_version="1"), streams)
    d = tmp_path / "ingest" / "ekf"
    write_flightlog(log, d)
    state = None
    if with_state:
        ts = t[5:-5]                                    # the grid starts and ends inside the log
        sn, se = _noisy_line(ts, 2.0, 0.3, seed=2)
        st = schema.empty("state").reindex(range(len(ts)))
        st["t_ns"] = np.round(ts * 1e9).astype(np.int64)
        st["pos_n_m"], st["pos_e_m"], st["pos_d_m"] = sn, se, -10.0
        st["vel_n_mps"], st["vel_e_mps"], st["vel_d_mps"] = 2.0 + 0.05 * np.sin(ts), 0.0, 0.0
        st["gap"] = False
        state = tmp_path / "state.parquet"
        write_table(st, state, schema.STATE, name="state", extra={"preprocess": {"n_samples": len(ts), "rate_hz": 10.0}})
    return d, state


def _summary(page: Path) -> dict[str, str]:
    return {k: html.unescape(v) for k, v in re.findall(r"<tr><th>([^<]*)</th><td>([^<]*)</td></tr>", page.read_text())}


# --- item 1: the duration ----------------------------------------------------------------------

def test_a_stale_control_record_before_the_log_does_not_stretch_the_duration_or_the_last_mode_band(tmp_path):
    from pipeline.report.flight import build_flight_report

    d, _ = _ekf_failure_like(tmp_path, with_state=False)
    page = tmp_path / "ekf.html"
    build_flight_report(d, page, template=TEMPLATE, plotly_js="plotly.min.js")
    rows = _summary(page)
    assert rows["duration"] == "79.6 s"                  # not 125.8 s (−46.2 … 79.6)
    assert rows["time span"] == "0.0 to 79.6 s (sensor streams); control reaches back to -46.2 s (stale records, not counted)"
    # the last mode band (POSCTL from 61.5 s) ends where the flight ends: an end time, not a duration
    bands = {(round(float(a), 6), round(float(b), 6))
             for a, b in re.findall(r'"type":"rect","x0":([-0-9.e]+),"x1":([-0-9.e]+)', page.read_text())}
    assert bands == {(0.0, 61.5), (61.5, 79.6)}


def test_the_duration_is_the_preprocessed_states_span_where_there_is_one():
    t = np.arange(0.0, 10.01, 0.5)
    log = FlightLog.from_streams(schema.new_meta(), {"imu": _stream("imu", t), "control": _stream("control", [-46.0, 1.0])})
    assert fs.flight_span(log) == (0.0, 10.0, "sensor streams")
    state = pd.DataFrame({"t_ns": np.array([1, 9], np.int64) * 10**9})
    assert fs.flight_span(log, state) == (1.0, 9.0, "preprocessed state")
    only_control = FlightLog.from_streams(schema.new_meta(), {"control": _stream("control", [-2.0, 3.0])})
    assert fs.flight_span(only_control) == (-2.0, 3.0, "all streams")
    assert fs.flight_span(FlightLog.from_streams(schema.new_meta(), {})) == (None, None, "no samples")


# --- item 2: the distance ----------------------------------------------------------------------

@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_noisy_straight_line_reads_within_three_percent_of_its_length(seed):
    t = np.arange(0.0, 100.0, 0.04)                      # 25 Hz, 100 s at 3 m/s: 300 m
    n, e = _noisy_line(t, 3.0, 1.0, seed)                # σ = 1 m white noise per axis
    raw = np.hypot(np.diff(n), np.diff(e)).sum()
    assert raw > 10 * 300                                # the old sum of raw steps: > 3 km
    length, sigma, band = fs.path_length((t * 1e9).astype(np.int64), n, e)
    assert length == pytest.approx(300.0, rel=0.03)
    assert sigma == pytest.approx(1.0 / np.sqrt(25), rel=0.35)   # σ of 1 s averages: σ / √25
    assert band == pytest.approx(fs.PATH_NOISE_K * sigma)


def test_the_flight_pages_distance_of_a_noisy_straight_line_is_its_length_not_the_sum_of_noise():
    t = np.arange(0.0, 100.0, 0.04)
    n, e = _noisy_line(t, 3.0, 1.0, seed=5)
    ned = pd.DataFrame({"t_ns": (t * 1e9).astype(np.int64), "pos_n_m": n, "pos_e_m": e, "pos_d_m": 0.0})
    rows = dict(fs.summary_rows({}, duration_s=100.0, ned=ned))
    assert float(rows["distance (horizontal path)"].split()[0].replace(",", "")) == pytest.approx(300.0, rel=0.03)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_noisy_circle_reads_within_three_percent_of_its_circumference(seed):
    rng = np.random.default_rng(seed)
    r, v = 40.0, 4.0                                     # two laps: 4 π r ≈ 502.7 m
    t = np.arange(0.0, 4 * np.pi * r / v, 0.1)
    n = r * np.cos(v * t / r) + 0.5 * rng.standard_normal(len(t))
    e = r * np.sin(v * t / r) + 0.5 * rng.standard_normal(len(t))
    length, _, _ = fs.path_length((t * 1e9).astype(np.int64), n, e)
    assert length == pytest.approx(4 * np.pi * r, rel=0.03)


def test_a_hover_with_noisy_positions_flies_almost_nowhere():
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 120.0, 0.04)
    n, e = 0.5 * rng.standard_normal(len(t)), 0.5 * rng.standard_normal(len(t))
    assert np.hypot(np.diff(n), np.diff(e)).sum() > 1000  # the raw sum: over a kilometre
    length, _, _ = fs.path_length((t * 1e9).astype(np.int64), n, e)
    assert length < 1.0
    # noise-free tracks keep their exact length; too few points give NaN
    assert fs.path_length([0, 10**9, 2 * 10**9], [0.0, 3.0, 3.0], [0.0, 4.0, 8.0])[0] == pytest.approx(9.0)
    assert np.isnan(fs.path_length([0], [1.0], [1.0])[0])


# --- item 3: one computation for the index and the flight page ---------------------------------

def test_the_index_shows_the_flight_pages_duration_distance_and_speed(tmp_path):
    from pipeline.report.flight import build_flight_report
    from pipeline.report.index import build_index

    d, state = _ekf_failure_like(tmp_path, with_state=True)
    page = tmp_path / "report" / "flights" / "ekf.html"
    build_flight_report(d, page, template=TEMPLATE, plotly_js="plotly.min.js", state=state)
    rows = _summary(page)
    idx = tmp_path / "index.html"
    table = build_index(["ekf"], [d / "meta.json"], idx, links={"ekf": "report/flights/ekf.html"})
    text = html.unescape(idx.read_text())
    cells = re.search(r'<a href="report/flights/ekf.html">ekf</a>.*?</tr>', text, re.S).group(0)
    got = re.findall(r"<td class=num>([^<]*)</td>", cells)
    assert got == [rows["duration"], rows["distance (horizontal path)"], rows["max horizontal speed"]]
    assert rows["duration"] == "78.6 s"                  # the state's span, 0.5 … 79.1 s
    assert float(rows["distance (horizontal path)"].split()[0]) == pytest.approx(2.0 * 78.6, rel=0.03)
    assert table.loc[0, "duration_s"] == pytest.approx(78.6)
    # without the page, the index computes the same numbers the same way (from the ingest streams)
    build_index(["ekf"], [d / "meta.json"], tmp_path / "index2.html")
    alone = html.unescape((tmp_path / "index2.html").read_text())
    from pipeline.io.parquet import read_flightlog

    txt = fs.number_texts(fs.flight_numbers(read_flightlog(d)))
    assert f"<td class=num>{txt['duration']}</td><td class=num>{txt['distance']}</td>" in alone
    assert txt["duration"] == "79.6 s"


def test_the_index_says_the_unknown_share_after_the_maneuvers_it_names(tmp_path):
    from pipeline.report.index import maneuver_summary

    p = tmp_path / "c.parquet"
    pd.DataFrame({"pred": ["unknown"] * 97 + ["background"] * 3}).to_parquet(p)
    # before: "f3a classifier: background 3%", read as if the flight were all background
    assert maneuver_summary(None, {"f3a": p}) == "f3a classifier: background 3%, unknown 97%"
    pd.DataFrame({"pred": ["M1"] * 3 + ["M2"]}).to_parquet(p)
    assert maneuver_summary(None, {"sim": p}) == "sim classifier: M1 75%, M2 25%"
    pd.DataFrame({"pred": ["unknown"] * 2}).to_parquet(p)
    assert maneuver_summary(None, {"sim": p}) == "sim classifier: unknown only"


def test_the_headline_speeds_leave_out_the_extrapolated_ends_of_a_differentiated_velocity():
    t = np.arange(0, 100) * 40_000_000                       # 4 s at 25 Hz, a gap in the middle
    v = pd.DataFrame({"t_ns": t, "vel_n_mps": 1.0, "vel_e_mps": 0.0, "vel_d_mps": 0.5})
    v.loc[[0, 49, 99], "vel_d_mps"] = -9.4                   # the run ends: edge spikes
    v.loc[50:52, ["vel_n_mps", "vel_e_mps", "vel_d_mps"]] = np.nan
    w = fs.without_edges(v, 0.5)
    kept = w["vel_d_mps"].notna().to_numpy()
    # 0.5 s = 12.5 samples dropped at each end of both runs [0, 50) and [53, 100)
    assert not kept[:13].any() and kept[13:37].all() and not kept[37:50].any() and not kept[53:66].any()
    assert fs.track_numbers(None, w)["max_vspeed_mps"] == 0.5
    assert fs.track_numbers(None, v)["max_vspeed_mps"] == 9.4
    assert fs.without_edges(v, 0.0) is v


def test_a_ground_vehicle_has_no_altitude_or_climb_numbers_and_says_why():
    n = {"duration_s": 395.0, "distance_m": 320.0, "max_alt_m": float("nan"), "max_hspeed_mps": 1.7,
         "max_vspeed_mps": float("nan"), "ground_vehicle": True}
    txt = fs.number_texts(n)
    assert txt["max_alt"] == "– (ground vehicle)" and txt["max_vspeed"] == "– (ground vehicle)"
    assert txt["max_hspeed"] == "1.7 m/s"
    assert fs.number_texts({**n, "ground_vehicle": False})["max_alt"] == "– (no height)"


def test_the_index_says_how_many_labelled_maneuver_samples_the_classifier_got_right(tmp_path):
    from pipeline.report.index import maneuver_summary

    p = tmp_path / "c.parquet"
    # a simulated M1 flight: its low-dynamic start and end read M4, every M1 sample is right
    pd.DataFrame({"truth": ["low"] * 4 + ["M1"] * 5 + ["low"] * 1, "pred": ["M4"] * 4 + ["M1"] * 5 + ["M4"],
                  "ll_M1": 0.0, "ll_M4": 0.0}).to_parquet(p)
    assert maneuver_summary(None, {"sim": p}) == "sim classifier: M4 50%, M1 50% (labelled M1 samples: 100% right)"
    pd.DataFrame({"truth": ["M1", "M2", "M2", "x"], "pred": ["M1", "M1", "M2", "M2"],
                  "ll_M1": 0.0, "ll_M2": 0.0, "ll_background": 0.0}).to_parquet(p)
    assert maneuver_summary(None, {"sim": p}).endswith("(3 samples of 2 known maneuvers: 67% right)")
