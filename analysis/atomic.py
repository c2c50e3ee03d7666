"""Atomic file writes: a reader (or a crash, or a full disk) never sees a half-written file.

The content goes to a temporary file in the target's folder (same file system), is flushed to
disk, and is renamed over the target with :func:`os.replace`, which is atomic on POSIX and Windows.
When the writer fails (a full disk, an error, Ctrl-C) the temporary file is removed and the target
is left as it was.

Temporary files and folders are named ``.TARGET.PID-RANDOM.part`` beside their target, with the
id of the process that made them: one left by a process that was killed is removed by the next
write of the same target (:func:`remove_stale_temporaries`), never one whose process still runs.
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from .disk_space import disk_full_cause
from .errors import DiskFullError

__all__ = ["atomic_path", "write_bytes_atomic", "write_text_atomic", "write_json_atomic", "temporary_beside",
           "remove_stale_temporaries", "fsync_file", "fsync_folder"]


def temporary_beside(target: str | os.PathLike[str], folder: str | os.PathLike[str] | None = None) -> Path:
    """A new temporary name for ``target``: ``.NAME.PID-RANDOM.part`` in ``folder`` (default: the
    target's own folder). Nothing is created."""
    t = Path(target)
    where = Path(folder) if folder is not None else t.parent
    return where / f".{t.name}.{os.getpid()}-{uuid.uuid4().hex[:12]}.part"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, owned by someone else
        return True
    return True


def remove_stale_temporaries(target: str | os.PathLike[str], folder: str | os.PathLike[str] | None = None) -> int:
    """Remove the temporary files and folders of ``target`` (named by :func:`temporary_beside`, in
    ``folder``, default the target's folder) whose process is gone; returns how many were removed."""
    t = Path(target)
    where = Path(folder) if folder is not None else t.parent
    pattern = re.compile(rf"^\.{re.escape(t.name)}\.(\d+)-[0-9a-f]+\.part(\.lock)?$")  # .lock: a recording's
    removed = 0
    try:
        names = os.listdir(where)
    except OSError:
        return 0
    for name in names:
        m = pattern.match(name)
        if m is None or _pid_alive(int(m.group(1))):
            continue
        p = where / name
        try:
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            else:
                p.unlink()
            removed += 1
        except OSError:
            continue
    return removed


def fsync_file(path: str | os.PathLike[str]) -> None:
    """Sync a file's data to the disk (the file may be closed)."""
    with open(path, "rb+") as fh:
        os.fsync(fh.fileno())


def fsync_folder(folder: Path) -> None:
    """Make a rename, a new or a removed file in ``folder`` durable (where folders can be opened; not on Windows)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` for a writer that wants a file name (pyarrow,
    matplotlib, h5py, pyuff); on normal exit it replaces ``path``, on an error it is removed and
    ``path`` is left as it was."""
    target = Path(path)
    remove_stale_temporaries(target)
    tmp = temporary_beside(target)   # created by the writer (umask applies)
    try:
        yield tmp
        fsync_file(tmp)
        os.replace(tmp, target)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        full = disk_full_cause(exc)
        if full is not None and not isinstance(full, DiskFullError):  # named by the file the user asked for
            raise OSError(full.errno, full.strerror, str(target)) from None
        raise
    fsync_folder(target.parent)


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: str | os.PathLike[str], doc: Any) -> None:
    """Write ``doc`` as strict JSON (no NaN) to ``path`` atomically."""
    write_text_atomic(path, json.dumps(doc, indent=2, allow_nan=False) + "\n")
