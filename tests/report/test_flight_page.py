"""The flight page of a flight whose ingest failed: the reason, never "None"."""

from __future__ import annotations

import html
from pathlib import Path

from pipeline.io.ingest import outputs_for, run_ingest
from pipeline.report.flight import build_flight_report

ROOT = Path(__file__).resolve().parents[2]


def test_a_failed_flight_page_shows_the_reason_and_no_none(tmp_path):
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"garbage" * 50)
    res = run_ingest({"log": bad}, outputs_for(tmp_path / "ingest" / "bad"), None, flight_id="bad")
    assert res.status == "failed" and res.error
    page = tmp_path / "bad.html"
    build_flight_report(tmp_path / "ingest" / "bad", page, template=ROOT / "reports" / "templates" / "flight.html.j2",
                        plotly_js="plotly.min.js")
    text = page.read_text()
    assert "None" not in text
    assert "none took the file" in text
    assert html.escape(res.error) in text
