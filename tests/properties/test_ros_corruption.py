"""Corruption suite for the ROS 1 bag, ROS 2 bag and MCAP readers.

Every damaged input must end in either an :class:`IngestError` whose one line names the file and
a specific reason (not the registry's generic "reader failed" wrapper), or a partial
``FlightLog`` whose losses are counted in ``meta['diagnostics']`` — never another exception —
and within 10 s. Cases: truncated bag, truncated MCAP (standalone and inside a ROS 2 bag),
random bytes behind a bag/MCAP header, bag directories with a broken ``metadata.yaml``, and
Hypothesis-driven truncations and byte flips of small fixtures written at test time.
"""

from __future__ import annotations

import importlib.util
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import TEST_SEED, realdata_file
from pipeline.io import registry
from pipeline.io.base import FlightLog, IngestError
from pipeline.io.mcap_reader import McapReader
from pipeline.io.rosbag import Ros1BagReader, Ros2BagReader

# a sweep of damaged bags (hypothesis): the full suite runs it; the fast lane keeps the
# damaged-log cases of tests/io (one fixed damage each)
pytestmark = pytest.mark.slow

_spec = importlib.util.spec_from_file_location(
    "_ros_fixture_writers", Path(__file__).parents[1] / "io" / "test_ros_fixtures.py")
fx = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fx)

LIMIT_S = 10.0


def outcome(reader_cls, path: Path) -> str:
    """Read ``path``; return ``"error"`` or ``"partial"``/``"ok"``; fail on anything else."""
    t = time.perf_counter()
    try:
        log = reader_cls().read(path)
    except IngestError as exc:
        msg = str(exc)
        assert msg.startswith(f"{path}: ") and exc.reason, msg
        assert "reader failed" not in msg and "\n" not in msg.strip(), msg
        res = "error"
    else:
        assert isinstance(log, FlightLog)
        d = log.meta["diagnostics"]
        lost = bool(d["bytes_skipped"] or d["records_dropped"])
        assert log.meta["status"] == ("partial" if lost else "ok")
        res = log.meta["status"]
    assert time.perf_counter() - t <= LIMIT_S
    return res


def against_clean(reader_cls, path: Path, clean: FlightLog, n_messages: int, flipped: bool = False) -> str:
    """:func:`outcome`, then what a read of damaged ``path`` must keep relative to the clean
    read of the same fixture. The readers do not promise an exact message accounting: the
    messages lost behind a truncation or a broken record header are counted in
    ``bytes_skipped`` (bytes), not per message, so rows + ``records_dropped`` can fall short of
    ``n_messages``. What they do promise: "ok" means nothing was lost, so every stream has the
    clean read's rows at the clean read's times, and the same records per type; a partial read
    never invents messages: the records read plus those counted dropped never exceed the
    messages written, and after a truncation no stream is longer than in the clean read. A byte
    flip may lengthen a stream (a flipped ``frame_id`` byte in a ROS 1 ``/pose`` message makes
    it a second attitude instance: 25 rows for 24), as no ROS format checksums its messages."""
    res = outcome(reader_cls, path)
    if res == "error":
        return res
    log = reader_cls().read(path)
    d, ref = log.meta["diagnostics"], clean.meta["diagnostics"]
    for s in clean.streams:
        assert flipped or len(log[s]) <= len(clean[s]), s
    assert sum(d["record_counts"].values()) + sum(d["records_dropped"].values()) <= n_messages
    if res == "ok":
        assert d["record_counts"] == ref["record_counts"]
        for s in (s for s in clean.streams if "t_ns" in clean[s]):  # not labels (intervals)
            # times exact; values may differ: a flipped payload byte has no checksum to fail
            np.testing.assert_array_equal(_absolute(log, s)["t_abs"], _absolute(clean, s)["t_abs"], err_msg=s)
    return res


@pytest.fixture(scope="module")
def clean(small):
    """The undamaged read of each fixture."""
    readers = dict(FILE_KINDS, ros2sqlite3=Ros2BagReader, ros2mcap=Ros2BagReader)
    return {k: r().read(small[k]) for k, r in readers.items()}


def test_the_clean_fixtures_read_every_message(small, clean):
    # 12 topics x 12 messages; /chatter (std_msgs/String) has no mapping and is not counted
    assert small["n_messages"] == 144
    for k, log in clean.items():
        d = log.meta["diagnostics"]
        assert log.meta["status"] == "ok" and d["records_dropped"] == {}, k
        assert sum(d["record_counts"].values()) == small["n_messages"] - 12, k
        assert {s: len(log[s]) for s in ("imu", "gps", "attitude", "radar")} == \
            {"imu": 24, "gps": 12, "attitude": 24, "radar": 12}, k


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """Small fixtures of each kind (bytes of single files; directories as paths)."""
    tmp = tmp_path_factory.mktemp("rosfx")
    msgs = fx.make_messages(np.random.default_rng(TEST_SEED), 12)
    out = {k: fx.write_fixture(k, tmp, msgs) for k in fx.KINDS}
    out["n_messages"] = sum(len(v[1]) for v in msgs.values())
    return out


# --- fixed cases -----------------------------------------------------------------------------


def test_truncated_small_ros1_bag(small, tmp_path):
    data = small["ros1bag"].read_bytes()
    seen = set()
    for frac in (0.001, 0.05, 0.5, 0.95, 0.999):
        p = tmp_path / f"t{frac}.bag"
        p.write_bytes(data[: int(len(data) * frac)])
        res = outcome(Ros1BagReader, p)
        seen.add(res)
        if res == "error":
            with pytest.raises(IngestError, match="sequential scan|no messages"):
                Ros1BagReader().read(p)
    assert seen == {"error", "partial"}


def _absolute(log, stream):
    df = log[stream]
    return df.assign(t_abs=df["t_ns"] + log.meta["t0_utc_ns"]).drop(columns="t_ns")


@pytest.mark.slow  # reads a real bag end to end (fast lane: the small synthetic bag above)
def test_truncated_real_ros1_bag_keeps_the_messages_before_the_cut(tmp_path):
    src = realdata_file("ros1_husky_imu_gps/test1.bag")
    full = Ros1BagReader().read(src)
    data = src.read_bytes()
    p = tmp_path / "husky_trunc.bag"
    p.write_bytes(data[: len(data) // 2])
    assert outcome(Ros1BagReader, p) == "partial"
    log = Ros1BagReader().read(p)
    d = log.meta["diagnostics"]
    assert 0 < d["bytes_skipped"] < len(data) // 2 and "without the index" in d["warnings"][0]
    for s in ("imu", "attitude", "gps", "odometry"):
        got, ref = _absolute(log, s), _absolute(full, s)
        assert 0 < len(got) < len(ref)
        pd.testing.assert_frame_equal(got, ref.iloc[: len(got)].reset_index(drop=True), obj=s)


@pytest.mark.slow  # reads a real bag end to end (fast lane: the small synthetic bag above)
def test_truncated_real_mcap(tmp_path):
    src = realdata_file("ros2mcap_husky_imu_gps/husky_mcap.mcap")
    data = src.read_bytes()
    p = tmp_path / "husky_trunc.mcap"
    p.write_bytes(data[: len(data) // 2])
    assert outcome(McapReader, p) == "partial"
    log = McapReader().read(p)
    d = log.meta["diagnostics"]
    assert 0 < d["bytes_skipped"] < len(data) // 2
    assert 0 < len(log["imu"]) < 11865  # the messages before the cut survive
    assert "unreadable from byte" in d["warnings"][-1]

    # the same damage inside a ROS 2 bag directory: rosbags refuses, sequential read recovers
    bagdir = tmp_path / "bag"
    bagdir.mkdir()
    shutil.copy(src.parent / "metadata.yaml", bagdir)
    (bagdir / src.name).write_bytes(data[: len(data) // 2])
    assert outcome(Ros2BagReader, bagdir) == "partial"
    log2 = Ros2BagReader().read(bagdir)
    assert len(log2["imu"]) == len(log["imu"])
    assert "sequentially" in log2.meta["diagnostics"]["warnings"][0]


@pytest.mark.parametrize("magic, reader", [(b"#ROSBAG V2.0\n", Ros1BagReader), (b"\x89MCAP0\r\n", McapReader)])
@pytest.mark.parametrize("seed", range(5))
def test_random_bytes_behind_a_header(magic, reader, seed, tmp_path):
    rng = np.random.default_rng(TEST_SEED + seed)
    p = tmp_path / "junk.bin"
    p.write_bytes(magic + rng.bytes(int(rng.integers(1, 200_000))))
    assert outcome(reader, p) == "error"
    assert registry.detect(p)[0] is reader
    with pytest.raises(IngestError) as ei:
        registry.read_log(p)
    assert "reader failed" not in str(ei.value)


@pytest.mark.parametrize("content, words", [
    (None, "metadata.yaml unreadable"),  # random bytes
    (b"rosbag2_bagfile_information: [unclosed\n", "metadata.yaml unreadable"),
    (b"just: a mapping\n", "no 'rosbag2_bagfile_information'"),
    (b"rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: sqlite3\n"
     b"  relative_file_paths: [gone_0.db3]\n", "missing: gone_0.db3"),
    (b"", "no 'rosbag2_bagfile_information'"),
])
def test_bag_dir_with_broken_metadata(content, words, tmp_path, small):
    d = tmp_path / "bag"
    shutil.copytree(small["ros2sqlite3"], d)
    if content is None:
        content = np.random.default_rng(TEST_SEED).bytes(400)
    (d / "metadata.yaml").write_bytes(content)
    assert registry.detect(d)[0] is Ros2BagReader
    assert outcome(Ros2BagReader, d) == "error"
    with pytest.raises(IngestError, match=words):
        Ros2BagReader().read(d)


def test_truncated_sqlite3_bag(small, tmp_path):
    src = small["ros2sqlite3"]
    db3 = next(src.glob("*.db3"))
    data = db3.read_bytes()
    results = set()
    for frac in (0.1, 0.5, 0.9):
        d = tmp_path / f"b{frac}"
        shutil.copytree(src, d)
        (d / db3.name).write_bytes(data[: int(len(data) * frac)])
        results.add(outcome(Ros2BagReader, d))
    assert results <= {"error", "partial"}


# --- properties ----------------------------------------------------------------------------


FILE_KINDS = {"ros1bag": Ros1BagReader, "mcap_ros1": McapReader, "mcap_ros2": McapReader,
              "mcap_json": McapReader}


@pytest.mark.parametrize("kind", list(FILE_KINDS))
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.floats(0.0, 1.0, exclude_max=True))
def test_any_truncation(kind, cut, small, clean):
    data = small[kind].read_bytes()
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / small[kind].name
        p.write_bytes(data[: max(1, int(len(data) * cut))])
        res = against_clean(FILE_KINDS[kind], p, clean[kind], small["n_messages"])
    assert res in ("error", "partial")


@pytest.mark.parametrize("kind", list(FILE_KINDS))
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(flips=st.lists(st.tuples(st.floats(0.0, 1.0, exclude_max=True), st.integers(1, 255)),
                      min_size=1, max_size=8))
def test_any_byte_flips(kind, flips, small, clean):
    buf = bytearray(small[kind].read_bytes())
    for pos, x in flips:
        i = 16 + int((len(buf) - 16) * pos)  # keep the magic so the reader under test is the one
        buf[min(i, len(buf) - 1)] ^= x
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / small[kind].name
        p.write_bytes(bytes(buf))
        against_clean(FILE_KINDS[kind], p, clean[kind], small["n_messages"], flipped=True)


@settings(max_examples=8, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.floats(0.0, 1.0, exclude_max=True), which=st.sampled_from(["ros2sqlite3", "ros2mcap"]))
def test_any_truncation_in_a_bag_dir(cut, which, small, clean):
    src = small[which]
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "bag"
        shutil.copytree(src, d)
        f = next(p for p in d.iterdir() if p.name != "metadata.yaml")
        data = f.read_bytes()
        f.write_bytes(data[: int(len(data) * cut)])
        assert against_clean(Ros2BagReader, d, clean[which], small["n_messages"]) in ("error", "partial")
