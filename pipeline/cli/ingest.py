"""``uavpipe ingest LOG... -o DIR``: write ``DIR/<flight_id>/<stream>.parquet`` + ``meta.json``.

Each log goes through :func:`pipeline.io.ingest.run_ingest`, the function the workflow's
ingest rule calls, so the CLI writes the same files: a log that cannot be decoded gets the
failure placeholders (empty streams, ``meta.json`` with ``status: failed`` and the reason) and
one line on stderr, and the command goes on with the next log (exit 1 if any failed).
``--config FILE`` passes the file's ``ingest`` section, as the workflow does with its config;
without it that of the default dataset config (``datasets/config.yaml``), as the workflow.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..io.manifest import reader_names
from ..io.registry import flight_id_for
from .common import Claims, add_config_option, folder_problem
from .progress import progress_bar


def add_parser(sub) -> None:
    p = sub.add_parser("ingest", help="decode logs into the canonical Parquet store")
    p.add_argument("logs", nargs="+", type=Path, metavar="LOG")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="DIR",
                   help="output root; each log goes to DIR/<flight_id>/")
    names = reader_names()
    p.add_argument("--format", dest="fmt", default=None, choices=names, metavar="FORMAT",
                   help=f"force a reader instead of detecting: {', '.join(names)}")
    add_config_option(p, "dataset config whose 'ingest' section is passed to the readers, as the workflow does")
    p.add_argument("--labels", type=Path, default=None, metavar="FILE",
                   help="labels/truth side-car to attach (one LOG only; default: <log>.truth.parquet "
                        "beside the log when present)")
    p.set_defaults(func=run)


def job_paths(log: Path, labels: Path | None, out_root: Path) -> tuple[dict, dict, str]:
    """``(inputs, outputs, flight_id)`` for one log, shaped like the workflow rule's."""
    from ..io.ingest import outputs_for

    fid = flight_id_for(log)
    inputs = {"log": str(log), "labels": [str(labels)] if labels else []}
    return inputs, outputs_for(out_root / fid), fid


def run(args) -> int:
    from ..io.ingest import run_ingest

    from ..config import ConfigError, load_config, section

    try:  # the same validated section the workflow's ingest rule passes
        config = section(load_config(args.config), "ingest")
    except ConfigError as exc:
        print(f"uavpipe ingest: {exc}", file=sys.stderr)
        return 2
    if args.labels is not None and len(args.logs) > 1:
        print("uavpipe ingest: --labels takes one LOG", file=sys.stderr)
        return 2
    bad = folder_problem("-o", args.out)
    if bad:  # once, not a "Not a directory" per LOG
        print(f"uavpipe ingest: {bad}", file=sys.stderr)
        return 2
    failed = []
    claims = Claims()
    for path in args.logs:
        inputs, outputs, fid = job_paths(path, args.labels, args.out)
        clash = claims.clash(args.out / fid)
        if clash:  # two logs with one flight id (same name, other extension or folder)
            print(f"uavpipe ingest: {path}: flight id {fid} {clash}", file=sys.stderr)
            failed.append(str(path))
            continue
        try:
            size = path.stat().st_size if path.is_file() else 0
        except OSError:
            size = 0
        try:
            with progress_bar(path.name, size) as cb:
                res = run_ingest(inputs, outputs, config, flight_id=fid, fmt=args.fmt, progress=cb)
        except OSError as exc:
            print(f"uavpipe ingest: {path}: cannot write output: {exc}", file=sys.stderr)
            failed.append(str(path))
            continue
        # the reader's warnings, as `uavpipe info` prints them (the meta.json diagnostics)
        for w in (res.diagnostics or {}).get("warnings", [])[:20]:
            print(f"uavpipe ingest: {path}: warning: {w}", file=sys.stderr)
        if res.status == "failed":
            failed.append(str(path))
        else:
            claims.claim(args.out / fid, path)
    if failed:
        print(f"uavpipe ingest: {len(failed)} of {len(args.logs)} log(s) failed", file=sys.stderr)
        return 1
    return 0
