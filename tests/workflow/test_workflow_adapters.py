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
import yaml

from pipeline.io import schema
from pipeline.io.parquet import read_table, read_table_meta

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def sim_cfg() -> dict:
    cfg = yaml.safe_load((ROOT / "datasets" / "config.yaml").read_text())
    sim = cfg["simulate"]
    sim["datasets"] = {**sim["datasets"], "size": "tiny", "maneuvers": ["M2"], "log_formats": ["bin", "mcap"],
                       "sizes": {"tiny": {"runs": 3, "mc_runs": 1, "switch_runs": 1, "log_flights": 1}}}
    sim["switch"] = {**sim["switch"], "times_s": [3, 8]}
    return sim


def test_planned_simulation_outputs_match_written_files(sim_cfg, tmp_path):
    from pipeline.simulate.run import planned_logs, planned_sets, run_simulate_logs, run_simulate_sets
    from pipeline.simulate.writers import LOG_NAMES

    run_simulate_sets(tmp_path / "sim", sim_cfg, 3)
    written = {p.stem for p in (tmp_path / "sim" / "sets").glob("*.parquet")}
    assert written == set(planned_sets(sim_cfg))
    assert {"M2_train", "M2_test", "mc_M2", "switch_A_3s", "switch_D_8s"} <= written
    rows = run_simulate_logs(tmp_path / "sim" / "logs", sim_cfg, 3)
    planned = planned_logs(sim_cfg)
    assert [p["flight_id"] for p in planned] == [r["flight_id"] for r in rows]
    for p, r in zip(planned, rows):
        log = tmp_path / "sim" / "logs" / p["log"]
        assert Path(r["path"]).name == p["log"] and Path(r["labels"]).name == p["sidecar"]
        assert log.is_dir() == p["is_dir"] and log.exists()
        assert (tmp_path / "sim" / "logs" / p["sidecar"]).is_file()
    assert {p["flight_id"] for p in planned} == {"sim-M2-000-bin", "sim-M2-000-mcap",
                                                 "sim-calibration-000-bin", "sim-calibration-000-mcap"}
    assert set(LOG_NAMES) == {"bin", "tlog", "bag", "mcap"}


def test_failed_flight_gets_placeholders_downstream(tmp_path):
    from pipeline.io.ingest import outputs_for, run_ingest
    from pipeline.models.run import classify_flight, train_model
    from pipeline.preprocess.run import run_preprocess_flight

    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"\x00\x01garbage" * 40)
    run_ingest({"log": bad}, outputs_for(tmp_path / "ingest" / "bad"), None, flight_id="bad")
    reason = json.loads((tmp_path / "ingest" / "bad" / "meta.json").read_text())["error"]
    assert reason
    out = {k: tmp_path / f"{k}.parquet" for k in ("state", "segments", "calibration")}
    diag = run_preprocess_flight(tmp_path / "ingest" / "bad", state_path=out["state"],
                                 segments_path=out["segments"], calibration_path=out["calibration"],
                                 info_path=tmp_path / "info.json")
    assert diag["status"] == "failed" and reason in diag["error"]
    st = read_table(out["state"], schema.STATE)
    assert len(st) == 0 and list(st.columns) == [c.name for c in schema.STATE]
    for k in out:
        m = read_table_meta(out[k])
        assert m["status"] == "failed" and reason in m["error"], k

    # a flights-model with only this failed flight to learn from -> placeholder model
    spec = {"data": "flights", "vehicles": ["q"]}
    meta = train_model("m", spec, tmp_path / "model", {}, states=[out["state"]], segments=[out["segments"]])
    assert meta["status"] == "failed" and "no labelled training data" in meta["error"]
    res = classify_flight(out["state"], out["segments"], tmp_path / "model", tmp_path / "cls.parquet", model="m")
    assert len(res) == 0
    cm = read_table_meta(tmp_path / "cls.parquet")
    assert cm["status"] == "failed" and "model m failed" in cm["error"]
