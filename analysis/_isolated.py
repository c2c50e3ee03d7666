"""Run a file parser in a child process, so a crash of a C library on a damaged file (a
segmentation fault in libhdf5 or in scipy's MATLAB reader, both found by fuzzing) cannot kill the
calling program. Used by :mod:`acquisition.importers` and :func:`analysis.recording.verify_recording`.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .errors import ChildCrashed, ChildTimeout

__all__ = ["ChildCrashed", "ChildTimeout", "run_isolated"]


def _child(target: Callable[..., Any], args: tuple, conn: Any) -> None:
    import faulthandler

    faulthandler.disable()  # a crash here is expected and reported by the exit code, not dumped on stderr
    try:
        conn.send(("ok", target(*args)))
    except Exception as exc:  # reported to the parent, which decides what it means
        conn.send(("error", exc))
    finally:
        conn.close()


def run_isolated(target: Callable[..., Any], args: tuple, timeout_s: float) -> Any:
    """``target(*args)`` in a child process; returns its (picklable) result or re-raises its exception.

    Raises :class:`ChildCrashed` when the child dies without answering and :class:`ChildTimeout`
    after ``timeout_s`` seconds. Uses ``fork`` when this process runs a single thread (fast: no
    re-import), else ``spawn`` (``target`` must then be importable at module level)."""
    import multiprocessing
    import threading

    single = threading.active_count() == 1
    method = "fork" if single and "fork" in multiprocessing.get_all_start_methods() else "spawn"
    ctx: Any = multiprocessing.get_context(method)
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(target, args, send), daemon=True)
    proc.start()
    send.close()
    try:
        if not recv.poll(timeout_s):
            raise ChildTimeout(f"no answer within {timeout_s:g} s")
        try:
            kind, payload = recv.recv()
        except (EOFError, OSError):
            proc.join(5.0)
            raise ChildCrashed(proc.exitcode) from None
    finally:
        recv.close()
        proc.join(5.0)
        if proc.is_alive():
            proc.kill()
            proc.join(1.0)
    if kind == "error":
        raise payload
    return payload


def call_isolated(target: Callable[..., Any], args: tuple, timeout_s: float, *,
                  crashed: Callable[[int | None], Exception], timed_out: Callable[[], Exception]) -> Any:
    """:func:`run_isolated`, with a crash or a timeout of the child turned into the caller's own
    error: ``crashed(exitcode)`` and ``timed_out()`` build the exception raised instead."""
    try:
        return run_isolated(target, args, timeout_s)
    except ChildCrashed as exc:
        raise crashed(exc.exitcode) from None
    except ChildTimeout:
        raise timed_out() from None
