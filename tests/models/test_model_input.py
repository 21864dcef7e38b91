"""A model set's ``input`` (truth | ekf): the thesis tables it is evaluated against, and the
config checks (``input: ekf`` needs simulated data)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.config import ConfigError, validate_config
from pipeline.io.parquet import read_table, read_table_meta
from pipeline.models.metrics import THESIS_EKF, THESIS_SWITCH_EKF, THESIS_TRUTH, thesis_side_by_side
from pipeline.models.run import run_evaluate, run_train, thesis_tables_for


@pytest.fixture
def rng():
    return np.random.default_rng(5)


def test_input_defaults_to_truth_and_takes_only_truth_or_ekf():
    cfg = validate_config({"model_sets": {"s": {"data": "simulated", "vehicles": ["q"]}}})
    assert cfg["model_sets"]["s"]["input"] == "truth"
    with pytest.raises(ConfigError, match=r"^model_sets\.s\.input: 'gps' is not one of truth, ekf$"):
        validate_config({"model_sets": {"s": {"data": "simulated", "vehicles": ["q"], "input": "gps"}}})


def test_ekf_input_on_flight_data_is_a_config_error_naming_the_model_set():
    validate_config({"model_sets": {"a": {"data": "simulated", "vehicles": ["q"], "input": "ekf"}}})
    validate_config({"model_sets": {"f": {"data": "flights", "vehicles": ["q"], "input": "truth"}}})
    with pytest.raises(ConfigError, match=r"^model_sets\.f\.input: 'ekf' is not truth with data: flights "
                                          r"\(input: ekf needs data: simulated\)$"):
        validate_config({"model_sets": {"f": {"data": "flights", "vehicles": ["q"], "input": "ekf"}}})


def test_the_shipped_config_has_simekf_on_ekf_input_beside_sim_on_truth():
    from pipeline.config import load_config

    sets = load_config()["model_sets"]
    assert sets["simekf"]["input"] == "ekf" and sets["simekf"]["data"] == "simulated"
    assert sets["sim"]["input"] == "truth"
    assert sets["simekf"]["labels"] == sets["sim"]["labels"]


def test_truth_input_maps_to_tables_3_1_to_3_4_and_ekf_input_to_3_5_to_3_8():
    assert thesis_tables_for({}) == {("train", "oneclass"): "3.1", ("train", "confidence"): "3.2",
                                     ("test", "oneclass"): "3.3", ("test", "confidence"): "3.4"}
    assert thesis_tables_for({"input": "ekf"}) == {("train", "oneclass"): "3.5", ("train", "confidence"): "3.6",
                                                   ("test", "oneclass"): "3.7", ("test", "confidence"): "3.8"}
    assert set(THESIS_EKF) == {"3.5", "3.6", "3.7", "3.8"} and not set(THESIS_EKF) & set(THESIS_TRUTH)


def test_the_thesis_ekf_tables_hold_the_digest_values():
    # digest §11, verbatim: Table 3.8 M1 100/87.88, M5 100/91.59; Table 3.5 M1 100/76.45
    assert THESIS_EKF["3.8"]["M1"] == (100, 87.88) and THESIS_EKF["3.8"]["M5"] == (100, 91.59)
    assert THESIS_EKF["3.5"]["M1"] == (100, 76.45) and "M5" not in THESIS_EKF["3.5"]
    assert THESIS_SWITCH_EKF[(3, "D")] == (8.23, 100, 19.20, 34.34)
    assert THESIS_SWITCH_EKF[(13, "D")] == (100, 84.77, 66.33, 10.25) and len(THESIS_SWITCH_EKF) == 12
    import pandas as pd

    t = thesis_side_by_side(pd.DataFrame({"maneuver": ["M4"], "n_runs": [1], "FA_pct": [1.0], "MAoT_pct": [2.0]}), "3.7")
    assert (t["thesis_FA_pct"].iloc[0], t["thesis_MAoT_pct"].iloc[0]) == (100, 89.00)


def _trained(synth, rng, tmp_path, **spec_extra):
    """A model set 'm' trained on three synthetic M1 and M2 runs: (sets, spec, model paths)."""
    _, bulk = synth
    sets = []
    for lab in ("M1", "M2"):
        p = tmp_path / f"{lab}_train.parquet"
        bulk([lab], 3, rng).to_parquet(p)
        sets.append(p)
    spec = {"data": "simulated", **spec_extra, "vehicles": ["x"], "hmm": {"n_states": 3, "n_iter": 5}}
    model = {"params": tmp_path / "m" / "params.npz", "meta": tmp_path / "m" / "meta.json"}
    assert run_train({"sets": sets}, model, spec, model_set="m", seed=3).status == "ok"
    return sets, spec, model


def test_an_ekf_input_model_set_is_evaluated_as_tables_3_5_to_3_8(synth, rng, tmp_path):
    sets, spec, model = _trained(synth, rng, tmp_path, input="ekf")
    out = tmp_path / "m" / "evaluation.parquet"
    run_evaluate({**model, "train_sets": sets, "test_sets": sets}, {"evaluation": out}, spec, model_set="m")
    ev = read_table(out)
    assert set(ev["table"]) == {"3.5", "3.6", "3.7", "3.8"}
    r = ev[(ev.table == "3.8") & (ev.maneuver == "M1")].iloc[0]
    assert (r.thesis_FA_pct, r.thesis_MAoT_pct) == THESIS_EKF["3.8"]["M1"]
    meta = read_table_meta(out)
    assert meta["input"] == "ekf" and meta["thesis_tables"] == ["3.5", "3.6", "3.7", "3.8"]


def test_classification_and_flight_evaluation_files_carry_the_declared_layout_and_units(synth, rng, tmp_path):
    import pyarrow.parquet as pq

    from pipeline.io import schema
    from pipeline.io.parquet import write_table
    from pipeline.models.run import run_classify

    run = synth[0]
    _, spec, model = _trained(synth, rng, tmp_path)
    flight = pd.concat([run("M1", rng), run("M2", rng, t0_ns=26_000_000_000)], ignore_index=True)
    seg = pd.DataFrame({"segment_id": [0, 1], "t_start_ns": [0, 26_000_000_000],
                        "t_end_ns": [25_000_000_000, 51_000_000_000], "label": ["M1", "M2"]})
    write_table(schema.conform("state", flight.drop(columns="label")), tmp_path / "state.parquet",
                schema.STATE, name="state", extra={"flight_id": "f1"})
    write_table(schema.conform("segments", seg), tmp_path / "segments.parquet", schema.SEGMENTS, name="segments")
    out = tmp_path / "f1.parquet"
    res = run_classify({**model, "state": tmp_path / "state.parquet", "segments": tmp_path / "segments.parquet"},
                       {"classification": out}, {}, model_set="m")
    assert res.status == "ok", res.error
    meta, arrow = read_table_meta(out), pq.read_schema(out)
    assert meta["columns"]["V_best"] == {"unit": "1", "frame": ""}
    assert meta["columns"]["t_ns"]["unit"] == "ns" and meta["columns"]["ll_M1"]["unit"] == "1"
    assert str(arrow.field("pred").type) == "string" and str(arrow.field("t_ns").type) == "int64"
    assert arrow.names[:6] == list(schema.CLASSIFY_MIN_COLUMNS)
    ev_out = tmp_path / "evaluation.parquet"
    run_evaluate({**model, "classified": [out]}, {"evaluation": ev_out}, {**spec, "data": "flights"}, model_set="m")
    ev, ev_arrow = read_table(ev_out), pq.read_schema(ev_out)
    assert len(ev) == 2 and ev_arrow.names == [c.name for c in schema.MODEL_EVALUATION]
    assert str(ev_arrow.field("thesis_FA_pct").type) == "double"  # NaN for flights, never int64
    assert read_table_meta(ev_out)["columns"]["FA_pct"]["unit"] == "%"


def test_training_flights_that_give_no_labelled_sample_are_named_with_the_reason(synth, rng, tmp_path, capsys):
    from pipeline.io import schema
    from pipeline.io.parquet import write_table
    from pipeline.models.run import run_train

    run = synth[0]
    flight = pd.concat([run("M1", rng), run("M2", rng, t0_ns=26_000_000_000)], ignore_index=True)
    labelled = pd.DataFrame({"segment_id": [0, 1], "t_start_ns": [0, 26_000_000_000],
                             "t_end_ns": [25_000_000_000, 51_000_000_000], "label": ["M1", "M2"]})
    states, segments = [], []
    for name, st, seg, extra in (("good", flight, labelled, {}),
                                 ("nolabels", flight, labelled.iloc[:0], {}),
                                 ("failed", flight.iloc[:0], labelled.iloc[:0],
                                  {"status": "failed", "error": "preprocessing failed: time span"})):
        write_table(schema.conform("state", st.drop(columns="label")), tmp_path / f"{name}.parquet",
                    schema.STATE, name="state", extra={"flight_id": name, **extra})
        write_table(schema.conform("segments", seg), tmp_path / f"{name}.seg.parquet", schema.SEGMENTS,
                    name="segments")
        states.append(tmp_path / f"{name}.parquet")
        segments.append(tmp_path / f"{name}.seg.parquet")
    d = tmp_path / "m"
    spec = {"data": "flights", "vehicles": ["q"], "hmm": {"n_states": 3, "n_iter": 3, "phases": False}}
    res = run_train({"states": states, "segments": segments}, {"params": d / "params.npz", "meta": d / "meta.json"},
                    spec, model_set="m", seed=1)
    assert res.status == "ok"
    assert res.diagnostics["training_skipped"] == {
        "nolabels": "no labelled segments", "failed": "no state (preprocessing failed: time span)"}
    err = capsys.readouterr().err
    assert ("m: 2 of 3 training flight(s) gave no labelled sample: nolabels (no labelled segments); "
            "failed (no state (preprocessing failed: time span))") in err
    # none left: the placeholder's reason names them, not a guess
    res = run_train({"states": states[1:], "segments": segments[1:]},
                    {"params": d / "params.npz", "meta": d / "meta.json"}, spec, model_set="m", seed=1)
    assert res.status == "failed" and "nolabels: no labelled segments; failed: no state" in res.error


def _flight_files(synth, rng, tmp_path, names):
    """State and segment tables of one labelled M1+M2 flight per name: (states, segments)."""
    from pipeline.io import schema
    from pipeline.io.parquet import write_table

    run = synth[0]
    flight = pd.concat([run("M1", rng), run("M2", rng, t0_ns=26_000_000_000)], ignore_index=True)
    seg = pd.DataFrame({"segment_id": [0, 1], "t_start_ns": [0, 26_000_000_000],
                        "t_end_ns": [25_000_000_000, 51_000_000_000], "label": ["M1", "M2"]})
    states, segments = [], []
    for name in names:
        write_table(schema.conform("state", flight.drop(columns="label")), tmp_path / f"{name}.parquet",
                    schema.STATE, name="state", extra={"flight_id": name})
        write_table(schema.conform("segments", seg), tmp_path / f"{name}.seg.parquet", schema.SEGMENTS,
                    name="segments")
        states.append(tmp_path / f"{name}.parquet")
        segments.append(tmp_path / f"{name}.seg.parquet")
    return states, segments


_FLIGHTS_SPEC = {"data": "flights", "vehicles": ["q"], "hmm": {"n_states": 3, "n_iter": 3, "phases": False}}


def test_a_training_flight_with_a_garbage_state_or_segments_file_is_skipped_by_name_and_the_others_train(
        synth, rng, tmp_path, capsys):
    import json

    states, segments = _flight_files(synth, rng, tmp_path, ["good", "badstate", "badseg"])
    states[1].write_bytes(b"not a parquet file\n\x00\x01 damaged on the card")
    segments[2].write_bytes(b"PAR1 truncated")
    d = tmp_path / "m"
    res = run_train({"states": states, "segments": segments}, {"params": d / "params.npz", "meta": d / "meta.json"},
                    _FLIGHTS_SPEC, model_set="m", seed=1)
    assert res.status == "ok", res.error
    assert res.diagnostics["labels"] == ["M1", "M2"]
    skipped = res.diagnostics["training_skipped"]
    assert set(skipped) == {"badstate", "badseg"}
    assert skipped["badstate"].startswith("unreadable state: ArrowInvalid: ")
    assert skipped["badseg"].startswith("unreadable segments: ArrowInvalid: ")
    assert all("\n" not in why for why in skipped.values())
    assert json.loads((d / "meta.json").read_text())["training_skipped"] == skipped
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert "m: 2 of 3 training flight(s) gave no labelled sample: badstate (unreadable state: ArrowInvalid" in err


@pytest.mark.parametrize("damage, kind", [("missing", "FileNotFoundError"), ("directory", "OSError")])
def test_a_training_flight_whose_state_path_is_missing_or_a_directory_is_skipped_in_one_line_not_a_traceback(
        synth, rng, tmp_path, capsys, damage, kind):
    states, segments = _flight_files(synth, rng, tmp_path, ["good", "bad"])
    states[1].unlink()
    if damage == "directory":
        states[1].mkdir()
    d = tmp_path / "m"
    out = {"params": d / "params.npz", "meta": d / "meta.json"}
    res = run_train({"states": states, "segments": segments}, out, _FLIGHTS_SPEC, model_set="m", seed=1)
    assert res.status == "ok", res.error
    why = res.diagnostics["training_skipped"]["bad"]
    assert why.startswith(f"unreadable state: {kind}: ") and "bad.parquet" in why and "\n" not in why
    assert list(res.diagnostics["training_skipped"]) == ["bad"]
    # no flight left: a failed placeholder whose one-line reason names the flight, still no traceback
    res = run_train({"states": states[1:], "segments": segments[1:]}, out, _FLIGHTS_SPEC, model_set="m", seed=1)
    assert res.status == "failed" and f"bad: unreadable state: {kind}" in res.error and "\n" not in res.error
    assert "Traceback" not in capsys.readouterr().err


def test_flight_evaluation_metadata_lists_the_flights_used_and_names_each_skipped_one_with_its_reason(
        synth, rng, tmp_path, capsys):
    from pipeline.io import schema
    from pipeline.io.parquet import write_table
    from pipeline.models.run import run_classify

    _, spec, model = _trained(synth, rng, tmp_path)
    states, segments = _flight_files(synth, rng, tmp_path, ["f1", "f2"])
    write_table(schema.conform("state", pd.DataFrame({"t_ns": pd.Series([], dtype="int64")})),
                tmp_path / "f3.parquet", schema.STATE, name="state",
                extra={"flight_id": "f3", "status": "failed", "error": "preprocessing failed: no GPS\nfix"})
    cdir = tmp_path / "classify"
    classified = [cdir / f"{f}.parquet" for f in ("f1", "f2", "f3", "f4", "f5", "f6")]
    # f4: classified without its segments; f5: its one segment after the flight ended
    late = pd.DataFrame({"segment_id": [0], "t_start_ns": [90_000_000_000], "t_end_ns": [99_000_000_000],
                         "label": ["M1"]})
    write_table(schema.conform("segments", late), tmp_path / "late.seg.parquet", schema.SEGMENTS, name="segments")
    for st, seg, out in zip([*states, tmp_path / "f3.parquet", states[0], states[0]],
                            [*segments, None, None, tmp_path / "late.seg.parquet"], classified):
        run_classify({**model, "state": st, "segments": seg}, {"classification": out}, {}, model_set="m")
    classified[5].write_bytes(b"garbage")  # f6: damaged on disk
    ev_out = tmp_path / "evaluation.parquet"
    res = run_evaluate({**model, "classified": classified}, {"evaluation": ev_out}, {**spec, "data": "flights"},
                       model_set="m")
    assert res.status == "ok"
    meta = read_table_meta(ev_out)
    assert meta["flights_used"] == ["f1", "f2"] == res.diagnostics["flights_used"]
    skipped = meta["flights_skipped"]
    assert skipped["f3"] == "no classification (preprocessing failed: no GPS fix)"
    assert skipped["f4"] == "no 'truth' column (not classified with its segments)"
    assert skipped["f5"] == "no classified sample inside a labelled segment"
    assert skipped["f6"].startswith("unreadable classification: ArrowInvalid: ") and "f6.parquet" in skipped["f6"]
    assert list(skipped) == ["f3", "f4", "f5", "f6"] and all("\n" not in why for why in skipped.values())
    assert set(read_table(ev_out)["n_runs"]) == {2}  # one run per segment of each used flight
    err = capsys.readouterr().err
    assert "m: 4 of 6 test flight(s) left out of the evaluation: f3 (no classification (" in err
    assert "placeholder classification (preprocessing failed: no GPS fix)" in err  # one line there too


def test_a_failed_model_set_names_every_test_flight_as_skipped_in_the_evaluation_metadata(tmp_path):
    d = tmp_path / "m"
    model = {"params": d / "params.npz", "meta": d / "meta.json"}
    assert run_train({"states": [], "segments": []}, model, _FLIGHTS_SPEC, model_set="m", seed=1).status == "failed"
    ev_out = tmp_path / "evaluation.parquet"
    res = run_evaluate({**model, "classified": [tmp_path / "f1.parquet"]}, {"evaluation": ev_out}, _FLIGHTS_SPEC,
                       model_set="m")
    meta = read_table_meta(ev_out)
    assert res.status == meta["status"] == "failed"
    assert meta["flights_used"] == [] and meta["flights_skipped"] == {"f1": "model set m failed"}


def test_a_flight_whose_state_or_segments_cannot_be_read_is_a_classification_placeholder_naming_it(synth, rng, tmp_path,
                                                                                                      capsys):
    from pipeline.models.run import run_classify

    _, _, model = _trained(synth, rng, tmp_path)
    states, segments = _flight_files(synth, rng, tmp_path, ["f1"])
    bad_state = tmp_path / "bad.parquet"
    bad_state.write_bytes(b"garbage")
    bad_seg = tmp_path / "bad.seg.parquet"
    bad_seg.write_bytes(b"PAR1 garbage")
    for st, seg, why in ((bad_state, segments[0], f"cannot read {bad_state}: ArrowInvalid"),
                         (states[0], bad_seg, "classification failed: ArrowInvalid")):
        out = tmp_path / f"out-{st.stem}-{seg.stem}.parquet"
        res = run_classify({**model, "state": st, "segments": seg}, {"classification": out}, {}, model_set="m")
        meta = read_table_meta(out)
        assert res.status == "failed" and res.error.startswith(why) and "\n" not in res.error
        assert meta["status"] == "failed" and meta["error"] == res.error and not len(read_table(out))
    assert "Traceback" not in capsys.readouterr().err
