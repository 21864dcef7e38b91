"""The flight page of a flight whose ingest failed: the reason, never "None"."""

from __future__ import annotations

import html
from pathlib import Path

from pipeline.io.ingest import outputs_for, run_ingest
from pipeline.report.flight import build_flight_report

ROOT = Path(__file__).resolve().parents[2]


def test_a_failed_flight_page_shows_the_reason_once_and_no_none_and_no_meaningless_fields(tmp_path):
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"garbage" * 50)
    res = run_ingest({"log": bad}, outputs_for(tmp_path / "ingest" / "bad"), None, flight_id="bad")
    assert res.status == "failed" and res.error
    page = tmp_path / "bad.html"
    build_flight_report(tmp_path / "ingest" / "bad", page, template=ROOT / "reports" / "templates" / "flight.html.j2",
                        plotly_js="plotly.min.js")
    text = page.read_text()
    assert "None" not in text
    assert text.count(html.escape(res.error)) == 1           # once, under the title
    for field in ("<th>duration</th>", "<th>reader</th>", "<th>diagnostics</th>", "0.0 s", "<th>reason</th>",
                  "worst warning"):
        assert field not in text, field
    assert "<th>source</th>" in text and "failed (the reason is above)" in text


def _small_flight(tmp_path: Path, *, calibration: dict | None = None, site=(0.0, 0.0, -1.5)):
    """A 20 s flight (IMU, local position), 3 bytes skipped and 1 record dropped by ingest, a
    preprocessed state with the given barometric ``calibration`` diagnostics and an (empty) EKF
    estimate whose radar site is ``site``."""
    import numpy as np
    import pandas as pd

    from pipeline.io import schema
    from pipeline.io.base import FlightLog
    from pipeline.io.parquet import write_flightlog, write_table

    t = np.arange(0, 200) * 10**8
    def stream(name, **cols):
        df = pd.DataFrame({"t_ns": t, "instance": np.zeros(len(t), np.uint8), "src": "X", **cols})
        return df.reindex(columns=list(dict.fromkeys(["t_ns", "instance", "src", *cols,
                                                      *(c.name for c in schema.STREAMS[name])])))
    log = FlightLog.from_streams(
        schema.new_meta(flight_id="small", status="ok", source_format="ardupilot_dataflash", reader="dataflash",
                        reader_version="3"),
        {"imu": stream("imu", acc_z_mps2=np.full(len(t), -9.81)),
         "local_position": stream("local_position", pos_n_m=t * 1e-9, pos_e_m=0.0 * t, pos_d_m=-5.0 + 0 * t)})
    log.meta["diagnostics"].update(bytes_skipped=3, records_dropped={"truncated": 1})
    write_flightlog(log, tmp_path / "ingest")
    st = schema.empty("state").reindex(range(len(t)))
    st["t_ns"], st["pos_n_m"], st["pos_e_m"], st["pos_d_m"], st["gap"] = t, t * 1e-9, 0.0, -5.0, False
    state = tmp_path / "state.parquet"
    write_table(st, state, schema.STATE, name="state",
                extra={"preprocess": {"n_samples": len(t), "rate_hz": 10.0, "sources": {"position": "gps"},
                                      "calibration": calibration or {"method": "none", "regions": [],
                                                                     "notes": ["no barometer"]}}})
    est = tmp_path / "ekf.parquet"
    write_table(schema.empty("estimate"), est, schema.ESTIMATE, name="estimate",
                extra={"status": "ok", "n_steps": 0, "n_predict_only": 0, "radar": "stream",
                       "radar_site_ned_m": list(site), "radar_site_from": "meta.json", "q": 3.0,
                       "reference": "truth"})
    page = tmp_path / "small.html"
    build_flight_report(tmp_path / "ingest", page, template=ROOT / "reports" / "templates" / "flight.html.j2",
                        plotly_js="plotly.min.js", state=state, estimates={"ekf": est})
    return page


def test_the_barometric_calibration_is_a_table_of_offset_drift_rms_and_points_per_region(tmp_path):
    cal = {"method": "rangefinder", "n_candidates": 1411, "n_used": 789, "notes": [],
           "regions": [{"region": 0, "t_start_s": 4.05, "t_end_s": 12.65, "t_ref_s": 8.35, "offset_m": -1.54256,
                        "drift_mps": -0.004133, "n_points": 173, "rms_m": 0.025907},
                       {"region": 1, "t_start_s": 12.7, "t_end_s": 21.3, "t_ref_s": 17.0, "offset_m": -1.5907,
                        "drift_mps": -0.004133, "n_points": 172, "rms_m": 0.031145}]}
    text = html.unescape(_small_flight(tmp_path, calibration=cal).read_text())
    assert "<h2>Barometric calibration (against the rangefinder; 789 of 1411 candidate points used)</h2>" in text
    assert ("<tr><th>region</th><th>t start [s]</th><th>t end [s]</th><th>offset [m]</th><th>drift [m/s]</th>"
            "<th>RMS of fit [m]</th><th>points used</th></tr>") in text
    assert "<tr><td>0</td><td>4.0</td><td>12.7</td><td>-1.543</td><td>-0.00413</td><td>0.026</td><td>173</td></tr>" in text
    assert "<td>1</td><td>12.7</td><td>21.3</td><td>-1.591</td>" in text


def test_a_missing_barometer_is_said_once_in_the_calibration_heading(tmp_path):
    from pipeline.report.flight import calibration_table

    title, _, rows = calibration_table({"calibration": {"method": "none", "notes": ["no barometer"], "regions": []}})
    assert title == "Barometric calibration (no barometer)" and rows == []


def test_the_barometric_calibration_heading_of_a_flight_without_a_barometer_is_not_repeated_under_itself(tmp_path):
    import re

    text = html.unescape(re.sub(r"<script.*?</script>", "", _small_flight(tmp_path).read_text(), flags=re.S))
    assert text.count("Barometric calibration (no barometer)") == 1
    assert '<h2>Barometric calibration (no barometer)</h2>\n<p class="absent">no data in this flight</p>' in text


def test_the_facts_read_as_text_without_python_reprs_and_every_page_is_marked_english(tmp_path):
    import re

    raw = _small_flight(tmp_path).read_text()
    text = html.unescape(re.sub(r"<script.*?</script>", "", raw, flags=re.S))
    assert "<th>diagnostics</th><td>3 bytes skipped; 1 record dropped (truncated)</td>" in text
    assert "(site (0, 0, -1.5) m NED from meta.json)" in text
    for leak in ('{"', "{'", "[0.0", "': ", "None"):
        assert leak not in text, leak
    assert raw.startswith('<!doctype html>\n<html lang="en">')
    from pipeline.report.pages import with_lang

    for tpl in (ROOT / "reports" / "templates").glob("[!_]*.html.j2"):
        assert '<html lang="en">' in with_lang(tpl.read_text()), tpl.name
    assert with_lang('<html lang="de"><body></body></html>') == '<html lang="de"><body></body></html>'
