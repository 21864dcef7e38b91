"""Truth/labels side-cars: naming, round trip, time-base shift, bad files."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.io import schema
from pipeline.io.base import FlightLog, IngestError
from pipeline.io.parquet import write_table
from pipeline.io.sidecar import attach_sidecar, find_sidecar, read_sidecar, sidecar_path, write_sidecar


def _truth(n=5):
    return pd.DataFrame({"t_ns": np.arange(n, dtype=np.int64) * 10_000_000, "src": "simulation",
                         "pos_n_m": np.arange(n, dtype=float), "label": pd.array(["M1"] * n, dtype="string")})


def _labels():
    return pd.DataFrame({"t_start_ns": np.array([0, 20_000_000], np.int64),
                         "t_end_ns": np.array([20_000_000, 40_000_000], np.int64),
                         "label": pd.array(["low", "M1"], dtype="string"),
                         "source": pd.array(["simulation_truth"] * 2, dtype="string")})


def test_names(tmp_path):
    log = tmp_path / "flight.bin"
    log.write_bytes(b"x")
    assert find_sidecar(log) is None
    alt = tmp_path / "flight.truth.parquet"
    write_sidecar(alt, _truth(), _labels())
    assert find_sidecar(log) == alt
    full = sidecar_path(log)
    assert full.name == "flight.bin.truth.parquet"
    write_sidecar(full, _truth(), _labels())
    assert find_sidecar(log) == full  # the full-name side-car wins
    bag = tmp_path / "flight-mcap"
    bag.mkdir()
    assert sidecar_path(bag).name == "flight-mcap.truth.parquet"


def test_round_trip_and_shift(tmp_path):
    p = write_sidecar(tmp_path / "a.truth.parquet", _truth(), _labels(), t0_utc_ns=1_000_000_000)
    truth, labels, meta = read_sidecar(p)
    assert list(truth.columns) == schema.column_names("truth")
    assert list(labels["label"]) == ["low", "M1"] and meta["t0_utc_ns"] == 1_000_000_000
    log = FlightLog.from_streams({"t0_utc_ns": 1_000_000_000}, {})
    attach_sidecar(log, p)
    assert log["truth"]["t_ns"].tolist() == _truth()["t_ns"].tolist()
    assert log.meta["labels_path"] == str(p) and not log.meta["diagnostics"]["warnings"]
    # a log that started 5 ms later: the truth moves back onto the log's t_ns base
    log2 = FlightLog.from_streams({"t0_utc_ns": 1_005_000_000}, {})
    attach_sidecar(log2, p)
    assert log2["truth"]["t_ns"].iloc[1] == 10_000_000 - 5_000_000
    assert log2["labels"]["t_start_ns"].iloc[1] == 20_000_000 - 5_000_000
    assert "shifted" in log2.meta["diagnostics"]["warnings"][0]


def test_bad_sidecars(tmp_path):
    with pytest.raises(IngestError, match="not found"):
        read_sidecar(tmp_path / "missing.truth.parquet")
    junk = tmp_path / "j.truth.parquet"
    junk.write_bytes(b"PAR1 nonsense")
    with pytest.raises(IngestError, match="j.truth.parquet"):
        read_sidecar(junk)
    other = tmp_path / "o.truth.parquet"
    write_table(schema.empty("imu"), other, schema.columns("imu"), name="imu")
    with pytest.raises(IngestError, match="not a truth side-car"):
        read_sidecar(other)


def test_a_hand_edited_side_car_loses_its_bad_label_rows_only_counted_and_named(tmp_path):
    rows = [{"t_start_ns": 0, "t_end_ns": 20_000_000, "label": "low", "source": "x"},
            {"t_start_ns": 20_000_000, "label": "M1"},                            # no end
            {"t_start_ns": None, "t_end_ns": 5, "label": "M2"},                   # a null time
            {"t_start_ns": "later", "t_end_ns": 5, "label": "M3"},                # not an integer
            {"t_start_ns": 40_000_000, "t_end_ns": 30_000_000, "label": "M4"},   # ends before it starts
            {"t_start_ns": 30_000_000, "t_end_ns": 40_000_000, "label": "M5"}]
    p = tmp_path / "h.truth.parquet"
    write_table(schema.conform("truth", _truth()), p, schema.columns("truth"), name="truth", extra={"labels": rows})
    _, labels, meta = read_sidecar(p)
    assert list(labels["label"]) == ["low", "M5"] and list(labels["source"].fillna("-")) == ["x", "-"]
    assert meta["labels_dropped"] == ["row 1: no t_end_ns", "row 2: no t_start_ns",
                                      "row 3: time not an integer ('later', 5)", "row 4: ends before it starts"]
    log = attach_sidecar(FlightLog.from_streams({}, {}), p)
    diag = log.meta["diagnostics"]
    assert diag["records_dropped"]["bad_label"] == 4 and len(log["labels"]) == 2
    assert diag["warnings"][-1].startswith("truth side-car h.truth.parquet: 4 label row(s) dropped (row 1: no t_end_ns;")


def test_a_side_car_failing_in_an_unforeseen_way_is_one_ingest_error_naming_the_log(tmp_path, monkeypatch):
    from pipeline.io import registry, sidecar
    from pipeline.simulate.demo import write_demo_flight

    log = tmp_path / "d.bin"
    write_demo_flight(log, seed=0, duration_s=5.0)
    p = write_sidecar(sidecar_path(log), _truth(), _labels())

    def broken(*a, **k):
        raise KeyError("t_end_ns")

    monkeypatch.setattr(sidecar, "attach_sidecar", broken)
    with pytest.raises(IngestError, match=rf"d\.bin: attaching the side-car {p.name} failed: KeyError: 't_end_ns'"):
        registry.read_log(log)


def test_a_side_car_that_shares_no_time_with_the_log_is_refused_naming_it(tmp_path):
    # a ULog given a simulated flight's truth was a 6.6-year flight with one warning
    p = write_sidecar(tmp_path / "a.truth.parquet", _truth(), _labels(), t0_utc_ns=1_000_000_000)
    imu = pd.DataFrame({"t_ns": np.arange(3, dtype=np.int64) * 10_000_000, "src": "IMU", "acc_x_mps2": 0.0})
    # the log starts 1 h later on the UTC clock: shifted, the 40 ms of truth end before it
    late = FlightLog.from_streams({"t0_utc_ns": 1_000_000_000 + 3600 * 10**9}, {"imu": imu})
    with pytest.raises(IngestError, match=r"a\.truth\.parquet: truth side-car spans -3600\.0 to -3600\.0 s on the log's "
                                          r"time base, the log 0\.0 to 0\.0 s: no overlap"):
        attach_sidecar(late, p)
    # the same log 5 ms later overlaps, and a log without sensor samples takes it as before
    ok = FlightLog.from_streams({"t0_utc_ns": 1_005_000_000}, {"imu": imu})
    assert len(attach_sidecar(ok, p)["truth"]) == 5
    assert len(attach_sidecar(FlightLog.from_streams({"t0_utc_ns": 5}, {}), p)["truth"]) == 5


def test_the_side_cars_origin_and_radar_put_a_first_fix_logs_state_in_the_truths_frame(tmp_path):
    # a ROS bag has no navigation origin: its reader takes the first fix, which put the
    # simulated M1 flight's state 440 m north and 354 m east of its truth
    frame = {"ned_origin": {"lat_deg": 32.5994, "lon_deg": -85.4897, "alt_wgs84_m": 200.0, "alt_msl_m": 229.0},
             "radar": {"site_ned_m": [1.0, 2.0, -3.0], "tau_rd_s": 0.0}}
    p = write_sidecar(tmp_path / "a.truth.parquet", _truth(), _labels(), t0_utc_ns=1_000_000_000, extra=frame)
    first_fix = {"lat_deg": 32.5954, "lon_deg": -85.4859, "alt_wgs84_m": 219.3}
    bag = attach_sidecar(FlightLog.from_streams({"t0_utc_ns": 1_000_000_000, "ned_origin": first_fix}, {}), p)
    assert bag.meta["ned_origin"] == {**frame["ned_origin"], "source": "truth side-car"}
    assert bag.meta["radar"] == frame["radar"]
    assert "the log's own, 569 m away, is not used" in bag.meta["diagnostics"]["warnings"][0]
    # a log without an origin takes it too
    none = attach_sidecar(FlightLog.from_streams({"t0_utc_ns": 1_000_000_000, "ned_origin": None}, {}), p)
    assert none.meta["ned_origin"]["source"] == "truth side-car"
    # a log whose own origin is the same place (DataFlash ORGN) keeps its own, and its radar
    orgn = {"lat_deg": 32.5994, "lon_deg": -85.4897000001, "alt_msl_m": 229.0, "alt_wgs84_m": None, "source": "ORGN"}
    own_radar = {"site_ned_m": [0.0, 0.0, 0.0], "tau_rd_s": 0.0}
    df = attach_sidecar(FlightLog.from_streams({"t0_utc_ns": 1_000_000_000, "ned_origin": dict(orgn),
                                                "radar": own_radar}, {}), p)
    assert df.meta["ned_origin"] == orgn and df.meta["radar"] == own_radar
    assert not df.meta["diagnostics"]["warnings"]
