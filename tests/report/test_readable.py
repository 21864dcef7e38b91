"""Readable flight pages (issue 13, item 4): labels with units, one palette, plain ticks, and a
display decimation that keeps the extremes and bounds the page size."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline.report import plots

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("col, expected", [
    ("acc_x_mps2", "acceleration x [m/s²]"),
    ("gyr_z_radps", "angular rate z [rad/s]"),
    ("vel_n_mps", "velocity north [m/s]"),
    ("pos_d_m", "position down [m]"),
    ("alt_wgs84_m", "altitude (WGS-84) [m]"),
    ("alt_cal_m", "altitude (calibrated) [m]"),
    ("press_Pa", "pressure [Pa]"),
    ("diff_press_Pa", "differential pressure [Pa]"),
    ("temp_degC", "temperature [°C]"),
    ("lat_deg", "latitude [°]"),
    ("roll_rad", "roll [rad]"),
    ("p_radps", "roll rate [rad/s]"),
    ("voltage_V", "voltage [V]"),
    ("current_A", "current [A]"),
    ("consumed_Ah", "charge drawn [A·h]"),
    ("remaining_frac", "remaining capacity [0..1]"),
    ("mag_y_T", "magnetic field y [T]"),
    ("rc_3_us", "RC input 3 [µs]"),
    ("vibe_z_mps2", "vibration z [m/s²]"),
    ("hacc_m", "horizontal accuracy [m]"),
    ("hdop", "HDOP"),
    ("n_sats", "satellites"),
    ("fix_type", "fix type"),
    ("x_vel_e_mps", "estimated velocity east [m/s]"),
    ("something_new", "something new"),
])
def test_the_label_of_a_canonical_column_names_the_quantity_and_its_unit(col, expected):
    assert plots.label(col) == expected


def test_every_schema_column_with_a_unit_suffix_gets_a_bracketed_unit():
    from pipeline.io import schema

    for stream, cols in schema.STREAMS.items():
        for c in cols:
            if c.name.split("_")[-1] in plots.UNITS and plots.UNITS[c.name.split("_")[-1]]:
                assert plots.label(c.name).endswith("]"), (stream, c.name, plots.label(c.name))
                assert "_" not in plots.label(c.name), (stream, c.name)


def test_a_component_has_the_same_colour_in_every_quantity_and_its_setpoint():
    assert plots.colour("acc_x_mps2") == plots.colour("gyr_x_radps") == plots.colour("vibe_x_mps2")
    assert plots.colour("vel_n_mps") == plots.colour("pos_n_m")
    assert plots.colour("roll") == plots.colour("roll_rad") == plots.colour("p_radps")
    assert len({plots.colour(f"acc_{a}_mps2") for a in "xyz"}) == 3
    # a name with no palette token: a pick from the cycle by the name itself (crc32, the same in
    # every process; Python's hash() is salted per process), never by trace order
    import subprocess
    import sys

    other = subprocess.run([sys.executable, "-c", "from pipeline.report import plots; print(plots.colour('an unknown series'))"],
                           capture_output=True, text=True, check=True).stdout.strip()
    assert plots.colour("an unknown series") == other
    assert len({plots.colour(f"unknown series {i}") for i in range(20)}) >= 5
    assert len({plots.colour(f"servo_{i}_us") for i in range(1, 11)}) == 10
    assert plots.colour("rc_2_us") == plots.colour("servo_2_us")


def test_a_confidence_axis_has_plain_number_ticks_not_si_prefixes():
    cls = pd.DataFrame({"t_ns": np.arange(50) * 10**8, "label": ["M1"] * 50,
                        "confidence": np.linspace(-380.0, -20.0, 50)})
    fig = plots.timeline(None, cls)
    assert fig.layout.yaxis2.exponentformat == "none"
    assert fig.layout.yaxis.exponentformat == "none" and fig.layout.xaxis.exponentformat == "none"


def test_decimation_keeps_the_minimum_and_maximum_of_every_bucket():
    rng = np.random.default_rng(3)
    n, max_points = 100_000, 1000
    df = pd.DataFrame({"t_ns": np.arange(n, dtype=np.int64), "a": rng.normal(size=n), "b": rng.normal(size=n)})
    df.loc[12_345, "a"] = 50.0     # a one-sample spike must survive
    df.loc[77_777, "b"] = -40.0
    df.loc[500:600, "a"] = np.nan  # NaN never replaces a finite extreme
    d = plots.decimate(df, max_points)
    assert len(d) <= max_points + 2
    assert d["t_ns"].is_monotonic_increasing and d["t_ns"].iloc[0] == 0 and d["t_ns"].iloc[-1] == n - 1
    n_b = max_points // 4
    bucket = np.arange(n) * n_b // n
    kept = set(d.index)
    for c in ("a", "b"):
        g = df[c].groupby(bucket)
        assert set(g.idxmin()) <= kept and set(g.idxmax()) <= kept
    assert 12_345 in kept and 77_777 in kept
    small = df.iloc[:500]
    assert plots.decimate(small, max_points) is small  # short series untouched


def test_a_line_trace_is_broken_across_a_telemetry_outage_and_across_rows_without_a_value():
    # 25 Hz for 10 s, nothing for 30 s, then 25 Hz again; and a run of NaN values inside
    t = np.r_[np.arange(250), np.arange(1000, 1250)].astype(np.int64) * 40_000_000
    v = np.sin(np.arange(500) / 20.0)
    v[300:340] = np.nan                              # 1.6 s of a state gap (rows, no value)
    d = plots.decimate(pd.DataFrame({"t_ns": t, "v": v}), 100, cols=["v"], breaks=True)
    hole = d["v"].isna().to_numpy()
    assert hole.sum() == 2                           # one row in each gap, only the time
    tt = d["t_ns"].to_numpy()
    assert np.all(np.diff(tt) > 0)
    # each hole lies between the two samples around its gap, which are both kept
    for k in np.flatnonzero(hole):
        before, after = tt[k - 1], tt[k + 1]
        assert (before, after) in {(249 * 40_000_000, 1000 * 40_000_000),
                                   (1049 * 40_000_000, 1090 * 40_000_000)}
        assert before < tt[k] < after
    # a trace without a gap gets no hole, and without ``breaks`` nothing changes
    even = pd.DataFrame({"t_ns": np.arange(500, dtype=np.int64) * 40_000_000, "v": np.cos(np.arange(500.0))})
    assert not plots.decimate(even, 100, cols=["v"], breaks=True)["v"].isna().any()
    assert len(plots.decimate(pd.DataFrame({"t_ns": t, "v": v}), 100, cols=["v"])) <= 102


def test_the_ground_track_of_a_flight_with_an_outage_draws_a_hole_and_a_finite_scale_bar():
    t = np.r_[np.arange(200), np.arange(900, 1100)].astype(np.int64) * 10**8
    ned = pd.DataFrame({"t_ns": t, "pos_n_m": np.linspace(0, 400, 400), "pos_e_m": np.linspace(0, 100, 400),
                        "pos_d_m": np.zeros(400)})
    fig = plots.ground_track(ned)
    x = np.asarray(fig.data[0].x, dtype=float)
    assert np.isnan(x).sum() == 1
    bar = fig.layout.shapes[0]
    assert np.isfinite([bar.x0, bar.x1, bar.y0]).all() and bar.x1 - bar.x0 == 100


@pytest.mark.slow  # renders a whole long-flight page (about 3 s); the full suite keeps it
def test_a_long_flight_page_stays_under_3_mb_with_every_panel_drawn_or_said_absent(tmp_path):
    from pipeline.io.ingest import outputs_for, run_ingest
    from pipeline.report.flight import build_flight_report
    from pipeline.simulate.demo import write_demo_flight

    write_demo_flight(tmp_path / "long.bin", seed=2, duration_s=3600.0)   # 180 000 IMU samples
    run_ingest({"log": tmp_path / "long.bin"}, outputs_for(tmp_path / "ingest"), None, flight_id="long")
    page = tmp_path / "long.html"
    build_flight_report(tmp_path / "ingest", page, template=ROOT / "reports" / "templates" / "flight.html.j2",
                        plotly_js="plotly.min.js")
    text = page.read_text()
    assert page.stat().st_size < 3_000_000, page.stat().st_size
    assert "plotly.min.js" in text and "function(" not in text[:5000]  # plotly.js is not inlined
    # trace names are labels with units (plotly escapes "/" and "²" in its JSON), never column names
    assert '"name":"acceleration x [m\\u002fs\\u00b2]"' in text
    assert not re.search(r'"name":"[a-z]+_[a-z0-9_]+"', text)
    for shown in ("GPS quality", "Vibration (accelerometer RMS", "Attitude vs setpoint", "Log messages", "Parameters"):
        assert shown in text, shown
    assert "Battery: no data in this flight" in text  # the demo logs no battery: one line, not nothing


def test_a_plot_is_an_image_named_by_its_panel_and_traces_for_a_screen_reader():
    import plotly.graph_objects as go

    from pipeline.report.pages import figure_divs

    fig = go.Figure([go.Scatter(x=[0, 1], y=[0, 1], name="roll [°]"), go.Scatter(x=[0, 1], y=[1, 0], name="a<b")])
    (title, div), (t2, none) = figure_divs([("Attitude & rates", fig), ("Battery", None)])
    assert div.startswith('<div id="plot-0" class="plotly-graph-div" role="img" '
                          'aria-label="Attitude &amp; rates (2 traces: roll [°], a&lt;b)"')
    assert none is None and t2 == "Battery"
