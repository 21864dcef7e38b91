"""``uavpipe`` command line: one module per subcommand, each exposing ``add_parser(subparsers)``.

Subcommands print a one-line reason and exit non-zero on failure; batch commands keep going
past a bad input and report it at the end.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .. import __version__

#: subcommand modules under ``pipeline.cli``, in help order
COMMANDS: tuple[str, ...] = ("info", "ingest", "simulate", "preprocess", "train", "classify")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="uavpipe", description="UAV flight-log analytics: ingest, preprocess, learn, estimate, report.")
    parser.add_argument("--version", action="version", version=f"uavpipe {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for mod in COMMANDS:
        importlib.import_module(f"{__name__}.{mod}").add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("uavpipe: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
