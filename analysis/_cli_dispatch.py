"""Shared subcommand dispatch for the three ``python -m`` entry points.

Each subcommand lives in its own module with a ``main(argv) -> int`` function; the
dispatcher imports only the one asked for.
"""
from __future__ import annotations

import contextlib
import importlib
import io
import os
import sys
from collections.abc import Iterator, Mapping, Sequence
from typing import Any, TextIO

from .command_line import Parser, UsageError, parse_args

__all__ = ["dispatch", "version", "pipe_safe_stdout", "Parser", "UsageError", "parse_args"]


def version() -> str:
    """The installed impactlab version (``--version`` of every command)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as _version

    try:
        return _version("impactlab")
    except PackageNotFoundError:  # run from a checkout that is not installed
        return "unknown (not installed: pip install -e .)"


def dispatch(prog: str, commands: Mapping[str, tuple[str, str]], argv: Sequence[str] | None = None) -> int:
    """Run ``prog SUBCOMMAND ...``; ``commands`` maps a name to (module, one-line help).

    ``--version`` prints the version. Output into a closed pipe (``... | head``) does not stop the
    command: what it writes to files is still written, and it exits as if the output was read."""
    args = list(sys.argv[1:] if argv is None else argv)
    with pipe_safe_stdout():
        return _dispatch(prog, commands, args)


def _dispatch(prog: str, commands: Mapping[str, tuple[str, str]], args: list[str]) -> int:
    if args and args[0] == "--version":
        print(f"{prog} (impactlab) {version()}")
        return 0
    if not args or args[0] in ("-h", "--help"):
        print(f"usage: {prog} SUBCOMMAND [options]\n\nsubcommands:")
        for name, (_, text) in commands.items():
            print(f"  {name:14s} {text}")
        print(f"\n'{prog} SUBCOMMAND --help' describes each (with examples); '{prog} --version' "
              "prints the version.")
        return 0 if args else 2
    name = args[0]
    if name not in commands:
        print(f"{prog}: unknown subcommand {name!r}; choose one of: {', '.join(commands)}", file=sys.stderr)
        return 2
    module = importlib.import_module(commands[name][0])
    return int(module.main(args[1:]) or 0)


class _PipeSafeStream:
    """A text stream that stops writing, without raising, once its reader has gone (EPIPE)."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream
        self.broken = False

    def write(self, text: str) -> int:
        if not self.broken:
            try:
                self._stream.write(text)
            except BrokenPipeError:
                self.broken = True
        return len(text)

    def flush(self) -> None:
        if not self.broken:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self.broken = True

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


@contextlib.contextmanager
def pipe_safe_stdout() -> Iterator[None]:
    """Within the block, printing into a closed pipe is silently dropped (the command goes on and
    writes its files); afterwards stdout points at /dev/null so that the interpreter's final flush
    does not complain either."""
    original = sys.stdout
    safe = _PipeSafeStream(original)
    sys.stdout = safe
    try:
        yield
    finally:
        safe.flush()
        sys.stdout = original
        if safe.broken:
            try:
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, original.fileno())
                os.close(devnull)
            except (OSError, ValueError, io.UnsupportedOperation):  # not a real file (captured in tests)
                pass

