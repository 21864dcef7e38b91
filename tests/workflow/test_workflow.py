"""The Snakemake workflow: lint, dry run, incremental reruns, a corrupt flight, cluster-clean rules.

Each test runs Snakemake in a scratch copy of the workflow (Snakefile, rules/, reports/,
profiles/, datasets/) with a tiny manifest of flights the workflow writes itself, so it needs
neither ../shared nor network access.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.io.parquet import read_table, read_table_meta

ROOT = Path(__file__).resolve().parents[2]
SNAKEMAKE = str(Path(sys.executable).parent / "snakemake")
HEADER = "flight_id\tpath\tvehicle\trole\tlabels\tformat\tnotes\n"


def _copy_workflow(dst: Path, rows: list[str], extra_config: str = "", tiny: bool = True) -> Path:
    dst.mkdir(parents=True, exist_ok=True)
    for name in ("Snakefile", "rules", "reports", "profiles"):
        src = ROOT / name
        (shutil.copytree if src.is_dir() else shutil.copy)(src, dst / name)
    (dst / "datasets").mkdir()
    cfg = (ROOT / "datasets" / "config.yaml").read_text()
    (dst / "datasets" / "config.yaml").write_text(cfg + extra_config)
    (dst / "datasets" / "flights.tsv").write_text(HEADER + "".join(r + "\n" for r in rows))
    # the tiny sizes of tests/workflow/config.yaml, merged over the default config by _smk
    shutil.copy(ROOT / "tests" / "workflow" / "config.yaml", dst / "datasets" / ("tiny.yaml" if tiny else "unused.yaml"))
    return dst


def _smk(wd: Path, *args: str, check: bool = True, timeout: int = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    tiny = (wd / "datasets" / "tiny.yaml").exists()
    p = subprocess.run([SNAKEMAKE, "--cores", "2", *(["--configfile", "datasets/tiny.yaml"] if tiny else []), *args],
                       cwd=wd, capture_output=True, text=True, timeout=timeout, env=env)
    if check and p.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(args)} failed ({p.returncode}):\n{p.stdout[-3000:]}\n{p.stderr[-5000:]}")
    return p


def _planned_jobs(wd: Path, *args: str) -> dict[str, int]:
    """Job counts per rule from a dry run's 'Job stats' table."""
    p = _smk(wd, "-n", *args)
    out = p.stdout + p.stderr
    if "Nothing to be done" in out:
        return {}
    m = re.search(r"Job stats:\njob\s+count\n[- ]+\n(.*?)\ntotal", out, re.S)
    assert m, out[-3000:]
    return {r.split()[0]: int(r.split()[1]) for r in m.group(1).strip().splitlines()}


DEMO = "demo-quad\tresults/sim/demo/demo-quad.bin\tsim-quad\ttest\tnone\t\tdemo"
SIM = ("sim-M1-000-bin\tresults/sim/logs/sim-M1-000.bin\tsim-quad\ttest\t"
       "results/sim/logs/sim-M1-000.bin.truth.parquet\t\tsimulated M1 with truth side-car")
STAGES = ("demo_log", "simulate_sets", "simulate_logs", "ingest_flight", "preprocess_flight", "train_model",
          "evaluate_model", "classify_flight", "flight_report", "model_report", "report_index", "plotly_js", "all")


def test_lint_is_clean():
    p = subprocess.run([SNAKEMAKE, "--lint"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "Congratulations" in p.stdout + p.stderr


def test_dry_run_default_config_plans_every_stage():
    """The real default: datasets/config.yaml + datasets/flights.tsv, in the checkout itself."""
    jobs = _planned_jobs(ROOT, "--forceall")
    for rule in STAGES:
        assert jobs.get(rule, 0) >= 1, jobs
    import pandas as pd

    manifest = pd.read_csv(ROOT / "datasets" / "flights.tsv", sep="\t", dtype=str, keep_default_na=False)
    assert manifest["path"].str.startswith("results/sim/logs/").sum() >= 4  # every simulated log format
    assert jobs["model_report"] == jobs["train_model"] >= 2


@pytest.mark.parametrize("target,rules", [
    ("simulate", {"simulate_sets", "simulate_logs", "simulate"}),
    ("ingest", {"demo_log", "simulate_logs", "ingest_flight", "ingest"}),
    ("preprocess", {"demo_log", "simulate_logs", "ingest_flight", "preprocess_flight", "preprocess"}),
    ("train", {"simulate_sets", "train_model", "evaluate_model", "train"}),
    ("classify", {"simulate_sets", "simulate_logs", "demo_log", "ingest_flight", "preprocess_flight",
                  "train_model", "classify_flight", "classify"}),
    ("report", {"simulate_sets", "simulate_logs", "demo_log", "ingest_flight", "preprocess_flight",
                "train_model", "evaluate_model", "classify_flight", "plotly_js", "flight_report",
                "model_report", "report_index", "report"}),
])
def test_named_stage_targets(tmp_path, target, rules):
    wd = _copy_workflow(tmp_path / "wf", [DEMO, SIM])
    assert set(_planned_jobs(wd, target)) == rules


def test_bad_config_key_fails_at_start_naming_it(tmp_path):
    wd = _copy_workflow(tmp_path / "wf", [DEMO], extra_config="\nnot_a_key: 1\n")
    p = _smk(wd, "-n", check=False)
    assert p.returncode != 0
    assert "not_a_key" in p.stdout + p.stderr


def test_bad_manifest_value_fails_at_start_naming_it(tmp_path):
    wd = _copy_workflow(tmp_path / "wf", [DEMO.replace("\ttest\t", "\tsometimes\t")])
    p = _smk(wd, "-n", check=False)
    assert p.returncode != 0
    assert "sometimes" in p.stdout + p.stderr


def test_manifest_row_for_unsimulated_log_fails_at_start(tmp_path):
    # the tiny config simulates M1 and M2 only
    wd = _copy_workflow(tmp_path / "wf", [SIM.replace("M1", "M3")])
    p = _smk(wd, "-n", check=False)
    assert p.returncode != 0
    assert "sim-M3-000-bin" in p.stdout + p.stderr and "not written by the simulate stage" in p.stdout + p.stderr


def test_absent_real_log_is_skipped_with_notice(tmp_path):
    wd = _copy_workflow(tmp_path / "wf", [DEMO, "ghost\t/nonexistent/x.bin\tq\tnone\tnone\t\tgone"])
    p = _smk(wd, "-n")
    assert "skipping flight ghost" in p.stderr
    assert "ghost" not in _planned_jobs(wd).keys()


@pytest.mark.slow
def test_run_incremental_and_corrupt_flight(tmp_path):
    """Full tiny run with a corrupt log: exit 0, every other report, the index lists the failure
    with its reason; every stage's outputs exist (failed placeholders for the broken flight);
    then adding one test flight reruns only that flight's jobs plus the index, and changing one
    preprocessing parameter reruns preprocessing and what depends on it, nothing upstream."""
    wd = _copy_workflow(tmp_path / "wf", [DEMO, SIM, "broken\tlogs/broken.bin\tq\ttest\tnone\t\tcorrupt"])
    (wd / "logs").mkdir()
    (wd / "logs" / "broken.bin").write_bytes(b"\xa3\x95" + bytes(range(256)) * 3)
    _smk(wd)
    res = wd / "results"
    index = (res / "index.html").read_text()
    assert "broken" in index and "failed" in index
    meta = json.loads((res / "ingest" / "broken" / "meta.json").read_text())
    assert meta["status"] == "failed" and meta["error"] and html.escape(meta["error"]) in index
    for f in ("demo-quad", "sim-M1-000-bin", "broken"):
        assert (res / "report" / "flights" / f"{f}.html").exists()
        for stage in ("state", "segments", "calibration"):
            assert (res / stage / f"{f}.parquet").exists()
    assert read_table_meta(res / "state" / "broken.parquet")["status"] == "failed"
    assert len(read_table(res / "state" / "broken.parquet")) == 0
    # the simulated flight: ingested with its truth side-car, preprocessed, classified
    assert len(read_table(res / "segments" / "sim-M1-000-bin.parquet")) >= 1
    cls = read_table(res / "classify" / "sim" / "sim-M1-000-bin.parquet")
    assert len(cls) > 10 and set(cls["pred"]) <= {"M1", "M2", "unknown"}
    assert 'report/models/sim.html' in index and (res / "report" / "models" / "sim.html").exists()
    ev = read_table(res / "models" / "sim" / "evaluation.parquet")
    assert set(ev["table"]) == {"3.1", "3.2", "3.3", "3.4"} and ev["thesis_FA_pct"].notna().all()
    # a model without training flights is a readable placeholder, not a crashed job
    assert json.loads((res / "models" / "f3a" / "meta.json").read_text())["status"] == "failed"
    assert "classifier:" in index
    assert _planned_jobs(wd) == {}

    # add one test flight: a second, identical demo log copied in as a plain file
    shutil.copy(res / "sim" / "demo" / "demo-quad.bin", wd / "logs" / "extra.bin")
    with open(wd / "datasets" / "flights.tsv", "a") as fh:
        fh.write("extra\tlogs/extra.bin\tsim-quad\ttest\tnone\t\tadded\n")
    jobs = _planned_jobs(wd)
    assert jobs == {"ingest_flight": 1, "preprocess_flight": 1, "classify_flight": 1, "flight_report": 1,
                    "report_index": 1, "all": 1}, jobs
    _smk(wd)
    assert "extra" in (res / "index.html").read_text()

    # one preprocessing parameter: preprocess + classify + reports of every flight, no ingest/simulate/train
    cfg = wd / "datasets" / "config.yaml"
    text = cfg.read_text()
    assert "\n  rate_hz: 25 " in text
    cfg.write_text(text.replace("\n  rate_hz: 25 ", "\n  rate_hz: 20 ", 1))
    jobs = _planned_jobs(wd)
    assert jobs == {"preprocess_flight": 4, "classify_flight": 3, "flight_report": 4, "report_index": 1,
                    "all": 1}, jobs

    # snakemake --report over the finished run
    cfg.write_text(text)
    _smk(wd, "--report", "report.zip")
    assert (wd / "report.zip").stat().st_size > 10_000


@pytest.mark.slow
def test_cluster_generic_executor_runs_each_job_as_separate_process(tmp_path):
    wd = _copy_workflow(tmp_path / "wf", [DEMO])
    submit = wd / "submit.sh"
    # the 'cluster': start the job script as a detached local process and print a job id
    submit.write_text("#!/usr/bin/env bash\nnohup bash \"$1\" > \"$1.out\" 2>&1 &\necho $!\n")
    submit.chmod(0o755)
    p = _smk(wd, "--executor", "cluster-generic", "--cluster-generic-submit-cmd", str(submit),
             "--jobs", "4", "--latency-wait", "30", "--seconds-between-status-checks", "1")
    assert (wd / "results" / "index.html").exists(), p.stderr[-2000:]
    assert "demo-quad" in (wd / "results" / "index.html").read_text()
