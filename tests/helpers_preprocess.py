"""Synthetic flights shared by the preprocessing tests."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.frames.geodesy import ned_to_geodetic
from pipeline.frames.rotations import euler_to_quat
from pipeline.io.base import FlightLog


def ns(t):
    return np.round(np.asarray(t) * 1e9).astype(np.int64)


def synthetic_flight(rng, gap=True):
    """A circle at 20 m radius, 0.5 rad/s, as GPS (5 Hz), attitude (20 Hz), IMU (50 Hz), RC."""
    tg = np.arange(0, 60, 0.2)
    if gap:
        tg = tg[(tg < 30) | (tg > 34)]  # a 4 s GPS dropout
    w = 0.5
    n, e = 20 * np.cos(w * tg), 20 * np.sin(w * tg)
    lat0, lon0, h0 = 46.5, 6.6, 500.0
    lat, lon, h = ned_to_geodetic(n, e, -10 + 0 * tg, lat0, lon0, h0)
    gps = pd.DataFrame({"t_ns": ns(tg), "lat_deg": lat, "lon_deg": lon, "alt_wgs84_m": h, "fix_type": 3.0,
                        "vel_n_mps": -20 * w * np.sin(w * tg), "vel_e_mps": 20 * w * np.cos(w * tg), "vel_d_mps": 0.0})
    ta = np.arange(0, 60, 0.05)
    q = euler_to_quat(0.2 + 0 * ta, 0 * ta, w * ta + np.pi / 2)
    att = pd.DataFrame({"t_ns": ns(ta), **dict(zip(["q_w", "q_x", "q_y", "q_z"], q.T))})
    ti = np.arange(0, 60, 0.02)
    imu = pd.DataFrame({"t_ns": ns(ti), "gyr_x_radps": 0.0, "gyr_y_radps": w * np.sin(0.2),
                        "gyr_z_radps": w * np.cos(0.2), "acc_z_mps2": -9.81})
    tc = np.arange(0, 60, 0.1)
    ctrl = pd.DataFrame({"t_ns": ns(tc), "rc_1_us": 1500 + 400 * np.sin(tc), "rc_3_us": 1500.0})
    mode = pd.DataFrame({"t_ns": ns([0.0, 20.0]), "mode": ["STABILIZE", "LOITER"]})
    meta = {"flight_id": "synthetic", "ned_origin": {"lat_deg": lat0, "lon_deg": lon0, "alt_wgs84_m": h0}}
    return FlightLog.from_streams(meta, {"gps": gps, "attitude": att, "imu": imu, "control": ctrl, "mode": mode}), w
