"""Bad input on the command line is one line naming the file, option or key and the reason; one bad
input never stops the others; an input that would overwrite another's output is refused by name."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from helpers_estimate import ingested_flight
from helpers_maneuvers import synth_bulk
from pipeline.cli import main
from pipeline.io import schema
from pipeline.io.parquet import read_table, write_table
from pipeline.simulate.demo import write_demo_flight


def _err_lines(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip() and not ln.startswith(("\r", " "))]


@pytest.fixture(scope="module")
def demo_logs(tmp_path_factory) -> tuple[Path, Path]:
    """Two different demo flights that share a file name (a/x.bin, b/x.bin)."""
    d = tmp_path_factory.mktemp("logs")
    (d / "a").mkdir(), (d / "b").mkdir()
    write_demo_flight(d / "a" / "x.bin", seed=3)
    write_demo_flight(d / "b" / "x.bin", seed=4)
    return d / "a" / "x.bin", d / "b" / "x.bin"


def test_an_error_no_command_foresaw_is_one_line_and_uavpipe_debug_shows_the_traceback(monkeypatch, capsys):
    import pipeline.cli.config as cmd

    def boom(args):
        raise RuntimeError("something\n  went wrong")

    monkeypatch.setattr(cmd, "run", boom)
    assert main(["config"]) == 1
    assert _err_lines(capsys) == ["uavpipe config: RuntimeError: something went wrong "
                                  "(UAVPIPE_DEBUG=1 shows the traceback)"]
    monkeypatch.setenv("UAVPIPE_DEBUG", "1")
    with pytest.raises(RuntimeError):
        main(["config"])


def test_two_logs_with_one_flight_id_do_not_overwrite_each_other(demo_logs, tmp_path, capsys):
    a, b = demo_logs
    assert main(["ingest", str(a), str(b), "-o", str(tmp_path)]) == 1
    err = _err_lines(capsys)
    assert f"uavpipe ingest: {b}: flight id x would overwrite {tmp_path / 'x'}, written from {a} in this run; skipped" in err
    assert err[-1] == "uavpipe ingest: 1 of 2 log(s) failed"
    assert json.loads((tmp_path / "x" / "meta.json").read_text())["source_path"] == str(a)


def test_preprocess_goes_on_past_a_bad_ingest_folder_and_refuses_a_second_one_of_a_flight(demo_logs, tmp_path, capsys):
    assert main(["ingest", str(demo_logs[0]), "-o", str(tmp_path / "ing")]) == 0
    good = tmp_path / "ing" / "x"
    listed = tmp_path / "ing" / "listed"
    shutil.copytree(good, listed)
    (listed / "meta.json").write_text("[]")
    twin = tmp_path / "ing" / "twin"
    shutil.copytree(good, twin)  # its meta.json says flight x too
    failed = tmp_path / "ing" / "failed"  # flight x as well, but its ingest failed
    shutil.copytree(good, failed)
    meta = json.loads((failed / "meta.json").read_text())
    (failed / "meta.json").write_text(json.dumps({**meta, "status": "failed", "error": "corrupt log"}))
    capsys.readouterr()
    rc = main(["preprocess", str(listed), str(failed), str(good), str(twin), "-o", str(tmp_path / "pp")])
    assert rc == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert f"uavpipe preprocess: {listed}: not an ingest folder ({listed / 'meta.json'} holds a JSON list, not an object)\n" in err
    assert f"uavpipe preprocess: {failed}: ingest failed: corrupt log\n" in err
    # a failure claims nothing: the good folder of flight x still runs; its twin may not overwrite it
    assert (f"uavpipe preprocess: {twin}: flight x would overwrite {tmp_path / 'pp' / 'x'}, "
            f"written from {good} in this run; skipped\n") in err
    assert err.endswith("uavpipe preprocess: 3 of 4 flight(s) failed\n")
    assert len(read_table(tmp_path / "pp" / "x" / "state.parquet")) > 100  # the good one ran


def test_classify_checks_the_model_and_the_tables_before_running_and_names_each(model_dir, tmp_path, capsys):
    st = tmp_path / "a" / "state.parquet"
    st.parent.mkdir()
    run = synth_bulk(("M1",), 1, np.random.default_rng(2)).drop(columns=["label", "run_id"])
    write_table(schema.conform("state", run), st, schema.STATE, name="state")
    (tmp_path / "b").mkdir()
    shutil.copy(st, tmp_path / "b" / "state.parquet")
    seg = tmp_path / "seg.parquet"
    write_table(schema.conform("segments", pd.DataFrame({"segment_id": [0], "t_start_ns": [0],
                                                          "t_end_ns": [10**10], "label": ["M1"]})),
                seg, schema.SEGMENTS, name="segments")
    # --reset-at-segments without segments to reset at
    assert main(["classify", str(model_dir), str(st), "-o", str(tmp_path / "c.parquet"), "--reset-at-segments"]) == 2
    assert _err_lines(capsys) == ["uavpipe classify: --reset-at-segments needs --segments (the segment starts to reset at)"]
    # a segments table given as the state; two a/state, b/state inputs written apart
    assert main(["classify", str(model_dir), str(seg), str(st), str(tmp_path / "b" / "state.parquet"),
                 "-o", str(tmp_path / "out")]) == 1
    err = [ln for ln in _err_lines(capsys) if ln.startswith("uavpipe classify:")]
    assert err == [f"uavpipe classify: {seg}: not a state table or simulated set (it is a 'segments' table)"]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["a-state.parquet", "b-state.parquet"]
    # a damaged model is named once, as the model's fault
    bad = tmp_path / "badmodel"
    shutil.copytree(model_dir, bad)
    (bad / "params.npz").write_bytes((model_dir / "params.npz").read_bytes()[:200])
    assert main(["classify", str(bad), str(st), "-o", str(tmp_path / "d.parquet")]) == 2   # refused before any work, as estimate --model
    err = _err_lines(capsys)
    assert len(err) == 1 and err[0].startswith(f"uavpipe classify: {bad}: unreadable model files: BadZipFile")
    (bad / "params.npz").write_bytes(b"")
    assert main(["classify", str(bad), str(st), "-o", str(tmp_path / "d.parquet")]) == 2
    assert _err_lines(capsys) == [f"uavpipe classify: {bad}: unreadable model files: EOFError: No data left in file"]
    shutil.copy(model_dir / "params.npz", bad / "params.npz")
    (bad / "meta.json").write_text("[1]")
    assert main(["classify", str(bad), str(st), "-o", str(tmp_path / "d.parquet")]) == 2
    assert _err_lines(capsys) == [f"uavpipe classify: {bad}: unreadable model files: meta.json holds a JSON "
                                  f"list, not an object"]


def test_train_names_a_swapped_state_and_segments_pair_and_a_negative_seed(model_dir, tmp_path, capsys):
    st, seg = tmp_path / "st.parquet", tmp_path / "seg.parquet"
    run = synth_bulk(("M1",), 1, np.random.default_rng(2)).drop(columns=["label", "run_id"])
    write_table(schema.conform("state", run), st, schema.STATE, name="state")
    write_table(schema.conform("segments", pd.DataFrame({"segment_id": [0], "t_start_ns": [0],
                                                          "t_end_ns": [10**10], "label": ["M1"]})),
                seg, schema.SEGMENTS, name="segments")
    assert main(["train", str(seg), "--segments", str(st), "-o", str(tmp_path / "m")]) == 2  # usage, as elsewhere
    assert _err_lines(capsys) == [f"uavpipe train: {seg}: not a state table (it is a 'segments' table)"]
    with pytest.raises(SystemExit) as exc:
        main(["train", str(st), "-o", str(tmp_path / "m"), "--seed", "-3"])
    assert exc.value.code == 2 and "-3 is negative (a seed is an integer >= 0)" in capsys.readouterr().err


def test_flights_in_the_cli_layout_train_as_separate_runs(tmp_path):
    from pipeline.models.run import flight_runs

    seg = pd.DataFrame({"segment_id": [0], "t_start_ns": [0], "t_end_ns": [10**10], "label": ["M1"]})
    paths = []
    for k, f in enumerate(("a", "b")):  # uavpipe preprocess -o DIR writes DIR/<flight>/state.parquet
        (tmp_path / f).mkdir()
        run = synth_bulk(("M1",), 1, np.random.default_rng(k)).drop(columns=["label", "run_id"])
        write_table(schema.conform("state", run), tmp_path / f / "state.parquet", schema.STATE, name="state")
        write_table(schema.conform("segments", seg), tmp_path / f / "segments.parquet", schema.SEGMENTS, name="segments")
        paths.append((tmp_path / f / "state.parquet", tmp_path / f / "segments.parquet"))
    runs = flight_runs([p for p, _ in paths], [s for _, s in paths])
    assert sorted(runs["run_id"].unique()) == ["a/state:0", "b/state:0"]  # was one run 'state:0' of both


def test_estimate_checks_its_side_inputs_before_any_flight(tmp_path, model_dir, capsys):
    inputs = ingested_flight(tmp_path)
    base = ["estimate", str(inputs["meta"].parent), "-o", str(tmp_path / "o")]
    q2 = tmp_path / "q2.json"
    q2.write_text("[]")
    seg = tmp_path / "seg.parquet"
    write_table(schema.empty("segments"), seg, schema.SEGMENTS, name="segments")
    cases = [(["--state", str(tmp_path / "nope.parquet")], f"--state {tmp_path / 'nope.parquet'}: no such file"),
             (["--state", str(seg)], f"--state {seg}: not a state table (it is a 'segments' table)"),
             (["--state", str(inputs["state"]), "--model", str(model_dir), "--q2", str(q2)],
              f"--q2 {q2}: holds a JSON list, not an object"),
             (["--state", str(inputs["state"]), "--vehicle", "bogus"], "--vehicle: unknown vehicle 'bogus'")]
    for extra, msg in cases:
        assert main([*base, *extra]) == 2
        err = _err_lines(capsys)
        assert len(err) == 1 and err[0].startswith(f"uavpipe estimate: {msg}"), err
    assert not (tmp_path / "o").exists()
    # a JSON object that is no Q2 file: refused up front, naming the file (was exit 0 with a placeholder)
    q2.write_text('{"a": 1}')
    assert main([*base, "--state", str(inputs["state"]), "--model", str(model_dir), "--q2", str(q2)]) == 2
    assert _err_lines(capsys) == [f"uavpipe estimate: --q2 {q2}: not a Q2 file of run_q2 (no 'status')"]
    assert not (tmp_path / "o").exists()


def test_simulate_and_align_refuse_an_output_folder_that_is_a_file_before_any_work(tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    assert main(["simulate", str(f)]) == 2
    assert _err_lines(capsys) == [f"uavpipe simulate: {f}: exists and is not a folder"]
    with pytest.raises(SystemExit) as exc:
        main(["simulate", str(tmp_path / "s"), "--seed", "-1"])
    assert exc.value.code == 2
    capsys.readouterr()
    st = tmp_path / "fc-p23-036.parquet"
    write_table(schema.empty("state"), st, schema.STATE, name="state")
    seg = tmp_path / "seg" / "fc-p23-036.parquet"
    seg.parent.mkdir()
    write_table(schema.empty("segments"), seg, schema.SEGMENTS, name="segments")
    assert main(["align", "--state", str(st), "--segments", str(seg), "--set", "p23", "-o", str(f)]) == 2
    assert _err_lines(capsys) == [f"uavpipe align: -o {f}: exists and is not a folder"]
    assert main(["align", "--state", str(seg), "--segments", str(st), "--set", "p23", "-o", str(tmp_path / "o")]) == 2
    assert _err_lines(capsys) == [f"uavpipe align: {seg}: not a state table (it is a 'segments' table)"]


def test_train_says_which_labels_the_data_has_when_the_selection_leaves_none(model_dir, tmp_path, capsys):
    s = model_dir.parent / "M12_train.parquet"
    assert main(["train", str(s), "-o", str(tmp_path / "m"), "--exclude", "M1", "M2"]) == 1
    err = _err_lines(capsys)
    # the reason once (from the training entry point), then where the placeholder is
    assert sum("no training samples left" in ln for ln in err) == 1, err
    assert ("no training samples left: the data has labels ['M1', 'M2'], the model set takes all and "
            "excludes ['M1', 'M2']") in err[0]
    assert err[1:] == [f"uavpipe train: no models trained; placeholder {tmp_path / 'm' / 'meta.json'} holds the reason"]



def test_a_log_cut_inside_its_header_fails_as_empty_instead_of_partial(demo_logs, tmp_path, capsys):
    cut = tmp_path / "cut.bin"
    cut.write_bytes(demo_logs[0].read_bytes()[:100])
    assert main(["ingest", str(cut), "-o", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert f"uavpipe ingest: FAILED {cut}: no data: every stream is empty after decoding as dataflash" in err
    assert json.loads((tmp_path / "o" / "cut" / "meta.json").read_text())["status"] == "failed"
