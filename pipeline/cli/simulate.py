"""``uavpipe simulate OUT_DIR``: the seed-000 simulated data sets, log files and summary table.

The same entry points as the workflow's ``simulate_sets`` and ``simulate_logs`` rules, with the
same layout: ``OUT_DIR/sets/<name>.parquet``, ``OUT_DIR/summary.parquet``, ``OUT_DIR/index.json``
and ``OUT_DIR/logs/`` (log files, truth side-cars, ``flights.tsv``).

Reads the ``simulate`` section and ``seed`` of the dataset config (see
:mod:`pipeline.simulate.datasets` for what is written). ``--size thesis`` switches to the
thesis-sized sets; ``--seed`` overrides the config's master seed.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..config import ConfigError, load_config, section
from .common import add_config_option, folder_problem, nonnegative_int


def add_parser(sub) -> None:
    p = sub.add_parser("simulate", help="simulate the seed-000 maneuver data sets and log files")
    p.add_argument("out_dir", type=Path, metavar="OUT_DIR")
    add_config_option(p)
    p.add_argument("--seed", type=nonnegative_int, default=None, help="master seed (default: the config's seed)")
    p.add_argument("--size", default=None, help="datasets size row (small, thesis, or one defined in config)")
    p.add_argument("--no-logs", action="store_true", help="skip the log files")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..simulate.run import planned_logs, planned_sets, run_simulate_logs, run_simulate_sets

    bad = folder_problem("", args.out_dir)
    if bad:
        print(f"uavpipe simulate: {bad}", file=sys.stderr)
        return 2
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
        out = args.out_dir
        # the plan first, as the workflow plans at start-up: a sensor rate that does not divide
        # simulate.rate_hz stops here, not after every set has been simulated and written
        names = planned_sets(sim)
        logs = planned_logs(sim)
        sets = run_simulate_sets({}, {"sets": [out / "sets" / f"{n}.parquet" for n in names],
                                      "summary": out / "summary.parquet", "index": out / "index.json"},
                                 sim, seed=seed)
        if logs:
            run_simulate_logs({}, {"logs": [out / "logs" / r["log"] for r in logs],
                                   "sidecars": [out / "logs" / r["sidecar"] for r in logs],
                                   "manifest": out / "logs" / "flights.tsv"}, sim, seed=seed)
    except ConfigError as exc:
        print(f"uavpipe simulate: {exc}", file=sys.stderr)
        return 2
    print(f"uavpipe simulate: {len(sets.paths)} sets, {len(logs)} log files -> {args.out_dir}", file=sys.stderr)
    return 0
