"""Flight-page panels read in the units of what they plot (report audit, item 2): an absolute
barometer is drawn about its start beside the relative heights, non-PWM actuator outputs are not
labelled µs, battery volts, amps and percent each get an axis, and an IMU spectrogram is taken at
the IMU's own rate (none from a 1 Hz telemetry IMU)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline.io import schema
from pipeline.io.base import FlightLog
from pipeline.io.parquet import write_flightlog
from pipeline.report import flight, plots

ROOT = Path(__file__).resolve().parents[2]


def _stream(name: str, t_s: np.ndarray, instance: int = 0, **cols) -> pd.DataFrame:
    n = len(t_s)
    df = pd.DataFrame({"t_ns": np.round(t_s * 1e9).astype(np.int64), "instance": np.full(n, instance, np.uint8),
                       "src": "X", **cols})
    return df.reindex(columns=list(dict.fromkeys(["t_ns", "instance", "src", *cols,
                                                  *(c.name for c in schema.STREAMS[name])])))


def _page_figures(tmp_path: Path, monkeypatch, streams: dict) -> dict:
    """Build a flight page of ``streams`` (a PX4-like log) and return its ``{title: figure}``."""
    log = FlightLog.from_streams(schema.new_meta(flight_id="px4", status="ok", source_format="px4_ulog",
                                                 reader="ulog", reader_version="1"), streams)
    write_flightlog(log, tmp_path / "ingest")
    seen = {}
    real = flight.figure_divs

    def capture(figs):
        seen.update({title: fig for title, fig in figs})
        return real(figs)

    monkeypatch.setattr(flight, "figure_divs", capture)
    flight.build_flight_report(tmp_path / "ingest", tmp_path / "px4.html",
                               template=ROOT / "reports" / "templates" / "flight.html.j2", plotly_js="plotly.min.js")
    return seen


def _one(figs: dict, prefix: str):
    hits = [(t, f) for t, f in figs.items() if t.startswith(prefix)]
    assert len(hits) == 1, list(figs)
    return hits[0]


def _axis_title(fig, yaxis: str | None) -> str:
    name = "yaxis" if yaxis in (None, "y") else f"yaxis{yaxis[1:]}"
    return getattr(fig.layout, name).title.text or ""


def test_an_absolute_barometer_is_drawn_relative_to_its_start_beside_the_relative_heights(tmp_path, monkeypatch):
    t = np.arange(0, 60, 0.1)
    climb = np.clip(t - 10, 0, 20)                                      # 0 -> 20 m
    figs = _page_figures(tmp_path, monkeypatch, {
        "baro": _stream("baro", t, alt_rel_m=276.0 + climb),            # ULog: ISA pressure altitude
        "local_position": _stream("local_position", t, pos_n_m=0 * t, pos_e_m=0 * t, pos_d_m=-climb)})
    _, fig = _one(figs, "Altitude")
    baro = [tr for tr in fig.data if tr.name.startswith("baro")]
    assert len(baro) == 1 and "relative to its start" in baro[0].name and "276.0 m" in baro[0].name
    y = np.asarray(baro[0].y, float)
    assert abs(y[0]) < 1e-9 and y.max() == pytest.approx(20.0)          # the track's scale, not 276-296 m


def test_normalised_and_raw_actuator_outputs_are_not_labelled_microseconds(tmp_path, monkeypatch):
    t = np.arange(0, 20, 0.05)
    figs = _page_figures(tmp_path, monkeypatch, {"control": pd.concat([
        _stream("control", t, 0, servo_1_us=np.sin(t), servo_2_us=-np.sin(t)),      # PX4 [-1, 1] outputs
        _stream("control", t, 1, servo_1_us=1500 + 400 * np.sin(t)),               # a PWM group
        _stream("control", t, 2, servo_1_us=4000 + 1000 * np.sin(t))])})           # ESC command units
    _, fig = _one(figs, "Actuator outputs")
    by_axis = {}
    for tr in fig.data:
        by_axis.setdefault(_axis_title(fig, tr.yaxis), []).append(tr.name)
    assert by_axis["pulse width [µs]"] == ["servo output 1 (instance 1) [µs]"]
    assert by_axis["normalised output [−1…1]"] == ["servo output 1 (instance 0) [−1…1]",
                                                    "servo output 2 (instance 0) [−1…1]"]
    assert by_axis["output [raw command units, not µs]"] == ["servo output 1 (instance 2) [raw units]"]


def test_pwm_outputs_keep_their_microseconds_and_a_zero_channel_reads_like_its_group():
    t = np.arange(0, 10, 0.1)
    ctl = _stream("control", t, servo_1_us=1100 + 0 * t, servo_2_us=0 * t)
    fig = plots.actuator_outputs(ctl, ["servo_1_us", "servo_2_us"])
    assert [tr.name for tr in fig.data] == ["servo output 1 [µs]", "servo output 2 [µs]"]
    assert fig.layout.yaxis.title.text == "pulse width [µs]" and "yaxis2" not in fig.layout.to_plotly_json()
    assert plots.output_kind([0.0, 0.2, 1.0]) == "normalised01" and plots.output_kind([0, 0]) is None
    assert plots.output_kind([0, 109, 970]) == "raw"               # a simulator's 0..1000: not PWM


def test_battery_volts_amps_and_percent_never_share_an_axis(tmp_path, monkeypatch):
    t = np.arange(0, 30, 0.5)
    figs = _page_figures(tmp_path, monkeypatch, {"battery": _stream(
        "battery", t, voltage_V=np.linspace(16.8, 15.0, len(t)), current_A=np.full(len(t), 12.0),
        remaining_frac=np.linspace(1.0, 0.7, len(t)))})
    _, fig = _one(figs, "Battery")
    units = {}
    for tr in fig.data:
        units.setdefault(tr.yaxis or "y", set()).add(tr.name.split("[")[1].rstrip("]"))
    assert sorted(map(sorted, units.values())) == [["%"], ["A"], ["V"]]
    for ax, (u,) in units.items():
        assert f"[{u}]" in _axis_title(fig, ax)


def test_a_one_hertz_telemetry_imu_draws_no_spectrogram_and_the_panel_says_why(tmp_path, monkeypatch):
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.6, 1.2, 600))                      # a tlog's RAW_IMU, ~1 Hz
    figs = _page_figures(tmp_path, monkeypatch, {"imu": _stream(
        "imu", t, **{f"acc_{a}_mps2": rng.standard_normal(len(t)) for a in "xyz"},
        **{f"gyr_{a}_radps": rng.standard_normal(len(t)) for a in "xyz"})})
    for name in ("Accelerometer spectrogram", "Gyroscope spectrogram"):
        title, fig = _one(figs, name)
        assert fig is None and "IMU logged at 1.12 Hz, below the 20 Hz" in title, title


def test_a_kilohertz_imu_spectrogram_uses_half_second_windows_at_its_own_rate():
    fs, n = 1000.0, 20_000
    t = np.arange(n) / fs
    imu = _stream("imu", t, acc_x_mps2=np.sin(2 * np.pi * 123.0 * t), acc_y_mps2=0 * t, acc_z_mps2=-9.81 + 0 * t)
    fig = plots.spectrogram(imu, ["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"], "Accelerometer spectrogram", "m/s²")
    f = np.asarray(fig.data[0].y, float)
    assert len(f) == 257 and f[1] - f[0] < 2.0                   # 512-sample windows: 1.95 Hz bins, not 7.8
    z = np.asarray(fig.data[0].z, float)
    assert f[np.argmax(z.mean(axis=1))] == pytest.approx(123.0, abs=2.0)
    assert "fs = 1000 Hz" in fig.layout.title.text


def test_the_body_rate_panel_and_its_setpoint_are_drawn_in_degrees_per_second_as_the_summary_states_them(tmp_path, monkeypatch):
    t = np.arange(0, 10, 0.1)
    p = 0.5 * np.sin(t)                                                  # rad/s
    figs = _page_figures(tmp_path, monkeypatch, {
        "imu": _stream("imu", t, gyr_x_radps=p, gyr_y_radps=0 * t, gyr_z_radps=0 * t, acc_z_mps2=-9.81 + 0 * t),
        "setpoint": _stream("setpoint", t, p_radps=0.4 * np.sin(t))})
    _, fig = _one(figs, "Body rates")
    assert fig.layout.yaxis.title.text == "body rate [°/s]"
    tr = {x.name: x for x in fig.data}
    assert set(tr) == {"roll rate [°/s]", "pitch rate [°/s]", "yaw rate [°/s]", "roll rate setpoint [°/s]"}
    np.testing.assert_allclose(np.asarray(tr["roll rate [°/s]"].y, float), np.degrees(p), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(tr["roll rate setpoint [°/s]"].y, float), np.degrees(0.4 * np.sin(t)),
                               rtol=1e-12)
