"""One batch at a time per output folder: ``DIR/.batch.lock`` holds the running batch's process id
under an exclusive ``flock`` (released by the operating system when the process ends, even when
it is killed), so a second ``analysis batch --out DIR`` refuses at once naming the holder instead
of mixing its results with the first one's. The lock file is never written through a link
(:func:`analysis.recording_lock.open_lock_file`)."""
from __future__ import annotations

import os
from pathlib import Path

from ..errors import FolderBusy
from ..recording_lock import open_lock_file

__all__ = ["FolderLock", "FolderBusy"]

LOCK_NAME = ".batch.lock"


class FolderLock:
    """Take ``DIR/.batch.lock`` (raises :class:`FolderBusy` naming the holder's pid); :meth:`release` frees it."""

    def __init__(self, folder: str | Path) -> None:
        self.path = Path(folder) / LOCK_NAME
        self._fd: int | None = open_lock_file(self.path, write=True, error=FolderBusy)  # never through a link
        if self._fd is None:  # a folder that cannot be written: the results cannot be either (reported there)
            return
        try:
            import fcntl
        except ImportError:  # no flock on this platform: no protection, as before
            return
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(self._fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(self._fd)
            self._fd = None
            raise FolderBusy(f"{folder} is in use by another batch (process {holder}): wait for it to finish or give "
                             "another --out folder") from None
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, f"{os.getpid()}\n".encode(), 0)

    def release(self) -> None:
        if self._fd is not None:
            os.ftruncate(self._fd, 0)
            os.close(self._fd)
            self._fd = None
