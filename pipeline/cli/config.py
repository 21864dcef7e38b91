"""``uavpipe config [--config FILE] [--defaults] [--section NAME]``: the validated configuration.

Prints, as YAML, what every stage sees: the dataset config (default ``datasets/config.yaml`` of
the current folder, else the project's)
validated against ``rules/schemas/config.schema.yaml`` with every default filled, exactly as the
workflow resolves it; ``--defaults`` prints the schema defaults alone (a starting file).
``--section`` takes a top-level section or a dotted key path (``simulate.sensors.radar``,
``preprocess.rate_hz``). A bad key or value is one line naming the file and the key path (exit 2).
"""

from __future__ import annotations

import sys

from ..config import ConfigError, defaults, load_config
from .common import add_config_option


def add_parser(sub) -> None:
    p = sub.add_parser("config", help="print the validated configuration with every default filled")
    add_config_option(p)
    p.add_argument("--defaults", action="store_true", help="print the schema defaults only")
    p.add_argument("--section", default=None,
                   help="print one section or key only (e.g. preprocess, simulate.sensors.radar)")
    p.set_defaults(func=run)


def run(args) -> int:
    import yaml

    try:
        cfg = defaults() if args.defaults else load_config(args.config)
        out = at_path(cfg, args.section) if args.section else cfg
    except ConfigError as exc:
        print(f"uavpipe config: {exc}", file=sys.stderr)
        return 2
    # lists of numbers inline, but a mapping of plain values (one key, a flat section) in block
    # style: PyYAML's "auto" would print it as one {a: 1, b: 2} line
    flat = not any(isinstance(v, (dict, list)) for v in out.values())
    sys.stdout.write(yaml.safe_dump(out, sort_keys=False, default_flow_style=False if flat else None, width=100))
    return 0


def at_path(cfg: dict, path: str) -> dict:
    """The validated ``cfg`` at a dotted key path: a section as it is, a single value as
    ``{path: value}``; an unknown key is one :class:`ConfigError` naming the keys there."""
    node, seen = cfg, []
    for part in path.split("."):
        if not isinstance(node, dict) or part not in node:
            where = ".".join(seen) or "the top level"
            keys = ", ".join(node) if isinstance(node, dict) else f"none: {where} is a value"
            raise ConfigError(f"--section {path}: no key {part!r} in {where} (keys: {keys})")
        node = node[part]
        seen.append(part)
    return node if isinstance(node, dict) else {path: node}
