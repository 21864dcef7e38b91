"""The end-of-run summary (pipeline/report/summary.py) on a tiny fake results tree."""

from __future__ import annotations

import json
from pathlib import Path

from pipeline.report.summary import flight_status, run_summary


def _meta(res: Path, flight: str, **meta) -> None:
    d = res / "ingest" / flight
    d.mkdir(parents=True)
    (d / "meta.json").write_text(json.dumps(meta))


def _tree(tmp_path: Path) -> Path:
    res = tmp_path / "results"
    _meta(res, "good", status="ok", diagnostics={"warnings": []})
    _meta(res, "half", status="partial", diagnostics={"bytes_skipped": 120, "records_dropped": {"GPS": 3}})
    _meta(res, "broken", status="failed", error="unrecognised log format")
    _meta(res, "late", status="ok", diagnostics={})
    (res / "state").mkdir()
    (res / "state" / "good.json").write_text(json.dumps({"status": "ok"}))
    (res / "state" / "half.json").write_text(json.dumps({"status": "ok"}))  # no state json: failed
    (res / "state" / "late.json").write_text(json.dumps({"status": "failed", "error": "no IMU rows"}))
    (res / "models" / "sim").mkdir(parents=True)
    (res / "models" / "sim" / "meta.json").write_text(json.dumps({"status": "ok"}))
    (res / "models" / "f3a").mkdir(parents=True)
    (res / "models" / "f3a" / "meta.json").write_text(json.dumps({"status": "failed", "error": "no training flights"}))
    for f in ("good", "half", "broken", "late"):               # what the index is built from
        for p in (res / "segments" / f"{f}.parquet", res / "report" / "flights" / f"{f}.html"):
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text("")
    for m in ("sim", "f3a"):
        (res / "report" / "models" / f"{m}.html").parent.mkdir(parents=True, exist_ok=True)
        (res / "report" / "models" / f"{m}.html").write_text("")
    (res / "index.html").write_text("<html></html>")
    return res


def test_the_summary_counts_ok_partial_and_failed_flights_with_their_reasons(tmp_path):
    res = _tree(tmp_path)
    text = run_summary(["good", "half", "broken", "late"], ["sim", "f3a"], res,
                       skipped={"ghost": "/nonexistent/x.bin not found"})
    lines = text.splitlines()
    assert lines[0] == "uavpipe: 4 flight(s): 1 ok, 1 partial, 2 failed; 1 manifest row(s) skipped"
    assert "  failed   broken: ingest: unrecognised log format" in lines
    assert "  failed   late: preprocess: no IMU rows" in lines
    assert "  partial  half: 120 bytes skipped, 3 records dropped (GPS)" in lines
    assert "  skipped  ghost: /nonexistent/x.bin not found" in lines
    assert "  model sets: sim ok, f3a failed (no training flights)" in lines
    assert lines[-1] == f"  report: {res / 'index.html'}"
    assert not any("good" in l for l in lines[1:])  # ok flights are counted, not listed


def test_a_corrupt_status_file_is_a_reason_not_an_exception(tmp_path):
    res = tmp_path / "results"
    (res / "ingest" / "bad").mkdir(parents=True)
    (res / "ingest" / "bad" / "meta.json").write_text("{not json")
    state, why = flight_status("bad", res)
    assert state == "failed" and "meta.json: not JSON" in why


def test_an_interrupted_run_says_what_did_not_run_and_that_the_report_is_missing(tmp_path):
    text = run_summary(["never"], ["sim"], tmp_path / "results")
    assert "1 not run" in text.splitlines()[0]
    assert "  not run  never: no ingest output" in text
    assert "model sets: sim not run" in text
    assert text.endswith("index.html (not written)")


def test_a_model_set_trained_before_its_data_was_rewritten_is_reported_stale(tmp_path):
    import os
    res = _tree(tmp_path)
    data = res / "sim" / "sets" / "M1_train.parquet"
    data.parent.mkdir(parents=True)
    data.write_text("")
    meta = res / "models" / "sim" / "meta.json"
    t = meta.stat().st_mtime_ns
    os.utime(data, ns=(t - 10**9, t - 10**9))          # trained after its data: ok
    inputs = {"sim": [data]}
    assert "  model sets: sim ok, f3a failed (no training flights)" in \
        run_summary(["good"], ["sim", "f3a"], res, model_inputs=inputs).splitlines()
    os.utime(data, ns=(t + 10**9, t + 10**9))          # the sets rebuilt, the run stopped before training
    assert f"  model sets: sim stale (trained before {data} was rewritten), f3a failed (no training flights)" \
        in run_summary(["good"], ["sim", "f3a"], res, model_inputs=inputs).splitlines()
    data.unlink()
    assert f"  model sets: sim stale ({data} missing), f3a failed (no training flights)" \
        in run_summary(["good"], ["sim", "f3a"], res, model_inputs=inputs).splitlines()
