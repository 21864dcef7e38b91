"""ROS message -> canonical stream mapping, shared by the ROS 1/ROS 2 bag and MCAP readers.

The bag and MCAP readers only *decode*: they list the topics of a source, ask :func:`plan_topics`
which ones to decode, deserialise those messages and hand them, per topic, to
:func:`build_flightlog`. Everything about ROS semantics lives here, once:

* **Topic → stream by message type** (:data:`BUILTIN_TYPES`), overridable per topic by the
  ``ingest: ros: topics:`` config map (a stream name, ``null``/``ignore`` to skip, or a mapping
  ``{stream, instance, orientation}``). Messages of other types are decoded when a ``custom``
  (by topic) or ``custom_types`` (by type) entry maps their fields to a canonical stream; the
  simulator's ``uavpipe_msgs/msg/Radar`` mapping ships as a default (:data:`DEFAULT_CUSTOM_TYPES`).
  Topics left unmapped are not deserialised; they are listed in
  ``meta['diagnostics']['unmapped_topics']`` with their type, message count and the reason.
  ``meta['status']`` is ``partial`` when bytes or records were lost to damage
  (``bytes_skipped``, ``records_dropped``), not for topics left unmapped by design.
* **Frames** (REP 103 → ours). World vectors ENU → NED with
  :func:`~pipeline.frames.rotations.enu_to_ned`, body vectors FLU → FRD with
  :func:`~pipeline.frames.rotations.flu_to_frd`, orientations FLU→ENU → FRD→NED with
  :func:`~pipeline.frames.rotations.quat_enu_flu_to_ned_frd`:

  .. math:: (e, n, u) \\mapsto (n, e, -u), \\qquad (x, y, z)_{FLU} \\mapsto (x, -y, -z)_{FRD},
            \\qquad q_{NED \\leftarrow FRD} = q_{NED \\leftarrow ENU} \\otimes q
            \\otimes q_{FLU \\leftarrow FRD}

  REP 103 allows frames suffixed ``_ned``/``_frd``: data whose ``header.frame_id`` (first message
  of the topic) ends that way is taken as already NED/FRD and not converted. Sensor mount
  rotations (e.g. the Husky's rotated ``imu_link``) are *not* applied here; preprocessing does.
  Odometry stays in its source frame (wheel odometry is not north-aligned); its ``frame_id`` and
  ``child_frame_id`` are recorded in ``meta['frames']['odometry']``. Every mapped topic's
  ``frame_id`` is recorded in ``meta['frames']['topics']``.
* **Time.** ``t_abs`` is ``header.stamp`` in ns; where a stamp is zero (unset) the record
  (receive) time is used instead and counted in ``meta['diagnostics']['stamp_from_record_time']``.
  ``t0`` is the earliest ``t_abs`` over all mapped streams, ``t_ns = t_abs − t0``;
  ROS time is Unix time, so ``meta['t0_utc_ns'] = t0`` with ``utc_source = "host"``.
  ``t_boot_ns`` stays NA (ROS has no boot clock).
* **NED origin** (:func:`first_fix_origin`): the earliest fix of any gps source — a
  ``NavSatFix`` with ``status.status >= 0``, or a custom type mapped to ``gps`` — with finite
  latitude/longitude not at lat = lon = 0.
* **Custom types with no config** (:func:`infer_mapping`): a message that embeds standard
  ones (``sensor_msgs/Imu``, ``NavSatFix``, ``MagneticField``, ``FluidPressure``, ``Range``)
  maps through them (``src`` ``<topic>.<field>``); one whose float fields carry NavSatFix names
  (``latitude``, ``longitude``, ``altitude``) maps to ``gps``. The inferred mapping is recorded
  in ``meta['diagnostics']['inferred_mappings']`` and ``meta['frames']['topics']``.

Configuration (``ingest: ros:`` in ``datasets/config.yaml``; every key optional, defaults in
code so ``uavpipe ingest`` works without a config)::

    ros:
      topics:                       # per-topic override of the by-type mapping
        /sonar: {stream: rangefinder, orientation: 25, instance: 0}
        /odometry/filtered: local_position
        /camera/imu: null           # skip
      custom:                       # field mapping for one topic (any message type)
        /radar: {type: uavpipe_msgs/msg/Radar, stream: radar, stamp: header.stamp,
                 fields: {range_m: range, dcos_u: u, dcos_v: v}}
      custom_types:                 # the same keyed by message type (merged over the default)
      world_frames: [map, world, earth, enu, local_origin]

Field paths are dotted (``pose.position.x``; numeric parts index arrays); ``stamp: null``
uses the record time. A bad entry raises :class:`IngestError` naming the file and the key.

Per-type mapping (style.md §3.2):

=====================================  ======================================================
``sensor_msgs/Imu``                    ``imu`` (gyr/acc FLU→FRD); ``orientation`` →
                                       ``attitude`` unless ``orientation_covariance[0] == -1``
                                       (REP 145 "no orientation") or the quaternion is zero
``sensor_msgs/NavSatFix``              ``gps``: ``altitude`` is WGS-84 ellipsoidal →
                                       ``alt_wgs84_m``; ``status.status`` → ``fix_type``
                                       (:data:`NAVSAT_FIX_TYPE`); ``hacc_m`` =
                                       √max(σ²_E, σ²_N), ``vacc_m`` = √σ²_U from
                                       ``position_covariance`` (NaN when its type is UNKNOWN)
``sensor_msgs/MagneticField``          ``mag`` (tesla, FLU→FRD)
``sensor_msgs/FluidPressure``          ``baro.press_Pa``
``sensor_msgs/Range``                  ``rangefinder``: ``dist_m``; ``valid`` = finite and in
                                       [min_range, max_range]; ``orientation`` NaN (unknown)
                                       unless the topic map sets it (25 = down-facing)
``nav_msgs/Odometry``                  ``odometry`` as logged (pose position, twist linear,
                                       twist angular z); topic map ``local_position``
                                       instead treats it as a world ENU pose: position
                                       ENU→NED, twist rotated by the orientation into ENU then
                                       NED, orientation → ``attitude``
``geometry_msgs/PoseStamped``          ``local_position`` position (ENU→NED) + ``attitude``
``geometry_msgs/TwistStamped``         ``local_position`` velocity (ENU→NED) when
                                       ``header.frame_id`` is a world frame (``world_frames``
                                       config, default :data:`DEFAULT_WORLD_FRAMES`, or a
                                       ``_ned``/``_enu`` suffix); a topic in any other (body)
                                       frame is listed in ``unmapped_topics`` with that reason
=====================================  ======================================================
"""

from __future__ import annotations

import difflib
import functools
import math
from dataclasses import dataclass, field
from operator import attrgetter
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np
from .lazy import pandas as pd  # imported on first use (see lazy.py)

from ..config import ConfigError, build, cfield, default_at, validate_section
from ..frames.rotations import enu_to_ned, flu_to_frd, quat_enu_flu_to_ned_frd, quat_normalize, quat_rotate
from . import schema
from .base import FlightLog, IngestError

#: message type (normalised ``pkg/msg/Type``) -> default canonical stream
BUILTIN_TYPES: dict[str, str] = {
    "sensor_msgs/msg/Imu": "imu",
    "sensor_msgs/msg/NavSatFix": "gps",
    "sensor_msgs/msg/MagneticField": "mag",
    "sensor_msgs/msg/FluidPressure": "baro",
    "sensor_msgs/msg/Range": "rangefinder",
    "nav_msgs/msg/Odometry": "odometry",
    "geometry_msgs/msg/PoseStamped": "local_position",
    "geometry_msgs/msg/TwistStamped": "local_position",
}

#: streams a topic map may send each built-in type to
ALLOWED_STREAMS: dict[str, tuple[str, ...]] = {
    **{t: (s,) for t, s in BUILTIN_TYPES.items()},
    "nav_msgs/msg/Odometry": ("odometry", "local_position"),
}

#: The simulator's radar message (``uavpipe_msgs/msg/Radar``: Header header, float64 range,
#: float64 u, float64 v, float64 range_rate, uint8 sensor_id), decoded out of the box.
DEFAULT_CUSTOM_TYPES: dict[str, dict[str, Any]] = {
    "uavpipe_msgs/msg/Radar": {
        "stream": "radar",
        "fields": {"range_m": "range", "dcos_u": "u", "dcos_v": "v",
                   "range_rate_mps": "range_rate", "sensor_id": "sensor_id"},
        "stamp": "header.stamp",
    },
}

#: ``header.frame_id`` values taken as world-fixed, north-aligned ENU frames for TwistStamped.
#: ``odom`` is deliberately absent: wheel odometry frames are not north-aligned.
#: (the schema default of ``ingest.ros.world_frames``: map, world, earth, enu, local_origin)
DEFAULT_WORLD_FRAMES: tuple[str, ...] = tuple(default_at("ingest.ros.world_frames"))

#: ``sensor_msgs/NavSatStatus.status`` -> canonical ``fix_type`` (schema: 1 no fix, 3 3D,
#: 4 DGPS). SBAS and GBAS (ground-based augmentation, used by RTK drivers) are both
#: differential corrections; NavSatStatus cannot tell RTK float from fixed, so neither is claimed.
NAVSAT_FIX_TYPE: dict[int, int] = {-1: 1, 0: 3, 1: 4, 2: 4}


def per_topic_text(counts: Mapping[str, int]) -> str:
    """``"/imu/data 7, /fix 1"``: a count per topic for a warning, largest first."""
    return ", ".join(f"{t} {n}" for t, n in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))


def count_missing(listed: Mapping[str, int], accounted: Mapping[str, int], drops: dict[str, int]) -> dict[str, int]:
    """The messages per topic a log lists (its index, summary or ``metadata.yaml``) beyond those
    read or counted lost (``accounted``), each counted in ``drops['missing:<topic>']``; returns
    them per topic (empty when nothing is short) for the caller's warning."""
    short = {t: n - accounted.get(t, 0) for t, n in listed.items() if n > accounted.get(t, 0)}
    for t, k in short.items():
        drops[f"missing:{t}"] = drops.get(f"missing:{t}", 0) + k
    return short


def normalize_type(name: str) -> str:
    """``pkg/Type`` (ROS 1, MCAP ros1msg) or ``pkg/msg/Type`` -> ``pkg/msg/Type``."""
    name = name.strip()
    parts = name.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name


# --- configuration --------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class CustomSpec:
    """Field mapping of one custom message type: canonical column -> dotted field path."""

    stream: str
    fields: Mapping[str, str]
    stamp: str | None = "header.stamp"
    type: str | None = None


@dataclass(frozen=True, kw_only=True)
class RosConfig:
    """The ``ingest: ros:`` config section, validated (see :meth:`from_config`)."""

    topics: Mapping[str, Mapping[str, Any] | None] = field(default_factory=dict)
    custom: Mapping[str, CustomSpec] = field(default_factory=dict)
    custom_types: Mapping[str, CustomSpec] = field(default_factory=dict)
    world_frames: tuple[str, ...] = cfield("ingest.ros", "world_frames")

    @classmethod
    def from_config(cls, ingest: Mapping[str, Any] | None, path: Path | str | None = None) -> "RosConfig":
        """Build from the ``ingest`` config section (uses its ``ros`` key; defaults otherwise).

        Keys of ``ros``: ``topics`` ({topic: stream | null | {stream, instance, orientation}}),
        ``custom`` ({topic: {type?, stream, fields: {column: field.path}, stamp?}}),
        ``custom_types`` ({msgtype: {stream, fields, stamp?}}, merged over the defaults),
        ``world_frames`` (list of frame ids).

        The section is validated (and defaulted) against the config schema first; what the
        schema cannot know (stream names, their columns) is checked here.

        Raises
        ------
        IngestError
            Naming ``path`` and the offending config key.
        """
        def bad(msg: str) -> IngestError:
            return IngestError(path, f"invalid config ingest.ros.{msg}")

        try:
            ros = validate_section("ingest.ros", (ingest or {}).get("ros"))
        except ConfigError as exc:
            raise IngestError(path, f"invalid config {exc}") from None
        topics: dict[str, Mapping[str, Any] | None] = {}
        for topic, v in (ros.get("topics") or {}).items():
            if v is None or v is False or v == "ignore":
                topics[topic] = None
            elif isinstance(v, str):
                topics[topic] = {"stream": v}
            elif isinstance(v, Mapping):
                extra = set(v) - {"stream", "instance", "orientation"}
                if extra:
                    raise bad(f"topics[{topic!r}]: unknown key(s) {sorted(extra)}")
                topics[topic] = dict(v)
            else:
                raise bad(f"topics[{topic!r}]: expected a stream name, null or a mapping")
            s = (topics[topic] or {}).get("stream")
            if s is not None and s not in schema.STREAMS:
                raise bad(f"topics[{topic!r}]: unknown stream {s!r}")

        def spec(key: str, v: Any) -> CustomSpec:
            if not isinstance(v, Mapping) or "stream" not in v or "fields" not in v:
                raise bad(f"{key}: needs 'stream' and 'fields'")
            stream = v["stream"]
            if stream not in schema.STREAMS:
                raise bad(f"{key}: unknown stream {stream!r}")
            cols = set(schema.column_names(stream)) - {"t_ns", "instance", "src", "t_boot_ns"}
            fields = dict(v["fields"] or {})
            wrong = sorted(set(fields) - cols)
            if wrong:
                raise bad(f"{key}.fields: {wrong} not column(s) of stream {stream!r}")
            if not fields:
                raise bad(f"{key}.fields: empty")
            typ = v.get("type")
            return CustomSpec(stream=stream, fields=fields, stamp=v.get("stamp", "header.stamp"),
                              type=normalize_type(typ) if typ else None)

        custom = {t: spec(f"custom[{t!r}]", v) for t, v in (ros.get("custom") or {}).items()}
        ctypes = {normalize_type(t): spec(f"custom_types[{t!r}]", v)
                  for t, v in {**DEFAULT_CUSTOM_TYPES, **(ros.get("custom_types") or {})}.items()}
        return build(cls, ros, topics=topics, custom=custom, custom_types=ctypes)


# --- planning: which topics to decode, into what -------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Route:
    """How one topic is decoded."""

    topic: str
    msgtype: str
    stream: str
    instance: int
    orientation: float = math.nan
    custom: CustomSpec | None = None
    #: a custom message embedding standard ones: one sub-route per embedded message, whose
    #: ``topic`` is ``<topic>.<field path>`` (its ``src``) and ``path`` the field path
    embedded: tuple["Route", ...] = ()
    path: str = ""
    #: how the mapping of a custom type was inferred (None: built-in or configured)
    inferred: str | None = None


# --- mappings inferred from a custom message's definition ----------------------------------

#: standard messages a custom message may embed: they map through it as they would alone
EMBEDDABLE_TYPES: tuple[str, ...] = (
    "sensor_msgs/msg/Imu", "sensor_msgs/msg/NavSatFix", "sensor_msgs/msg/MagneticField",
    "sensor_msgs/msg/FluidPressure", "sensor_msgs/msg/Range",
)

#: NavSatFix field names (float) that make a custom message a GPS fix: column -> field
NAVSAT_NAMES: dict[str, str] = {"lat_deg": "latitude", "lon_deg": "longitude", "alt_wgs84_m": "altitude"}

_NOT_NESTED = ("std_msgs/msg/Header", "builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration")


@dataclass(frozen=True)
class Inferred:
    """The mapping of a custom type found from its definition (:func:`infer_mapping`)."""

    embedded: tuple[tuple[str, str], ...] = ()  # (field path, standard type)
    custom: CustomSpec | None = None            # NavSatFix-named fields -> gps

    def describe(self) -> str:
        if self.embedded:
            return "embeds " + ", ".join(f"{p}: {t} -> {BUILTIN_TYPES[t]}" for p, t in self.embedded)
        assert self.custom is not None
        return ("NavSatFix field names -> gps ("
                + ", ".join(f"{f} -> {c}" for c, f in self.custom.fields.items()) + ")")


def _fields(fielddefs: Mapping[str, Any], msgtype: str) -> list:
    d = fielddefs.get(msgtype)
    return list(d[1]) if d else []


def infer_mapping(msgtype: str, fielddefs: Mapping[str, Any], *, max_depth: int = 3) -> Inferred | None:
    """Map a custom message type through what its definition shows, with no config.

    1. Fields (at any depth up to ``max_depth``, not inside arrays) whose type is one of
       :data:`EMBEDDABLE_TYPES` map as that type would on its own topic (``sensor_msgs/Imu``
       -> ``imu`` and ``attitude``, ``NavSatFix`` -> ``gps``, ``MagneticField`` -> ``mag``, ...).
    2. Otherwise, top-level float fields named ``latitude`` and ``longitude`` (and
       ``altitude``, WGS-84 as in NavSatFix) make the message a ``gps`` fix; its stamp is
       ``header.stamp`` when it has a ``header``, else the record time.

    Parameters
    ----------
    fielddefs : mapping
        rosbags field definitions (``Typestore.fielddefs`` or ``get_types_from_msg`` output):
        ``msgtype -> (constants, [(name, (Nodetype, detail)), ...])``.

    Returns
    -------
    Inferred or None
        None when nothing is recognised (the topic stays unmapped).
    """
    from rosbags.typesys.base import Nodetype

    msgtype = normalize_type(msgtype)
    if msgtype in BUILTIN_TYPES or msgtype not in fielddefs:
        return None
    found: list[tuple[str, str]] = []

    def walk(t: str, prefix: str, depth: int) -> None:
        for name, (nt, det) in _fields(fielddefs, t):
            if nt != Nodetype.NAME:
                continue
            sub = normalize_type(det)
            p = f"{prefix}{name}"
            if sub in EMBEDDABLE_TYPES:
                found.append((p, sub))
            elif depth < max_depth and sub not in _NOT_NESTED and sub not in BUILTIN_TYPES:
                walk(sub, p + ".", depth + 1)

    walk(msgtype, "", 1)
    if found:
        return Inferred(embedded=tuple(found))
    top = {name: (nt, det) for name, (nt, det) in _fields(fielddefs, msgtype)}

    def is_float(name: str) -> bool:
        nt, det = top.get(name, (None, None))
        return nt == Nodetype.BASE and str(det[0]).startswith("float")

    if is_float("latitude") and is_float("longitude"):
        fields = {c: f for c, f in NAVSAT_NAMES.items() if is_float(f)}
        has_header = top.get("header", (None, None))[0] == Nodetype.NAME
        return Inferred(custom=CustomSpec(stream="gps", fields=fields,
                                          stamp="header.stamp" if has_header else None))
    return None


@functools.lru_cache(maxsize=256)
def parse_definition(msgtype: str, fmt: str, text: str) -> Mapping[str, Any]:
    """Field definitions in one stored message definition (``fmt`` ``msg`` or ``idl``);
    empty when it cannot be parsed (the reader reports that when it decodes)."""
    from rosbags.typesys import get_types_from_idl, get_types_from_msg

    try:
        if fmt == "idl":
            sep = "=" * 80 + "\n"
            if not text.startswith(f"{sep}IDL: "):
                return get_types_from_idl(text)
            out: dict = {}
            for part in text.split(sep)[1:]:
                out.update(get_types_from_idl(part.split("\n", 1)[1]))
            return out
        return get_types_from_msg(text, normalize_type(msgtype))
    except Exception:  # noqa: BLE001 - an unparsable definition: nothing to infer from
        return {}


def defined_fields(defs: Iterable[tuple[str, str, str]]) -> dict[str, Any]:
    """Field definitions of the custom (non built-in) types among stored definitions
    ``(msgtype, format, text)``, for :func:`plan_topics` to infer mappings from."""
    out: dict[str, Any] = {}
    for msgtype, fmt, text in defs:
        if text and normalize_type(msgtype) not in BUILTIN_TYPES:
            out.update(parse_definition(msgtype, fmt, text))
    return out


def is_candidate(topic: str, msgtype: str, cfg: RosConfig, definition: tuple[str, str] | None = None) -> bool:
    """Could this topic be routed? Readers that keep raw bytes while scanning keep them only
    for such topics. ``definition`` is the stored ``(format, text)`` of its type, from which a
    custom type's mapping may be inferred (:func:`infer_mapping`)."""
    msgtype = normalize_type(msgtype)
    if topic in cfg.topics:
        return cfg.topics[topic] is not None
    if topic in cfg.custom or msgtype in BUILTIN_TYPES or msgtype in cfg.custom_types:
        return True
    if definition and definition[1]:
        return infer_mapping(msgtype, parse_definition(msgtype, *definition)) is not None
    return False


def warn_configured_topics_absent(connections: Iterable[tuple[str, str, int]], cfg: RosConfig,
                                  warnings: list[str]) -> list[str]:
    """Configured ``ingest.ros.topics``/``custom`` topics the source does not hold.

    A topic whose name is close to one the log holds (``difflib`` ratio ≥ 0.75: ``/sonarr``
    beside ``/sonar``) is most likely misspelt, which would otherwise change nothing and say
    nothing: one warning names it and the near match. The others are sensors this log does not
    carry (a dataset's one config lists what some of its bags hold: the simulator's
    ``/rangefinder`` on the husky bags), returned for ``diagnostics.absent_topics``, not warned.
    """
    present = {t for t, _, _ in connections}
    # a topic the config skips (null) may well be absent too
    used = [t for t, m in cfg.topics.items() if m is not None]
    quiet: list[str] = []
    for key, names in (("topics", used), ("custom", list(cfg.custom))):
        near = []
        for t in names:
            if t in present:
                continue
            close = difflib.get_close_matches(t, sorted(present), n=1, cutoff=0.75)
            if close:
                near.append(f"{t} (did you mean {close[0]}?)")
            else:
                quiet.append(t)
        if near:
            warnings.append(
                f"ingest.ros.{key}: topic(s) {', '.join(near)} not in the log (it has "
                f"{', '.join(sorted(present)[:12])}{', ...' if len(present) > 12 else ''})")
    return quiet


def plan_topics(connections: Iterable[tuple[str, str, int]], cfg: RosConfig,
                path: Path | str | None = None,
                fielddefs: Mapping[str, Any] | None = None) -> tuple[dict[str, Route], dict[str, dict]]:
    """Choose a route for each topic.

    Parameters
    ----------
    connections : iterable of (topic, msgtype, message count)
        One entry per connection (a topic may appear several times, e.g. in split bags).
    fielddefs : mapping, optional
        Field definitions of the source's types: a type with neither a built-in nor a
        configured mapping is mapped by :func:`infer_mapping` when its definition shows how.

    Returns
    -------
    routes : dict topic -> Route
        Topics to decode; instances are numbered per stream in sorted topic order unless
        the topic map fixes them.
    unmapped : dict topic -> {type, count, reason}
    """
    types: dict[str, str] = {}
    counts: dict[str, int] = {}
    for topic, msgtype, n in connections:
        types.setdefault(topic, normalize_type(msgtype))
        counts[topic] = counts.get(topic, 0) + int(n or 0)
    pending: list[tuple[str, str, str, dict, CustomSpec | None]] = []
    unmapped: dict[str, dict] = {}
    for topic in sorted(types):
        msgtype = types[topic]
        over = cfg.topics.get(topic, {}) if topic in cfg.topics else {}
        if topic in cfg.topics and over is None:
            unmapped[topic] = {"type": msgtype, "count": counts[topic], "reason": "ignored by config"}
            continue
        custom = cfg.custom.get(topic)
        if custom is not None and custom.type and custom.type != msgtype:
            raise IngestError(path, f"config ingest.ros.custom[{topic!r}] expects type "
                                    f"{custom.type}, the source has {msgtype}")
        if custom is None and msgtype not in BUILTIN_TYPES:
            custom = cfg.custom_types.get(msgtype)
        if custom is not None:
            stream = over.get("stream") or custom.stream
            if stream != custom.stream:
                raise IngestError(path, f"config ingest.ros.topics[{topic!r}]: stream {stream!r} "
                                        f"conflicts with its custom mapping to {custom.stream!r}")
        elif msgtype in BUILTIN_TYPES:
            stream = over.get("stream") or BUILTIN_TYPES[msgtype]
            if stream not in ALLOWED_STREAMS[msgtype]:
                raise IngestError(path, f"config ingest.ros.topics[{topic!r}]: a {msgtype} topic "
                                        f"cannot go to stream {stream!r} (allowed: "
                                        f"{', '.join(ALLOWED_STREAMS[msgtype])})")
        else:
            inf = infer_mapping(msgtype, fielddefs) if fielddefs is not None else None
            if inf is not None and inf.custom is not None and over.get("stream") in (None, "gps"):
                pending.append((topic, msgtype, "gps", over, inf.custom, inf))
                continue
            if inf is not None and inf.embedded and not over.get("stream"):
                pending.append((topic, msgtype, "", over, None, inf))
                continue
            reason = "no mapping for this message type"
            if over.get("stream"):
                raise IngestError(path, f"config ingest.ros.topics[{topic!r}]: type {msgtype} has no "
                                        "built-in mapping; add an ingest.ros.custom field mapping")
            unmapped[topic] = {"type": msgtype, "count": counts[topic], "reason": reason}
            continue
        pending.append((topic, msgtype, stream, over, custom, None))
    routes: dict[str, Route] = {}
    used: dict[str, set[int]] = {}
    for topic, msgtype, stream, over, custom, inf in pending:  # fixed instances first
        if over.get("instance") is not None and stream:
            used.setdefault(stream, set()).add(int(over["instance"]))

    def take(stream: str) -> int:
        taken = used.setdefault(stream, set())
        inst = next(i for i in range(len(taken) + 1) if i not in taken)
        taken.add(inst)
        return inst

    for topic, msgtype, stream, over, custom, inf in pending:
        desc = inf.describe() if inf is not None else None
        if inf is not None and inf.embedded:  # one sub-route per embedded standard message
            subs = tuple(Route(topic=f"{topic}.{p}", msgtype=t, stream=BUILTIN_TYPES[t], instance=take(BUILTIN_TYPES[t]),
                               orientation=math.nan if over.get("orientation") is None else float(over["orientation"]),
                               path=p, inferred=f"embedded field {p!r} of {msgtype} ({topic})")
                         for p, t in inf.embedded)
            routes[topic] = Route(topic=topic, msgtype=msgtype, stream="+".join(r.stream for r in subs),
                                  instance=subs[0].instance, embedded=subs, inferred=desc)
            continue
        if over.get("instance") is not None:
            inst = int(over["instance"])
        else:
            inst = take(stream)
        if not 0 <= inst <= 255:
            raise IngestError(path, f"config ingest.ros.topics[{topic!r}]: instance {inst} not in 0..255")
        orient = over.get("orientation")
        routes[topic] = Route(topic=topic, msgtype=msgtype, stream=stream, instance=inst,
                              orientation=math.nan if orient is None else float(orient),
                              custom=custom, inferred=desc)
    return routes, unmapped


# --- field extraction -----------------------------------------------------------------------


def _resolve(obj: Any, part: str) -> Any:
    if isinstance(obj, dict):  # JSON-decoded messages
        return obj[part]
    if part.isdigit() and not hasattr(obj, part):
        return obj[int(part)]
    return getattr(obj, part)


def getter(path: str) -> Callable[[Any], Any]:
    """Accessor for a dotted field path (``pose.position.x``; numeric parts index arrays)."""
    parts = path.split(".")
    if not any(p.isdigit() for p in parts):
        fast = attrgetter(path)

        def get(obj: Any) -> Any:
            try:
                return fast(obj)
            except AttributeError:  # dict-shaped (JSON) messages
                for p in parts:
                    obj = _resolve(obj, p)
                return obj
        return get

    def get_slow(obj: Any) -> Any:
        for p in parts:
            obj = _resolve(obj, p)
        return obj
    return get_slow


def col(msgs: list, path: str, dtype: Any = np.float64) -> np.ndarray:
    """One field of every message as a 1-D array."""
    g = getter(path)
    if dtype is object:
        return np.array([g(m) for m in msgs], dtype=object)
    return np.fromiter((g(m) for m in msgs), dtype=dtype, count=len(msgs))


def vec3(msgs: list, path: str) -> np.ndarray:
    """``path.{x,y,z}`` of every message as an ``(n, 3)`` array."""
    return np.stack([col(msgs, f"{path}.{a}") for a in "xyz"], axis=-1)


def _time_ns(t: Any) -> int:
    try:  # rosbags / mcap_ros2 objects: builtin_interfaces/Time
        return t.sec * 1_000_000_000 + t.nanosec
    except AttributeError:
        pass
    if isinstance(t, (int, np.integer)):
        return int(t)
    if isinstance(t, float):
        return int(round(t * 1e9))
    if isinstance(t, dict):
        sec = t.get("sec", t.get("secs", 0))
        nsec = t.get("nanosec", t.get("nsec", t.get("nsecs", 0)))
    else:  # genpy-style ROS 1 time
        sec, nsec = getattr(t, "secs", 0), getattr(t, "nsecs", 0)
    return int(sec) * 1_000_000_000 + int(nsec)


def stamps_ns(msgs: list, path: str = "header.stamp") -> np.ndarray:
    """``header.stamp`` (``sec``/``nanosec``, ROS 1 ``secs``/``nsecs``, or int ns) as int64 ns."""
    g = getter(path)
    return np.fromiter((_time_ns(g(m)) for m in msgs), dtype=np.int64, count=len(msgs))


def _frame_id(msgs: list, path: str = "header.frame_id") -> str | None:
    try:
        return str(getter(path)(msgs[0]))
    except (AttributeError, KeyError, IndexError, TypeError):
        return None


# --- per-type converters --------------------------------------------------------------------


@dataclass
class Bucket:
    """Messages of one topic, in source order, with their record (receive) times in ns."""

    route: Route
    msgs: list = field(default_factory=list)
    rec_ns: list = field(default_factory=list)


Rows = dict[str, np.ndarray]  # column -> values, plus "t_abs" (int64 ns, absolute)


@dataclass
class _Ctx:
    cfg: RosConfig
    diag: dict
    frames: dict
    unmapped: dict


def _is_frd(frame: str | None) -> bool:
    return bool(frame) and frame.lower().endswith(("_frd", "_ned"))


def _is_ned(frame: str | None) -> bool:
    return bool(frame) and frame.lower().endswith("_ned")


def _body(v: np.ndarray, frame: str | None) -> np.ndarray:
    return v if _is_frd(frame) else flu_to_frd(v)


def _world(v: np.ndarray, frame: str | None) -> np.ndarray:
    return v if _is_ned(frame) else enu_to_ned(v)


def _quat(msgs: list, path: str) -> np.ndarray:
    return np.stack([col(msgs, f"{path}.{c}") for c in "wxyz"], axis=-1)


def _attitude_rows(q_ros: np.ndarray, keep: np.ndarray, frame: str | None, t: np.ndarray) -> Rows:
    q = q_ros[keep]
    q = quat_normalize(q) if _is_frd(frame) else quat_enu_flu_to_ned_frd(q)
    return {"t_abs": t[keep], **{f"q_{c}": q[:, i] for i, c in enumerate("wxyz")}}


def _conv_imu(msgs, t, route, frame, ctx) -> dict[str, Rows]:
    gyr = _body(vec3(msgs, "angular_velocity"), frame)
    acc = _body(vec3(msgs, "linear_acceleration"), frame)
    out = {"imu": {"t_abs": t, **{f"gyr_{a}_radps": gyr[:, i] for i, a in enumerate("xyz")},
                   **{f"acc_{a}_mps2": acc[:, i] for i, a in enumerate("xyz")}}}
    has_q = col(msgs, "orientation_covariance.0") != -1.0
    q = _quat(msgs, "orientation")
    norm = np.linalg.norm(q, axis=1)
    good = has_q & np.isfinite(norm) & (norm > 0.5)
    if np.any(has_q & ~good):
        ctx.diag["warnings"].append(f"{route.topic}: {int(np.sum(has_q & ~good))} orientation(s) "
                                    "zero/non-finite with covariance set; not used as attitude")
    if good.any():
        out["attitude"] = _attitude_rows(q, good, frame, t)
    return out


def _conv_navsatfix(msgs, t, route, frame, ctx) -> dict[str, Rows]:
    status = col(msgs, "status.status", np.int64)
    fix = np.array([NAVSAT_FIX_TYPE.get(int(s), np.nan) for s in status], dtype=np.float64)
    cov_type = col(msgs, "position_covariance_type", np.int64)
    c_e, c_n, c_u = (col(msgs, f"position_covariance.{i}") for i in (0, 4, 8))
    known = cov_type > 0
    with np.errstate(invalid="ignore"):
        hacc = np.where(known, np.sqrt(np.maximum(c_e, c_n)), np.nan)
        vacc = np.where(known, np.sqrt(c_u), np.nan)
    rows = {"t_abs": t, "lat_deg": col(msgs, "latitude"), "lon_deg": col(msgs, "longitude"),
            "alt_wgs84_m": col(msgs, "altitude"), "fix_type": fix, "hacc_m": hacc, "vacc_m": vacc,
            "_status": status}
    return {"gps": rows}


def _conv_mag(msgs, t, route, frame, ctx) -> dict[str, Rows]:
    m = _body(vec3(msgs, "magnetic_field"), frame)
    return {"mag": {"t_abs": t, **{f"mag_{a}_T": m[:, i] for i, a in enumerate("xyz")}}}


def _conv_baro(msgs, t, route, frame, ctx) -> dict[str, Rows]:
    return {"baro": {"t_abs": t, "press_Pa": col(msgs, "fluid_pressure")}}


def _conv_range(msgs, t, route, frame, ctx) -> dict[str, Rows]:
    r = col(msgs, "range")
    lo, hi = col(msgs, "min_range"), col(msgs, "max_range")
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(r) & (r >= lo) & (r <= hi)
    # REP 117: +inf "no return within max_range", -inf "closer than min_range". The other
    # readers give an out-of-range reading a distance at the limit (valid False); so does this
    # one, so dist_m stays finite for plots and statistics and `valid` keeps the meaning
    r = np.where(r == np.inf, hi, np.where(r == -np.inf, lo, r))
    return {"rangefinder": {"t_abs": t, "dist_m": r, "valid": valid,
                            "orientation": np.full(len(r), route.orientation)}}


def _conv_odometry(msgs, t, route, frame, ctx) -> dict[str, Rows]:
    pos = vec3(msgs, "pose.pose.position")
    vel = vec3(msgs, "twist.twist.linear")
    child = _frame_id(msgs, "child_frame_id")
    info = {"topic": route.topic, "frame_id": frame, "child_frame_id": child}
    if route.stream == "odometry":
        ctx.frames.setdefault("odometry", info)
        return {"odometry": {"t_abs": t, **{f"pos_{a}_m": pos[:, i] for i, a in enumerate("xyz")},
                             **{f"vel_{a}_mps": vel[:, i] for i, a in enumerate("xyz")},
                             "yaw_rate_radps": col(msgs, "twist.twist.angular.z")}}
    # local_position: a world-frame ENU pose; the twist is in child_frame_id (body FLU)
    ctx.frames.setdefault("local_position", info)
    q = _quat(msgs, "pose.pose.orientation")
    norm = np.linalg.norm(q, axis=1)
    good = np.isfinite(norm) & (norm > 0.5)
    q_ok = np.where(good[:, None], q, [1.0, 0.0, 0.0, 0.0])
    if _is_ned(frame):
        v_world = quat_rotate(quat_normalize(q_ok), vel)
    else:
        v_world = enu_to_ned(quat_rotate(quat_normalize(q_ok), vel))
    v_world[~good] = np.nan
    p = _world(pos, frame)
    out = {"local_position": {"t_abs": t, **{f"pos_{a}_m": p[:, i] for i, a in enumerate("ned")},
                              **{f"vel_{a}_mps": v_world[:, i] for i, a in enumerate("ned")}}}
    if good.any():
        out["attitude"] = _attitude_rows(q, good, frame, t)
    return out


def _conv_pose(msgs, t, route, frame, ctx) -> dict[str, Rows]:
    p = _world(vec3(msgs, "pose.position"), frame)
    q = _quat(msgs, "pose.orientation")
    norm = np.linalg.norm(q, axis=1)
    good = np.isfinite(norm) & (norm > 0.5)
    out = {"local_position": {"t_abs": t, **{f"pos_{a}_m": p[:, i] for i, a in enumerate("ned")}}}
    if good.any():
        out["attitude"] = _attitude_rows(q, good, frame, t)
    return out


def _conv_twist(msgs, t, route, frame, ctx) -> dict[str, Rows]:
    f = (frame or "").lstrip("/").lower()
    if not (f in ctx.cfg.world_frames or f.endswith(("_ned", "_enu"))):
        ctx.unmapped[route.topic] = {
            "type": route.msgtype, "count": len(msgs),
            "reason": f"TwistStamped in frame {frame!r}, not a world frame (ingest.ros.world_frames)"}
        return {}
    v = _world(vec3(msgs, "twist.linear"), frame)
    return {"local_position": {"t_abs": t, **{f"vel_{a}_mps": v[:, i] for i, a in enumerate("ned")}}}


_CONVERTERS = {
    "sensor_msgs/msg/Imu": _conv_imu,
    "sensor_msgs/msg/NavSatFix": _conv_navsatfix,
    "sensor_msgs/msg/MagneticField": _conv_mag,
    "sensor_msgs/msg/FluidPressure": _conv_baro,
    "sensor_msgs/msg/Range": _conv_range,
    "nav_msgs/msg/Odometry": _conv_odometry,
    "geometry_msgs/msg/PoseStamped": _conv_pose,
    "geometry_msgs/msg/TwistStamped": _conv_twist,
}


def _conv_custom(msgs, t, route, frame, ctx) -> dict[str, Rows]:
    spec = route.custom
    assert spec is not None
    rows: Rows = {"t_abs": t}
    for column, path in spec.fields.items():
        try:
            vals = col(msgs, path, object)
        except (AttributeError, KeyError, IndexError, TypeError) as exc:
            raise IngestError(None, f"topic {route.topic} ({route.msgtype}): field {path!r} for "
                                    f"column {column!r} not found ({type(exc).__name__}: {exc})") from None
        dtype = next(c.dtype for c in schema.columns(spec.stream) if c.name == column)
        if dtype == "float64":
            vals = vals.astype(np.float64)
        elif dtype in ("bool", "boolean"):
            vals = vals.astype(bool)
        rows[column] = vals
    return {spec.stream: rows}


# --- assembly -------------------------------------------------------------------------------


def first_fix_origin(gps_parts: Iterable[tuple[Route, Rows]]) -> dict | None:
    """NED origin: the earliest fix of any gps source (NavSatFix or a custom mapping) with
    finite latitude and longitude, not at lat = lon = 0 (no fix), and not flagged as no fix
    (``status.status < 0`` for NavSatFix, ``fix_type <= 1`` where a custom mapping gives one);
    ties go to the lower instance. ``alt_wgs84_m`` is None where the source has no altitude."""
    best = None
    for route, rows in gps_parts:
        n = len(rows["t_abs"])
        if not n or "lat_deg" not in rows or "lon_deg" not in rows:
            continue
        lat = np.asarray(rows["lat_deg"], dtype=np.float64)
        lon = np.asarray(rows["lon_deg"], dtype=np.float64)
        ok = np.isfinite(lat) & np.isfinite(lon) & ~((lat == 0) & (lon == 0))
        if "_status" in rows:
            ok &= np.asarray(rows["_status"]) >= 0
        elif "fix_type" in rows:
            ok &= ~(np.asarray(rows["fix_type"], dtype=np.float64) <= 1)
        if not ok.any():
            continue
        i = int(np.flatnonzero(ok)[np.argmin(rows["t_abs"][ok])])
        key = (int(rows["t_abs"][i]), route.instance)
        if best is None or key < best[0]:
            alt = float(rows["alt_wgs84_m"][i]) if "alt_wgs84_m" in rows else float("nan")
            best = (key, {"lat_deg": float(lat[i]), "lon_deg": float(lon[i]),
                          "alt_wgs84_m": alt if math.isfinite(alt) else None})
    return None if best is None else best[1]


def build_flightlog(buckets: Mapping[str, Bucket], unmapped: Mapping[str, dict], cfg: RosConfig,
                    *, path: Path | str, source_format: str, diag: dict | None = None,
                    extra_meta: Mapping[str, Any] | None = None) -> FlightLog:
    """Convert decoded messages per topic into a canonical :class:`FlightLog`.

    Parameters
    ----------
    buckets : mapping topic -> Bucket
        Deserialised messages of each routed topic, in source order.
    unmapped : mapping topic -> {type, count, reason}
        From :func:`plan_topics`; recorded in the diagnostics.
    diag : dict, optional
        Diagnostics collected while decoding (drops, bytes skipped); completed here.

    Raises
    ------
    IngestError
        When no mapped topic yielded any message.
    """
    diag = {**schema.new_diagnostics(), **(diag or {})}
    frames: dict[str, Any] = {"world": "NED", "body": "FRD",
                              "conversion": "ROS REP 103 ENU/FLU converted to NED/FRD on ingest; "
                                            "odometry kept in its source frame; sensor mounts not applied",
                              "topics": {}}
    unmapped = {k: dict(v) for k, v in unmapped.items()}
    ctx = _Ctx(cfg=cfg, diag=diag, frames=frames, unmapped=unmapped)
    parts: dict[str, list[tuple[Route, Rows]]] = {}
    zero_stamps: dict[str, int] = {}
    inferred: dict[str, dict] = {}

    def convert(topic: str, route: Route, msgs: list, rec: np.ndarray, outer_t: np.ndarray | None) -> None:
        """Stamps, frame and the converter of one (sub-)route; rows into ``parts``."""
        stamp_path = route.custom.stamp if route.custom is not None else "header.stamp"
        if stamp_path:
            try:
                st = stamps_ns(msgs, stamp_path)
            except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
                raise IngestError(path, f"topic {topic} ({route.msgtype}): stamp field {stamp_path!r} "
                                        f"unreadable ({type(exc).__name__}: {exc})") from None
            zero = st == 0
        else:
            st, zero = rec, np.zeros(len(rec), dtype=bool)
        if outer_t is not None:  # an embedded message without its own stamp: the outer one's
            st = np.where(zero, outer_t, st)
            zero = st == 0
        if zero.any():
            zero_stamps[topic] = int(zero.sum())
        t_abs = np.where(zero, rec, st)
        frame = _frame_id(msgs)
        conv = _conv_custom if route.custom is not None else _CONVERTERS[route.msgtype]
        try:
            out = conv(msgs, t_abs, route, frame, ctx)
        except IngestError as exc:
            raise IngestError(path, exc.reason) from None
        except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
            raise IngestError(path, f"topic {topic} ({route.msgtype}): unexpected message layout "
                                    f"({type(exc).__name__}: {exc})") from None
        info = {"type": route.msgtype, "stream": route.stream, "instance": route.instance,
                "frame_id": frame}
        if route.inferred:
            info["inferred"] = route.inferred
        if route.msgtype == "nav_msgs/msg/Odometry":
            info["child_frame_id"] = _frame_id(msgs, "child_frame_id")
        frames["topics"][topic] = info
        if route.stream not in frames and route.instance == 0 and route.stream != "odometry":
            frames[route.stream] = {"topic": topic, "frame_id": frame}
        for stream, rows in out.items():
            parts.setdefault(stream, []).append((route, rows))

    for topic in sorted(buckets):
        b = buckets[topic]
        route = b.route
        diag["record_counts"][route.msgtype] = diag["record_counts"].get(route.msgtype, 0) + len(b.msgs)
        if route.inferred:
            inferred[topic] = {"type": route.msgtype, "mapping": route.inferred,
                               "streams": ({r.topic: {"type": r.msgtype, "stream": r.stream, "instance": r.instance}
                                            for r in route.embedded} if route.embedded else
                                           {topic: {"stream": route.stream, "instance": route.instance}})}
        if not b.msgs:
            continue
        rec = np.asarray(b.rec_ns, dtype=np.int64)
        if not route.embedded:
            convert(topic, route, b.msgs, rec, None)
            continue
        try:  # the outer header's stamp (if any) stands in for unset embedded stamps
            outer = stamps_ns(b.msgs, "header.stamp")
        except (AttributeError, KeyError, IndexError, TypeError, ValueError):
            outer = np.zeros(len(rec), dtype=np.int64)
        for sub in route.embedded:
            g = getter(sub.path)
            try:
                msgs = [g(m) for m in b.msgs]
            except (AttributeError, KeyError, IndexError, TypeError) as exc:
                raise IngestError(path, f"topic {topic} ({route.msgtype}): embedded field {sub.path!r} "
                                        f"unreadable ({type(exc).__name__}: {exc})") from None
            diag["record_counts"][sub.msgtype] = diag["record_counts"].get(sub.msgtype, 0) + len(msgs)
            convert(sub.topic, sub, msgs, rec, outer)
    if inferred:
        diag["inferred_mappings"] = inferred
    if zero_stamps:
        diag["stamp_from_record_time"] = zero_stamps
        diag["warnings"].append(f"header.stamp zero on {sum(zero_stamps.values())} message(s) "
                                f"({', '.join(sorted(zero_stamps))}); record time used")
    diag["unmapped_topics"] = unmapped
    nonempty = [r["t_abs"] for lst in parts.values() for _, r in lst if len(r["t_abs"])]
    if not nonempty:
        found = ", ".join(f"{k} ({v['type']})" for k, v in sorted(unmapped.items())) or "none"
        raise IngestError(path, "no messages on any mapped topic (decodable topics: "
                                f"{', '.join(sorted(buckets)) or 'none'}; unmapped: {found})")
    t0 = int(min(int(t.min()) for t in nonempty))

    ned_origin = first_fix_origin(parts.get("gps", []))

    streams: dict[str, pd.DataFrame] = {}
    attitude_inst = 0
    for stream, lst in parts.items():
        frames_ = []
        for route, rows in lst:
            n = len(rows["t_abs"])
            if not n:
                continue
            inst = route.instance
            if stream == "attitude" and route.stream != "attitude":  # secondary output
                inst, attitude_inst = attitude_inst, attitude_inst + 1
            data = {k: v for k, v in rows.items() if k not in ("t_abs", "_status")}
            data["t_ns"] = rows["t_abs"] - t0
            data["instance"] = np.full(n, inst, dtype=np.uint8)
            data["src"] = np.full(n, route.topic, dtype=object)
            frames_.append(pd.DataFrame(data))
        if frames_:
            streams[stream] = pd.concat(frames_, ignore_index=True) if len(frames_) > 1 else frames_[0]
    status = "partial" if diag.get("bytes_skipped") or diag.get("records_dropped") else "ok"
    meta = schema.new_meta(source_format=source_format, t0_utc_ns=t0, utc_source="host",
                           t0_boot_ns=None, ned_origin=ned_origin, frames=frames, diagnostics=diag,
                           status=status)
    if extra_meta:
        meta.update(extra_meta)
    try:
        return FlightLog.from_streams(meta, streams)
    except schema.SchemaError as exc:
        raise IngestError(path, f"mapped values do not fit the canonical schema: {exc}") from None


# --- rosbags type store from definitions carried by the source -----------------------------


def make_typestore(defs: Iterable[tuple[str, str, str]], base: str | None,
                   wanted: Iterable[str] = ()):
    """Cached :func:`_make_typestore` (compiling a store's deserialisers is the slow part, and
    a batch of flights from one robot carries the same definitions)."""
    return _make_typestore_cached(tuple(defs), base, frozenset(wanted))


@functools.lru_cache(maxsize=32)
def _make_typestore_cached(defs: tuple, base: str | None, wanted: frozenset):
    return _make_typestore(defs, base, wanted)


def _make_typestore(defs: Iterable[tuple[str, str, str]], base: str | None,
                    wanted: Iterable[str] = ()):
    """A rosbags ``Typestore`` with the source's own message definitions over a default store.

    Parameters
    ----------
    defs : iterable of (msgtype, format, text)
        ``format`` is ``"msg"`` (ROS 1 msgdef, ROS 2 ``ros2msg``; dependencies concatenated
        after ``=====`` / ``MSG: pkg/Type`` lines) or ``"idl"`` (``ros2idl``).
    base : str or None
        Name of a rosbags ``Stores`` member whose definitions fill in types the source does not
        carry (older rosbag2 sqlite3 bags store none), e.g. ``"ROS2_HUMBLE"``; the source's own
        definitions win, which is how custom message types are decoded.
    wanted : iterable of str
        Message types to be decoded; only they and their dependencies are taken from ``base``.

    Returns
    -------
    (typestore, {msgtype: reason}) for definitions that could not be parsed.
    """
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
    from rosbags.typesys.base import Nodetype

    typs: dict = {}
    errors: dict[str, str] = {}
    for msgtype, fmt, text in defs:
        if not text:
            continue
        try:
            if fmt == "idl":
                sep = "=" * 80 + "\n"
                if text.startswith(f"{sep}IDL: "):
                    for part in text.split(sep)[1:]:
                        typs.update(get_types_from_idl(part.split("\n", 1)[1]))
                else:
                    typs.update(get_types_from_idl(text))
            else:
                typs.update(get_types_from_msg(text, normalize_type(msgtype)))
        except Exception as exc:  # noqa: BLE001 - any parser failure is a per-type diagnostic
            errors[normalize_type(msgtype)] = f"{type(exc).__name__}: {exc}"
    if base:
        # fill in what the source lacks: the wanted types and every type they reference
        stock = get_typestore(Stores[base]).fielddefs
        todo = [normalize_type(t) for t in wanted]
        seen: set[str] = set()
        while todo:
            t = todo.pop()
            if t in seen:
                continue
            seen.add(t)
            if t not in typs and t in stock:
                typs[t] = stock[t]
            for _name, (nt, det) in (typs.get(t) or ((), ()))[1]:
                if nt == Nodetype.NAME:
                    todo.append(det)
                elif nt in (Nodetype.ARRAY, Nodetype.SEQUENCE) and det[0][0] == Nodetype.NAME:
                    todo.append(det[0][1])
    store = get_typestore(Stores.EMPTY)
    store.register(typs)
    return store, errors
