"""ROS 1 ``.bag`` files and ROS 2 bag directories (sqlite3 or MCAP storage), through rosbags.

Detection (one rule, from the bytes/structure, never the extension):

* a **file** starting with ``#ROSBAG V2.0\\n`` → :class:`Ros1BagReader`;
* a **directory** holding ``metadata.yaml`` (or that ``metadata.yaml`` file itself) →
  :class:`Ros2BagReader`, whatever its storage (sqlite3 ``.db3`` or ``.mcap``);
* a bare ``.mcap`` **file** (magic ``\\x89MCAP0\\r\\n``) → the MCAP reader
  (:mod:`pipeline.io.mcap_reader`), also when it lies inside a ROS 2 bag directory;
* a ROS 2 sqlite3 storage **file** (``.db3``) passed alone → :class:`Ros2Sqlite3FileReader`,
  which refuses it with an :class:`IngestError` naming the bag directory to pass instead: a
  ``.db3`` holds no ``metadata.yaml`` and may be one split of several.

Decoding: the readers list the connections, let :func:`ros_common.plan_topics` pick the
topics, deserialise only those with a rosbags ``Typestore`` built from the definitions stored
in the bag (ROS 1 connection ``message_definition``; ROS 2 MCAP schemas and rosbag2 ≥ v9
``message_definitions``) over a stock store for bags that carry none — so custom message types
decode — and hand the messages to :func:`ros_common.build_flightlog` for the mapping to the
canonical schema (frames, stamps, NED origin: see :mod:`pipeline.io.ros_common`).

Damage: a ROS 1 bag rosbags cannot open (truncated, or never closed: its index at the end
is missing or damaged) is scanned record by record without the index (:func:`_scan_ros1`),
keeping the messages before the damage and counting the rest in ``bytes_skipped``. An indexed
ROS 1 bag with a damaged chunk (one that fails to decompress) loses that chunk only: its
messages, known from the index, are counted per topic in ``records_dropped['bad_chunk:<topic>']``
and reading goes on with the next chunk (:func:`_ros1_messages`). A single-file MCAP-storage
ROS 2 bag that rosbags cannot open (no summary/footer), or that yields fewer messages than its
``metadata.yaml`` lists (rosbags stops at damage inside an MCAP chunk), is read sequentially by
the MCAP reader, which keeps what the chunks' message indexes point to and counts the rest.
Anything else unreadable (bad bag header, broken ``metadata.yaml``, missing storage file,
nothing decodable) raises :class:`IngestError` with the reason; a message that fails to
deserialise is dropped and counted (``records_dropped['deserialize:<topic>']``); when the
storage fails mid-way the messages read so far are kept and the rest counted
(``records_dropped['unread_after_error']``); when it ends without an error but short of the
messages the bag lists (index or ``metadata.yaml``), the shortfall is counted per topic in
``records_dropped['missing:<topic>']``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Iterator

import yaml

from . import ros_common as rc
from .base import FlightLog, IngestError, LogReader, Progress
from .registry import register

ROS1_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"
ROS2_META_KEY = "rosbag2_bagfile_information"


def _decode(path: Path, reader: Any, routes: dict[str, rc.Route], deser: Callable[[bytes, str], Any],
            known_types: set[str], diag: dict, progress: Progress | None, *,
            messages: Callable[[list, dict[str, int]], Iterator[tuple[Any, int, bytes]]] | None = None,
            listed_by: str = "the bag's index lists") -> dict[str, rc.Bucket]:
    """Deserialise the routed topics of an open rosbags reader into buckets.

    ``messages(connections, lost)`` replaces ``reader.messages`` (the ROS 1 reader's, which
    skips a damaged chunk instead of stopping); it counts in ``lost`` the messages of the routed
    topics it could not read. When the iteration ends, the messages read or counted lost per
    topic are compared with the counts the bag lists (``listed_by``, for the warning): a
    storage that ends short without raising (rosbags' MCAP storage stops at damage inside an
    uncompressed chunk) is counted in ``records_dropped['missing:<topic>']``.
    """
    drops = diag["records_dropped"]
    for topic, route in list(routes.items()):
        if route.msgtype not in known_types:
            n = sum(c.msgcount for c in reader.connections if c.topic == topic)
            drops[f"unknown_type:{topic}"] = n
            diag["warnings"].append(f"{topic}: no definition for {route.msgtype} in the bag or the "
                                    f"default type store; {n} message(s) not decoded")
            del routes[topic]
    buckets = {t: rc.Bucket(route=r) for t, r in routes.items()}
    conns = [c for c in reader.connections if c.topic in routes]
    total = sum(c.msgcount for c in conns)
    done = bad = 0
    seen: dict[str, int] = {}
    lost: dict[str, int] = {}
    if not conns:
        return buckets
    try:
        for conn, ts, raw in (reader.messages(connections=conns) if messages is None else messages(conns, lost)):
            b = buckets[conn.topic]
            seen[conn.topic] = seen.get(conn.topic, 0) + 1
            try:
                msg = deser(raw, conn.msgtype)
            except Exception:  # noqa: BLE001 - one bad message is a counted drop, not a failure
                key = f"deserialize:{conn.topic}"
                drops[key] = drops.get(key, 0) + 1
                bad += 1
                continue
            b.msgs.append(msg)
            b.rec_ns.append(ts)
            done += 1
            if progress is not None and done % 4096 == 0:
                progress(done, total)
    except Exception as exc:  # noqa: BLE001 - storage failure mid-way: keep what was read
        reason = f"{type(exc).__name__}: {exc}"
        if done == 0:
            raise IngestError(path, f"cannot read messages: {reason}") from None
        left = max(total - done - bad - sum(lost.values()), 0)
        drops["unread_after_error"] = drops.get("unread_after_error", 0) + left
        diag["warnings"].append(f"reading stopped after {done} message(s): {reason}; "
                                f"{left} message(s) not read")
    else:
        listed: dict[str, int] = {}
        for c in conns:
            listed[c.topic] = listed.get(c.topic, 0) + c.msgcount
        short = rc.count_missing(listed, {t: seen.get(t, 0) + lost.get(t, 0) for t in listed}, drops)
        if short:
            diag["warnings"].append(f"storage ended after {done + bad} message(s) without an error: "
                                    f"{sum(short.values())} message(s) that {listed_by} not found "
                                    f"({rc.per_topic_text(short)})")
    if progress is not None:
        progress(total, total)
    return buckets


def _ros1_messages(reader: Any, diag: dict) -> Callable[[list, dict[str, int]], Iterator[tuple[Any, int, bytes]]]:
    """The messages of an open, indexed rosbags ROS 1 reader, in time order, skipping damage.

    rosbags' own ``Reader.messages`` stops at the first chunk that fails to decompress (a
    damaged bz2/lz4 chunk: ``OSError: Invalid data stream``), losing every message after it.
    This walks the same index but drops only the damaged chunk: its messages, known from its
    ``CHUNK_INFO`` record, are counted per topic in ``records_dropped['bad_chunk:<topic>']``
    and its bytes in ``bytes_skipped``, as :func:`_scan_ros1` drops one bad chunk and goes on.
    A message record unreadable at its indexed offset, or differing from its index entry
    (connection, time), is counted in ``records_dropped['bad_record:<topic>']``.
    """
    import heapq
    import io
    import os

    from rosbags.rosbag1.reader import Header, RecordType, read_bytes, read_uint32

    def messages(conns: list, lost: dict[str, int]) -> Iterator[tuple[Any, int, bytes]]:
        drops = diag["records_dropped"]
        connmap = {c.id: c for c in reader.connections}
        infos = {ci.pos: ci for ci in reader.chunk_infos}
        wanted = {c.id for c in conns}
        bad_chunks: set[int] = set()
        bad_records: dict[str, int] = {}
        cur_pos, cur = -1, io.BytesIO()

        def keyed(cid: int) -> Iterator[tuple[int, int, int, int]]:
            return ((e.time, e.chunk_pos, e.offset, cid) for e in reader.indexes[cid])

        entries = heapq.merge(*(keyed(c.id) for c in conns))
        for time, chunk_pos, offset, cid in entries:
            if chunk_pos in bad_chunks:
                continue  # counted when the chunk failed
            topic = connmap[cid].topic
            if chunk_pos != cur_pos:
                chunk = reader.chunks[chunk_pos]
                try:
                    reader.bio.seek(chunk.datapos)
                    cur = io.BytesIO(chunk.decompressor(read_bytes(reader.bio, chunk.datasize)))
                    cur_pos = chunk_pos
                except Exception as exc:  # noqa: BLE001 - bad compression: drop this chunk only
                    bad_chunks.add(chunk_pos)
                    in_chunk: dict[str, int] = {}
                    for c, k in infos[chunk_pos].connection_counts.items():
                        t = connmap[c].topic if c in connmap else f"connection {c}"
                        in_chunk[t] = in_chunk.get(t, 0) + k
                        if c in wanted:
                            lost[t] = lost.get(t, 0) + k
                    for t, k in in_chunk.items():
                        drops[f"bad_chunk:{t}"] = drops.get(f"bad_chunk:{t}", 0) + k
                    diag["bytes_skipped"] = diag.get("bytes_skipped", 0) + chunk.datasize
                    reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                    diag["warnings"].append(
                        f"chunk at byte {chunk_pos} dropped: {reason}; {sum(in_chunk.values())} "
                        f"message(s) lost ({rc.per_topic_text(in_chunk)}); {chunk.datasize} byte(s) skipped")
                    continue
            try:
                cur.seek(offset)
                while True:  # connection records may stand before the message (as in rosbags)
                    header = Header.read(cur)
                    op = header.get_uint8("op")
                    if op != RecordType.CONNECTION:
                        break
                    cur.seek(read_uint32(cur), os.SEEK_CUR)
                if op != RecordType.MSGDATA or header.get_uint32("conn") != cid or header.get_time("time") != time:
                    raise ValueError("record differs from its index entry")
                data = read_bytes(cur, read_uint32(cur))
            except Exception:  # noqa: BLE001 - one unreadable message record is a counted drop
                bad_records[topic] = bad_records.get(topic, 0) + 1
                lost[topic] = lost.get(topic, 0) + 1
                drops[f"bad_record:{topic}"] = drops.get(f"bad_record:{topic}", 0) + 1
                continue
            yield connmap[cid], time, data
        if bad_records:
            diag["warnings"].append(f"{sum(bad_records.values())} message record(s) unreadable at the "
                                    f"offsets the bag's index gives ({rc.per_topic_text(bad_records)})")

    return messages


def _connections(reader: Any) -> list[tuple[str, str, int]]:
    return [(c.topic, c.msgtype, c.msgcount) for c in reader.connections]


@register
class Ros1BagReader(LogReader):
    """ROS 1 bag (format 2.0) through ``rosbags.rosbag1``."""

    name = "rosbag1"
    source_format = "ros1bag"
    version = "2"  # 2: REP 117 +/-inf ranges read as the limit (valid False)
    priority = 10
    magic = ROS1_MAGIC

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        if head.startswith(ROS1_MAGIC):
            return "ROS 1 bag magic '#ROSBAG V2.0'"
        return None

    def read(self, path: Path, *, config: dict | None = None,
             progress: Progress | None = None) -> FlightLog:
        from rosbags.rosbag1 import Reader

        cfg = rc.RosConfig.from_config(config, path)
        diag: dict = {"records_dropped": {}, "warnings": []}
        try:
            reader = Reader(path)
            reader.open()
        except Exception as exc:  # noqa: BLE001 - rosbags raises ReaderError and OS errors
            msg = str(exc) or type(exc).__name__
            if exc.__cause__ is not None and str(exc.__cause__):
                msg = f"{msg} ({exc.__cause__})"
            # no usable index (truncated, or never closed): scan the records sequentially
            return _scan_ros1(path, f"rosbags cannot open it: {msg}", cfg, progress, self.source_format)
        try:
            conns = _connections(reader)
            if not conns or reader.message_count == 0:
                raise IngestError(path, "ROS 1 bag holds no messages")
            defs = [(c.msgtype, "msg", c.msgdef.data) for c in reader.connections]
            diag["absent_topics"] = rc.warn_configured_topics_absent(conns, cfg, diag["warnings"])
            routes, unmapped = rc.plan_topics(conns, cfg, path, rc.defined_fields(defs))
            store, errs = rc.make_typestore(defs, "ROS1_NOETIC", {r.msgtype for r in routes.values()})
            for t, e in errs.items():
                diag["warnings"].append(f"message definition of {t} unparsable: {e}")
            buckets = _decode(path, reader, routes, store.deserialize_ros1, set(store.fielddefs),
                              diag, progress, messages=_ros1_messages(reader, diag))
        finally:
            reader.close()
        return rc.build_flightlog(buckets, unmapped, cfg, path=path, source_format=self.source_format,
                                  diag=diag)


def _listed_counts(bi: dict) -> dict[str, int] | None:
    """Messages per topic from ``metadata.yaml``'s ``topics_with_message_count`` (None when it
    is missing or malformed: then nothing is checked against it)."""
    out: dict[str, int] = {}
    try:
        for entry in bi.get("topics_with_message_count") or []:
            name = str(entry["topic_metadata"]["name"])
            out[name] = out.get(name, 0) + int(entry["message_count"])
    except (AttributeError, KeyError, TypeError, ValueError):
        return None
    return out or None


def _bag_dir(path: Path) -> Path:
    return path.parent if path.is_file() and path.name == "metadata.yaml" else path


@register
class Ros2BagReader(LogReader):
    """ROS 2 bag directory (``metadata.yaml`` + sqlite3 or MCAP storage) through ``rosbags.rosbag2``."""

    name = "rosbag2"
    source_format = "ros2bag"
    version = "2"  # 2: REP 117 +/-inf ranges read as the limit (valid False)
    priority = 12

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        if path.is_dir() and (path / "metadata.yaml").is_file():
            return "directory with metadata.yaml (ROS 2 bag)"
        if path.name == "metadata.yaml" and ROS2_META_KEY.encode() in head:
            return "rosbag2 metadata.yaml (reads its bag directory)"
        return None

    def read(self, path: Path, *, config: dict | None = None,
             progress: Progress | None = None) -> FlightLog:
        from rosbags.rosbag2 import Reader

        cfg = rc.RosConfig.from_config(config, path)
        bag = _bag_dir(path)
        meta_path = bag / "metadata.yaml"
        if not bag.is_dir():  # --format rosbag2 forced on a file
            raise IngestError(path, "a ROS 2 bag is a folder holding metadata.yaml and its storage "
                                    "file, not a single file")
        try:
            info = yaml.safe_load(meta_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            raise IngestError(path, f"ROS 2 bag metadata.yaml unreadable: {type(exc).__name__}: "
                                    f"{str(exc).splitlines()[0] if str(exc) else ''}") from None
        if not isinstance(info, dict) or not isinstance(info.get(ROS2_META_KEY), dict):
            raise IngestError(path, f"metadata.yaml has no '{ROS2_META_KEY}' mapping: not a ROS 2 bag")
        bi = info[ROS2_META_KEY]
        storage = bi.get("storage_identifier", "?")
        files = bi.get("relative_file_paths") or []
        missing = [f for f in files if not (bag / str(f)).is_file()]
        if missing:
            raise IngestError(path, f"storage file(s) listed in metadata.yaml missing: {', '.join(map(str, missing))}")
        diag: dict = {"records_dropped": {}, "warnings": [], "storage": storage}
        single_mcap = storage == "mcap" and len(files) == 1
        try:
            reader = Reader(bag)
            reader.open()
        except Exception as exc:  # noqa: BLE001 - rosbags ReaderError, sqlite3/mcap errors
            reason = f"unreadable ROS 2 bag ({storage} storage): {type(exc).__name__}: {exc}"
            if single_mcap:
                return self._mcap_fallback(path, bag / str(files[0]), reason, config, progress,
                                           _listed_counts(bi))
            raise IngestError(path, reason) from None
        try:
            conns = _connections(reader)
            if not conns or reader.message_count == 0:
                raise IngestError(path, "ROS 2 bag holds no messages")
            defs = []
            for c in reader.connections:
                fmt = getattr(c.msgdef.format, "name", "NONE")
                if fmt in ("MSG", "IDL"):
                    defs.append((c.msgtype, fmt.lower(), c.msgdef.data))
            diag["absent_topics"] = rc.warn_configured_topics_absent(conns, cfg, diag["warnings"])
            routes, unmapped = rc.plan_topics(conns, cfg, path, rc.defined_fields(defs))
            store, errs = rc.make_typestore(defs, "LATEST", {r.msgtype for r in routes.values()})
            for t, e in errs.items():
                diag["warnings"].append(f"message definition of {t} unparsable: {e}")
            fmts = {c.topic: getattr(c.ext, "serialization_format", "cdr") for c in reader.connections}
            for topic in list(routes):
                if fmts.get(topic, "cdr") != "cdr":
                    n = sum(c.msgcount for c in reader.connections if c.topic == topic)
                    diag["records_dropped"][f"unsupported_serialization:{topic}"] = n
                    del routes[topic]
            listed = {c.topic: 0 for c in reader.connections}
            for c in reader.connections:
                listed[c.topic] += c.msgcount
            try:
                buckets = _decode(path, reader, routes, store.deserialize_cdr, set(store.fielddefs),
                                  diag, progress, listed_by="metadata.yaml lists")
            except IngestError as exc:
                if not single_mcap:
                    raise
                buckets, failed = None, exc.reason  # nothing read: the chunk was parsed whole first
        finally:
            reader.close()
        if buckets is None:
            return self._mcap_fallback(path, bag / str(files[0]), f"rosbags' MCAP storage: {failed}",
                                       config, progress, listed)
        short = sum(v for k, v in diag["records_dropped"].items()
                    if k.startswith("missing:") or k == "unread_after_error")
        if short and single_mcap:
            # rosbags stops at damage inside an MCAP chunk (without a word when the chunk has no
            # CRC); the MCAP reader reads on, the chunk's other messages through its message index
            reason = (f"rosbags' MCAP storage read {short} message(s) fewer than metadata.yaml "
                      "lists for the decoded topics")
            try:
                return self._mcap_fallback(path, bag / str(files[0]), reason, config, progress, listed)
            except IngestError:
                pass  # keep rosbags' messages, the shortfall counted
        return rc.build_flightlog(buckets, unmapped, cfg, path=path, source_format=self.source_format,
                                  diag=diag)

    def _mcap_fallback(self, path: Path, file: Path, reason: str, config: dict | None,
                       progress: Progress | None, listed: dict[str, int] | None = None) -> FlightLog:
        """rosbags needs an intact MCAP summary and stops at damage inside a chunk; a damaged
        single-file MCAP bag is read sequentially instead by the MCAP reader, which recovers
        what the chunks' message indexes point to, counts the rest in the diagnostics and checks
        the messages per topic against ``listed`` (``metadata.yaml``) when the file's own
        summary cannot tell."""
        from .mcap_reader import McapReader

        try:
            log = McapReader().read(file, config=config, progress=progress, expected_counts=listed)
        except IngestError as exc:
            raise IngestError(path, f"{reason}; sequential read failed too: {exc.reason}") from None
        d = log.meta["diagnostics"]
        d["storage"] = "mcap"
        d["warnings"].insert(0, f"{reason}; read {file.name} sequentially instead")
        log.meta["source_format"] = self.source_format
        return log


@register
class Ros2Sqlite3FileReader(LogReader):
    """A ROS 2 sqlite3 storage file (``.db3``) passed alone: refused with a pointer to its bag."""

    name = "rosbag2_db3"
    source_format = "ros2bag"
    version = "2"  # 2: REP 117 +/-inf ranges read as the limit (valid False)
    priority = 14

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        if head.startswith(SQLITE_MAGIC) and b"CREATE TABLE topics" in head and b"messages" in head:
            return "sqlite3 file with rosbag2 'topics'/'messages' tables"
        return None

    def read(self, path: Path, *, config: dict | None = None,
             progress: Progress | None = None) -> FlightLog:
        meta = path.parent / "metadata.yaml"
        if meta.is_file():
            raise IngestError(path, "a ROS 2 sqlite3 storage file is one part of a bag; ingest its "
                                    f"bag directory {path.parent} (with metadata.yaml) instead")
        raise IngestError(path, "a ROS 2 sqlite3 storage file cannot be read without its bag's "
                                "metadata.yaml (none beside it); `ros2 bag reindex` can recreate it")


def _length(fh: Any, size: int, skip: bool = False) -> int:
    """Next uint32 length field, checked against the bytes left (garbage must not make us
    allocate gigabytes); with ``skip`` the field is consumed, else the position is kept."""
    import struct

    pos = fh.tell()
    raw = fh.read(4)
    if len(raw) < 4:
        raise EOFError(f"length field cut at byte {pos}")
    n = struct.unpack("<L", raw)[0]
    if n > size - pos - 4:
        raise ValueError(f"record length {n} at byte {pos} exceeds the {size - pos - 4} bytes left")
    if not skip:
        fh.seek(pos)
    return n


def _scan_ros1(path: Path, why: str, cfg: rc.RosConfig, progress: Progress | None,
               source_format: str) -> FlightLog:
    """Read a ROS 1 bag without its index, record by record (bag format 2.0).

    Records are ``<header_len><header: name=value fields><data_len><data>``; chunks (op 5)
    hold connection (op 7) and message (op 2) records, bz2/lz4-compressed or not. Reading stops
    at the first record that cannot be parsed (truncation, garbage): the messages before it are
    kept, the remaining bytes are counted in ``bytes_skipped``; a chunk that fails to decompress
    is counted in ``records_dropped['bad_chunk']`` and skipped. Messages of a topic are taken in
    record-time order.
    """
    import io
    import struct

    from rosbags.rosbag1.reader import Header, RecordType, decompressors, normalize, read_bytes, read_uint32
    from rosbags.typesys.msg import normalize_msgtype

    size = path.stat().st_size
    drops: dict[str, int] = {}
    warnings: list[str] = []
    conns: dict[int, tuple[str, str, str]] = {}  # conn id -> (topic, msgtype, msgdef)
    raw: dict[int, list[tuple[int, int, bytes]]] = {}
    counts: dict[int, int] = {}
    bytes_skipped = 0
    n_msgs = 0
    good = 0

    def connection(hdr: Header, data: bytes) -> None:
        cid = hdr.get_uint32("conn")
        if cid in conns:
            return
        fields = Header.read(io.BytesIO(struct.pack("<L", len(data)) + data))
        topic = normalize(hdr.get_string("topic"))
        typ = normalize_msgtype(fields.get_string("type"))
        conns[cid] = (topic, typ, fields.get_string("message_definition"))
        if rc.is_candidate(topic, typ, cfg, ("msg", conns[cid][2])):
            raw[cid] = []

    def message(hdr: Header, data: bytes, seq: int) -> None:
        nonlocal n_msgs
        cid = hdr.get_uint32("conn")
        n_msgs += 1
        counts[cid] = counts.get(cid, 0) + 1
        if cid in raw:
            raw[cid].append((hdr.get_time("time"), seq, data))
        elif cid not in conns:
            drops["unknown_connection"] = drops.get("unknown_connection", 0) + 1

    with open(path, "rb") as fh:
        if fh.read(len(ROS1_MAGIC)) != ROS1_MAGIC:
            raise IngestError(path, "not a ROS 1 bag (bad magic)")
        good = fh.tell()
        seq = 0
        try:
            while good < size:
                hdr = Header.read(io.BytesIO(read_bytes(fh, 4 + _length(fh, size))))
                op = hdr.get_uint8("op")
                data = read_bytes(fh, _length(fh, size, skip=True))
                if op == RecordType.CHUNK:
                    try:
                        inner = io.BytesIO(decompressors[hdr.get_string("compression")](data))
                    except Exception as exc:  # noqa: BLE001 - bad compression: drop the chunk
                        drops["bad_chunk"] = drops.get("bad_chunk", 0) + 1
                        bytes_skipped += len(data)
                        warnings.append(f"chunk at byte {good} dropped: {type(exc).__name__}: {exc}")
                        inner = io.BytesIO()
                    end = len(inner.getbuffer())
                    while inner.tell() < end:
                        h = Header.read(inner)
                        d = read_bytes(inner, read_uint32(inner))
                        iop = h.get_uint8("op")
                        if iop == RecordType.CONNECTION:
                            connection(h, d)
                        elif iop == RecordType.MSGDATA:
                            message(h, d, seq)
                            seq += 1
                elif op == RecordType.CONNECTION:
                    connection(hdr, data)
                elif op == RecordType.MSGDATA:
                    message(hdr, data, seq)
                    seq += 1
                good = fh.tell()
                if progress is not None:
                    progress(good, size)
        except Exception as exc:  # noqa: BLE001 - truncation/garbage ends the scan
            reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
            if exc.__cause__ is not None and str(exc.__cause__):
                reason = f"{reason} ({exc.__cause__})"
            if n_msgs == 0:
                raise IngestError(path, f"unreadable ROS 1 bag ({why}); sequential scan found no "
                                        f"messages before byte {good} ({reason})") from None
            bytes_skipped += size - good
            warnings.append(f"bag unreadable from byte {good} of {size} ({reason}); "
                            f"{size - good} byte(s) skipped")
    if n_msgs == 0:
        raise IngestError(path, f"unreadable ROS 1 bag ({why}); no messages in it")
    warnings.insert(0, f"{why}; read sequentially without the index")
    listed = [(t, typ, counts.get(c, 0)) for c, (t, typ, _d) in conns.items()]
    absent = rc.warn_configured_topics_absent(listed, cfg, warnings)
    routes, unmapped = rc.plan_topics(listed, cfg, path, rc.defined_fields((typ, "msg", d) for t, typ, d in conns.values()))
    defs = [(typ, "msg", d) for c, (t, typ, d) in conns.items() if t in routes]
    store, errs = rc.make_typestore(defs, "ROS1_NOETIC", {r.msgtype for r in routes.values()})
    for t, e in errs.items():
        warnings.append(f"message definition of {t} unparsable: {e}")
    buckets: dict[str, rc.Bucket] = {}
    for cid in sorted((c for c in conns if conns[c][0] in routes), key=lambda c: conns[c][0]):
        topic, typ, _d = conns[cid]
        route = routes[topic]
        b = buckets.setdefault(topic, rc.Bucket(route=route))
        items = sorted(raw.get(cid, []))
        if route.msgtype not in store.fielddefs:
            drops[f"unknown_type:{topic}"] = drops.get(f"unknown_type:{topic}", 0) + len(items)
            continue
        for t_rec, _s, data in items:
            try:
                msg = store.deserialize_ros1(data, typ)
            except Exception:  # noqa: BLE001 - one bad message is a counted drop
                key = f"deserialize:{topic}"
                drops[key] = drops.get(key, 0) + 1
                continue
            b.msgs.append(msg)
            b.rec_ns.append(t_rec)
    diag = {"records_dropped": drops, "warnings": warnings, "bytes_skipped": bytes_skipped,
            "absent_topics": absent}
    return rc.build_flightlog(buckets, unmapped, cfg, path=path, source_format=source_format, diag=diag)
