"""A corrupt time base in preprocessing: a grid spanning days is one clear error, and the stage
turns any failure of one flight into that flight's placeholder outputs with a one-line reason."""

from __future__ import annotations

import json
import random

import numpy as np
import pandas as pd
import pytest

from pipeline.io import registry, schema
from pipeline.io.base import FlightLog
from pipeline.io.parquet import read_table, read_table_meta, write_flightlog
from pipeline.preprocess import run as prun
from pipeline.preprocess.resample import MAX_GRID_SAMPLES, TimeBaseError, make_grid
from pipeline.simulate.demo import write_demo_flight


def _outputs(root):
    return {"state": root / "state.parquet", "segments": root / "segments.parquet",
            "calibration": root / "calibration.parquet", "info": root / "info.json"}


def _flight(rng, *, absurd_ns=None, gps_at_ns=0):
    """20 s of attitude (20 Hz) and GPS (5 Hz); one attitude sample at ``absurd_ns`` if given;
    the whole GPS stream shifted by ``gps_at_ns``."""
    ta = np.arange(0, 20, 0.05)
    t_ns = np.round(ta * 1e9).astype(np.int64)
    if absurd_ns is not None:
        t_ns[len(t_ns) // 2] = absurd_ns
    att = pd.DataFrame({"t_ns": t_ns, "q_w": 1.0, "q_x": 0.0, "q_y": 0.0, "q_z": 0.0})
    tg = np.arange(0, 20, 0.2)
    gps = pd.DataFrame({"t_ns": np.round(tg * 1e9).astype(np.int64) + gps_at_ns, "lat_deg": 46.5 + 1e-6 * tg,
                        "lon_deg": 6.6 + rng.normal(0, 1e-7, len(tg)), "alt_wgs84_m": 500.0, "fix_type": 3.0})
    return FlightLog.from_streams({"flight_id": "f1"}, {"attitude": att, "gps": gps})


def test_a_grid_spanning_centuries_is_a_time_base_error_naming_span_and_rate():
    with pytest.raises(TimeBaseError, match=r"time span 9\.22337e\+09 s .* at 25 Hz .* grid samples") as err:
        make_grid(-(1 << 63), 0, 25.0)  # would be 1.7 TiB of int64, failed as a MemoryError
    assert "\n" not in str(err.value) and isinstance(err.value, ValueError)
    assert MAX_GRID_SAMPLES >= 9 * 86400 * 25  # 9 days at 25 Hz still fit
    assert len(make_grid(0, 3_960_000_000, 25.0, max_samples=100)) == 100  # the limit itself is allowed
    with pytest.raises(TimeBaseError, match=r"time span 4 s .* 101 grid samples \(limit 100\)"):
        make_grid(0, 4_000_000_000, 25.0, max_samples=100)


def test_a_lone_absurd_stamp_is_dropped_as_stray_and_counted(tmp_path, rng):
    # one attitude record 146 years early: damaged, not the flight's time base
    write_flightlog(_flight(rng, absurd_ns=-(1 << 62)), tmp_path / "in")
    out = _outputs(tmp_path / "out")
    res = prun.run_preprocess({"meta": tmp_path / "in" / "meta.json"}, out, {})
    assert res.status == "ok"
    st = read_table(out["state"], schema.STATE)
    assert len(st) == 499 and st["t_ns"].iloc[-1] < 20e9        # the 20 s of the flight at 25 Hz
    assert st["gap"].mean() < 0.01
    assert res.diagnostics["timestamp_repairs"]["attitude"]["stray"] == 1


def test_a_flight_with_an_absurd_time_base_gets_a_placeholder_with_a_one_line_reason(tmp_path, rng, capsys):
    # written straight to the store, as a reader without ingest's guard would have: a whole
    # stream 146 years away from the others (not a stray record: its own clock)
    write_flightlog(_flight(rng, gps_at_ns=-(1 << 62)), tmp_path / "in")
    out = _outputs(tmp_path / "out")
    res = prun.run_preprocess({"meta": tmp_path / "in" / "meta.json"}, out, {})
    assert res.status == "failed"
    reason = res.diagnostics["error"]
    assert reason.startswith("preprocessing failed: time span") and "Hz" in reason and "\n" not in reason
    assert json.loads(out["info"].read_text()) == {"flight_id": "f1", "status": "failed", "error": reason}
    assert len(read_table(out["state"], schema.STATE)) == 0
    assert read_table_meta(out["state"])["error"] == reason
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "placeholder outputs" in err and "Traceback" not in err


def test_an_unexpected_error_in_one_flight_becomes_its_placeholder(tmp_path, rng, monkeypatch):
    write_flightlog(_flight(rng), tmp_path / "in")

    def boom(*a, **k):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(prun, "preprocess_log", boom)
    out = _outputs(tmp_path / "out")
    res = prun.run_preprocess({"meta": tmp_path / "in" / "meta.json"}, out, {})
    assert res.status == "failed"
    assert res.diagnostics["error"].startswith(
        "preprocessing failed: ZeroDivisionError: float division by zero (at test_bad_time_base.py:")
    assert all(p.exists() for p in out.values())


def test_a_bit_flipped_dataflash_log_preprocesses_to_a_grid_as_long_as_the_flight(tmp_path):
    p = tmp_path / "flipped.bin"
    write_demo_flight(p, seed=0, duration_s=60.0)
    data = bytearray(p.read_bytes())
    r = random.Random(1)
    for i in range(20_000, len(data), 997):
        data[i] ^= 1 << r.randrange(8)
    p.write_bytes(bytes(data))
    registry_log = registry.read_log(p, flight_id="flipped")
    write_flightlog(registry_log, tmp_path / "in")
    out = _outputs(tmp_path / "out")
    res = prun.run_preprocess({"meta": tmp_path / "in" / "meta.json"}, out, {"rate_hz": 25.0})
    assert res.status == "ok"
    assert 60 * 25 <= res.diagnostics["n_samples"] <= 120 * 25  # was 2.3e11 samples: MemoryError
