"""The study targets of rules/studies.smk: each plans only itself (and plotly.js), none is in
``all``, and the FlightCoach target without the real logs stops at start naming the file."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

#: each test runs Snakemake (a dry run): the full suite, not the fast lane
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
SNAKEMAKE = str(Path(sys.executable).parent / "snakemake")


def _dry(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([SNAKEMAKE, "--cores", "2", "-n", "--forceall", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=300, env={**os.environ, "PYTHONWARNINGS": "ignore"})


def _jobs(p: subprocess.CompletedProcess) -> dict[str, int]:
    out = p.stdout + p.stderr
    assert p.returncode == 0, out[-3000:]
    m = re.search(r"Job stats:\njob\s+count\n[- ]+\n(.*?)\ntotal", out, re.S)
    assert m, out[-3000:]
    return {r.split()[0]: int(r.split()[1]) for r in m.group(1).strip().splitlines()}


def test_the_seed000_target_plans_only_the_study_and_plotly_js():
    assert _jobs(_dry("study_seed000_classification")) == {"plotly_js": 1, "study_seed000_classification": 1}


def test_no_study_is_part_of_the_main_job():
    assert not [r for r in _jobs(_dry()) if r.startswith("study_")]


def test_the_flightcoach_target_without_real_logs_stops_naming_the_file(tmp_path):
    p = _dry("study_flightcoach_classification", "--config", f"realdata_dir={tmp_path}")
    assert p.returncode != 0
    line = [ln for ln in (p.stdout + p.stderr).splitlines() if "FlightCoach file not found" in ln]
    assert len(line) == 1 and str(tmp_path / "flightcoach_f3a_json") in line[0], p.stderr[-2000:]


def test_the_flightcoach_ekf_hmm_target_without_real_logs_stops_naming_the_file(tmp_path):
    p = _dry("study_flightcoach_ekf_hmm", "--config", f"realdata_dir={tmp_path}")
    assert p.returncode != 0
    line = [ln for ln in (p.stdout + p.stderr).splitlines() if "FlightCoach file not found" in ln]
    assert len(line) == 1 and str(tmp_path / "flightcoach_f3a_json") in line[0], p.stderr[-2000:]
    assert "flightcoach_ekf_hmm" in line[0]


def test_the_flightcoach_ekf_hmm_target_plans_only_the_study_and_plotly_js():
    from helpers import REALDATA, realdata_file

    realdata_file("flightcoach_f3a_json")
    assert _jobs(_dry("study_flightcoach_ekf_hmm", "--config", f"realdata_dir={REALDATA}")) == {
        "plotly_js": 1, "study_flightcoach_ekf_hmm": 1}


def test_the_bearing_only_target_plans_only_the_study_and_plotly_js():
    assert _jobs(_dry("study_bearing_only")) == {"plotly_js": 1, "study_bearing_only": 1}


def test_a_bearing_pair_without_its_flights_is_skipped_with_a_notice_and_the_main_job_still_plans(tmp_path):
    p = _dry("--config", f"realdata_dir={tmp_path}")
    jobs = _jobs(p)
    assert "estimate_bearing" not in jobs and "all" in jobs
    assert "skipping bearing pair austin-p23" in p.stderr


def _readme_config_commands() -> list[list[str]]:
    """The README's study commands that pass ``--config`` (the rest are planned above), split."""
    import shlex

    cmds = []
    for ln in (ROOT / "README.md").read_text().splitlines():
        ln = ln.strip()
        if ln.startswith(".venv/bin/snakemake") and " study_" in ln and "--config" in ln:
            cmds.append(shlex.split(ln.split(" #", 1)[0]))
    return cmds


def test_the_readme_study_commands_with_config_overrides_plan_their_study():
    # Snakemake leaves a nested --config value's scalars strings ('true'); the workflow types
    # them as the config file would (pipeline.config.command_line_overrides), so these validate
    cmds = _readme_config_commands()
    assert len(cmds) >= 2, "README.md should show study commands with --config overrides"
    for cmd in cmds:
        target = next(a for a in cmd if a.startswith("study_"))
        jobs = _jobs(_dry(*cmd[1:]))
        assert jobs.get(target) == 1, (cmd, jobs)
