"""Every table of every stage is declared in ``io.schema``: one registry, ``empty``/``conform``/
``cast`` for streams and derived tables alike, and the stages use those declarations."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.io import schema
from pipeline.io.parquet import read_table, write_table

DERIVED = ("state", "segments", "calibration", "simulate_set", "simulate_summary", "flights",
           "classification", "model_evaluation", "estimate", "estimate_hmm", "hmpf", "pf", "bearing_estimate",
           "bearing_weights", "align_learned", "align_alignment", "align_iterations", "align_demos")


def test_the_registry_holds_every_stream_and_every_derived_table():
    assert set(schema.TABLES) == {*schema.STREAM_NAMES, *DERIVED, *schema.STUDY_RESULTS}
    for s in schema.STREAMS:
        assert schema.columns(s)[:4] == schema.COMMON
    assert schema.columns("state") is schema.STATE and schema.columns("labels") is schema.LABELS
    assert [c.name for c in schema.SIM_SET] == [c.name for c in schema.STATE] + ["run_id", "label"]
    with pytest.raises(schema.SchemaError, match="unknown table 'stat'"):
        schema.columns("stat")


@pytest.mark.parametrize("table", sorted(schema.TABLES))
def test_empty_has_every_declared_column_with_its_dtype(table):
    df = schema.empty(table)
    cols = [c for c in schema.columns(table) if not c.name.endswith("*")]
    assert list(df.columns) == [c.name for c in cols] and len(df) == 0
    for c in cols:
        assert str(df[c.name].dtype) == c.dtype, (table, c.name)
    again = schema.conform(table, df)
    assert list(again.columns) == list(df.columns) and len(again) == 0
    assert [str(d) for d in again.dtypes] == [str(d) for d in df.dtypes]


@pytest.mark.parametrize("table", sorted(schema.TABLES))
def test_empty_tables_round_trip_through_parquet(tmp_path, table):
    cols = tuple(c for c in schema.columns(table) if not c.name.endswith("*"))
    write_table(schema.empty(table), tmp_path / "t.parquet", cols, name=table)
    pd.testing.assert_frame_equal(read_table(tmp_path / "t.parquet", cols), schema.empty(table))


def test_conform_of_a_derived_table_adds_casts_orders_and_keeps_row_order():
    df = pd.DataFrame({"label": ["b", "a"], "t_end_ns": [30, 10], "t_start_ns": [20, 0],
                       "segment_id": np.array([1, 0], dtype=np.int32)})
    out = schema.conform("segments", df)
    assert list(out.columns) == ["segment_id", "t_start_ns", "t_end_ns", "label"]
    assert out["segment_id"].tolist() == [1, 0]  # derived tables are not re-sorted
    assert out["segment_id"].dtype == np.int64 and str(out["label"].dtype) == "string"
    cal = schema.conform("calibration", pd.DataFrame({"t_ns": [5], "region": [0], "used": [True]}))
    assert np.isnan(cal["h_ref_m"].iloc[0]) and cal["reason"].isna().all()
    with pytest.raises(schema.SchemaError, match="table 'segments': unknown column"):
        schema.conform("segments", df.assign(lable="x"))
    with pytest.raises(schema.SchemaError, match="'region'.*missing"):
        schema.conform("calibration", pd.DataFrame({"t_ns": [5], "region": [None]}))


def test_conform_keeps_a_wildcard_family_in_its_place():
    df = pd.DataFrame({"run_id": ["r"], "t_ns": [1], "pred": ["M1"], "ll_M2": [-2], "ll_M1": [-1.5],
                       "oneclass_ok": [True], "state": [0], "change": [False], "change_t_ns": [-1]})
    out = schema.conform("classification", df)
    names = list(out.columns)
    assert names[names.index("oneclass_ok") + 1:names.index("oneclass_ok") + 3] == ["ll_M2", "ll_M1"]
    assert out["ll_M2"].dtype == np.float64 and out["V_best"].isna().all()
    assert out["acc_hmm_gated_n"].isna().all()  # the GMR columns are optional
    assert names[:6] == list(schema.CLASSIFY_MIN_COLUMNS)
    assert "ll_*" not in names and "ll_*" not in schema.empty("classification").columns


def test_cast_names_the_column_that_fails():
    c = schema.Column("n_runs", "int64")
    assert schema.cast(c, pd.Series([1.0, 2.0])).dtype == np.int64
    with pytest.raises(schema.SchemaError, match="'n_runs'"):
        schema.cast(c, pd.Series(["x"]))


def test_stages_use_the_schema_declarations():
    from pipeline.models import run as models_run
    from pipeline.preprocess import calibrate
    from pipeline.simulate import datasets

    assert calibrate.CALIBRATION is schema.CALIBRATION
    assert datasets.SET_COLUMNS is schema.SIM_SET and datasets.SUMMARY_COLUMNS is schema.SIM_SUMMARY
    assert models_run.EVAL_COLUMNS == tuple(c.name for c in schema.MODEL_EVALUATION)
    assert models_run.CLASSIFY_MIN_COLUMNS == schema.CLASSIFY_MIN_COLUMNS
