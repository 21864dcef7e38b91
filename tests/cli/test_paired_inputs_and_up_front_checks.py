"""Inputs paired by position hold one flight, side inputs and output folders are checked once
before any work, and usage errors exit 2 in every command (the CLI audit's items 2, 4-7, 9, 14
and 15)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from helpers_maneuvers import synth_bulk
from pipeline.cli import main
from pipeline.io import schema
from pipeline.io.parquet import write_table


def _err_lines(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip() and not ln.startswith(("\r", " "))]


def _table(path: Path, kind: str, flight: str | None = None, *, name: str | None = None, **extra) -> Path:
    """An empty ``kind`` table at ``path`` whose metadata says ``flight`` (when given)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {**({"flight_id": flight} if flight else {}), **extra}
    write_table(schema.empty(kind), path, schema.columns(kind), name=name or kind, extra=meta)
    return path


def _ingest_dir(path: Path, flight: str) -> Path:
    """An ingest folder as far as its ``meta.json`` goes (the checks run before any stream is read)."""
    path.mkdir(parents=True, exist_ok=True)
    (path / "meta.json").write_text(json.dumps({"flight_id": flight}))
    return path


@pytest.fixture
def two_flights(tmp_path) -> dict[str, dict[str, Path]]:
    """Flights a and b in the CLI layout: ``ing/<f>`` and ``pp/<f>/{state,segments}.parquet``."""
    return {f: {"ingest": _ingest_dir(tmp_path / "ing" / f, f),
                "state": _table(tmp_path / "pp" / f / "state.parquet", "state", f),
                "segments": _table(tmp_path / "pp" / f / "segments.parquet", "segments", f)} for f in ("a", "b")}


def test_estimate_refuses_a_state_of_another_flight_in_one_line_naming_both_files(two_flights, tmp_path, capsys):
    a, b = two_flights["a"], two_flights["b"]
    rc = main(["estimate", str(a["ingest"]), str(b["ingest"]), "--state", str(b["state"]), str(a["state"]),
               "-o", str(tmp_path / "o")])
    assert rc == 2
    assert _err_lines(capsys) == [f"uavpipe estimate: {a['ingest']} (flight a) and --state {b['state']} (flight b) "
                                  f"are paired by position but hold different flights"]
    rc = main(["estimate", str(a["ingest"]), "--state", str(a["state"]), "--segments", str(b["segments"]),
               "-o", str(tmp_path / "o")])
    assert rc == 2
    assert _err_lines(capsys) == [f"uavpipe estimate: {a['ingest']} (flight a) and --segments {b['segments']} "
                                  f"(flight b) are paired by position but hold different flights"]
    assert not (tmp_path / "o").exists()


def test_classify_and_train_refuse_segments_of_another_flight(two_flights, model_dir, tmp_path, capsys):
    a, b = two_flights["a"], two_flights["b"]
    rc = main(["classify", str(model_dir), str(a["state"]), "--segments", str(b["segments"]),
               "-o", str(tmp_path / "c.parquet")])
    assert rc == 2
    assert _err_lines(capsys) == [f"uavpipe classify: {a['state']} (flight a) and --segments {b['segments']} "
                                  f"(flight b) are paired by position but hold different flights"]
    rc = main(["train", str(a["state"]), str(b["state"]), "--segments", str(b["segments"]), str(a["segments"]),
               "-o", str(tmp_path / "m")])
    assert rc == 2
    assert _err_lines(capsys) == [f"uavpipe train: {a['state']} (flight a) and --segments {b['segments']} "
                                  f"(flight b) are paired by position but hold different flights"]
    assert not (tmp_path / "c.parquet").exists() and not (tmp_path / "m").exists()


@pytest.mark.parametrize("content, reason", [
    ("{}", "not a Q2 file of run_q2 (no 'status')"),
    ('{"status": "ok"}', "not a Q2 file of run_q2 (no 'Q2')"),
    ('{"status": "ok", "Q2": "x"}', "Q2 is not a numeric matrix (ValueError: could not convert string to float: 'x')"),
    ('{"status": "ok", "Q2": [[1, 2], [3, 4]]}', "Q2 is not a finite 9 x 9 matrix (shape (2, 2))"),
    ('{"status": "failed", "error": "no training runs", "Q2": null}',
     "records a failed Q2 (status 'failed': no training runs)"),
    # a covariance: -I ended every flight's EKF+HMM in a non-positive-definite innovation
    ('{"status": "ok", "Q2": [[-1.0, -0.0, -0.0, -0.0, -0.0, -0.0, -0.0, -0.0, -0.0], [-0.0, -1.0, -0.0, -0.0, -0.0, -0.0, -0.0, -0.0, -0.0], [-0.0, -0.0, -1.0, -0.0, -0.0, -0.0, -0.0, -0.0, -0.0], [-0.0, -0.0, -0.0, -1.0, -0.0, -0.0, -0.0, -0.0, -0.0], [-0.0, -0.0, -0.0, -0.0, -1.0, -0.0, -0.0, -0.0, -0.0], [-0.0, -0.0, -0.0, -0.0, -0.0, -1.0, -0.0, -0.0, -0.0], [-0.0, -0.0, -0.0, -0.0, -0.0, -0.0, -1.0, -0.0, -0.0], [-0.0, -0.0, -0.0, -0.0, -0.0, -0.0, -0.0, -1.0, -0.0], [-0.0, -0.0, -0.0, -0.0, -0.0, -0.0, -0.0, -0.0, -1.0]]}', "Q2 is not positive semidefinite (smallest eigenvalue -1; a covariance is)"),
    ('{"status": "ok", "Q2": [[1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]]}', "Q2 is not symmetric (a covariance is)"),
    ('{"status": "ok", "model_set": "another", "Q2": [[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]]}',
     "is the Q2 of model set another, not m"),
])
def test_estimate_refuses_a_bad_q2_file_before_any_flight_naming_the_option_and_file(
        two_flights, model_dir, tmp_path, capsys, content, reason):
    a = two_flights["a"]
    q2 = tmp_path / "q2.json"
    q2.write_text(content)
    rc = main(["estimate", str(a["ingest"]), "--state", str(a["state"]), "-o", str(tmp_path / "o"),
               "--model", str(model_dir), "--q2", str(q2)])
    assert rc == 2
    assert _err_lines(capsys) == [f"uavpipe estimate: --q2 {q2}: {reason}"]
    assert not (tmp_path / "o").exists()


def test_estimate_loads_the_model_once_up_front_and_names_the_damaged_file(two_flights, model_dir, tmp_path, capsys):
    a, b = two_flights["a"], two_flights["b"]
    bad = tmp_path / "badmodel"
    shutil.copytree(model_dir, bad)
    q2 = tmp_path / "q2.json"
    q2.write_text(json.dumps({"status": "ok", "Q2": [[float(i == j) for j in range(9)] for i in range(9)]}))
    args = ["estimate", str(a["ingest"]), str(b["ingest"]), "--state", str(a["state"]), str(b["state"]),
            "-o", str(tmp_path / "o"), "--model", str(bad), "--q2", str(q2)]
    (bad / "meta.json").write_text("garbage")
    assert main(args) == 2
    err = _err_lines(capsys)  # once, not once per flight
    assert len(err) == 1 and err[0].startswith(f"uavpipe estimate: --model {bad}: {bad / 'meta.json'}: "
                                               f"not a readable JSON file (JSONDecodeError"), err
    shutil.copy(model_dir / "meta.json", bad / "meta.json")
    (bad / "params.npz").write_bytes((model_dir / "params.npz").read_bytes()[:200])
    assert main(args) == 2
    err = _err_lines(capsys)
    assert len(err) == 1, err
    assert err[0].startswith(f"uavpipe estimate: --model {bad}: {bad / 'params.npz'}: BadZipFile"), err
    assert not (tmp_path / "o").exists()


def test_estimate_model_and_its_q2_go_together_and_train_sets_must_be_simulated_sets(
        two_flights, model_dir, tmp_path, capsys):
    a = two_flights["a"]
    base = ["estimate", str(a["ingest"]), "--state", str(a["state"]), "-o", str(tmp_path / "o")]
    q2 = tmp_path / "q2.json"
    q2.write_text("{}")
    st = str(a["state"])
    cases = [(["--q2", str(q2)], "--q2 needs --model (the model set whose Q2 it is)"),
             (["--train-sets", st], "--train-sets needs --model (the model set whose Q2 it is)"),
             (["--model", str(model_dir)], "--model needs --q2 Q2.json or --train-sets SET... (the model set's Q2)"),
             (["--model", str(model_dir), "--q2", str(q2), "--train-sets", st],
              "--q2 and --train-sets: give one (a Q2 file, or the sets to compute it from)"),
             (["--model", str(model_dir), "--train-sets", st],
              f"--train-sets {st}: not a simulated set (it is a 'state' table)")]
    for extra, msg in cases:
        assert main([*base, *extra]) == 2
        assert _err_lines(capsys) == [f"uavpipe estimate: {msg}"]
    assert not (tmp_path / "o").exists()


def test_an_output_folder_that_is_a_file_is_refused_once_before_any_work(two_flights, model_dir, tmp_path, capsys):
    a, b = two_flights["a"], two_flights["b"]
    f = tmp_path / "notes.txt"
    f.write_text("x")
    runs = {"ingest": ["ingest", str(tmp_path / "x.bin"), str(tmp_path / "y.bin"), "-o", str(f)],
            "preprocess": ["preprocess", str(a["ingest"]), str(b["ingest"]), "-o", str(f)],
            "estimate": ["estimate", str(a["ingest"]), "--state", str(a["state"]), "-o", str(f)],
            "classify": ["classify", str(model_dir), str(a["state"]), str(b["state"]), "-o", str(f)]}
    for command, args in runs.items():
        assert main(args) == 2, command
        assert _err_lines(capsys) == [f"uavpipe {command}: -o {f}: exists and is not a folder"]
        # a file where a folder above it must go: once, not a 'Not a directory' per flight
        sub = f / "out"
        assert main([str(sub) if x == str(f) else x for x in args]) == 2, command
        assert _err_lines(capsys) == [f"uavpipe {command}: -o {sub}: {f} is a file, not a folder"]
    assert f.read_text() == "x"


def test_classify_of_one_table_into_an_existing_folder_writes_it_there_as_several_would(model_dir, tmp_path, capsys):
    st = tmp_path / "pp" / "a" / "state.parquet"
    st.parent.mkdir(parents=True)
    run = synth_bulk(("M1",), 1, np.random.default_rng(2)).drop(columns=["label", "run_id"])
    write_table(schema.conform("state", run), st, schema.STATE, name="state", extra={"flight_id": "a"})
    out = tmp_path / "out"
    out.mkdir()
    assert main(["classify", str(model_dir), str(st), "-o", str(out)]) == 0
    assert f"{st} -> {out / 'state.parquet'} (" in capsys.readouterr().out
    assert [p.name for p in out.iterdir()] == ["state.parquet"]  # no temp file named, nothing left over


def test_usage_errors_of_train_and_classify_exit_2_as_in_every_command(model_dir, tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("hmm: {bogus: 1}\n")
    s = model_dir.parent / "M12_train.parquet"
    assert main(["train", str(s), "-o", str(tmp_path / "m"), "--config", str(bad)]) == 2
    err = _err_lines(capsys)
    assert len(err) == 1 and err[0].startswith(f"uavpipe train: {bad}: hmm.bogus: unknown key")
    st = _table(tmp_path / "st.parquet", "state")
    seg = _table(tmp_path / "seg.parquet", "segments")
    assert main(["classify", str(model_dir), str(st), "--segments", str(seg), str(seg), "-o", str(tmp_path / "c")]) == 2
    assert _err_lines(capsys) == ["uavpipe classify: --segments: 2 given for 1 tables"]


def test_a_set_written_by_an_older_uavpipe_is_refused_with_how_to_rebuild_it(model_dir, tmp_path, capsys):
    # before sets recorded table 'simulate_set', their table kind was the set's own name
    old = _table(tmp_path / "M1_train.parquet", "simulate_set", name="M1_train", seed=1, runs=0)
    msg = (f"{old}: a simulated set written by an older uavpipe (its metadata names the table 'M1_train', "
           f"not 'simulate_set'): rerun `snakemake -R simulate_sets` to rebuild the sets")
    assert main(["train", str(old), "-o", str(tmp_path / "m")]) == 2
    assert _err_lines(capsys) == [f"uavpipe train: {msg}"]
    ing = _ingest_dir(tmp_path / "ing" / "a", "a")
    st = _table(tmp_path / "st.parquet", "state", "a")
    assert main(["estimate", str(ing), "--state", str(st), "-o", str(tmp_path / "o"), "--model", str(model_dir),
                 "--train-sets", str(old)]) == 2
    assert _err_lines(capsys) == [f"uavpipe estimate: --train-sets {msg}"]
    # another kind of table stays named as such
    seg = _table(tmp_path / "seg.parquet", "segments")
    assert main(["train", str(seg), "-o", str(tmp_path / "m")]) == 2
    assert _err_lines(capsys) == [f"uavpipe train: {seg}: not a simulated set or labelled state table "
                                  f"(it is a 'segments' table)"]


def test_classify_help_states_the_real_defaults_and_ingest_docs_agree_with_its_help(capsys):
    import pipeline.cli.ingest as ingest_cmd

    with pytest.raises(SystemExit):
        main(["classify", "--help"])
    out = " ".join(capsys.readouterr().out.split())  # argparse wraps the help text
    assert "classification mode (default: the model set's own, its hmm.mode when trained)" in out
    assert "decision rule (default: the model set's own, its hmm.decision when trained)" in out
    with pytest.raises(SystemExit):
        main(["ingest", "--help"])
    assert "(default datasets/config.yaml" in " ".join(capsys.readouterr().out.split())
    doc = " ".join(ingest_cmd.__doc__.split())
    assert "readers use their defaults" not in doc and "datasets/config.yaml" in doc


def test_estimate_refuses_a_model_set_without_a_gmr_up_front(two_flights, model_dir, tmp_path, capsys, monkeypatch):
    # the fixture's state9h model stands in for a set without a GMR (an aero or box model):
    # without the check, every flight would end as an ekf_hmm placeholder and the run exit 0
    import pipeline.models.features as features

    monkeypatch.setattr(features, "GMR_FEATURE_SETS", ("state9", "state9box"))
    a = two_flights["a"]
    q2 = tmp_path / "q2.json"
    q2.write_text(json.dumps({"status": "ok", "Q2": [[float(i == j) for j in range(9)] for i in range(9)]}))
    rc = main(["estimate", str(a["ingest"]), "--state", str(a["state"]), "-o", str(tmp_path / "o"),
               "--model", str(model_dir), "--q2", str(q2)])
    assert rc == 2
    assert _err_lines(capsys) == [f"uavpipe estimate: --model {model_dir}: has no GMR (feature set state9h; "
                                  f"the EKF+HMM needs one of state9, state9box)"]
    assert not (tmp_path / "o").exists()


def test_a_segments_table_without_its_end_times_is_refused_up_front_by_every_command_naming_the_column(
        two_flights, tmp_path, capsys):
    # an edited table kept its 'segments' metadata; the readers failed deep inside with
    # "'Pandas' object has no attribute 't_end_ns'"
    import pyarrow.parquet as pq

    a, b = two_flights["a"], two_flights["b"]
    seg = b["segments"]
    pq.write_table(pq.read_table(seg).drop(["t_end_ns"]), seg)
    want = f"{seg}: a segments table without column(s) t_end_ns"
    rc = main(["align", "--state", str(a["state"]), str(b["state"]), "--segments", str(a["segments"]), str(seg),
               "--set", "p23", "-o", str(tmp_path / "al")])
    assert rc == 2 and _err_lines(capsys) == [f"uavpipe align: {want}"]
    rc = main(["train", str(b["state"]), "--segments", str(seg), "-o", str(tmp_path / "m")])
    assert rc == 2 and _err_lines(capsys) == [f"uavpipe train: {want}"]
    rc = main(["estimate", str(b["ingest"]), "--state", str(b["state"]), "--segments", str(seg),
               "-o", str(tmp_path / "e")])
    assert rc == 2 and _err_lines(capsys) == [f"uavpipe estimate: --segments {want}"]
    assert not any((tmp_path / d).exists() for d in ("al", "m", "e"))
