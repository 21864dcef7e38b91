"""The flight page's estimate panels: error against the reference per group, the EKF+HMM mode
timeline, and one line saying why where a panel has no data."""

from __future__ import annotations

import html
from pathlib import Path

from helpers_estimate import ingested_flight
from pipeline.config import validate_config
from pipeline.estimate.run import ESTIMATORS, job_config, run_estimate
from pipeline.report.flight import build_flight_report

ROOT = Path(__file__).resolve().parents[2]
TEMPLATE = ROOT / "reports" / "templates" / "flight.html.j2"


def _page(tmp, inputs, estimates=True):
    out = {e: tmp / e / "f1.parquet" for e in ESTIMATORS}
    res = run_estimate(inputs, out, job_config(validate_config({})["estimate"], None), flight_id="f1")
    page = tmp / "f1.html"
    build_flight_report(Path(inputs["meta"]).parent, page, template=TEMPLATE, plotly_js="plotly.min.js",
                        state=inputs["state"], estimates=out if estimates else None)
    return res, page.read_text()


def test_error_panels_per_group_and_the_ekf_hmm_placeholder_reason(tmp_path):
    res, text = _page(tmp_path, ingested_flight(tmp_path))
    assert res.status == "partial"
    for g in ("position", "velocity", "acceleration"):
        assert f"Estimation error vs truth: {g}" in text
    assert "EKF + RTS (RMSE" in text and "EKF+HMM (RMSE" not in text
    # the EKF+HMM has no model set here: its timeline says why, in one line
    assert f"EKF+HMM mode timeline ({html.escape(res.error)}): no data in this flight" in text
    assert "151 steps (0 predict-only), radar stream" in text


def test_a_flight_without_radar_or_estimates_says_so_in_one_line(tmp_path):
    res, text = _page(tmp_path, ingested_flight(tmp_path, radar=False))
    assert res.status == "failed"
    assert f"Estimation error (no estimates: {html.escape(res.error)}): no data in this flight" in text
    _, text = _page(tmp_path / "b", ingested_flight(tmp_path / "b"), estimates=False)
    assert "Estimates (the flight&#39;s vehicle is not in estimate.vehicles): no data in this flight" in text
    assert "None" not in text
