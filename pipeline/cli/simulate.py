"""``uavpipe simulate OUT_DIR``: the seed-000 simulated data sets, log files and summary table.

Reads the ``simulate`` section and ``seed`` of the dataset config (see
:mod:`pipeline.simulate.datasets` for what is written). ``--size thesis`` switches to the
thesis-sized sets; ``--seed`` overrides the config's master seed.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..config import ConfigError, load_config, section


def add_parser(sub) -> None:
    p = sub.add_parser("simulate", help="simulate the seed-000 maneuver data sets and log files")
    p.add_argument("out_dir", type=Path, metavar="OUT_DIR")
    p.add_argument("--config", type=Path, default=None, help="dataset config (default datasets/config.yaml)")
    p.add_argument("--seed", type=int, default=None, help="master seed (default: the config's seed)")
    p.add_argument("--size", default=None, help="datasets size row (small, thesis, or one defined in config)")
    p.add_argument("--no-logs", action="store_true", help="skip the log files")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..simulate.datasets import run_simulate

    try:
        cfg = load_config(args.config)
        sim = dict(section(cfg, "simulate"))
        ds = dict(sim.get("datasets") or {})
        if args.size:
            ds["size"] = args.size
        if args.no_logs:
            ds["log_formats"] = []
        sim["datasets"] = ds
        seed = args.seed if args.seed is not None else int(cfg.get("seed", 0))
        index = run_simulate(args.out_dir, sim, seed, progress=lambda m: print(f"uavpipe simulate: {m}",
                                                                               file=sys.stderr))
    except ConfigError as exc:
        print(f"uavpipe simulate: {exc}", file=sys.stderr)
        return 2
    print(f"uavpipe simulate: {len(index['sets'])} sets, {len(index['logs'])} log files -> {args.out_dir}",
          file=sys.stderr)
    return 0
