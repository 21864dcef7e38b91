"""``uavpipe train TABLE... -o MODEL_DIR``: one HMM per maneuver label (seed 000 §3.3).

The same entry point as the workflow's ``train_model`` rule (:func:`pipeline.models.run.run_train`):

* without ``--segments`` the tables are *sets*: ``schema.STATE`` columns plus ``label`` (one
  maneuver per run) and ``run_id`` (the simulated bulk sets; run ids made unique per file);
* with ``--segments SEG...`` (one per table, same order) they are flights' ``state`` tables and
  every labelled segment is one training run.

Hyperparameters come from the config's ``hmm`` section, or with ``--model-set NAME`` from that
entry of ``model_sets`` (its ``hmm`` overrides, ``labels`` and ``exclude``) exactly as the
workflow trains it. Writes ``MODEL_DIR/params.npz`` and ``MODEL_DIR/meta.json``.

A config error or an input refused before training (a count mismatch, a table of the wrong
kind, a state and segments pair of two flights, ``-o`` a file) exits 2, as in every command;
a failed training exits 1.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..config import ConfigError, load_config
from ..io.stage import caller_restates
from .common import add_config_option, folder_problem, nonnegative_int, pairing_problem, table_problem


def add_parser(sub) -> None:
    p = sub.add_parser("train", help="train per-maneuver HMMs from labelled state tables")
    p.add_argument("tables", nargs="+", type=Path, metavar="TABLE")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="MODEL_DIR")
    p.add_argument("--segments", nargs="+", type=Path, default=None, metavar="SEGMENTS",
                   help="segments tables of the flights (one per TABLE): train on flights")
    add_config_option(p)
    p.add_argument("--model-set", default=None, help="use this model_sets entry of the config")
    p.add_argument("--labels", nargs="*", default=None, help="train only these maneuver labels")
    p.add_argument("--exclude", nargs="*", default=None, help="labels to leave out (e.g. take-off, landing)")
    p.add_argument("--seed", type=nonnegative_int, default=None, help="override the config's master seed")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..models.base import ModelError
    from ..models.run import model_set_config, run_train

    try:  # usage: exit 2, as the other commands' config and input errors
        cfg = load_config(args.config)
        if args.model_set:
            spec = model_set_config(cfg, args.model_set)
            name = args.model_set
        else:
            spec = {"data": "flights" if args.segments else "simulated", "hmm": dict(cfg.get("hmm") or {})}
            name = args.out.name
        if args.labels is not None:
            spec["labels"] = list(args.labels)
        if args.exclude is not None:
            spec["exclude"] = list(args.exclude)
        if args.segments is not None and len(args.segments) != len(args.tables):
            raise ConfigError(f"--segments: {len(args.segments)} given for {len(args.tables)} tables")
        bad = folder_problem("-o", args.out)
        if bad:
            raise ConfigError(bad)
        # every input the kind it must be, before any training (a swapped pair is named)
        kinds = ([(p, ("state",), "a state table") for p in args.tables]
                 + [(p, ("segments",), "a segments table") for p in args.segments] if args.segments
                 else [(p, ("state", "simulate_set"), "a simulated set or labelled state table") for p in args.tables])
        for p, expected, what in kinds:
            bad = table_problem(p, expected, what)
            if bad:
                raise ConfigError(f"{p}: {bad}")
        bad = pairing_problem([("", args.tables), ("--segments", args.segments)]) if args.segments else None
        if bad:
            raise ConfigError(bad)
    except ConfigError as exc:
        print(f"uavpipe train: {exc}", file=sys.stderr)
        return 2
    try:
        inputs = ({"states": args.tables, "segments": args.segments} if args.segments
                  else {"sets": args.tables})
        seed = args.seed if args.seed is not None else int(cfg.get("seed", 0))
        with caller_restates():  # this command prints one line per trained model itself
            res = run_train(inputs, {"params": args.out / "params.npz", "meta": args.out / "meta.json"}, spec,
                            model_set=name, seed=seed)
    except (ConfigError, ModelError, ValueError, OSError) as exc:
        print(f"uavpipe train: {exc}", file=sys.stderr)
        return 1
    if res.status != "ok":
        # run_train has already said why (``uavpipe models: …``); name where its placeholder went
        print(f"uavpipe train: no models trained; placeholder {args.out / 'meta.json'} holds the reason",
              file=sys.stderr)
        return 1
    for lab, t in res.diagnostics["training"].items():
        print(f"{lab}: {t['n_states']} states, {t['n_sequences']} sequences, {t['n_samples']} samples, "
              f"{t['n_iter']} iterations, converged={t['converged']}")
    print(f"models -> {args.out}")
    return 0
