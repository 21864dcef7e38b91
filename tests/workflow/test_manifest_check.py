"""The workflow checks its manifest at start-up: a bad row stops the dry run with one line."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SNAKEMAKE = str(Path(sys.executable).parent / "snakemake")
HEADER = "flight_id\tpath\tvehicle\trole\tlabels\tformat\tnotes\n"
DEMO = "demo-quad\tresults/sim/demo/demo-quad.bin\tsim-quad\ttest\tnone\t\tdemo"


@pytest.mark.slow
def test_an_unknown_vehicle_stops_the_dry_run_with_one_line_naming_file_line_and_flight(tmp_path):
    wd = tmp_path / "wf"
    wd.mkdir()
    for name in ("Snakefile", "rules", "reports", "profiles"):
        src = ROOT / name
        (shutil.copytree if src.is_dir() else shutil.copy)(src, wd / name)
    (wd / "datasets").mkdir()
    shutil.copy(ROOT / "datasets" / "config.yaml", wd / "datasets" / "config.yaml")
    (wd / "datasets" / "flights.tsv").write_text(
        HEADER + DEMO + "\n" + "typo\tresults/sim/demo/demo-quad.bin\tsim-qaud\ttest\tnone\t\tx\n")
    p = subprocess.run([SNAKEMAKE, "-n", "--cores", "1"], cwd=wd, capture_output=True, text=True,
                       timeout=300, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert p.returncode != 0
    lines = [l for l in (p.stdout + p.stderr).splitlines() if l.startswith("uavpipe:")]
    assert len(lines) == 1, p.stdout + p.stderr
    assert lines[0].startswith("uavpipe: datasets/flights.tsv:3: flight typo: unknown vehicle 'sim-qaud'")
    assert "Traceback" not in p.stdout + p.stderr
