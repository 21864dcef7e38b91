"""``uavpipe align --state STATE... --segments SEGMENTS... --set NAME -o DIR``: trajectory learning.

The same entry point as the workflow's ``align_set`` rule (:func:`pipeline.align.run.run_align`):
each ``STATE``/``SEGMENTS`` pair is one preprocessed flight (``uavpipe preprocess`` output
``DIR/<flight>/{state,segments}.parquet`` or the workflow's ``results/{state,segments}/<flight>.parquet``;
flight id: the tables' metadata, see :func:`pipeline.align.run.table_flight_id`); ``--set``
names an ``align.sets`` entry of the config (its flights
without a file here are skipped with a notice). Writes ``DIR/{learned,alignment,iterations,demos}.parquet``
and, with ``--page``, the set's HTML page.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..config import ConfigError, load_config, section
from .common import add_config_option, folder_problem, table_problem


def add_parser(sub) -> None:
    p = sub.add_parser("align", help="learn one intended trajectory per maneuver from repeated demos")
    p.add_argument("--state", nargs="+", type=Path, required=True, metavar="STATE",
                   help="preprocessed state tables (DIR/<flight>/state.parquet or results/state/<flight>.parquet)")
    p.add_argument("--segments", nargs="+", type=Path, required=True, metavar="SEGMENTS",
                   help="segments tables, one per STATE (same flight ids)")
    p.add_argument("--set", dest="set_name", required=True, metavar="NAME", help="align.sets entry")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="DIR",
                   help="output folder: DIR/{learned,alignment,iterations,demos}.parquet")
    p.add_argument("--page", type=Path, default=None, metavar="HTML", help="also write the set's report page")
    add_config_option(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..align.run import ALIGN_OUTPUTS, run_align, table_flight_id

    try:
        sec = section(load_config(args.config), "align")
    except ConfigError as exc:
        print(f"uavpipe align: {exc}", file=sys.stderr)
        return 2
    if args.set_name not in sec["sets"]:
        print(f"uavpipe align: --set {args.set_name}: not an align.sets entry "
              f"({', '.join(sec['sets']) or 'none'})", file=sys.stderr)
        return 2
    kinds = [*((p, ("state",), "a state table") for p in args.state),
             *((p, ("segments",), "a segments table") for p in args.segments)]
    for p, expected, what in kinds:
        bad = table_problem(p, expected, what)
        if bad:
            print(f"uavpipe align: {p}: {bad}", file=sys.stderr)
            return 2
    # the flights by their tables' flight ids, not the file stems (every `uavpipe preprocess`
    # output is called state.parquet); the two lists need not be in the same order
    flights = {opt: [table_flight_id(p) for p in paths] for opt, paths in (("--state", args.state),
                                                                          ("--segments", args.segments))}
    for opt, paths in (("--state", args.state), ("--segments", args.segments)):
        seen: dict[str, Path] = {}
        for f, p in zip(flights[opt], paths):
            if f in seen:
                print(f"uavpipe align: {opt}: {seen[f]} and {p} are both flight {f}", file=sys.stderr)
                return 2
            seen[f] = p
    if sorted(flights["--state"]) != sorted(flights["--segments"]):
        print(f"uavpipe align: --state and --segments name different flights ({', '.join(sorted(flights['--state']))} "
              f"vs {', '.join(sorted(flights['--segments']))})", file=sys.stderr)
        return 2
    # the outputs' places, before minutes of learning
    for opt, p in (("-o", args.out), ("--page", args.page.parent if args.page else None)):
        bad = folder_problem(opt, p) if p is not None else None
        if bad:
            print(f"uavpipe align: {bad}", file=sys.stderr)
            return 2
    if args.page is not None and args.page.is_dir():
        print(f"uavpipe align: --page {args.page}: is a folder (give the page's file name)", file=sys.stderr)
        return 2
    outputs = {k: args.out / f"{k}.parquet" for k in ALIGN_OUTPUTS}
    res = run_align({"states": [str(p) for p in args.state], "segments": [str(p) for p in args.segments]},
                    outputs, sec, set_name=args.set_name)
    if args.page is not None and res.status != "failed":
        from ..report.align import build_align_report
        from ..report.flight import write_plotly_js

        js = args.page.parent / "plotly.min.js"
        write_plotly_js(js)
        build_align_report({k: str(v) for k, v in outputs.items()}, args.page, set_name=args.set_name,
                           template=Path(__file__).resolve().parents[2] / "reports" / "templates" / "align.html.j2",
                           plotly_js=js.name, band_deg=tuple(sec["pitch_band_deg"]))
    m = res.diagnostics.get("maneuvers", {})
    n_ok = sum(1 for v in m.values() if v["status"] == "ok")
    print(f"set {args.set_name} -> {args.out}/{{{','.join(ALIGN_OUTPUTS)}}}.parquet: {n_ok}/{len(m)} maneuvers "
          f"learned ({res.status}{': ' + res.error if res.error else ''})")
    return 1 if res.status == "failed" else 0
