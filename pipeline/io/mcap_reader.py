"""Standalone MCAP files (ROS 1, ROS 2 CDR and JSON message encodings) through ``mcap``.

Detection rule (see also :mod:`pipeline.io.rosbag`): a **file** starting with the MCAP magic
``\\x89MCAP0\\r\\n`` goes here — including a ``.mcap`` that lies inside a ROS 2 bag directory
when that file, not the directory, is passed. A ROS 2 bag **directory** (``metadata.yaml``)
goes to the rosbag2 reader. Both paths decode the same bytes to the same canonical values.

The file is read sequentially with :class:`mcap.stream_reader.StreamReader` (no summary or
index needed), chunk by chunk, so a truncated or damaged file still yields every message
before the damage:

* a chunk that fails to decompress or fails its CRC is dropped and counted
  (``records_dropped['bad_chunk']``, its bytes in ``bytes_skipped``), and reading goes on;
* a record that cannot be parsed (truncation, garbage) ends the read: the bytes from there to
  the end of the file are counted in ``bytes_skipped`` and a warning names the offset;
* if nothing was decoded, :class:`IngestError` names the reason and the byte offset.

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
from pathlib import Path
from typing import Any

from . import ros_common as rc
from .base import FlightLog, IngestError, LogReader, Progress
from .registry import register

MCAP_MAGIC = b"\x89MCAP0\r\n"

#: message encoding -> schema encodings it is decoded with
_ROS2 = ("ros2msg", "ros2idl")


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

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        if head.startswith(MCAP_MAGIC):
            return "MCAP magic"
        return None

    def read(self, path: Path, *, config: dict | None = None,
             progress: Progress | None = None) -> FlightLog:
        from mcap.exceptions import InvalidMagic
        from mcap.records import Channel, Chunk, Message, Schema
        from mcap.stream_reader import StreamReader, breakup_chunk

        cfg = rc.RosConfig.from_config(config, path)
        size = path.stat().st_size
        drops: dict[str, int] = {}
        warnings: list[str] = []
        bytes_skipped = 0
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        raw: dict[int, list[tuple[int, int, bytes]]] = {}  # channel -> (log_time, seq, data)
        counts: dict[int, int] = {}
        n_msgs = 0
        seq = 0

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

        with open(path, "rb") as fh:
            reader = StreamReader(fh, emit_chunks=True, validate_crcs=True, record_size_limit=size)
            good = 0
            try:
                for rec in reader.records:
                    if isinstance(rec, Chunk):
                        try:
                            inner = breakup_chunk(rec, validate_crc=True)
                        except Exception as exc:  # noqa: BLE001 - bad compression/CRC/layout
                            drops["bad_chunk"] = drops.get("bad_chunk", 0) + 1
                            bytes_skipped += len(rec.data)
                            warnings.append(f"chunk at byte {good} dropped: {type(exc).__name__}: {exc}")
                            inner = []
                        for r in inner:
                            on_record(r)
                    else:
                        on_record(rec)
                    good = fh.tell()
                    if progress is not None:
                        progress(good, size)
            except InvalidMagic:
                if good == 0:
                    raise IngestError(path, "not an MCAP file (bad magic)") from None
                warnings.append(f"bad closing magic at byte {good}")
                bytes_skipped += size - good
            except Exception as exc:  # noqa: BLE001 - truncation/garbage ends the read
                reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                if n_msgs == 0:
                    raise IngestError(path, f"corrupt or truncated MCAP at byte {good} of {size} "
                                            f"({reason}); no messages before it") from None
                bytes_skipped += size - good
                warnings.append(f"MCAP unreadable from byte {good} of {size} ({reason}); "
                                f"{size - good} byte(s) skipped")
        if n_msgs == 0:
            raise IngestError(path, "MCAP file holds no messages")

        def msgtype_of(ch: Channel) -> str:
            sch = schemas.get(ch.schema_id)
            return rc.normalize_type(sch.name) if sch is not None and sch.name else ""

        conns = [(ch.topic, msgtype_of(ch), counts.get(cid, 0)) for cid, ch in channels.items()]
        defs = [(msgtype_of(ch), *d) for ch in channels.values()
                if (d := _definition(schemas.get(ch.schema_id))) is not None]
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
                "encodings": sorted({ch.message_encoding for ch in channels.values()})}
        return rc.build_flightlog(buckets, unmapped, cfg, path=path, source_format=self.source_format,
                                  diag=diag)


def _json_loads(data: bytes) -> Any:
    return json.loads(data)
