"""The second CLI audit: ``simulate`` checks its sensor rates before simulating anything;
``info --json`` is strict JSON with an entry for every LOG and stops quietly at a closed pipe;
every ``--config`` help says where its default is read from."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.cli import COMMANDS, main
from pipeline.io.dataflash.writer import DataFlashWriter

ROOT = Path(__file__).resolve().parents[2]


def _err_lines(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip() and not ln.startswith(("\r", " "))]


def _one_fix_log(path: Path) -> Path:
    """10 s of IMU and attitude at 10 Hz, and a single GPS record (its rate is undefined)."""
    with DataFlashWriter(path) as w:
        w.define_layout("ardupilot4")
        t = 3_000_000 + np.arange(101, dtype=np.int64) * 100_000
        w.write_merged({"IMU": {"TimeUS": t, "I": 0, "AccZ": -9.8},
                        "ATT": {"TimeUS": t, "Roll": 0.0, "Pitch": 0.0, "Yaw": 10.0},
                        "GPS": {"TimeUS": t[:1], "I": 0, "Status": 3, "Lat": 47.0, "Lng": 8.0}})
    return path


def _strict(text: str):
    """``text`` as JSON, refusing the NaN/Infinity that Python's json writes but RFC 8259 lacks."""
    def refuse(name):
        raise ValueError(f"not JSON: {name}")
    return json.loads(text, parse_constant=refuse)


def test_simulate_refuses_a_sensor_rate_that_does_not_divide_rate_hz_before_simulating_any_set(
        tmp_path, monkeypatch, capsys):
    import pipeline.simulate.run as sim_run

    def no_work(*a, **k):
        raise AssertionError("simulated the sets before checking the sensor rates")

    monkeypatch.setattr(sim_run, "run_simulate_sets", no_work)
    monkeypatch.setattr(sim_run, "run_simulate_logs", no_work)
    cfg = tmp_path / "config.yaml"
    cfg.write_text("simulate: {rate_hz: 150}\n")
    out = tmp_path / "sim"
    assert main(["simulate", str(out), "--config", str(cfg)]) == 2
    err = _err_lines(capsys)
    assert len(err) == 1 and err[0].startswith(
        "uavpipe simulate: simulate.sensors.imu.rate_hz 200 must divide rate_hz 150 (e.g. 150, 75,"), err
    assert not out.exists()  # no sets/, summary.parquet or index.json left behind


def test_info_json_is_strict_json_with_null_for_an_undefined_rate_and_an_entry_for_every_log(tmp_path, capsys):
    good = _one_fix_log(tmp_path / "one-fix.bin")
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"not a log at all\n" * 20)
    assert main(["info", "--json", str(good), str(bad)]) == 1
    out, err = capsys.readouterr()
    assert "NaN" not in out
    entries = _strict(out)
    assert [e["path"] for e in entries] == [str(good), str(bad)]  # in the order given, the failure too
    assert entries[0]["streams"]["gps"]["rows"] == 1 and entries[0]["streams"]["gps"]["rate_hz"] is None
    assert entries[0]["streams"]["imu"]["rate_hz"] == pytest.approx(10.0)
    assert entries[1]["status"] == "failed" and entries[1]["error"].startswith("unrecognised log format (file")
    assert err.count("\n") == 1 and f"uavpipe info: {bad}: unrecognised log format" in err  # still said on stderr


def test_info_into_a_closed_pipe_exits_141_and_says_nothing(tmp_path):
    log = _one_fix_log(tmp_path / "one-fix.bin")
    r, w = os.pipe()
    os.close(r)  # the reader has gone before uavpipe writes a byte (`uavpipe info --json ... | head -0`)
    try:
        p = subprocess.run([sys.executable, "-c", "import sys; from pipeline.cli import main; sys.exit(main())",
                            "info", "--json", str(log)], stdout=w, stderr=subprocess.PIPE, text=True,
                           env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    finally:
        os.close(w)
    assert p.stderr == "" and p.returncode == 141  # 128 + SIGPIPE, as 130 is 128 + SIGINT


def test_every_config_option_says_the_same_default_as_config_help(capsys):
    with_config = [c for c in COMMANDS if c != "classify"]  # classify uses the model set's own settings
    for command in with_config:
        with pytest.raises(SystemExit):
            main([command, "--help"])
        out = " ".join(capsys.readouterr().out.split())  # argparse wraps the help text
        assert "--config FILE" in out, command
        assert "(default datasets/config.yaml of the current folder, else the project's)" in out, command
