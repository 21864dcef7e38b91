"""Simulated sensors against closed forms: IMU specific force, barometer error model, rangefinder
validity, GPS dropouts, RC mapping, schema conformance, seeding; summary accumulation."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.config import ConfigError
from pipeline.frames.geodesy import geodetic_to_ned
from pipeline.io import schema
from pipeline.simulate.datasets import SummaryAccumulator, summary_table
from pipeline.simulate.quadcopter import CommandSample, QuadParams, simulate
from pipeline.simulate.scenarios import SimSettings, run_named, time_grid
from pipeline.simulate.sensors import (
    SensorSettings, all_streams, dropout_mask, gps_stream, isa_pressure, truth_stream)


def _hover(duration=30.0, rate=200.0, alt=3.0, roll_deg=0.0):
    p = QuadParams()
    t = time_grid(duration, rate)
    e = np.zeros((len(t), 3))
    e[:, 0] = np.deg2rad(roll_deg)
    cmd = CommandSample(np.full(len(t), 1.0 / np.cos(e[0, 0])), e, np.zeros_like(e))
    tr = simulate(cmd, t, p, yaw0=np.array([0.7]), pos0=np.array([[10.0, -5.0, -alt]]),
                  vel0=np.zeros((1, 3)), label=np.full(len(t), "hover", dtype=object))
    return tr, p


def test_imu_at_hover_measures_minus_g_plus_bias(rng):
    tr, p = _hover()
    se = SensorSettings.from_config({})
    s = all_streams(tr, se, p, 200.0, rng)
    imu = s["imu"]
    acc = imu[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy()
    gyr = imu[["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].to_numpy()
    bias_a = np.array(se.imu["acc_bias_mps2"])
    np.testing.assert_allclose(acc.mean(0), [0, 0, -p.g_mps2] + bias_a, atol=4 * 0.03 / np.sqrt(len(acc)))
    np.testing.assert_allclose(acc.std(0), 0.03, rtol=0.1)
    np.testing.assert_allclose(gyr.mean(0), se.imu["gyro_bias_radps"], atol=4 * 0.002 / np.sqrt(len(gyr)))
    # banked, from rest: before drag builds up the specific force is the thrust alone, along
    # body -z with magnitude g/cos(roll); later it is thrust plus drag, R^T(-k v)
    tr2, _ = _hover(roll_deg=20.0)
    s2 = all_streams(tr2, SensorSettings.from_config({"sensors": {"imu": {"acc_sigma_mps2": 0.0,
                                                                          "acc_bias_mps2": [0, 0, 0]}}}),
                     p, 200.0, rng)
    a2 = s2["imu"][["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy()
    np.testing.assert_allclose(a2[0], [0, 0, -p.g_mps2 / np.cos(np.deg2rad(20))], atol=1e-9)
    from pipeline.frames.rotations import quat_rotate_inverse

    drag_b = quat_rotate_inverse(tr2.quat[0, -1], -p.k * tr2.vel[0, -1])
    np.testing.assert_allclose(a2[-1], drag_b + [0, 0, -p.g_mps2 / np.cos(np.deg2rad(20))], atol=1e-9)


def test_baro_offset_drift_noise(rng):
    tr, p = _hover(alt=3.0)
    se = SensorSettings.from_config({"sensors": {"baro": {"offset_m": 2.0, "drift_mps": 0.01, "sigma_m": 0.1}}})
    b = all_streams(tr, se, p, 200.0, rng)["baro"]
    t = b["t_ns"].to_numpy() * 1e-9
    err = b["alt_rel_m"].to_numpy() - 3.0
    slope, icpt = np.polyfit(t, err, 1)
    assert icpt == pytest.approx(2.0, abs=0.05) and slope == pytest.approx(0.01, abs=0.003)
    assert np.std(err - (icpt + slope * t)) == pytest.approx(0.1, rel=0.15)
    h = se.origin[2] - se.geoid_undulation_m + b["alt_rel_m"].to_numpy()
    np.testing.assert_allclose(b["press_Pa"], isa_pressure(h), rtol=1e-12)
    assert isa_pressure(0.0) == 101325.0 and isa_pressure(1000.0) == pytest.approx(89874.6, rel=1e-4)


def test_rangefinder_valid_range_and_tilt(rng):
    se = SensorSettings.from_config({"sensors": {"rangefinder": {"sigma_m": 0.0}}})
    for alt, ok in ((3.0, True), (8.0, False), (0.1, False)):
        tr, p = _hover(duration=2.0, alt=alt, roll_deg=10.0)
        rf = all_streams(tr, se, p, 200.0, rng)["rangefinder"]
        assert rf["valid"].all() == ok and (~rf["valid"]).all() == (not ok)
        if ok:
            np.testing.assert_allclose(rf["dist_m"], alt / np.cos(np.deg2rad(10.0)), rtol=1e-12)
        assert rf["dist_m"].max() <= 6.0 and (rf["orientation"] == 25).all()


@pytest.mark.parametrize("count,length", [(1, 2.0), (3, 1.5)])
def test_gps_dropouts_count_and_length(rng, count, length):
    t = time_grid(60.0, 10.0)
    keep = dropout_mask(t, count, length, rng)
    starts = np.flatnonzero(np.diff(keep.astype(int)) == -1)
    ends = np.flatnonzero(np.diff(keep.astype(int)) == 1)
    assert len(starts) == count and len(ends) == count
    lengths = (ends - starts) / 10.0
    np.testing.assert_allclose(lengths, length, atol=0.1 + 1e-9)
    tr, p = _hover(duration=60.0, rate=200.0)
    se = SensorSettings.from_config({"sensors": {"gps": {"dropout_count": count, "dropout_s": length}}})
    g = gps_stream(tr, se.gps, se.origin, se.geoid_undulation_m, 20, rng)
    gaps = np.diff(g["t_ns"].to_numpy()) * 1e-9
    big = gaps[gaps > 0.15]
    assert len(big) == count and np.allclose(big, length + 0.1, atol=0.1 + 1e-9)
    with pytest.raises(ConfigError, match="do not fit"):
        dropout_mask(time_grid(5.0, 10.0), 3, 2.0, rng)


def test_gps_position_on_origin(rng):
    tr, p = _hover(duration=5.0)
    se = SensorSettings.from_config({"sensors": {"gps": {"sigma_h_m": 0.0, "sigma_v_m": 0.0}}})
    g = gps_stream(tr, se.gps, se.origin, se.geoid_undulation_m, 20, rng)
    n, e, d = geodetic_to_ned(g["lat_deg"], g["lon_deg"], g["alt_wgs84_m"], *se.origin)
    np.testing.assert_allclose(np.c_[n, e, d], np.tile([10.0, -5.0, -3.0], (len(g), 1)), atol=1e-6)
    np.testing.assert_allclose(g["alt_msl_m"] - g["alt_wgs84_m"], -se.geoid_undulation_m)


def test_streams_conform_and_seeded():
    settings = SimSettings()
    tr = run_named("maneuver", settings, 1, 3, "M5")
    se = SensorSettings.from_config({})
    a = all_streams(tr, se, settings.vehicle, settings.rate_hz, np.random.default_rng(1))
    b = all_streams(tr, se, settings.vehicle, settings.rate_hz, np.random.default_rng(1))
    c = all_streams(tr, se, settings.vehicle, settings.rate_hz, np.random.default_rng(2))
    for name, df in a.items():
        conf = schema.conform(name, df)
        assert len(conf) == len(df) and conf["t_ns"].iloc[0] == 0, name
        pd.testing.assert_frame_equal(df, b[name])
    assert not a["imu"].equals(c["imu"])
    # RC sticks follow the commands: roll stick = roll command / 50 deg on 1100-1900 us
    ctl = a["control"]
    k = np.round(ctl["t_ns"].to_numpy() * 1e-9 * settings.rate_hz).astype(int)
    roll_cmd = np.rad2deg(tr.cmd.euler[k, 0])
    np.testing.assert_allclose(ctl["rc_1_us"], np.round(1500 + 400 * roll_cmd / 50.0))
    assert ctl[[f"servo_{i}_us" for i in range(1, 5)]].to_numpy().min() >= 1100
    t = truth_stream(tr)
    assert len(schema.conform("truth", t)) == len(tr.t_s)


def test_summary_accumulates_in_chunks():
    settings = SimSettings()
    tr = run_named("maneuver", settings, 4, 9, "M2")
    acc = SummaryAccumulator()
    for i in range(4):
        acc.add("M2", tr.run(i))
    a, b = acc.table(), summary_table({"M2": [tr]})
    pd.testing.assert_frame_equal(a[["min", "max", "n_runs"]], b[["min", "max", "n_runs"]])
    np.testing.assert_allclose(a["rms"], b["rms"], rtol=1e-12)
    row = b[(b.quantity == "acc") & (b.axis == "norm")].iloc[0]
    ref = np.linalg.norm(tr.acc, axis=-1)
    assert row["max"] == ref.max() and row["rms"] == pytest.approx(np.sqrt(np.mean(ref ** 2)), rel=1e-12)
