"""Start-up checks of the workflow (one line each, before any job) and the config's canonical
form: settings that mean the same rerun nothing."""

from __future__ import annotations

import os
import subprocess

import pytest

from helpers_workflow import SNAKEMAKE, copy_workflow

DEMO = "demo-quad\tresults/sim/demo/demo-quad.bin\tsim-quad\ttest\tnone\t\tdemo"
ENV = {**os.environ, "PYTHONWARNINGS": "ignore"}


def _snakemake(wd, *args, timeout=300):
    return subprocess.run([SNAKEMAKE, "--cores", "1", *args], cwd=wd, capture_output=True, text=True,
                          timeout=timeout, env=ENV)


def _one_line(p) -> str:
    out = p.stdout + p.stderr
    assert p.returncode != 0, out[-2000:]
    lines = [ln for ln in out.splitlines() if ln.startswith("uavpipe:")]
    assert len(lines) == 1 and "Traceback" not in out, out[-3000:]
    return lines[0]


@pytest.mark.slow
@pytest.mark.parametrize("rows, args, expected", [
    ([DEMO], ["--config", "model_sets={sim: {labels: [M1, M9]}}"],
     "uavpipe: model_sets.sim.labels: 'M9' is not a simulated maneuver (known: M1, M2, M3, M4, M5)"),
    ([DEMO], ["--config", "model_sets={sim: {labels: [M5]}}", "simulate={datasets: {maneuvers: [M1, M2]}}"],
     "uavpipe: model_sets.sim.labels: none of M5 is simulated with this config"),
    ([DEMO], ["--config", "simulate={rate_hz: 150}"],
     "uavpipe: simulate.sensors.imu.rate_hz 200 must divide rate_hz 150"),
    ([DEMO, "x1\tlogs/{date}/x.bin\tgeneric\ttest\tnone\t\t"], [],
     "uavpipe: datasets/flights.tsv:3: flight x1: braces in a path are read as workflow wildcards"),
    ([DEMO, "x_1\tresults/sim/demo/demo-quad.bin\tgeneric\tTrain\tnone\t\t"], [],
     "uavpipe: datasets/flights.tsv:3: flight_id 'x_1' must be letters, digits and '-' only"),
    ([DEMO], ["--config", "estimate={ekf_hmm: {model: nosuch}}"],
     "uavpipe: datasets/config.yaml + --config: estimate.ekf_hmm.model: no model set 'nosuch'"),
])
def test_a_config_or_manifest_mistake_stops_the_dry_run_with_one_line(tmp_path, rows, args, expected):
    wd = copy_workflow(tmp_path / "wf", rows, tiny=False)
    assert _one_line(_snakemake(wd, "-n", *args)).startswith(expected)


@pytest.mark.slow
def test_a_setting_written_as_its_default_or_reordered_reruns_nothing(tmp_path):
    wd = copy_workflow(tmp_path / "wf", [DEMO], tiny=False)
    target = "results/state/demo-quad.parquet"
    p = _snakemake(wd, target, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    # the default rate as an integer, and two preprocess keys in the other order: same params
    same = _snakemake(wd, "-n", target, "--config", "preprocess={gap_multiple: 3, rate_hz: 25}")
    assert same.returncode == 0 and "Nothing to be done" in same.stdout + same.stderr, same.stdout[-3000:]
    changed = _snakemake(wd, "-n", target, "--config", "preprocess={rate_hz: 20}")
    assert changed.returncode == 0 and "preprocess_flight" in changed.stdout + changed.stderr


@pytest.mark.slow
def test_a_yaml_mistake_in_the_config_file_is_one_line_with_its_line_and_column(tmp_path):
    # before: Snakemake's "Config file is not valid JSON or YAML" with no place
    wd = copy_workflow(tmp_path / "wf", [DEMO], extra_config="\nbroken: {a: 1\n", tiny=False)
    line = _one_line(_snakemake(wd, "-n"))
    assert line.startswith("uavpipe: datasets/config.yaml:") and "invalid YAML: while parsing a flow mapping" in line


@pytest.mark.slow
def test_a_manifest_of_only_its_header_plans_the_simulated_work_without_a_traceback(tmp_path):
    # before: KeyError "None of ['flight_id'] are in the columns" from the empty selection
    wd = copy_workflow(tmp_path / "wf", [], tiny=False)
    p = _snakemake(wd, "-n")
    out = p.stdout + p.stderr
    assert p.returncode == 0 and "Traceback" not in out and "KeyError" not in out, out[-3000:]
    assert "flight_report" not in out and "train_model" in out
