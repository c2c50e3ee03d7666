"""Reading a recording while it is being written: a lock file beside the recording.

libhdf5 locks a file it writes (``flock``), so a second process cannot open it at all, and it gives
no way to read a file whose writer adds groups as it goes (HDF5's single-writer/multiple-reader
mode only allows appending to datasets that exist). impactlab's writer therefore keeps
``REC.h5.lock`` beside the recording while it is open: the file holds the writer's process id, and
the writer holds an exclusive ``flock`` on it while it changes the recording (from the first change
until the flush that ends it). A reader that finds the recording locked takes a shared ``flock``,
copies the recording (then consistent: the last flush is complete and nothing is being written),
releases the lock and reads the copy. So a live reader sees every hit flushed before it started,
and the writer waits at most one file copy before its next write.

A recording locked by any other program is reported as locked, with the process id from the
operating system's lock table when it can be found, never as damaged.
"""
from __future__ import annotations

import contextlib
import errno
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

from analysis.errors import RecordingError

__all__ = ["WriterLock", "locked", "lock_path", "locked_by_writer", "live_copy", "holder_pid", "locked_error", "is_lock_error"]

_F = TypeVar("_F", bound=Callable[..., Any])


def lock_path(path: str | Path) -> Path:
    """The lock file of a recording: ``REC.h5`` -> ``REC.h5.lock``."""
    p = Path(path)
    return p.with_name(p.name + ".lock")


def _flock(fd: int, op: int) -> None:
    try:
        import fcntl
    except ImportError:  # no flock on this platform: writer and readers do not share the file there
        return
    fcntl.flock(fd, op)


def _ops() -> tuple[int, int, int]:
    try:
        import fcntl
    except ImportError:
        return 0, 0, 0
    return fcntl.LOCK_EX, fcntl.LOCK_SH, fcntl.LOCK_UN


class WriterLock:
    """The writer's side of ``REC.h5.lock``: :meth:`changing` holds it exclusively around one change
    of the recording (re-entrant), :meth:`claim` writes this process id into it once the recording
    is open, :meth:`release` removes it when the recording is closed."""

    def __init__(self, path: str | Path) -> None:
        self.path = lock_path(path)
        self._depth = 0
        self._created = not self.path.exists()
        try:
            self._fd: int | None = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError:
            self._fd = None  # a read-only folder: the recording itself cannot be written either

    def claim(self) -> None:
        """Write this process id into the lock file (call holding :meth:`changing`)."""
        if self._fd is not None:
            os.ftruncate(self._fd, 0)
            os.pwrite(self._fd, f"{os.getpid()}\n".encode(), 0)
            self._created = True

    @contextlib.contextmanager
    def changing(self) -> Iterator[None]:
        """Hold the lock exclusively while the body changes and flushes the recording (re-entrant)."""
        if self._fd is None:
            yield
            return
        ex, _, un = _ops()
        if self._depth == 0:
            _flock(self._fd, ex)
        self._depth += 1
        try:
            yield
        finally:
            self._depth -= 1
            if self._depth == 0 and self._fd is not None:
                _flock(self._fd, un)

    def release(self) -> None:
        """Remove the lock file (the recording is closed, or could not be opened: then a lock file
        another writer made is left alone)."""
        if self._fd is None:
            return
        if self._created:
            with contextlib.suppress(OSError):
                self.path.unlink()
        os.close(self._fd)
        self._fd = None


def locked(method: _F) -> _F:
    """Decorator for a writer method: run it holding the writer's lock (``self._lock``)."""
    import functools

    @functools.wraps(method)
    def wrapper(self: Any, *args: Any, **kwargs: Any) -> Any:
        lock = getattr(self, "_lock", None)
        if lock is None:
            return method(self, *args, **kwargs)
        with lock.changing():
            return method(self, *args, **kwargs)

    return wrapper  # type: ignore[return-value]


def is_lock_error(exc: BaseException) -> bool:
    """Whether an error opening an HDF5 file is libhdf5's file lock held by another process."""
    if getattr(exc, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK):
        return True
    text = str(exc).lower()
    return "unable to lock file" in text or "resource temporarily unavailable" in text


def _writer_pid(path: Path) -> int | None:
    try:
        text = lock_path(path).read_text().strip()
        return int(text) if text else None
    except (OSError, ValueError):
        return None


def holder_pid(path: str | Path) -> int | None:
    """The process id holding a lock on ``path`` (impactlab's lock file, else the Linux lock table)."""
    p = Path(path)
    pid = _writer_pid(p) if lock_path(p).exists() else None
    if pid is not None:
        return pid
    try:
        st = p.stat()
        with open("/proc/locks", encoding="ascii") as fh:
            for line in fh:
                parts = line.split()
                if len(parts) >= 6 and parts[1] in ("FLOCK", "POSIX", "OFDLCK"):
                    dev = parts[5].split(":")
                    if len(dev) == 3 and int(dev[2]) == st.st_ino and int(dev[0], 16) == os.major(st.st_dev) \
                            and int(dev[1], 16) == os.minor(st.st_dev):
                        return int(parts[4]) if parts[4].isdigit() else None
    except (OSError, ValueError, IndexError):
        return None
    return None


def locked_by_writer(path: str | Path) -> bool:
    """Whether an impactlab writer has the recording open (its lock file exists and is locked)."""
    lp = lock_path(path)
    if not lp.exists():
        return False
    try:
        fd = os.open(lp, os.O_RDONLY)
    except OSError:
        return False
    try:
        import fcntl

        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError:
            return True  # held exclusively right now: a writer is changing it
        fcntl.flock(fd, fcntl.LOCK_UN)
        return _writer_pid(Path(path)) is not None
    except ImportError:
        return False
    finally:
        os.close(fd)


def live_copy(path: str | Path) -> Path:
    """A consistent copy of a recording an impactlab writer has open (see module doc); the caller
    deletes it. Raises :class:`RecordingError` when the lock file cannot be read."""
    p = Path(path)
    try:
        fd = os.open(lock_path(p), os.O_RDONLY)
    except OSError as exc:
        raise locked_error(p, f"its lock file cannot be read ({exc.strerror})") from None
    _, sh, un = _ops()
    try:
        _flock(fd, sh)
        tmp_fd, tmp_name = _live_copy_file(p)
        try:
            with open(p, "rb") as src, os.fdopen(tmp_fd, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
        except OSError:
            with contextlib.suppress(OSError):
                os.unlink(tmp_name)
            raise
        return Path(tmp_name)
    finally:
        _flock(fd, un)
        os.close(fd)


def _live_copy_file(path: Path) -> tuple[int, str]:
    """A new file for the live copy of ``path`` (open fd, name): ``.REC.h5.PID-RANDOM.part`` beside the
    recording, where copies left by killed readers are removed first
    (:func:`analysis.atomic.remove_stale_temporaries`); in the temporary folder when the recording's
    folder cannot be written or has less room than twice the recording (the copy must never take the
    writer's last room)."""
    from .atomic import remove_stale_temporaries, temporary_beside

    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL
    remove_stale_temporaries(path)
    try:
        st = os.statvfs(path.parent)
        if st.f_bavail * st.f_frsize >= 2 * path.stat().st_size:
            name = temporary_beside(path)
            return os.open(name, flags, 0o600), str(name)
    except OSError:
        pass  # a folder this reader cannot write: the temporary folder
    folder = Path(tempfile.gettempdir())
    remove_stale_temporaries(path, folder)
    name = temporary_beside(path, folder)
    return os.open(name, flags, 0o600), str(name)


def locked_error(path: str | Path, why: str = "") -> RecordingError:
    """The one message for a recording that another process holds open for writing."""
    p = Path(path)
    pid = holder_pid(p)
    who = f"process {pid}" if pid is not None else "another process"
    why = why or f"not by an impactlab writer: {lock_path(p).name} is missing"
    return RecordingError(f"{p} is being written by {who} ({why}): wait for it to finish or close it there; "
                          "recordings written by impactlab's capture, station or import are read live while they "
                          "are written. The file is not damaged")
