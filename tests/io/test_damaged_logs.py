"""Damage in the middle of a log: the data after it is kept and the loss is counted, never lost
in silence (project rule on bad input).

* MCAP: chunks mostly carry no CRC, so damage inside an uncompressed chunk shows only as a record
  that does not parse. The chunk's message index names every message: the ones after the damage
  are read at their listed offsets, the ones hit are counted per topic
  (``bad_chunk:<topic>``); without a message index the summary's Statistics record counts what
  is missing (``missing:<topic>``). The same file in a ROS 2 bag folder gives the same result.
* ROS 1 bag (indexed): a chunk that fails to decompress costs that chunk only, its messages
  counted from the index, instead of ending the read.
* ULog: pyulog's data loop ends without a word at a DATA message too short to hold its id;
  the message walk places the damage, cuts it out and decodes the rest.

Synthetic logs are written here with the libraries' writers (``mcap``, ``rosbags``) and
``helpers_ulog.ULogWriter``; the ``realdata`` cases apply the audit's damage (every 7th byte
inverted over 4000 bytes in the middle of the file) to the real logs.
"""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from helpers import TEST_SEED, realdata_file
from helpers_ulog import ULogWriter, add_sensor_combined
from pipeline.io import registry
from pipeline.io.base import losses_text
from pipeline.io.mcap_reader import McapReader
from pipeline.io.rosbag import Ros1BagReader, Ros2BagReader

_spec = importlib.util.spec_from_file_location("_ros_fixture_writers", Path(__file__).with_name("test_ros_fixtures.py"))
fx = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fx)

N = 150  # messages per topic
TOPICS = ("/imu/data", "/fix")


@pytest.fixture(scope="module")
def msgs():
    out = fx.make_messages(np.random.default_rng(TEST_SEED), N)
    return {t: out[t] for t in TOPICS}


def audit_damage(data: bytes) -> bytes:
    """The audit's damage: every 7th byte inverted over 4000 bytes in the middle."""
    buf = bytearray(data)
    mid = len(buf) // 2
    for i in range(mid - 2000, mid + 2000, 7):
        buf[i] ^= 0xFF
    return bytes(buf)


def rows(log) -> dict[str, int]:
    return {"/imu/data": len(log["imu"]), "/fix": len(log["gps"])}


# --- MCAP ----------------------------------------------------------------------------------------

def write_mcap(path: Path, msgs, *, index: bool = True) -> Path:
    """JSON-encoded MCAP with small uncompressed chunks (no CRC, as rosbags writes them)."""
    from mcap.writer import CompressionType, IndexType, Writer

    kinds = IndexType.ALL if index else IndexType.CHUNK
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=8192, compression=CompressionType.NONE, index_types=kinds,
                   enable_crcs=False)
        w.start(profile="", library="uavpipe-tests")
        chans = {}
        for topic, (typ, _m) in msgs.items():
            sid = w.register_schema(name=typ, encoding="jsonschema", data=b'{"type": "object"}')
            chans[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=sid)
        for i, (rec, topic, _typ, d) in enumerate(fx._ordered(msgs)):
            w.add_message(chans[topic], log_time=rec, publish_time=rec, sequence=i, data=json.dumps(d).encode())
        w.finish()
    return path


def break_message_length(path: Path, msgs, topic: str, k: int) -> None:
    """Make the ``k``-th message of ``topic`` claim more bytes than its chunk holds (one damaged
    length field: the chunk parser cannot step over it)."""
    data = bytearray(path.read_bytes())
    at = data.find(json.dumps(msgs[topic][1][k][1]).encode())
    assert at > 0
    start = at - 31  # opcode, length, channel id, sequence, log_time, publish_time
    assert data[start] == 0x05
    data[start + 1:start + 9] = (0xFFFF_FFFF).to_bytes(8, "little")
    path.write_bytes(bytes(data))


def test_a_damaged_mcap_chunk_keeps_the_messages_after_the_damage_and_counts_the_one_hit(msgs, tmp_path):
    p = write_mcap(tmp_path / "hit.mcap", msgs)
    break_message_length(p, msgs, "/imu/data", N // 2)
    log = McapReader().read(p)
    d = log.meta["diagnostics"]
    assert log.meta["status"] == "partial"
    assert d["records_dropped"] == {"bad_chunk:/imu/data": 1}  # was: the rest of the chunk, uncounted
    assert rows(log) == {"/imu/data": N - 1, "/fix": N}
    assert 0 < d["bytes_skipped"] < 1000
    assert any("damaged at offset" in w and "message index" in w for w in d["warnings"])


def test_a_damaged_mcap_chunk_without_message_index_is_counted_from_the_summary_statistics(msgs, tmp_path):
    p = write_mcap(tmp_path / "noindex.mcap", msgs, index=False)
    break_message_length(p, msgs, "/imu/data", N // 2)
    log = McapReader().read(p)
    d = log.meta["diagnostics"]
    got = rows(log)
    assert log.meta["status"] == "partial"
    assert got["/imu/data"] < N  # the rest of the chunk is lost...
    for t in TOPICS:  # ...but every lost message is counted
        assert got[t] + d["records_dropped"].get(f"missing:{t}", 0) == N, t
    assert d["records_dropped"]["bad_chunk"] == 1
    assert any("Statistics record lists" in w for w in d["warnings"])


def test_the_same_damaged_mcap_in_a_ros2_bag_folder_gives_the_same_messages_and_counts(msgs, tmp_path):
    bag = fx.write_ros2bag(tmp_path / "bag", msgs, "mcap")
    f = next(bag.glob("*.mcap"))
    _break_middle_message(f)
    alone = McapReader().read(f)
    log = Ros2BagReader().read(bag)  # was: IngestError, rosbags parses the chunk whole and gave up
    d = log.meta["diagnostics"]
    assert log.meta["status"] == alone.meta["status"] == "partial"
    assert d["records_dropped"] == alone.meta["diagnostics"]["records_dropped"]
    assert sum(d["records_dropped"].values()) == 1
    assert sum(rows(log).values()) == 2 * N - 1
    assert "rosbags' MCAP storage" in d["warnings"][0] and "sequentially" in d["warnings"][0]


def _break_middle_message(f: Path) -> None:
    """Give the middle message record of the file's uncompressed chunk a length past the chunk's
    end (its offset from the message index that follows the chunk)."""
    from mcap.records import Chunk, MessageIndex
    from mcap.stream_reader import StreamReader

    data = bytearray(f.read_bytes())
    offsets, chunk_at, pos = [], None, 0
    with open(f, "rb") as fh:
        for rec in StreamReader(fh, emit_chunks=True).records:
            if isinstance(rec, Chunk):
                assert chunk_at is None and rec.compression == ""
                chunk_at = pos
            elif isinstance(rec, MessageIndex):
                offsets += [o for _t, o in rec.records]
            pos = fh.tell()
    # chunk record: opcode, length, start/end time, uncompressed size, crc, compression "", records length
    records_at = chunk_at + 1 + 8 + 8 + 8 + 8 + 4 + 4 + 8
    off = sorted(offsets)[len(offsets) // 2]
    assert data[records_at + off] == 0x05
    data[records_at + off + 1:records_at + off + 9] = (0xFFFF_FFFF).to_bytes(8, "little")
    f.write_bytes(bytes(data))


# --- ROS 1 bag ----------------------------------------------------------------------------------

def write_bz2_bag(path: Path, msgs) -> Path:
    """An indexed ROS 1 bag with bz2 chunks of ~4 kB (several chunks)."""
    from rosbags.rosbag1 import Writer

    ts = fx.typestore(ros1=True)
    w = Writer(path)
    w.set_compression(Writer.CompressionFormat.BZ2)
    w.chunk_threshold = 4096
    with w:
        conns = {t: w.add_connection(t, typ, typestore=ts) for t, (typ, _m) in msgs.items()}
        for rec, topic, typ, d in fx._ordered(msgs):
            w.write(conns[topic], rec, ts.serialize_ros1(fx.build(ts, typ, d), typ))
    return path


def test_a_bad_chunk_of_an_indexed_ros1_bag_costs_that_chunk_only(msgs, tmp_path):
    from rosbags.rosbag1 import Reader

    p = write_bz2_bag(tmp_path / "b.bag", msgs)
    with Reader(p) as r:
        infos = r.chunk_infos
        assert len(infos) >= 4
        bad = infos[len(infos) // 2]
        chunk = r.chunks[bad.pos]
        lost = {c.topic: bad.connection_counts.get(c.id, 0) for c in r.connections}
    data = bytearray(p.read_bytes())
    mid = chunk.datapos + chunk.datasize // 2
    data[mid:mid + 64] = bytes(b ^ 0xFF for b in data[mid:mid + 64])
    p.write_bytes(bytes(data))

    log = Ros1BagReader().read(p)
    d = log.meta["diagnostics"]
    assert log.meta["status"] == "partial"
    assert d["records_dropped"] == {f"bad_chunk:{t}": k for t, k in lost.items() if k}  # was: unread_after_error
    assert rows(log) == {t: N - lost[t] for t in TOPICS}
    assert d["bytes_skipped"] == chunk.datasize
    assert any(w.startswith(f"chunk at byte {bad.pos} dropped") for w in d["warnings"])
    full = Ros1BagReader().read(write_bz2_bag(tmp_path / "ok.bag", msgs))
    assert log["imu"]["t_ns"].max() + log.meta["t0_utc_ns"] == full["imu"]["t_ns"].max() + full.meta["t0_utc_ns"]


# --- ULog --------------------------------------------------------------------------------------

def _imu_ulog(n: int = 3000) -> bytes:
    rng = np.random.default_rng(TEST_SEED)
    w = ULogWriter(start_us=1_000_000)
    add_sensor_combined(w, n, rng)
    return w.to_bytes()


def test_a_ulog_whose_data_loop_pyulog_ends_mid_file_decodes_the_rest_and_counts_the_damage(tmp_path):
    raw = bytearray(_imu_ulog())
    pos, heads = 16, []
    while pos + 3 <= len(raw):
        heads.append(pos)
        pos += 3 + (raw[pos] | raw[pos + 1] << 8)
    k = heads[len(heads) // 2]
    assert raw[k + 2] == ord("D")
    size = raw[k] | raw[k + 1] << 8
    raw[k:k + 2] = (1).to_bytes(2, "little")  # a DATA message of 1 byte: pyulog's struct.error
    p = tmp_path / "cut_short.ulg"
    p.write_bytes(bytes(raw))

    log = registry.read_log(p)
    d = log.meta["diagnostics"]
    assert log.meta["status"] == "partial"  # was: 'ok' with the second half (1502 rows) gone
    assert len(log["imu"]) == 3000 - 2  # the message hit and the one before it (its payload is suspect)
    assert log["imu"]["t_ns"].max() == 2999 * 4_000_000  # the end of the flight is there
    assert d["records_dropped"] == {"corrupt": 1}
    assert d["bytes_skipped"] == 2 * (3 + size)
    w = [x for x in d["warnings"] if x.startswith("ULog damaged from byte")]
    assert len(w) == 1 and f"byte {heads[len(heads) // 2 - 1]} " in w[0] and "t = 5.984 s" in w[0]
    assert "resumed there (t = 5.996 s)" in w[0]
    assert "bytes skipped" in losses_text(d)


# --- the audit's damage on the real logs ---------------------------------------------------------

@pytest.mark.realdata
@pytest.mark.slow  # ~3 s: the fast lane keeps the synthetic damage tests
def test_the_damaged_real_husky_mcap_keeps_all_but_the_messages_hit_alone_and_in_its_bag(tmp_path):
    src = realdata_file("ros2mcap_husky_imu_gps/husky_mcap.mcap")
    bag = tmp_path / "bag"
    bag.mkdir()
    shutil.copy(src.parent / "metadata.yaml", bag)
    (bag / src.name).write_bytes(audit_damage(src.read_bytes()))
    for log in (McapReader().read(bag / src.name), Ros2BagReader().read(bag)):
        d = log.meta["diagnostics"]
        assert log.meta["status"] == "partial"
        assert set(d["records_dropped"]) <= {f"bad_chunk:{t}" for t in fx_husky_counts()}
        lost = {k.split(":", 1)[1]: v for k, v in d["records_dropped"].items()}
        for t, n in fx_husky_counts().items():  # nothing unaccounted for
            assert log_rows_of(log, t) + lost.get(t, 0) == n, t
        assert len(log["attitude"]) > 11_800  # was 11061 of 11865, with no loss reported
        assert sum(lost.values()) < 20


def fx_husky_counts() -> dict[str, int]:
    return {"/imu/data": 11865, "/fix": 989, "/husky_velocity_controller/odom": 3952}


def log_rows_of(log, topic: str) -> int:
    stream = {"/imu/data": "imu", "/fix": "gps", "/husky_velocity_controller/odom": "odometry"}[topic]
    return len(log[stream])


@pytest.mark.realdata
def test_the_damaged_real_husky_bag_skips_its_one_bad_chunk_and_reads_on(tmp_path):
    src = realdata_file("ros1_husky_imu_gps/test1.bag")
    p = tmp_path / "flip.bag"
    p.write_bytes(audit_damage(src.read_bytes()))
    log = Ros1BagReader().read(p)
    d = log.meta["diagnostics"]
    assert set(d["records_dropped"]) == {f"bad_chunk:{t}" for t in fx_husky_counts()}
    lost = {k.split(":", 1)[1]: v for k, v in d["records_dropped"].items()}
    for t, n in fx_husky_counts().items():
        assert log_rows_of(log, t) + lost[t] == n, t
    assert len(log["imu"]) > 10_000  # was 4959: reading stopped at the bad chunk
    assert log.duration_s > 395
    assert len([w for w in d["warnings"] if w.startswith("chunk at byte")]) == 1


@pytest.mark.realdata
def test_the_damaged_real_px4_ulog_keeps_its_second_half_and_says_where_the_damage_is(tmp_path):
    src = realdata_file("ulg_px4_flight_review_fixtures/motor_failure.ulg")
    p = tmp_path / "flip.ulg"
    p.write_bytes(audit_damage(src.read_bytes()))
    full, log = registry.read_log(src), registry.read_log(p)
    d = log.meta["diagnostics"]
    assert log.meta["status"] == "partial"
    kept = sum(log.n_rows().values()) / sum(full.n_rows().values())
    assert kept > 0.98  # was 0.47: pyulog stopped reading at byte 384704 of 621491
    assert log["imu"]["t_ns"].max() == full["imu"]["t_ns"].max()  # 44.0 s, was 24.0 s
    mid = src.stat().st_size // 2
    assert 3900 < d["bytes_skipped"] < 4200 and d["records_dropped"]["corrupt"] == 1
    (w,) = [x for x in d["warnings"] if x.startswith("ULog damaged from byte")]
    start = int(w.split()[4])
    assert mid - 2200 < start <= mid - 2000 and "t = 24.0" in w


def test_a_ulog_log_message_whose_size_was_hit_costs_that_message_not_the_data_behind_it(tmp_path):
    rng = np.random.default_rng(TEST_SEED)
    n = 1500
    w = ULogWriter(start_us=1_000_000)
    w.topic("vehicle_attitude", [("uint64_t", "timestamp"), ("float[4]", "q")], {
        "timestamp": 1_000_000 + np.arange(n, dtype=np.uint64) * 4_000,
        "q": np.tile(np.array([1, 0, 0, 0], np.float32), (n, 1))})
    w.log("INFO", 7_000_000, "[commander] armed")
    w.topic("vehicle_local_position", [("uint64_t", "timestamp"), ("float", "x"), ("float", "y"), ("float", "z")], {
        "timestamp": 7_000_000 + np.arange(n, dtype=np.uint64) * 4_000,
        **{c: rng.normal(0, 1, n).astype(np.float32) for c in "xyz"}})
    raw = bytearray(w.to_bytes())
    at = raw.find(b"[commander] armed") - 3 - 9  # header, level, timestamp
    assert raw[at + 2] == ord("L")
    raw[at:at + 2] = (40_000).to_bytes(2, "little")  # now it claims most of the position data
    p = tmp_path / "swallowed.ulg"
    p.write_bytes(bytes(raw))

    log = registry.read_log(p)
    d = log.meta["diagnostics"]
    assert log.meta["status"] == "partial"  # was: 'ok', with all 1500 position rows gone
    assert len(log["local_position"]) == n and len(log["attitude"]) == n - 1
    assert d["records_dropped"] == {"corrupt": 1}
    assert any(x.startswith("ULog damaged from byte") for x in d["warnings"])
