"""Write a simulated flight as real log files: DataFlash ``.bin``, MAVLink ``.tlog``, ROS 1 bag,
ROS 2 bag with MCAP storage — each with its ``<log>.truth.parquet`` side-car.

Every time derives from the configured start time ``t0_utc_ns`` (``simulate.start_time_utc``)
and the simulation clock, never the wall clock; the writers are pure functions of the streams,
so the same seed gives the same bytes.

* **DataFlash** (:class:`pipeline.io.dataflash_writer.DataFlashWriter`): FMT/FMTU definitions
  of modern ArduPilot (copied from ArduPlane 4.2 ``pilot_0004.BIN``): ``GPS`` + ``GPA``,
  ``IMU``, ``ATT``, ``BARO``, ``RFND``, ``RCIN``, ``RCOU``, ``MODE``, ``EV``, ``PARM``,
  ``MSG``, ``ORGN``, plus the simulation radar ``RADR`` (TimeUS:Q, I:B, Rng:f m (ρ + τ_RD ρ̇),
  U:f, V:f direction cosines, RR:f m/s) and PARM ``RADR_SN/SE/SD`` (site, NED m) and
  ``RADR_TAU`` (s). ``TimeUS`` = boot offset (5 s) + flight time; GPS week/ms from the UTC
  start with 18 leap seconds. Quantisation: lat/lon 1e-7°, GPS alt and ATT angles 0.01 (m,
  °), RFND 1 cm, BARO temperature 0.01 °C, float32 elsewhere.
* **tlog** (pymavlink's ``ardupilotmega`` v2 encoder; framing: big-endian µs UNIX time +
  frame): ``HEARTBEAT`` 1 Hz, ``SYSTEM_TIME`` 1 Hz, ``ATTITUDE``, ``GPS_RAW_INT``,
  ``SCALED_IMU`` (mG, mrad/s), ``SCALED_PRESSURE`` (hPa, cdegC), ``RC_CHANNELS``,
  ``SERVO_OUTPUT_RAW``, ``DISTANCE_SENSOR`` (cm). No radar: MAVLink has no such message.
* **ROS 1 bag / ROS 2 MCAP bag** (rosbags writers): ``/imu`` ``sensor_msgs/Imu`` (FLU, with
  orientation), ``/gps/fix`` ``NavSatFix``, ``/baro`` ``FluidPressure``, ``/rangefinder``
  ``Range``, ``/radar`` ``uavpipe_msgs/msg/Radar`` (definition stored in the bag). World/body
  data are converted NED/FRD → ENU/FLU with :mod:`pipeline.frames.rotations`.
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from ..frames.rotations import frd_to_flu, quat_ned_frd_to_enu_flu, quat_to_euler
from ..io.dataflash_writer import RADR, DataFlashWriter
from ..io.sidecar import sidecar_path, write_sidecar
from .sensors import all_streams, labels_table, truth_stream

BOOT_US = 5_000_000
GPS_EPOCH_UNIX_S = 315964800  # 1980-01-06
LEAP_S = 18

RADAR_MSG_DEF = """std_msgs/Header header
float64 range
float64 u
float64 v
float64 range_rate
uint8 sensor_id
"""
RADAR_TYPE = "uavpipe_msgs/msg/Radar"


def _us(t_ns) -> np.ndarray:
    return (np.asarray(t_ns, np.int64) // 1000).astype(np.int64)


# --- DataFlash ---------------------------------------------------------------------------

def write_bin(path: Path, streams: dict[str, pd.DataFrame], *, t0_utc_ns: int, radar_site, radar_tau: float,
              origin, undulation_m: float) -> Path:
    """Write the simulated streams as an ArduPilot DataFlash log (see the module docstring)."""
    boot = BOOT_US
    with DataFlashWriter(path) as w:
        w.define("PARM", 32, "QNf", "TimeUS,Name,Value", units="s--", mults="F--")
        w.define("MSG", 59, "QZ", "TimeUS,Message", units="s-", mults="F-")
        w.define("GPS", 84, "QBBIHBcLLeffffB", "TimeUS,I,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,Yaw,U",
                 units="s#---SmDUmnhnh-", mults="F----0BGGB000--")
        w.define("GPA", 85, "QBCCCCfBIHf", "TimeUS,I,VDop,HAcc,VAcc,SAcc,YAcc,VV,SMS,Delta,Und",
                 units="s#mmmnd-ssm", mults="F-BBBB0-CC0")
        w.define("RCIN", 60, "QHHHHHHHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8,C9,C10,C11,C12,C13,C14",
                 units="sYYYYYYYYYYYYYY", mults="F--------------")
        w.define("RCOU", 62, "QHHHHHHHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8,C9,C10,C11,C12,C13,C14",
                 units="sYYYYYYYYYYYYYY", mults="F--------------")
        w.define("BARO", 64, "QBffcfIffB", "TimeUS,I,Alt,Press,Temp,CRt,SMS,Offset,GndTemp,Health",
                 units="s#mPOnsmO-", mults="F-00B0C?0-")
        w.define("ORGN", 69, "QBLLe", "TimeUS,Type,Lat,Lng,Alt", units="s#DUm", mults="F-GGB")
        w.define("ATT", 68, "QccccCCCCB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF",
                 units="sddddhhdh-", mults="FBBBBBBBB-")
        w.define("RFND", 106, "QBCBB", "TimeUS,Instance,Dist,Stat,Orient", units="s#m--", mults="F-B--")
        w.define("MODE", 112, "QMBB", "TimeUS,Mode,ModeNum,Rsn", units="s---", mults="F---")
        w.define("IMU", 162, "QBffffffIIfBBHH", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH,GHz,AHz",
                 units="s#EEEooo--O--zz", mults="F-000000-----00")
        w.define("EV", 179, "QB", "TimeUS,Id", units="s-", mults="F-")
        w.define(RADR["name"], RADR["type_id"], RADR["fmt"], RADR["labels"], units=RADR["units"], mults=RADR["mults"])

        w.write_params({"RADR_SN": float(radar_site[0]), "RADR_SE": float(radar_site[1]),
                        "RADR_SD": float(radar_site[2]), "RADR_TAU": float(radar_tau),
                        "FRAME_CLASS": 1.0, "FRAME_TYPE": 1.0, "RNGFND1_ORIENT": 25.0}, time_us=boot)
        w.write("MSG", TimeUS=boot, Message="ArduCopter V4.5.0 (uavpipe simulation)")
        w.write("ORGN", TimeUS=boot, Type=0, Lat=origin[0], Lng=origin[1], Alt=origin[2] - undulation_m)
        w.write("MODE", TimeUS=boot, Mode=0, ModeNum=0, Rsn=0)
        w.write("EV", TimeUS=boot, Id=10)

        batches: dict[str, dict] = {}
        g = streams["gps"]
        if len(g):
            t_us = _us(g["t_ns"])
            gps_us = t0_utc_ns // 1000 + t_us + (LEAP_S - GPS_EPOCH_UNIX_S) * 1_000_000
            wk = gps_us // (7 * 86400 * 1_000_000)
            gms = (gps_us - wk * 7 * 86400 * 1_000_000) // 1000
            vn, ve = g["vel_n_mps"].to_numpy(), g["vel_e_mps"].to_numpy()
            batches["GPS"] = {"TimeUS": boot + t_us, "I": 0, "Status": g["fix_type"].to_numpy().astype(np.uint8),
                              "GMS": gms, "GWk": wk, "NSats": g["n_sats"].to_numpy().astype(np.uint8), "HDop": 0.8,
                              "Lat": g["lat_deg"].to_numpy(), "Lng": g["lon_deg"].to_numpy(),
                              "Alt": g["alt_msl_m"].to_numpy(), "Spd": np.hypot(vn, ve),
                              "GCrs": np.mod(np.rad2deg(np.arctan2(ve, vn)), 360.0),
                              "VZ": g["vel_d_mps"].to_numpy(), "Yaw": 0.0, "U": 1}
            batches["GPA"] = {"TimeUS": boot + t_us, "I": 0, "VDop": 1.2, "HAcc": g["hacc_m"].to_numpy(),
                              "VAcc": g["vacc_m"].to_numpy(), "SAcc": 0.1, "YAcc": 0.0, "VV": 1,
                              "SMS": gms, "Delta": 100, "Und": -undulation_m + 0.0 * t_us}
        i = streams["imu"]
        batches["IMU"] = {"TimeUS": boot + _us(i["t_ns"]), "I": 0,
                          **{f"Gyr{a.upper()}": i[f"gyr_{a}_radps"].to_numpy() for a in "xyz"},
                          **{f"Acc{a.upper()}": i[f"acc_{a}_mps2"].to_numpy() for a in "xyz"},
                          "EG": 0, "EA": 0, "T": i["temp_degC"].to_numpy(), "GH": 1, "AH": 1,
                          "GHz": 200, "AHz": 200}
        a = streams["attitude"]
        q = a[["q_w", "q_x", "q_y", "q_z"]].to_numpy()
        r, p, y = (np.rad2deg(v) for v in quat_to_euler(q))
        batches["ATT"] = {"TimeUS": boot + _us(a["t_ns"]), "DesRoll": r, "Roll": r, "DesPitch": p, "Pitch": p,
                          "DesYaw": np.mod(y, 360.0), "Yaw": np.mod(y, 360.0), "ErrRP": 0.0, "ErrYaw": 0.0, "AEKF": 3}
        b = streams["baro"]
        batches["BARO"] = {"TimeUS": boot + _us(b["t_ns"]), "I": 0, "Alt": b["alt_rel_m"].to_numpy(),
                           "Press": b["press_Pa"].to_numpy(), "Temp": b["temp_degC"].to_numpy(), "CRt": 0.0,
                           "SMS": (_us(b["t_ns"]) // 1000 + boot // 1000).astype(np.uint32), "Offset": 0.0,
                           "GndTemp": b["temp_degC"].to_numpy(), "Health": 1}
        rf = streams["rangefinder"]
        batches["RFND"] = {"TimeUS": boot + _us(rf["t_ns"]), "Instance": 0, "Dist": rf["dist_m"].to_numpy(),
                           "Stat": np.where(rf["valid"].to_numpy(dtype=bool), 4, 3).astype(np.uint8),
                           "Orient": 25}
        c = streams["control"]
        tc = boot + _us(c["t_ns"])
        batches["RCIN"] = {"TimeUS": tc, **{f"C{k}": c[f"rc_{k}_us"].to_numpy() for k in range(1, 5)},
                           **{f"C{k}": 1500 for k in range(5, 9)}}
        batches["RCOU"] = {"TimeUS": tc, **{f"C{k}": c[f"servo_{k}_us"].to_numpy() for k in range(1, 5)}}
        rd = streams["radar"]
        if len(rd):
            batches["RADR"] = {"TimeUS": boot + _us(rd["t_ns"]), "I": rd["sensor_id"].to_numpy().astype(np.uint8),
                               "Rng": rd["range_m"].to_numpy(), "U": rd["dcos_u"].to_numpy(),
                               "V": rd["dcos_v"].to_numpy(), "RR": rd["range_rate_mps"].to_numpy()}
        # scalars broadcast: the writer's records() needs arrays of one length per batch
        for cols in batches.values():
            n = max(len(v) for v in cols.values() if np.ndim(v) > 0)
            for k, v in cols.items():
                if np.ndim(v) == 0:
                    cols[k] = np.full(n, v)
        w.write_merged(batches)
    return path


# --- MAVLink tlog -----------------------------------------------------------------------------

def write_tlog(path: Path, streams: dict[str, pd.DataFrame], *, t0_utc_ns: int, duration_s: float) -> Path:
    """Write the simulated streams as a MAVLink telemetry log (see the module docstring)."""
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
        add(tu, link.system_time_encode(t0_us + tu, (BOOT_US + tu) // 1000))
    a = streams["attitude"]
    r, p, y = quat_to_euler(a[["q_w", "q_x", "q_y", "q_z"]].to_numpy())
    for tu, rr, pp, yy in zip(_us(a["t_ns"]), r, p, y):
        add(tu, link.attitude_encode((BOOT_US + tu) // 1000, rr, pp, yy, 0.0, 0.0, 0.0))
    g = streams["gps"]
    vn, ve = g["vel_n_mps"].to_numpy(), g["vel_e_mps"].to_numpy()
    cog = np.rint(np.mod(np.rad2deg(np.arctan2(ve, vn)), 360.0) * 100).astype(int) % 36000
    for k, tu in enumerate(_us(g["t_ns"])):
        add(tu, link.gps_raw_int_encode(
            BOOT_US + tu, int(g["fix_type"].iat[k]), int(np.rint(g["lat_deg"].iat[k] * 1e7)),
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
        add(tu, link.scaled_imu_encode((BOOT_US + tu) // 1000, *acc[k], *gyr[k], 0, 0, 0, int(temp[k])))
    b = streams["baro"]
    for k, tu in enumerate(_us(b["t_ns"])):
        add(tu, link.scaled_pressure_encode((BOOT_US + tu) // 1000, float(b["press_Pa"].iat[k]) / 100.0, 0.0,
                                            int(np.rint(b["temp_degC"].iat[k] * 100))))
    c = streams["control"]
    for k, tu in enumerate(_us(c["t_ns"])):
        rc = [int(c[f"rc_{j}_us"].iat[k]) for j in range(1, 5)] + [1500] * 4 + [0] * 10
        add(tu, link.rc_channels_encode((BOOT_US + tu) // 1000, 8, *rc, 255))
        sv = [int(c[f"servo_{j}_us"].iat[k]) for j in range(1, 5)] + [0] * 12
        add(tu, link.servo_output_raw_encode((BOOT_US + tu) & 0xFFFFFFFF, 0, *sv))
    rf = streams["rangefinder"]
    for k, tu in enumerate(_us(rf["t_ns"])):
        cm = int(np.rint(rf["dist_m"].iat[k] * 100))
        valid = bool(rf["valid"].iat[k])
        # out of range: report the reading at the limit + 1 cm so that "valid" is recoverable
        add(tu, link.distance_sensor_encode((BOOT_US + tu) // 1000, 17, 600, cm if valid else 601,
                                            mav.MAV_DISTANCE_SENSOR_LASER, 0, 25, 0))
    recs.sort(key=lambda r: (r[0], r[1]))
    with open(path, "wb") as fh:
        for tu, _, msg in recs:
            fh.write(struct.pack(">Q", t0_us + tu) + msg.pack(link))
    return path


# --- ROS -----------------------------------------------------------------------------------

def _ros_messages(streams: dict[str, pd.DataFrame], t0_utc_ns: int, store, ros2: bool):
    """Yield (topic, msgtype, t_abs_ns, message) in time order for the ROS writers."""
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
                                                          field_of_view=0.05, min_range=0.17, max_range=6.0,
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


def write_ros1(path: Path, streams: dict[str, pd.DataFrame], *, t0_utc_ns: int) -> Path:
    """ROS 1 bag (rosbags writer); the radar type's definition is stored in its connection."""
    from rosbags.rosbag1 import Writer

    store = _typestore(False)
    msgs = _ros_messages(streams, t0_utc_ns, store, ros2=False)
    if path.exists():
        path.unlink()
    with Writer(path) as w:
        conns = {}
        for topic, mtype, _, _ in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, mtype, typestore=store)
        for topic, mtype, tn, msg in msgs:
            w.write(conns[topic], t0_utc_ns + int(tn), store.serialize_ros1(msg, mtype))
    return path


def write_ros2_mcap(path: Path, streams: dict[str, pd.DataFrame], *, t0_utc_ns: int) -> Path:
    """ROS 2 bag directory with MCAP storage (rosbags writer, CDR; radar schema in the file)."""
    import shutil

    from rosbags.rosbag2 import StoragePlugin, Writer

    store = _typestore(True)
    msgs = _ros_messages(streams, t0_utc_ns, store, ros2=True)
    if path.exists():
        shutil.rmtree(path)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {}
        for topic, mtype, _, _ in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, mtype, typestore=store)
        for topic, mtype, tn, msg in msgs:
            w.write(conns[topic], t0_utc_ns + int(tn), store.serialize_cdr(msg, mtype))
    return path


# --- one flight in every format ----------------------------------------------------------

LOG_NAMES: dict[str, Callable[[str], str]] = {
    "bin": lambda s: f"{s}.bin",
    "tlog": lambda s: f"{s}.tlog",
    "bag": lambda s: f"{s}.bag",
    "mcap": lambda s: f"{s}-mcap",
}


def write_flight(out_dir: Path, stem: str, truth, sensors, params, rate_hz: float, rng, *,
                 t0_utc_ns: int, formats=("bin", "tlog", "bag", "mcap")) -> dict[str, Path]:
    """Simulate run 0 of ``truth``'s sensors (one draw of ``rng``) and write it in ``formats``,
    each with its side-car. Returns ``{format: path}``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    streams = all_streams(truth, sensors, params, rate_hz, rng)
    tdf, lab = truth_stream(truth), labels_table(truth)
    o = sensors.origin
    paths = {}
    for fmt in formats:
        p = out_dir / LOG_NAMES[fmt](stem)
        if fmt == "bin":
            write_bin(p, streams, t0_utc_ns=t0_utc_ns, radar_site=sensors.radar.site_ned_m,
                      radar_tau=sensors.radar.tau_rd_s, origin=o, undulation_m=sensors.geoid_undulation_m)
        elif fmt == "tlog":
            write_tlog(p, streams, t0_utc_ns=t0_utc_ns, duration_s=float(truth.t_s[-1]))
        elif fmt == "bag":
            write_ros1(p, streams, t0_utc_ns=t0_utc_ns)
        elif fmt == "mcap":
            write_ros2_mcap(p, streams, t0_utc_ns=t0_utc_ns)
        else:
            raise ValueError(f"unknown log format {fmt!r}")
        write_sidecar(sidecar_path(p), tdf, lab, t0_utc_ns=t0_utc_ns,
                      extra={"scenario": truth.meta.get("scenario"), "format": fmt})
        paths[fmt] = p
    return paths, streams


def write_flight_logs(out_dir: Path, settings, sensors, ds, seed: int, say=lambda m: None) -> list[dict]:
    """``log_flights`` padded flights per maneuver (random start/heading) + one calibration
    flight, in every configured format; writes ``out_dir/flights.tsv``. Returns manifest rows."""
    from .datasets import set_rng
    from .scenarios import run_scenario, scenario_for

    rows = []
    jobs = [("mc", m, k) for m in ds.maneuvers for k in range(ds.log_flights)] + [("calibration", None, 0)]
    for kind, man, k in jobs:
        stem = f"sim-{man}-{k:03d}" if man else "sim-calibration-000"
        rng = set_rng(seed, f"log/{stem}")
        sc = scenario_for(kind, settings, man)
        if kind == "calibration":
            tr = run_scenario(sc, settings, 1, rng, vel0_zero=True, vertical_disturbance=False)
        else:
            tr = run_scenario(sc, settings, 1, rng, min_alt_m=settings.switch_min_alt_m)
        paths, _ = write_flight(out_dir, stem, tr, sensors, settings.vehicle, settings.rate_hz, rng,
                                t0_utc_ns=ds.start_time_utc_ns, formats=ds.log_formats)
        for fmt, p in paths.items():
            rows.append({"flight_id": f"{stem}-{fmt}", "path": str(p), "vehicle": "sim-quad",
                         "role": "test", "labels": str(sidecar_path(p)), "format": "",
                         "notes": f"simulated {sc.name} ({fmt})"})
        say(f"log files {stem}: {', '.join(paths)}")
    df = pd.DataFrame(rows, columns=["flight_id", "path", "vehicle", "role", "labels", "format", "notes"])
    out_dir.mkdir(parents=True, exist_ok=True)
    df.to_csv(out_dir / "flights.tsv", sep="\t", index=False)
    return rows
