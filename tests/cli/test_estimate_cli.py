"""``uavpipe estimate``: writes what the workflow's entry point writes; bad input is one line."""

from __future__ import annotations

import pandas as pd

from helpers_estimate import ingested_flight
from pipeline.cli import main
from pipeline.config import validate_config
from pipeline.estimate.run import ESTIMATORS, job_config, run_estimate


def test_cli_estimate_writes_what_run_estimate_writes(tmp_path, capsys):
    inputs = ingested_flight(tmp_path, drop=range(10, 14))
    assert main(["estimate", str(inputs["meta"].parent), "--state", str(inputs["state"]), "-o",
                 str(tmp_path / "cli")]) == 0
    out = capsys.readouterr().out
    assert "151 steps (4 predict-only), radar stream, reference truth; ekf_hmm placeholder: no model set" in out
    ref = {e: tmp_path / "api" / e / "f1.parquet" for e in ESTIMATORS}
    run_estimate(inputs, ref, job_config(validate_config({})["estimate"], None), flight_id="f1")
    for e in ESTIMATORS:
        pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "cli" / e / "f1.parquet"), pd.read_parquet(ref[e]))


def test_cli_estimate_bad_config_key_or_arguments_are_one_line(tmp_path, capsys):
    inputs = ingested_flight(tmp_path, radar=False)
    bad = tmp_path / "bad.yaml"
    bad.write_text("estimate: {ekf: {qq: 1}}\n")
    args = ["estimate", str(inputs["meta"].parent), "--state", str(inputs["state"]), "-o", str(tmp_path / "o")]
    assert main([*args, "--config", str(bad)]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and "estimate.ekf.qq: unknown key" in err[0] and str(bad) in err[0]
    assert not (tmp_path / "o").exists()
    assert main([*args[:2], *args[1:]]) == 2     # two ingest dirs, one state
    assert "--state: 1 given for 2 flights" in capsys.readouterr().err
    # no radar: non-zero, one line naming the flight and the reason
    assert main(args) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and "f1" in err[0] and "no radar stream" in err[0]
