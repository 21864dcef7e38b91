"""Corruption suite for the ULog, FlightCoach JSON and CSV/Parquet readers.

Every damaged input must end in either an :class:`IngestError` whose one-line message names the
file and a reason, or a FlightLog whose losses are counted in ``meta['diagnostics']`` — never a
library traceback — and each case must finish within 10 s.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import realdata_file
from helpers_ulog import ULogWriter
from pipeline.io import registry
from pipeline.io.base import FlightLog, IngestError

LIMIT_S = 10.0
HYP = settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _ingest(path: Path, **kw) -> FlightLog | IngestError:
    """read_log; returns the log or the IngestError. Any other exception fails the test."""
    t = time.monotonic()
    try:
        out = registry.read_log(path, **kw)
    except IngestError as exc:
        out = exc
        assert str(path) in str(exc) and exc.reason.strip(), str(exc)
        assert "\n" not in str(exc)
    assert time.monotonic() - t <= LIMIT_S
    return out


def _losses(log: FlightLog) -> int:
    d = log.meta["diagnostics"]
    return d["bytes_skipped"] + sum(d["records_dropped"].values())


# --- ULog ---------------------------------------------------------------------------------------

def _small_ulog() -> bytes:
    w = ULogWriter(start_us=2_000_000)
    w.add_param("SYS_AUTOSTART", 4001)
    n = 30
    ts = 2_000_000 + np.arange(n, dtype=np.uint64) * 4_000
    w.topic("sensor_combined", [("uint64_t", "timestamp"), ("float[3]", "gyro_rad"),
                                ("int32_t", "accelerometer_timestamp_relative"), ("float[3]", "accelerometer_m_s2")],
            {"timestamp": ts, "gyro_rad": np.zeros((n, 3), np.float32),
             "accelerometer_timestamp_relative": np.zeros(n, np.int32),
             "accelerometer_m_s2": np.tile(np.float32([0, 0, -9.81]), (n, 1))})
    w.topic("vehicle_attitude", [("uint64_t", "timestamp"), ("float[4]", "q")],
            {"timestamp": ts, "q": np.tile(np.float32([1, 0, 0, 0]), (n, 1))})
    w.log("INFO", 2_000_500, "[logger] started")
    return w.to_bytes()


ULOG = _small_ulog()


@HYP
@given(cut=st.integers(min_value=0, max_value=len(ULOG) - 1))
def test_truncated_ulog(cut):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "cut.ulg"
        p.write_bytes(ULOG[:cut])
        out = _ingest(p)
        if isinstance(out, IngestError):
            assert any(s in out.reason for s in ("empty file", "not a readable ULog", "no data messages",
                                                 "unrecognised log format", "start of a ulog file's"))
        else:
            # a cut inside a message is counted; a cut on a boundary just ends the log early
            # every sensor_combined / vehicle_attitude DATA message wholly before the cut is kept
            assert len(out["imu"]) == _complete_data_before(cut, "sensor_combined")
            assert len(out["attitude"]) == _complete_data_before(cut, "vehicle_attitude")
            full = registry.read_log(_write(Path(d) / "full.ulg", ULOG))
            lost = len(full["imu"]) + len(full["attitude"]) - len(out["imu"]) - len(out["attitude"])
            if lost and _boundary(cut) is False:
                assert out.meta["diagnostics"]["bytes_skipped"] > 0
                assert out.meta["status"] == "partial"


def _write(p: Path, b: bytes) -> Path:
    p.write_bytes(b)
    return p


def _boundary(cut: int) -> bool:
    """True if ``cut`` falls on a message boundary of ULOG."""
    pos = 16
    while pos < len(ULOG):
        if pos == cut:
            return True
        pos += 3 + (ULOG[pos] | ULOG[pos + 1] << 8)
    return cut == pos


def _messages(buf: bytes) -> list[tuple[int, int, str]]:
    """(offset, payload size, type) of each message after the 16-byte ULog header."""
    pos, out = 16, []
    while pos + 3 <= len(buf):
        size = buf[pos] | buf[pos + 1] << 8
        out.append((pos, size, chr(buf[pos + 2])))
        pos += 3 + size
    return out


#: msg_id of each subscription ('A': size, type, multi_id u8, msg_id u16, name)
MSG_IDS = {ULOG[p + 6:p + 3 + n].decode(): ULOG[p + 4] | ULOG[p + 5] << 8
           for p, n, typ in _messages(ULOG) if typ == "A"}


def _complete_data_before(cut: int, name: str) -> int:
    """DATA messages ('D': size, type, msg_id u16, ...) of topic ``name`` ending at or before ``cut``."""
    return sum(1 for p, n, typ in _messages(ULOG)
               if typ == "D" and (ULOG[p + 3] | ULOG[p + 4] << 8) == MSG_IDS[name] and p + 3 + n <= cut)


def test_the_small_ulog_has_30_data_messages_per_topic_and_reads_whole():
    assert _complete_data_before(len(ULOG), "sensor_combined") == 30
    assert _complete_data_before(len(ULOG), "vehicle_attitude") == 30
    with tempfile.TemporaryDirectory() as d:
        log = _ingest(_write(Path(d) / "full.ulg", ULOG))
    assert (len(log["imu"]), len(log["attitude"]), log.meta["status"]) == (30, 30, "ok")


@HYP
@given(start=st.integers(min_value=0, max_value=len(ULOG) - 1), junk=st.binary(min_size=1, max_size=64))
def test_garbled_ulog(start, junk):
    raw = bytearray(ULOG)
    raw[start:start + len(junk)] = junk
    with tempfile.TemporaryDirectory() as d:
        out = _ingest(_write(Path(d) / "garbled.ulg", bytes(raw)))
        if isinstance(out, FlightLog):
            assert out.meta["reader"] == "ulog"
            # garbling never invents rows, and "ok" means nothing was lost; the converse does not
            # hold (junk in a payload rewrites values, which no ULog checksum catches), and the
            # rows lost need not be counted per message (a skipped span is counted in bytes)
            assert len(out["imu"]) <= 30 and len(out["attitude"]) <= 30
            if out.meta["status"] == "ok":
                assert (len(out["imu"]), len(out["attitude"])) == (30, 30)
                assert _losses(out) == 0
            else:
                assert out.meta["status"] == "partial" and _losses(out) > 0


@pytest.mark.parametrize("frac", [0.0001, 0.37, 0.999])
def test_truncated_real_ulog(tmp_path, frac):
    raw = realdata_file("ulg_px4_flight_review_fixtures/ekf_failure.ulg").read_bytes()
    p = _write(tmp_path / "ekf_cut.ulg", raw[: int(len(raw) * frac)])
    out = _ingest(p)
    if frac < 0.01:
        assert isinstance(out, IngestError) and "no data messages" in out.reason
    else:
        assert isinstance(out, FlightLog) and len(out["imu"]) > 0
        assert out.meta["diagnostics"]["bytes_skipped"] > 0  # these cuts fall mid-message
        assert out.meta["status"] == "partial"


# --- FlightCoach JSON ---------------------------------------------------------------------------

def _fc_doc(n=40) -> bytes:
    data = [{"time": 1_000_000 + 40_000 * i, "N": 1.0 * i, "E": 0.5 * i, "D": -10.0, "VN": 1.0, "VE": 0.5,
             "VD": 0.0, "roll": 0.1, "pitch": 0.2, "yaw": 0.3, "r": 5.73, "p": 11.46, "yw": 17.19}
            for i in range(n)]
    return json.dumps({"version": "1.2", "parameters": {"rotation": 0.1, "originLat": 51.0, "originLng": -2.0,
                                                        "originAlt": 3.0},
                       "mans": [{"name": "tkoff", "start": 0, "stop": 20}, {"name": "loop", "start": 20, "stop": 39}],
                       "data": data}).encode()


FC = _fc_doc()


@HYP
@given(cut=st.integers(min_value=1, max_value=len(FC) - 1))
def test_truncated_flightcoach_json(cut):
    with tempfile.TemporaryDirectory() as d:
        out = _ingest(_write(Path(d) / "fc.json", FC[:cut]), fmt="flightcoach")
        assert isinstance(out, IngestError)
        assert "invalid JSON" in out.reason


@HYP
@given(pos=st.integers(min_value=0, max_value=len(FC) - 1), junk=st.binary(min_size=1, max_size=8))
def test_garbled_flightcoach_json(pos, junk):
    raw = FC[:pos] + junk + FC[pos + len(junk):]
    with tempfile.TemporaryDirectory() as d:
        out = _ingest(_write(Path(d) / "fc.json", raw), fmt="flightcoach")
        if isinstance(out, FlightLog):  # the junk landed somewhere harmless, e.g. inside a string
            assert len(out["local_position"]) + out.meta["diagnostics"]["records_dropped"].get("bad_sample", 0) == 40


def test_truncated_real_flightcoach(tmp_path):
    raw = realdata_file("flightcoach_f3a_json/manual_F3A_P23_22_02_18_00000036.json").read_bytes()
    out = _ingest(_write(tmp_path / "p23_cut.json", raw[: len(raw) // 2]))
    assert isinstance(out, IngestError) and "invalid JSON" in out.reason and "truncated" in out.reason


# --- CSV / Parquet ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def kd0aij_head() -> pd.DataFrame:
    return pd.read_csv(realdata_file("kd0aij_f3a_csv/141.csv"), nrows=200)


def test_empty_csv(tmp_path):
    out = _ingest(_write(tmp_path / "empty.csv", b""))
    assert isinstance(out, IngestError) and "empty file" in out.reason
    out = _ingest(_write(tmp_path / "empty2.csv", b""), fmt="tabular")
    assert isinstance(out, IngestError) and "empty CSV" in out.reason
    out = _ingest(_write(tmp_path / "blank.csv", b"\n\n"), fmt="tabular")
    assert isinstance(out, IngestError) and "empty CSV" in out.reason


def test_header_only_csv(tmp_path, kd0aij_head):
    p = tmp_path / "header_only.csv"
    kd0aij_head.iloc[:0].to_csv(p, index=False)
    out = _ingest(p)
    assert isinstance(out, IngestError) and "no data rows" in out.reason


@pytest.mark.parametrize("col", ["time_actual", "attitude_yaw", "servos_3"])
def test_csv_missing_column(tmp_path, kd0aij_head, col):
    p = tmp_path / "missing.csv"
    kd0aij_head.drop(columns=[col]).to_csv(p, index=False)
    out = _ingest(p)
    assert isinstance(out, IngestError)
    assert col in out.reason


def test_csv_missing_unit_in_map(tmp_path, kd0aij_head):
    import yaml

    from pipeline.io.tabular import shipped_columnmaps

    raw = yaml.safe_load((Path(__file__).resolve().parents[2] / "pipeline/io/columnmaps/kd0aij_flightdata.yaml")
                         .read_text())
    assert set(raw["columns"]) == set(shipped_columnmaps()["kd0aij_flightdata"].columns)
    del raw["columns"]["position_x"]["unit"]
    raw["name"] = "kd0aij_nounit"
    p = tmp_path / "flight.csv"
    kd0aij_head.to_csv(p, index=False)
    out = _ingest(p, config={"columnmaps": {"x": raw}, "tabular": {"columnmap": "kd0aij_nounit"}})
    assert isinstance(out, IngestError) and "'position_x'" in out.reason and "no unit given" in out.reason


@HYP
@given(cut_frac=st.floats(min_value=0.0, max_value=1.0))
def test_truncated_csv(cut_frac):
    raw = Path(realdata_file("kd0aij_f3a_csv/141.csv")).read_bytes()[:20_000]
    cut = int(len(raw) * cut_frac)
    with tempfile.TemporaryDirectory() as d:
        out = _ingest(_write(Path(d) / "cut.csv", raw[:cut]))
        if isinstance(out, FlightLog):
            # a short prefix can leave e.g. the parked plane's GPS constant (-> absent), but
            # some stream carries the rows that were read
            assert out.meta["reader"] == "tabular"
            n_rows = out.meta["diagnostics"]["record_counts"]["rows"]
            assert 1 <= n_rows <= raw[:cut].count(b"\n")
            assert max(len(df) for df in out.streams.values()) >= 1


def test_csv_text_in_numeric_column_is_counted(tmp_path, kd0aij_head):
    df = kd0aij_head.copy()
    df["attitude_roll"] = df["attitude_roll"].astype(object)
    df.loc[[5, 6, 7], "attitude_roll"] = "ERR"
    p = tmp_path / "text.csv"
    df.to_csv(p, index=False)
    out = _ingest(p)
    assert isinstance(out, FlightLog)
    assert out.meta["diagnostics"]["records_dropped"] == {"bad_value:attitude_roll": 3}
    assert out.meta["status"] == "partial" and _losses(out) == 3
    assert len(out["attitude"]) == 197  # rows left without any attitude value carry no sample


def test_corrupt_parquet(tmp_path, kd0aij_head):
    p = tmp_path / "flight.parquet"
    kd0aij_head.to_parquet(p)
    raw = p.read_bytes()
    bad = _write(tmp_path / "broken.parquet", raw[: len(raw) // 2])
    out = _ingest(bad)
    assert isinstance(out, IngestError) and "unreadable Parquet" in out.reason
    ok = _ingest(p)  # the shipped map matches the Parquet copy's columns too
    assert isinstance(ok, FlightLog) and len(ok["gps"]) == 200
