"""``uavpipe info``: the sensor span beside the log span when a non-sensor record starts
earlier (issue 13, defect 13); the topic -> stream map with inferred custom-type mappings
(defect 9); the reason of a null NED origin (defect 11)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np

from pipeline.cli import main
from pipeline.io.dataflash.writer import DataFlashWriter
from pipeline.io.parquet import read_flightlog


def _early_rc_log(path: Path) -> Path:
    """RC input from boot + 1 s, GPS/IMU/ATT from + 3 s to + 13 s (GPS without a fix)."""
    with DataFlashWriter(path) as w:
        w.define_layout("ardupilot4")
        w.write_many("RCIN", {"TimeUS": 1_000_000 + np.arange(12) * 1_000_000, "C1": 1500})
        t = 3_000_000 + np.arange(101, dtype=np.int64) * 100_000
        w.write_merged({"IMU": {"TimeUS": t, "I": 0, "AccZ": -9.8},
                        "ATT": {"TimeUS": t, "Roll": 0.0, "Pitch": 0.0, "Yaw": 10.0},
                        "GPS": {"TimeUS": t[::2], "I": 0, "Status": 1, "Lat": 0.0, "Lng": 0.0}})
    return path


def test_info_shows_the_sensor_span_beside_the_log_span(tmp_path, capsys):
    p = _early_rc_log(tmp_path / "early.bin")
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    assert "duration 12.0 s (sensors 10.0 s, t = 2.0..12.0 s)" in out
    assert "NED origin  none: GPS never got a fix" in out
    assert main(["info", "--json", str(p)]) == 0
    d = json.loads(capsys.readouterr().out)[0]
    assert d["duration_s"] == 12.0 and d["sensor_span"] == {"start_s": 2.0, "end_s": 12.0, "duration_s": 10.0}
    assert d["ned_origin"] is None and d["ned_origin_reason"].startswith("GPS never got a fix")


def test_info_prints_and_ingest_records_an_inferred_ros_mapping(tmp_path, capsys, rng):
    spec = importlib.util.spec_from_file_location(
        "_ros_custom_fixtures", Path(__file__).parents[1] / "io" / "test_ros_custom_types.py")
    cx = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cx)
    bag = cx._write("ros1bag", tmp_path, cx._messages(rng))
    assert main(["info", str(bag)]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.strip().startswith("/pack.imu "))
    assert "-> imu[0]  sensor_msgs/msg/Imu  (inferred: embedded field 'imu'" in line
    assert f"inferred    /pack ({cx.PACK_TYPE}): embeds imu: sensor_msgs/msg/Imu -> imu" in out
    assert "/geo" in out and "NavSatFix field names -> gps" in out
    assert main(["ingest", str(bag), "-o", str(tmp_path / "out")]) == 0
    meta = json.loads((tmp_path / "out" / "custom" / "meta.json").read_text())
    inf = meta["diagnostics"]["inferred_mappings"]
    assert inf["/pack"]["streams"]["/pack.fix"] == {"type": "sensor_msgs/msg/NavSatFix", "stream": "gps",
                                                    "instance": 1}
    assert inf["/geo"]["streams"] == {"/geo": {"stream": "gps", "instance": 0}}
    assert len(read_flightlog(tmp_path / "out" / "custom")["mag"]) == cx.N * 2
