"""The end-of-run summary (pipeline/report/summary.py): a preprocess that never finished is a
failed flight, and the report line says when results/index.html is stale or missing."""

from __future__ import annotations

import json
import os
from pathlib import Path

from pipeline.report.summary import flight_status, run_summary


def _flight(res: Path, flight: str, *, state: bool = True, page: bool = True) -> list[Path]:
    """A flight's ingest meta.json, preprocess json and (``page``) segments table and page;
    returns the files written."""
    files = {res / "ingest" / flight / "meta.json": json.dumps({"status": "ok", "diagnostics": {}})}
    if state:
        files[res / "state" / f"{flight}.json"] = json.dumps({"status": "ok"})
    if page:
        files[res / "segments" / f"{flight}.parquet"] = ""
        files[res / "report" / "flights" / f"{flight}.html"] = "<html></html>"
    for p, text in files.items():
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return list(files)


def _age(path: Path, seconds_ago: float) -> None:
    t = path.stat().st_mtime - seconds_ago
    os.utime(path, (t, t))


def test_a_flight_whose_preprocess_crashed_without_its_state_json_counts_as_failed(tmp_path):
    res = tmp_path / "results"
    _flight(res, "good")
    _flight(res, "crashed", state=False)
    # not preprocessed yet (an ingest-only target): judged by its ingest
    assert flight_status("crashed", res) == ("ok", "")
    # its preprocess job started (the job log exists) and wrote no state json: it crashed
    log = res / "logs" / "preprocess_flight" / "crashed.log"
    log.parent.mkdir(parents=True)
    log.write_text("Traceback ...\nMemoryError\n")
    assert flight_status("crashed", res) == (
        "failed", f"preprocess did not finish (no {res / 'state' / 'crashed.json'})")
    text = run_summary(["good", "crashed"], [], res)
    assert text.splitlines()[0] == "uavpipe: 2 flight(s): 1 ok, 1 failed; 0 manifest row(s) skipped"
    assert f"  failed   crashed: preprocess did not finish (no {res / 'state' / 'crashed.json'})" in text


def test_an_index_older_than_a_flight_page_is_reported_stale_with_the_newest_input(tmp_path):
    res = tmp_path / "results"
    for p in _flight(res, "a") + _flight(res, "b"):
        _age(p, 120)
    (res / "index.html").write_text("<html></html>")
    _age(res / "index.html", 60)
    page = res / "report" / "flights" / "b.html"
    page.write_text("<html></html>")                     # rebuilt after the index, index not rewritten
    assert run_summary(["a", "b"], [], res).splitlines()[-1] == \
        f"  report: {res / 'index.html'} (stale: older than {page})"


def _report_line(res: Path, flights, model_sets) -> str:
    return run_summary(flights, model_sets, res).splitlines()[-1].removeprefix("  report: ")


def test_an_index_newer_than_its_inputs_is_current_and_a_missing_one_not_written(tmp_path):
    res = tmp_path / "results"
    files = _flight(res, "a")
    assert _report_line(res, ["a"], ["sim"]) == f"{res / 'index.html'} (not written)"
    for p, text in ((res / "models" / "sim" / "meta.json", "{}"), (res / "report" / "models" / "sim.html", "")):
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
        files.append(p)
    for p in files:
        _age(p, 60)
    (res / "index.html").write_text("<html></html>")
    assert _report_line(res, ["a"], ["sim"]) == str(res / "index.html")
    # a model set retrained after it makes it stale too
    _age(res / "models" / "sim" / "meta.json", -120)
    assert _report_line(res, ["a"], ["sim"]) == \
        f"{res / 'index.html'} (stale: older than {res / 'models' / 'sim' / 'meta.json'})"


def test_an_index_whose_flight_page_was_removed_by_a_failed_job_is_reported_stale(tmp_path):
    res = tmp_path / "results"
    for p in _flight(res, "a") + _flight(res, "b"):
        _age(p, 60)
    (res / "index.html").write_text("<html></html>")
    (res / "report" / "flights" / "b.html").unlink()        # Snakemake removes a failed job's output
    assert _report_line(res, ["a", "b"], []) == \
        f"{res / 'index.html'} (stale: {res / 'report' / 'flights' / 'b.html'} missing)"
