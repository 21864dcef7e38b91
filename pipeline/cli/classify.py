"""``uavpipe classify MODEL_DIR STATE.parquet -o OUT.parquet``: per-sample online labels.

Output columns: ``run_id``, ``t_ns``, ``truth`` (when the input has ``label``), ``pred``
(maneuver or ``unknown``), ``best`` (``background`` when that rival wins under
``--decision confidence_bg``), ``V_best`` (confidence), ``oneclass_ok``, ``ll_<label>``
(and ``ll_background``),
``state`` (online Viterbi state), ``change``/``change_t_ns`` (reset mode) and the GMR
acceleration/jerk estimates (``state9`` models).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

from ..io.parquet import write_table
from ..models.base import ModelError


def add_parser(sub) -> None:
    p = sub.add_parser("classify", help="classify maneuvers online with trained HMMs")
    p.add_argument("model", type=Path, metavar="MODEL_DIR")
    p.add_argument("tables", nargs="+", type=Path, metavar="STATE.parquet")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="OUT.parquet",
                   help="output file (one input) or directory (several inputs)")
    p.add_argument("--mode", choices=("cumulative", "windowed", "reset"), default=None)
    p.add_argument("--decision", choices=("confidence", "oneclass", "both", "confidence_bg"), default=None)
    p.add_argument("--reset-at-segments", type=Path, default=None, metavar="SEGMENTS.parquet",
                   help="restart the forward passes at each segment's t_start_ns")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..models.classifier import ManeuverModelSet

    try:
        ms = ManeuverModelSet.load(args.model)
    except ModelError as exc:
        print(f"uavpipe classify: {exc}", file=sys.stderr)
        return 1
    resets = None
    if args.reset_at_segments is not None:
        resets = pd.read_parquet(args.reset_at_segments)["t_start_ns"].to_numpy()
    failed = 0
    for path in args.tables:
        out = args.out if len(args.tables) == 1 else args.out / f"{path.stem}.parquet"
        try:
            df = pd.read_parquet(path)
            res = ms.classify(df, mode=args.mode, decision=args.decision, reset_t_ns=resets)
            res["run_id"] = res["run_id"].astype(str)
            write_table(res, out, name="classification",
                        extra={"model": str(args.model), "labels": ms.labels_,
                               "mode": args.mode or ms.config.mode})
        except (ModelError, ValueError, OSError, KeyError) as exc:
            print(f"uavpipe classify: {path}: {exc}", file=sys.stderr)
            failed += 1
            continue
        n_unknown = int((res["pred"] == "unknown").sum())
        print(f"{path} -> {out} ({len(res)} samples, {n_unknown} unknown)")
    return 1 if failed else 0
