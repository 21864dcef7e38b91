"""``uavpipe estimate INGEST_DIR... --state STATE... -o DIR``: CA EKF, RTS smoother and EKF+HMM.

The same entry point as the workflow's ``estimate_flight`` rule
(:func:`pipeline.estimate.run.run_estimate`): each ``INGEST_DIR`` is one flight written by
``uavpipe ingest`` (its ``radar``/``truth``/``attitude`` streams and ``meta.json``), each
``STATE`` its preprocessed state (same order). Writes ``DIR/{ekf,ekf_rts,ekf_hmm}/<flight>.parquet``.

``--vehicle V`` picks the ``estimate.synthetic_radar`` entry (radar synthesised from the state,
noise from the config's master seed and the flight id). The EKF+HMM needs ``--model MODEL_DIR``
(a trained model set with GMR) and its Q₂: ``--q2 FILE`` (the workflow's
``results/estimate/q2/<model_set>.json``) or ``--train-sets SET...`` (computed into
``DIR/q2/<model_set>.json`` first); without a model its table is a placeholder with the reason.
``--model`` and its Q₂ go together: one without the other is a usage error, as are a ``--q2``
file that is no usable Q₂ and a model folder that does not load (each said once, before any
flight). Inputs paired by position must hold the same flight when they say which one.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..config import ConfigError, load_config, section
from ..io.stage import caller_restates
from .common import (Claims, add_config_option, describe, folder_problem, ingest_flight_id, model_problem,
                     pairing_problem, q2_problem, table_problem, vehicle_problem)


def add_parser(sub) -> None:
    p = sub.add_parser("estimate", help="EKF, RTS smoother and EKF+HMM over flights' radar")
    p.add_argument("ingest_dirs", nargs="+", type=Path, metavar="INGEST_DIR")
    p.add_argument("--state", nargs="+", type=Path, required=True, metavar="STATE",
                   help="preprocessed state tables, one per INGEST_DIR (same order)")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="DIR",
                   help="output root: DIR/<estimator>/<flight_id>.parquet")
    p.add_argument("--segments", nargs="+", type=Path, default=None, metavar="SEGMENTS",
                   help="segments tables (one per flight): classifier resets with estimate.ekf_hmm.reset_at_segments")
    p.add_argument("--model", type=Path, default=None, metavar="MODEL_DIR",
                   help="model set of the EKF+HMM (with --q2 or --train-sets)")
    p.add_argument("--q2", type=Path, default=None, metavar="Q2.json",
                   help="the model set's Q2 (estimate_q2 output; needs --model)")
    p.add_argument("--train-sets", nargs="+", type=Path, default=None, metavar="SET",
                   help="the model set's simulated training sets: compute Q2 from them (needs --model)")
    p.add_argument("--vehicle", default=None, help="manifest vehicle (its estimate.synthetic_radar entry, if any)")
    add_config_option(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..estimate.run import ESTIMATORS, job_config, run_estimate, run_q2

    try:
        cfg = load_config(args.config)
        sec = section(cfg, "estimate")
    except ConfigError as exc:
        print(f"uavpipe estimate: {exc}", file=sys.stderr)
        return 2
    for opt, vals in (("--state", args.state), ("--segments", args.segments)):
        if vals is not None and len(vals) != len(args.ingest_dirs):
            print(f"uavpipe estimate: {opt}: {len(vals)} given for {len(args.ingest_dirs)} flights", file=sys.stderr)
            return 2
    # the EKF+HMM's inputs go together: a lone --q2 or --model was silently a placeholder
    usage = None
    if args.model is None and (args.q2 is not None or args.train_sets):
        usage = f"{'--q2' if args.q2 is not None else '--train-sets'} needs --model (the model set whose Q2 it is)"
    elif args.model is not None and args.q2 is None and not args.train_sets:
        usage = "--model needs --q2 Q2.json or --train-sets SET... (the model set's Q2)"
    elif args.q2 is not None and args.train_sets:
        usage = "--q2 and --train-sets: give one (a Q2 file, or the sets to compute it from)"
    if usage:
        print(f"uavpipe estimate: {usage}", file=sys.stderr)
        return 2
    # every side input the kind it must be, before any flight runs (a missing --q2 was a placeholder
    # that never named the file; a segments table given as --state a KeyError)
    checks = [("", folder_problem("-o", args.out)),
              *((f"--state {p}", table_problem(p, ("state",), "a state table")) for p in args.state),
              *((f"--segments {p}", table_problem(p, ("segments",), "a segments table")) for p in args.segments or ()),
              *((f"--train-sets {p}", table_problem(p, ("simulate_set",), "a simulated set"))
                for p in args.train_sets or ()),
              ("--vehicle", vehicle_problem(args.vehicle, cfg))]
    if args.model is not None:  # loaded once here, not once per flight
        checks.append((f"--model {args.model}", model_problem(args.model)))
    if args.q2 is not None:
        checks.append((f"--q2 {args.q2}", q2_problem(args.q2, _model_set_name(args.model))))
    # inputs pair by position: a flight given another flight's state is refused, not estimated
    checks.append(("", pairing_problem([("", args.ingest_dirs), ("--state", args.state),
                                        ("--segments", args.segments)])))
    for opt, bad in checks:
        if bad:
            print(f"uavpipe estimate: {f'{opt}: ' if opt else ''}{bad}", file=sys.stderr)
            return 2
    q2 = args.q2
    if args.model is not None and q2 is None and args.train_sets:
        q2 = args.out / "q2" / f"{_model_set_name(args.model)}.json"
        with caller_restates():  # its line is said below, once
            res = run_q2({"params": args.model / "params.npz", "sets": args.train_sets}, {"q2": q2},
                         sec["ekf_hmm"], model_set=_model_set_name(args.model))
        print(f"uavpipe estimate: Q2 of {_model_set_name(args.model)}: "
              + (res.error if res.status != "ok" else f"{res.diagnostics['n_runs']} training runs -> {q2}"),
              file=sys.stderr)
    config = job_config(sec, args.vehicle)
    if args.model is not None:
        config["ekf_hmm"]["model"] = _model_set_name(args.model)
    failed = 0
    claims = Claims()
    for k, d in enumerate(args.ingest_dirs):
        meta = d / "meta.json"
        try:
            fid = ingest_flight_id(d)
        except ValueError as exc:
            print(f"uavpipe estimate: {exc}", file=sys.stderr)
            failed += 1
            continue
        clash = claims.clash(args.out / "ekf" / f"{fid}.parquet")
        if clash:
            print(f"uavpipe estimate: {d}: flight {fid} {clash}", file=sys.stderr)
            failed += 1
            continue
        inputs = {"meta": meta, "state": args.state[k], "segments": args.segments[k] if args.segments else None,
                  "model_params": args.model / "params.npz" if args.model else None, "q2": q2}
        outputs = {e: args.out / e / f"{fid}.parquet" for e in ESTIMATORS}
        try:
            with caller_restates():  # this command prints the flight's one line itself
                res = run_estimate(inputs, outputs, config, flight_id=fid, vehicle=args.vehicle, seed=int(cfg["seed"]))
        except Exception as exc:  # one bad flight never stops the others
            print(f"uavpipe estimate: {d}: {describe(exc)}", file=sys.stderr)
            failed += 1
            continue
        if res.status == "failed":  # run_estimate has said why, in one line naming the flight
            failed += 1
            continue
        claims.claim(args.out / "ekf" / f"{fid}.parquet", d)
        dg = res.diagnostics
        print(f"{d} -> {args.out}/{{{','.join(ESTIMATORS)}}}/{fid}.parquet: {dg['n_steps']} steps "
              f"({dg['n_predict_only']} predict-only), radar {dg['radar']}, reference {dg['reference']}"
              + (f"; ekf_hmm placeholder: {res.error}" if res.status == "partial" else ""))
    return 1 if failed else 0


def _model_set_name(model: Path | None) -> str | None:
    """The name a model folder was trained under (its ``meta.json`` ``name``; the folder name
    when it has none), which its Q2 file records."""
    if model is None:
        return None
    try:
        name = json.loads((model / "meta.json").read_text(encoding="utf-8")).get("name")
    except (OSError, ValueError, AttributeError):
        name = None
    return str(name) if name else model.name
