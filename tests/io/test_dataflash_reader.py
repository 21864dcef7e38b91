"""DataFlash reader: raw tables and canonical streams against pymavlink's DFReader (the oracle).

For every real ``.bin`` log the oracle is ``mavutil.mavlink_connection(path)`` + a
``recv_msg()`` loop. We require the same record count for every message type, the same value
for every field of every record (exact: pymavlink's own scaling is reproduced), and canonical
GPS/IMU/attitude/baro/RC values equal to pymavlink's at the same samples after unit conversion.
Synthetic logs from ``pipeline.io.dataflash.writer`` cover the old TimeMS format, RADR and instances.
"""

from __future__ import annotations

import io
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from helpers import realdata_file
from helpers_time import gps_minus_utc
from pipeline.frames.rotations import quat_to_euler
from pipeline.io import dataflash as df
from pipeline.io import schema
from pipeline.io.base import IngestError
from pipeline.io.dataflash.writer import RADR, DataFlashWriter
from pipeline.io.registry import detect, read_log
from pipeline.simulate.demo import write_demo_flight

REAL_LOGS = {
    "ap_copter313_austin_4flights/2014-10-18_20-04-24.bin":
        {"imu", "gps", "baro", "attitude", "mode"},
    "ap_copter313_austin_4flights/2014-10-18_20-44-05.bin":
        {"imu", "gps", "baro", "attitude", "mode"},
    "ap_copter_forum_crash_pool/log_0036_mechanical_failure.bin":
        {"imu", "gps", "baro", "mag", "attitude", "local_position", "control", "mode"},
    "ap_plane_flightcoach_box/pilot_0004.BIN":
        {"gps", "mag", "attitude", "local_position", "mode"},
    "pymavlink_test_bin/test.BIN":
        {"imu", "gps", "baro", "mag", "attitude", "local_position", "control", "mode"},
}

_ORACLE: dict[str, dict] = {}


def oracle(path: Path) -> dict:
    """pymavlink's view of a log, cached per session: messages by type, params, mode trail."""
    key = str(path)
    if key not in _ORACLE:
        from pymavlink import mavutil

        m = mavutil.mavlink_connection(key)
        msgs = defaultdict(list)
        modes = []
        while True:
            x = m.recv_msg()
            if x is None:
                break
            t = x.get_type()
            msgs[t].append(x)
            if t == "MODE":
                modes.append(m.flightmode)
        _ORACLE[key] = {"msgs": dict(msgs), "params": dict(m.params), "modes": modes, "cols": {}}
        m.close()
    return _ORACLE[key]


def _values(msgs, col):
    """pymavlink's (scaled) values of field ``col``; cached, DFMessage.__getattr__ is slow."""
    cache = next(o["cols"] for o in _ORACLE.values() if any(v is msgs for v in o["msgs"].values()))
    key = (id(msgs), col)
    if key not in cache:
        cache[key] = [getattr(x, col) for x in msgs]
    return cache[key]


@pytest.fixture(scope="module", params=sorted(REAL_LOGS))
def real(request):
    path = realdata_file(request.param)
    return request.param, path, df.decode(path), oracle(path)


# --------------------------------------------------------------------------------------------
# raw tables == pymavlink
# --------------------------------------------------------------------------------------------

def test_record_count_per_type_equals_pymavlink(real):
    _, path, res, orc = real
    theirs = {k: len(v) for k, v in orc["msgs"].items()}
    assert res.diagnostics["record_counts"] == theirs
    assert sum(theirs.values()) > 1000


def test_every_field_of_every_record_equals_pymavlink(real):
    """All fields of all types; bulk types on an evenly spaced sample of <= 600 records (the
    stream tests below compare every IMU/GPS/ATT/BARO/RC record)."""
    _, path, res, orc = real
    checked = 0
    for name, msgs in orc["msgs"].items():
        fmt = res.formats[name]
        table = res.tables[name]
        k = np.unique(np.linspace(0, len(msgs) - 1, min(len(msgs), 600)).astype(int))
        sample = [msgs[i] for i in k]
        for col, key in zip(fmt.columns, fmt.dtype.names):
            ours = table[key][k]
            theirs = [getattr(x, col) for x in sample]
            if fmt.fmt[fmt.columns.index(col)] == "a":
                assert np.array_equal(ours, np.array([list(v) for v in theirs])), (name, col)
                continue
            if ours.dtype == object:
                assert ours.tolist() == theirs, (name, col)
            else:
                t = np.array(theirs)
                if ours.dtype.kind == "f":
                    assert np.array_equal(ours, t.astype(np.float64), equal_nan=True), (name, col)
                else:
                    assert ours.dtype.kind in "iu" and np.array_equal(ours, t), (name, col)
            checked += len(k)
    assert checked > 1000


def test_decode_from_bytes_equals_decode_from_path(real):
    _, path, res, _ = real
    tables, diag = df.decode_all(path.read_bytes())
    assert diag["record_counts"] == res.diagnostics["record_counts"]
    for name, cols in res.tables.items():
        for k, v in cols.items():
            if v.dtype == object:
                assert tables[name][k].tolist() == v.tolist()
            else:
                assert np.array_equal(tables[name][k], v, equal_nan=True)


# --------------------------------------------------------------------------------------------
# canonical streams == pymavlink after unit conversion
# --------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def real_log(real):
    rel, path, res, orc = real
    return rel, read_log(path), res, orc


def _tus(msgs, log):
    """Expected t_ns of pymavlink messages (TimeUS, or TimeMS on old logs)."""
    t0 = log.meta["t0_boot_ns"]
    if "TimeUS" in msgs[0]._fieldnames:
        return np.array([x.TimeUS * 1000 - t0 for x in msgs], dtype=np.int64)
    return np.array([x.TimeMS * 1_000_000 - t0 for x in msgs], dtype=np.int64)


def _stream_rows(log, stream, src):
    d = log[stream]
    d = d[d["src"].astype(str) == src]
    # conform sorts by (instance, t_ns) stably; file order within a message is restored by
    # sorting on t_boot_ns stably only where instances do not interleave
    return d


def test_streams_the_source_contains_are_nonempty(real_log):
    rel, log, res, _ = real_log
    nonempty = {k for k, v in log.streams.items() if len(v)}
    assert REAL_LOGS[rel] <= nonempty
    assert log.meta["source_format"] == "ardupilot_dataflash"
    assert log.meta["reader"] == "dataflash"
    assert len(log.meta["source_sha256"]) == 64


def test_imu_equals_pymavlink(real_log):
    rel, log, res, orc = real_log
    names = [n for n in ("IMU", "IMU2", "IMU3") if orc["msgs"].get(n)]
    if not names:
        pytest.skip(f"{rel} logs no IMU message")
    for inst, name in enumerate(names):
        msgs = orc["msgs"][name]
        rows = _stream_rows(log, "imu", name)
        assert len(rows) == len(msgs)
        assert (rows["instance"] == inst).all()
        assert np.array_equal(rows["t_ns"].to_numpy(), _tus(msgs, log))
        for ax in "xyz":
            assert np.array_equal(rows[f"gyr_{ax}_radps"].to_numpy(), _values(msgs, f"Gyr{ax.upper()}"))
            assert np.array_equal(rows[f"acc_{ax}_mps2"].to_numpy(), _values(msgs, f"Acc{ax.upper()}"))


def test_gps_equals_pymavlink(real_log):
    rel, log, res, orc = real_log
    msgs = orc["msgs"]["GPS"]
    rows = _stream_rows(log, "gps", "GPS")
    if "I" in msgs[0]._fieldnames:
        rows = rows.sort_values("t_boot_ns", kind="stable")
    assert len(rows) == len(msgs)
    # a receiver without a fix logs lat = lon = 0: those rows stay, their position is missing
    lat, lon, alt = (np.array(_values(msgs, k), dtype=np.float64) for k in ("Lat", "Lng", "Alt"))
    zero = (lat == 0) & (lon == 0)
    lat[zero] = lon[zero] = alt[zero] = np.nan
    assert np.array_equal(rows["lat_deg"], lat, equal_nan=True)
    assert np.array_equal(rows["lon_deg"], lon, equal_nan=True)
    assert np.array_equal(rows["alt_msl_m"], alt, equal_nan=True)
    assert log.meta["diagnostics"].get("gps_zero_positions", 0) == int(zero.sum())
    assert np.array_equal(rows["fix_type"], _values(msgs, "Status"))
    assert np.array_equal(rows["n_sats"], _values(msgs, "NSats"))
    spd = np.array(_values(msgs, "Spd"))
    crs = np.deg2rad(_values(msgs, "GCrs"))
    np.testing.assert_allclose(rows["vel_n_mps"], spd * np.cos(crs), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(rows["vel_e_mps"], spd * np.sin(crs), rtol=1e-9, atol=1e-12)
    assert np.array_equal(rows["vel_d_mps"], _values(msgs, "VZ"))
    if "T" in msgs[0]._fieldnames:  # old format: boot time in T (ms)
        expect = np.array([x.T * 1_000_000 for x in msgs]) - log.meta["t0_boot_ns"]
    else:
        expect = _tus(msgs, log)
    assert np.array_equal(rows["t_ns"], expect)
    if orc["msgs"].get("GPA") and "HAcc" in orc["msgs"]["GPA"][0]._fieldnames:
        assert np.array_equal(rows["hacc_m"], _values(orc["msgs"]["GPA"], "HAcc"))


def test_attitude_roundtrips_pymavlink_euler(real_log):
    rel, log, res, orc = real_log
    for name in ("ATT", "AHR2"):
        msgs = orc["msgs"].get(name)
        if not msgs:
            continue
        rows = _stream_rows(log, "attitude", name)
        assert len(rows) == len(msgs)
        q = rows[["q_w", "q_x", "q_y", "q_z"]].to_numpy()
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
        r, p, y = quat_to_euler(q)
        rr, pp, yy = (np.deg2rad(_values(msgs, c)) for c in ("Roll", "Pitch", "Yaw"))

        def wrap(a):
            return (a + np.pi) % (2 * np.pi) - np.pi

        ok = np.abs(pp) < np.deg2rad(89.9)  # roll/yaw are not separable at gimbal lock
        assert np.max(np.abs(wrap(p - pp))) < 1e-6
        assert np.max(np.abs(wrap(r - rr)[ok])) < 1e-6
        assert np.max(np.abs(wrap(y - yy)[ok])) < 1e-6


def test_baro_equals_pymavlink(real_log):
    rel, log, res, orc = real_log
    if orc["msgs"].get("BARO"):
        msgs = orc["msgs"]["BARO"]
        rows = _stream_rows(log, "baro", "BARO")
        assert np.array_equal(rows["alt_rel_m"], _values(msgs, "Alt"))
        assert np.array_equal(rows["press_Pa"], _values(msgs, "Press"))
        assert np.array_equal(rows["temp_degC"], _values(msgs, "Temp"))
    elif orc["msgs"].get("CTUN") and "BarAlt" in orc["msgs"]["CTUN"][0]._fieldnames:
        msgs = orc["msgs"]["CTUN"]
        rows = _stream_rows(log, "baro", "CTUN")
        assert np.array_equal(rows["alt_rel_m"], _values(msgs, "BarAlt"))
        assert np.array_equal(rows["t_ns"], _tus(msgs, log))
    else:
        assert not len(log["baro"])


def test_rc_and_servo_equal_pymavlink(real_log):
    rel, log, res, orc = real_log
    logged = [(n, p) for n, p in (("RCIN", "rc"), ("RCOU", "servo")) if orc["msgs"].get(n)]
    if not logged:   # nothing to compare: said, not a silent pass; and then no control rows
        assert not (log["control"]["src"].astype(str).isin(["RCIN", "RCOU"])).any()
        pytest.skip(f"{rel} logs no RCIN or RCOU record")
    for name, prefix in logged:
        msgs = orc["msgs"][name]
        rows = _stream_rows(log, "control", name)
        assert len(rows) == len(msgs)
        for i in range(1, 15):
            col = f"C{i}" if f"C{i}" in msgs[0]._fieldnames else f"Chan{i}"
            if col in msgs[0]._fieldnames:
                assert np.array_equal(rows[f"{prefix}_{i}_us"], _values(msgs, col)), (name, i)


def test_mag_is_pymavlinks_mgauss_times_1e7_on_all_three_axes(real_log):
    rel, log, res, orc = real_log
    names = [n for n in ("MAG", "MAG2", "MAG3") if orc["msgs"].get(n)]
    if not names:
        pytest.skip(f"{rel} logs no MAG record")
    for name in names:
        msgs = orc["msgs"][name]
        rows = _stream_rows(log, "mag", name)
        order = np.arange(len(msgs))
        if "I" in msgs[0]._fieldnames:  # one MAG message for all compasses: conform sorts by instance
            order = np.argsort(np.array(_values(msgs, "I")), kind="stable")
        assert len(rows) == len(msgs)
        assert np.array_equal(rows["t_ns"].to_numpy(), _tus(msgs, log)[order])
        for ax in "xyz":
            want = np.array(_values(msgs, f"Mag{ax.upper()}"), dtype=np.float64)[order] * 1e-7
            np.testing.assert_allclose(rows[f"mag_{ax}_T"].to_numpy(), want, rtol=1e-15, atol=0, err_msg=f"{name} {ax}")
    # Earth's field is 25-65 µT: the unit conversion is right if the magnitudes land there
    b = np.linalg.norm(rows[["mag_x_T", "mag_y_T", "mag_z_T"]].to_numpy(), axis=1)
    assert 15e-6 < np.median(b) < 80e-6


def test_params_modes_and_utc_match_pymavlink(real_log):
    rel, log, res, orc = real_log
    assert log.meta["params"] == {k: float(v) for k, v in orc["params"].items()}
    ours = log["mode"]
    ours = ours[ours["src"].astype(str) == "MODE"].sort_values("t_boot_ns", kind="stable")
    assert ours["mode"].tolist() == orc["modes"]
    # UTC of the first good GPS fix: pymavlink's clock (GPS week/ms less a fixed 18 leap
    # seconds) corrected to the leap seconds of the log's date from the IERS list (16 s in 2014)
    gps = [x for x in orc["msgs"]["GPS"] if x.Status >= 3]
    if not gps:
        assert log.meta["t0_utc_ns"] is None
        return
    g = gps[0]
    if "GWk" in g._fieldnames:
        utc = 315964800 + 604800 * g.GWk + g.GMS * 1e-3 - 18
        boot_ns = g.TimeUS * 1000
    else:
        utc = 315964800 + 604800 * g.Week + g.TimeMS * 1e-3 - 18
        boot_ns = g.T * 1_000_000
    leap = gps_minus_utc(utc)
    utc += 18 - leap
    assert log.meta["leap_seconds"] == leap and log.meta["utc_source"] == "gps"
    t_utc = (log.meta["t0_utc_ns"] + boot_ns - log.meta["t0_boot_ns"]) * 1e-9
    assert abs(t_utc - utc) < 1e-6
    assert log.meta["ned_origin"]["lat_deg"] != 0


def test_timestamps_are_ns_since_first_sample(real_log):
    rel, log, res, orc = real_log
    # t_ns = 0 is the first sensor record; the event streams (schema 1.1: params, messages)
    # keep their true stamps, so a parameter dump logged before it has t_ns < 0
    firsts = [int(v["t_ns"].min()) for k, v in log.streams.items()
              if len(v) and k != "labels" and k not in schema.EVENT_STREAMS]
    assert min(firsts) == 0
    for k in schema.EVENT_STREAMS:
        if len(log[k]):
            assert int(log[k]["t_ns"].min()) > -1_000_000_000  # within a second before
    assert log.meta["diagnostics"]["timestamp_anomalies"] == {}


# --------------------------------------------------------------------------------------------
# detection and synthetic logs
# --------------------------------------------------------------------------------------------

def test_sniff_claims_dataflash_and_rejects_others(tmp_path, rng):
    p = tmp_path / "demo.bin"
    write_demo_flight(p, duration_s=5.0)
    r, why = detect(p)
    assert r.name == "dataflash" and "FMT" in why
    # a log that starts mid-stream (first 1000 bytes cut) is still recognised by header density
    q = tmp_path / "cut.bin"
    q.write_bytes(p.read_bytes()[1000:])
    assert df.DataFlashReader.sniff(q, q.read_bytes()[:65536])
    assert df.DataFlashReader.sniff(q, rng.integers(0, 256, 65536, dtype=np.uint8).tobytes()) is None
    assert df.DataFlashReader.sniff(q, b"") is None


def _old_format_log() -> bytes:
    """An ArduCopter-3.1-style log: TimeMS, untimed MODE/EV, cm rangefinder, no FMTU."""
    buf = io.BytesIO()
    with DataFlashWriter(buf) as w:
        w.define("PARM", 129, "Nf", "Name,Value")
        w.define("IMU", 131, "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        w.define("IMU2", 135, "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        w.define("MODE", 3, "Mh", "Mode,ThrCrs")
        w.define("EV", 13, "B", "Id")
        w.define("RFND", 20, "IHH", "TimeMS,Dist1,Dist2")
        w.define("CTUN", 4, "Ihhhffecchh", "TimeMS,ThrIn,AngBst,ThrOut,DAlt,Alt,BarAlt,DSAlt,SAlt,DCRt,CRt")
        w.write_many("PARM", {"Name": ["A_B", "RADR_TAU"], "Value": [1.5, 0.25]})
        w.write("IMU", TimeMS=1000, GyrX=0.5, AccZ=-9.8)
        w.write("IMU2", TimeMS=1000, GyrX=0.25, AccZ=-9.7)
        w.write("MODE", Mode=5, ThrCrs=400)
        w.write("EV", Id=10)
        w.write("RFND", TimeMS=1020, Dist1=150, Dist2=0)
        w.write("CTUN", TimeMS=1030, BarAlt=12.34, SAlt=1.5)
        w.write("IMU", TimeMS=1040, GyrX=0.75, AccZ=-9.8)
        w.write("MODE", Mode=6, ThrCrs=400)
        w.write("EV", Id=11)
    return buf.getvalue()


def test_old_format_synthetic_log(tmp_path):
    p = tmp_path / "old.bin"
    p.write_bytes(_old_format_log())
    log = read_log(p)
    imu = log["imu"]
    assert imu["instance"].tolist() == [0, 0, 1]  # IMU2 -> instance 1
    assert imu.loc[imu["instance"] == 0, "t_ns"].tolist() == [0, 40_000_000]
    assert log.meta["t0_boot_ns"] == 1_000_000_000
    # untimed MODE/EV take the time of the preceding timed record
    m = log["mode"]
    assert m["mode"].tolist() == ["LOITER", "LOITER", "RTL", "RTL"]
    assert m["armed"].isna().iloc[0] and m["armed"].iloc[1:].tolist() == [True, True, False]
    assert m["t_ns"].tolist() == [0, 0, 40_000_000, 40_000_000]
    rf = log["rangefinder"]
    np.testing.assert_allclose(rf.loc[rf["instance"] == 0, "dist_m"], [1.5])  # cm -> m
    assert log["baro"]["alt_rel_m"].tolist() == [12.34]
    assert log.meta["params"] == {"A_B": 1.5, "RADR_TAU": 0.25}
    assert log.meta["dataflash"]["old_format"] is True


def test_radar_message_and_site_params(tmp_path):
    p = tmp_path / "radar.bin"
    with DataFlashWriter(p) as w:
        w.define(**RADR)
        w.write_params({"RADR_SN": 100.0, "RADR_SE": -50.0, "RADR_SD": -2.0, "RADR_TAU": 0.05})
        t = np.arange(1, 11, dtype=np.uint64) * 100_000
        w.write_many("RADR", {"TimeUS": t, "I": np.full(10, 2, np.uint8), "Rng": np.linspace(100, 110, 10),
                              "U": np.full(10, 0.6), "V": np.full(10, 0.8), "RR": np.full(10, 1.5)})
    log = read_log(p)
    r = log["radar"]
    assert len(r) == 10 and r["t_ns"].iloc[1] == 100_000_000
    np.testing.assert_allclose(r["range_m"], np.linspace(100, 110, 10), rtol=1e-7)
    assert (r["sensor_id"] == 2).all() and (r["dcos_v"] == np.float32(0.8)).all()
    assert log.meta["radar"] == {"site_ned_m": [100.0, -50.0, -2.0], "tau_rd_s": pytest.approx(0.05)}


def test_fmtu_units_and_mult_scaling():
    buf = io.BytesIO()
    with DataFlashWriter(buf) as w:
        w.define("MAGX", 60, "QhiB", "TimeUS,MagX,Alt,I", units="sGm#", mults="FCB-")
        w.write("MAGX", TimeUS=5, MagX=321, Alt=-1234, I=1)
    res = df.decode(buf.getvalue())
    f = res.formats["MAGX"]
    assert f.units == ["s", "Gauss", "m", "instance"] and f.instance_field == "I"
    assert f.mults[:3] == [1e-6, 1e-3, 1e-2]
    assert res.tables["MAGX"]["MagX"].tolist() == [321]
    scaled = df.decode(buf.getvalue(), apply_mult=True).tables["MAGX"]
    assert scaled["MagX"].tolist() == [pytest.approx(0.321)]
    assert scaled["Alt"].tolist() == [pytest.approx(-12.34)]
    assert scaled["TimeUS"].tolist() == [5]  # time stays integer


def test_not_dataflash_raises_ingest_error(tmp_path):
    p = tmp_path / "x.bin"
    p.write_bytes(b"\xa3\x95" + bytes(range(256)) * 8)
    with pytest.raises(IngestError, match="x.bin.*FMT"):
        df.DataFlashReader().read(p)
    with pytest.raises(IngestError, match="FMT"):
        df.decode_all(b"\x00" * 100)
    with pytest.raises(IngestError, match="empty"):
        df.decode_all(b"")


def _held_bytes(tables) -> int:
    seen = {}
    for cols in tables.values():
        for v in cols.values():
            base = v
            while isinstance(base.base, np.ndarray):
                base = base.base
            seen[id(base)] = base.nbytes
    return sum(seen.values())


def test_decode_memory_peak_is_bounded():
    """tracemalloc peak <= 3x the file size plus the output tables (benchmarks/ingest.py
    measures all four real logs)."""
    import tracemalloc

    path = realdata_file("ap_copter313_austin_4flights/2014-10-18_20-04-24.bin")
    size = path.stat().st_size
    tracemalloc.start()
    try:
        tables, _ = df.decode_all(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    strings = sum(len(s) + 49 for cols in tables.values() for v in cols.values() if v.dtype == object
                  for s in set(v.tolist()))
    assert peak - _held_bytes(tables) - strings <= 3 * size


def test_progress_reports_bytes(tmp_path):
    p = tmp_path / "demo.bin"
    write_demo_flight(p, duration_s=5.0)
    calls = []
    df.DataFlashReader().read(p, progress=lambda done, total: calls.append((done, total)))
    size = p.stat().st_size
    assert calls and all(t == size for _, t in calls)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls) and calls[-1][0] == size


def test_message_lacking_an_expected_field_costs_only_its_stream(tmp_path):
    p = tmp_path / "odd.bin"
    with DataFlashWriter(p) as w:
        w.define("GPS", 130, "QBLLf", "TimeUS,Status,Lat,Lng,Alt")  # no Spd/GCrs/NSats
        w.define("IMU", 131, "Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        w.write_merged({"GPS": {"TimeUS": [100, 200], "Status": [3, 3], "Lat": [1.0, 1.0],
                                "Lng": [2.0, 2.0], "Alt": [5.0, 5.0]},
                        "IMU": {"TimeUS": [100, 150, 200], "GyrX": [0.1, 0.2, 0.3]}})
    log = read_log(p)
    assert len(log["imu"]) == 3 and len(log["gps"]) == 0
    assert any(w.startswith("gps: GPS not mapped (KeyError") and "its 2 record(s) left out" in w
               for w in log.meta["diagnostics"]["warnings"])
    assert log.meta["diagnostics"]["records_dropped"] == {"unmapped:GPS": 2} and log.meta["status"] == "partial"
    assert log.meta["ned_origin"]["lat_deg"] == 1.0


def test_a_second_imu_lacking_a_field_costs_its_own_records_not_the_first_imus(tmp_path):
    p = tmp_path / "imu2.bin"
    with DataFlashWriter(p) as w:
        w.define("IMU", 131, "Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        w.define("IMU2", 132, "Qfff", "TimeUS,GyrX,GyrY,GyrZ")  # no accelerometer
        w.write_merged({"IMU": {"TimeUS": [100, 150, 200], "GyrX": [0.1, 0.2, 0.3]},
                        "IMU2": {"TimeUS": [110, 160], "GyrX": [0.4, 0.5]}})
    log = read_log(p)
    assert len(log["imu"]) == 3 and set(log["imu"]["instance"]) == {0}
    assert log.meta["diagnostics"]["records_dropped"] == {"unmapped:IMU2": 2}
    assert any(w.startswith("imu: IMU2 not mapped") and w.endswith("the stream's other messages kept")
               for w in log.meta["diagnostics"]["warnings"])
