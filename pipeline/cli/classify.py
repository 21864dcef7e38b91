"""``uavpipe classify MODEL_DIR STATE.parquet... -o OUT``: per-sample online maneuver labels.

The same entry point as the workflow's ``classify_flight`` rule
(:func:`pipeline.models.run.run_classify`). With ``--segments SEG...`` (one per table) samples
carry their segment's label in ``truth`` and, with ``--reset-at-segments``, the forward passes
restart at every segment start (the workflow's default for its model sets); without it a table
that carries ``run_id``/``label`` (a simulated set) is classified run by run.

``-o OUT`` is the output file of one table, or the folder ``OUT/<name>.parquet`` of several
(``<name>`` tells the inputs apart, see :func:`pipeline.io.stage.source_names`); one table
with ``OUT`` an existing folder goes into it the same way.

Output columns: ``run_id``, ``t_ns``, ``truth`` (when the input has labels), ``pred`` (maneuver
or ``unknown``), ``best`` (``background`` when that rival wins under ``--decision
confidence_bg``), ``V_best`` (confidence), ``oneclass_ok``, ``ll_<label>`` (and
``ll_background``), ``state`` (online Viterbi state), ``change``/``change_t_ns`` (reset mode)
and the GMR acceleration/jerk estimates (``state9`` models).
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..io.stage import caller_restates
from .common import Claims, describe, folder_problem, pairing_problem, table_problem


def add_parser(sub) -> None:
    p = sub.add_parser("classify", help="classify maneuvers online with trained HMMs")
    p.add_argument("model", type=Path, metavar="MODEL_DIR")
    p.add_argument("tables", nargs="+", type=Path, metavar="STATE.parquet")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="OUT",
                   help="output file (one input) or directory (several inputs, or an existing "
                        "folder: OUT/<name>.parquet)")
    p.add_argument("--segments", nargs="+", type=Path, default=None, metavar="SEGMENTS",
                   help="segments tables (one per STATE table): labels in 'truth'")
    p.add_argument("--reset-at-segments", action="store_true",
                   help="restart the forward passes at each segment's t_start_ns (needs --segments)")
    p.add_argument("--mode", choices=("cumulative", "windowed", "reset"), default=None,
                   help="classification mode (default: the model set's own, its hmm.mode when trained)")
    p.add_argument("--decision", choices=("confidence", "oneclass", "both", "confidence_bg"), default=None,
                   help="decision rule (default: the model set's own, its hmm.decision when trained)")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..io.stage import source_names
    from ..models.base import ModelError
    from ..models.classifier import ManeuverModelSet
    from ..models.run import run_classify

    if not (args.model / "meta.json").is_file():
        print(f"uavpipe classify: {args.model}: not a model directory (no meta.json)", file=sys.stderr)
        return 2   # refused before any work, as estimate --model
    if args.segments is not None and len(args.segments) != len(args.tables):
        print(f"uavpipe classify: --segments: {len(args.segments)} given for {len(args.tables)} tables",
              file=sys.stderr)
        return 2
    if args.reset_at_segments and args.segments is None:
        print("uavpipe classify: --reset-at-segments needs --segments (the segment starts to reset at)",
              file=sys.stderr)
        return 2
    try:  # once, before any table: a damaged model is the model's fault, not the first table's
        ManeuverModelSet.load(args.model)
    except ModelError as exc:
        print(f"uavpipe classify: {exc}", file=sys.stderr)
        return 2
    # several tables (or one, into an existing folder): DIR/<name>.parquet, the name telling the
    # inputs apart (a/state, b/state); said once, not as a "File exists" per table
    into_folder = len(args.tables) > 1 or args.out.is_dir()
    bad = folder_problem("-o", args.out) if into_folder else None
    # tables and segments pair by position: another flight's labels would become 'truth'
    bad = bad or pairing_problem([("", args.tables), ("--segments", args.segments)])
    if bad:
        print(f"uavpipe classify: {bad}", file=sys.stderr)
        return 2
    failed = 0
    claims = Claims()
    names = [n.replace("/", "-") for n in source_names(args.tables)]
    for k, path in enumerate(args.tables):
        out = args.out / f"{names[k]}.parquet" if into_folder else args.out
        seg = args.segments[k] if args.segments else None
        bad = table_problem(path, ("state", "simulate_set"), "a state table or simulated set")
        bad_seg = table_problem(seg, ("segments",), "a segments table") if seg is not None else None
        bad = bad or (f"--segments {seg}: {bad_seg}" if bad_seg else None)
        clash = claims.clash(out)
        if bad or clash:
            print(f"uavpipe classify: {path}: {bad or clash}", file=sys.stderr)
            failed += 1
            continue
        inputs = {"params": args.model / "params.npz", "meta": args.model / "meta.json", "state": path,
                  "segments": seg}
        try:
            with caller_restates():  # this command prints the table's one line itself
                res = run_classify(inputs, {"classification": out}, {"reset_at_segments": args.reset_at_segments},
                                   model_set=args.model.name, mode=args.mode, decision=args.decision)
        except Exception as exc:  # one bad table never stops the others
            print(f"uavpipe classify: {path}: {describe(exc)}", file=sys.stderr)
            failed += 1
            continue
        if res.status != "ok":
            print(f"uavpipe classify: {path}: {res.error}", file=sys.stderr)
            failed += 1
            continue
        claims.claim(out, path)
        print(f"{path} -> {out} ({res.diagnostics['n_samples']} samples, {res.diagnostics['n_unknown']} unknown)")
    return 1 if failed else 0
