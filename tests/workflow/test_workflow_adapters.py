"""The stage entry points the workflow's rules call (pipeline/*/run.py), without Snakemake.

* the simulate stage's planned output names equal the files the simulation actually writes
  (the static DAG depends on it);
* a failed ingest gives schema-complete, empty placeholders with the reason downstream;
* a model that cannot be trained is a readable placeholder, and classifying with it too.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.io import schema
from pipeline.io.parquet import read_table, read_table_meta

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def sim_cfg() -> dict:
    from pipeline.config import load_config

    cfg = load_config()   # validated: every default filled
    sim = cfg["simulate"]
    sim["datasets"] = {**sim["datasets"], "size": "tiny", "maneuvers": ["M2"], "log_formats": ["bin", "mcap"],
                       "sizes": {"tiny": {"runs": 3, "mc_runs": 1, "switch_runs": 1, "log_flights": 1}}}
    sim["switch"] = {**sim["switch"], "times_s": [3, 8]}
    return sim


def test_planned_simulation_outputs_match_written_files(sim_cfg, tmp_path):
    from pipeline.simulate.run import planned_logs, planned_sets, run_simulate_logs, run_simulate_sets
    from pipeline.simulate.writers import LOG_NAMES

    sim = tmp_path / "sim"
    run_simulate_sets({}, {"sets": [sim / "sets" / f"{n}.parquet" for n in planned_sets(sim_cfg)],
                           "summary": sim / "summary.parquet", "index": sim / "index.json"}, sim_cfg, seed=3)
    written = {p.stem for p in (tmp_path / "sim" / "sets").glob("*.parquet")}
    assert written == set(planned_sets(sim_cfg))
    assert {"M2_train", "M2_test", "mc_M2", "switch_A_3s", "switch_D_8s"} <= written
    planned = planned_logs(sim_cfg)
    rows = run_simulate_logs({}, {"logs": [sim / "logs" / p["log"] for p in planned],
                                  "sidecars": [sim / "logs" / p["sidecar"] for p in planned],
                                  "manifest": sim / "logs" / "flights.tsv"}, sim_cfg, seed=3).diagnostics["flights"]
    assert [p["flight_id"] for p in planned] == [r["flight_id"] for r in rows]
    for p, r in zip(planned, rows):
        log = tmp_path / "sim" / "logs" / p["log"]
        assert Path(r["path"]).name == p["log"] and Path(r["labels"]).name == p["sidecar"]
        assert log.is_dir() == p["is_dir"] and log.exists()
        assert (tmp_path / "sim" / "logs" / p["sidecar"]).is_file()
    assert {p["flight_id"] for p in planned} == {"sim-M2-000-bin", "sim-M2-000-mcap",
                                                 "sim-calibration-000-bin", "sim-calibration-000-mcap"}
    assert set(LOG_NAMES) == {"bin", "tlog", "bag", "mcap"}


def test_a_declared_simulation_output_that_is_not_written_is_an_error(sim_cfg, tmp_path):
    from pipeline.simulate.run import planned_sets, run_simulate_sets

    sim = tmp_path / "sim"
    sets = [sim / "sets" / f"{n}.parquet" for n in planned_sets(sim_cfg)] + [sim / "sets" / "ghost.parquet"]
    with pytest.raises(RuntimeError, match="ghost"):
        run_simulate_sets({}, {"sets": sets, "summary": sim / "summary.parquet", "index": sim / "index.json"},
                          sim_cfg, seed=3)


def test_failed_flight_gets_placeholders_downstream(tmp_path):
    from pipeline.io.ingest import run_ingest
    from pipeline.models.run import run_classify, run_train
    from pipeline.preprocess.run import run_preprocess

    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"\x00\x01garbage" * 40)
    ing = tmp_path / "ingest" / "bad"
    run_ingest({"log": bad, "labels": []},
               {"streams": [ing / f"{s}.parquet" for s in schema.STREAM_NAMES], "meta": ing / "meta.json"},
               {}, flight_id="bad")
    reason = json.loads((ing / "meta.json").read_text())["error"]
    assert reason
    out = {k: tmp_path / f"{k}.parquet" for k in ("state", "segments", "calibration")}
    res = run_preprocess({"meta": ing / "meta.json"}, {**out, "info": tmp_path / "info.json"}, {})
    diag = res.diagnostics
    assert res.status == "failed" and diag["status"] == "failed" and reason in diag["error"]
    st = read_table(out["state"], schema.STATE)
    assert len(st) == 0 and list(st.columns) == [c.name for c in schema.STATE]
    for k in out:
        m = read_table_meta(out[k])
        assert m["status"] == "failed" and reason in m["error"], k

    # a flights-model with only this failed flight to learn from -> placeholder model
    spec = {"data": "flights", "vehicles": ["q"], "hmm": {}}
    model = {"params": tmp_path / "model" / "params.npz", "meta": tmp_path / "model" / "meta.json"}
    meta = run_train({"states": [out["state"]], "segments": [out["segments"]]}, model, spec,
                     model_set="m", seed=0).diagnostics
    assert meta["status"] == "failed" and "no labelled training data" in meta["error"]
    res = run_classify({**model, "state": out["state"], "segments": out["segments"]},
                       {"classification": tmp_path / "cls.parquet"}, spec, model_set="m")
    assert res.status == "failed" and len(read_table(tmp_path / "cls.parquet")) == 0
    assert "model set m failed" in read_table_meta(tmp_path / "cls.parquet")["error"]
