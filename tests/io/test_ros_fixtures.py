"""Round trips through the ROS readers on small fixtures written at test time by the libraries'
own writers (rosbags rosbag1/rosbag2 writers, mcap + mcap_ros2 writers): what the real Husky
files do not exercise — ROS 2 sqlite3 bags, MCAP with ROS 1 and JSON encodings, a custom message
type whose definition is stored in the file, and every mapped message type (MagneticField,
FluidPressure, Range, PoseStamped, TwistStamped, ...).

The expected canonical values are computed here from the written message values with the
documented conversions in closed form (ENU->NED: (e, n, u) -> (n, e, -u); FLU->FRD:
(x, y, z) -> (x, -y, -z)); orientations are checked as rotation matrices against scipy's
``Rotation`` (an independent quaternion implementation).

The writer helpers are reused by ``tests/properties/test_ros_corruption.py``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from pipeline.io import registry
from pipeline.io.base import IngestError
from pipeline.io.mcap_reader import McapReader
from pipeline.io.rosbag import Ros1BagReader, Ros2BagReader

RADAR_TYPE = "uavpipe_msgs/msg/Radar"
RADAR_MSG = ("std_msgs/Header header\nfloat64 range\nfloat64 u\nfloat64 v\n"
             "float64 range_rate\nuint8 sensor_id\n")
T_BASE = 1_700_000_000_000_000_000  # Unix ns
N = 12
KINDS = ("ros1bag", "ros2sqlite3", "ros2mcap", "mcap_ros1", "mcap_ros2", "mcap_json")

# --- message values ---------------------------------------------------------------------------


def _stamp(t: int) -> dict:
    return {"sec": t // 1_000_000_000, "nanosec": t % 1_000_000_000}


def _hdr(t: int, frame: str) -> dict:
    return {"stamp": _stamp(t), "frame_id": frame}


def _v3(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _q(q) -> dict:  # q = (w, x, y, z)
    return {"w": float(q[0]), "x": float(q[1]), "y": float(q[2]), "z": float(q[3])}


def make_messages(rng: np.random.Generator, n: int = N) -> dict[str, tuple[str, list[tuple[int, dict]]]]:
    """``{topic: (msgtype, [(record_time_ns, message dict), ...])}`` covering every mapped type."""
    out: dict[str, tuple[str, list[tuple[int, dict]]]] = {}

    def series(topic, typ, offset_ns, make):
        msgs = []
        for k in range(n):
            rec = T_BASE + offset_ns + k * 50_000_000
            stamp = rec - 1_000_000 - int(rng.integers(0, 1000))  # stamped ~1 ms before recording
            msgs.append((rec, make(k, stamp)))
        out[topic] = (typ, msgs)

    def imu(k, t):
        q = rng.normal(size=4)
        return {"header": _hdr(t, "imu_link"), "orientation": _q(q / np.linalg.norm(q)),
                "orientation_covariance": [0.01] + [0.0] * 8,
                "angular_velocity": _v3(rng.normal(size=3)), "angular_velocity_covariance": [0.0] * 9,
                "linear_acceleration": _v3(rng.normal(size=3) * 3 + [0, 0, 9.8]),
                "linear_acceleration_covariance": [0.0] * 9}

    def imu_noq(k, t):
        m = imu(k, t)
        m["orientation_covariance"] = [-1.0] + [0.0] * 8
        m["header"]["frame_id"] = "imu2_link"
        return m

    def fix(k, t):
        cov = [float(rng.uniform(0.5, 4)), 0, 0, 0, float(rng.uniform(0.5, 4)), 0, 0, 0,
               float(rng.uniform(1, 9))]
        return {"header": _hdr(t, "gps"), "status": {"status": [-1, 0, 1, 2][k % 4], "service": 1},
                "latitude": 47.0 + 1e-4 * k + float(rng.normal()) * 1e-6,
                "longitude": 8.0 - 1e-4 * k, "altitude": 400.0 + float(rng.normal()),
                "position_covariance": cov, "position_covariance_type": 0 if k == 5 else 2}

    def mag(k, t):
        return {"header": _hdr(0 if k == 3 else t, "mag_link"),  # one unset stamp
                "magnetic_field": _v3(rng.normal(size=3) * 2e-5), "magnetic_field_covariance": [0.0] * 9}

    def baro(k, t):
        return {"header": _hdr(t, "baro_link"), "fluid_pressure": float(rng.uniform(9e4, 1.01e5)),
                "variance": 0.0}

    def rng_(k, t):
        # k = 2, 3: REP 117's +inf (nothing within max_range) and -inf (closer than min_range)
        r = float(rng.uniform(0.05, 8.0)) if k not in (0, 1, 2, 3) else (0.5, 7.5, math.inf, -math.inf)[k]
        return {"header": _hdr(t, "sonar_link"), "radiation_type": 0, "field_of_view": 0.3,
                "min_range": 0.2, "max_range": 6.0, "range": r, "variance": 0.0}

    def odom(k, t):
        yaw = float(rng.uniform(-math.pi, math.pi))
        return {"header": _hdr(t, "odom"), "child_frame_id": "base_link",
                "pose": {"pose": {"position": _v3(rng.normal(size=3) * 10),
                                  "orientation": _q([math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)])},
                         "covariance": [0.0] * 36},
                "twist": {"twist": {"linear": _v3(rng.normal(size=3)), "angular": _v3(rng.normal(size=3))},
                          "covariance": [0.0] * 36}}

    def pose(k, t):
        q = rng.normal(size=4)
        return {"header": _hdr(t, "map"), "pose": {"position": _v3(rng.normal(size=3) * 20),
                                                    "orientation": _q(q / np.linalg.norm(q))}}

    def twist(frame):
        def f(k, t):
            return {"header": _hdr(t, frame), "twist": {"linear": _v3(rng.normal(size=3)),
                                                         "angular": _v3(rng.normal(size=3))}}
        return f

    def radar(k, t):
        u, v = rng.uniform(-0.5, 0.5, size=2)
        return {"header": _hdr(t, "radar"), "range": float(rng.uniform(100, 5000)), "u": float(u),
                "v": float(v), "range_rate": float(rng.normal() * 30), "sensor_id": k % 3}

    series("/imu/data", "sensor_msgs/msg/Imu", 0, imu)
    series("/imu2/data", "sensor_msgs/msg/Imu", 1_000_000, imu_noq)
    series("/fix", "sensor_msgs/msg/NavSatFix", 2_000_000, fix)
    series("/mag", "sensor_msgs/msg/MagneticField", 3_000_000, mag)
    series("/baro", "sensor_msgs/msg/FluidPressure", 4_000_000, baro)
    series("/sonar", "sensor_msgs/msg/Range", 5_000_000, rng_)
    series("/odom", "nav_msgs/msg/Odometry", 6_000_000, odom)
    series("/pose", "geometry_msgs/msg/PoseStamped", 7_000_000, pose)
    series("/vel", "geometry_msgs/msg/TwistStamped", 8_000_000, twist("map"))
    series("/vel_body", "geometry_msgs/msg/TwistStamped", 9_000_000, twist("base_link"))
    series("/radar", RADAR_TYPE, 10_000_000, radar)
    series("/chatter", "std_msgs/msg/String", 11_000_000, lambda k, t: {"data": f"hello {k}"})
    return out


# --- writers ------------------------------------------------------------------------------------


def typestore(ros1: bool = False):
    """A fresh rosbags store with the stock types and the custom radar type."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    ts.register(get_types_from_msg(RADAR_MSG, RADAR_TYPE))
    return ts


def build(ts, typ: str, d: dict):
    """A rosbags message object of ``typ`` from a nested dict (missing fields: zero/empty)."""
    from rosbags.typesys.base import Nodetype

    _consts, fields = ts.fielddefs[typ]
    kw = {}
    for name, (nt, det) in fields:
        v = d.get(name)
        if nt == Nodetype.NAME:
            kw[name] = build(ts, det, v or {})
        elif nt == Nodetype.BASE:
            kind = det[0]
            kw[name] = v if v is not None else ("" if kind == "string" else 0)
            if kind.startswith("float"):
                kw[name] = float(kw[name])
        else:
            (snt, sdet), size = det
            assert snt == Nodetype.BASE
            vals = v if v is not None else [0] * (size or 0)
            kw[name] = np.asarray(vals, dtype=np.dtype(sdet[0]))
    if "seq" in dict(fields) and "seq" not in d:
        kw["seq"] = 0
    return ts.types[typ](**kw)


def write_ros1bag(path: Path, msgs) -> Path:
    from rosbags.rosbag1 import Writer

    ts = typestore(ros1=True)
    with Writer(path) as w:
        conns = {t: w.add_connection(t, typ, typestore=ts) for t, (typ, _m) in msgs.items()}
        for rec, topic, typ, d in _ordered(msgs):
            w.write(conns[topic], rec, ts.serialize_ros1(build(ts, typ, d), typ))
    return path


def write_ros2bag(path: Path, msgs, storage: str = "sqlite3") -> Path:
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = typestore()
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conns = {t: w.add_connection(t, typ, typestore=ts) for t, (typ, _m) in msgs.items()}
        for rec, topic, typ, d in _ordered(msgs):
            w.write(conns[topic], rec, ts.serialize_cdr(build(ts, typ, d), typ))
    return path


def write_mcap_ros2(path: Path, msgs) -> Path:
    from mcap_ros2.writer import Writer

    ts = typestore()
    with open(path, "wb") as fh:
        w = Writer(fh)
        schemas = {t: w.register_msgdef(typ, ts.generate_msgdef(typ, ros_version=2)[0])
                   for t, (typ, _m) in msgs.items()}
        for rec, topic, typ, d in _ordered(msgs):
            w.write_message(topic, schemas[topic], d, log_time=rec, publish_time=rec)
        w.finish()
    return path


def write_mcap_ros1(path: Path, msgs) -> Path:
    from mcap.writer import Writer

    ts = typestore(ros1=True)
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros1", library="uavpipe-tests")
        chans = {}
        for topic, (typ, _m) in msgs.items():
            name = typ.replace("/msg/", "/")
            sid = w.register_schema(name=name, encoding="ros1msg",
                                    data=ts.generate_msgdef(typ)[0].encode())
            chans[topic] = w.register_channel(topic=topic, message_encoding="ros1", schema_id=sid)
        for i, (rec, topic, typ, d) in enumerate(_ordered(msgs)):
            w.add_message(chans[topic], log_time=rec, publish_time=rec, sequence=i,
                          data=bytes(ts.serialize_ros1(build(ts, typ, d), typ)))
        w.finish()
    return path


def write_mcap_json(path: Path, msgs) -> Path:
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start(profile="", library="uavpipe-tests")
        chans = {}
        for topic, (typ, _m) in msgs.items():
            sid = w.register_schema(name=typ, encoding="jsonschema", data=b'{"type": "object"}')
            chans[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        for i, (rec, topic, typ, d) in enumerate(_ordered(msgs)):
            w.add_message(chans[topic], log_time=rec, publish_time=rec, sequence=i,
                          data=json.dumps(d).encode())
        w.finish()
    return path


def _ordered(msgs):
    rows = [(rec, topic, typ, d) for topic, (typ, lst) in msgs.items() for rec, d in lst]
    return sorted(rows, key=lambda r: (r[0], r[1]))


def write_fixture(kind: str, tmp: Path, msgs) -> Path:
    """Write ``msgs`` as one of :data:`KINDS`; returns the path to ingest."""
    if kind == "ros1bag":
        return write_ros1bag(tmp / "fx.bag", msgs)
    if kind == "ros2sqlite3":
        return write_ros2bag(tmp / "fx_sqlite", msgs, "sqlite3")
    if kind == "ros2mcap":
        return write_ros2bag(tmp / "fx_mcapbag", msgs, "mcap")
    if kind == "mcap_ros1":
        return write_mcap_ros1(tmp / "fx1.mcap", msgs)
    if kind == "mcap_ros2":
        return write_mcap_ros2(tmp / "fx2.mcap", msgs)
    if kind == "mcap_json":
        return write_mcap_json(tmp / "fxj.mcap", msgs)
    raise ValueError(kind)


READER_FOR = {"ros1bag": Ros1BagReader, "ros2sqlite3": Ros2BagReader, "ros2mcap": Ros2BagReader,
              "mcap_ros1": McapReader, "mcap_ros2": McapReader, "mcap_json": McapReader}
CONFIG = {"ros": {"topics": {"/sonar": {"stream": "rangefinder", "orientation": 25}}}}

# --- expected values (closed form) --------------------------------------------------------------


def _t(d: dict) -> int:
    return d["header"]["stamp"]["sec"] * 1_000_000_000 + d["header"]["stamp"]["nanosec"]


def _arr(lst, f):
    return np.array([f(d) for _rec, d in lst], dtype=float)


def _xyz(lst, f):
    return np.array([[f(d)["x"], f(d)["y"], f(d)["z"]] for _rec, d in lst])


def _t0(msgs) -> int:
    ts = []
    for topic, (_typ, lst) in msgs.items():
        if topic in ("/vel_body", "/chatter"):
            continue
        ts += [_t(d) or rec for rec, d in lst]
    return min(ts)


def _rows(df: pd.DataFrame, src: str) -> pd.DataFrame:
    return df[df["src"] == src].sort_values("t_ns", kind="stable").reset_index(drop=True)


def _dcm_ros_to_ours(q_wxyz: np.ndarray) -> np.ndarray:
    """R_ned_frd = C_ned_enu · R_enu_flu · C_flu_frd, R from scipy (scalar-last input)."""
    c_ned_enu = np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]])
    c_flu_frd = np.diag([1.0, -1, -1])
    r = Rotation.from_quat(q_wxyz[:, [1, 2, 3, 0]]).as_matrix()
    return c_ned_enu @ r @ c_flu_frd


def _dcm(q_wxyz: np.ndarray) -> np.ndarray:
    return Rotation.from_quat(q_wxyz[:, [1, 2, 3, 0]]).as_matrix()


def check_log(log, msgs) -> None:
    """Assert every canonical value of ``log`` equals the closed-form conversion of ``msgs``."""
    t0 = _t0(msgs)
    assert log.meta["t0_utc_ns"] == t0 and log.meta["utc_source"] == "host"
    rows_t = lambda lst: np.array([(_t(d) or rec) - t0 for rec, d in lst], dtype=np.int64)  # noqa: E731

    # imu (FLU -> FRD) and attitude from the first IMU only (the second has covariance[0] = -1)
    lst = msgs["/imu/data"][1]
    imu = _rows(log["imu"], "/imu/data")
    np.testing.assert_array_equal(imu["t_ns"].to_numpy(), rows_t(lst))
    flu_frd = np.array([1.0, -1, -1])
    np.testing.assert_allclose(imu[["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]].to_numpy(),
                               _xyz(lst, lambda d: d["angular_velocity"]) * flu_frd, rtol=0, atol=1e-12)
    np.testing.assert_allclose(imu[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy(),
                               _xyz(lst, lambda d: d["linear_acceleration"]) * flu_frd, rtol=0, atol=1e-12)
    assert set(log["imu"]["src"]) == {"/imu/data", "/imu2/data"}
    assert sorted(log["imu"].groupby("src", observed=True)["instance"].first()) == [0, 1]
    att = log["attitude"]
    assert set(att["src"]) == {"/imu/data", "/pose"}
    a = _rows(att, "/imu/data")
    q_ros = np.array([[d["orientation"][c] for c in "wxyz"] for _r, d in lst])
    np.testing.assert_allclose(_dcm(a[["q_w", "q_x", "q_y", "q_z"]].to_numpy()), _dcm_ros_to_ours(q_ros),
                               atol=1e-9)

    # gps: WGS-84 ellipsoidal altitude, status -> fix_type, covariance -> accuracies
    lst = msgs["/fix"][1]
    g = _rows(log["gps"], "/fix")
    np.testing.assert_array_equal(g["t_ns"].to_numpy(), rows_t(lst))
    np.testing.assert_allclose(g["lat_deg"], _arr(lst, lambda d: d["latitude"]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(g["lon_deg"], _arr(lst, lambda d: d["longitude"]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(g["alt_wgs84_m"], _arr(lst, lambda d: d["altitude"]), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(g["fix_type"], [{-1: 1, 0: 3, 1: 4, 2: 4}[d["status"]["status"]] for _r, d in lst])
    known = np.array([d["position_covariance_type"] > 0 for _r, d in lst])
    hacc = np.sqrt(_arr(lst, lambda d: max(d["position_covariance"][0], d["position_covariance"][4])))
    np.testing.assert_allclose(g["hacc_m"][known], hacc[known], rtol=1e-12)
    np.testing.assert_allclose(g["vacc_m"][known], np.sqrt(_arr(lst, lambda d: d["position_covariance"][8]))[known])
    assert g["hacc_m"][~known].isna().all() and g["vacc_m"][~known].isna().all()
    first_ok = next(d for _r, d in lst if d["status"]["status"] >= 0)  # the first message has no fix
    assert log.meta["ned_origin"] == {"lat_deg": first_ok["latitude"], "lon_deg": first_ok["longitude"],
                                      "alt_wgs84_m": first_ok["altitude"]}

    # mag (tesla, FLU -> FRD); one zero stamp -> record time, counted
    lst = msgs["/mag"][1]
    m = _rows(log["mag"], "/mag")
    np.testing.assert_array_equal(m["t_ns"].to_numpy(), np.sort(rows_t(lst)))
    order = np.argsort(rows_t(lst), kind="stable")
    np.testing.assert_allclose(m[["mag_x_T", "mag_y_T", "mag_z_T"]].to_numpy(),
                               (_xyz(lst, lambda d: d["magnetic_field"]) * flu_frd)[order], rtol=0, atol=1e-18)
    assert log.meta["diagnostics"]["stamp_from_record_time"] == {"/mag": 1}

    lst = msgs["/baro"][1]
    np.testing.assert_allclose(_rows(log["baro"], "/baro")["press_Pa"], _arr(lst, lambda d: d["fluid_pressure"]))

    lst = msgs["/sonar"][1]
    r = _rows(log["rangefinder"], "/sonar")
    dist = _arr(lst, lambda d: d["range"])
    np.testing.assert_array_equal(r["valid"].to_numpy(dtype=bool), np.isfinite(dist) & (dist >= 0.2) & (dist <= 6.0))
    assert not r["valid"][1] and r["valid"][0] and not r["valid"][2] and not r["valid"][3]
    # +/-inf read as a reading at the limit, as the other formats give out-of-range readings
    np.testing.assert_allclose(r["dist_m"], np.where(
        dist == np.inf, 6.0, np.where(dist == -np.inf, 0.2, dist)))
    assert (r["orientation"] == 25).all()

    # odometry: as logged, frames recorded
    lst = msgs["/odom"][1]
    o = _rows(log["odometry"], "/odom")
    np.testing.assert_allclose(o[["pos_x_m", "pos_y_m", "pos_z_m"]].to_numpy(),
                               _xyz(lst, lambda d: d["pose"]["pose"]["position"]))
    np.testing.assert_allclose(o[["vel_x_mps", "vel_y_mps", "vel_z_mps"]].to_numpy(),
                               _xyz(lst, lambda d: d["twist"]["twist"]["linear"]))
    np.testing.assert_allclose(o["yaw_rate_radps"], _arr(lst, lambda d: d["twist"]["twist"]["angular"]["z"]))
    assert log.meta["frames"]["odometry"] == {"topic": "/odom", "frame_id": "odom", "child_frame_id": "base_link"}

    # pose -> local_position (ENU -> NED) + attitude; twist in 'map' -> velocity; body twist dropped
    enu_ned = lambda v: np.stack([v[:, 1], v[:, 0], -v[:, 2]], axis=1)  # noqa: E731
    lp = log["local_position"]
    lst = msgs["/pose"][1]
    p = _rows(lp, "/pose")
    np.testing.assert_allclose(p[["pos_n_m", "pos_e_m", "pos_d_m"]].to_numpy(),
                               enu_ned(_xyz(lst, lambda d: d["pose"]["position"])))
    assert p[["vel_n_mps", "vel_e_mps", "vel_d_mps"]].isna().all().all()
    q_ros = np.array([[d["pose"]["orientation"][c] for c in "wxyz"] for _r, d in lst])
    pa = _rows(att, "/pose")
    np.testing.assert_allclose(_dcm(pa[["q_w", "q_x", "q_y", "q_z"]].to_numpy()), _dcm_ros_to_ours(q_ros), atol=1e-9)
    lst = msgs["/vel"][1]
    v = _rows(lp, "/vel")
    np.testing.assert_allclose(v[["vel_n_mps", "vel_e_mps", "vel_d_mps"]].to_numpy(),
                               enu_ned(_xyz(lst, lambda d: d["twist"]["linear"])))
    assert "/vel_body" not in set(lp["src"])
    diag = log.meta["diagnostics"]
    assert diag["records_dropped"] == {}
    assert diag["unmapped_topics"]["/vel_body"]["count"] == N
    assert "not a world frame" in diag["unmapped_topics"]["/vel_body"]["reason"]

    # custom radar type, mapped by the default config
    lst = msgs["/radar"][1]
    rd = _rows(log["radar"], "/radar")
    for col_, fld in {"range_m": "range", "dcos_u": "u", "dcos_v": "v", "range_rate_mps": "range_rate",
                      "sensor_id": "sensor_id"}.items():
        np.testing.assert_allclose(rd[col_], _arr(lst, lambda d: d[fld]), err_msg=col_)

    # unmapped type listed, frames of every topic recorded
    assert diag["unmapped_topics"]["/chatter"]["type"] == "std_msgs/msg/String"
    assert diag["unmapped_topics"]["/chatter"]["count"] == N
    topics = log.meta["frames"]["topics"]
    assert topics["/fix"]["frame_id"] == "gps" and topics["/radar"]["frame_id"] == "radar"
    assert log.meta["frames"]["gps"] == {"topic": "/fix", "frame_id": "gps"}
    for s in ("imu", "gps", "mag", "baro", "rangefinder", "odometry", "local_position", "attitude", "radar"):
        assert log[s]["t_boot_ns"].isna().all()


@pytest.fixture
def msgs(rng):
    return make_messages(rng)


@pytest.mark.parametrize("kind", KINDS)
def test_roundtrip_every_type(kind, msgs, tmp_path):
    path = write_fixture(kind, tmp_path, msgs)
    log = READER_FOR[kind]().read(path, config=CONFIG)
    check_log(log, msgs)
    assert log.meta["status"] == "ok"


def test_fixtures_decode_with_library_oracles(msgs, tmp_path):
    """The fixtures are valid for independent decoders (mcap_ros1/mcap_ros2, rosbags AnyReader)."""
    from mcap.reader import make_reader
    from mcap_ros1.decoder import DecoderFactory as D1
    from mcap_ros2.decoder import DecoderFactory as D2
    from rosbags.highlevel import AnyReader

    p1 = write_mcap_ros1(tmp_path / "a.mcap", msgs)
    p2 = write_mcap_ros2(tmp_path / "b.mcap", msgs)
    for p, fac in ((p1, D1()), (p2, D2())):
        with open(p, "rb") as fh:
            got = [(ch.topic, m) for _s, ch, _r, m in make_reader(fh, decoder_factories=[fac]).iter_decoded_messages()
                   if ch.topic == "/radar"]
        assert [m.range for _t, m in got] == [d["range"] for _r, d in msgs["/radar"][1]]
    bag = write_ros2bag(tmp_path / "sq", msgs, "sqlite3")
    with AnyReader([bag]) as r:  # the custom type comes from the bag's own definitions
        conn = next(c for c in r.connections if c.topic == "/radar")
        vals = [r.deserialize(raw, conn.msgtype).u for _c, _t, raw in r.messages(connections=[conn])]
    assert vals == [d["u"] for _r, d in msgs["/radar"][1]]


def test_custom_type_needs_the_definition_from_the_file(msgs, tmp_path):
    """The radar type is not in any stock store: decoding it proves the reader registered it
    from the bag; without a field mapping it is listed as unmapped, not lost silently."""
    from rosbags.typesys import Stores, get_typestore

    assert RADAR_TYPE not in get_typestore(Stores.LATEST).fielddefs
    path = write_ros2bag(tmp_path / "sq", msgs, "sqlite3")
    cfg = {"ros": {"custom_types": {RADAR_TYPE: {"stream": "radar", "fields": {"range_m": "range"}}},
                   "topics": {"/sonar": None}}}
    log = Ros2BagReader().read(path, config=cfg)
    np.testing.assert_allclose(_rows(log["radar"], "/radar")["range_m"],
                               _arr(msgs["/radar"][1], lambda d: d["range"]))
    assert log["radar"]["dcos_u"].isna().all()
    assert log.meta["diagnostics"]["unmapped_topics"]["/sonar"]["reason"] == "ignored by config"
    assert len(log["rangefinder"]) == 0


def test_custom_mapping_by_topic_and_stamp_from_record_time(msgs, tmp_path):
    path = write_mcap_ros2(tmp_path / "c.mcap", msgs)
    cfg = {"ros": {"custom": {"/radar": {"type": RADAR_TYPE, "stream": "radar", "stamp": None,
                                         "fields": {"range_m": "range", "sensor_id": "sensor_id"}}}}}
    log = McapReader().read(path, config=cfg)
    rd = _rows(log["radar"], "/radar")
    recs = np.array([rec for rec, _d in msgs["/radar"][1]])
    np.testing.assert_array_equal(rd["t_ns"].to_numpy() + log.meta["t0_utc_ns"], recs)
    assert rd["dcos_u"].isna().all()


def test_a_configured_topic_the_bag_lacks_is_a_warning_naming_it(msgs, tmp_path):
    # a misspelt topic in the map changes nothing; it must say so, not pass in silence. A topic
    # named like none in the log is a sensor this bag lacks (a dataset's one config lists what
    # some bags hold): listed in diagnostics.absent_topics, no warning
    cfg = {"ros": {"topics": {"/sonarr": {"stream": "rangefinder"}, "/radar": None,
                              "/thermal_camera_left": {"stream": "rangefinder"}}}}
    for path, reader in ((write_ros1bag(tmp_path / "w.bag", msgs), Ros1BagReader()),
                         (write_mcap_ros2(tmp_path / "w.mcap", msgs), McapReader())):
        log = reader.read(path, config=cfg)
        warn = [w for w in log.meta["diagnostics"]["warnings"] if w.startswith("ingest.ros.topics:")]
        assert len(warn) == 1 and warn[0].startswith(
            "ingest.ros.topics: topic(s) /sonarr (did you mean /sonar?) not in the log (it has "), \
            log.meta["diagnostics"]["warnings"]
        assert "/radar" not in warn[0].split("(it has")[0] and "/thermal" not in warn[0]
        assert log.meta["diagnostics"]["absent_topics"] == ["/thermal_camera_left"]
    # a topic the config skips (null) may be absent: a shared config lists what some bags hold
    log = Ros1BagReader().read(write_ros1bag(tmp_path / "s.bag", msgs), config={"ros": {"topics": {"/camera": None}}})
    assert not any(w.startswith("ingest.ros.") for w in log.meta["diagnostics"]["warnings"])


def test_topic_map_overrides(msgs, tmp_path):
    """Instance, ignore, and Odometry as a world ENU pose (local_position: position ENU->NED,
    body twist rotated by the orientation into the world, then ENU->NED)."""
    path = write_ros1bag(tmp_path / "o.bag", msgs)
    cfg = {"ros": {"topics": {"/odom": "local_position", "/imu2/data": {"instance": 0},
                              "/imu/data": {"instance": 3}, "/radar": None}}}
    log = Ros1BagReader().read(path, config=cfg)
    assert len(log["odometry"]) == 0 and len(log["radar"]) == 0
    inst = log["imu"].groupby("src", observed=True)["instance"].first().to_dict()
    assert inst == {"/imu/data": 3, "/imu2/data": 0}
    lst = msgs["/odom"][1]
    lp = _rows(log["local_position"], "/odom")
    pos = _xyz(lst, lambda d: d["pose"]["pose"]["position"])
    np.testing.assert_allclose(lp[["pos_n_m", "pos_e_m", "pos_d_m"]].to_numpy(), pos[:, [1, 0, 2]] * [1, 1, -1])
    q = np.array([[d["pose"]["pose"]["orientation"][c] for c in "wxyz"] for _r, d in lst])
    v_enu = np.einsum("nij,nj->ni", _dcm(q), _xyz(lst, lambda d: d["twist"]["twist"]["linear"]))
    np.testing.assert_allclose(lp[["vel_n_mps", "vel_e_mps", "vel_d_mps"]].to_numpy(),
                               v_enu[:, [1, 0, 2]] * [1, 1, -1], atol=1e-12)
    assert log.meta["frames"]["local_position"]["frame_id"] == "odom"


@pytest.mark.parametrize("cfg, words", [
    ({"ros": {"topics": {"/imu/data": "gps"}}}, "cannot go to stream 'gps'"),
    ({"ros": {"topics": {"/imu/data": "nonsense"}}}, "'nonsense' is not null or False or 'ignore' or one of imu, gps"),
    ({"ros": {"custom": {"/radar": {"stream": "radar", "fields": {"range": "range"}}}}}, "not column"),
    ({"ros": {"custom": {"/radar": {"type": "x/msg/Y", "stream": "radar", "fields": {"range_m": "range"}}}}},
     "expects type"),
    ({"ros": {"custom": {"/radar": {"stream": "radar", "fields": {"range_m": "no.such"}}}}}, "no.such"),
    ({"ros": {"topics": {"/chatter": "mode"}}}, "no built-in mapping"),
])
def test_bad_config_is_a_clear_error(cfg, words, msgs, tmp_path):
    path = write_ros1bag(tmp_path / "b.bag", msgs)
    with pytest.raises(IngestError) as ei:
        Ros1BagReader().read(path, config=cfg)
    assert str(path) in str(ei.value) and words in str(ei.value)


def test_frd_ned_suffixed_frames_are_not_converted(rng, tmp_path):
    """REP 103 ``_ned``/``_frd`` frames are already in our conventions."""
    msgs = make_messages(rng, 4)
    keep = {k: msgs[k] for k in ("/imu/data", "/pose")}
    for _r, d in keep["/imu/data"][1]:
        d["header"]["frame_id"] = "imu_frd"
    for _r, d in keep["/pose"][1]:
        d["header"]["frame_id"] = "map_ned"
    log = McapReader().read(write_mcap_json(tmp_path / "n.mcap", keep))
    np.testing.assert_allclose(log["imu"][["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy(),
                               _xyz(keep["/imu/data"][1], lambda d: d["linear_acceleration"]))
    np.testing.assert_allclose(log["local_position"][["pos_n_m", "pos_e_m", "pos_d_m"]].to_numpy(),
                               _xyz(keep["/pose"][1], lambda d: d["pose"]["position"]))


def test_detection_rule_both_ways(msgs, tmp_path):
    """A ROS 2 bag directory (or its metadata.yaml) -> rosbag2 reader; the bare .mcap inside it
    -> MCAP reader; both give the same canonical values. A .db3 alone is refused clearly."""
    mbag = write_ros2bag(tmp_path / "mb", msgs, "mcap")
    mfile = next(mbag.glob("*.mcap"))
    assert registry.detect(mbag)[0] is Ros2BagReader
    assert registry.detect(mbag / "metadata.yaml")[0] is Ros2BagReader
    assert registry.detect(mfile)[0] is McapReader
    assert registry.detect(write_ros1bag(tmp_path / "x.bag", msgs))[0] is Ros1BagReader
    a = registry.read_log(mbag, config=CONFIG)
    b = registry.read_log(mfile, config=CONFIG)
    c = registry.read_log(mbag / "metadata.yaml", config=CONFIG)
    assert (a.meta["reader"], b.meta["reader"]) == ("rosbag2", "mcap")
    for s in a.streams:
        pd.testing.assert_frame_equal(a[s], b[s], obj=s)
        pd.testing.assert_frame_equal(a[s], c[s], obj=s)
    check_log(b, msgs)

    sq = write_ros2bag(tmp_path / "sq", msgs, "sqlite3")
    db3 = next(sq.glob("*.db3"))
    with pytest.raises(IngestError) as ei:
        registry.read_log(db3)
    assert str(db3) in str(ei.value) and f"bag directory {sq}" in str(ei.value)
    alone = tmp_path / "alone.db3"
    alone.write_bytes(db3.read_bytes())
    with pytest.raises(IngestError, match="metadata.yaml"):
        registry.read_log(alone)


def test_sqlite3_bag_without_stored_definitions(msgs, tmp_path):
    """Older rosbag2 bags carry no message definitions: stock types decode from the default
    store; the custom type cannot, and its messages are counted, not lost silently."""
    import sqlite3

    bag = write_ros2bag(tmp_path / "nodefs", msgs, "sqlite3")
    db3 = next(bag.glob("*.db3"))
    con = sqlite3.connect(db3)
    with con:
        con.execute("DELETE FROM message_definitions")
    con.close()
    log = Ros2BagReader().read(bag, config=CONFIG)
    diag = log.meta["diagnostics"]
    assert diag["records_dropped"] == {"unknown_type:/radar": N}
    assert log.meta["status"] == "partial" and len(log["radar"]) == 0
    imu = _rows(log["imu"], "/imu/data")
    np.testing.assert_allclose(imu["acc_y_mps2"], -_arr(msgs["/imu/data"][1], lambda d: d["linear_acceleration"]["y"]))
    assert len(log["gps"]) == len(log["baro"]) == len(log["mag"]) == N


def test_project_config_section_is_valid(msgs, tmp_path):
    """datasets/config.yaml's ingest section parses, and the simulator's topics decode with it."""
    from pipeline.config import load_config, section
    from pipeline.io.ros_common import RosConfig

    ingest = section(load_config(), "ingest")
    cfg = RosConfig.from_config(ingest)
    assert cfg.topics["/rangefinder"] == {"stream": "rangefinder", "orientation": 25}
    assert RADAR_TYPE in cfg.custom_types
    renamed = {("/rangefinder" if k == "/sonar" else k): v for k, v in msgs.items()}
    log = McapReader().read(write_mcap_ros2(tmp_path / "s.mcap", renamed), config=ingest)
    assert (log["rangefinder"]["orientation"] == 25).all() and len(log["rangefinder"]) == N
    assert len(log["radar"]) == N
