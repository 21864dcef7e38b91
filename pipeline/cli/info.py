"""``uavpipe info LOG...``: which reader took a file and why, duration, streams, diagnostics."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..io import registry
from ..io.base import IngestError
from ..io.manifest import reader_names
from .progress import progress_bar


def add_parser(sub) -> None:
    p = sub.add_parser("info", help="describe a log: format, reader, streams with rates, diagnostics")
    p.add_argument("logs", nargs="+", type=Path, metavar="LOG")
    names = reader_names()
    p.add_argument("--format", dest="fmt", default=None, choices=names, metavar="FORMAT",
                   help=f"force a reader instead of detecting: {', '.join(names)}")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--config", type=Path, default=None, metavar="FILE",
                   help="dataset config whose 'ingest' section the readers use (default datasets/config.yaml)")
    p.set_defaults(func=run)


def describe(log) -> dict:
    m = log.meta
    return {
        "path": m.get("source_path"),
        "flight_id": m.get("flight_id"),
        "format": m.get("source_format"),
        "reader": f"{m.get('reader')} v{m.get('reader_version')}",
        "detected_by": m.get("detected_by"),
        "status": m.get("status"),
        "duration_s": round(log.duration_s, 3),
        "t0_utc_ns": m.get("t0_utc_ns"),
        "ned_origin": m.get("ned_origin"),
        "streams": log.summary(),
        "diagnostics": {k: v for k, v in m.get("diagnostics", {}).items() if k != "messages"},
    }


def _print_text(d: dict) -> None:
    print(f"{d['path']}")
    print(f"  format      {d['format']}  (reader {d['reader']}: {d['detected_by']})")
    print(f"  status      {d['status']}   duration {d['duration_s']:.1f} s   flight_id {d['flight_id']}")
    if d["ned_origin"]:
        o = d["ned_origin"]
        h, datum = (o.get("alt_wgs84_m"), "WGS-84") if o.get("alt_wgs84_m") is not None else (o.get("alt_msl_m"), "MSL")
        hs = "unknown height" if h is None else f"{h:.2f} m {datum}"
        print(f"  NED origin  {o['lat_deg']:.7f}, {o['lon_deg']:.7f}, {hs}")
    print("  streams:")
    for name, s in d["streams"].items():
        rate = "" if s["rate_hz"] != s["rate_hz"] else f"{s['rate_hz']:8.2f} Hz"
        print(f"    {name:15s} {s['rows']:9d} rows  {s['instances']} inst  {rate}")
    diag = d["diagnostics"]
    print(f"  diagnostics: bytes skipped {diag.get('bytes_skipped', 0)}, "
          f"records dropped {json.dumps(diag.get('records_dropped', {}))}, "
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
            continue
        d = describe(log)
        if args.json:
            out.append(d)
        else:
            _print_text(d)
    if args.json:
        json.dump(out, sys.stdout, indent=1, default=str)
        print()
    return 1 if failed else 0
