"""The `topdress` command. Each subsystem registers its own subcommands (see REGISTRARS)."""

from __future__ import annotations

import argparse
import importlib
import importlib.metadata
import logging
import sys
from collections.abc import Sequence

from topdress import __version__
from topdress.errors import TopdressError

# Each module defines `register(subparsers)` and sets `func` on its parsers;
# `func(args) -> int` is the exit code.
REGISTRARS = (
    "topdress.cli.config",
    "topdress.cli.run",
    "topdress.cli.gnss",
    "topdress.cli.experiment",
    "topdress.cli.log",
    "topdress.cli.sim",
    "topdress.cli.office",
)


def version() -> str:
    """The installed package's version (the source tree's when not installed)."""
    try:
        return importlib.metadata.version("topdress")
    except importlib.metadata.PackageNotFoundError:
        return __version__


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="topdress",
        description=(
            "Variable-rate topdressing with dual speed measurement: "
            "ECU core, cab terminal, simulator."
        ),
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in REGISTRARS:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """The exit code: 0 done, 2 an error the message explains, 130 interrupted (Ctrl-C while
    starting: the subcommands import numpy and more, which takes a moment)."""
    try:
        args = build_parser().parse_args(argv)
        logging.basicConfig(
            level=logging.DEBUG if args.verbose else logging.WARNING,
            format="%(levelname)s %(name)s: %(message)s",
        )
        code: int = args.func(args)
    except TopdressError as exc:
        print(f"topdress: error: {exc}", file=sys.stderr)
        return int(getattr(exc, "exit_code", 2))
    except KeyboardInterrupt:
        print("topdress: interrupted", file=sys.stderr)
        return 130
    return code


if __name__ == "__main__":
    sys.exit(main())
