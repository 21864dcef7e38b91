"""The workflow checks its manifest at start-up: a bad row stops the dry run with one line."""

from __future__ import annotations

import os
import subprocess

import pytest

from helpers_workflow import SNAKEMAKE, copy_workflow

DEMO = "demo-quad\tresults/sim/demo/demo-quad.bin\tsim-quad\ttest\tnone\t\tdemo"


@pytest.mark.slow
def test_an_unknown_vehicle_stops_the_dry_run_with_one_line_naming_file_line_and_flight(tmp_path):
    wd = copy_workflow(tmp_path / "wf", [DEMO, "typo\tresults/sim/demo/demo-quad.bin\tsim-qaud\ttest\tnone\t\tx"], tiny=False)
    p = subprocess.run([SNAKEMAKE, "-n", "--cores", "1"], cwd=wd, capture_output=True, text=True,
                       timeout=300, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert p.returncode != 0
    lines = [l for l in (p.stdout + p.stderr).splitlines() if l.startswith("uavpipe:")]
    assert len(lines) == 1, p.stdout + p.stderr
    assert lines[0].startswith("uavpipe: datasets/flights.tsv:3: flight typo: unknown vehicle 'sim-qaud'")
    assert "Traceback" not in p.stdout + p.stderr


@pytest.mark.slow
def test_a_finished_run_prints_the_summary_with_skipped_rows_and_the_report_path(tmp_path):
    wd = copy_workflow(tmp_path / "wf", [DEMO, "ghost\t/nonexistent/x.bin\tgeneric\tnone\tnone\t\tgone"], tiny=False)
    # one flight's ingest only (seconds): the handler still summarises the whole run
    p = subprocess.run([SNAKEMAKE, "--cores", "1", "results/ingest/demo-quad/meta.json"], cwd=wd,
                       capture_output=True, text=True, timeout=300,
                       env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert p.returncode == 0, p.stderr[-3000:]
    assert "uavpipe: 1 flight(s): 1 ok, 0 failed; 1 manifest row(s) skipped" in p.stderr
    assert "  skipped  ghost: /nonexistent/x.bin not found" in p.stderr
    assert "  model sets: sim not run, simekf not run, f3a not run" in p.stderr
    assert "  report: results/index.html (not written)" in p.stderr
