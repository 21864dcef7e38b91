"""``uavpipe info`` / ``uavpipe ingest``: reader and reason shown, one bad file doesn't stop others."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from pipeline.cli import main
from pipeline.io import schema
from pipeline.io.ingest import IngestResult, run_ingest
from pipeline.io.parquet import read_flightlog
from pipeline.io.registry import flight_id_for
from pipeline.simulate.demo import write_demo_flight

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def demo_log(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("logs") / "demo.bin"
    write_demo_flight(p, seed=3)
    return p


#: rows per stream of the 60 s demo flight: rate (Hz) x 60 s (control: 600 RCIN + 600 RCOU records;
#: mode: its 4 MODE + 2 EV records; messages / params: its 2 MSG and 7 PARM records)
DEMO_ROWS = {"imu": 3000, "gps": 300, "baro": 600, "mag": 600, "attitude": 600, "local_position": 600,
             "rangefinder": 600, "control": 1200, "mode": 6, "setpoint": 600, "messages": 2, "params": 7}


def test_info_names_reader_and_reason(demo_log, capsys):
    from pipeline.io.dataflash import DataFlashReader

    assert main(["info", str(demo_log)]) == 0
    out = capsys.readouterr().out
    lines = [" ".join(line.split()) for line in out.splitlines()]
    assert lines[1] == (f"format ardupilot_dataflash (reader dataflash v{DataFlashReader.version}: "
                        "DataFlash FMT-for-FMT record at offset 0 (A3 95 80 80))")
    rows = {ln.split()[0]: int(ln.split()[1]) for ln in lines[lines.index("streams:") + 1:]
            if len(ln.split()) > 2 and ln.split()[2] == "rows"}
    assert rows == DEMO_ROWS
    assert "imu 3000 rows 1 inst 50.00 Hz" in lines and "gps 300 rows 1 inst 5.00 Hz" in lines


def test_info_json_and_wrong_extension(demo_log, tmp_path, capsys):
    renamed = tmp_path / "demo.tlog"  # extension lies; detection uses the bytes
    renamed.write_bytes(demo_log.read_bytes())
    assert main(["info", "--json", str(renamed)]) == 0
    d = json.loads(capsys.readouterr().out)[0]
    assert d["reader"].startswith("dataflash")
    assert d["detected_by"] == "DataFlash FMT-for-FMT record at offset 0 (A3 95 80 80)"
    assert {k: v["rows"] for k, v in d["streams"].items()} == DEMO_ROWS


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
    # and as a module, by either name a user tries
    for mod in ("pipeline", "pipeline.cli"):
        q = subprocess.run([sys.executable, "-m", mod, "--version"], capture_output=True, text=True)
        assert q.returncode == 0 and q.stdout == p.stdout, (mod, q.stderr)


def _job(log, out_dir, labels=()):
    """run_ingest arguments shaped as the workflow rule passes them."""
    inputs = {"log": str(log), "labels": [str(x) for x in labels]}
    outputs = {"meta": str(out_dir / "meta.json"),
               "streams": [str(out_dir / f"{s}.parquet") for s in schema.STREAM_NAMES]}
    return inputs, outputs


def test_run_ingest_records_failure_with_empty_streams(tmp_path, capsys):
    bad = tmp_path / "x.bin"
    bad.write_bytes(b"")
    res = run_ingest(*_job(bad, tmp_path / "o"), None, flight_id="x")
    assert isinstance(res, IngestResult)
    assert res.status == "failed" and "empty file" in res.error
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "x.bin" in err and "FAILED" in err  # one line, no traceback
    back = read_flightlog(tmp_path / "o")
    assert back.meta["status"] == "failed" and "empty file" in back.meta["error"]
    assert all(len(df) == 0 for df in back.streams.values())
    assert isinstance(back["imu"], pd.DataFrame) and "gyr_x_radps" in back["imu"].columns


def test_run_ingest_writes_exactly_the_declared_outputs(demo_log, tmp_path):
    inputs, outputs = _job(demo_log, tmp_path / "o")
    res = run_ingest(inputs, outputs, {}, flight_id="demo-1")
    assert res.status == "ok" and res.source_format == "ardupilot_dataflash" and res.duration_s > 0
    assert res.diagnostics["record_counts"]["IMU"] > 0
    written = sorted(str(p) for p in (tmp_path / "o").iterdir())
    assert written == sorted([outputs["meta"], *outputs["streams"]])
    assert sorted(str(p) for p in res.paths) == written
    with pytest.raises(ValueError, match="outputs.streams"):
        run_ingest(inputs, {**outputs, "streams": outputs["streams"][:-1]}, {}, flight_id="demo-1")


def _read_all(d):
    log = read_flightlog(d)
    return {name: log[name] for name in schema.STREAM_NAMES}, json.loads((d / "meta.json").read_text())


@pytest.mark.parametrize("which", ["demo", "bad"])
def test_cli_ingest_equals_run_ingest_with_the_workflow_arguments(demo_log, tmp_path, which):
    log = demo_log
    if which == "bad":
        log = tmp_path / "in" / "bad.bin"
        log.parent.mkdir()
        log.write_bytes(b"not a log at all\n" * 20)
    from pipeline.config import DEFAULT_CONFIG, load_config, section

    rc = main(["ingest", str(log), "-o", str(tmp_path / "cli"), "--config", str(DEFAULT_CONFIG)])
    assert rc == (0 if which == "demo" else 1)
    fid = flight_id_for(log)
    # the workflow's call: the rule's declared paths and the config's ingest section
    run_ingest(*_job(log, tmp_path / "wf" / fid), section(load_config(DEFAULT_CONFIG), "ingest"), flight_id=fid)
    frames_cli, meta_cli = _read_all(tmp_path / "cli" / fid)
    frames_wf, meta_wf = _read_all(tmp_path / "wf" / fid)
    assert meta_cli == meta_wf  # source paths are the same input path; nothing ignored
    for name in schema.STREAM_NAMES:
        pd.testing.assert_frame_equal(frames_cli[name], frames_wf[name], check_exact=True)
    if which == "bad":
        assert meta_cli["status"] == "failed" and "unrecognised log format" in meta_cli["error"]


def test_cli_ingest_bad_config_is_one_line(demo_log, tmp_path, capsys):
    rc = main(["ingest", str(demo_log), "-o", str(tmp_path), "--config", str(tmp_path / "missing.yaml")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "missing.yaml" in err


def _small_tlog(path: Path) -> Path:
    """A short vehicle tlog: heartbeats, attitude and GPS (pymavlink-encoded)."""
    from pymavlink.dialects.v20 import ardupilotmega as v2

    from pipeline.io.tlog import write_tlog

    m = v2.MAVLink(None)
    t0 = 1_700_000_000_000_000
    recs = []
    for k in range(40):
        t = t0 + k * 100_000
        if k % 10 == 0:
            recs.append((t, m.heartbeat_encode(2, 3, v2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5, 4)))
        recs.append((t + 1, m.attitude_encode(1000 + k * 100, 0.1, -0.2, 0.01 * k, 0.0, 0.0, 0.0)))
        recs.append((t + 2, m.gps_raw_int_encode(1_000_000 + k * 100_000, 3, 473977420 + k, 85455940, 488000,
                                                 121, 180, 250, 9000, 11, 536700, 850, 1300, 0, 0, 0)))
    return write_tlog(path, recs)


_NO_PANDAS = """
import sys
from pipeline.cli import main
rc = main(sys.argv[1:])
assert rc == 0, rc
bad = sorted(m for m in sys.modules if m == "pandas" or m.startswith("pandas."))
print("PANDAS" if bad else "NO-PANDAS")
"""


@pytest.mark.parametrize("kind", ["dataflash", "tlog"])
@pytest.mark.parametrize("command", ["ingest", "info"])
def test_ingest_and_info_do_not_import_pandas(demo_log, tmp_path, kind, command):
    log = demo_log
    if kind == "tlog":
        log = _small_tlog(tmp_path / "flight.tlog")
    args = ["ingest", str(log), "-o", str(tmp_path / "out")] if command == "ingest" else ["info", str(log)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, "-c", _NO_PANDAS, *args], capture_output=True, text=True, env=env,
                       timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.strip().splitlines()[-1] == "NO-PANDAS"


def test_ingest_reads_the_log_once(demo_log, tmp_path, monkeypatch):
    import builtins

    opened, real_open = [], builtins.open

    def counting_open(file, *a, **k):
        if str(file) == str(demo_log):
            opened.append(file)
        return real_open(file, *a, **k)

    monkeypatch.setattr(builtins, "open", counting_open)
    res = run_ingest(*_job(demo_log, tmp_path / "o"), None, flight_id="demo")
    assert res.status == "ok"
    assert len(opened) == 2  # the 64 KiB sniff head, then the whole file once (hashed from memory)
    meta = json.loads((tmp_path / "o" / "meta.json").read_text())
    import hashlib

    assert meta["source_sha256"] == hashlib.sha256(demo_log.read_bytes()).hexdigest()


def test_ingest_conforms_each_stream_once_and_never_through_pandas(demo_log, tmp_path, monkeypatch):
    from pipeline.io import schema as sch

    from pipeline.io.dataflash import decode
    from pipeline.io.dataflash.streams import stream_parts

    calls: list[str] = []
    with_data: list[str] = []
    real = sch.conform_arrow_counted

    def counted(stream, data):
        calls.append(stream)
        if data is not None:
            with_data.append(stream)
        return real(stream, data)

    def no_pandas_conform(*a, **k):
        raise AssertionError("pandas conform on the DataFlash ingest path")

    monkeypatch.setattr(sch, "conform_arrow_counted", counted)
    monkeypatch.setattr(sch, "conform", no_pandas_conform)
    res = run_ingest(*_job(demo_log, tmp_path / "o"), None, flight_id="demo")
    assert res.status == "ok"
    # every stream of the decoder's table is conformed exactly once, in table order; those with
    # records are exactly the non-empty streams of the decoded parts (the others get None)
    parts = stream_parts(decode(demo_log))
    assert calls == list(parts)
    assert set(with_data) == {k for k, v in parts.items() if v} == set(DEMO_ROWS)
    assert len(with_data) == len(set(with_data))


def test_a_log_the_manifest_says_embeds_labels_but_carries_none_gets_a_warning(demo_log, tmp_path):
    res = run_ingest(*_job(demo_log, tmp_path / "o"), None, flight_id="demo", labels_embedded=True)
    assert res.status == "ok"
    assert any(w.startswith("manifest labels 'embedded', but the log carries no labelled segment")
               for w in res.diagnostics["warnings"])
    res = run_ingest(*_job(demo_log, tmp_path / "p"), None, flight_id="demo")
    assert not any("manifest labels" in w for w in res.diagnostics["warnings"])


def test_a_damaged_labels_side_car_is_named_in_the_flights_reason(demo_log, tmp_path):
    bad = tmp_path / "labels.parquet"
    bad.write_text("not parquet\n")
    inputs, outputs = _job(demo_log, tmp_path / "o")
    res = run_ingest({**inputs, "labels": [bad]}, outputs, None, flight_id="demo")
    assert res.status == "failed" and res.error.startswith(f"{bad}: not a readable truth side-car")
