"""Outputs never replace inputs: the one check every command runs on the files it is about to write.

:func:`check_outputs` compares every output a command was given with every input it reads (the same
file by device and inode: the same path, a symbolic link or a hard link to it all count) and with
the other outputs, and refuses an output that a live impactlab writer holds (a recording being
captured, recorded by the station or imported), before anything is opened for writing. Commands
call it right after parsing, so a refusal costs nothing and writes nothing.
"""
from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from .errors import UsageError
from .recording_lock import busy_error, writer_alive

__all__ = ["same_file", "check_outputs"]

PathLike = str | os.PathLike[str]


def same_file(a: PathLike, b: PathLike) -> bool:
    """Whether ``a`` and ``b`` are one file (links followed; hard links share device and inode).
    False when either does not exist."""
    return _key(a) is not None and _key(a) == _key(b)


def _key(path: PathLike) -> tuple[int, int] | None:
    """The file ``path`` is (device, inode; links followed), None when there is none."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return st.st_dev, st.st_ino


def _how(out: Path, other: Path) -> str:
    return "" if os.path.abspath(out) == os.path.abspath(other) else " through a link"


def check_outputs(outputs: Iterable[PathLike | None], inputs: Iterable[PathLike | None] = ()) -> None:
    """Refuse the outputs of a command before it writes any (None entries are options not given).

    Raises :class:`~analysis.errors.UsageError` when an output is one of the ``inputs`` or another
    output, and :class:`~analysis.errors.OutputBusy` when a live writer holds it (see module doc).
    Each file is looked at once (a batch of thousands of inputs costs one ``stat`` each)."""
    ins: dict[tuple[int, int], Path] = {}
    for i in inputs:
        key = None if i is None else _key(i)
        if key is not None:
            ins.setdefault(key, Path(i))  # type: ignore[arg-type]
    seen: dict[object, Path] = {}
    for o in outputs:
        if o is None:
            continue
        out = Path(o)
        key = _key(out)
        if key is not None and key in ins:
            inp = ins[key]
            raise UsageError(f"the output {out} is the input {inp} (the same file{_how(out, inp)}): an output "
                             "never replaces an input; give another output file")
        for k in (key, os.path.abspath(out)):
            if k is not None and k in seen:
                raise UsageError(f"the output {out} is also given as the output {seen[k]}: give each output its own "
                                 "file")
            if k is not None:
                seen[k] = out
        if writer_alive(out):
            raise busy_error(out)
