"""Standalone MCAP files (ROS 1, ROS 2 CDR and JSON message encodings) through ``mcap``.

Detection rule (see also :mod:`pipeline.io.rosbag`): a **file** starting with the MCAP magic
``\\x89MCAP0\\r\\n`` goes here — including a ``.mcap`` that lies inside a ROS 2 bag directory
when that file, not the directory, is passed. A ROS 2 bag **directory** (``metadata.yaml``)
goes to the rosbag2 reader. Both paths decode the same bytes to the same canonical values.

The file is read sequentially with :class:`mcap.stream_reader.StreamReader` (no summary or
index needed), chunk by chunk, so a truncated or damaged file still yields every message
before the damage:

* a chunk that fails to decompress or fails its CRC is dropped, its bytes counted in
  ``bytes_skipped``, and reading goes on;
* a chunk whose records cannot all be parsed (most chunks carry no CRC, so damage inside an
  uncompressed chunk shows only as a record that does not parse) keeps the records before the
  damage; where the chunk's Message Index records (written after each chunk) list the
  messages, every listed message is checked against them (channel and ``log_time`` at its
  offset) and the ones after the damage are read at their listed offsets, so only the
  messages whose bytes were hit are lost;
* messages lost in a chunk are counted per topic from its message index
  (``records_dropped['bad_chunk:<topic>']``); a damaged chunk without a message index is
  counted as one ``records_dropped['bad_chunk']``, the bytes not decoded in ``bytes_skipped``,
  with a warning naming its byte offset;
* after the read, the messages decoded and counted lost per channel are compared with the
  summary's Statistics record (when present and self-consistent): messages it lists that were
  neither are counted in ``records_dropped['missing:<topic>']`` with a warning, so no loss
  goes uncounted even where the chunk parser could not see the damage;
* a record outside the chunks that cannot be parsed (truncation, garbage) ends the read: the
  bytes from there to the end of the file are counted in ``bytes_skipped`` and a warning names
  the offset;
* if nothing was decoded, :class:`IngestError` names the reason and the byte offset.

A message whose record header survived the damage but whose payload was hit cannot be told from
a good one (chunks without a CRC carry no checksum): it decodes, or fails to deserialise
(``records_dropped['deserialize:<topic>']``).

Message decoding per channel: ``cdr`` with ``ros2msg``/``ros2idl`` schemas and ``ros1`` with
``ros1msg`` schemas through a rosbags ``Typestore`` registered from the file's own schema
records (so custom types decode); ``json`` through :func:`json.loads`, fields addressed as in
ROS (``header.stamp`` as ``{sec, nanosec}`` or ``{secs, nsecs}``). Schemas give the message type
(``pkg/Type`` and ``pkg/msg/Type`` are equivalent). Other encodings (protobuf, flatbuffer,
cbor) are counted as ``records_dropped['unsupported_encoding:<topic>']``. The record time is the
message ``log_time``; messages of a topic are taken in ``log_time`` order (chunks may overlap).
Mapping to the canonical schema: :mod:`pipeline.io.ros_common`.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from . import ros_common as rc
from .base import FlightLog, IngestError, LogReader, Progress
from .registry import register

MCAP_MAGIC = b"\x89MCAP0\r\n"

#: message encoding -> schema encodings it is decoded with
_ROS2 = ("ros2msg", "ros2idl")


#: opcodes of records that may not stand inside a chunk (only Schema 0x03, Channel 0x04 and
#: Message 0x05 do; 0x00 is reserved): one of them there means the chunk's bytes are damaged
_NOT_IN_CHUNK = frozenset({0x00, 0x01, 0x02, 0x06, 0x07, 0x08, 0x09, 0x0A, 0x0B, 0x0C, 0x0D, 0x0E, 0x0F})
_KIND = {0x03: "schema", 0x04: "channel"}
_MSG_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel id, sequence, log_time, publish_time


def _definition(sch: Any) -> tuple[str, str] | None:
    """``(format, text)`` of a ROS schema record (for mapping inference), else None."""
    if sch is None or not sch.data or sch.encoding not in (*_ROS2, "ros1msg"):
        return None
    return ("idl" if sch.encoding == "ros2idl" else "msg"), bytes(sch.data).decode("utf-8", errors="replace")


@register
class McapReader(LogReader):
    """A standalone MCAP file."""

    name = "mcap"
    source_format = "mcap"
    version = "2"  # 2: REP 117 +/-inf ranges read as the limit (valid False)
    priority = 11
    magic = MCAP_MAGIC

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        if head.startswith(MCAP_MAGIC):
            return "MCAP magic"
        return None

    def read(self, path: Path, *, config: dict | None = None, progress: Progress | None = None,
             expected_counts: Mapping[str, int] | None = None) -> FlightLog:
        """Decode a standalone MCAP file.

        Parameters
        ----------
        path : Path
            The ``.mcap`` file.
        config : dict, optional
            The ``ingest`` config (its ``ros`` section: see :mod:`pipeline.io.ros_common`).
        progress : callable, optional
            ``progress(bytes_read, file_size)``.
        expected_counts : mapping, optional
            Messages per topic the file should hold, from outside it (a ROS 2 bag's
            ``metadata.yaml``); used for the final count check when the file's own summary has
            no usable Statistics record.
        """
        from mcap.exceptions import InvalidMagic
        from mcap.records import Channel, Chunk, Message, MessageIndex, Schema, Statistics
        from mcap.stream_reader import StreamReader, get_chunk_data_stream

        cfg = rc.RosConfig.from_config(config, path)
        size = path.stat().st_size
        drops: dict[str, int] = {}
        warnings: list[str] = []
        bytes_skipped = 0
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        raw: dict[int, list[tuple[int, int, bytes]]] = {}  # channel -> (log_time, seq, data)
        counts: dict[int, int] = {}
        lost: dict[int, int] = {}  # channel -> messages counted lost in damaged chunks
        n_msgs = 0
        seq = 0
        stats: list[Statistics] = []
        # the chunk read last, settled once the Message Index records that follow it are in:
        # [file offset, chunk, its records' bytes or None, why they are unreadable, {channel: index}]
        pending: list | None = None

        def on_record(rec: Any) -> None:
            nonlocal n_msgs, seq
            if isinstance(rec, Message):
                n_msgs += 1
                counts[rec.channel_id] = counts.get(rec.channel_id, 0) + 1
                lst = raw.get(rec.channel_id)
                if lst is not None:
                    lst.append((rec.log_time, seq, bytes(rec.data)))
                    seq += 1
                elif rec.channel_id not in channels:
                    drops["unknown_channel"] = drops.get("unknown_channel", 0) + 1
            elif isinstance(rec, Schema):
                schemas.setdefault(rec.id, rec)
            elif isinstance(rec, Channel) and rec.id not in channels:
                channels[rec.id] = rec
                sch = schemas.get(rec.schema_id)
                msgtype = rc.normalize_type(sch.name) if sch is not None and sch.name else ""
                if rc.is_candidate(rec.topic, msgtype, cfg, _definition(sch)):
                    raw[rec.id] = []

        def count_lost(per_channel: Mapping[int, int]) -> str:
            """Count messages lost in a chunk per topic; the warning's ``"N message(s) lost (...)"``."""
            by_topic: dict[str, int] = {}
            for cid, k in per_channel.items():
                if k:
                    lost[cid] = lost.get(cid, 0) + k
                    t = _topic(channels, cid)
                    by_topic[t] = by_topic.get(t, 0) + k
            for t, k in by_topic.items():
                drops[f"bad_chunk:{t}"] = drops.get(f"bad_chunk:{t}", 0) + k
            if not by_topic:
                return "no listed message lost"
            return f"{sum(by_topic.values())} message(s) lost ({rc.per_topic_text(by_topic)})"

        def settle(at: int, chunk: Any, data: bytes | None, why: str,
                   index: dict[int, list[tuple[int, int]]]) -> None:
            """Hand a chunk's records on; count what its damage lost (see the module docstring)."""
            nonlocal bytes_skipped
            listed = {cid: len(v) for cid, v in index.items()}
            if data is None:  # failed to decompress or its CRC
                bytes_skipped += len(chunk.data)
                if index:
                    warnings.append(f"chunk at byte {at} dropped: {why}; {count_lost(listed)}")
                else:
                    drops["bad_chunk"] = drops.get("bad_chunk", 0) + 1
                    warnings.append(f"chunk at byte {at} dropped: {why}")
                return
            records, damage_at, reason = _parse_chunk(data)
            if damage_at is None:  # the records fill the chunk: nothing to check them against
                for _o, _e, r in records:
                    on_record(r)
                return
            if not index:
                for _o, _e, r in records:
                    on_record(r)
                drops["bad_chunk"] = drops.get("bad_chunk", 0) + 1
                bytes_skipped += len(data) - damage_at
                warnings.append(f"chunk at byte {at} damaged at offset {damage_at} of its {len(data)} "
                                f"byte(s) ({reason}); {len(data) - damage_at} byte(s) skipped, messages "
                                "lost uncounted here (no message index)")
                return
            # the message index names every message: keep the parsed ones it confirms (channel and
            # log_time at their offset), read the rest at their listed offsets, count the others
            want = {off: (cid, t) for cid, v in index.items() for t, off in v}
            listed_offs = sorted(want)
            after = {o: listed_offs[k + 1] if k + 1 < len(listed_offs) else len(data)
                     for k, o in enumerate(listed_offs)}

            def confirmed(off: int, end: int, msg: Any) -> bool:
                # channel and log_time as listed, and its length leads to the next listed
                # message (over schema/channel records only): a damaged length does not pass
                return want.get(off) == (msg.channel_id, msg.log_time) and _leads_to(data, end, after[off])

            keep: dict[int, tuple[int, Any]] = {}
            first_bad = damage_at
            for off, end, r in records:
                if isinstance(r, Message):
                    if confirmed(off, end, r):
                        keep[off] = (end, r)
                    else:
                        first_bad = min(first_bad, off)
            for off, end, r in records:  # schema/channel records before the damage
                if off < first_bad and not isinstance(r, Message):
                    keep[off] = (end, r)
            recovered = 0
            for off in sorted(want.keys() - keep.keys()):
                got = _message_at(data, off)
                if got is not None and confirmed(off, got[1], got[0]):
                    keep[off] = (got[1], got[0])
                    recovered += 1
            missing: dict[int, int] = dict(listed)
            for off, (_end, r) in keep.items():
                if isinstance(r, Message):
                    missing[r.channel_id] -= 1
            for off in sorted(keep):
                on_record(keep[off][1])
            skipped = len(data) - sum(end - off for off, (end, _r) in keep.items())
            bytes_skipped += skipped
            warnings.append(f"chunk at byte {at} damaged at offset {first_bad} of its {len(data)} byte(s) "
                            f"({reason}); {count_lost(missing)}, {recovered} read at the offsets its "
                            f"message index lists; {skipped} byte(s) skipped")

        def flush() -> None:
            nonlocal pending
            if pending is not None:
                p, pending = pending, None
                settle(*p)

        with open(path, "rb") as fh:
            reader = StreamReader(fh, emit_chunks=True, validate_crcs=True, record_size_limit=size)
            good = 0
            try:
                for rec in reader.records:
                    if isinstance(rec, MessageIndex) and pending is not None:
                        pending[4].setdefault(rec.channel_id, []).extend(rec.records)
                    else:
                        flush()
                        if isinstance(rec, Chunk):
                            try:
                                stream, length = get_chunk_data_stream(rec, validate_crc=True)
                                pending = [good, rec, stream.read(length), "", {}]
                            except Exception as exc:  # noqa: BLE001 - bad compression/CRC
                                pending = [good, rec, None, f"{type(exc).__name__}: {exc}", {}]
                        elif isinstance(rec, Statistics):
                            stats.append(rec)
                        else:
                            on_record(rec)
                    good = fh.tell()
                    if progress is not None:
                        progress(good, size)
                flush()
            except InvalidMagic:
                flush()
                if good == 0:
                    raise IngestError(path, "not an MCAP file (bad magic)") from None
                warnings.append(f"bad closing magic at byte {good}")
                bytes_skipped += size - good
            except Exception as exc:  # noqa: BLE001 - truncation/garbage ends the read
                flush()
                reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                if n_msgs == 0:
                    raise IngestError(path, f"corrupt or truncated MCAP at byte {good} of {size} "
                                            f"({reason}); no messages before it") from None
                bytes_skipped += size - good
                warnings.append(f"MCAP unreadable from byte {good} of {size} ({reason}); "
                                f"{size - good} byte(s) skipped")
        if n_msgs == 0:
            raise IngestError(path, "MCAP file holds no messages")
        _check_counts(stats[-1] if stats else None, expected_counts, channels, counts, lost, drops, warnings)

        def msgtype_of(ch: Channel) -> str:
            sch = schemas.get(ch.schema_id)
            return rc.normalize_type(sch.name) if sch is not None and sch.name else ""

        conns = [(ch.topic, msgtype_of(ch), counts.get(cid, 0)) for cid, ch in channels.items()]
        defs = [(msgtype_of(ch), *d) for ch in channels.values()
                if (d := _definition(schemas.get(ch.schema_id))) is not None]
        absent = rc.warn_configured_topics_absent(conns, cfg, warnings)
        routes, unmapped = rc.plan_topics(conns, cfg, path, rc.defined_fields(defs))

        # type stores from the schemas of the routed channels
        used = [cid for cid, ch in channels.items() if ch.topic in routes]
        defs2, defs1 = [], []
        for cid in used:
            sch = schemas.get(channels[cid].schema_id)
            if sch is None or not sch.data:
                continue
            text = bytes(sch.data).decode("utf-8", errors="replace")
            if sch.encoding in _ROS2:
                defs2.append((sch.name, "idl" if sch.encoding == "ros2idl" else "msg", text))
            elif sch.encoding == "ros1msg":
                defs1.append((sch.name, "msg", text))
        stores = {}
        wanted = {r.msgtype for r in routes.values()}
        if defs2:
            stores["cdr"] = rc.make_typestore(defs2, "LATEST", wanted)
        if defs1:
            stores["ros1"] = rc.make_typestore(defs1, "ROS1_NOETIC", wanted)
        for _store, errs in stores.values():
            for t, e in errs.items():
                warnings.append(f"message definition of {t} unparsable: {e}")

        buckets: dict[str, rc.Bucket] = {}
        for cid in sorted(used, key=lambda c: channels[c].topic):
            ch = channels[cid]
            route = routes[ch.topic]
            b = buckets.setdefault(ch.topic, rc.Bucket(route=route))
            items = sorted(raw.get(cid, []))
            enc = ch.message_encoding
            if enc == "json":
                decode = _json_loads
            elif enc in stores:
                store = stores[enc][0]
                if route.msgtype not in store.fielddefs:
                    drops[f"unknown_type:{ch.topic}"] = len(items)
                    warnings.append(f"{ch.topic}: no definition for {route.msgtype}; not decoded")
                    continue
                fn = store.deserialize_cdr if enc == "cdr" else store.deserialize_ros1
                decode = (lambda f, t: lambda d: f(d, t))(fn, route.msgtype)
            else:
                drops[f"unsupported_encoding:{ch.topic}"] = len(items)
                warnings.append(f"{ch.topic}: message encoding {enc!r} not supported "
                                "(ros1, cdr, json are); not decoded")
                continue
            for log_time, _s, data in items:
                try:
                    msg = decode(data)
                except Exception:  # noqa: BLE001 - one bad message is a counted drop
                    key = f"deserialize:{ch.topic}"
                    drops[key] = drops.get(key, 0) + 1
                    continue
                b.msgs.append(msg)
                b.rec_ns.append(log_time)
        diag = {"records_dropped": drops, "warnings": warnings, "bytes_skipped": bytes_skipped,
                "absent_topics": absent,
                "encodings": sorted({ch.message_encoding for ch in channels.values()})}
        return rc.build_flightlog(buckets, unmapped, cfg, path=path, source_format=self.source_format,
                                  diag=diag)


def _json_loads(data: bytes) -> Any:
    return json.loads(data)


def _message_at(data: bytes, off: int) -> tuple[Any, int] | None:
    """The Message record starting at ``off`` of a chunk's records, with its end offset; None when
    the bytes there cannot be one (wrong opcode, too short, running past the chunk)."""
    from mcap.records import Message

    if off < 0 or off + _MSG_HEAD.size > len(data):
        return None
    op, length, cid, seq, log_time, publish_time = _MSG_HEAD.unpack_from(data, off)
    end = off + 9 + length
    if op != 0x05 or length < 22 or end > len(data):
        return None
    return Message(channel_id=cid, sequence=seq, log_time=log_time, publish_time=publish_time,
                   data=data[off + _MSG_HEAD.size:end]), end


def _parse_chunk(data: bytes) -> tuple[list[tuple[int, int, Any]], int | None, str]:
    """The records of a chunk's uncompressed bytes, bounds-checked.

    Returns ``(records, damage_at, reason)``: ``records`` as ``(offset, end, record)`` for the
    Schema, Channel and Message records parsed in order; ``damage_at`` the offset of the first
    record that cannot be parsed (``None`` when the records fill the chunk exactly) and
    ``reason`` what was wrong with it. ``mcap``'s own ``breakup_chunk`` cannot serve here: a
    damaged length on an unknown opcode makes it skip to the end of the chunk without a word.
    """
    from mcap.data_stream import ReadDataStream
    from mcap.records import Channel, Schema

    out: list[tuple[int, int, Any]] = []
    n = len(data)
    pos = 0
    while pos < n:
        if pos + 9 > n:
            return out, pos, f"record header cut ({n - pos} byte(s) left)"
        op = data[pos]
        length = int.from_bytes(data[pos + 1:pos + 9], "little")
        end = pos + 9 + length
        if end > n:
            return out, pos, f"record length {length} exceeds the {n - pos - 9} byte(s) left"
        if op in _NOT_IN_CHUNK:
            return out, pos, f"opcode 0x{op:02x} cannot stand in a chunk"
        if op == 0x05:
            got = _message_at(data, pos)
            if got is None:
                return out, pos, f"message record of {length} byte(s) is too short"
            out.append((pos, end, got[0]))
        elif op in (0x03, 0x04):
            body = ReadDataStream(_Bounded(data[pos + 9:end]))
            try:
                rec = (Schema if op == 0x03 else Channel).read(body)
            except Exception as exc:  # noqa: BLE001 - garbage inside the record's bounds
                return out, pos, f"{_KIND[op]} record unparsable ({type(exc).__name__})"
            if body.count != length:
                return out, pos, f"{_KIND[op]} record fills {body.count} of its {length} bytes"
            out.append((pos, end, rec))
        # other opcodes (0x10 and up): record types of later MCAP versions, skipped as the spec says
        pos = end
    return out, None, ""


def _leads_to(data: bytes, pos: int, target: int) -> bool:
    """From ``pos``, whole non-message records (schema, channel, later record types) reach
    ``target`` exactly (``pos == target``: nothing between)."""
    while pos < target:
        if pos + 9 > target or data[pos] in _NOT_IN_CHUNK or data[pos] == 0x05:
            return False
        pos += 9 + int.from_bytes(data[pos + 1:pos + 9], "little")
    return pos == target


class _Bounded:
    """A read-only byte source for ``mcap``'s record parsers that refuses to read past its end
    (``ReadDataStream`` turns the empty read into ``EndOfFile``)."""

    __slots__ = ("_data", "_pos")

    def __init__(self, data: bytes):
        self._data = data
        self._pos = 0

    def read(self, n: int) -> bytes:
        out = self._data[self._pos:self._pos + n]
        if len(out) < n:
            return b""  # a short read inside a record: garbage, not a record
        self._pos += n
        return out


def _topic(channels: Mapping[int, Any], cid: int) -> str:
    """The topic of channel ``cid``, or ``"channel <cid>"`` when no Channel record named it."""
    ch = channels.get(cid)
    return ch.topic if ch is not None else f"channel {cid}"


def _check_counts(stats: Any, expected: Mapping[str, int] | None, channels: Mapping[int, Any],
                 counts: Mapping[int, int], lost: Mapping[int, int], drops: dict[str, int],
                 warnings: list[str]) -> None:
    """Count as ``missing:<topic>`` the messages the file says it holds but that were neither
    decoded nor counted lost: per channel from the summary's Statistics record when its
    per-channel counts add up to its total (a damaged summary must not invent losses), else
    per topic from ``expected`` (a ROS 2 bag's ``metadata.yaml``)."""
    want: dict[str, int] = {}
    if stats is not None and stats.channel_message_counts \
            and sum(stats.channel_message_counts.values()) == stats.message_count:
        for cid, n in stats.channel_message_counts.items():
            t = _topic(channels, cid)
            want[t] = want.get(t, 0) + n
        source = "the MCAP summary's Statistics record lists"
    elif expected:
        want = {str(t): int(n) for t, n in expected.items()}
        source = "metadata.yaml lists"
    else:
        return
    seen: dict[str, int] = {}
    for cid in counts.keys() | lost.keys():
        t = _topic(channels, cid)
        seen[t] = seen.get(t, 0) + counts.get(cid, 0) + lost.get(cid, 0)
    short = rc.count_missing(want, seen, drops)
    if short:
        warnings.append(f"{sum(short.values())} message(s) that {source} not found in the file "
                        f"({rc.per_topic_text(short)})")
