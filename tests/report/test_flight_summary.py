"""The flight page's summary table and spectrograms (issue 13, item 2)."""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline.report import flight_summary as fs
from pipeline.report import plots

ROOT = Path(__file__).resolve().parents[2]


def _rows(**kw) -> dict:
    return dict(fs.summary_rows(kw.pop("meta", {}), duration_s=kw.pop("duration_s", 10.0), **kw))


def test_the_utc_of_t0_reads_as_a_date_and_time_with_its_clock():
    meta = {"t0_utc_ns": 1432235497988949113, "utc_source": "gps"}
    assert fs.utc_of_t0(meta) == "2015-05-21 19:11:37.988 UTC (gps clock)"
    assert fs.utc_date(meta) == "2015-05-21"
    assert fs.utc_of_t0({}) == "– (no UTC in the log)" and fs.utc_date({}) == ""


def test_autopilot_and_firmware_come_from_what_the_log_states():
    msgs = pd.DataFrame({"t_ns": [2, 1], "text": ["Initialising APM", "ArduCopter V3.1.3 (7bd9d1f3)"]})
    assert fs.autopilot_firmware({}, msgs) == "ArduCopter 3.1.3"
    # PX4's ver_sw_release 0x010E00FF = v1.14.0 release
    ulog = {"source_info": {"sys_name": "PX4", "ver_sw_release": 0x010E00FF, "ver_sw": "abcdef0123", "ver_hw": "PX4_FMU_V5"}}
    assert fs.autopilot_firmware(ulog) == "PX4 v1.14.0 (abcdef01), hardware PX4_FMU_V5"
    assert fs.autopilot_firmware({"mavlink": {"autopilot": 3}}, msgs) == "ArduPilot, ArduCopter 3.1.3"
    assert fs.autopilot_firmware({}) == "– (not logged)"


def test_the_envelope_numbers_follow_their_closed_forms():
    t = np.arange(5) * 10**9
    # a 3-4-5 leg and back up: 5 m + 5 m horizontal, climbing to 7 m above a start at d = -2
    ned = pd.DataFrame({"t_ns": t, "pos_n_m": [0, 3, 3, 3, 0.0], "pos_e_m": [0, 4, 4, 4, 0.0],
                        "pos_d_m": [-2, -5, -9, np.nan, -3.0]})
    vel = pd.DataFrame({"t_ns": t, "vel_n_mps": [0, 3, 0, 0, 0.0], "vel_e_mps": [0, 4, 0, 0, 0.0],
                        "vel_d_mps": [0, -1, -6, 2, 0.0]})
    rates = pd.DataFrame({"t_ns": t, "p_radps": [0, 0, 0, 0, 1.0], "q_radps": [0, 0, 0, 0, 1.0],
                          "r_radps": [0, 0, 0, 0, 1.0]})
    roll, pitch = np.radians([0, 30, 0, 0, 0.0]), np.radians([0, 45, 10, 0, 0.0])
    r = _rows(ned=ned, velocity=vel, rates=rates, euler=(roll, pitch, np.zeros(5)), vehicle="copter")
    assert r["distance (horizontal path)"] == "10 m"
    assert r["max altitude above start"] == "7.0 m"
    assert r["max horizontal speed"] == "5.0 m/s" and r["max vertical speed"] == "6.0 m/s"
    tilt = np.degrees(np.arccos(np.cos(np.radians(30)) * np.cos(np.radians(45))))
    assert r["max tilt"] == f"{tilt:.1f} °"
    assert r["max body rate"] == f"{np.degrees(np.sqrt(3)):.0f} °/s"
    assert r["vehicle"] == "copter" and r["duration"] == "10.0 s"
    empty = _rows()
    assert empty["max tilt"] == "– (no attitude)" and empty["distance (horizontal path)"] == "– (no track)"
    assert list(r) == list(empty)   # the same rows, in the same order, for every flight


def test_the_gps_fix_share_counts_3d_fixes_else_finite_positions():
    g = pd.DataFrame({"t_ns": np.arange(4), "instance": 0, "fix_type": [0, 2, 3, 4.0],
                      "lat_deg": [0, 1, 1, 1.0], "lon_deg": [0, 1, 1, 1.0]})
    assert fs.gps_fix_share(g) == "50.0 % of 4 records (3-D fix or better)"
    assert fs.gps_fix_share(g.assign(fix_type=np.nan)).startswith("75.0 % of 4 records (finite position")
    assert fs.gps_fix_share(None) == "– (no GPS)"


def test_the_worst_warning_ranks_lost_data_above_reader_warnings_and_counts_only_warnings():
    meta = {"diagnostics": {"warnings": ["RAW_IMU ignored"], "records_dropped": {"truncated": 3}}}
    assert fs.worst_warning(meta, {"notes": ["no barometer"]}) == "ingest: 3 records dropped (truncated) (+1 more)"
    assert fs.worst_warning({"diagnostics": {"warnings": ["RAW_IMU ignored"]}}) == "ingest: RAW_IMU ignored"
    assert fs.worst_warning({"status": "failed", "error": "bad magic"}).startswith("ingest failed: bad magic")
    assert fs.worst_warning({}, {"status": "failed", "error": "no state"}) == "preprocess failed: no state"
    assert fs.worst_warning({}) == "none"


def test_preprocess_notes_are_information_so_a_flight_with_only_notes_has_no_worst_warning():
    # the notes of the simulated tlog flight's preprocess info JSON: what was done, not what went wrong
    notes = ["baro altitude from pressure (international barometric formula)",
             "gps positions smoothed (white-jerk RTS, q 10 m²/s⁵): 0.307 m RMS from the interpolated fixes"]
    assert fs.worst_warning({"diagnostics": {"warnings": []}}, {"status": "ok", "notes": notes}) == "none"
    assert dict(fs.summary_rows({}, preprocess={"notes": notes}))["worst warning"] == "none"


def test_timestamp_anomalies_name_only_the_nonzero_counts_of_the_streams_that_have_any():
    diag = {"timestamp_anomalies": {"gps": {"backwards": 0, "duplicate": 2}, "imu": {"backwards": 0, "duplicate": 0},
                                    "baro": {"backwards": 1, "duplicate": 1}}}
    assert fs.timestamp_anomalies(diag) == ["gps: 2 duplicate timestamps", "baro: 1 backwards, 1 duplicate timestamp"]
    assert fs.timestamp_anomalies({}) == []
    assert fs.worst_warning({"diagnostics": diag}) == "ingest: gps: 2 duplicate timestamps (+1 more)"


def test_the_spectrogram_puts_a_sine_at_its_frequency_and_keeps_the_page_bounded():
    from scipy.signal import welch

    fs_hz, n = 200.0, 200 * 120                        # 2 minutes at 200 Hz
    t = np.arange(n) / fs_hz
    rng = np.random.default_rng(3)
    imu = pd.DataFrame({"t_ns": (t * 1e9).astype(np.int64), "instance": 0,
                        "acc_x_mps2": np.sin(2 * np.pi * 37.5 * t) + 0.01 * rng.standard_normal(n),
                        "acc_y_mps2": 0.01 * rng.standard_normal(n), "acc_z_mps2": np.full(n, -9.81)})
    fig = plots.spectrogram(imu, ["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"], "Accelerometer spectrogram", "m/s²")
    hm = fig.data[0]
    z = np.asarray(hm.z, float)
    assert z.shape[1] <= 200 and z.shape[0] == 65                   # 128-sample windows: 65 bins
    assert np.asarray(hm.y)[np.argmax(z.mean(axis=1))] == pytest.approx(37.5, abs=fs_hz / 128)
    # the columns average Welch's windows: the mean PSD equals scipy's Welch of the whole series
    f, p = welch(imu["acc_x_mps2"].to_numpy(), fs=fs_hz, nperseg=128)
    k = np.argmax(p)
    assert 10 * np.log10(p[k]) == pytest.approx(np.log10(np.mean(10 ** (z[k] / 10))) * 10, abs=0.2)
    assert fig.layout.xaxis.title.text == "t [s]" and plots.is_time_panel(fig)
    assert plots.spectrogram(imu.iloc[:50], ["acc_x_mps2"], "x", "m/s²") is None


def test_the_demo_page_opens_with_the_summary_and_says_which_panels_have_no_data(tmp_path):
    from pipeline.io.ingest import outputs_for, run_ingest
    from pipeline.report.flight import build_flight_report
    from pipeline.simulate.demo import write_demo_flight

    write_demo_flight(tmp_path / "demo.bin", seed=1, duration_s=30.0)
    run_ingest({"log": tmp_path / "demo.bin"}, outputs_for(tmp_path / "ingest"), None, flight_id="demo")
    page = tmp_path / "demo.html"
    build_flight_report(tmp_path / "ingest", page, template=ROOT / "reports" / "templates" / "flight.html.j2",
                        plotly_js="plotly.min.js", vehicle="sim-quad")
    text = html.unescape(page.read_text())
    head = text[:text.index("3-D path")]
    for row in ("UTC at t = 0", "<td>sim-quad</td>", "ArduCopter 4.5.0", "max tilt", "GPS fix share", "worst warning"):
        assert row in head, row
    assert "Accelerometer spectrogram (raw, sensor frame)" in text and "Gyroscope spectrogram" in text
    assert "Estimator flags (EKF status, XKF flags, estimator_status): no data in this flight" in text
    assert text.index("Vibration") < text.index("Accelerometer spectrogram") < text.index("Battery") \
        < text.index("Estimator flags") < text.index("Maneuver timeline") < text.index("<h2>Log messages")
