"""``uavpipe`` command line: one module per subcommand, each exposing ``add_parser(subparsers)``.

Subcommands print a one-line reason and exit non-zero on failure; batch commands keep going
past a bad input and report it at the end. What a command did not foresee still ends in one
line, ``uavpipe <command>: <Type>: <message>`` with exit 1 (:func:`main`);
``UAVPIPE_DEBUG=1`` shows the traceback instead. Exit status: 0 done, 1 failed work (an input
that failed, the rest done), 2 usage (options, config, an input refused before any work), 130
interrupted, 141 stdout closed by its reader (``| head``), said nowhere.
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
        rc = int(args.func(args) or 0)
        sys.stdout.flush()  # a reader gone away shows here, not as "Exception ignored" at exit
        return rc
    except KeyboardInterrupt:
        print("uavpipe: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # stdout closed early (`uavpipe info --json ... | head`): quietly
        return closed_stdout()
    except Exception as exc:  # the last resort: bad input a command did not foresee, one line
        if os.environ.get("UAVPIPE_DEBUG"):
            raise
        from .common import describe

        print(f"uavpipe {args.command}: {describe(exc)} (UAVPIPE_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 1


def closed_stdout() -> int:
    """Exit status 141 (128 + SIGPIPE, as a shell reports a writer killed by a closed pipe, and as
    130 is an interrupt) after pointing stdout at the null device, so that the interpreter's last
    flush of what is still buffered raises nothing either."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # not a file descriptor (an in-process capture)
        pass
    return 141


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
