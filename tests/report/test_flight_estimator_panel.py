"""The flight page's estimator-flags panel (issue 13 item 2): every bit ever set of the
``estimator_status`` stream as a band over the intervals where it is set, named by source,
and the innovation test ratios with the gate at 1; an empty stream keeps the one-line "no data"."""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.io import schema
from pipeline.report import plots
from pipeline.report.flight import ESTIMATOR_FLAGS_TITLE, ESTIMATOR_RATIOS_TITLE, estimator_flag_panels

ROOT = Path(__file__).resolve().parents[2]


def _est(src: str, inst: int, t_s, **cols) -> pd.DataFrame:
    t = np.asarray(t_s, float)
    df = pd.DataFrame({"t_ns": (t * 1e9).astype(np.int64), "instance": np.full(len(t), inst, np.uint8),
                       "src": src, **cols})
    for c in schema.STREAMS["estimator_status"]:
        if c.name not in df:
            df[c.name] = pd.array([pd.NA] * len(t), dtype="Int64") if c.dtype == "Int64" else np.nan
    return df


def _bands(fig) -> dict[str, list]:
    return {t.name: list(t.x) for t in fig.data}


def test_an_empty_estimator_stream_keeps_the_one_line_no_data():
    assert estimator_flag_panels(None) == [(ESTIMATOR_FLAGS_TITLE, None)]
    assert estimator_flag_panels(schema.empty("estimator_status")) == [(ESTIMATOR_FLAGS_TITLE, None)]


def test_each_bit_ever_set_is_a_band_from_the_report_that_sets_it_to_the_one_that_clears_it():
    t = [0.0, 1.0, 2.0, 3.0, 4.0]
    # attitude (bit 0) always, horiz_vel (bit 1) from 1 s until the report at 3 s clears it
    ss = pd.array([1, 3, 3, 1, 1], dtype="Int64")
    fs = pd.array([0, 0, 0, 0, 128], dtype="Int64")            # not_initialised in the last report
    est = pd.concat([_est("XKF4", 0, t, solution_flags=ss, fault_flags=fs, vel_test_ratio=[0.1, 0.5, 1.5, 0.2, 0.1],
                          tas_test_ratio=np.zeros(5)),
                     _est("XKF4", 1, t, solution_flags=pd.array([1] * 5, dtype="Int64"),
                          vel_test_ratio=np.full(5, 0.3), tas_test_ratio=np.zeros(5))], ignore_index=True)
    panels = estimator_flag_panels(est)
    assert [p[0] for p in panels] == [ESTIMATOR_FLAGS_TITLE, ESTIMATOR_RATIOS_TITLE]
    flags, ratios = panels[0][1], panels[1][1]
    bands = _bands(flags)
    assert bands == {"solution: attitude (XKF4 0)": [0.0, 4.0, None],
                     "solution: horiz_vel (XKF4 0)": [1.0, 3.0, None],
                     "fault: not_initialised (XKF4 0)": [4.0, 4.0, None],
                     "solution: attitude (XKF4 1)": [0.0, 4.0, None]}
    assert list(flags.layout.yaxis.ticktext) == list(bands)          # one named row per band, in order
    # one colour per flag column, the same for every lane
    col = {t.name: t.line.color for t in flags.data}
    assert col["solution: attitude (XKF4 0)"] == col["solution: horiz_vel (XKF4 0)"] == col["solution: attitude (XKF4 1)"]
    assert col["fault: not_initialised (XKF4 0)"] != col["solution: attitude (XKF4 0)"]
    assert [t.name for t in ratios.data] == ["velocity (XKF4 0)", "velocity (XKF4 1)"]
    assert list(ratios.data[0].y) == [0.1, 0.5, 1.5, 0.2, 0.1]
    gate = [s for s in ratios.layout.shapes if s.type == "line"]
    assert len(gate) == 1 and gate[0].y0 == gate[0].y1 == 1.0
    assert "always 0: true airspeed" in ratios.layout.title.text   # not fused: named, not drawn
    assert plots.is_time_panel(flags) and plots.is_time_panel(ratios)


def test_bit_names_follow_the_source_of_each_row():
    t = [0.0, 1.0]
    est = pd.concat([_est("EKF_STATUS_REPORT", 0, t, solution_flags=pd.array([1024, 1024], dtype="Int64")),
                     _est("ESTIMATOR_STATUS", 0, t, solution_flags=pd.array([1024, 0], dtype="Int64")),
                     _est("estimator_status", 0, t, fault_flags=pd.array([1024, 1024], dtype="Int64"))],
                    ignore_index=True)
    legacy = {"estimator_status": {"layout": "px4_legacy"}}
    names = list(_bands(estimator_flag_panels(est)[0][1]))
    assert names == ["solution: uninitialized (EKF_STATUS_REPORT 0)", "solution: gps_glitch (ESTIMATOR_STATUS 0)",
                     "fault: bad_acc_vertical (estimator_status 0)"]
    assert list(_bands(estimator_flag_panels(est, legacy)[0][1]))[2] == "fault: bad_vel_e (estimator_status 0)"
    assert len(estimator_flag_panels(est)) == 1  # no ratio logged: no ratio panel


def test_a_dataflash_flight_with_xkf4_draws_both_estimator_panels_on_the_page(tmp_path):
    from pipeline.io.dataflash.writer import DataFlashWriter
    from pipeline.io.ingest import outputs_for, run_ingest
    from pipeline.report.flight import build_flight_report

    p = tmp_path / "xkf4.bin"
    with DataFlashWriter(p) as w:
        w.define("IMU", 162, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        w.define("XKF4", 164, "QBcccccfffHBIHb", "TimeUS,C,SV,SP,SH,SM,SVT,errRP,OFN,OFE,FS,TS,SS,GPS,PI")
        for k in range(50):
            w.write("IMU", TimeUS=1_000_000 + 20_000 * k, I=0, AccZ=-9.8)
            if k % 5 == 0:
                for c in (0, 1):
                    w.write("XKF4", TimeUS=1_000_000 + 20_000 * k, C=c, SV=0.1 * (k // 5), SP=0.2, SH=0.3, SM=0.0,
                            SVT=0.0, FS=0, TS=0, SS=(1 | 1 << 13) if k >= 10 else 1, GPS=256 if k < 10 else 0, PI=0)
    run_ingest({"log": p}, outputs_for(tmp_path / "ingest"), None, flight_id="xkf4")
    page = tmp_path / "xkf4.html"
    build_flight_report(tmp_path / "ingest", page, template=ROOT / "reports" / "templates" / "flight.html.j2",
                        plotly_js="plotly.min.js")
    text = html.unescape(page.read_text())
    assert f"{ESTIMATOR_FLAGS_TITLE}: no data" not in text
    for drawn in ("solution: using_gps (XKF4 1)", "GPS check failed: bad_fix (XKF4 0)",
                  "Estimator innovation test ratios (gate at 1); always 0: magnetometer, true airspeed"):
        assert drawn in text, drawn
    assert text.index("Battery") < text.index(ESTIMATOR_FLAGS_TITLE) < text.index(ESTIMATOR_RATIOS_TITLE) \
        < text.index("Maneuver timeline")
