"""The schema 1.3 ``estimator_status`` stream (issue 13 item 2) against the library oracles:
pymavlink for DataFlash (XKF4/XKF9/NKF4/NKF9/EKF4) and tlog (EKF_STATUS_REPORT,
ESTIMATOR_STATUS), pyulog for ULog (``estimator_status``), on the real logs where they have the
message and on fixtures written with uavpipe's DataFlash writer / the tlog writer / the test ULog
writer, read back by the same oracles, where they do not. Counts and values equal the oracle's.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from helpers import pymavlink_by_type, realdata_file
from pipeline.io import estimator_bits as bits
from pipeline.io import schema
from pipeline.io.registry import read_log

EKF_MSGS = ("XKF4", "XKF9", "NKF4", "NKF9", "EKF4")
REAL_BIN = (
    "ap_copter_forum_crash_pool/log_0036_mechanical_failure.bin",
    "ap_plane_flightcoach_box/pilot_0004.BIN",
    "pymavlink_test_bin/test.BIN",
)
REAL_ULG = ("ulg_px4_flight_review_fixtures/ekf_failure.ulg", "ulg_px4_flight_review_fixtures/motor_failure.ulg")
TLOG = "tlog_phoenix_ubc_quad/phoenix_mission1_2018-09-17_16-44-06.tlog"
#: DataFlash field -> stream column
AP_RATIOS = {"SV": "vel_test_ratio", "SP": "pos_test_ratio", "SH": "hgt_test_ratio", "SVT": "tas_test_ratio"}
AP_FLAGS = {"FS": "fault_flags", "TS": "timeout_flags", "SS": "solution_flags", "GPS": "gps_check_flags"}


@lru_cache(maxsize=None)
def _real(rel):
    """A real log read once per module run (several tests look at the same file)."""
    return read_log(realdata_file(rel))


def _src(log, src):
    d = log["estimator_status"]
    return d[d["src"].astype(str) == src].sort_values(["instance", "t_boot_ns"], kind="stable").reset_index(drop=True)


def _vals(msgs, field):
    return np.array([getattr(m, field) for m in msgs], dtype=np.float64)


def _int(col):
    return col.astype("int64").to_numpy()


# --- schema -----------------------------------------------------------------------------------

def test_schema_1_3_adds_the_estimator_status_stream_and_nothing_else():
    major, minor, _ = (int(x) for x in schema.SCHEMA_VERSION.split("."))
    assert major == 1 and minor >= 3  # 1.3.0 added it; later minors keep it
    assert schema.STREAMS_1_3 == ("estimator_status",)
    assert "estimator_status" in schema.STREAM_NAMES and "estimator_status" not in schema.SENSOR_STREAMS
    cols = schema.column_names("estimator_status")
    assert cols[:4] == ["t_ns", "instance", "src", "t_boot_ns"]
    assert set(bits.FLAG_COLUMNS) <= set(cols)
    for c in schema.STREAMS["estimator_status"]:
        assert c.dtype == ("Int64" if c.name in bits.FLAG_COLUMNS else "float64"), c.name
        assert c.unit == "1"  # bit fields and ratios are dimensionless
    assert [c for c in cols if c.endswith("_test_ratio")] == [
        f"{r}_test_ratio" for r in ("vel", "pos", "hgt", "mag", "hdg", "tas", "hagl")]


# --- DataFlash: real logs ---------------------------------------------------------------------

@pytest.fixture(scope="module", params=REAL_BIN)
def real_bin(request):
    return request.param, _real(request.param), pymavlink_by_type(realdata_file(request.param))


def test_dataflash_estimator_status_equals_pymavlink_on_every_real_log(real_bin):
    rel, log, orc = real_bin
    present = [m for m in EKF_MSGS if orc.get(m)]
    assert present, rel
    assert len(log["estimator_status"]) == sum(len(orc[m]) for m in present)
    t0 = log.meta["t0_boot_ns"]
    for m in present:
        msgs = sorted(orc[m], key=lambda r: (getattr(r, "C", 0), r.TimeUS))
        rows = _src(log, m)
        assert len(rows) == len(msgs), m
        core = _vals(msgs, "C") if "C" in msgs[0]._fieldnames else np.full(len(msgs), m.endswith("9"), float)
        assert np.array_equal(rows["instance"], core)
        assert np.array_equal(rows["t_ns"], np.array([r.TimeUS * 1000 - t0 for r in msgs], np.int64))
        for f, col in AP_RATIOS.items():
            assert np.array_equal(rows[col], _vals(msgs, f)), (m, f)
        assert np.array_equal(rows["mag_test_ratio"], _vals(msgs, "SM"))
        for f, col in AP_FLAGS.items():
            assert np.array_equal(_int(rows[col]), _vals(msgs, f).astype(np.int64)), (m, f)
        assert np.array_equal(rows["primary_core"], _vals(msgs, "PI"))
        assert rows["innovation_fail_flags"].isna().all() and rows["control_mode_flags"].isna().all()


def test_a_real_log_from_before_the_ekf_has_an_empty_estimator_stream():
    """ArduCopter 3.1.3 (2014) declares no EKF message: pymavlink finds none (FMT), nor do we."""
    from pymavlink import mavutil

    path = realdata_file("ap_copter313_austin_4flights/2014-10-18_20-04-24.bin")
    m = mavutil.mavlink_connection(str(path))
    try:
        declared = {f.name for f in m.formats.values()}
    finally:
        m.close()
    assert declared and not declared & set(EKF_MSGS)
    assert len(_real("ap_copter313_austin_4flights/2014-10-18_20-04-24.bin")["estimator_status"]) == 0


def test_real_ekf2_log_has_both_cores_and_named_solution_bits():
    log = _real("ap_copter_forum_crash_pool/log_0036_mechanical_failure.bin")
    e = log["estimator_status"]
    assert e.groupby(["src", "instance"], observed=True).size().to_dict() == {("NKF4", 0): 1502, ("NKF9", 1): 1502}
    names = {bits.bit_name("NKF4", "solution_flags", k) for k in bits.bits_set(e["solution_flags"].dropna())}
    assert {"attitude", "horiz_vel", "vert_vel", "horiz_pos_abs", "using_gps"} <= names


def test_estimator_status_does_not_move_t0_of_the_real_logs():
    """t0 is the first sensor record, as before the stream existed (values of schema 1.2)."""
    t0 = {"ap_copter_forum_crash_pool/log_0036_mechanical_failure.bin": 224602238000,
          "ap_plane_flightcoach_box/pilot_0004.BIN": 4835992000,
          "pymavlink_test_bin/test.BIN": 81794643000}
    for rel, want in t0.items():
        assert _real(rel).meta["t0_boot_ns"] == want, rel


# --- DataFlash: fixtures (uavpipe's writer, read back by pymavlink) ---------------------------

def _ekf_fixture(path):
    from pipeline.io.dataflash.writer import DataFlashWriter

    with DataFlashWriter(path) as w:
        w.define("IMU", 162, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        # EKF1 (Copter 3.4 FMT, as log_0036 declares it): per-axis magnetometer ratios
        w.define("EKF4", 163, "QcccccccbbHBHH", "TimeUS,SV,SP,SH,SMX,SMY,SMZ,SVT,OFN,OFE,FS,TS,SS,GPS")
        # early EKF3: no core field, the second core in XKF9
        w.define("XKF4", 164, "QcccccfbbHBHHb", "TimeUS,SV,SP,SH,SM,SVT,errRP,OFN,OFE,FS,TS,SS,GPS,PI")
        w.define("XKF9", 165, "QcccccfbbHBHHb", "TimeUS,SV,SP,SH,SM,SVT,errRP,OFN,OFE,FS,TS,SS,GPS,PI")
        w.write("EKF4", TimeUS=900_000, SV=0.25, SP=0.5, SH=1.25, SMX=0.1, SMY=0.75, SMZ=0.2, SVT=0.0,
                FS=4, TS=16, SS=127, GPS=2)  # before the first sensor record
        w.write("IMU", TimeUS=1_000_000, I=0, AccZ=-9.8)
        w.write("XKF4", TimeUS=1_100_000, SV=0.07, SP=0.02, SH=0.03, SM=0.01, SVT=0.0, FS=0, TS=16, SS=9087,
                GPS=0, PI=0)
        w.write("XKF9", TimeUS=1_100_000, SV=1.5, SP=0.0, SH=0.05, SM=0.0, SVT=0.0, FS=128, TS=0, SS=0,
                GPS=256, PI=0)
    return path


def test_dataflash_ekf1_and_early_ekf3_fixture_equals_pymavlink(tmp_path):
    p = _ekf_fixture(tmp_path / "ekf.bin")
    log, orc = read_log(p), pymavlink_by_type(p)
    assert log.meta["t0_boot_ns"] == 1_000_000_000  # the EKF4 record before the IMU does not move t0
    e = log["estimator_status"]
    assert len(e) == len(orc["EKF4"]) + len(orc["XKF4"]) + len(orc["XKF9"]) == 3
    old = _src(log, "EKF4").iloc[0]
    o = orc["EKF4"][0]
    assert (old["instance"], old["t_ns"]) == (0, -100_000_000)
    assert old["mag_test_ratio"] == max(o.SMX, o.SMY, o.SMZ) == 0.75  # the largest axis, as EKF2/3 log SM
    assert (old["vel_test_ratio"], old["pos_test_ratio"], old["hgt_test_ratio"]) == (o.SV, o.SP, o.SH)
    assert (old["fault_flags"], old["timeout_flags"], old["solution_flags"], old["gps_check_flags"]) == \
        (o.FS, o.TS, o.SS, o.GPS) == (4, 16, 127, 2)
    assert np.isnan(old["primary_core"])  # EKF1 logs no primary core
    for m, core in (("XKF4", 0), ("XKF9", 1)):
        r, o = _src(log, m).iloc[0], orc[m][0]
        assert (r["instance"], r["t_ns"]) == (core, 100_000_000)
        assert (r["vel_test_ratio"], r["hgt_test_ratio"], r["mag_test_ratio"]) == (o.SV, o.SH, o.SM)
        assert (r["fault_flags"], r["solution_flags"], r["gps_check_flags"]) == (o.FS, o.SS, o.GPS)
    assert bits.bit_name("XKF9", "fault_flags", 7) == "not_initialised"
    assert bits.bit_name("XKF9", "gps_check_flags", 8) == "bad_fix"


def test_copter41_uint16_ratios_are_hundredths_as_the_fmtu_multiplier_says(tmp_path):
    """Copter 4.1+ XKF4: ``QBHHHHHfffHBIHb`` with FMTU multiplier 1e-2 on SV..SVT; pymavlink
    returns the raw integers, the stream the ratios."""
    from pipeline.io.dataflash.writer import DataFlashWriter

    p = tmp_path / "xkf4.bin"
    with DataFlashWriter(p) as w:
        w.define("IMU", 162, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        w.define("XKF4", 166, "QBHHHHHfffHBIHb", "TimeUS,C,SV,SP,SH,SM,SVT,errRP,OFN,OFE,FS,TS,SS,GPS,PI",
                 units="s#------mm-----", mults="F-BBBBB-??-----")
        w.write("IMU", TimeUS=1_000_000, I=0, AccZ=-9.8)
        w.write("XKF4", TimeUS=1_050_000, C=0, SV=7, SP=250, SH=3, SM=1, SVT=0, FS=0, TS=0, SS=2 ** 18 + 1,
                GPS=0, PI=1)
        w.write("XKF4", TimeUS=1_050_000, C=1, SV=120, SP=2, SH=5, SM=0, SVT=9, FS=128, TS=3, SS=0, GPS=1024,
                PI=1)
    orc = pymavlink_by_type(p)["XKF4"]
    rows = _src(read_log(p), "XKF4")
    assert rows["instance"].tolist() == [o.C for o in orc] == [0, 1]
    for f, col in (*AP_RATIOS.items(), ("SM", "mag_test_ratio")):
        np.testing.assert_allclose(rows[col], _vals(orc, f) * 0.01, rtol=0, atol=1e-15)
    assert rows["pos_test_ratio"].iloc[0] == pytest.approx(2.5)  # rejected: above the gate
    assert _int(rows["solution_flags"]).tolist() == [o.SS for o in orc]
    assert bits.bits_set(rows["solution_flags"]) == [0, 18]
    assert bits.bit_name("XKF4", "solution_flags", 18) == "dead_reckoning"
    assert bits.bit_name("XKF4", "gps_check_flags", 10) == "bad_vAcc"
    assert rows["primary_core"].tolist() == [1.0, 1.0]


# --- tlog -------------------------------------------------------------------------------------

def test_tlog_ekf_status_report_equals_pymavlink_on_the_real_log():
    path = realdata_file(TLOG)
    log, orc = read_log(path), pymavlink_by_type(path)
    veh = (log.meta["mavlink"]["sysid"], log.meta["mavlink"]["compid"])
    msgs = [m for m in orc["EKF_STATUS_REPORT"] if (m.get_srcSystem(), m.get_srcComponent()) == veh]
    rows = _src(log, "EKF_STATUS_REPORT")
    assert len(rows) == len(msgs) == 765
    assert _int(rows["solution_flags"]).tolist() == [m.flags for m in msgs]
    for f, col in (("velocity_variance", "vel_test_ratio"), ("pos_horiz_variance", "pos_test_ratio"),
                   ("pos_vert_variance", "hgt_test_ratio"), ("compass_variance", "mag_test_ratio"),
                   ("terrain_alt_variance", "hagl_test_ratio")):
        assert np.array_equal(rows[col], _vals(msgs, f)), f
    # airspeed_variance is a MAVLink 2 extension: only a v2 frame (magic 0xFD) carries it; a v1
    # frame has none, whatever pymavlink's current dialect fills in (0 when mavutil was left on
    # the v2 dialect by an earlier test in the same worker)
    tas = np.array([getattr(m, "airspeed_variance", np.nan) if m.get_msgbuf()[0] == 0xFD else np.nan
                    for m in msgs], dtype=np.float64)
    assert np.array_equal(rows["tas_test_ratio"], tas, equal_nan=True)
    assert rows["t_boot_ns"].isna().all()  # the message carries no boot stamp
    assert rows["fault_flags"].isna().all()


def test_tlog_fixture_with_both_estimator_messages_equals_pymavlink(tmp_path):
    from pymavlink.dialects.v20 import ardupilotmega as v2

    from pipeline.io.tlog import write_tlog

    mav = v2.MAVLink(None)
    t = 1_767_268_800_000_000
    recs = [
        (t, mav.heartbeat_encode(2, 3, 81, 0, 4)),
        (t + 10_000, mav.attitude_encode(1000, 0.1, 0.2, 0.3, 0, 0, 0)),
        (t + 20_000, mav.ekf_status_report_encode(0x01 | 0x02 | 0x8000, 0.5, 1.5, 0.25, 0.125, 0.0, 0.75)),
        (t + 30_000, mav.estimator_status_encode(1_030_000, 0x01 | 0x400, 0.2, 0.3, 0.4, 0.6, 0.7, 1.2, 0.9, 1.1)),
        (t + 40_000, mav.ekf_status_report_encode(0x400, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0)),
    ]
    p = write_tlog(tmp_path / "ekf.tlog", recs)
    log, orc = read_log(p), pymavlink_by_type(p)
    ekf, est = _src(log, "EKF_STATUS_REPORT"), _src(log, "ESTIMATOR_STATUS")
    assert len(ekf) == len(orc["EKF_STATUS_REPORT"]) == 2 and len(est) == len(orc["ESTIMATOR_STATUS"]) == 1
    o = orc["ESTIMATOR_STATUS"][0]
    r = est.iloc[0]
    assert r["solution_flags"] == o.flags and r["t_boot_ns"] == o.time_usec * 1000
    assert (r["vel_test_ratio"], r["pos_test_ratio"], r["hgt_test_ratio"], r["mag_test_ratio"],
            r["hagl_test_ratio"], r["tas_test_ratio"]) == \
        (o.vel_ratio, o.pos_horiz_ratio, o.pos_vert_ratio, o.mag_ratio, o.hagl_ratio, o.tas_ratio)
    assert ekf["t_ns"].tolist() == [20_000_000, 40_000_000]
    assert ekf["vel_test_ratio"].tolist() == [m.velocity_variance for m in orc["EKF_STATUS_REPORT"]]
    assert ekf["tas_test_ratio"].tolist() == [0.75, 0.0]
    # the same bit value means different things in the two messages
    assert bits.bit_name("EKF_STATUS_REPORT", "solution_flags", 10) == "uninitialized"
    assert bits.bit_name("ESTIMATOR_STATUS", "solution_flags", 10) == "gps_glitch"
    assert bits.bit_name("EKF_STATUS_REPORT", "solution_flags", 15) == "gps_glitching"
    # the vehicle pick is unchanged by the new message types (ATTITUDE decides it)
    assert log.meta["mavlink"]["sysid"] == 1


def test_mavlink_bit_tables_equal_pymavlink_enums():
    from pymavlink.dialects.v20 import ardupilotmega as v2

    def table(enum, prefix):
        return {int(k).bit_length() - 1: e.name[len(prefix):].lower()
                for k, e in v2.enums[enum].items() if not e.name.endswith("ENUM_END")}
    assert table("EKF_STATUS_FLAGS", "EKF_") == bits.MAVLINK_EKF_STATUS_FLAGS
    assert table("ESTIMATOR_STATUS_FLAGS", "ESTIMATOR_") == bits.PX4_SOLUTION_STATUS


# --- ULog -------------------------------------------------------------------------------------

@pytest.fixture(scope="module", params=REAL_ULG)
def real_ulg(request):
    import pyulog

    return request.param, _real(request.param), pyulog.ULog(str(realdata_file(request.param)))


def test_ulog_estimator_status_equals_pyulog_on_the_real_logs(real_ulg):
    rel, log, u = real_ulg
    ds = [d for d in u.data_list if d.name == "estimator_status"]
    e = _src(log, "estimator_status")
    assert len(e) == sum(len(d.data["timestamp"]) for d in ds) > 0
    for d in ds:
        rows = e[e["instance"] == d.multi_id].reset_index(drop=True)
        assert len(rows) == len(d.data["timestamp"])
        assert np.array_equal(rows["t_ns"], (d.data["timestamp"].astype(np.int64) - int(u.start_timestamp)) * 1000)
        for f, col in (("solution_status_flags", "solution_flags"), ("filter_fault_flags", "fault_flags"),
                       ("innovation_check_flags", "innovation_fail_flags"), ("gps_check_fail_flags", "gps_check_flags"),
                       ("timeout_flags", "timeout_flags"), ("control_mode_flags", "control_mode_flags")):
            if f in d.data:
                assert np.array_equal(_int(rows[col]), d.data[f].astype(np.int64)), f
            else:
                assert rows[col].isna().all(), f
        for r in ("vel", "pos", "hgt", "mag", "hdg", "tas", "hagl"):
            f = f"{r}_test_ratio"
            if f in d.data:
                assert np.array_equal(rows[f], d.data[f].astype(np.float64), equal_nan=True), f
            else:
                assert rows[f].isna().all(), f


def test_ulog_layout_follows_the_logs_own_estimator_status_flags():
    new, old = _real(REAL_ULG[0]), _real(REAL_ULG[1])
    assert new.meta["estimator_status"] == {"layout": "px4", "innovation_fail_flags": [
        "reject_hor_vel", "reject_ver_vel", "reject_hor_pos", "reject_ver_pos", "reject_yaw", "reject_airspeed",
        "reject_sideslip", "reject_hagl", "reject_optflow_x", "reject_optflow_y"]}  # the log's own names
    assert old.meta["estimator_status"] == {"layout": "px4_legacy"}  # PX4 1.9: no estimator_status_flags
    # ekf_failure.ulg: filter_fault_flags 1024 is the vertical-accelerometer fault in PX4 1.15
    faults = bits.bits_set(new["estimator_status"]["fault_flags"])
    assert faults == [10]
    assert bits.bit_name("estimator_status", "fault_flags", 10, new.meta) == "bad_acc_vertical"
    assert bits.bit_name("estimator_status", "fault_flags", 10, old.meta) == "bad_vel_e"
    assert bits.bit_name("estimator_status", "gps_check_flags", 5, new.meta) == "max_spd_err"


def test_px4_1_15_rejections_come_from_estimator_status_flags_packed_in_field_order():
    """ekf_failure.ulg (PX4 1.15) logs no innovation_check_flags: its estimator_status_flags
    ``reject_*`` booleans become rows whose bit k is the k-th reject field (pyulog's values)."""
    import pyulog

    log = _real(REAL_ULG[0])
    f = pyulog.ULog(str(realdata_file(REAL_ULG[0]))).get_dataset("estimator_status_flags").data
    rows = _src(log, "estimator_status_flags")
    assert len(rows) == len(f["timestamp"]) == 91
    names = log.meta["estimator_status"]["innovation_fail_flags"]
    want = sum((f[n].astype(np.int64) != 0).astype(np.int64) << k for k, n in enumerate(names))
    assert np.array_equal(_int(rows["innovation_fail_flags"]), want)
    assert rows[[c for c in bits.FLAG_COLUMNS if c != "innovation_fail_flags"]].isna().all().all()
    assert bits.bit_name("estimator_status_flags", "innovation_fail_flags", 2, log.meta) == "reject_hor_pos"
    # motor_failure.ulg (PX4 1.9) has innovation_check_flags and no such topic: no extra rows
    assert set(_real(REAL_ULG[1])["estimator_status"]["src"].astype(str)) == {"estimator_status"}


def test_px4_bit_tables_match_the_field_order_of_a_real_estimator_status_flags():
    """The ``cs_*`` and ``fs_*`` booleans of PX4 1.15's ``estimator_status_flags`` are its
    control-mode and fault bits in order (the fault bits skip the unused bit 9), and
    ``estimator_gps_status.check_fail_*`` are the GPS-check bits."""
    import pyulog

    u = pyulog.ULog(str(realdata_file(REAL_ULG[0])))
    f = u.get_dataset("estimator_status_flags").data
    cs = [k[3:] for k in f if k.startswith("cs_")]
    assert [bits.PX4_CONTROL_MODE[k] for k in range(len(cs))] == cs
    fs = [k[3:] for k in f if k.startswith("fs_")]
    assert [bits.PX4_FILTER_FAULTS[k] for k in sorted(bits.PX4_FILTER_FAULTS)] == fs
    g = u.get_dataset("estimator_gps_status").data
    chk = [k[len("check_fail_"):] for k in g if k.startswith("check_fail_")]
    assert [bits.PX4_GPS_CHECKS[k] for k in range(len(chk))] == [c.replace("_gps", "") for c in chk]
    # and the logged control_mode_flags agree with the booleans of the same filter sample
    s = u.get_dataset("estimator_status").data
    k = np.flatnonzero(np.isin(f["timestamp_sample"], s["timestamp_sample"]))
    assert len(k) == 3  # the on-change topic meets the 2.5 Hz status at three samples
    for i in k:
        j = int(np.flatnonzero(s["timestamp_sample"] == f["timestamp_sample"][i])[0])
        packed = sum(int(f[f"cs_{n}"][i]) << b for b, n in enumerate(cs))
        assert packed == int(s["control_mode_flags"][j])


def test_ulog_fixture_with_two_instances_and_reject_names(tmp_path):
    from helpers_ulog import ULogWriter

    F = [("uint64_t", "timestamp")]
    es = F + [("uint16_t", "solution_status_flags"), ("uint32_t", "filter_fault_flags"),
              ("uint16_t", "innovation_check_flags"), ("uint16_t", "gps_check_fail_flags"),
              ("uint64_t", "control_mode_flags"), ("float", "vel_test_ratio"), ("float", "hgt_test_ratio"),
              ("float", "hdg_test_ratio")]
    w = ULogWriter(start_us=2_000_000)
    ts = np.array([2_100_000, 2_200_000], np.uint64)
    for inst, base in ((0, 0), (1, 1)):
        w.topic("estimator_status", es, {
            "timestamp": ts + inst, "solution_status_flags": np.array([1, 3 + base], np.uint16),
            "filter_fault_flags": np.array([0, 1 << 10], np.uint32),
            "innovation_check_flags": np.array([0, 1 << 2], np.uint16),
            "gps_check_fail_flags": np.array([1, 0], np.uint16),
            "control_mode_flags": np.array([1 << 44 | 3, 3], np.uint64),
            "vel_test_ratio": np.array([0.5, 1.5], np.float32), "hgt_test_ratio": np.array([0.25, 0.0], np.float32),
            "hdg_test_ratio": np.array([0.125, 2.0], np.float32)}, multi_id=inst)
    w.topic("estimator_status_flags", F + [("bool", "fs_bad_mag_x"), ("bool", "fs_bad_acc_vertical"),
                                           ("bool", "reject_hor_vel"), ("bool", "reject_ver_vel"),
                                           ("bool", "reject_hor_pos")],
            {"timestamp": ts[:1], **{k: np.zeros(1, bool) for k in ("fs_bad_mag_x", "fs_bad_acc_vertical",
                                                                     "reject_hor_vel", "reject_ver_vel",
                                                                     "reject_hor_pos")}})
    p = w.write(tmp_path / "est.ulg")
    import pyulog

    ref = {d.multi_id: d.data for d in pyulog.ULog(str(p)).data_list if d.name == "estimator_status"}
    log = read_log(p)
    e = log["estimator_status"]
    assert e.groupby("instance").size().to_dict() == {0: 2, 1: 2}
    for inst, d in ref.items():
        rows = e[e["instance"] == inst]
        assert _int(rows["control_mode_flags"]).tolist() == d["control_mode_flags"].astype(np.int64).tolist()
        assert rows["hdg_test_ratio"].tolist() == d["hdg_test_ratio"].astype(float).tolist()
        assert rows["mag_test_ratio"].isna().all() and rows["timeout_flags"].isna().all()
    assert log.meta["estimator_status"] == {
        "layout": "px4", "innovation_fail_flags": ["reject_hor_vel", "reject_ver_vel", "reject_hor_pos"]}
    assert set(e["src"].astype(str)) == {"estimator_status"}  # innovation_check_flags logged: no packed rows
    assert bits.bit_name("estimator_status", "innovation_fail_flags", 2, log.meta) == "reject_hor_pos"
    assert bits.bit_name("estimator_status", "control_mode_flags", 44, log.meta) == "gnss_vel"
    assert bits.bit_name("estimator_status", "control_mode_flags", 43, log.meta) == "bit 43"
    assert bits.bits_set(e["control_mode_flags"]) == [0, 1, 44]


# --- the bit tables ---------------------------------------------------------------------------

def test_every_layout_names_each_bit_once_and_every_known_source_has_a_layout():
    for layout, cols in bits.LAYOUTS.items():
        assert set(cols) <= set(bits.FLAG_COLUMNS), layout
        for col, names in cols.items():
            assert len(set(names.values())) == len(names), (layout, col)
            assert all(0 <= k < 64 for k in names), (layout, col)
    assert set(bits.SRC_LAYOUT.values()) <= set(bits.LAYOUTS)
    assert bits.layout_of("unknown_topic") is None and bits.bit_name("unknown_topic", "fault_flags", 3) == "bit 3"
    assert bits.bits_set(np.array([np.nan, 5.0])) == [0, 2] and bits.bits_set([]) == []
