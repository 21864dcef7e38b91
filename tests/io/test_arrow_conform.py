"""The Arrow-native conform (``schema.conform_arrow``) against the pandas one it replaces on the
ingest path: same tables, same ``pandas`` metadata, same anomaly counts, same frames back."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest
from hypothesis import given, settings, strategies as st

from pipeline.io import schema
from pipeline.io.base import FlightLog
from pipeline.io.dataflash import decode
from pipeline.io.dataflash.streams import stream_parts
from pipeline.simulate.demo import write_demo_flight


def pandas_oracle(stream: str, parts: list[dict]) -> pa.Table:
    """What ingest wrote before: pandas frames per part, concatenated, conformed, from_pandas."""
    frames = []
    for p in parts:
        n = next(len(v) for v in p.values() if not np.isscalar(v))
        d = {}
        for k, v in p.items():
            if isinstance(v, np.ma.MaskedArray):
                v = pd.array(np.ma.getdata(v), dtype="Int64").copy()
                v[np.ma.getmaskarray(p[k])] = pd.NA
            elif k == "src" and isinstance(v, str):
                v = pd.Categorical([v] * n)
            d[k] = v
        frames.append(pd.DataFrame(d, index=range(n)))
    df = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]
    return pa.Table.from_pandas(schema.conform(stream, df)[schema.column_names(stream)],
                                schema=schema.arrow_schema(stream), preserve_index=False)


def _parts(rng: np.random.Generator) -> dict[str, list[dict]]:
    def t(n):
        return rng.integers(0, 10**9, n)

    imu = []
    for name, inst in (("IMU", 0), ("IMU2", 1), ("IMU", 0)):
        n = int(rng.integers(1, 30))
        boot = rng.integers(0, 10**12, n)
        imu.append({"t_ns": t(n), "instance": np.full(n, inst, np.uint8), "src": name,
                    "t_boot_ns": np.ma.masked_array(boot, mask=rng.random(n) < 0.3),
                    "gyr_x_radps": np.where(rng.random(n) < 0.2, np.nan, rng.normal(size=n)),
                    **({"temp_degC": rng.normal(size=n).astype(np.float32)} if name == "IMU2" else {})})
    rf = [{"t_ns": t(4), "src": "RFND", "dist_m": np.array([0.5, np.nan, 2.0, 3.0]),
           "valid": np.array([True, False, True, True])},
          {"t_ns": t(3), "src": "CTUN", "dist_m": np.array([1.0, 2.0, 3.0]), "orientation": 25.0}]
    mode = [{"t_ns": np.sort(t(4)), "src": np.array(["MODE", "EV", "EV", "MODE"], dtype=object),
             "mode": np.array([None, "STABILIZE", "STABILIZE", "LOITER"], dtype=object),
             "armed": np.array([None, True, False, False], dtype=object)}]
    labels = [{"t_start_ns": np.array([5, 1, 3]), "t_end_ns": np.array([9, 4, 4]),
               "label": np.array(["M2", "M1", "M1"], dtype=object), "source": "sim"}]
    return {"imu": imu, "rangefinder": rf, "mode": mode, "labels": labels}


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_conform_arrow_equals_the_pandas_conform(seed):
    for stream, parts in _parts(np.random.default_rng(seed)).items():
        ours, anomalies = schema.conform_arrow_counted(stream, parts)
        expect = pandas_oracle(stream, parts)
        assert ours.schema.equals(expect.schema.remove_metadata(), check_metadata=True), stream
        assert ours.equals(expect.replace_schema_metadata(None)), stream
        if stream != "labels":
            raw = pd.concat([pd.DataFrame({k: v for k, v in p.items() if k in ("t_ns", "instance", "src")},
                                          index=range(len(p["t_ns"]))) for p in parts], ignore_index=True)
            if "instance" not in raw:
                raw["instance"] = 0
            assert anomalies == schema.timestamp_anomalies(raw.fillna({"instance": 0})), stream


def test_pandas_metadata_is_what_from_pandas_writes():
    for stream, parts in _parts(np.random.default_rng(7)).items():
        expect = pandas_oracle(stream, parts).schema.metadata[b"pandas"]
        ours = schema.pandas_metadata(schema.columns(stream), schema.conform_arrow(stream, parts))
        assert ours == expect, stream
    empty = pa.Table.from_pandas(schema.empty("rangefinder"), schema=schema.arrow_schema("rangefinder"),
                                 preserve_index=False)
    assert schema.pandas_metadata(schema.columns("rangefinder"), schema.empty_arrow("rangefinder")) == \
        empty.schema.metadata[b"pandas"]


def test_conform_arrow_rejects_what_conform_rejects():
    with pytest.raises(schema.SchemaError, match="unknown column"):
        schema.conform_arrow("imu", {"t_ns": np.arange(3), "gyro_x": np.zeros(3)})
    with pytest.raises(schema.SchemaError, match="t_ns"):
        schema.conform_arrow("imu", {"gyr_x_radps": np.zeros(3)})
    with pytest.raises(schema.SchemaError, match="missing values"):
        schema.conform_arrow("imu", {"t_ns": np.array([1.0, np.nan])})


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    p = tmp_path_factory.mktemp("demo") / "demo.bin"
    write_demo_flight(p, seed=5)
    return p


def test_dataflash_streams_equal_the_pandas_path(demo):
    parts = stream_parts(decode(demo))
    log = FlightLog.from_streams({}, parts)
    for stream, p in parts.items():
        if not p:
            continue
        expect = pandas_oracle(stream, p)
        assert log.table(stream).equals(expect.replace_schema_metadata(None)), stream
        # the lazily converted frame is what schema.conform gave
        pd.testing.assert_frame_equal(log[stream], schema.conform(stream, expect.to_pandas()), check_exact=True)


def test_flightlog_frames_are_converted_once_and_assignable():
    log = FlightLog.from_streams({}, {"baro": {"t_ns": np.array([2, 1]), "alt_rel_m": np.array([1.0, 2.0]),
                                               "src": "BARO"}})
    assert log["baro"] is log["baro"]  # cached
    assert log["baro"]["t_ns"].tolist() == [1, 2]
    assert log.meta["diagnostics"]["timestamp_anomalies"]["baro"] == {"backwards": 1, "duplicate": 0}
    df = log["baro"].assign(alt_rel_m=[5.0, 6.0])
    log.streams["baro"] = df
    assert log.table("baro").column("alt_rel_m").to_pylist() == [5.0, 6.0]
    assert set(log.streams) == set(schema.STREAM_NAMES)
    assert log.duration_s == pytest.approx(1e-9)
    assert log.summary()["baro"]["rows"] == 2
