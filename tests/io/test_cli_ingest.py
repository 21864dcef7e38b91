"""``uavpipe info`` / ``uavpipe ingest``: reader and reason shown, one bad file doesn't stop others."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from pipeline.cli import main
from pipeline.io.ingest import run_ingest
from pipeline.io.parquet import read_flightlog
from pipeline.simulate.demo import write_demo_flight


@pytest.fixture(scope="module")
def demo_log(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("logs") / "demo.bin"
    write_demo_flight(p, seed=3)
    return p


def test_info_names_reader_and_reason(demo_log, capsys):
    assert main(["info", str(demo_log)]) == 0
    out = capsys.readouterr().out
    assert "dataflash" in out and "reader" in out
    assert "imu" in out and "gps" in out


def test_info_json_and_wrong_extension(demo_log, tmp_path, capsys):
    renamed = tmp_path / "demo.tlog"  # extension lies; detection uses the bytes
    renamed.write_bytes(demo_log.read_bytes())
    assert main(["info", "--json", str(renamed)]) == 0
    d = json.loads(capsys.readouterr().out)[0]
    assert d["reader"].startswith("dataflash")
    assert d["streams"]["imu"]["rows"] > 0


def test_ingest_continues_past_bad_file_and_exits_nonzero(demo_log, tmp_path, capsys):
    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"not a log at all\n" * 20)
    out = tmp_path / "out"
    rc = main(["ingest", str(bad), str(demo_log), "-o", str(out)])
    assert rc == 1
    err = capsys.readouterr().err
    assert "bad.bin" in err and "unrecognised log format" in err
    assert err.count("\n") <= 3  # one line per failure plus the summary, no traceback
    log = read_flightlog(out / "demo")
    assert len(log["imu"]) > 0 and log.meta["reader"] == "dataflash"


def test_console_script_runs():
    exe = Path(sys.executable).parent / "uavpipe"
    p = subprocess.run([str(exe), "--version"], capture_output=True, text=True)
    assert p.returncode == 0 and "uavpipe" in p.stdout


def test_run_ingest_records_failure_with_empty_streams(tmp_path):
    bad = tmp_path / "x.bin"
    bad.write_bytes(b"")
    log = run_ingest(bad, tmp_path / "o", flight_id="x")
    assert log.meta["status"] == "failed" and "empty file" in log.meta["error"]
    back = read_flightlog(tmp_path / "o")
    assert back.meta["status"] == "failed"
    assert all(len(df) == 0 for df in back.streams.values())
    assert isinstance(back["imu"], pd.DataFrame) and "gyr_x_radps" in back["imu"].columns
