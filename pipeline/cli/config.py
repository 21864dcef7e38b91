"""``uavpipe config [--config FILE] [--defaults] [--section NAME]``: the validated configuration.

Prints, as YAML, what every stage sees: the dataset config (default ``datasets/config.yaml``)
validated against ``rules/schemas/config.schema.yaml`` with every default filled, exactly as the
workflow resolves it; ``--defaults`` prints the schema defaults alone (a starting file). A bad key
or value is one line naming the file and the key path (exit 2).
"""

from __future__ import annotations

import sys
from pathlib import Path

from ..config import ConfigError, defaults, load_config, section


def add_parser(sub) -> None:
    p = sub.add_parser("config", help="print the validated configuration with every default filled")
    p.add_argument("--config", type=Path, default=None, help="dataset config (default datasets/config.yaml)")
    p.add_argument("--defaults", action="store_true", help="print the schema defaults only")
    p.add_argument("--section", default=None, help="print one section only (e.g. preprocess)")
    p.set_defaults(func=run)


def run(args) -> int:
    import yaml

    try:
        cfg = defaults() if args.defaults else load_config(args.config)
        out = section(cfg, args.section) if args.section else cfg
    except ConfigError as exc:
        print(f"uavpipe config: {exc}", file=sys.stderr)
        return 2
    sys.stdout.write(yaml.safe_dump(out, sort_keys=False, default_flow_style=None, width=100))
    return 0
