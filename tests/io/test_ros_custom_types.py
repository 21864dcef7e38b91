"""Custom ROS message types mapped with no config (issue 13, defect 9), on fixtures written by
the libraries' own writers (rosbags ROS 1 bag, rosbags ROS 2 MCAP-storage bag, mcap_ros2 MCAP):

* a custom message embedding ``sensor_msgs/Imu``, ``MagneticField`` and ``NavSatFix`` maps
  through them: its ``imu``/``attitude``/``mag``/``gps`` rows equal those of the same messages
  written on their own standard topics (the oracle), only ``src`` and ``instance`` differ;
* a custom message whose float fields carry NavSatFix names maps to ``gps``;
* a custom type *configured* to ``gps`` (it has no ``status``) no longer crashes: the NED
  origin is the first finite fix of any gps source;
* a NavSatFix that never gets a fix (status −1, lat = lon = 0) gives a null origin with its
  reason and a warning (defect 11).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from pipeline.io import registry

_spec = importlib.util.spec_from_file_location(
    "_ros_fixture_writers_custom", Path(__file__).with_name("test_ros_fixtures.py"))
fx = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fx)

PACK_TYPE = "my_msgs/msg/SensorPack"
PACK_MSG = ("std_msgs/Header header\nsensor_msgs/Imu imu\nsensor_msgs/MagneticField mag\n"
            "sensor_msgs/NavSatFix fix\nfloat32 battery\n")
GEO_TYPE = "my_msgs/msg/GeoFix"
GEO_MSG = "std_msgs/Header header\nfloat64 latitude\nfloat64 longitude\nfloat64 altitude\nuint8 quality\n"
T0 = 1_700_000_000_000_000_000
N = 8


def _store(ros1: bool):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    ts.register({**get_types_from_msg(PACK_MSG, PACK_TYPE), **get_types_from_msg(GEO_MSG, GEO_TYPE)})
    return ts


def _messages(rng: np.random.Generator, *, fix_ok: bool = True) -> dict:
    """``{topic: (type, [(record ns, dict)])}``: the pack, the same parts on standard topics,
    and the NavSatFix-named custom fix (starting 10 ms after the pack's first fix)."""
    out = {k: (t, []) for k, t in (("/pack", PACK_TYPE), ("/ref/imu", "sensor_msgs/msg/Imu"),
                                   ("/ref/mag", "sensor_msgs/msg/MagneticField"),
                                   ("/ref/fix", "sensor_msgs/msg/NavSatFix"), ("/geo", GEO_TYPE))}
    for k in range(N):
        t = T0 + k * 100_000_000
        q = rng.normal(size=4)
        imu = {"header": fx._hdr(t + 1000, "imu_link"), "orientation": fx._q(q / np.linalg.norm(q)),
               "orientation_covariance": [0.01] + [0.0] * 8, "angular_velocity": fx._v3(rng.normal(size=3)),
               "angular_velocity_covariance": [0.0] * 9,
               "linear_acceleration": fx._v3(rng.normal(size=3) + [0, 0, 9.8]),
               "linear_acceleration_covariance": [0.0] * 9}
        mag = {"header": fx._hdr(t + 2000, "mag_link"), "magnetic_field": fx._v3(rng.normal(size=3) * 2e-5),
               "magnetic_field_covariance": [0.0] * 9}
        lat, lon = (47.0 + 1e-5 * k, 8.0 - 1e-5 * k) if fix_ok else (0.0, 0.0)
        fix = {"header": fx._hdr(t + 3000, "gps"), "status": {"status": 0 if fix_ok else -1, "service": 1},
               "latitude": lat, "longitude": lon, "altitude": 400.0 + k if fix_ok else 0.0,
               "position_covariance": [1.0, 0, 0, 0, 1.0, 0, 0, 0, 4.0], "position_covariance_type": 2}
        out["/pack"][1].append((t + 5000, {"header": fx._hdr(t, "base_link"), "imu": imu, "mag": mag,
                                           "fix": fix, "battery": 12.5}))
        out["/ref/imu"][1].append((t + 5000, imu))
        out["/ref/mag"][1].append((t + 5000, mag))
        out["/ref/fix"][1].append((t + 5000, fix))
        out["/geo"][1].append((t + 10_000_000, {"header": fx._hdr(t + 10_000_000, "gps2"),
                                                "latitude": 46.9 + 1e-5 * k, "longitude": 7.9,
                                                "altitude": 390.0, "quality": 4}))
    return out


def _write(kind: str, tmp: Path, msgs: dict) -> Path:
    ros1 = kind == "ros1bag"
    ts = _store(ros1)
    rows = fx._ordered(msgs)
    if kind == "ros1bag":
        from rosbags.rosbag1 import Writer

        path = tmp / "custom.bag"
        with Writer(path) as w:
            conns = {t: w.add_connection(t, typ, typestore=ts) for t, (typ, _m) in msgs.items()}
            for rec, topic, typ, d in rows:
                w.write(conns[topic], rec, ts.serialize_ros1(fx.build(ts, typ, d), typ))
        return path
    if kind == "ros2mcap":
        from rosbags.rosbag2 import StoragePlugin, Writer

        path = tmp / "custom_bag"
        with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            conns = {t: w.add_connection(t, typ, typestore=ts) for t, (typ, _m) in msgs.items()}
            for rec, topic, typ, d in rows:
                w.write(conns[topic], rec, ts.serialize_cdr(fx.build(ts, typ, d), typ))
        return path
    from mcap_ros2.writer import Writer

    path = tmp / "custom.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        schemas = {t: w.register_msgdef(typ, ts.generate_msgdef(typ, ros_version=2)[0])
                   for t, (typ, _m) in msgs.items()}
        for rec, topic, typ, d in rows:
            w.write_message(topic, schemas[topic], d, log_time=rec, publish_time=rec)
        w.finish()
    return path


def _rows(log, stream: str, src: str):
    df = log[stream]
    return df[df["src"].astype(str) == src].drop(columns=["src", "instance"]).reset_index(drop=True)


@pytest.mark.parametrize("kind", ["ros1bag", "ros2mcap", "mcap"])
def test_custom_message_embedding_standard_ones_maps_through_them(kind, tmp_path):
    msgs = _messages(np.random.default_rng(13))
    log = registry.read_log(_write(kind, tmp_path, msgs))
    for stream, part in (("imu", "imu"), ("attitude", "imu"), ("mag", "mag"), ("gps", "fix")):
        ours = _rows(log, stream, f"/pack.{part}")
        ref = _rows(log, stream, f"/ref/{part}")
        assert len(ours) == N, (stream, len(ours))
        np.testing.assert_array_equal(ours.to_numpy(dtype=np.float64, na_value=np.nan),
                                      ref.to_numpy(dtype=np.float64, na_value=np.nan))
    # the embedded messages keep their own stamps (ns), FLU -> FRD applied as for /ref/imu
    imu = _rows(log, "imu", "/pack.imu")
    t_imu = np.array([d["imu"]["header"]["stamp"]["sec"] * 10**9 + d["imu"]["header"]["stamp"]["nanosec"]
                      for _r, d in msgs["/pack"][1]])
    np.testing.assert_array_equal(imu["t_ns"].to_numpy() + log.meta["t0_utc_ns"], t_imu)
    np.testing.assert_allclose(imu["gyr_y_radps"], [-d["imu"]["angular_velocity"]["y"] for _r, d in msgs["/pack"][1]])
    inf = log.meta["diagnostics"]["inferred_mappings"]
    assert set(inf["/pack"]["streams"]) == {"/pack.imu", "/pack.mag", "/pack.fix"}
    assert inf["/pack"]["type"] == PACK_TYPE and "sensor_msgs/msg/Imu -> imu" in inf["/pack"]["mapping"]
    assert log.meta["frames"]["topics"]["/pack.imu"]["inferred"].startswith("embedded field 'imu'")
    assert "/pack" not in log.meta["diagnostics"]["unmapped_topics"]


@pytest.mark.parametrize("kind", ["ros1bag", "mcap"])
def test_custom_message_with_navsatfix_field_names_maps_to_gps(kind, tmp_path):
    msgs = _messages(np.random.default_rng(14))
    log = registry.read_log(_write(kind, tmp_path, msgs))
    geo = _rows(log, "gps", "/geo")
    assert len(geo) == N
    np.testing.assert_array_equal(geo["lat_deg"], [d["latitude"] for _r, d in msgs["/geo"][1]])
    np.testing.assert_array_equal(geo["alt_wgs84_m"], 390.0)
    assert log.meta["diagnostics"]["inferred_mappings"]["/geo"]["mapping"].startswith("NavSatFix field names")
    # origin: the earliest finite fix of any gps source (the pack's, 10 ms before /geo's)
    first = msgs["/ref/fix"][1][0][1]
    assert log.meta["ned_origin"] == {"lat_deg": first["latitude"], "lon_deg": first["longitude"],
                                      "alt_wgs84_m": first["altitude"]}


def test_custom_type_configured_to_gps_gets_its_origin_without_navsatstatus(tmp_path):
    """The former ``KeyError: '_status'``: a configured custom gps mapping, no NavSatFix at all."""
    msgs = {"/geo": _messages(np.random.default_rng(15))["/geo"]}
    cfg = {"ros": {"custom_types": {GEO_TYPE: {"stream": "gps", "fields": {"lat_deg": "latitude",
                                                                           "lon_deg": "longitude"}}}}}
    log = registry.read_log(_write("ros1bag", tmp_path, msgs), config=cfg)
    assert len(log["gps"]) == N
    assert log.meta["ned_origin"] == {"lat_deg": 46.9, "lon_deg": 7.9, "alt_wgs84_m": None}
    assert "inferred_mappings" not in log.meta["diagnostics"]  # configured, not inferred


def test_navsatfix_without_a_fix_gives_a_null_origin_with_its_reason(tmp_path):
    msgs = _messages(np.random.default_rng(16), fix_ok=False)
    msgs = {k: msgs[k] for k in ("/ref/fix", "/ref/imu")}
    log = registry.read_log(_write("mcap", tmp_path, msgs))
    assert log.meta["ned_origin"] is None
    reason = log.meta["ned_origin_reason"]
    assert "never got a fix" in reason and f"{N} at lat = lon = 0" in reason
    assert reason in log.meta["diagnostics"]["warnings"]
    gps = log["gps"]
    assert len(gps) == N and gps["lat_deg"].isna().all() and gps["lon_deg"].isna().all()
    assert log.meta["diagnostics"]["gps_zero_positions"] == N
