"""``uavpipe`` command line: one module per subcommand, each exposing ``add_parser(subparsers)``.

Subcommands print a one-line reason and exit non-zero on failure; batch commands keep going
past a bad input and report it at the end. What a command did not foresee still ends in one
line, ``uavpipe <command>: <Type>: <message>`` with exit 1 (:func:`main`);
``UAVPIPE_DEBUG=1`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from .. import __version__

#: subcommand modules under ``pipeline.cli``, in help order
COMMANDS: tuple[str, ...] = ("info", "ingest", "simulate", "preprocess", "train", "classify", "estimate", "align", "config")


def build_parser(commands: tuple[str, ...] = COMMANDS) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="uavpipe",
        description="UAV flight-log analytics, one stage per command; the Snakemake workflow "
                    "(`snakemake --cores 2`) runs them all over datasets/flights.tsv and writes the reports.")
    parser.add_argument("--version", action="version", version=f"uavpipe {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for mod in commands:
        importlib.import_module(f"{__name__}.{mod}").add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    # import only the chosen subcommand's module: `uavpipe ingest` must not pay for the
    # models/pandas imports of `train` and `classify`
    first = next((a for a in argv if not a.startswith("-")), None)
    args = build_parser((first,) if first in COMMANDS else COMMANDS).parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("uavpipe: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # the last resort: bad input a command did not foresee, one line
        if os.environ.get("UAVPIPE_DEBUG"):
            raise
        from .common import describe

        print(f"uavpipe {args.command}: {describe(exc)} (UAVPIPE_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
