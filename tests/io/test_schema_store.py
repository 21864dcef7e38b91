"""The canonical schema, FlightLog conformance and the Parquet store round trip."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings, strategies as st

from pipeline.io import schema
from pipeline.io.base import FlightLog, IngestError
from pipeline.io.parquet import read_flightlog, read_table_meta, write_flightlog
from pipeline.io.registry import detect, flight_id_for, read_log


def test_every_stream_has_full_schema_when_absent():
    log = FlightLog.from_streams({"flight_id": "x"}, {})
    assert set(log.streams) == set(schema.STREAM_NAMES)
    for name, df in log.streams.items():
        assert list(df.columns) == schema.column_names(name)
        assert len(df) == 0
    assert log["imu"]["t_ns"].dtype == np.int64
    assert log["imu"]["instance"].dtype == np.uint8


def test_units_in_column_names_are_declared():
    # every physical column carries its unit suffix and a unit string
    for name in schema.TABLES:  # every declared table, the studies' included
        inferred = schema.units_from_names(c.name for c in schema.columns(name))
        for c in schema.columns(name):
            if c.name in inferred:
                assert c.unit == inferred[c.name]["unit"], (name, c.name, c.unit)


def test_a_study_table_is_written_in_its_declared_types_units_and_order(tmp_path):
    from pipeline.io.parquet import write_table

    # seed000_gmr_rmse declares maneuver, quantity, rmse, n: given out of order, n as float
    df = pd.DataFrame({"n": [3.0], "rmse": [0.25], "quantity": ["acc"], "maneuver": ["M1"]})
    write_table(df, tmp_path / "t.parquet", name="seed000_classification_gmr_rmse")
    sch = pq.read_schema(tmp_path / "t.parquet")
    assert sch.names == [c.name for c in schema.columns("seed000_classification_gmr_rmse")]
    assert str(sch.field("n").type) == "int64" and str(sch.field("maneuver").type) == "string"
    meta = read_table_meta(tmp_path / "t.parquet")
    assert meta["table"] == "seed000_classification_gmr_rmse" and meta["columns"]["rmse"]["unit"] == schema.columns(
        "seed000_classification_gmr_rmse")[2].unit


def test_an_undeclared_study_table_or_column_is_refused_naming_the_file(tmp_path):
    from pipeline.io.parquet import write_table

    with pytest.raises(schema.SchemaError, match=r"t\.parquet: table 'study_x' is not declared"):
        write_table(pd.DataFrame({"err_m": [1.0]}), tmp_path / "t.parquet", name="study_x")
    with pytest.raises(schema.SchemaError, match=r"t\.parquet: .*undeclared column\(s\) \['extra_m'\]"):
        write_table(pd.DataFrame({"maneuver": ["M1"], "extra_m": [1.0]}), tmp_path / "t.parquet",
                    name="seed000_classification_gmr_rmse")
    assert not (tmp_path / "t.parquet").exists()


def test_a_part_that_did_not_run_writes_its_declared_columns_with_no_rows(tmp_path):
    from pipeline.io.parquet import read_table, write_table

    write_table(pd.DataFrame(), tmp_path / "t.parquet", name="seed000_classification_gmr_rmse", extra={"skipped": True})
    df = read_table(tmp_path / "t.parquet")
    assert list(df.columns) == [c.name for c in schema.columns("seed000_classification_gmr_rmse")] and len(df) == 0
    assert read_table_meta(tmp_path / "t.parquet")["skipped"] is True


def test_conform_sorts_stably_and_counts_anomalies_in_arrival_order():
    imu = pd.DataFrame({"t_ns": [10, 5, 5, 20, 1], "instance": [0, 0, 0, 0, 1], "src": ["IMU"] * 4 + ["IMU2"],
                        "gyr_x_radps": [1.0, 2.0, 3.0, 4.0, 5.0]})
    log = FlightLog.from_streams({}, {"imu": imu})
    out = log["imu"]
    assert out["t_ns"].tolist() == [5, 5, 10, 20, 1]
    assert out["gyr_x_radps"].tolist() == [2.0, 3.0, 1.0, 4.0, 5.0]  # stable: 2 before 3
    assert log.meta["diagnostics"]["timestamp_anomalies"]["imu"] == {"backwards": 1, "duplicate": 1}


def test_unknown_column_or_stream_is_rejected():
    with pytest.raises(schema.SchemaError, match="unknown column"):
        FlightLog.from_streams({}, {"imu": pd.DataFrame({"t_ns": [1], "gyro_x": [1.0]})})
    with pytest.raises(schema.SchemaError, match="unknown stream"):
        FlightLog.from_streams({}, {"imus": pd.DataFrame({"t_ns": [1]})})


def _random_log(rng: np.random.Generator) -> FlightLog:
    n = int(rng.integers(1, 50))
    imu = pd.DataFrame({"t_ns": rng.integers(0, 10**12, n), "instance": rng.integers(0, 3, n),
                        "src": rng.choice(["IMU", "IMU2"], n), "acc_z_mps2": rng.normal(size=n),
                        "t_boot_ns": pd.array(np.where(rng.random(n) < 0.3, None, rng.integers(0, 10**9, n)),
                                              dtype="Int64")})
    mode = pd.DataFrame({"t_ns": np.sort(rng.integers(0, 10**9, 3)), "src": "MODE",
                         "mode": ["STABILIZE", None, "LOITER"], "armed": pd.array([True, None, False], dtype="boolean")})
    rf = pd.DataFrame({"t_ns": [1, 2], "dist_m": [0.5, np.nan], "valid": [True, False], "src": "RFND"})
    labels = pd.DataFrame({"t_start_ns": [5, 1], "t_end_ns": [9, 4], "label": ["M2", "M1"], "source": "sim"})
    return FlightLog.from_streams({"flight_id": "f-1", "ned_origin": {"lat_deg": 1.0, "lon_deg": 2.0,
                                   "alt_wgs84_m": 3.0}}, {"imu": imu, "mode": mode, "rangefinder": rf,
                                                           "labels": labels})


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_parquet_round_trip_is_exact(tmp_path_factory, seed):
    log = _random_log(np.random.default_rng(seed))
    d = tmp_path_factory.mktemp("store")
    write_flightlog(log, d)
    back = read_flightlog(d)
    assert back.meta == json.loads(json.dumps(log.meta))
    for name in schema.STREAM_NAMES:
        pd.testing.assert_frame_equal(log[name], back[name], check_exact=True)


def test_a_stream_file_holding_another_table_is_named_and_a_missing_one_is_listed(tmp_path):
    # a copied gps.parquet in imu's place failed deep in preprocessing as
    # "KeyError: 'Field "gyr_x_radps" does not exist in schema'"; a deleted one passed in silence
    import shutil

    write_flightlog(_random_log(np.random.default_rng(2)), tmp_path)
    assert "missing_streams" not in read_flightlog(tmp_path).meta
    (tmp_path / "rangefinder.parquet").unlink()
    back = read_flightlog(tmp_path)
    assert back.meta["missing_streams"] == ["rangefinder"] and len(back["rangefinder"]) == 0
    shutil.copy(tmp_path / "gps.parquet", tmp_path / "imu.parquet")
    with pytest.raises(ValueError, match=r"imu\.parquet: not the imu stream \(it holds the 'gps' table\)$"):
        read_flightlog(tmp_path)
    assert len(read_flightlog(tmp_path, streams=["mode"])["mode"]) == 3


def test_parquet_metadata_has_units_frames_and_schema_version(tmp_path):
    log = _random_log(np.random.default_rng(1))
    write_flightlog(log, tmp_path)
    md = read_table_meta(tmp_path / "imu.parquet")
    assert md["schema_version"] == schema.SCHEMA_VERSION
    assert md["columns"]["acc_z_mps2"] == {"unit": "m/s^2", "frame": "FRD"}
    f = pq.read_schema(tmp_path / "imu.parquet").field("gyr_x_radps")
    assert f.metadata[b"unit"] == b"rad/s" and f.metadata[b"frame"] == b"FRD"
    assert pq.ParquetFile(tmp_path / "imu.parquet").metadata.row_group(0).column(0).compression == "ZSTD"


def test_registry_errors_name_the_file(tmp_path):
    with pytest.raises(IngestError, match="no such file"):
        read_log(tmp_path / "missing.bin")
    empty = tmp_path / "empty.bin"
    empty.write_bytes(b"")
    with pytest.raises(IngestError, match=r"empty\.bin: empty file"):
        detect(empty)
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"this is not a flight log\n" * 10)
    with pytest.raises(IngestError, match=r"junk\.bin: unrecognised log format"):
        read_log(junk)
    # a pipeline output given as a log: named as such, not "no column map matches this parquet header"
    from pipeline.io.parquet import write_table

    out = tmp_path / "state.parquet"
    write_table(schema.empty("state"), out, schema.columns("state"), name="state")
    with pytest.raises(IngestError, match=r"state\.parquet: a uavpipe 'state' table \(a pipeline output\), not a flight log"):
        read_log(out)
    # a file cut inside a format's fixed header is said to be cut, not of an unknown format
    from pipeline.io.rosbag import ROS1_MAGIC
    from pipeline.io.ulog import MAGIC as ULOG_MAGIC

    for name, head, fmt in (("cut.bag", ROS1_MAGIC[:10], "rosbag1"), ("cut.ulg", ULOG_MAGIC[:5], "ulog")):
        (tmp_path / name).write_bytes(head)
        with pytest.raises(IngestError, match=rf"{name}: truncated: its {len(head)} byte\(s\) are the start of a "
                                              rf"{fmt} file's {len(ROS1_MAGIC if fmt == 'rosbag1' else ULOG_MAGIC)}-byte"):
            read_log(tmp_path / name)
    # a device reads as nothing: said as such, not "unrecognised log format (file starting )"
    with pytest.raises(IngestError, match=r"/dev/null: not a regular file"):
        detect("/dev/null")


def test_flight_id_alphabet():
    assert flight_id_for("/x/2014-10-18 20-04-24.bin") == "2014-10-18-20-04-24"
    assert flight_id_for("a_b.c.tlog") == "a-b-c"


def test_metadata_with_nan_or_infinity_is_strict_json_with_nulls(tmp_path):
    from pipeline.io.parquet import write_json, write_table

    df = pd.DataFrame({"maneuver": ["M1", "M2"], "rmse": [1.0, 2.0]})
    extra = {"score": {"converged_s": float("nan"), "ratio": np.float64("inf"), "ok": 1.5},
             "series": np.array([1.0, np.nan]), "nested": [float("-inf"), 2]}
    write_table(df, tmp_path / "t.parquet", name="seed000_classification_gmr_rmse", extra=extra)
    raw = pq.read_schema(tmp_path / "t.parquet").metadata[b"uavpipe"].decode()
    # strict JSON: no bare NaN/Infinity tokens, which pyarrow, browsers and jq refuse
    meta = json.loads(raw, parse_constant=lambda c: pytest.fail(f"non-JSON token {c}"))
    assert meta["score"] == {"converged_s": None, "ratio": None, "ok": 1.5}
    assert meta["series"] == [1.0, None] and meta["nested"] == [None, 2]
    write_json(extra, tmp_path / "e.json")
    again = json.loads((tmp_path / "e.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    assert again["score"]["converged_s"] is None
