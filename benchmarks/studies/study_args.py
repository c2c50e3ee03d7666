"""The command lines the studies share, so that each is written once.

- :func:`study_parser`, :func:`study_commands`: a study's parser (described by the first line of its
  docstring), with sub-commands.
- :func:`add_data`, :func:`data_folder`: ``--data DIR`` (the real datasets, default ``../shared/data``
  beside the repository) and the check that it is there.
- :func:`add_draw`, :func:`add_run`: a hold-out study's ``draw`` (``--seed``, ``--out``: the case list,
  committed before it is run) and ``run`` (the list, ``--json``, ``--write``, ``--label``: the results
  beside the list, :func:`benchmarks.results.results_of_cases`) sub-commands.
- :func:`table_head`: the head of a study's markdown table.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["study_parser", "study_commands", "add_data", "data_folder", "add_draw", "add_run", "table_head"]

#: the real datasets' folder when ``--data`` is not given: ``shared/data`` beside the repository
DEFAULT_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def study_parser(doc: str | None, *, data: bool = False) -> argparse.ArgumentParser:
    """The parser of a study whose module docstring is ``doc`` (its first line is the description); with
    ``data``, its ``--data`` option (:func:`add_data`)."""
    ap = argparse.ArgumentParser(description=(doc or "").splitlines()[0])
    if data:
        add_data(ap)
    return ap


def study_commands(doc: str | None) -> tuple[argparse.ArgumentParser, argparse._SubParsersAction]:
    """The parser of a study made of sub-commands (:func:`add_draw`, :func:`add_run`) and their table."""
    ap = study_parser(doc)
    return ap, ap.add_subparsers(dest="cmd", required=True)


def add_data(ap: argparse.ArgumentParser) -> None:
    """``--data DIR``: the folder of the real datasets (default :data:`DEFAULT_DATA`)."""
    ap.add_argument("--data", default=str(DEFAULT_DATA), help="the folder of the real datasets")


def data_folder(args: argparse.Namespace) -> Path | None:
    """The ``--data`` folder, or None with one line on stderr when it is not there (nothing to do)."""
    data = Path(args.data)
    if not data.is_dir():
        print(f"no data folder {data}: nothing to do", file=sys.stderr)
        return None
    return data


def add_draw(sub: argparse._SubParsersAction, name: str, help: str, **counts: int) -> argparse.ArgumentParser:
    """A ``draw`` sub-command ``name``: ``--seed`` (required), ``--out`` (the case list to write) and, per
    keyword of ``counts``, how many cases of that kind (``--KIND N``, default its value)."""
    d = sub.add_parser(name, help=help)
    d.add_argument("--seed", type=int, required=True)
    d.add_argument("--out", required=True)
    for kind, n in counts.items():
        d.add_argument(f"--{kind.replace('_', '-')}", type=int, default=n)
    return d


def add_run(sub: argparse._SubParsersAction, name: str, help: str, listed: str = "cases") -> argparse.ArgumentParser:
    """A ``run`` sub-command ``name`` over a list (the positional ``listed``): ``--json`` (every result),
    ``--write`` (the results beside the list, CASES[.LABEL].results.json) and ``--label`` (a later run)."""
    r = sub.add_parser(name, help=help)
    r.add_argument(listed)
    r.add_argument("--json", help="write every result")
    r.add_argument("--write", action="store_true",
                   help="write the results beside the case list (CASES[.LABEL].results.json)")
    r.add_argument("--label", help="a later run: CASES.LABEL.results.json (the first run keeps its file)")
    return r


def table_head(*columns: str) -> None:
    """Print the head of a study's markdown table: the columns and the separator line."""
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
