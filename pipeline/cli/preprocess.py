"""``uavpipe preprocess INGEST_DIR... -o DIR``: ``state``/``segments``/``calibration`` per flight.

Each ``INGEST_DIR`` is one flight written by ``uavpipe ingest`` (``<stream>.parquet`` +
``meta.json``); outputs go to ``DIR/<flight_id>/{state,segments,calibration}.parquet`` plus
``preprocess.json`` (diagnostics).
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..config import ConfigError, default_config_path, load_config, section
from ..io.stage import caller_restates
from .common import Claims, add_config_option, describe, folder_problem, ingest_flight_id, vehicle_problem


def add_parser(sub) -> None:
    p = sub.add_parser("preprocess", help="resample, filter, calibrate and differentiate ingested flights")
    p.add_argument("ingest_dirs", nargs="+", type=Path, metavar="INGEST_DIR")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="DIR",
                   help="output root; each flight goes to DIR/<flight_id>/")
    add_config_option(p)
    p.add_argument("--vehicle", default=None,
                   help="vehicle key in preprocess.vehicles, or 'generic' (the default entry); "
                        "without it: preprocess.flights by flight id, else the default entry")
    p.set_defaults(func=run)


def vehicle_profile(diag: dict) -> str:
    """``vehicle profile <name>`` (the ``preprocess.vehicles`` entry used), or the built-in one."""
    used = diag.get("vehicle")
    return f"vehicle profile {used}" if used else "vehicle profile: built-in defaults (no entry)"


def run(args) -> int:
    from ..preprocess.run import run_preprocess
    from ..preprocess.state import check_preprocess_config, summary_line

    try:
        cfg = load_config(args.config)
        sec = section(cfg, "preprocess")
    except ConfigError as exc:
        print(f"uavpipe preprocess: {exc}", file=sys.stderr)
        return 2
    try:    # what the schema cannot check (mounts, stick ranges), named with the file
        check_preprocess_config(sec)
    except ConfigError as exc:
        print(f"uavpipe preprocess: {args.config or default_config_path()}: {exc}", file=sys.stderr)
        return 2
    # once, before any flight (an output folder that is a file: "Not a directory" per flight)
    bad = vehicle_problem(args.vehicle, cfg) or folder_problem("-o", args.out)
    if bad:
        print(f"uavpipe preprocess: {bad}", file=sys.stderr)
        return 2
    failed = []
    claims = Claims()
    for d in args.ingest_dirs:
        meta = d / "meta.json"
        try:
            fid = ingest_flight_id(d)
        except ValueError as exc:
            print(f"uavpipe preprocess: {exc}", file=sys.stderr)
            failed.append(d)
            continue
        out = args.out / fid
        clash = claims.clash(out)
        if clash:
            print(f"uavpipe preprocess: {d}: flight {fid} {clash}", file=sys.stderr)
            failed.append(d)
            continue
        outputs = {"state": out / "state.parquet", "segments": out / "segments.parquet",
                   "calibration": out / "calibration.parquet", "info": out / "preprocess.json"}
        try:
            with caller_restates():  # this command prints the flight's one line itself
                res = run_preprocess({"meta": meta}, outputs, sec, vehicle=args.vehicle)
        except Exception as exc:  # one bad flight never stops the others
            print(f"uavpipe preprocess: {d}: {describe(exc)}", file=sys.stderr)
            failed.append(d)
            continue
        if res.status == "failed":
            print(f"uavpipe preprocess: {d}: {res.diagnostics.get('error')}", file=sys.stderr)
            failed.append(d)
            continue
        claims.claim(out, d)
        print(f"{d} -> {out}: {summary_line(res.diagnostics)}, {vehicle_profile(res.diagnostics)}")
    if failed:
        print(f"uavpipe preprocess: {len(failed)} of {len(args.ingest_dirs)} flight(s) failed", file=sys.stderr)
        return 1
    return 0
