"""The tiny demo flight of the default dataset: a smooth analytic quadcopter trajectory written
as a < 1 MB DataFlash log.

:func:`demo_trajectory` is the path (take-off, one circle, landing; continuous acceleration);
:func:`write_demo_flight` turns it into physically consistent sensor records (IMU from the
attitude's finite rotations, baro, magnetometer, GPS from the exact WGS-84 conversion about
:data:`DEMO_ORIGIN`, RC, rangefinder, EKF) with seeded noise and writes them through
:class:`pipeline.io.dataflash.writer.DataFlashWriter` in the catalogue's ``demo`` layout
(:mod:`pipeline.io.dataflash.catalogue`). Same seed, same bytes.
"""

from __future__ import annotations

import os
from typing import BinaryIO

import numpy as np

from ..frames.geodesy import ned_to_geodetic
from ..frames.rotations import dcm_to_euler, dcm_to_quat, quat_conj, quat_multiply
from ..io.dataflash.writer import DataFlashWriter

G = 9.80665
#: demo origin: a field near Austin, TX (where the real copter logs were flown)
DEMO_ORIGIN = (30.1557, -97.9575, 270.0)


def _smoothstep(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic 0→1 step s(x) = 10x³ − 15x⁴ + 6x⁵ and its first two derivatives (x clipped)."""
    x = np.clip(x, 0.0, 1.0)
    s = x ** 3 * (10 - 15 * x + 6 * x * x)
    ds = 30 * x * x * (1 - x) ** 2
    dds = 60 * x * (1 - x) * (1 - 2 * x)
    return s, ds, dds


def demo_trajectory(t: np.ndarray, duration_s: float = 60.0, *, alt_m: float = 20.0,
                    radius_m: float = 25.0) -> dict[str, np.ndarray]:
    """Smooth analytic quadcopter path in NED about the home point.

    Take-off to ``alt_m`` over the first 15 % of the flight, a circle of ``radius_m`` entered
    and left with a smooth angular-rate ramp in the middle 65 %, landing in the last 20 %:

    .. math::

        p(t) = r\\,(\\cos\\theta(t) - 1,\\; \\sin\\theta(t),\\; 0) + (0, 0, -h\\,s_{up}(t) + h\\,s_{dn}(t))

    with quintic steps ``s`` (continuous acceleration). Returns position, velocity and
    acceleration (NED, m, m/s, m/s²) and the heading (rad; the nose turns with θ).
    """
    t = np.asarray(t, dtype=np.float64)
    T = float(duration_s)
    t_up, t_c0, t_c1, t_dn = 0.15 * T, 0.18 * T, 0.78 * T, 0.80 * T
    su, dsu, ddsu = _smoothstep((t - 0.02 * T) / (t_up - 0.02 * T))
    sd, dsd, ddsd = _smoothstep((t - t_dn) / (0.97 * T - t_dn))
    k_up, k_dn = 1 / (t_up - 0.02 * T), 1 / (0.97 * T - t_dn)
    d = -alt_m * su + alt_m * sd
    vd = -alt_m * dsu * k_up + alt_m * dsd * k_dn
    ad = -alt_m * ddsu * k_up ** 2 + alt_m * ddsd * k_dn ** 2
    # angle θ(t): integral of a smooth rate ramp, one full turn between t_c0 and t_c1
    sc, dsc, ddsc = _smoothstep((t - t_c0) / (t_c1 - t_c0))
    kc = 1 / (t_c1 - t_c0)
    th = 2 * np.pi * sc
    w = 2 * np.pi * dsc * kc
    wd = 2 * np.pi * ddsc * kc * kc
    c, s = np.cos(th), np.sin(th)
    n = radius_m * (c - 1)
    e = radius_m * s
    vn, ve = -radius_m * s * w, radius_m * c * w
    an = -radius_m * (c * w * w + s * wd)
    ae = radius_m * (-s * w * w + c * wd)
    # the nose turns with the circle angle (smooth, one full turn): yaw = θ
    return {"pos": np.stack([n, e, d], -1), "vel": np.stack([vn, ve, vd], -1),
            "acc": np.stack([an, ae, ad], -1), "yaw": th}


def _attitude(acc_ned: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Body->NED rotation of a multirotor: thrust axis (−z body) along a − g, heading ``yaw``."""
    f = acc_ned - np.array([0.0, 0.0, G])  # specific force, NED
    zb = -f / np.linalg.norm(f, axis=-1, keepdims=True)
    xc = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], -1)
    yb = np.cross(zb, xc)
    yb /= np.linalg.norm(yb, axis=-1, keepdims=True)
    xb = np.cross(yb, zb)
    return np.stack([xb, yb, zb], axis=-1)  # columns are body axes in NED


def write_demo_flight(path: str | os.PathLike | BinaryIO, *, seed: int = 0,
                      duration_s: float = 60.0) -> dict:
    """Write a tiny, physically consistent quadcopter DataFlash log (< 1 MB).

    Take-off to 20 m, one 25 m circle, landing, from :func:`demo_trajectory`. Rates: IMU 50 Hz,
    GPS 5 Hz, ATT/BARO/MAG/RCIN/RCOU/RFND/XKF1 10 Hz; MODE changes (STABILIZE → LOITER →
    CIRCLE → LAND), EV arm/disarm, PARM, MSG and ORGN records; modern format with
    FMTU/UNIT/MULT. The geoid is taken as the ellipsoid (GPS ``Alt`` = WGS-84 height), and
    latitude/longitude come from the exact WGS-84 NED->geodetic conversion
    (:func:`pipeline.frames.geodesy.ned_to_geodetic`) about :data:`DEMO_ORIGIN`.

    Sensor noise (seeded through ``np.random.default_rng(seed)``): gyro 0.005 rad/s, accel
    0.05 m/s², baro 0.1 m, GPS 0.3 m horizontal, mag 2 mGauss.

    Returns
    -------
    dict
        Summary: ``duration_s``, ``records`` (per type), ``origin`` and ``seed``.
    """
    rng = np.random.default_rng(seed)
    T = float(duration_s)
    boot_us = 2_000_000  # log starts 2 s after boot, like a real vehicle
    lat0, lon0, h0 = DEMO_ORIGIN

    def grid(rate):
        t = np.arange(0.0, T, 1.0 / rate)
        return t, (boot_us + np.rint(t * 1e6)).astype(np.uint64)

    counts: dict[str, int] = {}
    with DataFlashWriter(path) as w:
        w.define_layout("demo")

        params = {"INS_ACCEL_FILTER": 20.0, "INS_GYRO_FILTER": 20.0, "RNGFND1_MIN_CM": 20.0,
                  "RNGFND1_MAX_CM": 700.0, "RNGFND1_ORIENT": 25.0, "FRAME_CLASS": 1.0,
                  "DEMO_SEED": float(seed)}
        w.write_params(params, time_us=boot_us)
        w.write("MSG", TimeUS=boot_us, Message="ArduCopter V4.5.0 (uavpipe demo flight)")
        w.write("MSG", TimeUS=boot_us, Message="Frame: QUAD/X")
        w.write("ORGN", TimeUS=boot_us, Type=0, Lat=lat0, Lng=lon0, Alt=h0)
        counts["PARM"] = len(params)
        counts["MSG"] = 2
        counts["ORGN"] = 1

        # IMU from the exact trajectory; gyro from the attitude's finite rotation per step
        t_i, us_i = grid(50)
        tr = demo_trajectory(t_i, T)
        R = _attitude(tr["acc"], tr["yaw"])
        q = dcm_to_quat(R)
        dq = quat_multiply(quat_conj(q[:-1]), q[1:])
        dq *= np.sign(dq[:, :1] + (dq[:, :1] == 0))
        omega = 2 * dq[:, 1:] * 50.0
        omega = np.vstack([omega, omega[-1:]])
        f_body = np.einsum("nji,nj->ni", R, tr["acc"] - np.array([0.0, 0.0, G]))
        gyr = omega + rng.normal(0, 0.005, omega.shape)
        acc = f_body + rng.normal(0, 0.05, f_body.shape)
        imu = {"TimeUS": us_i, "GyrX": gyr[:, 0], "GyrY": gyr[:, 1], "GyrZ": gyr[:, 2],
               "AccX": acc[:, 0], "AccY": acc[:, 1], "AccZ": acc[:, 2]}

        # 10 Hz streams
        t10, us10 = grid(10)
        tr10 = demo_trajectory(t10, T)
        R10 = _attitude(tr10["acc"], tr10["yaw"])
        roll, pitch, yaw = dcm_to_euler(R10)
        roll_d, pitch_d = np.rad2deg(roll), np.rad2deg(pitch)
        yaw_d = np.mod(np.rad2deg(yaw), 360.0)
        att = {"TimeUS": us10, "DesRoll": roll_d, "Roll": roll_d, "DesPitch": pitch_d,
               "Pitch": pitch_d, "DesYaw": yaw_d, "Yaw": yaw_d}
        alt = -tr10["pos"][:, 2]
        press = 101325.0 * (1 - 2.25577e-5 * (h0 + alt)) ** 5.25588
        baro = {"TimeUS": us10, "Alt": alt + rng.normal(0, 0.1, len(alt)), "Press": press,
                "Temp": np.full(len(alt), 31.5), "Health": np.ones(len(alt), np.uint8)}
        b_ned = np.array([280.0, 45.0, 430.0])  # mGauss, mid-latitude field
        m_body = np.einsum("nji,j->ni", R10, b_ned) + rng.normal(0, 2.0, (len(t10), 3))
        mag = {"TimeUS": us10, "MagX": np.rint(m_body[:, 0]), "MagY": np.rint(m_body[:, 1]),
               "MagZ": np.rint(m_body[:, 2])}
        thr = np.clip(1100 + 400 * np.linalg.norm(tr10["acc"] - [0, 0, G], axis=1) / G, 1000, 2000)
        armed = (t10 >= 0.01 * T) & (t10 < 0.985 * T)
        thr = np.where(armed, thr, 1000.0)
        rc = {"TimeUS": us10, "C1": np.rint(1500 + 500 * roll_d / 45).astype(np.uint16),
              "C2": np.rint(1500 - 500 * pitch_d / 45).astype(np.uint16),
              "C3": np.rint(thr).astype(np.uint16), "C4": np.full(len(t10), 1500, np.uint16)}
        for k in range(5, 9):
            rc[f"C{k}"] = np.full(len(t10), 1500 if k != 5 else 1165, np.uint16)
        mot = np.rint(np.clip(thr[:, None] + np.array([1, -1, 1, -1]) * 20 * roll_d[:, None] / 45, 1000, 2000))
        rcou = {"TimeUS": us10, **{f"C{k + 1}": mot[:, k].astype(np.uint16) for k in range(4)},
                **{f"C{k}": np.zeros(len(t10), np.uint16) for k in range(5, 9)}}
        agl = alt + 0.1  # sensor 10 cm above the skids
        rng_ok = (agl >= 0.2) & (agl <= 7.0)
        rfnd = {"TimeUS": us10, "Instance": np.zeros(len(t10), np.uint8),
                "Dist": np.where(rng_ok, agl + rng.normal(0, 0.02, len(agl)), np.where(agl < 0.2, 0.0, 7.0)),
                "Stat": np.where(rng_ok, 4, np.where(agl < 0.2, 2, 3)).astype(np.uint8),
                "Orient": np.full(len(t10), 25, np.uint8)}
        xkf = {"TimeUS": us10, "C": np.zeros(len(t10), np.uint8), "Roll": roll_d, "Pitch": pitch_d,
               "Yaw": yaw_d, "VN": tr10["vel"][:, 0], "VE": tr10["vel"][:, 1], "VD": tr10["vel"][:, 2],
               "PN": tr10["pos"][:, 0], "PE": tr10["pos"][:, 1], "PD": tr10["pos"][:, 2]}

        # GPS 5 Hz
        t5, us5 = grid(5)
        tr5 = demo_trajectory(t5, T)
        pn = tr5["pos"] + np.column_stack([rng.normal(0, 0.3, (len(t5), 2)), rng.normal(0, 0.5, len(t5))])
        lat, lon, h = ned_to_geodetic(pn[:, 0], pn[:, 1], pn[:, 2], lat0, lon0, h0)
        vn, ve, vd = tr5["vel"].T
        gps_week, gms0 = 2345, 302_400_000
        gps = {"TimeUS": us5, "Status": np.full(len(t5), 3, np.uint8),
               "GMS": (gms0 + np.rint(t5 * 1000)).astype(np.uint32),
               "GWk": np.full(len(t5), gps_week, np.uint16), "NSats": np.full(len(t5), 14, np.uint8),
               "HDop": np.full(len(t5), 0.7), "Lat": lat, "Lng": lon, "Alt": h,
               "Spd": np.hypot(vn, ve), "GCrs": np.mod(np.rad2deg(np.arctan2(ve, vn)), 360.0),
               "VZ": vd, "U": np.ones(len(t5), np.uint8)}

        # modes and arming
        mode_t = np.array([0.0, 0.16 * T, 0.18 * T, 0.80 * T])
        mode_n = np.array([0, 5, 7, 9])
        mode = {"TimeUS": (boot_us + np.rint(mode_t * 1e6)).astype(np.uint64), "Mode": mode_n.astype(np.int8),
                "ModeNum": mode_n.astype(np.uint8), "Rsn": np.ones(4, np.uint8)}
        ev = {"TimeUS": (boot_us + np.rint(np.array([0.01, 0.985]) * T * 1e6)).astype(np.uint64),
              "Id": np.array([10, 11], np.uint8)}
        batches = {"MODE": mode, "EV": ev, "IMU": imu, "ATT": att, "BARO": baro, "MAG": mag,
                   "RCIN": rc, "RCOU": rcou, "RFND": rfnd, "XKF1": xkf, "GPS": gps}
        w.write_merged(batches)
        counts.update({k: len(v["TimeUS"]) for k, v in batches.items()})
    return {"duration_s": T, "records": counts, "origin": {"lat_deg": lat0, "lon_deg": lon0,
                                                          "alt_wgs84_m": h0}, "seed": seed}
