"""Shared subcommand dispatch for the three ``python -m`` entry points.

Each subcommand lives in its own module with a ``main(argv) -> int`` function; the
dispatcher imports only the one asked for.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from typing import Mapping, Sequence

from .errors import UsageError


def dispatch(prog: str, commands: Mapping[str, tuple[str, str]], argv: Sequence[str] | None = None) -> int:
    """Run ``prog SUBCOMMAND ...``; ``commands`` maps a name to (module, one-line help)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print(f"usage: python -m {prog} SUBCOMMAND [options]\n\nsubcommands:")
        for name, (_, text) in commands.items():
            print(f"  {name:14s} {text}")
        print(f"\n'python -m {prog} SUBCOMMAND --help' describes each.")
        return 0 if args else 2
    name = args[0]
    if name not in commands:
        print(f"{prog}: unknown subcommand {name!r}; choose one of: {', '.join(commands)}", file=sys.stderr)
        return 2
    module = importlib.import_module(commands[name][0])
    return int(module.main(args[1:]) or 0)


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` that raises :class:`UsageError` instead of exiting, so ``main`` reports."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(f"{self.prog}: {message}")


def parse_args(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> "argparse.Namespace | int":
    """Parse ``argv`` (default ``sys.argv[1:]``); an ``int`` is the exit code to return at once
    (2 after printing a usage error on stderr, 0 after ``--help``)."""
    try:
        return parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    except UsageError as exc:
        print(f"{exc}\n(see --help)", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
