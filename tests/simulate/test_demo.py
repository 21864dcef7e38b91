"""The demo flight: a small, physically consistent DataFlash log from an analytic trajectory,
read back by our ingest and by pymavlink; same seed -> same bytes."""

from __future__ import annotations

import hashlib
import io

import numpy as np
import pytest

from helpers import pymavlink_by_type
from pipeline.frames.geodesy import geodetic_to_ned
from pipeline.io import dataflash as df
from pipeline.io.registry import read_log
from pipeline.simulate.demo import demo_trajectory, write_demo_flight


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
    pm = pymavlink_by_type(p)
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
