"""The standalone MCAP reader on the real Husky MCAP file (ROS 2 CDR), against the rosbags oracle,
and the one detection rule: the bag directory goes to the rosbag2 reader, the bare ``.mcap``
inside it to the MCAP reader, and both give identical canonical values."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pandas as pd
import pytest

from pipeline.io import registry
from pipeline.io.mcap_reader import McapReader
from pipeline.io.rosbag import Ros2BagReader

pytestmark = pytest.mark.realdata

_spec = importlib.util.spec_from_file_location("_ros_real_helpers", Path(__file__).with_name("test_rosbag_reader.py"))
_rb = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_rb)

MCAP = "ros2mcap_husky_imu_gps/husky_mcap.mcap"


@pytest.fixture(scope="module")
def mcap_log():
    return _rb.timed_read(MCAP)


def test_mcap_file_equals_rosbags_oracle(mcap_log):
    log, secs, path = mcap_log
    assert log.meta["reader"] == "mcap" and log.meta["status"] == "ok"
    assert log.meta["diagnostics"]["encodings"] == ["cdr"]
    assert log.meta["diagnostics"]["bytes_skipped"] == 0
    assert secs < 10, f"ingest took {secs:.1f} s"
    _rb.check_against(log, _rb.rosbags_oracle(path.parent))


def test_detection_rule_on_the_real_bag(mcap_log):
    log, _secs, path = mcap_log
    assert registry.detect(path)[0] is McapReader
    assert registry.detect(path.parent)[0] is Ros2BagReader
    bag = registry.read_log(path.parent)
    assert bag.meta["reader"] == "rosbag2"
    for s in log.streams:
        pd.testing.assert_frame_equal(log[s], bag[s], obj=s)
    assert log.meta["frames"] == bag.meta["frames"]
    assert log.meta["ned_origin"] == bag.meta["ned_origin"]
