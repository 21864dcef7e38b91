"""Canonical streams written as a ROS 1 bag or a ROS 2 bag with MCAP storage (rosbags writers).

Topics: ``/imu`` ``sensor_msgs/Imu`` (FLU, with orientation: the nearest attitude sample at or
before each IMU sample), ``/gps/fix`` ``NavSatFix``, ``/baro`` ``FluidPressure``,
``/rangefinder`` ``Range`` (``inf`` when out of range), ``/radar`` ``uavpipe_msgs/msg/Radar``
(:data:`RADAR_MSG_DEF`, stored in the bag so that any reader can decode it). World/body data
are converted NED/FRD -> ENU/FLU with :mod:`pipeline.frames.rotations`. Header stamps and bag
times are ``t0_utc_ns + t_ns``; messages are sorted by (time, topic), so the output is a pure
function of the streams (same streams, same bytes).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Mapping

import numpy as np

from ..frames.rotations import frd_to_flu, quat_ned_frd_to_enu_flu

if TYPE_CHECKING:  # annotations only
    import pandas as pd

RADAR_MSG_DEF = """std_msgs/Header header
float64 range
float64 u
float64 v
float64 range_rate
uint8 sensor_id
"""
RADAR_TYPE = "uavpipe_msgs/msg/Radar"


def _ros_messages(streams: Mapping[str, pd.DataFrame], t0_utc_ns: int, store, ros2: bool,
                  range_limits_m: tuple[float, float] = (0.17, 6.0)):
    """(topic, msgtype, t_ns, message) of every message, sorted by (time, topic)."""
    T = store.types
    Header = T["std_msgs/msg/Header"]
    Time = T["builtin_interfaces/msg/Time"]
    Quat, Vec3 = T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Vector3"]

    def hdr(t_ns: int, frame: str, seq: int):
        ta = t0_utc_ns + int(t_ns)
        st = Time(sec=ta // 1_000_000_000, nanosec=ta % 1_000_000_000)
        return Header(stamp=st, frame_id=frame) if ros2 else Header(seq=seq, stamp=st, frame_id=frame)

    out = []
    i = streams["imu"]
    a = streams["attitude"]
    # orientation: nearest attitude sample at or before each IMU sample (attitude is slower)
    ka = np.clip(np.searchsorted(a["t_ns"].to_numpy(), i["t_ns"].to_numpy(), side="right") - 1, 0, len(a) - 1)
    q = quat_ned_frd_to_enu_flu(a[["q_w", "q_x", "q_y", "q_z"]].to_numpy()[ka])
    gyr = frd_to_flu(i[["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].to_numpy())
    acc = frd_to_flu(i[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy())
    Imu = T["sensor_msgs/msg/Imu"]
    cov0 = np.zeros(9)
    for k, tn in enumerate(i["t_ns"].to_numpy()):
        msg = Imu(header=hdr(tn, "base_link", k),
                  orientation=Quat(x=q[k, 1], y=q[k, 2], z=q[k, 3], w=q[k, 0]), orientation_covariance=cov0,
                  angular_velocity=Vec3(x=gyr[k, 0], y=gyr[k, 1], z=gyr[k, 2]), angular_velocity_covariance=cov0,
                  linear_acceleration=Vec3(x=acc[k, 0], y=acc[k, 1], z=acc[k, 2]),
                  linear_acceleration_covariance=cov0)
        out.append(("/imu", Imu.__msgtype__, tn, msg))
    g = streams["gps"]
    Fix, Status = T["sensor_msgs/msg/NavSatFix"], T["sensor_msgs/msg/NavSatStatus"]
    for k, tn in enumerate(g["t_ns"].to_numpy()):
        sh, sv = g["hacc_m"].iat[k] ** 2, g["vacc_m"].iat[k] ** 2
        msg = Fix(header=hdr(tn, "gps", k), status=Status(status=0, service=1),
                  latitude=g["lat_deg"].iat[k], longitude=g["lon_deg"].iat[k], altitude=g["alt_wgs84_m"].iat[k],
                  position_covariance=np.array([sh, 0, 0, 0, sh, 0, 0, 0, sv]), position_covariance_type=2)
        out.append(("/gps/fix", Fix.__msgtype__, tn, msg))
    b = streams["baro"]
    FP = T["sensor_msgs/msg/FluidPressure"]
    for k, tn in enumerate(b["t_ns"].to_numpy()):
        out.append(("/baro", FP.__msgtype__, tn, FP(header=hdr(tn, "base_link", k),
                                                   fluid_pressure=b["press_Pa"].iat[k], variance=0.0)))
    rf = streams["rangefinder"]
    Rg = T["sensor_msgs/msg/Range"]
    extra = {"variance": 0.0} if "variance" in Rg.__dataclass_fields__ else {}
    for k, tn in enumerate(rf["t_ns"].to_numpy()):
        d = float(rf["dist_m"].iat[k]) if bool(rf["valid"].iat[k]) else float("inf")
        out.append(("/rangefinder", Rg.__msgtype__, tn, Rg(header=hdr(tn, "rangefinder", k), radiation_type=1,
                                                          field_of_view=0.05, min_range=float(range_limits_m[0]),
                                                          max_range=float(range_limits_m[1]),
                                                          range=d, **extra)))
    rd = streams["radar"]
    Rad = T[RADAR_TYPE]
    for k, tn in enumerate(rd["t_ns"].to_numpy()):
        out.append(("/radar", RADAR_TYPE, tn, Rad(header=hdr(tn, "radar", k), range=rd["range_m"].iat[k],
                                                 u=rd["dcos_u"].iat[k], v=rd["dcos_v"].iat[k],
                                                 range_rate=rd["range_rate_mps"].iat[k],
                                                 sensor_id=int(rd["sensor_id"].iat[k]))))
    order = {"/imu": 0, "/gps/fix": 1, "/baro": 2, "/rangefinder": 3, "/radar": 4}
    out.sort(key=lambda m: (m[2], order[m[0]]))
    return out


def _typestore(ros2: bool):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.LATEST if ros2 else Stores.ROS1_NOETIC)
    store.register(get_types_from_msg(RADAR_MSG_DEF, RADAR_TYPE))
    return store


def _write_messages(writer, msgs, t0_utc_ns: int, store, serialize) -> None:
    """One connection per topic (in first-message order), then every message at its log time."""
    conns = {}
    for topic, mtype, _, _ in msgs:
        if topic not in conns:
            conns[topic] = writer.add_connection(topic, mtype, typestore=store)
    for topic, mtype, tn, msg in msgs:
        writer.write(conns[topic], t0_utc_ns + int(tn), serialize(msg, mtype))


def write_ros1(path: str | os.PathLike, streams: Mapping[str, pd.DataFrame], *, t0_utc_ns: int,
               range_limits_m: tuple[float, float] = (0.17, 6.0)) -> Path:
    """Write canonical streams as a ROS 1 bag (rosbags writer).

    Parameters
    ----------
    path : path-like
        Output ``.bag`` (replaced if it exists).
    streams : mapping of str to DataFrame
        Canonical ``imu``, ``attitude``, ``gps``, ``baro``, ``rangefinder`` and ``radar``
        streams (``t_ns`` since the flight's t = 0).
    t0_utc_ns : int
        UTC of ``t_ns = 0``: header stamps and bag times are ``t0_utc_ns + t_ns``.
    range_limits_m : (float, float)
        The rangefinder's ``min_range``/``max_range`` (the reader judges validity by them).

    Returns
    -------
    Path
        ``path``; the radar type's definition is stored in its connection.
    """
    from rosbags.rosbag1 import Writer

    path = Path(path)
    store = _typestore(False)
    msgs = _ros_messages(streams, t0_utc_ns, store, ros2=False, range_limits_m=range_limits_m)
    if path.exists():
        path.unlink()
    with Writer(path) as w:
        _write_messages(w, msgs, t0_utc_ns, store, store.serialize_ros1)
    return path


def write_ros2_mcap(path: str | os.PathLike, streams: Mapping[str, pd.DataFrame], *, t0_utc_ns: int,
                    range_limits_m: tuple[float, float] = (0.17, 6.0)) -> Path:
    """Write canonical streams as a ROS 2 bag directory with MCAP storage (rosbags writer, CDR).

    Parameters
    ----------
    path : path-like
        Output bag directory (replaced if it exists).
    streams : mapping of str to DataFrame
        As :func:`write_ros1`.
    t0_utc_ns : int
        UTC of ``t_ns = 0``: header stamps and log times are ``t0_utc_ns + t_ns``.
    range_limits_m : (float, float)
        The rangefinder's ``min_range``/``max_range`` (the reader judges validity by them).

    Returns
    -------
    Path
        ``path``; the radar schema is stored in the ``.mcap`` file.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    path = Path(path)
    store = _typestore(True)
    msgs = _ros_messages(streams, t0_utc_ns, store, ros2=True, range_limits_m=range_limits_m)
    if path.exists():
        shutil.rmtree(path)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        _write_messages(w, msgs, t0_utc_ns, store, store.serialize_cdr)
    return path
