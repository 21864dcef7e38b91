"""Canonical streams written as a MAVLink telemetry log (``.tlog``).

pymavlink's ``ardupilotmega`` v2 encoder; framing: big-endian µs UNIX time + frame.
``HEARTBEAT`` 1 Hz, ``SYSTEM_TIME`` 1 Hz, ``ATTITUDE``, ``GPS_RAW_INT``, ``SCALED_IMU`` (mG,
mrad/s), ``SCALED_PRESSURE`` (hPa, cdegC), ``RC_CHANNELS``, ``SERVO_OUTPUT_RAW``,
``DISTANCE_SENSOR`` (cm), ``GPS_GLOBAL_ORIGIN`` once when the origin is given. No radar:
MAVLink has no such message. Frames are sorted stably by time, so the output is a pure function
of the streams (same streams, same bytes).

(:func:`pipeline.io.tlog.write_tlog` is the lower-level writer of hand-built message lists used
by the reader tests.)
"""

from __future__ import annotations

import os
import struct
from typing import TYPE_CHECKING, Mapping

import numpy as np

from ..frames.rotations import quat_to_euler

if TYPE_CHECKING:  # annotations only
    import pandas as pd


def _us(t_ns) -> np.ndarray:
    return (np.asarray(t_ns, np.int64) // 1000).astype(np.int64)


def write_tlog_streams(path: str | os.PathLike, streams: Mapping[str, pd.DataFrame], *, t0_utc_ns: int,
                       duration_s: float, boot_us: int,
                       origin: tuple[float, float, float] | None = None,
                       undulation_m: float = 0.0,
                       range_limits_m: tuple[float, float] = (0.17, 6.0)) -> str | os.PathLike:
    """Write canonical streams as a MAVLink telemetry log (see the module docstring).

    Parameters
    ----------
    path : path-like
        Output ``.tlog`` (created/truncated).
    streams : mapping of str to DataFrame
        Canonical ``attitude``, ``gps``, ``imu``, ``baro``, ``control`` and ``rangefinder``
        streams (``t_ns`` since the flight's t = 0).
    t0_utc_ns : int
        UTC of ``t_ns = 0``: the frames' UNIX time stamps and ``SYSTEM_TIME.time_unix_usec``.
    duration_s : float
        ``HEARTBEAT``/``SYSTEM_TIME`` are written at 1 Hz for ``t = 0 .. floor(duration_s)``.
    boot_us : int
        Vehicle boot time at ``t_ns = 0`` (``time_boot_ms`` fields = (boot_us + t) / 1000).
    origin : (lat_deg, lon_deg, alt_wgs84_m), optional
        The EKF origin, sent once at t = 0 as ``GPS_GLOBAL_ORIGIN`` (altitude MSL =
        ``alt_wgs84_m - undulation_m``), as ArduPilot does once its origin is set: the reader
        then puts NED about it, as it does the DataFlash log's ``ORGN``.
    undulation_m : float
        Geoid undulation (WGS-84 minus MSL) at the origin.
    range_limits_m : (float, float)
        The rangefinder's limits, written as ``DISTANCE_SENSOR`` min/max distance (the reader
        judges validity by them); an invalid reading is written 1 cm past the maximum.

    Returns
    -------
    path-like
        ``path``.
    """
    from pymavlink.dialects.v20 import ardupilotmega as mav

    link = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    recs: list[tuple[int, int, bytes]] = []  # (t_us, order, frame)
    order = 0
    t0_us = t0_utc_ns // 1000

    def add(t_us: int, msg) -> None:
        nonlocal order
        recs.append((int(t_us), order, msg))
        order += 1

    for k in range(int(duration_s) + 1):
        tu = k * 1_000_000
        add(tu, link.heartbeat_encode(mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                      mav.MAV_MODE_FLAG_SAFETY_ARMED | mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                      0, mav.MAV_STATE_ACTIVE))
        add(tu, link.system_time_encode(t0_us + tu, (boot_us + tu) // 1000))
    if origin is not None:
        add(0, link.gps_global_origin_encode(int(np.rint(origin[0] * 1e7)), int(np.rint(origin[1] * 1e7)),
                                             int(np.rint((origin[2] - undulation_m) * 1000)), boot_us))
    a = streams["attitude"]
    r, p, y = quat_to_euler(a[["q_w", "q_x", "q_y", "q_z"]].to_numpy())
    for tu, rr, pp, yy in zip(_us(a["t_ns"]), r, p, y):
        add(tu, link.attitude_encode((boot_us + tu) // 1000, rr, pp, yy, 0.0, 0.0, 0.0))
    g = streams["gps"]
    vn, ve = g["vel_n_mps"].to_numpy(), g["vel_e_mps"].to_numpy()
    cog = np.rint(np.mod(np.rad2deg(np.arctan2(ve, vn)), 360.0) * 100).astype(int) % 36000
    for k, tu in enumerate(_us(g["t_ns"])):
        add(tu, link.gps_raw_int_encode(
            boot_us + tu, int(g["fix_type"].iat[k]), int(np.rint(g["lat_deg"].iat[k] * 1e7)),
            int(np.rint(g["lon_deg"].iat[k] * 1e7)), int(np.rint(g["alt_msl_m"].iat[k] * 1000)),
            80, 120, int(np.rint(np.hypot(vn[k], ve[k]) * 100)), int(cog[k]), int(g["n_sats"].iat[k]),
            alt_ellipsoid=int(np.rint(g["alt_wgs84_m"].iat[k] * 1000)),
            h_acc=int(np.rint(g["hacc_m"].iat[k] * 1000)), v_acc=int(np.rint(g["vacc_m"].iat[k] * 1000)),
            vel_acc=50, hdg_acc=0, yaw=0))
    i = streams["imu"]
    G0 = 9.80665
    acc = np.rint(i[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy() / (G0 * 1e-3)).astype(int)
    gyr = np.rint(i[["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].to_numpy() * 1e3).astype(int)
    temp = np.rint(i["temp_degC"].to_numpy() * 100).astype(int)
    for k, tu in enumerate(_us(i["t_ns"])):
        add(tu, link.scaled_imu_encode((boot_us + tu) // 1000, *acc[k], *gyr[k], 0, 0, 0, int(temp[k])))
    b = streams["baro"]
    for k, tu in enumerate(_us(b["t_ns"])):
        add(tu, link.scaled_pressure_encode((boot_us + tu) // 1000, float(b["press_Pa"].iat[k]) / 100.0, 0.0,
                                            int(np.rint(b["temp_degC"].iat[k] * 100))))
    c = streams["control"]
    for k, tu in enumerate(_us(c["t_ns"])):
        rc = [int(c[f"rc_{j}_us"].iat[k]) for j in range(1, 5)] + [1500] * 4 + [0] * 10
        add(tu, link.rc_channels_encode((boot_us + tu) // 1000, 8, *rc, 255))
        sv = [int(c[f"servo_{j}_us"].iat[k]) for j in range(1, 5)] + [0] * 12
        add(tu, link.servo_output_raw_encode((boot_us + tu) & 0xFFFFFFFF, 0, *sv))
    rf = streams["rangefinder"]
    # the sensor's configured limits (DISTANCE_SENSOR min/max_distance): the reader judges a
    # reading's validity by them, so fixed defaults turned every reading of a longer-range
    # rangefinder invalid
    lo_cm, hi_cm = (int(np.rint(v * 100)) for v in range_limits_m)
    for k, tu in enumerate(_us(rf["t_ns"])):
        cm = int(np.rint(rf["dist_m"].iat[k] * 100))
        valid = bool(rf["valid"].iat[k])
        # out of range: report the reading at the limit + 1 cm so that "valid" is recoverable
        add(tu, link.distance_sensor_encode((boot_us + tu) // 1000, lo_cm, hi_cm, cm if valid else hi_cm + 1,
                                            mav.MAV_DISTANCE_SENSOR_LASER, 0, 25, 0))
    recs.sort(key=lambda r: (r[0], r[1]))
    with open(path, "wb") as fh:
        for tu, _, msg in recs:
            fh.write(struct.pack(">Q", t0_us + tu) + msg.pack(link))
    return path
