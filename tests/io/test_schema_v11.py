"""Schema 1.1: the new canonical streams and GPS quality columns are declared once, in
``schema.py``, with a minor version bump and every 1.0 column kept."""

from __future__ import annotations

import numpy as np

from pipeline.io import schema
from pipeline.io.base import FlightLog


def test_schema_version_is_a_minor_bump_of_1_0():
    major, minor, _ = (int(x) for x in schema.SCHEMA_VERSION.split("."))
    # 1.1: these streams; 1.2.0: bearing (issue 16); 1.3.0: estimator_status; 1.4.0: study tables;
    # 1.5.0: seed000_ekf study columns renamed with their unit; 1.6.0: local_position reset_count;
    # 1.7.0: pf_geo_summary observer-distance shares
    assert (major, minor) == (1, 7)


def test_new_streams_are_canonical_streams_with_common_columns_first():
    for name in schema.STREAMS_1_1:
        assert name in schema.STREAM_NAMES and name in schema.TABLES
        assert schema.column_names(name)[:4] == ["t_ns", "instance", "src", "t_boot_ns"]
    assert set(schema.EVENT_STREAMS) <= set(schema.STREAMS_1_1)
    assert schema.column_names("battery")[4:] == ["voltage_V", "current_A", "consumed_Ah", "remaining_frac",
                                                  "temp_degC"]
    assert {"roll_rad", "p_radps", "vel_d_mps"} <= set(schema.column_names("setpoint"))
    assert {"text", "severity"} <= set(schema.column_names("messages"))
    assert {"name", "value"} <= set(schema.column_names("params"))
    assert {"vibe_x_mps2", "acc_vibration_mps2", "clip_0"} <= set(schema.column_names("vibration"))


def test_gps_keeps_its_1_0_columns_and_adds_dilutions_at_the_end():
    cols = schema.column_names("gps")
    assert cols[-6:] == ["fix_type", "n_sats", "hacc_m", "vacc_m", "hdop", "vdop"]


def test_every_new_float_column_names_its_unit():
    suffixes = ("_V", "_A", "_Ah", "_frac", "_degC", "_rad", "_radps", "_mps", "_mps2")
    for name in schema.STREAMS_1_1:
        for c in schema.STREAMS[name]:
            if c.dtype == "float64" and c.unit not in ("1", ""):
                assert c.name.endswith(suffixes), c.name


def test_event_streams_may_share_a_stamp_without_an_anomaly():
    t = np.zeros(3, np.int64)
    log = FlightLog.from_streams({}, {
        "params": {"t_ns": t, "src": "PARM", "name": np.array(["A", "B", "C"], dtype=object),
                   "value": np.ones(3)},
        "battery": {"t_ns": t, "src": "BAT", "voltage_V": np.ones(3)}})
    assert log.meta["diagnostics"]["timestamp_anomalies"] == {"battery": {"backwards": 0, "duplicate": 2}}
    assert log["params"]["name"].tolist() == ["A", "B", "C"] and str(log["params"]["name"].dtype) == "string"
