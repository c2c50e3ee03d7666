"""Each benchmark's results file, written by the benchmark itself.

A script that keeps a results file beside it names it in a module constant ``RESULTS`` (``Path(__file__)
.with_name(...)``) and, run with ``--write``, replaces it with this run's figures: the command line and
everything the run printed, through a temporary file beside the target and a rename
(:func:`analysis.atomic.write_text_atomic`), so an interrupted run leaves the previous results whole.
The file holds one run, the latest: the benchmark's history is in version control, not in the file.
Results of a hold-out case list ``CASES.json`` go to ``CASES`` + :data:`RESULTS_SUFFIX` beside it.

Use (the script puts the repository's root on ``sys.path`` first)::

    from benchmarks.results import add_write_option, recorded
    ...
    add_write_option(parser, RESULTS)
    with recorded(RESULTS, args.write):
        ...  # the run: what it prints goes to the terminal and, with --write, to RESULTS
"""
from __future__ import annotations

import argparse
import contextlib
import io
import shlex
import sys
from collections.abc import Iterator
from pathlib import Path

from analysis.atomic import write_text_atomic

__all__ = ["RESULTS_SUFFIX", "add_write_option", "recorded", "results_of_cases", "results_text"]

ROOT = Path(__file__).resolve().parents[1]
#: a hold-out case list CASES.json has its results in CASES.results.json beside it
RESULTS_SUFFIX = ".results.json"


def results_of_cases(cases: str | Path, label: str | None = None) -> Path:
    """The results file of a hold-out case list ``CASES.json``: ``CASES.results.json`` beside it, or
    ``CASES.LABEL.results.json`` for a run of part of the list (``pairs``, ``nulls``) or a later run (``later``):
    the first run as it came keeps its own file."""
    p = Path(cases)
    return p.with_name(p.name.removesuffix(".json") + (f".{label}" if label else "") + RESULTS_SUFFIX)


def add_write_option(parser: argparse.ArgumentParser, results: Path) -> None:
    """``--write``: replace the results file ``results`` with this run's figures."""
    parser.add_argument("--write", action="store_true",
                        help=f"replace {results.name} beside the script with this run's command line and output")


def results_text(results: Path, argv: list[str], output: str) -> str:
    """The results file's text: a title naming the script, the command line and the run's output."""
    script = Path(sys.argv[0]).resolve()
    shown = script.relative_to(ROOT) if script.is_relative_to(ROOT) else Path(script.name)
    command = " ".join(["python", *(shlex.quote(a) for a in [str(shown), *argv])])
    return (f"# Results of `{shown}`\n\nThe latest run, written by the benchmark itself (`--write`); earlier runs "
            f"are in version control.\n\n    {command}\n\n```\n{output.rstrip()}\n```\n")


class _Tee(io.TextIOBase):
    """Writes to the terminal and keeps a copy."""

    def __init__(self, terminal: io.TextIOBase) -> None:
        self.terminal = terminal
        self.copy = io.StringIO()

    def write(self, s: str) -> int:
        self.copy.write(s)
        return self.terminal.write(s)

    def flush(self) -> None:
        self.terminal.flush()


@contextlib.contextmanager
def recorded(results: Path, write: bool, argv: list[str] | None = None) -> Iterator[None]:
    """Run the block; with ``write``, what it printed on stdout then replaces ``results`` (atomically, and
    only when the block finished: a failed run leaves the previous results)."""
    if not write:
        yield
        return
    tee = _Tee(sys.stdout)  # type: ignore[arg-type]
    with contextlib.redirect_stdout(tee):  # type: ignore[type-var]
        yield
    write_text_atomic(results, results_text(results, sys.argv[1:] if argv is None else argv, tee.copy.getvalue()))
    print(f"results written to {results}", file=sys.stderr)
