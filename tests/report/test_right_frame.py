"""Right data, right frame (issue 13, item 1): the flight page's body-frame panels plot the
preprocessed, mount-corrected state; raw sensor panels say "sensor frame"."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers import realdata_file

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.realdata
@pytest.mark.slow  # renders the husky flight page (about 3 s); the full suite keeps it
def test_the_husky_page_plots_the_mount_corrected_state_attitude_with_roll_near_zero(tmp_path):
    from pipeline.config import load_config
    from pipeline.io.ingest import outputs_for, run_ingest
    from pipeline.io.parquet import read_flightlog, read_table
    from pipeline.preprocess.run import run_preprocess
    from pipeline.report import plots
    from pipeline.report.flight import STATE_FRAME, attitude_source, build_flight_report

    ing = tmp_path / "ingest" / "husky-ros1"
    run_ingest({"log": realdata_file("ros1_husky_imu_gps/test1.bag")}, outputs_for(ing), None,
               flight_id="husky-ros1")
    pre = {k: tmp_path / f"{k}.parquet" for k in ("state", "segments", "calibration")}
    run_preprocess({"meta": ing / "meta.json"}, {**pre, "info": tmp_path / "info.json"},
                   load_config()["preprocess"], vehicle="husky")
    log, state = read_flightlog(ing), read_table(pre["state"])

    # the raw attitude stream is the rotated imu_link's orientation: roll ≈ +90° (the old page)
    raw_t, raw, raw_frame = attitude_source(None, log)
    assert np.median(np.degrees(raw[0])) == pytest.approx(90.0, abs=10.0)
    assert "not mount-corrected" in raw_frame

    rows, euler, frame = attitude_source(state, log)
    assert frame == STATE_FRAME
    np.testing.assert_array_equal(euler[0], state["roll_rad"].dropna().to_numpy())
    fig = plots.attitude(rows, euler, log["setpoint"], frame=frame)
    roll = np.asarray(fig.data[0].y, float)
    assert fig.data[0].name == "roll [°]"
    assert np.max(np.abs(roll)) < 10.0 and abs(np.median(roll)) < 3.0   # a ground robot, level

    page = tmp_path / "husky.html"
    build_flight_report(ing, page, template=ROOT / "reports" / "templates" / "flight.html.j2",
                        plotly_js="plotly.min.js", state=pre["state"], segments=pre["segments"],
                        calibration=pre["calibration"])
    text = page.read_text()
    assert f"Attitude ({STATE_FRAME}; ZYX Euler" in text
    assert f"Body rates ({STATE_FRAME})" in text and "Body rates vs setpoint" not in text   # no rate setpoint logged
    assert "Accelerometer (raw, sensor frame)" in text and "Gyroscope (raw, sensor frame)" in text
    assert "FRD)" not in text.replace(f"{STATE_FRAME})", "")   # no raw panel claims the body frame
