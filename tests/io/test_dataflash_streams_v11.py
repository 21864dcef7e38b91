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
    first_sensor = min(int(log[s]["t_ns"].min()) for s in ("imu", "gps", "attitude") if len(log[s]))
    assert first_sensor >= 0
    assert int(log["params"]["t_ns"].min()) < 0  # the parameter dump precedes the sensors
