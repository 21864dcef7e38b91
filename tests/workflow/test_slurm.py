"""The workflow on a real SLURM cluster (profiles/slurm) and through the generic cluster profile.

The SLURM test runs the README's scale-out command, read from the README itself, on three flights
(the demo flight and two simulated DataFlash logs of the tiny config) and compares every Parquet
output with a local run's as frames (tests/workflow/compare_results.py). It needs a cluster that
answers ``sinfo`` with a usable node and ``snakemake-executor-plugin-slurm`` (the ``test``
extra); ``bash .ci/slurm-up`` starts a one-node cluster on this machine (CI does). Where either
is missing it skips with the reason, and fails instead under ``UAVPIPE_REQUIRE_SHARED=1``.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers import REQUIRE_SHARED
from helpers_workflow import ROOT, SNAKEMAKE, copy_workflow

#: the three flights: the demo flight and two simulated DataFlash logs of the tiny config (with
#: truth side-cars), made once by the workflow's own simulation rules and then given to both runs
#: as plain log files, so that the SLURM run is the ingest and preprocess jobs alone
FLIGHTS = ("demo-quad", "sim-M1-000-bin", "sim-M2-000-bin")
MADE = {"demo-quad": ("results/sim/demo/demo-quad.bin", None),
        **{f"sim-{m}-000-bin": (f"results/sim/logs/sim-{m}-000.bin", f"results/sim/logs/sim-{m}-000.bin.truth.parquet")
           for m in ("M1", "M2")}}
#: the README's scale-out command starts with this
README_PREFIX = ".venv/bin/snakemake --workflow-profile profiles/slurm"
USABLE_NODE_STATES = {"idle", "mixed", "allocated", "completing"}


def _unavailable(reason: str) -> None:
    if REQUIRE_SHARED:
        pytest.fail(f"UAVPIPE_REQUIRE_SHARED=1 but {reason}")
    pytest.skip(reason)


def _need_slurm() -> None:
    """Skip (or fail under UAVPIPE_REQUIRE_SHARED=1) unless a SLURM cluster and the plugin answer."""
    if importlib.util.find_spec("snakemake_executor_plugin_slurm") is None:
        _unavailable("snakemake-executor-plugin-slurm is not installed (bash .ci/venv test)")
    for tool in ("sinfo", "sbatch", "squeue"):
        if shutil.which(tool) is None:
            _unavailable(f"no SLURM here: `{tool}` not on PATH (bash .ci/slurm-up starts a one-node cluster)")
    try:
        p = subprocess.run(["sinfo", "-h", "-N", "-o", "%T"], capture_output=True, text=True, timeout=20)
    except subprocess.TimeoutExpired:
        _unavailable("no SLURM controller answers: `sinfo` timed out (bash .ci/slurm-up)")
    # a suffix marks a node that cannot take jobs now (idle* = not responding, idle~ = powered off),
    # except "-" (planned by the backfill scheduler)
    states = {s.strip().rstrip("-") for s in p.stdout.split()}
    if p.returncode != 0 or not states & USABLE_NODE_STATES:
        _unavailable(f"no usable SLURM node: `sinfo` says {(p.stdout + p.stderr).strip()[:200]!r} "
                     "(bash .ci/slurm-up)")


def readme_slurm_command() -> list[str]:
    """The scale-out command of README.md (the one line starting with README_PREFIX), split."""
    lines = [ln.strip() for ln in (ROOT / "README.md").read_text().splitlines()
             if ln.strip().startswith(README_PREFIX)]
    assert len(lines) == 1, f"README.md should have one line starting with {README_PREFIX!r}: {lines}"
    return shlex.split(lines[0])


def test_the_readme_scale_out_command_uses_the_slurm_profile_without_accounting_and_names_the_targets():
    cmd = readme_slurm_command()
    assert cmd[:3] == [".venv/bin/snakemake", "--workflow-profile", "profiles/slurm"]
    text = " ".join(cmd)
    for opt in ("--slurm-status-command squeue", "--slurm-no-account",
                "--slurm-init-seconds-before-status-checks 5"):
        assert opt in text
    assert cmd[-2:] == ["ingest", "preprocess"]
    assert "bash .ci/slurm-up" in (ROOT / "README.md").read_text()


def test_the_slurm_profile_names_no_placeholder_partition_or_account():
    import yaml

    prof = yaml.safe_load((ROOT / "profiles" / "slurm" / "config.yaml").read_text())
    assert prof["executor"] == "slurm"
    assert not {"slurm_partition", "slurm_account"} & set(prof["default-resources"])


def _manifest_rows(made: dict[str, tuple[str, str | None]]) -> list[str]:
    return [f"{f}\t{log}\tsim-quad\ttest\t{truth or 'none'}\t\t{f}" for f, (log, truth) in made.items()]


def _smk(wd: Path, *args: str, timeout: int = 300) -> subprocess.CompletedProcess:
    p = subprocess.run([SNAKEMAKE, *args, "--configfile", "datasets/tiny.yaml"], cwd=wd, capture_output=True,
                       text=True, timeout=timeout, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert p.returncode == 0, f"snakemake {' '.join(args)}:\n{p.stdout[-2000:]}\n{p.stderr[-4000:]}"
    return p


def _three_flight_logs(tmp_path: Path) -> dict[str, tuple[str, str | None]]:
    """The three flights' logs, written by the workflow's simulation rules, under tmp_path/logs."""
    gen = copy_workflow(tmp_path / "gen", _manifest_rows(MADE))
    _smk(gen, "--cores", "2", *{log for log, _ in MADE.values()})
    logs = tmp_path / "logs"
    logs.mkdir()
    made = {}
    for f, (log, truth) in MADE.items():
        for src in filter(None, (log, truth)):
            shutil.copy2(gen / src, logs / Path(src).name)
        made[f] = (f"logs/{Path(log).name}", truth and f"logs/{Path(truth).name}")
    return made


@pytest.mark.slow
def test_ingest_and_preprocess_of_three_flights_on_slurm_equal_the_local_run_as_frames(tmp_path):
    _need_slurm()
    made = _three_flight_logs(tmp_path)
    local = copy_workflow(tmp_path / "local", _manifest_rows(made))
    cluster = copy_workflow(tmp_path / "slurm", _manifest_rows(made))
    for wd in (local, cluster):
        shutil.copytree(tmp_path / "logs", wd / "logs")
    _smk(local, "--cores", "2", "ingest", "preprocess")

    t0 = time.monotonic()
    p = subprocess.run([SNAKEMAKE, *readme_slurm_command()[1:], "--configfile", "datasets/tiny.yaml"],
                       cwd=cluster, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=400,
                       env={**os.environ, "PYTHONWARNINGS": "ignore"})
    wall = time.monotonic() - t0
    (tmp_path / "slurm.log").write_text(p.stdout)  # kept for a look after a failure
    assert p.returncode == 0, p.stdout[-6000:]
    # every ingest and preprocess job went through sbatch (only the two target rules ran locally)
    submitted = re.findall(r"submitted with SLURM jobid (\d+) \(log: .*?/rule_(\w+?)/", p.stdout)
    rules = sorted(r for _, r in submitted)
    assert rules == ["ingest_flight"] * 3 + ["preprocess_flight"] * 3, rules
    for f in FLIGHTS:
        assert (cluster / "results" / "state" / f"{f}.parquet").exists()

    c = subprocess.run([sys.executable, str(ROOT / "tests" / "workflow" / "compare_results.py"),
                        str(local / "results"), str(cluster / "results")], capture_output=True, text=True,
                       timeout=120)
    assert c.returncode == 0, c.stdout[-3000:] + c.stderr[-2000:]
    res = dict(re.findall(r"^RESULT (\S+) (\d+)$", c.stdout, re.M))
    assert res["compare_files_new"] == "0" and res["compare_files_missing"] == "0", c.stdout[-3000:]
    # per flight: the ingest streams plus state, segments and calibration
    assert int(res["compare_files_equal"]) >= 3 * 4, c.stdout[-3000:]
    print(f"RESULT slurm_workflow_wall_s {wall:.1f}")
    print(f"RESULT slurm_jobs_submitted {len(submitted)}")
    print(f"RESULT slurm_frames_equal {res['compare_files_equal']}")


@pytest.mark.slow
def test_the_generic_profile_creates_its_log_folder_before_submitting(tmp_path):
    """Its submit command, with a stand-in `qsub` that refuses a missing -o/-e folder (as schedulers do)."""
    wd = copy_workflow(tmp_path / "wf", _manifest_rows({"demo-quad": MADE["demo-quad"]}))
    bindir = tmp_path / "bin"
    bindir.mkdir()
    qsub = bindir / "qsub"
    # a stand-in scheduler: check the -o/-e folders, start the job script detached, print an id
    qsub.write_text(
        "#!/usr/bin/env bash\n"
        "while [ $# -gt 1 ]; do case \"$1\" in\n"
        "  -o|-e) [ -d \"$2\" ] || { echo \"qsub: no such folder: $2\" >&2; exit 1; }; shift 2 ;;\n"
        "  -l) shift 2 ;;\n"
        "  *) shift ;;\n"
        "esac; done\n"
        "nohup bash \"$1\" > \"$1.out\" 2>&1 &\necho $!\n")
    qsub.chmod(0o755)
    assert not (wd / "results" / "logs" / "cluster").exists()
    env = {**os.environ, "PYTHONWARNINGS": "ignore", "PATH": f"{bindir}{os.pathsep}{os.environ['PATH']}"}
    p = subprocess.run([SNAKEMAKE, "--workflow-profile", "profiles/generic", "--latency-wait", "30",
                        "--seconds-between-status-checks", "1", "ingest", "--configfile", "datasets/tiny.yaml"],
                       cwd=wd, capture_output=True, text=True, timeout=300, env=env)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-4000:]
    assert (wd / "results" / "logs" / "cluster").is_dir()
    assert (wd / "results" / "ingest" / "demo-quad" / "imu.parquet").exists()
