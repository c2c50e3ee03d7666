"""Room on the disk for a file changed in place, and how a full disk is recognised.

A writer that changes a file in place (the recording's HDF5 file) reserves the room a change needs
*before* it writes any of it (:func:`reserve`): when the disk is full, or the process' file size
limit is reached, the reservation fails with ``ENOSPC``/``EFBIG`` and nothing has been written, so
the file stays as its last complete change left it, readable and resumable. (A write that fails
half way would leave libhdf5's copy of the file's structure out of step with the disk: the file
then cannot be read, and libhdf5 itself may crash.)

On Linux the room is taken with ``fallocate(FALLOC_FL_KEEP_SIZE)``: blocks after the end of the
file, which the file's later writes then fill, while its size stays what the writer wrote. Where
that is not available the free space the file system reports is checked instead (another program
filling the disk at the same moment can then still win the race). :func:`release_reserve` gives
back what was reserved and not used.
"""
from __future__ import annotations

import contextlib
import ctypes
import errno
import functools
import os
from pathlib import Path
from typing import Any

from .errors import DiskFullError

__all__ = ["DISK_FULL_ERRNOS", "disk_full_cause", "reserve", "release_reserve"]

#: what a write returns when there is no room: disk full, file size limit, disk quota
DISK_FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EFBIG, getattr(errno, "EDQUOT", errno.ENOSPC)})

_FALLOC_FL_KEEP_SIZE = 1


def disk_full_cause(exc: BaseException | None) -> OSError | None:
    """The ``OSError`` saying the disk (or the file size limit) is full in ``exc`` or in the errors
    it was raised from (libraries such as pyuff wrap it in their own error), else None."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, DiskFullError) or (isinstance(exc, OSError) and exc.errno in DISK_FULL_ERRNOS):
            return exc
        exc = exc.__cause__ or exc.__context__
    return None


def _file_size_limit() -> int | None:
    """The process' file size limit in bytes (``ulimit -f``), None when unlimited."""
    try:
        import resource
    except ImportError:  # not on this platform
        return None
    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    return None if soft == resource.RLIM_INFINITY else int(soft)


@functools.lru_cache(maxsize=1)
def _fallocate() -> Any:
    """The C library's ``fallocate`` (Linux), None where there is none."""
    try:
        fallocate = ctypes.CDLL(None, use_errno=True).fallocate
    except (OSError, AttributeError, TypeError):
        return None
    fallocate.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64]
    fallocate.restype = ctypes.c_int
    return fallocate


def _fallocate_keep_size(fd: int, offset: int, nbytes: int) -> bool:
    """Reserve ``nbytes`` from ``offset`` without changing the file's size; False when the system
    cannot (no ``fallocate``, or not on this file system); raises ``OSError`` when it has no room."""
    fallocate = _fallocate()
    if fallocate is None:
        return False
    if fallocate(fd, _FALLOC_FL_KEEP_SIZE, offset, nbytes) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL):
        return False
    raise OSError(code, os.strerror(code))


def reserve(fd: int, nbytes: int, path: str | os.PathLike[str]) -> None:
    """Make sure ``nbytes`` (bytes) can be written after the end of the open file ``fd`` (``path``
    names it in the error): raises ``OSError`` (``EFBIG`` beyond the file size limit, ``ENOSPC``
    when the disk has no room) before anything is written."""
    size = os.fstat(fd).st_size
    limit = _file_size_limit()
    if limit is not None and size + nbytes > limit:
        raise OSError(errno.EFBIG, os.strerror(errno.EFBIG), os.fspath(path))
    try:
        if _fallocate_keep_size(fd, size, nbytes):
            return
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, os.fspath(path)) from None
    if not hasattr(os, "fstatvfs"):  # Windows: no way to ask; the write itself will tell
        return
    st = os.fstatvfs(fd)
    if st.f_bavail * st.f_frsize < nbytes:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), os.fspath(path))


def release_reserve(path: str | os.PathLike[str]) -> None:
    """Give back the room :func:`reserve` took after the end of the (closed) file ``path``: its
    size is set one byte larger and back, which frees blocks beyond the end on every file system."""
    p = Path(path)
    with contextlib.suppress(OSError):
        size = p.stat().st_size
        os.truncate(p, size + 1)
        os.truncate(p, size)
