"""Shared subcommand dispatch for the three ``python -m`` entry points.

Each subcommand lives in its own module with a ``main(argv) -> int`` function; the
dispatcher imports only the one asked for.
"""
from __future__ import annotations

import importlib
import sys
from typing import Mapping, Sequence

from .cli_common import Parser, UsageError, parse_args

__all__ = ["dispatch", "Parser", "UsageError", "parse_args"]


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
