"""``uavpipe info LOG...``: which reader took a file and why, duration, streams, diagnostics.

``--json`` prints one array with an entry per LOG, in order (a failed one as ``{path, status:
"failed", error}``), as strict JSON: an undefined rate (a one-row stream) is ``null``, not NaN.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

from ..io import registry, schema
from ..io.base import IngestError, grouped_drops
from ..io.manifest import reader_names
from .common import add_config_option
from .progress import progress_bar


def add_parser(sub) -> None:
    p = sub.add_parser("info", help="describe a log: format, reader, streams with rates, diagnostics")
    p.add_argument("logs", nargs="+", type=Path, metavar="LOG")
    names = reader_names()
    p.add_argument("--format", dest="fmt", default=None, choices=names, metavar="FORMAT",
                   help=f"force a reader instead of detecting: {', '.join(names)}")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    add_config_option(p, "dataset config whose 'ingest' section the readers use")
    p.set_defaults(func=run)


SENSOR_STREAMS = schema.SENSOR_STREAMS


def _sensor_span(log) -> dict | None:
    """``{start_s, end_s, duration_s}`` of the sensor streams (t = 0 is the first record of any
    stream), None when the log has no sensor rows."""
    lo, hi = log.span_ns(SENSOR_STREAMS)
    if lo is None:
        return None
    return {"start_s": round(lo * 1e-9, 3), "end_s": round(hi * 1e-9, 3),
            "duration_s": round((hi - lo) * 1e-9, 3)}


def _topics(m: dict) -> dict:
    """ROS/MCAP: topic -> {type, stream, instance[, inferred]} as the reader mapped them."""
    return {t: {k: v for k, v in info.items() if k in ("type", "stream", "instance", "inferred")}
            for t, info in sorted(((m.get("frames") or {}).get("topics") or {}).items())}


def describe(log) -> dict:
    m = log.meta
    diag = m.get("diagnostics", {})
    return {
        "path": m.get("source_path"),
        "flight_id": m.get("flight_id"),
        "format": m.get("source_format"),
        "reader": f"{m.get('reader')} v{m.get('reader_version')}",
        "detected_by": m.get("detected_by"),
        "status": m.get("status"),
        "duration_s": round(log.duration_s, 3),
        "sensor_span": _sensor_span(log),
        "t0_utc_ns": m.get("t0_utc_ns"),
        "leap_seconds": m.get("leap_seconds"),
        "ned_origin": m.get("ned_origin"),
        "ned_origin_reason": m.get("ned_origin_reason"),
        "topics": _topics(m),
        "inferred_mappings": diag.get("inferred_mappings") or {},
        "streams": log.summary(),
        "diagnostics": {k: v for k, v in diag.items() if k != "messages"},
    }


def _print_text(d: dict) -> None:
    print(f"{d['path']}")
    print(f"  format      {d['format']}  (reader {d['reader']}: {d['detected_by']})")
    dur = f"duration {d['duration_s']:.1f} s"
    sp = d.get("sensor_span")
    if sp and (sp["start_s"] >= 0.05 or d["duration_s"] - sp["duration_s"] >= 0.05):
        # a non-sensor record (mode, parameters, RC) starts earlier or ends later than the sensors
        dur += f" (sensors {sp['duration_s']:.1f} s, t = {sp['start_s']:.1f}..{sp['end_s']:.1f} s)"
    print(f"  status      {d['status']}   {dur}   flight_id {d['flight_id']}")
    if d["ned_origin"]:
        o = d["ned_origin"]
        h, datum = (o.get("alt_wgs84_m"), "WGS-84") if o.get("alt_wgs84_m") is not None else (o.get("alt_msl_m"), "MSL")
        hs = "unknown height" if h is None else f"{h:.2f} m {datum}"
        print(f"  NED origin  {o['lat_deg']:.7f}, {o['lon_deg']:.7f}, {hs}")
    elif d.get("ned_origin_reason"):
        print(f"  NED origin  none: {d['ned_origin_reason']}")
    if d.get("topics"):
        print("  topics:")
        for topic, t in d["topics"].items():
            how = f"  (inferred: {t['inferred']})" if t.get("inferred") else ""
            print(f"    {topic:28s} -> {t['stream']}[{t['instance']}]  {t['type']}{how}")
    for topic, inf in (d.get("inferred_mappings") or {}).items():
        print(f"  inferred    {topic} ({inf['type']}): {inf['mapping']}")
    if d["diagnostics"].get("local_position_from"):
        print(f"  local_position from {d['diagnostics']['local_position_from']}")
    print("  streams:")
    for name, s in d["streams"].items():
        rate = "" if s["rate_hz"] != s["rate_hz"] else f"{s['rate_hz']:8.2f} Hz"
        print(f"    {name:15s} {s['rows']:9d} rows  {s['instances']} inst  {rate}")
    diag = d["diagnostics"]
    print(f"  diagnostics: bytes skipped {diag.get('bytes_skipped', 0)}, "
          f"records dropped {json.dumps(dict(grouped_drops(diag.get('records_dropped'))))}, "
          f"timestamp anomalies {json.dumps(diag.get('timestamp_anomalies', {}))}")
    for w in diag.get("warnings", [])[:20]:
        print(f"    warning: {w}")


def run(args) -> int:
    from ..config import ConfigError, load_config, section

    try:  # the readers see what the workflow's ingest rule gives them (ROS topic maps, ...)
        config = section(load_config(args.config), "ingest")
    except ConfigError as exc:
        print(f"uavpipe info: {exc}", file=sys.stderr)
        return 2
    failed = 0
    out = []
    for path in args.logs:
        try:
            size = path.stat().st_size if path.is_file() else 0
            with progress_bar(path.name, size) as cb:
                log = registry.read_log(path, fmt=args.fmt, progress=cb, config=config)
        except IngestError as exc:
            print(f"uavpipe info: {exc}", file=sys.stderr)
            failed += 1
            if args.json:  # one entry per LOG, a failed one with its reason: the array covers every input
                out.append({"path": str(path), "status": "failed", "error": exc.reason})
            continue
        d = describe(log)
        if args.json:
            out.append(d)
        else:
            _print_text(d)
    if args.json:
        json.dump(json_safe(out), sys.stdout, indent=1, default=str, allow_nan=False)
        print()
    return 1 if failed else 0


def json_safe(obj):
    """``obj`` with every non-finite float (a one-row stream's NaN rate) as ``None``: ``null`` in
    the JSON, which has no NaN or Infinity (RFC 8259)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj
