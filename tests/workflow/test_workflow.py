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
from pathlib import Path

import pytest

from pipeline.io.parquet import read_table, read_table_meta

from helpers_workflow import ROOT, SNAKEMAKE, copy_workflow as _copy_workflow


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
STAGES = ("demo_log", "simulate_sets", "ekf_sets", "simulate_logs", "ingest_flight", "preprocess_flight", "train_model",
           "evaluate_model", "classify_flight", "estimate_q2", "estimate_flight", "estimate_pf_jm", "flight_report",
           "model_report", "compare_report", "report_index", "plotly_js", "all")


@pytest.mark.slow
def test_lint_is_clean():
    p = subprocess.run([SNAKEMAKE, "--lint"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "Congratulations" in p.stdout + p.stderr


@pytest.mark.slow
def test_dry_run_default_config_plans_every_stage():
    """The real default: datasets/config.yaml + datasets/flights.tsv, in the checkout itself."""
    jobs = _planned_jobs(ROOT, "--forceall")
    for rule in STAGES:
        assert jobs.get(rule, 0) >= 1, jobs
    import pandas as pd

    manifest = pd.read_csv(ROOT / "datasets" / "flights.tsv", sep="\t", dtype=str, keep_default_na=False)
    assert manifest["path"].str.startswith("results/sim/logs/").sum() >= 4  # every simulated log format
    assert jobs["model_report"] == jobs["train_model"] >= 2


@pytest.mark.slow
@pytest.mark.parametrize("target,rules", [
    ("simulate", {"simulate_sets", "simulate_logs", "simulate"}),
    ("ingest", {"demo_log", "simulate_logs", "ingest_flight", "ingest"}),
    ("preprocess", {"demo_log", "simulate_logs", "ingest_flight", "preprocess_flight", "preprocess"}),
    # ekf_sets: the EKF estimates of the sets the shipped simekf model set (input: ekf) trains on
    ("train", {"simulate_sets", "ekf_sets", "train_model", "evaluate_model", "train"}),
    # classify: no ekf_sets, simekf (input: ekf) classifies no state track
    ("classify", {"simulate_sets", "simulate_logs", "demo_log", "ingest_flight", "preprocess_flight",
                  "train_model", "classify_flight", "classify"}),
    # the EKF+HMM's model is simekf (input: ekf): its Q2 needs the EKF sets and the truth sets
    ("estimate", {"simulate_sets", "ekf_sets", "simulate_logs", "demo_log", "ingest_flight", "preprocess_flight",
                  "train_model", "estimate_q2", "estimate_flight", "estimate_pf_jm", "estimate"}),
    ("report", {"simulate_sets", "ekf_sets", "simulate_logs", "demo_log", "ingest_flight", "preprocess_flight",
                "train_model", "evaluate_model", "classify_flight", "estimate_q2", "estimate_flight", "estimate_pf_jm",
                "plotly_js", "flight_report", "model_report", "compare_report", "report_index", "report"}),
])
def test_named_stage_targets(tmp_path, target, rules):
    wd = _copy_workflow(tmp_path / "wf", [DEMO, SIM])
    assert set(_planned_jobs(wd, target)) == rules


@pytest.mark.slow
def test_bad_config_key_fails_at_start_naming_it(tmp_path):
    wd = _copy_workflow(tmp_path / "wf", [DEMO], extra_config="\nnot_a_key: 1\n")
    p = _smk(wd, "-n", check=False)
    assert p.returncode != 0
    assert "not_a_key" in p.stdout + p.stderr


#: (section, YAML merged over the config, the key path the one-line error must name) for every
#: section: a bad nested key, a wrong type, an unknown section
BAD_CONFIG = [
    ("top level", "bogus_section: 1\n", "bogus_section"),
    ("seed", "seed: -3\n", "seed"),
    ("ingest", "ingest: {ros: {wrld_frames: [map]}}\n", "ingest.ros.wrld_frames"),
    ("simulate", "simulate: {sensors: {radar: {sigma_rnage_m: 1}}}\n", "simulate.sensors.radar.sigma_rnage_m"),
    ("simulate", "simulate: {rate_hz: fast}\n", "simulate.rate_hz"),
    ("preprocess", "preprocess: {rate_hx: 25}\n", "preprocess.rate_hx"),
    ("preprocess", "preprocess: {rate_hz: fast}\n", "preprocess.rate_hz"),
    ("hmm", "hmm: {n_stats: 3}\n", "hmm.n_stats"),
    ("model_sets", "model_sets: {sim: {colour: red}}\n", "model_sets.sim.colour"),
    ("model_sets", "model_sets: {sim: {data: simulated, vehicles: [q], hmm: {decision: maybe}}}\n",
     "model_sets.sim.hmm.decision"),
    ("model_sets", "model_sets: {x: {data: flights, vehicles: [q], input: ekf}}\n", "model_sets.x.input"),
    ("estimate", "estimate: {sets: {qq: 1}}\n", "estimate.sets.qq"),
    ("studies", "studies: {size: huge}\n", "studies.size"),
    ("estimate", "estimate: {ekf: {qq: 1.0}}\n", "estimate.ekf.qq"),
]


@pytest.mark.slow
@pytest.mark.parametrize("section,yaml_text,key", BAD_CONFIG, ids=[f"{b[0]}:{b[2]}" for b in BAD_CONFIG])
def test_bad_key_or_value_in_every_section_stops_the_dry_run_in_seconds_with_one_line(tmp_path, section,
                                                                                      yaml_text, key):
    import resource

    wd = _copy_workflow(tmp_path / "wf", [DEMO])
    (wd / "datasets" / "bad.yaml").write_text(yaml_text)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run([SNAKEMAKE, "-n", "--configfile", "datasets/bad.yaml"], cwd=wd, capture_output=True,
                       text=True, timeout=60)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert p.returncode != 0
    # the CPU time of the run (robust on a loaded machine; ~2 s idle, wall time about the same)
    cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    assert cpu_s < 10, cpu_s
    lines = [ln for ln in (p.stdout + p.stderr).splitlines() if ln.startswith("uavpipe: ")]
    assert len(lines) == 1 and f" {key}: " in lines[0], p.stdout + p.stderr
    assert "Traceback" not in p.stdout + p.stderr


@pytest.mark.slow
def test_an_ekf_hmm_model_that_is_no_model_set_stops_the_dry_run_naming_it(tmp_path):
    # an override (a second `estimate:` block in the file would be a duplicate key, refused as such)
    wd = _copy_workflow(tmp_path / "wf", [DEMO])
    p = _smk(wd, "-n", "--config", "estimate={ekf_hmm: {model: simm}}", check=False)
    lines = [ln for ln in (p.stdout + p.stderr).splitlines() if ln.startswith("uavpipe: ")]
    assert p.returncode != 0 and len(lines) == 1, p.stdout + p.stderr
    assert "estimate.ekf_hmm.model: no model set 'simm' (model_sets: sim, simekf, f3a)" in lines[0]



@pytest.mark.slow
def test_stick_pulse_widths_out_of_order_stop_the_dry_run_naming_the_key(tmp_path):
    # valid for the schema, but no stick can be normalised: said at start-up, not once per flight
    wd = _copy_workflow(tmp_path / "wf", [DEMO])
    p = _smk(wd, "-n", "--config",
             "preprocess={vehicles: {copter: {controls: {ail: {channel: rc_1_us, min_us: 2000, max_us: 1000}}}}}",
             check=False)
    lines = [ln for ln in (p.stdout + p.stderr).splitlines() if ln.startswith("uavpipe: ")]
    assert p.returncode != 0 and lines == [
        "uavpipe: preprocess.vehicles.copter.controls.ail: min_us 2000.0 must be below max_us 1000.0"], \
        p.stdout + p.stderr

CLI_COMMANDS = (["simulate", "OUT"], ["preprocess", "IN", "-o", "OUT"], ["ingest", "IN", "-o", "OUT"],
                ["train", "IN", "-o", "OUT"])


@pytest.mark.parametrize("section,yaml_text,key,command",
                         [(*b, CLI_COMMANDS[i % len(CLI_COMMANDS)]) for i, b in enumerate(BAD_CONFIG)],
                         ids=[f"{CLI_COMMANDS[i % len(CLI_COMMANDS)][0]}-{b[2]}" for i, b in enumerate(BAD_CONFIG)])
def test_bad_key_or_value_in_every_section_stops_the_cli_with_one_line(tmp_path, capsys, section, yaml_text,
                                                                       key, command):
    """Every section, each command in turn: they all validate the whole file before any work."""
    from pipeline.cli import main

    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml_text)
    (tmp_path / "IN").mkdir()
    args = [str(tmp_path / a) if a in ("IN", "OUT") else a for a in command]
    assert main([*args, "--config", str(bad)]) != 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and f" {key}: " in err[0] and str(bad) in err[0], err
    assert not (tmp_path / "OUT").exists()  # nothing ran


@pytest.mark.slow
def test_bad_manifest_value_fails_at_start_naming_it(tmp_path):
    wd = _copy_workflow(tmp_path / "wf", [DEMO.replace("\ttest\t", "\tsometimes\t")])
    p = _smk(wd, "-n", check=False)
    assert p.returncode != 0
    assert "sometimes" in p.stdout + p.stderr


@pytest.mark.slow
def test_manifest_row_for_unsimulated_log_fails_at_start(tmp_path):
    # the tiny config simulates M1 and M2 only
    wd = _copy_workflow(tmp_path / "wf", [SIM.replace("M1", "M3")])
    p = _smk(wd, "-n", check=False)
    assert p.returncode != 0
    # one line naming the manifest, its line and the flight (the manifest check), no traceback
    lines = [ln for ln in (p.stdout + p.stderr).splitlines() if ln.startswith("uavpipe:")]
    assert lines == ["uavpipe: datasets/flights.tsv:2: flight sim-M3-000-bin: results/sim/logs/sim-M3-000.bin "
                     "is not written by the simulate stage with this config (simulate.datasets: sizes, "
                     "log_formats)"], p.stdout + p.stderr
    assert "Traceback" not in p.stdout + p.stderr and "ValueError" not in p.stdout + p.stderr


@pytest.mark.slow
def test_absent_real_log_is_skipped_with_notice(tmp_path):
    wd = _copy_workflow(tmp_path / "wf", [DEMO, "ghost\t/nonexistent/x.bin\tgeneric\tnone\tnone\t\tgone"])
    p = _smk(wd, "-n")
    assert "skipping flight ghost" in p.stderr
    assert "ghost" not in _planned_jobs(wd).keys()


#: a second model set for the same vehicle (each must be trained, evaluated, reported on its own)
SECOND_SET = "model_sets:\n  sim2: {data: simulated, labels: [M1, M2], vehicles: [sim-quad], hmm: {n_states: 3}}\n"


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """One tiny run of the whole workflow (demo, simulated M1 with truth, a corrupt log; model
    sets sim, sim2 for the same vehicle, and f3a without training flights)."""
    wd = _copy_workflow(tmp_path_factory.mktemp("tiny") / "wf",
                        [DEMO, SIM, "broken\tlogs/broken.bin\tgeneric\ttest\tnone\t\tcorrupt"], extra_tiny=SECOND_SET)
    (wd / "logs").mkdir()
    (wd / "logs" / "broken.bin").write_bytes(b"\xa3\x95" + bytes(range(256)) * 3)
    p = _smk(wd)
    (wd / "first_run.stderr").write_text(p.stderr)   # the end-of-run summary, for the tests
    return wd


def _merged_config(wd: Path, out: Path) -> Path:
    """datasets/config.yaml with datasets/tiny.yaml deep-merged over it, as Snakemake's
    --configfile does: one file for the CLI's --config."""
    import yaml

    def merge(a, b):
        return {**a, **{k: merge(a[k], v) if isinstance(v, dict) and isinstance(a.get(k), dict) else v
                        for k, v in b.items()}}

    cfg = merge(yaml.safe_load((wd / "datasets" / "config.yaml").read_text()),
                yaml.safe_load((wd / "datasets" / "tiny.yaml").read_text()))
    out.write_text(yaml.safe_dump(cfg))
    return out


def _cli(*args: str) -> None:
    from pipeline.cli import main

    assert main(list(args)) == 0, args


def _frames_equal(a: Path, b: Path) -> None:
    import pandas as pd

    pd.testing.assert_frame_equal(pd.read_parquet(a), pd.read_parquet(b), obj=f"{a} vs {b}")


@pytest.mark.slow
def test_after_a_full_run_the_summary_reads_each_trained_model_set_ok_not_stale(tiny_run):
    # the Snakefile hands each set's train_model inputs to the summary: a wrong or missing path
    # there would read "stale (<path> missing)" here
    lines = [ln for ln in (tiny_run / "first_run.stderr").read_text().splitlines() if ln.startswith("  model sets: ")]
    assert len(lines) == 1, lines
    assert "stale" not in lines[0] and "sim ok" in lines[0] and "sim2 ok" in lines[0], lines[0]


@pytest.mark.slow
def test_two_model_sets_for_one_vehicle_are_each_trained_evaluated_and_reported(tiny_run):
    res = tiny_run / "results"
    index = (res / "index.html").read_text()
    for m in ("sim", "sim2"):
        meta = json.loads((res / "models" / m / "meta.json").read_text())
        assert meta["status"] == "ok" and meta["name"] == m
        assert meta["config"]["n_states"] == (3 if m == "sim2" else {"default": 6, "M1": 5})
        cls = read_table(res / "classify" / m / "sim-M1-000-bin.parquet")
        assert read_table_meta(res / "classify" / m / "sim-M1-000-bin.parquet")["model_set"] == m
        assert len(cls) > 10
        ev = read_table_meta(res / "models" / m / "evaluation.parquet")
        assert ev["model_set"] == m and ev["status"] == "ok"
        page = (res / "report" / "models" / f"{m}.html").read_text()
        assert m in page
        assert f"report/models/{m}.html" in index and f"{m} classifier:" in index
    a = read_table(res / "classify" / "sim" / "sim-M1-000-bin.parquet")
    b = read_table(res / "classify" / "sim2" / "sim-M1-000-bin.parquet")
    assert not a["V_best"].equals(b["V_best"])  # each set classifies with its own models
    flight = (res / "report" / "flights" / "sim-M1-000-bin.html").read_text()
    assert "Maneuver timeline (sim)" in flight and "Maneuver timeline (sim2)" in flight


@pytest.mark.slow
def test_simekf_trains_and_evaluates_on_the_ekf_sets_the_ekf_sets_rule_writes(tiny_run, tmp_path):
    import numpy as np

    from pipeline.estimate.sets import SET_COLUMNS, run_ekf_sets

    res = tiny_run / "results"
    names = [f"{m}_{p}" for m in ("M1", "M2") for p in ("train", "test")]
    assert sorted(p.stem for p in (res / "estimate" / "sets").glob("*.parquet")) == sorted(names)
    est = read_table(res / "estimate" / "sets" / "M1_train.parquet", SET_COLUMNS)
    assert est["jerk_n_mps3"].isna().all() and np.isfinite(est["pos_n_m"]).all()
    # the rule is the entry point: the same sets from the same truth, seed and config
    cfg = {"q": 3.0, "p0_sigma": [1.0, 0.1, 0.01], "radar": {}}
    run_ekf_sets({"sets": [res / "sim" / "sets" / "M1_train.parquet"]}, {"sets": [tmp_path / "M1_train.parquet"]},
                 cfg, seed=20261123)
    _frames_equal(res / "estimate" / "sets" / "M1_train.parquet", tmp_path / "M1_train.parquet")
    meta = json.loads((res / "models" / "simekf" / "meta.json").read_text())
    assert meta["status"] == "ok" and meta["spec"]["input"] == "ekf"
    assert meta["training_inputs"] == [f"results/estimate/sets/{m}_train.parquet" for m in ("M1", "M2")]
    ev = read_table(res / "models" / "simekf" / "evaluation.parquet")
    assert set(ev["table"]) == {"3.5", "3.6", "3.7", "3.8"}
    assert set(read_table(res / "models" / "sim" / "evaluation.parquet")["table"]) == {"3.1", "3.2", "3.3", "3.4"}
    # it classifies EKF increments (the EKF+HMM), not the flights' preprocessed GPS state
    assert not (res / "classify" / "simekf").exists()
    assert len(read_table(res / "estimate" / "ekf_hmm" / "sim-M1-000-bin.parquet")["pred"]) > 10


@pytest.mark.slow
def test_cli_simulate_equals_the_workflow(tiny_run, tmp_path):
    import hashlib

    res = tiny_run / "results" / "sim"
    _cli("simulate", str(tmp_path / "sim"), "--config", str(_merged_config(tiny_run, tmp_path / "c.yaml")))
    sets = sorted((res / "sets").glob("*.parquet"))
    assert sets and sorted(p.name for p in (tmp_path / "sim" / "sets").glob("*.parquet")) == [p.name for p in sets]
    for p in [*sets, res / "summary.parquet", *sorted((res / "logs").glob("*.truth.parquet"))]:
        _frames_equal(p, tmp_path / "sim" / p.relative_to(res))
    for p in sorted((res / "logs").glob("*.bin")):
        assert hashlib.sha256(p.read_bytes()).digest() == \
            hashlib.sha256((tmp_path / "sim" / "logs" / p.name).read_bytes()).digest(), p.name


@pytest.mark.slow
def test_cli_ingest_equals_the_workflow(tiny_run, tmp_path):
    res = tiny_run / "results"
    log = res / "sim" / "logs" / "sim-M1-000.bin"
    _cli("ingest", str(log), "--labels", str(res / "sim" / "logs" / "sim-M1-000.bin.truth.parquet"),
         "-o", str(tmp_path / "ing"), "--config", str(_merged_config(tiny_run, tmp_path / "c.yaml")))
    (out,) = [d for d in (tmp_path / "ing").iterdir() if d.is_dir()]
    ref = res / "ingest" / "sim-M1-000-bin"
    for p in sorted(ref.glob("*.parquet")):
        _frames_equal(p, out / p.name)
    a, b = (json.loads((d / "meta.json").read_text()) for d in (ref, out))
    for k in ("flight_id", "source_path", "labels_path"):  # where the files are, not what they hold
        a.pop(k, None), b.pop(k, None)
    assert a == b


@pytest.mark.slow
def test_cli_preprocess_equals_the_workflow(tiny_run, tmp_path):
    res = tiny_run / "results"
    _cli("preprocess", str(res / "ingest" / "sim-M1-000-bin"), "-o", str(tmp_path / "pp"), "--vehicle", "sim-quad",
         "--config", str(_merged_config(tiny_run, tmp_path / "c.yaml")))
    (out,) = [d for d in (tmp_path / "pp").iterdir() if d.is_dir()]
    for stage in ("state", "segments", "calibration"):
        _frames_equal(res / stage / "sim-M1-000-bin.parquet", out / f"{stage}.parquet")
    assert read_table_meta(out / "state.parquet")["preprocess"] == \
        read_table_meta(res / "state" / "sim-M1-000-bin.parquet")["preprocess"]


@pytest.mark.slow
def test_cli_train_equals_the_workflow(tiny_run, tmp_path):
    import numpy as np

    res = tiny_run / "results"
    cfg = str(_merged_config(tiny_run, tmp_path / "c.yaml"))
    sets = [str(res / "sim" / "sets" / f"{m}_train.parquet") for m in ("M1", "M2")]
    _cli("train", *sets, "-o", str(tmp_path / "sim"), "--model-set", "sim", "--config", cfg)
    a, b = np.load(res / "models" / "sim" / "params.npz"), np.load(tmp_path / "sim" / "params.npz")
    assert sorted(a.files) == sorted(b.files)
    for k in a.files:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    ma, mb = (json.loads((d / "meta.json").read_text()) for d in (res / "models" / "sim", tmp_path / "sim"))
    assert ma["training"] == mb["training"] and ma["config"] == mb["config"]


@pytest.mark.slow
def test_cli_classify_equals_the_workflow(tiny_run, tmp_path):
    res = tiny_run / "results"
    _cli("classify", str(res / "models" / "sim"), str(res / "state" / "sim-M1-000-bin.parquet"),
         "--segments", str(res / "segments" / "sim-M1-000-bin.parquet"), "--reset-at-segments",
         "-o", str(tmp_path / "cls.parquet"))
    _frames_equal(res / "classify" / "sim" / "sim-M1-000-bin.parquet", tmp_path / "cls.parquet")


@pytest.mark.slow
def test_changing_only_the_seed_reruns_exactly_the_simulated_and_trained_outputs(tiny_run):
    jobs = _planned_jobs(tiny_run, "--config", "seed=7")
    assert {"simulate_sets", "simulate_logs", "demo_log", "train_model"} <= set(jobs), jobs
    assert jobs["train_model"] == 4  # sim, sim2, simekf and f3a
    # a hyperparameter change retrains and reclassifies, but simulates and ingests nothing
    (tiny_run / "datasets" / "hmm4.yaml").write_text("hmm: {n_iter: 4}\n")
    jobs = _planned_jobs(tiny_run, "--configfile", "datasets/tiny.yaml", "datasets/hmm4.yaml")
    assert "train_model" in jobs and not {"simulate_sets", "simulate_logs", "demo_log", "ingest_flight",
                                          "preprocess_flight"} & set(jobs), jobs


@pytest.mark.slow
def test_run_incremental_and_corrupt_flight(tiny_run):
    """Full tiny run with a corrupt log: exit 0, every other report, the index lists the failure
    with its reason; every stage's outputs exist (failed placeholders for the broken flight);
    then adding one test flight reruns only that flight's jobs plus the index, and changing one
    preprocessing parameter reruns preprocessing and what depends on it, nothing upstream."""
    wd = tiny_run
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
    # estimates: the simulated flight from its radar stream against its truth; the demo flight
    # (no radar) placeholders with the reason; the broken flight's vehicle is not estimated
    for e in ("ekf", "ekf_rts", "ekf_hmm"):
        m = read_table_meta(res / "estimate" / e / "sim-M1-000-bin.parquet")
        assert m["status"] == "ok" and m["reference"] == "truth" and m["n_predict_only"] == 0, (e, m)
        assert len(read_table(res / "estimate" / e / "sim-M1-000-bin.parquet")) == m["n_steps"] > 100
        m = read_table_meta(res / "estimate" / e / "demo-quad.parquet")
        assert m["status"] == "failed" and "no radar stream" in m["error"]
        assert not (res / "estimate" / e / "broken.parquet").exists()
    assert json.loads((res / "estimate" / "q2" / "simekf.json").read_text())["status"] == "ok"  # the EKF+HMM's model set
    # the jump-Markov PF (issue 17) over the sim-quad flights, measured by the state's position
    m = read_table_meta(res / "estimate" / "pf_jm" / "sim-M1-000-bin.parquet")
    assert m["status"] == "ok" and m["n_steps"] > 100 and m["table"] == "pf", m
    assert not (res / "estimate" / "pf_jm" / "broken.parquet").exists()
    page = (res / "report" / "flights" / "sim-M1-000-bin.html").read_text()
    assert "Estimation error vs truth: acceleration" in page and "EKF+HMM mode (" in page
    assert "jump-Markov PF mode fractions beside the classifier" in page
    assert _planned_jobs(wd) == {}

    # add one test flight: a second, identical demo log copied in as a plain file
    shutil.copy(res / "sim" / "demo" / "demo-quad.bin", wd / "logs" / "extra.bin")
    with open(wd / "datasets" / "flights.tsv", "a") as fh:
        fh.write("extra\tlogs/extra.bin\tsim-quad\ttest\tnone\t\tadded\n")
    jobs = _planned_jobs(wd)
    # classified by every state-input model set of its vehicle (sim, sim2; not simekf, input: ekf),
    # estimated once and the comparison page of its vehicle
    assert jobs == {"ingest_flight": 1, "preprocess_flight": 1, "classify_flight": 2, "estimate_flight": 1,
                    "estimate_pf_jm": 1, "flight_report": 1, "compare_report": 1, "report_index": 1, "all": 1}, jobs
    _smk(wd)
    assert "extra" in (res / "index.html").read_text()

    # one preprocessing parameter: preprocess + classify + reports of every flight, no ingest/simulate/train
    cfg = wd / "datasets" / "tiny.yaml"
    text = cfg.read_text()
    assert "preprocess:" not in text
    cfg.write_text(text + "preprocess: {rate_hz: 20}\n")
    jobs = _planned_jobs(wd)
    # 3 sim-quad flights x 2 state-input model sets (sim, sim2); estimated: the three sim-quad flights
    # (the broken flight's vehicle is generic)
    # and the comparison pages of both vehicles (sim-quad, generic)
    assert jobs == {"preprocess_flight": 4, "classify_flight": 6, "estimate_flight": 3, "estimate_pf_jm": 3,
                    "flight_report": 4, "compare_report": 2, "report_index": 1, "all": 1}, jobs

    # snakemake --report over the finished run
    cfg.write_text(text)
    _smk(wd, "--report", "report.zip")
    assert (wd / "report.zip").stat().st_size > 10_000


@pytest.mark.slow
def test_cluster_generic_executor_runs_each_job_as_separate_process(tmp_path):
    wd = _copy_workflow(tmp_path / "wf", [DEMO])
    submit = wd / "submit.sh"
    # the 'cluster': start the job script as a detached local process and print a job id
    submit.write_text(f"#!/usr/bin/env bash\necho \"$1\" >> {wd / 'submitted.txt'}\n"
                      "nohup bash \"$1\" > \"$1.out\" 2>&1 &\necho $!\n")
    submit.chmod(0o755)
    # the flight's chain (demo_log -> ingest -> preprocess) is enough to show jobs leaving the
    # main process; the whole DAG runs locally in test_run_incremental_and_corrupt_flight
    p = _smk(wd, "--executor", "cluster-generic", "--cluster-generic-submit-cmd", str(submit),
             "--jobs", "4", "--latency-wait", "30", "--seconds-between-status-checks", "1",
             "results/state/demo-quad.parquet")
    assert (wd / "results" / "state" / "demo-quad.parquet").exists(), p.stderr[-2000:]
    # one submitted job script per job of the chain
    submitted = (wd / "submitted.txt").read_text().split()
    assert len(submitted) == len(set(submitted)) >= 3, (submitted, p.stderr[-2000:])
