"""``uavpipe ingest LOG... -o DIR``: write ``DIR/<flight_id>/<stream>.parquet`` + ``meta.json``."""

from __future__ import annotations

import sys
from pathlib import Path

from ..io import registry
from ..io.base import IngestError
from ..io.parquet import write_flightlog
from .progress import progress_bar


def add_parser(sub) -> None:
    p = sub.add_parser("ingest", help="decode logs into the canonical Parquet store")
    p.add_argument("logs", nargs="+", type=Path, metavar="LOG")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="DIR",
                   help="output root; each log goes to DIR/<flight_id>/")
    p.add_argument("--format", dest="fmt", default=None, help="force a reader instead of detecting")
    p.set_defaults(func=run)


def run(args) -> int:
    failed = []
    for path in args.logs:
        try:
            size = path.stat().st_size if path.is_file() else 0
            with progress_bar(path.name, size) as cb:
                log = registry.read_log(path, fmt=args.fmt, progress=cb)
            dest = args.out / log.meta["flight_id"]
            write_flightlog(log, dest)
        except IngestError as exc:
            print(f"uavpipe ingest: {exc}", file=sys.stderr)
            failed.append(str(path))
            continue
        except OSError as exc:
            print(f"uavpipe ingest: {path}: cannot write output: {exc}", file=sys.stderr)
            failed.append(str(path))
            continue
        status = log.meta["status"]
        print(f"{path} -> {dest} ({log.meta['source_format']}, {log.duration_s:.1f} s, {status})")
    if failed:
        print(f"uavpipe ingest: {len(failed)} of {len(args.logs)} log(s) failed", file=sys.stderr)
        return 1
    return 0
