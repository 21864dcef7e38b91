"""ROS 1 bag and ROS 2 (MCAP storage) bag readers on the real Husky logs, against library oracles.

* ``test1.bag`` (ROS 1) is checked against rosbags' high-level ``AnyReader`` (its own type store
  from the bag's definitions), the ROS 2 bag directory against the ``mcap`` library with the
  ``mcap_ros2`` decoder (an independent CDR decoder): every stream the source contains
  (imu, attitude, gps, odometry), every sample, after the documented conversion
  (FLU->FRD, orientation FLU->ENU -> FRD->NED, odometry as logged).
* Frame conversion: FRD y/z are the negated FLU y/z of the raw IMU message on every sample; at
  rest (odometry |v| < 0.01 m/s, |omega| < 0.01 rad/s) |acc| = 9.80 +- 0.05 m/s^2 (the IMU mount
  is not applied here); NavSatFix/odometry frames are in ``meta['frames']``.
"""

from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from helpers import realdata_file
from pipeline.io import registry
from pipeline.io.rosbag import Ros1BagReader, Ros2BagReader

BAG1 = "ros1_husky_imu_gps/test1.bag"
BAG2 = "ros2mcap_husky_imu_gps"
IMU, FIX, ODOM = "/imu/data", "/fix", "/husky_velocity_controller/odom"
COUNTS = {IMU: 11865, FIX: 989, ODOM: 3952}

pytestmark = pytest.mark.realdata


def _stamp(m) -> int:
    s = m.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def expected_streams(raw: dict[str, list[tuple[int, object]]]) -> dict[str, pd.DataFrame]:
    """Closed-form canonical values from oracle-decoded messages ``{topic: [(record_ns, msg)]}``."""
    t = {k: np.array([(_stamp(m) or rec) for rec, m in v], dtype=np.int64) for k, v in raw.items()}
    t0 = min(int(x.min()) for x in t.values())
    imu = raw[IMU]
    g = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for _r, m in imu])
    a = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z] for _r, m in imu])
    q = np.array([[m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z] for _r, m in imu])
    # R_ned_frd = C_ned_enu R_enu_flu C_flu_frd, via scipy (scalar-last)
    r = np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]]) @ Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix() \
        @ np.diag([1.0, -1, -1])
    fix = raw[FIX]
    odo = raw[ODOM]
    return {
        "imu": pd.DataFrame({"t_ns": t[IMU] - t0, "gyr_x_radps": g[:, 0], "gyr_y_radps": -g[:, 1],
                             "gyr_z_radps": -g[:, 2], "acc_x_mps2": a[:, 0], "acc_y_mps2": -a[:, 1],
                             "acc_z_mps2": -a[:, 2]}),
        "attitude_dcm": r,
        "gps": pd.DataFrame({"t_ns": t[FIX] - t0,
                             "lat_deg": [m.latitude for _r, m in fix], "lon_deg": [m.longitude for _r, m in fix],
                             "alt_wgs84_m": [m.altitude for _r, m in fix],
                             "fix_type": [{-1: 1.0, 0: 3.0, 1: 4.0, 2: 4.0}[m.status.status] for _r, m in fix],
                             "hacc_m": [np.sqrt(max(m.position_covariance[0], m.position_covariance[4]))
                                        for _r, m in fix],
                             "vacc_m": [np.sqrt(m.position_covariance[8]) for _r, m in fix]}),
        "odometry": pd.DataFrame({
            "t_ns": t[ODOM] - t0,
            **{f"pos_{c}_m": [getattr(m.pose.pose.position, c) for _r, m in odo] for c in "xyz"},
            **{f"vel_{c}_mps": [getattr(m.twist.twist.linear, c) for _r, m in odo] for c in "xyz"},
            "yaw_rate_radps": [m.twist.twist.angular.z for _r, m in odo]}),
        "t0": t0,
    }


def check_against(log, raw) -> None:
    """Every stream and sample of ``log`` equals the oracle after the documented conversion."""
    exp = expected_streams(raw)
    assert {s for s, df in log.streams.items() if len(df)} == {"imu", "attitude", "gps", "odometry"}
    assert log.meta["t0_utc_ns"] == exp["t0"]
    for s in ("imu", "gps", "odometry"):
        got = log[s]
        assert len(got) == len(exp[s]) == COUNTS[{"imu": IMU, "gps": FIX, "odometry": ODOM}[s]]
        assert (got["instance"] == 0).all()
        e = exp[s]
        np.testing.assert_array_equal(got["t_ns"].to_numpy(), e["t_ns"].to_numpy(), err_msg=s)
        for c in e.columns:
            np.testing.assert_allclose(got[c].to_numpy(dtype=float), e[c].to_numpy(dtype=float),
                                       rtol=0, atol=1e-12, err_msg=f"{s}.{c}")
    att = log["attitude"]
    np.testing.assert_array_equal(att["t_ns"].to_numpy(), exp["imu"]["t_ns"].to_numpy())
    q = att[["q_w", "q_x", "q_y", "q_z"]].to_numpy()
    r = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    np.testing.assert_allclose(r, exp["attitude_dcm"], atol=1e-9)


@functools.lru_cache(maxsize=4)
def rosbags_oracle(path: Path) -> dict[str, list[tuple[int, object]]]:
    from rosbags.highlevel import AnyReader

    out: dict[str, list] = {}
    with AnyReader([path]) as r:
        for conn, ts, raw in r.messages():
            out.setdefault(conn.topic, []).append((ts, r.deserialize(raw, conn.msgtype)))
    return out


@functools.lru_cache(maxsize=2)
def mcap_oracle(path: Path) -> dict[str, list[tuple[int, object]]]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out: dict[str, list] = {}
    with open(path, "rb") as fh:
        for _s, ch, msg, dec in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                log_time_order=True):
            out.setdefault(ch.topic, []).append((msg.log_time, dec))
    return out


def timed_read(rel: str):
    """Ingest one real file: (FlightLog, seconds taken, path)."""
    path = realdata_file(rel)
    t = time.perf_counter()
    log = registry.read_log(path)
    return log, time.perf_counter() - t, path


@pytest.fixture(scope="module")
def ros1_log():
    return timed_read(BAG1)


@pytest.fixture(scope="module")
def ros2_log():
    return timed_read(BAG2)


def test_ros1_bag_equals_rosbags_oracle(ros1_log):
    log, secs, path = ros1_log
    assert log.meta["reader"] == "rosbag1" and log.meta["status"] == "ok"
    assert secs < 10, f"ingest took {secs:.1f} s"
    check_against(log, rosbags_oracle(path))


def test_ros2_mcap_bag_equals_mcap_oracle(ros2_log):
    log, secs, path = ros2_log
    assert log.meta["reader"] == "rosbag2" and log.meta["diagnostics"]["storage"] == "mcap"
    assert secs < 10, f"ingest took {secs:.1f} s"
    check_against(log, mcap_oracle(path / "husky_mcap.mcap"))


def test_ros1_and_ros2_copies_agree(ros1_log, ros2_log):
    for s in ("imu", "attitude", "gps", "odometry"):
        pd.testing.assert_frame_equal(ros1_log[0][s], ros2_log[0][s], obj=s)


@pytest.mark.parametrize("which", ["ros1", "ros2"])
def test_husky_frame_conversion(which, ros1_log, ros2_log):
    log, _secs, path = ros1_log if which == "ros1" else ros2_log
    raw = rosbags_oracle(path)
    imu = log["imu"]
    flu = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
                    for _r, m in raw[IMU]])
    gflu = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for _r, m in raw[IMU]])
    # FRD y, z == -FLU y, z on every sample; x unchanged
    np.testing.assert_array_equal(imu["acc_y_mps2"].to_numpy(), -flu[:, 1])
    np.testing.assert_array_equal(imu["acc_z_mps2"].to_numpy(), -flu[:, 2])
    np.testing.assert_array_equal(imu["acc_x_mps2"].to_numpy(), flu[:, 0])
    np.testing.assert_array_equal(imu["gyr_y_radps"].to_numpy(), -gflu[:, 1])
    np.testing.assert_array_equal(imu["gyr_z_radps"].to_numpy(), -gflu[:, 2])

    # at rest per odometry: |acc| = 9.80 +- 0.05 on every sample
    odo = raw[ODOM]
    t_od = log["odometry"]["t_ns"].to_numpy()
    v = np.array([np.linalg.norm([m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.linear.z])
                  for _r, m in odo])
    w = np.array([np.linalg.norm([m.twist.twist.angular.x, m.twist.twist.angular.y, m.twist.twist.angular.z])
                  for _r, m in odo])
    t_imu = imu["t_ns"].to_numpy()
    i = np.clip(np.searchsorted(t_od, t_imu), 1, len(t_od) - 1)
    near = np.where(np.abs(t_od[i - 1] - t_imu) <= np.abs(t_od[i] - t_imu), i - 1, i)
    rest = (v[near] < 0.01) & (w[near] < 0.01) & (np.abs(t_od[near] - t_imu) < 100_000_000)
    assert rest.sum() > 100
    acc = np.linalg.norm(imu[["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_numpy(), axis=1)
    assert np.all(np.abs(acc[rest] - 9.80) <= 0.05), (acc[rest].min(), acc[rest].max())
    assert abs(acc[rest].mean() - 9.80) < 0.01
    # the mount is NOT applied here: gravity's reaction stays on the sensor's (FRD) -y axis
    assert imu["acc_y_mps2"].to_numpy()[rest].mean() < -9.7

    fr = log.meta["frames"]
    assert fr["world"] == "NED" and fr["body"] == "FRD"
    assert fr["gps"] == {"topic": FIX, "frame_id": "/gps"}
    assert fr["odometry"] == {"topic": ODOM, "frame_id": "odom", "child_frame_id": "base_link"}
    assert fr["topics"][IMU]["frame_id"] == "imu_link"
    first = next(m for _r, m in raw[FIX] if m.status.status >= 0)
    assert log.meta["ned_origin"] == {"lat_deg": first.latitude, "lon_deg": first.longitude,
                                      "alt_wgs84_m": first.altitude}


def test_reader_classes_claim_only_their_format(tmp_path):
    bag = realdata_file(BAG1)
    with bag.open("rb") as fh:
        head = fh.read(64)
    assert Ros1BagReader.sniff(bag, head)
    assert not Ros2BagReader.sniff(bag, head)
    d = realdata_file(BAG2)
    assert Ros2BagReader.sniff(d, b"") and not Ros1BagReader.sniff(d, b"")
    (tmp_path / "x.bag").write_bytes(b"#ROSBAG V1.2\n" + b"\0" * 100)
    assert not Ros1BagReader.sniff(tmp_path / "x.bag", (tmp_path / "x.bag").read_bytes())


def test_rosbag2_forced_on_a_single_file_says_a_bag_is_a_folder(tmp_path):
    from pipeline.io.base import IngestError
    from pipeline.io.registry import read_log

    f = tmp_path / "flight.csv"
    f.write_text("t,x\n0,1\n")
    with pytest.raises(IngestError, match="a ROS 2 bag is a folder holding metadata.yaml and its storage file"):
        read_log(f, fmt="rosbag2")
