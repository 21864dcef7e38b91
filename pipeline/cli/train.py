"""``uavpipe train STATE.parquet... -o MODEL_DIR``: one HMM per maneuver label (seed 000 §3.3).

Input tables carry the ``schema.STATE`` columns plus ``label`` (one maneuver per run) and,
for bulk sets, ``run_id``; several files are concatenated (``run_id`` made unique per file).
Writes ``MODEL_DIR/params.npz`` and ``MODEL_DIR/meta.json``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

from ..config import ConfigError, load_config, section
from ..models.base import ModelError, ModelsConfig


def add_parser(sub) -> None:
    p = sub.add_parser("train", help="train per-maneuver HMMs from labelled state tables")
    p.add_argument("tables", nargs="+", type=Path, metavar="STATE.parquet")
    p.add_argument("-o", "--out", type=Path, required=True, metavar="MODEL_DIR")
    p.add_argument("--config", type=Path, default=None, help="dataset config (default datasets/config.yaml)")
    p.add_argument("--labels", nargs="*", default=None, help="train only these maneuver labels")
    p.add_argument("--exclude", nargs="*", default=[], help="labels to leave out (e.g. take-off, landing)")
    p.add_argument("--seed", type=int, default=None, help="override the master seed")
    p.set_defaults(func=run)


def load_tables(paths: list[Path]) -> pd.DataFrame:
    frames = []
    for i, path in enumerate(paths):
        try:
            df = pd.read_parquet(path)
        except (OSError, ValueError) as exc:
            raise ModelError(f"{path}: cannot read Parquet: {exc}") from None
        if "run_id" not in df.columns:
            df = df.assign(run_id=0)
        df["run_id"] = [f"{i}:{r}" for r in df["run_id"]] if len(paths) > 1 else df["run_id"]
        frames.append(df)
    return pd.concat(frames, ignore_index=True)


def run(args) -> int:
    from ..models.classifier import ManeuverModelSet

    try:
        config = load_config(args.config)
        cfg = ModelsConfig.from_section(section(config, "hmm"),
                                        seed=config["seed"] if args.seed is None else args.seed)
        df = load_tables(args.tables)
        if "label" not in df.columns:
            raise ModelError("training tables need a 'label' column")
        keep = df["label"].notna() & ~df["label"].isin(args.exclude)
        if args.labels:
            keep &= df["label"].isin(args.labels)
        ms = ManeuverModelSet(config=cfg).fit(df[keep])
        ms.save(args.out)
    except (ConfigError, ModelError, ValueError) as exc:
        print(f"uavpipe train: {exc}", file=sys.stderr)
        return 1
    for lab in ms.labels_:
        t = ms.training_[lab]
        print(f"{lab}: {t['n_states']} states, {t['n_sequences']} sequences, {t['n_samples']} samples, "
              f"{t['n_iter']} iterations, converged={t['converged']}")
    print(f"models -> {args.out}")
    return 0
