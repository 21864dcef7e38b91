"""DataFlash writer: round trips through our decoder AND pymavlink, determinism, the demo flight."""

from __future__ import annotations

import hashlib
import io
from collections import defaultdict

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from pipeline.frames.geodesy import geodetic_to_ned
from pipeline.io import dataflash as df
from pipeline.io.dataflash_writer import DataFlashWriter, demo_trajectory, write_demo_flight
from pipeline.io.registry import read_log


def pymavlink_messages(path) -> dict[str, list]:
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(str(path))
    out = defaultdict(list)
    while (x := m.recv_msg()) is not None:
        out[x.get_type()].append(x)
    m.close()
    return out


ALL_CHARS = "bBhHiIfdnNZcCeELMqQ"


def test_every_format_char_roundtrips_through_both_readers(tmp_path):
    p = tmp_path / "all.bin"
    labels = [f"F{c}" if c.islower() else f"U{c}" for c in ALL_CHARS]
    n = 7
    vals = {
        "Fb": np.arange(-3, 4, dtype=np.int8), "UB": np.arange(250, 257) % 256,
        "Fh": np.array([-32768, -1, 0, 1, 2, 3, 32767]), "UH": np.arange(n) * 9000,
        "Fi": np.arange(n) * -300_000_001 // 1, "UI": np.arange(n, dtype=np.uint64) * 600_000_001,
        "Ff": np.linspace(-1, 1, n).astype(np.float32), "Fd": np.linspace(-1e10, 1e10, n) / 3,
        "Fn": ["ab", "", "xyzw", "a", "b", "c", "d"], "UN": [f"NAME_{i}" for i in range(n)],
        "UZ": ["hello world, this is a longer text message " + str(i) for i in range(n)],
        "Fc": np.arange(n) * 1.23 - 4, "UC": np.arange(n) * 100.25, "Fe": np.arange(n) * -1e5 + 0.07,
        "UE": np.arange(n) * 1e6 + 0.01, "UL": np.linspace(-89.9999999, 179.9999999, n),
        "UM": np.arange(n, dtype=np.int8), "Fq": -(2 ** np.arange(50, 57, dtype=np.int64)),
        "UQ": np.arange(n, dtype=np.uint64) * np.uint64(2 ** 61),
    }
    fmt = "".join(ALL_CHARS)
    assert len(fmt) > 16  # split across two messages (16 fields at most per FMT)
    with DataFlashWriter(p) as w:
        w.define("ALL1", 10, fmt[:10], labels[:10])
        w.define("ALL2", 11, fmt[10:], labels[10:])
        w.write_many("ALL1", {k: vals[k] for k in labels[:10]})
        w.write_many("ALL2", {k: vals[k] for k in labels[10:]})
    res = df.decode(p)
    pm = pymavlink_messages(p)
    assert res.diagnostics["record_counts"] == {k: len(v) for k, v in pm.items()} == {
        "FMT": 3, "ALL1": n, "ALL2": n}
    for name in ("ALL1", "ALL2"):
        for col in res.formats[name].columns:
            theirs = [getattr(x, col) for x in pm[name]]
            ours = res.tables[name][col]
            assert ours.tolist() == theirs, col
    # physical values come back (scaled formats to their resolution)
    t = res.tables
    np.testing.assert_allclose(t["ALL2"]["UL"], vals["UL"], atol=0.6e-7)
    np.testing.assert_allclose(t["ALL2"]["Fc"], vals["Fc"], atol=0.005)
    assert t["ALL1"]["UN"].tolist() == vals["UN"] and t["ALL1"]["Fn"].tolist() == vals["Fn"]
    assert t["ALL2"]["UQ"].tolist() == vals["UQ"].tolist()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_hypothesis_roundtrip_random_formats(data):
    """Random formats and values: write_many -> decode gives the values back; pymavlink agrees."""
    fmt = data.draw(st.text(alphabet="bBhHiIfdNcCLMQ", min_size=1, max_size=8), label="fmt")
    n = data.draw(st.integers(1, 20), label="n")
    labels = [f"V{i}" for i in range(len(fmt))]
    cols = {}
    for c, lab in zip(fmt, labels):
        if c == "N":
            cols[lab] = data.draw(st.lists(st.text(alphabet="abcXYZ_09", max_size=16), min_size=n, max_size=n))
        elif c in "fd":
            cols[lab] = np.array(data.draw(st.lists(st.floats(-1e6, 1e6, width=32), min_size=n, max_size=n)))
        else:
            kind = np.dtype(df.FORMAT_CHARS[c][0])
            info = np.iinfo(kind)
            raw = data.draw(st.lists(st.integers(int(info.min), int(info.max)), min_size=n, max_size=n))
            raw = np.array(raw, dtype=kind)
            div = df.FORMAT_CHARS[c][1]
            cols[lab] = raw / div if div else raw
    buf = io.BytesIO()
    with DataFlashWriter(buf) as w:
        w.define("RND", 42, fmt, labels)
        w.write_many("RND", cols)
    res = df.decode(buf.getvalue())
    assert res.diagnostics["record_counts"]["RND"] == n and res.diagnostics["bytes_skipped"] == 0
    for c, lab in zip(fmt, labels):
        got = res.tables["RND"][lab]
        if c == "N":
            assert got.tolist() == cols[lab]
        else:
            assert np.array_equal(got, np.asarray(cols[lab]).astype(got.dtype)), (c, lab)


def test_define_validates(tmp_path):
    with DataFlashWriter(io.BytesIO()) as w:
        w.define("AAA", 5, "Qf", "TimeUS,X")
        with pytest.raises(ValueError, match="already used"):
            w.define("BBB", 5, "Qf", "TimeUS,X")
        with pytest.raises(ValueError, match="labels"):
            w.define("CCC", 6, "Qf", "TimeUS")
        with pytest.raises(ValueError, match="bad format"):
            w.define("DDD", 7, "Qx", "TimeUS,X")
        with pytest.raises(ValueError, match="1-4"):
            w.define("TOOLONG", 8, "Q", "TimeUS")
        with pytest.raises(KeyError, match="no field"):
            w.write("AAA", TimeUS=1, Y=2)
        with pytest.raises(ValueError, match="different lengths"):
            w.write_many("AAA", {"TimeUS": [1, 2], "X": [1.0, 2.0, 3.0]})


def test_write_merged_interleaves_by_time():
    buf = io.BytesIO()
    with DataFlashWriter(buf) as w:
        w.define("AA", 1, "Qh", "TimeUS,V")
        w.define("BB", 2, "Qf", "TimeUS,W")
        w.write_merged({"AA": {"TimeUS": [10, 30, 50], "V": [1, 3, 5]},
                        "BB": {"TimeUS": [20, 30, 40], "W": [2.0, 3.5, 4.0]}})
    res = df.decode(buf.getvalue())
    order = np.argsort(np.concatenate([res.offsets["AA"], res.offsets["BB"]]))
    t = np.concatenate([res.tables["AA"]["TimeUS"], res.tables["BB"]["TimeUS"]])[order]
    assert t.tolist() == [10, 20, 30, 30, 40, 50]
    assert res.offsets["AA"][1] < res.offsets["BB"][1]  # tie at 30: batch order kept


def test_same_seed_same_bytes_and_seed_matters(tmp_path):
    a, b, c = tmp_path / "a.bin", tmp_path / "b.bin", tmp_path / "c.bin"
    write_demo_flight(a, seed=3, duration_s=10.0)
    write_demo_flight(b, seed=3, duration_s=10.0)
    write_demo_flight(c, seed=4, duration_s=10.0)
    h = [hashlib.sha256(p.read_bytes()).hexdigest() for p in (a, b, c)]
    assert h[0] == h[1] != h[2]
    buf = io.BytesIO()
    write_demo_flight(buf, seed=3, duration_s=10.0)
    assert buf.getvalue() == a.read_bytes()


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    p = tmp_path_factory.mktemp("demo") / "demo.bin"
    info = write_demo_flight(p, seed=0)
    return p, info, read_log(p)


def test_demo_flight_is_small_and_both_readers_agree(demo):
    p, info, log = demo
    assert p.stat().st_size < 1_000_000
    pm = pymavlink_messages(p)
    counts = {k: len(v) for k, v in pm.items()}
    assert log.meta["diagnostics"]["record_counts"] == counts
    for k, n in info["records"].items():
        assert counts[k] == n
    assert counts["IMU"] == 3000 and counts["GPS"] == 300 and counts["ATT"] == 600
    res = df.decode(p)
    for name in ("GPS", "IMU", "ATT", "BARO", "MODE", "PARM"):
        for col in res.formats[name].columns:
            assert res.tables[name][col].tolist() == [getattr(x, col) for x in pm[name]], (name, col)
    assert log.meta["status"] == "ok" and log.meta["diagnostics"]["bytes_skipped"] == 0
    for s in ("imu", "gps", "baro", "mag", "attitude", "local_position", "rangefinder", "control", "mode"):
        assert len(log[s]), s
    assert log["mode"]["mode"].dropna().unique().tolist() == ["STABILIZE", "LOITER", "CIRCLE", "LAND"]
    assert log["mode"]["armed"].tolist()[-1] is False


def test_demo_flight_is_physically_consistent(demo):
    p, info, log = demo
    o = info["origin"]
    # GPS positions back in NED agree with the EKF track (0.3 m horizontal GPS noise)
    g = log["gps"]
    n, e, d = geodetic_to_ned(g["lat_deg"], g["lon_deg"], g["alt_msl_m"], o["lat_deg"], o["lon_deg"],
                              o["alt_wgs84_m"])
    lp = log["local_position"].set_index("t_ns")
    ref = lp.loc[g["t_ns"]]
    assert np.sqrt(np.mean((n - ref["pos_n_m"].to_numpy()) ** 2)) < 0.6
    assert np.sqrt(np.mean((e - ref["pos_e_m"].to_numpy()) ** 2)) < 0.6
    assert lp["pos_d_m"].min() == pytest.approx(-20.0, abs=0.01)
    # GPS velocity is the analytic derivative of the path
    tr = demo_trajectory(g["t_ns"].to_numpy() * 1e-9, info["duration_s"])
    np.testing.assert_allclose(g["vel_n_mps"], tr["vel"][:, 0], atol=0.01)
    np.testing.assert_allclose(g["vel_d_mps"], tr["vel"][:, 2], atol=1e-6)
    # accelerometer = R^T (a - g): rotate by the logged attitude back to NED and compare
    imu = log["imu"]
    att = log["attitude"].set_index("t_ns")
    at = imu[imu["t_ns"].isin(att.index)]
    q = att.loc[at["t_ns"], ["q_w", "q_x", "q_y", "q_z"]].to_numpy()
    from pipeline.frames.rotations import quat_rotate

    f_ned = quat_rotate(q, at[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy())
    tr_i = demo_trajectory(at["t_ns"].to_numpy() * 1e-9, info["duration_s"])
    expect = tr_i["acc"] - np.array([0, 0, 9.80665])
    assert np.sqrt(np.mean((f_ned - expect) ** 2)) < 0.1  # 0.05 m/s² noise + 0.01° attitude quantisation
    # gyro -> Euler yaw rate ψ' = (q sinφ + r cosφ)/cosθ integrates to one full turn
    # (the nose follows the circle); roll/pitch from the logged attitude, held between samples
    from pipeline.frames.rotations import quat_to_euler

    roll, pitch, _ = quat_to_euler(log["attitude"][["q_w", "q_x", "q_y", "q_z"]].to_numpy())
    k = np.minimum(np.searchsorted(log["attitude"]["t_ns"].to_numpy(), imu["t_ns"].to_numpy()),
                   len(roll) - 1)
    psi_dot = (imu["gyr_y_radps"] * np.sin(roll[k]) + imu["gyr_z_radps"] * np.cos(roll[k])) / np.cos(pitch[k])
    assert np.sum(psi_dot) / 50.0 == pytest.approx(2 * np.pi, abs=0.03)
    # barometric altitude follows the height (0.1 m noise)
    b = log["baro"].set_index("t_ns")
    assert np.sqrt(np.mean((b["alt_rel_m"] + lp.loc[b.index, "pos_d_m"]) ** 2)) < 0.2
    # the rangefinder is valid only within its 0.2-7 m range, near the ground
    rf = log["rangefinder"]
    v = rf[rf["valid"].astype(bool)]
    assert 0 < len(v) < len(rf) and v["dist_m"].between(0.15, 7.1).all()
    # mag magnitude = the field used, in tesla
    m = np.linalg.norm(log["mag"][["mag_x_T", "mag_y_T", "mag_z_T"]].to_numpy(), axis=1)
    assert np.median(m) == pytest.approx(np.linalg.norm([280.0, 45.0, 430.0]) * 1e-7, rel=0.01)
    # UTC of the demo: GPS week 2345, TOW 302400 s at t = 0 (18 leap seconds)
    utc = 315964800 + 604800 * 2345 + 302400 - 18
    assert log.meta["t0_utc_ns"] == utc * 1_000_000_000
    assert log.meta["ned_origin"]["source"] == "ORGN"
