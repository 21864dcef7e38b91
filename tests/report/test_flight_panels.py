"""The flight page's panels fed by the schema 1.1 streams (issue 13, item 2): each is drawn from
its stream, or the page says in one line that the flight has no data for it."""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.io import schema
from pipeline.report import plots

ROOT = Path(__file__).resolve().parents[2]


def _stream(stream: str, n: int, rate_hz: float, /, **cols) -> pd.DataFrame:
    """A canonical ``stream`` table of ``n`` rows at ``rate_hz`` with the given columns (every
    other column of the schema present and empty, as readers leave it)."""
    df = pd.DataFrame({"t_ns": (np.arange(n) * 1e9 / rate_hz).astype(np.int64),
                       "instance": np.zeros(n, np.uint8), "src": "X", **cols})
    for c in schema.STREAMS[stream]:
        if c.name not in df:
            df[c.name] = np.nan
    return df


def _names(fig) -> list[str]:
    return [t.name for t in fig.data]


def test_the_gps_quality_panel_draws_fix_type_satellites_dop_and_accuracy_on_its_own_axis():
    n = 50
    gps = _stream("gps", n, 5.0, fix_type=np.full(n, 3.0), n_sats=np.full(n, 12.0), hdop=np.full(n, 0.8),
                  hacc_m=np.linspace(2.0, 0.5, n))
    fig = plots.gps_quality(gps)
    assert _names(fig) == ["fix type", "satellites", "HDOP", "horizontal accuracy [m]"]
    assert fig.data[-1].yaxis == "y2" and fig.layout.yaxis2.title.text == "accuracy [m]"
    # ticks of its own: plotly.js 4 would put an overlaying axis's ticks on the left grid
    # ("sync"), at values such as 0.441 ... 0.917 m
    assert fig.layout.yaxis2.tickmode == "auto" and fig.layout.yaxis2.overlaying == "y"
    assert plots.gps_quality(gps.assign(fix_type=np.nan, n_sats=np.nan, hdop=np.nan, hacc_m=np.nan)) is None
    assert plots.gps_quality(None) is None
    assert fig.layout.yaxis.title.text == "fix type (3 = 3-D), satellites, DOP"
    # a log with satellites alone (the kd0aij CSVs): the axis names what it draws
    sats = plots.gps_quality(gps.assign(fix_type=np.nan, hdop=np.nan, hacc_m=np.nan))
    assert sats.layout.yaxis.title.text == "satellites"


def test_the_vibration_panel_prefers_the_autopilots_metric():
    n = 40
    vib = _stream("vibration", n, 10.0, vibe_x_mps2=np.full(n, 3.0), vibe_y_mps2=np.full(n, 4.0),
                  vibe_z_mps2=np.full(n, 9.0), clip_0=np.arange(n, dtype=float))
    fig = plots.vibration(vib, None)
    assert _names(fig)[:3] == [f"vibration {a} [m/s²]" for a in "xyz"]
    assert "clipping events 1" in _names(fig) and fig.layout.yaxis2.title.text == "clipping events"
    assert fig.layout.title.text.startswith("Vibration (autopilot")
    assert fig.layout.yaxis2.rangemode == "tozero"        # a count: never drawn below 0


def test_the_px4_gyro_vibration_is_drawn_on_a_rad_per_s_axis_of_its_own_never_on_the_m_per_s2_axis():
    n = 40
    vib = _stream("vibration", n, 10.0, acc_vibration_mps2=np.full(n, 5.0), gyr_vibration_radps=np.full(n, 0.05))
    fig = plots.vibration(vib, None)

    def axis_title(tr) -> str:
        return (fig.layout.yaxis if tr.yaxis in (None, "y") else getattr(fig.layout, f"yaxis{tr.yaxis[1:]}")).title.text

    axes = {tr.name: axis_title(tr) for tr in fig.data}
    assert axes == {"accelerometer vibration [m/s²]": "vibration [m/s²]",
                    "gyro vibration [rad/s]": "gyro vibration [rad/s]"}
    assert fig.layout.yaxis2.overlaying == "y" and fig.layout.yaxis2.side == "right"
    # with clipping counts as well: three units, three axes, the plot narrowed for the third
    fig = plots.vibration(vib.assign(clip_0=np.arange(n, dtype=float)), None)
    assert [axis_title(tr) for tr in fig.data] == ["vibration [m/s²]", "gyro vibration [rad/s]", "clipping events"]
    # the gyro alone: its own unit on the left axis, no m/s² anywhere
    fig = plots.vibration(vib.assign(acc_vibration_mps2=np.nan), None)
    assert [axis_title(tr) for tr in fig.data] == ["gyro vibration [rad/s]"]


def test_the_vibration_panel_falls_back_to_the_accelerometer_rms_in_one_second_windows():
    rng = np.random.default_rng(5)
    n, rate = 500, 50.0                                 # 10 s at 50 Hz
    acc = {"acc_x_mps2": 1.0 + 0.3 * rng.standard_normal(n), "acc_y_mps2": np.zeros(n),
           "acc_z_mps2": -9.81 + np.sin(np.arange(n))}
    imu = _stream("imu", n, rate, **acc)
    r = plots.accel_rms(imu)
    assert len(r) == 10 and (r["t_ns"] == np.arange(10) * 10**9 + 5 * 10**8).all()
    # the oracle: population standard deviation of each second's 50 samples
    np.testing.assert_allclose(r["acc_x_mps2"], acc["acc_x_mps2"].reshape(10, 50).std(axis=1), rtol=1e-12)
    np.testing.assert_allclose(r["acc_y_mps2"], 0.0, atol=0)
    fig = plots.vibration(None, imu)
    assert _names(fig) == [f"acceleration {a} RMS [m/s²]" for a in "xyz"]
    assert "1 s windows" in fig.layout.title.text
    assert plots.vibration(None, None) is None


def test_the_battery_panel_draws_voltage_left_and_current_and_remaining_percent_each_on_its_own_right_axis():
    n = 30
    bat = _stream("battery", n, 1.0, voltage_V=np.linspace(16.8, 15.0, n), current_A=np.full(n, 12.0),
                  remaining_frac=np.linspace(1.0, 0.7, n))
    fig = plots.battery(bat)
    assert _names(fig) == ["voltage [V]", "current [A]", "remaining capacity [%]"]
    assert [t.yaxis for t in fig.data] == ["y", "y2", "y3"]
    assert [fig.layout.yaxis.title.text, fig.layout.yaxis2.title.text, fig.layout.yaxis3.title.text] == \
        ["voltage [V]", "current [A]", "remaining capacity [%]"]
    assert fig.layout.yaxis2.tickmode == fig.layout.yaxis3.tickmode == "auto"
    np.testing.assert_allclose(fig.data[2].y, np.linspace(100.0, 70.0, n))
    assert plots.battery(bat.iloc[:0]) is None


def test_a_remaining_capacity_that_never_changes_is_named_in_the_title_not_drawn_on_a_third_axis():
    n = 30
    bat = _stream("battery", n, 1.0, voltage_V=np.linspace(24.5, 23.5, n), current_A=np.full(n, 12.0),
                  remaining_frac=np.ones(n))                      # PX4 without a capacity estimate
    fig = plots.battery(bat)
    assert _names(fig) == ["voltage [V]", "current [A]"]
    assert fig.layout.title.text == "Battery (remaining capacity 100 % throughout, not drawn)"
    assert fig.layout.xaxis.domain is None                      # full width, in line with the other panels


def test_attitude_is_drawn_against_the_setpoint_with_yaw_unwrapped():
    from pipeline.frames.rotations import quat_to_euler

    n = 100
    yaw = np.linspace(0.0, 4 * np.pi, n)                 # two full turns
    q = np.c_[np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)]
    att = _stream("attitude", n, 10.0, q_w=q[:, 0], q_x=q[:, 1], q_y=q[:, 2], q_z=q[:, 3])
    sp = _stream("setpoint", n, 10.0, roll_rad=np.zeros(n), pitch_rad=np.zeros(n), yaw_rad=np.angle(np.exp(1j * yaw)))
    fig = plots.attitude(att, quat_to_euler(q), sp)
    assert _names(fig) == ["roll [°]", "pitch [°]", "yaw [°]", "roll setpoint [°]", "pitch setpoint [°]",
                           "yaw setpoint [°]"]
    np.testing.assert_allclose(fig.data[2].y, np.degrees(yaw), atol=1e-6)
    np.testing.assert_allclose(fig.data[5].y, np.degrees(yaw), atol=1e-6)
    assert fig.data[0].line.color == fig.data[3].line.color and fig.data[3].line.dash == "dash"
    assert "setpoint" in fig.layout.title.text
    assert "setpoint" not in plots.attitude(att, quat_to_euler(q), None).layout.title.text


def test_body_rates_with_a_setpoint_share_the_colour_per_axis():
    n = 20
    rates = pd.DataFrame({"t_ns": np.arange(n) * 10**8, "p_radps": np.ones(n), "q_radps": np.zeros(n),
                          "r_radps": np.zeros(n)})
    sp = _stream("setpoint", n, 10.0, p_radps=np.ones(n))
    fig = plots.with_setpoint(rates, ["p_radps", "q_radps", "r_radps"], sp, ["p_radps", "q_radps", "r_radps"],
                              "Body rates", "body rate [rad/s]")
    assert _names(fig) == ["roll rate [rad/s]", "pitch rate [rad/s]", "yaw rate [rad/s]", "roll rate setpoint [rad/s]"]
    assert fig.data[0].line.color == fig.data[3].line.color
    assert plots.with_setpoint(None, ["p_radps"], None, ["p_radps"], "x", "y") is None


def test_messages_and_parameters_become_tables_with_times():
    msgs = _stream("messages", 3, 1.0, text=["EKF3 IMU0 is using GPS", "Arming checks", "Crash"],
                   severity=[6.0, np.nan, 2.0])
    headers, rows = plots.messages_table(msgs)
    assert headers == ["t [s]", "severity", "text"]
    assert rows == [["0.000", "info", "EKF3 IMU0 is using GPS"], ["1.000", "–", "Arming checks"],
                    ["2.000", "critical", "Crash"]]
    par = _stream("params", 3, 1.0, name=["B_P", "A_P", "B_P"], value=[1.0, 0.5, 2.0])
    headers, rows = plots.params_table(par)
    assert headers == ["name", "value", "t [s]", "times set"]
    assert rows == [["A_P", "0.5", "1.000", "1"], ["B_P", "2", "2.000", "2"]]
    assert plots.messages_table(None)[1] == [] and plots.params_table(msgs.iloc[:0])[1] == []


def test_a_flight_without_the_new_streams_says_so_in_one_line_per_panel(tmp_path):
    from pipeline.io.ingest import outputs_for, run_ingest
    from pipeline.report.flight import build_flight_report

    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"garbage" * 50)
    run_ingest({"log": bad}, outputs_for(tmp_path / "ingest"), None, flight_id="bad")
    page = tmp_path / "bad.html"
    build_flight_report(tmp_path / "ingest", page, template=ROOT / "reports" / "templates" / "flight.html.j2",
                        plotly_js="plotly.min.js")
    text = html.unescape(page.read_text())
    for title in ("GPS quality (fix type, satellites, HDOP/EPH)", "Vibration", "Battery", "Attitude",
                  "Body rates", "Velocity"):
        assert f"{title}: no data in this flight" in text, title
    for title in ("Log messages", "Parameters"):   # a table: its heading, then the line, once each
        assert f'<h2>{title}</h2>\n<p class="absent">no data in this flight</p>' in text, title


def test_the_demo_flight_page_draws_the_new_panels_and_tables(tmp_path):
    from pipeline.io.ingest import outputs_for, run_ingest
    from pipeline.report.flight import build_flight_report
    from pipeline.simulate.demo import write_demo_flight

    write_demo_flight(tmp_path / "demo.bin", seed=1, duration_s=30.0)
    run_ingest({"log": tmp_path / "demo.bin"}, outputs_for(tmp_path / "ingest"), None, flight_id="demo")
    page = tmp_path / "demo.html"
    build_flight_report(tmp_path / "ingest", page, template=ROOT / "reports" / "templates" / "flight.html.j2",
                        plotly_js="plotly.min.js")
    text = html.unescape(page.read_text())
    for drawn in ("GPS quality", "Attitude vs setpoint", "Body rates", "Vibration (accelerometer RMS"):
        assert drawn in text and f"{drawn}: no data" not in text, drawn
    assert "Body rates vs setpoint" not in text   # the demo logs attitude setpoints, no rate setpoints
    assert "<td>ArduCopter V4.5.0 (uavpipe demo flight)</td>" in text   # a MSG record, with its time
    assert "<td>INS_GYRO_FILTER</td><td>20</td>" in text                 # a PARM record


def test_flight_mode_bands_cover_each_mode_until_the_next_and_the_last_until_the_end():
    import plotly.graph_objects as go

    mode = _stream("mode", 4, 1.0, mode=["STABILIZE", "STABILIZE", "LOITER", "LAND"])
    fig = plots.mode_bands(go.Figure(go.Scatter(x=[0, 10], y=[0, 1])), mode, 10.0)
    bands = [(s.x0, s.x1) for s in fig.layout.shapes]
    assert bands == [(0.0, 2.0), (2.0, 3.0), (3.0, 10.0)]   # the repeated STABILIZE continues its band
    assert [a.text for a in fig.layout.annotations] == ["STABILIZE", "LOITER", "LAND"]
    assert plots.mode_bands(go.Figure(), None).layout.shapes == ()


def test_every_mode_band_has_a_hover_marker_naming_its_mode_and_times_on_an_axis_of_its_own():
    import plotly.graph_objects as go

    # before: a shape has no hover text, so a band too short for its name said nothing at all
    mode = _stream("mode", 4, 1.0, mode=["STABILIZE", "LOITER", "AUTO", "RTL"])
    mode["t_ns"] = (np.array([0, 0.5, 1.0, 300.0]) * 1e9).astype(np.int64)
    fig = go.Figure(go.Scatter(x=[0, 330], y=[0, 1]))
    fig.update_layout(**plots.unit_axes(fig, ["m", "m/s"]))
    fig = plots.mode_bands(fig, mode, 330.0)
    marks = fig.data[-1]
    assert marks.hovertext == ("mode STABILIZE<br>0.0–0.5 s (0.5 s)", "mode LOITER<br>0.5–1.0 s (0.5 s)",
                               "mode AUTO<br>1.0–300.0 s (299.0 s)", "mode RTL<br>300.0–330.0 s (30.0 s)")
    np.testing.assert_allclose(marks.x, [0.25, 0.75, 150.5, 315.0])
    # its own hidden axis over the first, fixed at [0, 1]: the unit axes y and y2 are untouched
    assert marks.yaxis == "y3" and fig.layout.yaxis3.overlaying == "y" and fig.layout.yaxis3.visible is False
    assert tuple(fig.layout.yaxis3.range) == (0, 1) and fig.layout.yaxis2.title.text == "m/s"
    assert list(marks.marker.color) == [plots.label_colour(f"mode {n}") for n in ("STABILIZE", "LOITER", "AUTO", "RTL")]
    assert len(plots.mode_bands(go.Figure(), None).data) == 0


def test_mode_names_switched_within_moments_are_not_printed_over_each_other():
    import plotly.graph_objects as go

    # STABILIZE, LOITER 0.5 s later, AUTO at 1 s, RTL at 300 s of a 330 s flight: the longest
    # band (AUTO) and RTL are named; STABILIZE and LOITER would run into the name AUTO,
    # so only their bands are drawn
    mode = _stream("mode", 4, 1.0, mode=["STABILIZE", "LOITER", "AUTO", "RTL"])
    mode["t_ns"] = np.array([0, 0.5, 1.0, 300.0]) * 1e9
    mode["t_ns"] = mode["t_ns"].astype(np.int64)
    fig = plots.mode_bands(go.Figure(go.Scatter(x=[0, 330], y=[0, 1])), mode, 330.0)
    assert len(fig.layout.shapes) == 4
    assert [a.text for a in fig.layout.annotations] == ["AUTO", "RTL"]


def test_the_altitude_panel_thins_its_calibration_markers_and_names_how_many():
    t = np.arange(651, dtype=np.int64) * 10**8
    pts = pd.DataFrame({"t_ns": t, "alt_m": np.linspace(20, 65, 651)})
    fig = plots.altitude({"−d (track)": pts}, pts)
    marks = fig.data[-1]
    assert len(marks.x) <= plots.MAX_MARKERS and marks.name == f"calibration points ({len(marks.x)} of 651 shown)"
    assert plots.altitude({}, pts.iloc[:50]).data[-1].name == "calibration points"


def test_a_maneuver_label_has_one_colour_for_its_segment_and_its_prediction():
    seg = pd.DataFrame({"t_start_ns": [0, 5 * 10**9], "t_end_ns": [4 * 10**9, 9 * 10**9], "label": ["M1", "M2"]})
    cls = pd.DataFrame({"t_ns": np.arange(10) * 10**9, "label": ["M1"] * 5 + ["unknown"] * 5,
                        "confidence": np.zeros(10)})
    fig = plots.timeline(seg, cls)
    seg_colour = {t.name: t.line.color for t in fig.data if t.mode == "lines" and t.y[0] == plots.LABEL_SEGMENTS_ROW}
    pred_colour = {t.name: t.marker.color for t in fig.data if t.mode == "markers"}
    assert seg_colour["M1"] == pred_colour["classifier: M1"] == plots.label_colour("M1")
    assert pred_colour["classifier: unknown"] == "#999999"


def test_many_channels_share_one_panels_point_budget():
    n, k = 50_000, 16
    ctl = _stream("control", n, 50.0, **{f"servo_{i}_us": 1500 + 400 * np.sin(np.arange(n) / (100 + i))
                                         for i in range(1, k + 1)})
    fig = plots.time_series(ctl, [f"servo_{i}_us" for i in range(1, 33)], "Actuator outputs", "pulse width [µs]")
    assert len(fig.data) == k and fig.data[0].name == "servo output 1 [µs]"
    assert sum(len(t.x) for t in fig.data) <= k * 1002
    assert max(t.y.max() for t in fig.data) == ctl[[f"servo_{i}_us" for i in range(1, k + 1)]].max().max()


def test_an_unwrapped_yaw_setpoint_starts_on_the_measured_yaws_turn():
    from pipeline.frames.rotations import quat_to_euler

    n = 50
    yaw = np.full(n, -0.3)                                   # measured yaw just left of north
    q = np.c_[np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)]
    att = _stream("attitude", n, 10.0, q_w=q[:, 0], q_x=q[:, 1], q_y=q[:, 2], q_z=q[:, 3])
    sp = _stream("setpoint", n, 10.0, yaw_rad=np.full(n, 2 * np.pi - 0.3))   # the same heading, [0, 2π)
    fig = plots.attitude(att, quat_to_euler(q), sp)
    np.testing.assert_allclose(fig.data[-1].y, np.degrees(yaw), atol=1e-9)


def test_a_yaw_setpoint_stays_on_the_measured_yaws_turn_after_the_two_drift_whole_turns_apart():
    from pipeline.frames.rotations import quat_to_euler

    # the vehicle spins three times while its (1 Hz) setpoint holds 10°; afterwards the measured
    # yaw, unwrapped, sits at 1090°: the setpoint must be drawn 10° off it, not 1080°
    n = 200
    t = np.arange(n) / 10.0
    yaw = np.where(t < 5, 0.0, np.minimum(t - 5, 3.0) * 2 * np.pi) + np.radians(10.0) * (t >= 8)
    q = np.c_[np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)]
    att = _stream("attitude", n, 10.0, q_w=q[:, 0], q_x=q[:, 1], q_y=q[:, 2], q_z=q[:, 3])
    sp = _stream("setpoint", 20, 1.0, yaw_rad=np.full(20, np.radians(10.0)))
    fig = plots.attitude(att, quat_to_euler(q), sp)
    measured, setpoint = fig.data[2], fig.data[-1]
    after = np.asarray(setpoint.x) >= 9.0
    np.testing.assert_allclose(np.asarray(setpoint.y)[after], 1090.0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(measured.y)[-1], 1090.0, atol=1e-6)


def test_time_arrays_are_float32_for_display_and_values_keep_every_digit():
    n = 5000
    df = _stream("imu", n, 100.0, acc_x_mps2=np.linspace(0.0, 1.0, n) + 1e-9)
    fig = plots.time_series(df, ["acc_x_mps2"], "a", "b")
    x, y = fig.data[0].x, fig.data[0].y
    assert x.dtype == np.float32 and y.dtype == np.float64
    # the kept rows' times to float32 precision (a monotone series: min/max per bucket = its ends)
    t = df["t_ns"].to_numpy() * 1e-9
    np.testing.assert_allclose(x, t[np.searchsorted(df["acc_x_mps2"].to_numpy(), y)], rtol=1e-7)
    assert y.max() == df["acc_x_mps2"].max()


def test_flight_mode_segments_get_their_own_row_apart_from_the_labelled_maneuvers():
    seg = pd.DataFrame({"t_start_ns": [0, 61 * 10**9, 10 * 10**9], "t_end_ns": [61 * 10**9, 79 * 10**9, 20 * 10**9],
                        "label": ["mode:MANUAL", "mode:POSCTL", "M1"]})
    fig = plots.timeline(seg)
    rows = {t.name: t.y[0] for t in fig.data}
    assert rows == {"mode:MANUAL": "segments: flight mode", "mode:POSCTL": "segments: flight mode",
                    "M1": "segments: maneuvers"}
    assert [a.text for a in fig.layout.annotations] == ["MANUAL", "POSCTL", "M1"]


def test_an_out_of_range_rangefinder_reading_is_no_height_on_the_altitude_panel():
    from pipeline.report.flight import rangefinder_height

    n = 6
    rf = _stream("rangefinder", n, 10.0, dist_m=np.array([7.0, 2.5, 2.4, 7.0, 7.0, 2.2]))
    rf["valid"] = pd.array([False, True, True, False, None, True], dtype="boolean")
    h = rangefinder_height(rf)
    # the two readings at the 7 m limit flagged invalid are gaps; an unknown flag keeps its value
    np.testing.assert_array_equal(h["alt_m"].to_numpy(), [np.nan, 2.5, 2.4, np.nan, 7.0, 2.2])
    rf["valid"] = pd.array([False] * n, dtype="boolean")
    assert rangefinder_height(rf) is None and rangefinder_height(None) is None


def test_the_seventeen_labels_of_an_f3a_schedule_get_seventeen_colours_none_the_confidence_lines():
    labs = ["tHat", "iSp", "rollC", "fTrn", "h8L", "hB", "pImm", "lnd", "M", "sqL", "2x4", "Stall",
            "hSqL", "rollC2", "Av", "tkoff", "Z"]
    c = plots.label_colours([*labs, "unknown", "M"])
    assert len(c) == 18 and len({c[k] for k in labs}) == 17 and c["unknown"] == "#999999"
    assert plots.CONFIDENCE_COLOUR not in c.values()
    # the same set in another order, or another panel of it: the same colours
    assert plots.label_colours(reversed(labs)) == {k: c[k] for k in labs}
    # a label alone, or without a clash, keeps its own colour
    assert plots.label_colours(["M1", "M2"])["M1"] == plots.label_colour("M1")
    seg = pd.DataFrame({"t_start_ns": np.arange(17) * 10**9, "t_end_ns": np.arange(1, 18) * 10**9, "label": labs})
    cls = pd.DataFrame({"t_ns": np.arange(17) * 10**9, "label": labs, "confidence": np.zeros(17)})
    fig = plots.timeline(seg, cls)
    v = [t for t in fig.data if t.name == "confidence V"][0]
    assert v.line.color == plots.CONFIDENCE_COLOUR
    assert len({t.marker.color for t in fig.data if t.mode == "markers"}) == 17


def test_the_baro_starts_at_the_tracks_height_where_the_flight_does_not_start_at_its_origin():
    from pipeline.report.flight import baro_relative

    # a simulated flight begins in the air, 20 m above its NED origin; the baro reads 21.5 m
    climb = np.clip(np.arange(100) / 10.0 - 2.0, 0.0, None)     # level for 2 s, then 1 m/s up
    baro = _stream("baro", 100, 10.0, alt_rel_m=21.5 + climb)
    track = pd.DataFrame({"t_ns": baro["t_ns"], "alt_m": 20.0 + climb})
    shifted, name = baro_relative(baro, track)
    assert np.allclose(shifted["alt_m"], track["alt_m"])
    assert name == "baro (raw, shifted -1.5 m to start at the track's height)"
    alone, name = baro_relative(baro)      # no track: relative to its own start, as before
    assert np.allclose(alone["alt_m"], climb) and "+21.5 m subtracted" in name


def test_an_inverted_rolls_wrap_through_180_degrees_is_a_hole_in_its_line_not_a_vertical_stroke():
    d = pd.DataFrame({"t_ns": np.arange(6, dtype=np.int64) * 10**9,
                      "v": [170.0, 178.0, -179.0, -170.0, np.nan, -160.0]})
    out = plots.break_wraps(d)
    assert out["t_ns"].tolist() == [0, 10**9, 15 * 10**8, 2 * 10**9, 3 * 10**9, 4 * 10**9, 5 * 10**9]
    assert np.isnan(out["v"].iloc[2]) and out["v"].iloc[[1, 3]].tolist() == [178.0, -179.0]
    assert plots.break_wraps(d.iloc[:2]) is not None and len(plots.break_wraps(d.iloc[:2])) == 2
    secs = plots.break_wraps(pd.DataFrame({"t_s": [0.0, 1.0], "roll_deg": [179.0, -179.0]}), "roll_deg")
    assert secs["t_s"].tolist() == [0.0, 0.5, 1.0] and np.isnan(secs["roll_deg"].iloc[1])


def test_segment_names_on_the_timeline_are_written_only_where_they_do_not_overlap():
    seg = pd.DataFrame({"t_start_ns": np.array([0, 20, 22, 40], dtype=np.int64) * 10**9,
                        "t_end_ns": np.array([20, 22, 40, 800], dtype=np.int64) * 10**9,
                        "label": ["mode:STABILIZE", "mode:LOITER", "mode:AUTO", "mode:RTL"]})
    fig = plots.timeline(seg)
    # 20 s of STABILIZE, 2 s of LOITER and 18 s of AUTO at take-off on an 800 s panel: the names
    # would overlap, so the longest is written and the other two bars keep their hover text
    assert [a.text for a in fig.layout.annotations] == ["STABILIZE", "RTL"]
    assert len(fig.data) == 4 and fig.data[1].hovertext == "mode:LOITER"
    # names apart by more than their half widths are all written; left-aligned ones by the first's
    assert plots.spaced_labels([0.0, 0.5], [1.0, 1.0], 1.0, ["a", "b"]).all()
    assert plots.spaced_labels([0.0, 0.05], [1.0, 2.0], 1.0, ["STABILIZE", "AUTO"], align="left").tolist() == [False, True]
    assert plots.spaced_labels([0.0, 0.07], [1.0, 2.0], 1.0, ["STABILIZE", "AUTO"], align="left").all()


def test_a_ground_vehicles_altitude_panel_says_its_heights_are_the_sensors():
    from pipeline.report.flight import altitude_panel

    h = pd.DataFrame({"t_ns": np.arange(5, dtype=np.int64) * 10**9, "alt_m": [0.0, -5.0, -12.0, -20.0, -30.0]})
    assert altitude_panel({"−d (track)": h}, None).layout.title.text == "Altitude"
    assert "ground vehicle" in altitude_panel({"−d (track)": h}, None, ground=True).layout.title.text
    assert altitude_panel({}, None, ground=True) is None


def test_a_flight_whose_stream_file_is_damaged_gets_a_one_line_page_and_the_run_goes_on(tmp_path, capsys):
    from pipeline.io.ingest import outputs_for, run_ingest
    from pipeline.report.run import run_flight_report
    from pipeline.simulate.demo import write_demo_flight

    write_demo_flight(tmp_path / "demo.bin", seed=1, duration_s=10.0)
    run_ingest({"log": tmp_path / "demo.bin"}, outputs_for(tmp_path / "ingest" / "demo"), None, flight_id="demo")
    capsys.readouterr()
    (tmp_path / "ingest" / "demo" / "imu.parquet").write_bytes(b"PAR1 not a parquet file PAR1")
    page = tmp_path / "report" / "flights" / "demo.html"
    run_flight_report({"meta": tmp_path / "ingest" / "demo" / "meta.json", "template": ROOT / "reports" / "templates" / "flight.html.j2",
                       "plotly": tmp_path / "report" / "assets" / "plotly.min.js", "state": None, "segments": None,
                       "calibration": None, "classified": [], "estimates": []},
                      {"page": page}, index=str(tmp_path / "index.html"))
    text = html.unescape(page.read_text())
    assert "<h1>demo</h1>" in text and "The page could not be built: " in text and "<script" not in text
    assert "href='../../index.html'" in text
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("uavpipe report: demo: page not built: ") and "imu.parquet" in err[0]
