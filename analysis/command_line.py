"""The argument boilerplate every ``cli_*.py`` module of the three packages shares.

- :class:`Parser` / :func:`parse_args`: an ``ArgumentParser`` whose usage errors become exit code 2
  with a message instead of ``SystemExit`` from deep inside argparse.
- :func:`add_overwrite`, :func:`add_json_flag`, :func:`add_verbose`, :func:`set_verbosity`: the
  common options (``--overwrite``, ``--json``, ``-v``) with each command's own help text;
  :func:`add_threads`: ``--threads N`` of the commands that compute.
- :func:`check_out_dir`: an output path whose folder does not exist is bad input, found before
  any work is done.
- :func:`errors_to_exit` + :func:`cli_entry`: "these errors end the command with this exit code
  and the message ``PROG: [prefix]ERROR`` on stderr", written once; ``cli_entry`` also makes
  ``main`` safe against a closed stdout pipe (``... | head``).

This module is in ``analysis`` (the bottom layer) so that all three packages may import it.
"""
from __future__ import annotations

import argparse
import contextlib
import functools
import logging
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TypeVar

from .disk_space import disk_full_cause
from .errors import DiskFullError, OutputBusy, UsageError

__all__ = ["UsageError", "Parser", "parse_args", "with_examples", "add_overwrite", "add_estimator", "add_json_flag",
           "add_threads", "add_verbose", "set_verbosity", "check_out_dir", "CliExit", "exit_on", "errors_to_exit", "cli_entry"]

F = TypeVar("F", bound=Callable[..., int])


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` that raises :class:`UsageError` instead of exiting, so ``main`` reports."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(f"{self.prog}: {message}")


def parse_args(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> argparse.Namespace | int:
    """Parse ``argv`` (default ``sys.argv[1:]``); an ``int`` is the exit code to return at once
    (2 after printing a usage error on stderr, 0 after ``--help``)."""
    try:
        return parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    except UsageError as exc:
        print(f"{exc}\n(see --help)", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)


def with_examples(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The options and help every command shares: ``-v`` (more logging, repeatable) and ``-q``
    (no progress, errors only) unless the command has its own, and the command's worked examples
    (:mod:`analysis.command_examples`, by ``parser.prog``) at the end of its ``--help``, kept as
    written (line breaks and alignment)."""
    for container in [parser, *parser._action_groups]:  # a command's own -v/-q, defined later, replaces these
        container.conflict_handler = "resolve"
    have = {s for a in parser._actions for s in a.option_strings}
    if "-v" not in have:
        parser.add_argument("-v", "--verbose", action=_Verbosity, nargs=0, default=0,
                            help="log more: -v info, -vv debug")
    if "-q" not in have:
        parser.add_argument("-q", "--quiet", action=_Verbosity, nargs=0, default=False,
                            help="print no progress, only results and errors")
    set_verbosity(0)
    import re

    from .command_examples import examples_epilog

    def plain(s: str | None) -> str | None:  # docstring markup (``x``, :func:`x`) reads as plain text
        return None if s is None else re.sub(r"(:\w+:)?``?([^`]+)``?", r"\2", s)

    parser.description = plain(parser.description)
    for action in parser._actions:
        action.help = plain(action.help)
    text = examples_epilog(parser.prog)
    if text:
        parser.epilog = text if not parser.epilog else f"{parser.epilog}\n\n{text}"
        parser.formatter_class = argparse.RawDescriptionHelpFormatter
    return parser


def add_overwrite(parser: argparse.ArgumentParser, help: str | None = None) -> None:
    """``--overwrite``: replace an existing output file."""
    parser.add_argument("--overwrite", action="store_true", help=help)


def recording_in_out(prog: str, doc: str | None, out_help: str,
                     recording_help: str = "the recording to read (never modified)") -> argparse.ArgumentParser:
    """The parser of a command that reads one recording and writes another: ``prog``, the first
    paragraph of the face's docstring ``doc`` as its description, the options and examples every command
    shares (:func:`with_examples`), the ``recording`` to read (``recording_help``; never modified),
    ``--out FILE`` (required, ``out_help``) and ``--overwrite``. The command adds its own options."""
    p = argparse.ArgumentParser(prog=prog, description=(doc or "").split("\n\n")[0])
    with_examples(p)
    p.add_argument("recording", help=recording_help)
    p.add_argument("--out", required=True, help=out_help)
    add_overwrite(p, "replace an existing --out file")
    return p


def add_estimator(parser: argparse.ArgumentParser) -> None:
    """``--estimator H1|H2``: which FRF estimate of a recording to use (default: the recording's own
    preference, set by ``replay --estimator``, else H1)."""
    parser.add_argument("--estimator", choices=("H1", "H2"), default=None,
                        help="FRF estimate of a recording: H1 (noise on the response) or H2 (noise on the force); "
                             "default: the one the recording prefers (set by 'replay --estimator'), else H1")


def add_json_flag(parser: argparse.ArgumentParser, help: str = "print one JSON object instead of text") -> None:
    """``--json`` as a switch: print JSON on stdout instead of text."""
    parser.add_argument("--json", action="store_true", help=help)


def add_threads(parser: argparse.ArgumentParser) -> None:
    """``--threads N``: BLAS threads of the command's numerical kernels (default: chosen per problem
    from its size and the free cores, or the environment variable ``IMPACTLAB_THREADS``); set as soon
    as it is parsed, for the rest of the command (:func:`cli_entry` restores the previous value)."""
    parser.add_argument("--threads", type=_positive_int, metavar="N", action=_Threads, default=None,
                        help="BLAS threads of the computation (default: chosen from the problem size and the free "
                             "cores; also IMPACTLAB_THREADS=N)")


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be a positive whole number; got {text!r}")
    return n


class _Threads(argparse.Action):
    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        from .threads import set_threads

        setattr(namespace, self.dest, values)
        set_threads(int(values))  # type: ignore[call-overload]


def add_verbose(parser: argparse.ArgumentParser) -> None:
    """``-v/--verbose`` (repeatable): log more."""
    parser.add_argument("-v", "--verbose", action="count", default=0, help="log more (-v info, -vv debug)")


def set_verbosity(verbose: int, quiet: bool = False) -> None:
    """Logging from the ``-v`` count and ``-q``: warnings (default), info (-v), debug (-vv); the
    progress of long steps (:mod:`analysis.progress`) on stderr unless ``quiet``."""
    from .progress import PROGRESS_LOGGER

    level = (logging.WARNING, logging.INFO, logging.DEBUG)[min(max(verbose, 0), 2)]
    logging.basicConfig(level=logging.ERROR if quiet else level, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger().setLevel(logging.ERROR if quiet else level)
    plog = logging.getLogger(PROGRESS_LOGGER)
    plog.propagate = False
    plog.handlers = [h for h in plog.handlers if not getattr(h, "_impactlab", False)]
    if not quiet:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("... %(message)s"))
        handler._impactlab = True  # type: ignore[attr-defined]
        plog.addHandler(handler)
    plog.setLevel(logging.INFO if not quiet else logging.CRITICAL)


class _Verbosity(argparse.Action):
    """``-v`` / ``-q`` that set the logging levels as soon as they are parsed (every command alike)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        if self.dest == "verbose":
            namespace.verbose = int(getattr(namespace, "verbose", 0) or 0) + 1
        else:
            setattr(namespace, self.dest, True)
        set_verbosity(int(getattr(namespace, "verbose", 0) or 0), bool(getattr(namespace, "quiet", False)))


def check_out_dir(path: str | os.PathLike[str] | None, what: str = "", error: type[Exception] = UsageError,
                  message: str = "cannot write {label}: folder {folder} does not exist") -> None:
    """Raise ``error`` when the folder of the output ``path`` does not exist (None: nothing to check).
    ``what`` names the output in the message (``cannot write the JSON out.json: ...``); ``message``
    may use ``{label}`` and ``{folder}``."""
    if path is None:
        return
    folder = Path(path).resolve().parent
    if not folder.is_dir():
        label = f"the {what} {path}" if what else f"{path}"
        raise error(message.format(label=label, folder=folder))


class CliExit(Exception):
    """End the command with exit code ``code`` (the message is already on stderr)."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = int(code)


Errors = type[BaseException] | tuple[type[BaseException], ...]
Rule = tuple[Errors, int] | tuple[Errors, int, str]


@contextlib.contextmanager
def exit_on(prog: str, *rules: Rule) -> Iterator[None]:
    """Inside the block, an error matching a rule ``(errors, code[, prefix])`` (the first that
    matches, in order) prints ``PROG: PREFIXERROR`` on stderr and ends the command with ``code``
    (raises :class:`CliExit`, which :func:`cli_entry` turns into the return value). An output a live
    writer holds (:class:`~analysis.errors.OutputBusy`) always ends it with 1, before any rule."""
    try:
        yield
    except CliExit:
        raise
    except OutputBusy as exc:  # every command alike: a runtime failure, never written over
        print(f"{prog}: {exc}", file=sys.stderr)
        raise CliExit(1) from None
    except BaseException as exc:
        if disk_full_cause(exc) is not None:  # whatever the rules: a runtime failure, one line, exit 1
            print(disk_full_line(prog, exc), file=sys.stderr)
            raise CliExit(1) from None
        for rule in rules:
            if isinstance(exc, rule[0]):
                prefix = rule[2] if len(rule) > 2 else ""
                print(f"{prog}: {prefix}{exc}", file=sys.stderr)
                raise CliExit(rule[1]) from None
        raise


def disk_full_line(prog: str, exc: BaseException) -> str:
    """The one line for an output that a full disk (or the file size limit) stopped: a writer's own
    :class:`~analysis.errors.DiskFullError` message, else the file and what to do."""
    if isinstance(exc, DiskFullError):
        return f"{prog}: {exc}"
    cause = disk_full_cause(exc)
    assert cause is not None
    name = getattr(cause, "filename2", None) or getattr(cause, "filename", None)  # a copy's target is filename2
    where = f" {name}" if name else " an output"
    return (f"{prog}: cannot write{where}: {cause.strerror or cause} (the disk is full or the file size limit is "
            "reached); free space or write elsewhere, then run the command again")


def errors_to_exit(prog: str, errors: type[BaseException] | tuple[type[BaseException], ...], code: int = 2,
                   prefix: str = "") -> contextlib.AbstractContextManager[None]:
    """:func:`exit_on` with one rule: ``errors`` -> ``PROG: PREFIXERROR`` on stderr, exit ``code``."""
    return exit_on(prog, (errors, code, prefix))


def _last_resort(prog: str, exc: BaseException) -> int:
    """One line and the documented exit code for what no command rule caught: Ctrl-C 130; running
    out of memory, a file system error (disk full, permission) 1; input nested too deeply 2."""
    if isinstance(exc, KeyboardInterrupt):
        print(f"{prog}: interrupted (Ctrl-C)", file=sys.stderr)
        return 130
    if isinstance(exc, MemoryError):
        print(f"{prog}: out of memory ({exc or 'allocation failed'}); ask for less work (a smaller order, band or "
              "model) or free memory", file=sys.stderr)
        return 1
    if isinstance(exc, RecursionError):
        print(f"{prog}: an input is nested too deeply to be read ({exc}); check the files given", file=sys.stderr)
        return 2
    assert isinstance(exc, OSError)
    where = f": {exc.filename}" if getattr(exc, "filename", None) else ""
    print(f"{prog}: {exc.strerror or exc}{where}; check the disk space, permissions and paths", file=sys.stderr)
    return 1


def cli_entry(main: F) -> F:
    """Decorate a ``main(argv) -> int``: a :class:`CliExit` returns its code; a closed stdout pipe
    (``| head``) ends quietly with exit code 0 as the reader wanted no more; Ctrl-C, running out
    of memory and file system errors no rule caught end with one line (:func:`_last_resort`)."""

    @functools.wraps(main)
    def run(*args: object, **kwargs: object) -> int:
        from .threads import command_scope

        try:
            with command_scope():  # --threads holds for this command only
                return main(*args, **kwargs)
        except CliExit as done:
            return done.code
        except OutputBusy as exc:
            print(f"{_prog_of(main)}: {exc}", file=sys.stderr)
            return 1
        except (KeyboardInterrupt, MemoryError, RecursionError) as exc:
            return _last_resort(_prog_of(main), exc)
        except OSError as exc:
            if isinstance(exc, BrokenPipeError):
                return _quiet_broken_pipe()
            return _last_resort(_prog_of(main), exc)

    return run  # type: ignore[return-value]


def _prog_of(main: Callable[..., int]) -> str:
    """``python -m analysis fit`` style name of a command from its module (``analysis.cli_fit``)."""
    package, _, module = getattr(main, "__module__", "impactlab").partition(".")
    return f"{package} {module.removeprefix('cli_')}".strip()


def _quiet_broken_pipe() -> int:
    try:  # no flush of the rest at exit into the closed pipe
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    return 0
