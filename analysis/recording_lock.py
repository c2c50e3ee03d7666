"""Reading a recording while it is being written, and one writer at a time: a lock file beside the
recording.

libhdf5 locks a file it writes (``flock``), so a second process cannot open it at all, and it gives
no way to read a file whose writer adds groups as it goes (HDF5's single-writer/multiple-reader
mode only allows appending to datasets that exist). impactlab's writer therefore keeps
``REC.h5.lock`` beside the recording while it is open. The file holds the writer's process id and
two one-byte record locks, taken per open file (Linux open-file-description locks; POSIX record
locks elsewhere), which also work where libhdf5's own lock is switched off
(``HDF5_USE_FILE_LOCKING=FALSE``, network file systems):

- byte 0, *alive*: held exclusively by the writer from before it opens (or creates) the recording
  until it has closed it and removed the lock file. The operating system drops it when the writer
  dies, so a lock file whose byte 0 nobody holds was left by a killed writer (stale) and is taken
  over with a note. A second writer that finds byte 0 held refuses (:class:`OutputBusy`), whatever
  ``--overwrite`` says.
- byte 1, *changing*: held exclusively by the writer while it changes the recording (from the first
  change until the flush that ends it). A reader that finds byte 0 held takes byte 1 shared, copies
  the recording (then consistent: the last flush is complete and nothing is being written),
  releases it and reads the copy. So a live reader sees every hit flushed before it started, and
  the writer waits at most one file copy before its next write.

A lock file is opened without following links (:func:`open_lock_file`): a symbolic link, a hard
link or anything but a regular file there is refused, never written through. A recording locked by
any other program is reported as locked, with the process id from the operating system's lock table
when it can be found, never as damaged.
"""
from __future__ import annotations

import contextlib
import errno
import logging
import os
import shutil
import stat
import struct
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

from analysis.errors import OutputBusy, RecordingError

__all__ = ["WriterLock", "locked", "lock_path", "open_lock_file", "writer_alive", "live_copy",
           "holder_pid", "live_copy_file", "locked_error", "busy_error", "is_lock_error", "held_by_other_program"]

log = logging.getLogger(__name__)

_F = TypeVar("_F", bound=Callable[..., Any])

#: the byte of the lock file a writer holds for as long as it has the recording open
ALIVE_BYTE = 0
#: the byte of the lock file a writer holds while it changes the recording (readers: shared, to copy)
CHANGING_BYTE = 1


def lock_path(path: str | Path) -> Path:
    """The lock file of a recording: ``REC.h5`` -> ``REC.h5.lock``."""
    p = Path(path)
    return p.with_name(p.name + ".lock")


def open_lock_file(path: str | Path, *, write: bool, error: type[Exception] = RecordingError) -> int | None:
    """Open the lock file ``path`` without following a link: created when ``write``; None when it is
    missing (reading) or it cannot be created in its folder (writing: the output cannot be written
    either, the writer reports that). Raises ``error`` (one line, what to do) when ``path`` is a
    symbolic link, not a regular file, a file with other names (a hard link) or one that exists but
    cannot be opened for writing."""
    p = Path(path)
    flags = (os.O_RDWR | os.O_CREAT if write else os.O_RDONLY) | getattr(os, "O_NOFOLLOW", 0) \
        | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(p, flags, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP or (p.is_symlink() and exc.errno in (errno.ENOENT, errno.EEXIST)):
            raise error(_not_a_lock_file(p, "a symbolic link")) from None
        if exc.errno == errno.ENOENT and not write:
            return None
        if exc.errno in (errno.EACCES, errno.EROFS, errno.EPERM):
            if write and os.path.lexists(p):  # another user's lock file: never ignored
                raise error(f"{p} cannot be opened for writing ({exc.strerror}): it belongs to another user's "
                            "writer; wait for it to finish or choose another output file") from None
            return None
        raise
    st = os.fstat(fd)
    what = "" if stat.S_ISREG(st.st_mode) else "not a regular file"
    what = what or ("a hard link to another file" if st.st_nlink > 1 else "")
    if what:
        os.close(fd)
        raise error(_not_a_lock_file(p, what))
    return fd


def _not_a_lock_file(path: Path, what: str) -> str:
    return (f"{path} is {what}, not a lock file impactlab made: it is never written through; move it away "
            f"(it may hold your data) and run the command again")


# -- record locks on one byte, per open file ----------------------------------------------------------------
def _fcntl() -> Any:
    try:
        import fcntl
    except ImportError:  # no record locks on this platform: writers and readers do not share a file there
        return None
    return fcntl


def _ofd(fcntl: Any) -> bool:
    """Whether open-file-description locks can be used (Linux, 64-bit ``struct flock`` layout)."""
    return sys.platform.startswith("linux") and hasattr(fcntl, "F_OFD_SETLK") and struct.calcsize("P") == 8


def _flock_struct(kind: int, byte: int) -> bytes:
    # struct flock on 64-bit Linux: short l_type, short l_whence, off_t l_start, off_t l_len, pid_t l_pid
    return struct.pack("hhqqi4x", kind, os.SEEK_SET, byte, 1, 0)


def _set(fd: int, kind: str, byte: int, wait: bool) -> bool:
    """Take (``kind`` "ex"/"sh") or release ("un") the lock on ``byte``; False when ``wait`` is False
    and another open file holds a conflicting lock."""
    fcntl = _fcntl()
    if fcntl is None:
        return True
    if _ofd(fcntl):
        code = {"ex": fcntl.F_WRLCK, "sh": fcntl.F_RDLCK, "un": fcntl.F_UNLCK}[kind]
        try:
            fcntl.fcntl(fd, fcntl.F_OFD_SETLKW if wait else fcntl.F_OFD_SETLK, _flock_struct(code, byte))
            return True
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EACCES):
                return False
            if exc.errno != errno.EINVAL:  # EINVAL: a kernel without them: POSIX record locks below
                raise
    op = {"ex": fcntl.LOCK_EX, "sh": fcntl.LOCK_SH, "un": fcntl.LOCK_UN}[kind]
    try:
        fcntl.lockf(fd, op if wait or kind == "un" else op | fcntl.LOCK_NB, 1, byte, os.SEEK_SET)
        return True
    except OSError as exc:
        if exc.errno in (errno.EAGAIN, errno.EACCES):
            return False
        raise


def _held_exclusively(fd: int, byte: int) -> bool:
    """Whether another open file holds ``byte`` exclusively (tested without taking it)."""
    fcntl = _fcntl()
    if fcntl is None:
        return False
    if _ofd(fcntl):
        try:
            got = fcntl.fcntl(fd, fcntl.F_OFD_GETLK, _flock_struct(fcntl.F_RDLCK, byte))
            return bool(struct.unpack("hhqqi4x", got)[0] != fcntl.F_UNLCK)
        except OSError as exc:
            if exc.errno != errno.EINVAL:
                raise
    if not _set(fd, "sh", byte, wait=False):
        return True
    _set(fd, "un", byte, wait=False)
    return False


def _pid_in(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
        return int(text) if text else None
    except (OSError, ValueError):
        return None


def _is_at(fd: int, path: Path) -> bool:
    """Whether the open file ``fd`` is still the file at ``path`` (a writer that finished removes it)."""
    try:
        a, b = os.fstat(fd), os.stat(path, follow_symlinks=False)
    except OSError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


class WriterLock:
    """The writer's side of ``REC.h5.lock`` (see module doc). Creating it takes byte 0 for good, or
    raises :class:`OutputBusy` naming the live writer; :meth:`changing` holds byte 1 around one
    change of the recording (re-entrant); :meth:`release` removes the lock file and frees both."""

    def __init__(self, path: str | Path) -> None:
        self.recording = Path(path)
        self.path = lock_path(path)
        self._depth = 0
        self._fd: int | None = None
        existed = os.path.lexists(self.path)
        if existed and writer_alive(self.recording):  # seen read-only too (another user's writer)
            raise busy_error(self.recording)
        for _ in range(100):  # another writer may remove the file between our open and our lock
            fd = open_lock_file(self.path, write=True)
            if fd is None:
                return  # a read-only folder: the recording itself cannot be written either
            if not _set(fd, "ex", ALIVE_BYTE, wait=False):
                pid = _pid_in(fd)
                os.close(fd)
                raise busy_error(self.recording, pid)
            if _is_at(fd, self.path):
                break
            os.close(fd)
        else:  # pragma: no cover - a lock file replaced 100 times in a row
            raise RecordingError(f"{self.path} keeps changing: another program is creating and removing it")
        self._fd = fd
        if existed:
            left = _pid_in(fd)
            if left is None:
                log.warning("%s: removed a stale empty lock file (left by a writer killed before its recording "
                            "existed)", self.path)
            else:
                log.warning("%s: removed the stale lock of process %d, which no longer has the recording open (a "
                            "writer that was killed)", self.path, left)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        os.fsync(fd)

    @contextlib.contextmanager
    def changing(self) -> Iterator[None]:
        """Hold byte 1 exclusively while the body changes and flushes the recording (re-entrant)."""
        if self._fd is None:
            yield
            return
        if self._depth == 0:
            _set(self._fd, "ex", CHANGING_BYTE, wait=True)
        self._depth += 1
        try:
            yield
        finally:
            self._depth -= 1
            if self._depth == 0 and self._fd is not None:
                _set(self._fd, "un", CHANGING_BYTE, wait=False)

    def release(self) -> None:
        """Remove the lock file (still holding it, so no other writer can have taken it) and free it."""
        if self._fd is None:
            return
        if _is_at(self._fd, self.path):
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
        fd = open_lock_file(lock_path(path), write=False)
    except (RecordingError, OSError):
        return None
    if fd is None:
        return None
    try:
        return _pid_in(fd)
    finally:
        os.close(fd)


def holder_pid(path: str | Path) -> int | None:
    """The process id holding a lock on ``path`` (impactlab's lock file, else the Linux lock table)."""
    p = Path(path)
    pid = _writer_pid(p) if writer_alive(p) else None
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


def writer_alive(path: str | Path) -> bool:
    """Whether an impactlab writer has the recording ``path`` open now (it holds byte 0 of the lock
    file). Tested without taking any lock; False when there is no lock file, or none a writer could
    have made (a link, not a regular file) or it cannot be read."""
    try:
        fd = open_lock_file(lock_path(path), write=False)
    except OSError:  # RecordingError included: not a lock file impactlab made
        return False
    if fd is None:
        return False
    try:
        return _held_exclusively(fd, ALIVE_BYTE)
    finally:
        os.close(fd)


def held_by_other_program(path: str | Path) -> bool:
    """Whether a program holds the file ``path`` locked for writing with libhdf5's own ``flock``
    (an ``h5py`` session, HDFView); False when it is not there or cannot be checked."""
    fcntl = _fcntl()
    if fcntl is None:
        return False
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return False
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError as exc:
            return exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    finally:
        os.close(fd)


def live_copy(path: str | Path) -> Path:
    """A consistent copy of a recording an impactlab writer has open (see module doc); the caller
    deletes it. Raises :class:`RecordingError` when the lock file cannot be read."""
    p = Path(path)
    try:
        fd = open_lock_file(lock_path(p), write=False)
    except OSError as exc:
        raise locked_error(p, f"its lock file cannot be read ({exc.strerror or exc})") from None
    if fd is None:
        raise locked_error(p)
    try:
        _set(fd, "sh", CHANGING_BYTE, wait=True)
        tmp_fd, tmp_name = live_copy_file(p)
        try:
            with open(p, "rb") as src, os.fdopen(tmp_fd, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
        except OSError:
            with contextlib.suppress(OSError):
                os.unlink(tmp_name)
            raise
        return Path(tmp_name)
    finally:
        _set(fd, "un", CHANGING_BYTE, wait=False)
        os.close(fd)


def live_copy_file(path: Path) -> tuple[int, str]:
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


def busy_error(path: str | Path, pid: int | None = None) -> OutputBusy:
    """The one message for an output that a live writer holds: nothing is written to it."""
    p = Path(path)
    pid = _writer_pid(p) if pid is None else pid
    who = f"process {pid}" if pid is not None else "another impactlab process"
    return OutputBusy(f"{p} is being recorded by {who} (capture, station or import): it is never replaced or "
                      "written while a writer has it open, even with --overwrite; wait for that process to finish "
                      "(or stop it), or choose another output file")
