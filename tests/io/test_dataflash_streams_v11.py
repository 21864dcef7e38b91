"""DataFlash schema 1.1 streams (battery, setpoint, messages, params, vibration, GPS quality)
against pymavlink's DFReader on every real ``.bin`` log (the oracle: ``recv_msg()`` loop).

Values are compared exactly after the documented unit conversion; t_ns is the message's own
boot stamp less ``t0_boot_ns`` where the message has one.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import pymavlink_by_type, realdata_file
from pipeline.io.registry import read_log

REAL_LOGS = (
    "ap_copter313_austin_4flights/2014-10-18_20-04-24.bin",
    "ap_copter_forum_crash_pool/log_0036_mechanical_failure.bin",
    "ap_plane_flightcoach_box/pilot_0004.BIN",
    "pymavlink_test_bin/test.BIN",
)


@pytest.fixture(scope="module", params=REAL_LOGS)
def real(request):
    path = realdata_file(request.param)
    return request.param, read_log(path), pymavlink_by_type(path)


def _rows(log, stream, src):
    d = log[stream]
    return d[d["src"].astype(str) == src].sort_values("t_boot_ns", kind="stable")


def _vals(msgs, field):
    return np.array([getattr(m, field) for m in msgs], dtype=np.float64)


def _t_ns(msgs, log):
    """Expected t_ns (TimeUS, or TimeMS on old logs); None for untimed messages."""
    f = msgs[0]._fieldnames
    t0 = log.meta["t0_boot_ns"]
    if "TimeUS" in f:
        return np.array([m.TimeUS * 1000 - t0 for m in msgs], dtype=np.int64)
    if "TimeMS" in f:
        return np.array([m.TimeMS * 1_000_000 - t0 for m in msgs], dtype=np.int64)
    return None


def test_battery_equals_pymavlink_bat_or_curr_in_si_units(real):
    rel, log, orc = real
    name = "BAT" if orc.get("BAT") else "CURR" if orc.get("CURR") else None
    if name is None:
        assert len(log["battery"]) == 0
        pytest.skip(f"{rel} logs no BAT/CURR")
    msgs = orc[name]
    rows = _rows(log, "battery", name)
    assert len(rows) == len(msgs)
    # Copter 3.1 CURR logs Volt/Curr as integers in 1/100 V and 1/100 A
    scale = 0.01 if isinstance(msgs[0].Volt, int) else 1.0
    assert np.array_equal(rows["voltage_V"], _vals(msgs, "Volt") * scale)
    assert np.array_equal(rows["current_A"], _vals(msgs, "Curr") * scale)
    assert np.array_equal(rows["consumed_Ah"], _vals(msgs, "CurrTot") * 1e-3)
    assert np.array_equal(rows["t_ns"], _t_ns(msgs, log))
    assert 5 < rows["voltage_V"].median() < 60  # a real pack, in volts


def test_attitude_and_rate_setpoints_equal_pymavlink_in_radians(real):
    rel, log, orc = real
    msgs = orc["ATT"]
    rows = _rows(log, "setpoint", "ATT")
    assert len(rows) == len(msgs)
    for ours, theirs in (("roll_rad", "DesRoll"), ("pitch_rad", "DesPitch"), ("yaw_rad", "DesYaw")):
        assert np.array_equal(rows[ours], np.deg2rad(_vals(msgs, theirs)))
    assert np.array_equal(rows["t_ns"], _t_ns(msgs, log))
    assert rows["p_radps"].isna().all()
    if orc.get("RATE"):
        r = _rows(log, "setpoint", "RATE")
        assert len(r) == len(orc["RATE"])
        for ours, theirs in (("p_radps", "RDes"), ("q_radps", "PDes"), ("r_radps", "YDes")):
            assert np.array_equal(r[ours], np.deg2rad(_vals(orc["RATE"], theirs)))
    if orc.get("NTUN") and "DVelX" in orc["NTUN"][0]._fieldnames:
        v = _rows(log, "setpoint", "NTUN")
        assert np.array_equal(v["vel_n_mps"], _vals(orc["NTUN"], "DVelX") * 0.01)
        assert np.array_equal(v["vel_e_mps"], _vals(orc["NTUN"], "DVelY") * 0.01)
    if orc.get("CTUN") and "DCRt" in orc["CTUN"][0]._fieldnames:
        c = _rows(log, "setpoint", "CTUN")
        assert len(c) == len(orc["CTUN"])
        assert np.array_equal(c["vel_d_mps"], -_vals(orc["CTUN"], "DCRt") * 0.01)  # cm/s up -> m/s down
        assert np.array_equal(c["t_ns"], _t_ns(orc["CTUN"], log))


def test_messages_and_params_equal_pymavlink_records(real):
    rel, log, orc = real
    m = _rows(log, "messages", "MSG")
    assert m["text"].tolist() == [x.Message for x in orc["MSG"]]
    assert m["severity"].isna().all()  # DataFlash MSG carries no severity
    p = _rows(log, "params", "PARM")
    assert p["name"].tolist() == [x.Name for x in orc["PARM"]]
    assert np.array_equal(p["value"], _vals(orc["PARM"], "Value"))
    t = _t_ns(orc["PARM"], log)
    if t is not None:
        assert np.array_equal(p["t_ns"], t)
    # the last value per name is meta['params'] (kept as before)
    assert dict(zip(p["name"], p["value"])) == log.meta["params"]


def test_vibration_equals_pymavlink_vibe(real):
    rel, log, orc = real
    if not orc.get("VIBE"):
        assert len(log["vibration"]) == 0
        pytest.skip(f"{rel} logs no VIBE")
    msgs = orc["VIBE"]
    rows = _rows(log, "vibration", "VIBE")
    assert len(rows) == len(msgs)
    for a in "xyz":
        assert np.array_equal(rows[f"vibe_{a}_mps2"], _vals(msgs, f"Vibe{a.upper()}"))
    for i in range(3):
        assert np.array_equal(rows[f"clip_{i}"], _vals(msgs, f"Clip{i}"))
    assert np.array_equal(rows["t_ns"], _t_ns(msgs, log))


def test_gps_quality_columns_equal_pymavlink(real):
    rel, log, orc = real
    msgs = orc["GPS"]
    rows = _rows(log, "gps", "GPS")
    assert np.array_equal(rows["hdop"], _vals(msgs, "HDop"))
    assert np.array_equal(rows["fix_type"], _vals(msgs, "Status"))
    assert np.array_equal(rows["n_sats"], _vals(msgs, "NSats"))
    if orc.get("GPA") and "VDop" in orc["GPA"][0]._fieldnames and "I" not in msgs[0]._fieldnames:
        assert np.array_equal(rows["vdop"], _vals(orc["GPA"], "VDop"))


def test_new_streams_do_not_move_t0():
    """t0 stays the first sensor record: PARM/MSG records written before it do not count."""
    log = read_log(realdata_file("pymavlink_test_bin/test.BIN"))
    firsts = {s: int(log[s]["t_ns"].min()) for s in log.streams if len(log[s]) and s not in ("params", "messages")}
    assert min(firsts.values()) == 0 == firsts["imu"]  # the first IMU record defines t0
    assert log.meta["t0_boot_ns"] == 81_794_643_000  # its TimeUS (81 794 643 µs after boot)
    assert int(log["params"]["t_ns"].min()) < 0  # the parameter dump precedes the sensors


# --- synthetic logs (uavpipe's DataFlash writer, read back by pymavlink): no shared data ------

def _synthetic_log(path):
    from pipeline.io.dataflash.writer import DataFlashWriter

    with DataFlashWriter(path) as w:
        w.define("IMU", 162, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        w.define("BAT", 70, "QBfffffcf", "TimeUS,Instance,Volt,VoltR,Curr,CurrTot,EnrgTot,Temp,Res")
        w.define("VIBE", 71, "QBfffI", "TimeUS,IMU,VibeX,VibeY,VibeZ,Clip")
        w.define("RATE", 72, "Qffffff", "TimeUS,RDes,R,ROut,PDes,P,POut")  # no yaw: not mapped
        w.define("ATT", 73, "QccccCC", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw")
        w.define("MSG", 74, "QZ", "TimeUS,Message")
        w.define("PSCD", 75, "Qffffffff", "TimeUS,TPD,PD,DVD,TVD,VD,DAD,TAD,AD")
        w.write_params({"A_B": 1.5}, time_us=500_000)
        w.write("IMU", TimeUS=1_000_000, I=0, AccZ=-9.8)
        w.write("BAT", TimeUS=1_100_000, Instance=1, Volt=16.25, Curr=12.5, CurrTot=750.0, Temp=31.5)
        w.write("VIBE", TimeUS=1_200_000, IMU=0, VibeX=1.5, VibeY=2.5, VibeZ=3.5, Clip=4)
        w.write("VIBE", TimeUS=1_200_000, IMU=1, VibeX=0.5, VibeY=0.5, VibeZ=0.5, Clip=7)
        w.write("RATE", TimeUS=1_300_000, RDes=90.0)
        w.write("ATT", TimeUS=1_400_000, DesRoll=10.0, DesPitch=-5.0, DesYaw=270.0)
        w.write("MSG", TimeUS=1_500_000, Message="hello")
        w.write("PSCD", TimeUS=1_550_000, TVD=-1.25, DVD=-1.0)
        w.write_params({"A_B": 2.0}, time_us=1_600_000)
    return path


def test_synthetic_modern_log_fills_the_new_streams_as_pymavlink_reads_it(tmp_path):
    p = _synthetic_log(tmp_path / "v11.bin")
    log, orc = read_log(p), pymavlink_by_type(p)
    b = log["battery"].iloc[0]
    assert (b["instance"], b["t_ns"]) == (1, 100_000_000)
    assert (b["voltage_V"], b["current_A"], b["consumed_Ah"]) == (16.25, 12.5, 0.75)
    assert b["temp_degC"] == pytest.approx(orc["BAT"][0].Temp) == 31.5
    v = log["vibration"]
    assert v["instance"].tolist() == [0, 1]  # Copter 4: one VIBE per IMU, Clip -> clip_<IMU>
    assert v["clip_0"].iloc[0] == 4 and np.isnan(v["clip_1"].iloc[0])
    assert v["clip_1"].iloc[1] == 7 and v["vibe_z_mps2"].tolist() == [3.5, 0.5]
    s = log["setpoint"]
    assert s["src"].astype(str).tolist() == ["ATT", "PSCD"]  # RATE lacks YDes: not mapped
    assert s["vel_d_mps"].iloc[1] == orc["PSCD"][0].TVD == -1.25 and np.isnan(s["vel_n_mps"].iloc[1])
    np.testing.assert_allclose(s[["roll_rad", "pitch_rad", "yaw_rad"]].iloc[0].to_numpy(float),
                               np.deg2rad([orc["ATT"][0].DesRoll, orc["ATT"][0].DesPitch, orc["ATT"][0].DesYaw]))
    assert log["messages"]["text"].tolist() == ["hello"]
    prm = log["params"]
    assert prm["value"].tolist() == [1.5, 2.0] and prm["t_ns"].tolist() == [-500_000_000, 600_000_000]
    assert log.meta["params"] == {"A_B": 2.0} and log.meta["diagnostics"]["timestamp_anomalies"] == {}
    assert log.meta["t0_boot_ns"] == 1_000_000_000  # PARM before the IMU does not move t0


def test_old_copter_curr_integers_are_hundredths_of_volts_and_amps(tmp_path):
    from pipeline.io.dataflash.writer import DataFlashWriter

    p = tmp_path / "old.bin"
    with DataFlashWriter(p) as w:
        w.define("IMU", 131, "Iffffff", "TimeMS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        w.define("CURR", 132, "IhIhhhf", "TimeMS,ThrOut,ThrInt,Volt,Curr,Vcc,CurrTot")
        w.write("IMU", TimeMS=1000, AccZ=-9.8)
        w.write("CURR", TimeMS=1100, Volt=1640, Curr=294, Vcc=5000, CurrTot=66.5)
    orc = pymavlink_by_type(p)["CURR"][0]
    b = read_log(p)["battery"].iloc[0]
    assert (orc.Volt, orc.Curr) == (1640, 294)
    assert (b["voltage_V"], b["current_A"], b["consumed_Ah"], b["t_ns"]) == \
        (pytest.approx(16.40), pytest.approx(2.94), pytest.approx(0.0665), 100_000_000)
