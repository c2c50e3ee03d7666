"""How many BLAS threads the library's numerical kernels use, chosen from the problem and the machine.

A threaded BLAS (OpenBLAS, MKL) starts one thread per core for every matrix product. On the small
problems of an ordinary impact test (a few FRFs, a few thousand lines) that gains nothing, and on a
machine where other programs keep the cores busy the threads wait for each other: the fit of a
default capture, under 2 s of work single-threaded, took 70 s on a shared 2-core machine (35 s of
CPU spent by threads waiting), 160 s with two more CPU-bound programs running. The kernels
(the automatic fit, LSFD, stabilization, LSCF/LSCE, the diagnosis) therefore run inside
:func:`blas_threads`, which sets the thread count of every BLAS/OpenMP pool loaded in the process
(threadpoolctl) for the duration of the call:

- the user's choice when there is one: ``--threads N`` of the commands that compute
  (:func:`use_threads`), else the environment variable ``IMPACTLAB_THREADS`` (a positive number;
  ``auto`` or empty: the rule below);
- otherwise :func:`choose_threads`: one thread below ``WORK_PER_THREAD`` FRF values, and above it
  one thread per ``WORK_PER_THREAD`` values, at most as many as there are free cores (the cores this
  process may run on less the other programs running, from the 1-minute load average and the tasks
  running right now).

Nested kernels (LSFD inside the automatic fit) keep the choice of the outermost one.
"""
from __future__ import annotations

import contextlib
import functools
import os
import sys
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

__all__ = ["ENV_VAR", "BLAS_ENV_VARS", "WORK_PER_THREAD", "choose_threads", "requested_threads", "use_threads",
           "command_scope", "set_threads", "blas_threads", "limits_blas_threads", "load_blas_single_threaded",
           "worker_processes"]

#: environment variable with the user's thread count ("auto" or unset: chosen per problem)
ENV_VAR = "IMPACTLAB_THREADS"
#: FRF values (outputs x references x lines) per BLAS thread; below this a kernel runs single-threaded
WORK_PER_THREAD = 1_000_000

F = TypeVar("F", bound=Callable[..., Any])

_override: int | None = None     # --threads of the running command (use_threads)
_depth = 0                          # how many kernels are active (the outermost one chooses)


def choose_threads(work: float, cores: int, others_running: float) -> int:
    """The BLAS thread count for a problem of ``work`` FRF values on a machine with ``cores`` cores
    available to this process, of which ``others_running`` are kept busy by other programs
    (a count, may be fractional; this process itself not included).

    One thread per ``WORK_PER_THREAD`` values (at least one), at most the free cores
    ``round(cores - others_running)``, and never fewer than one."""
    if cores < 1:
        raise ValueError(f"cores must be >= 1; got {cores}")
    by_size = int(max(0.0, float(work)) // WORK_PER_THREAD)
    free = int(round(cores - max(0.0, float(others_running))))
    return max(1, min(by_size, free, cores))


def _cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not on Linux
        return max(1, os.cpu_count() or 1)


def _others_running() -> float:
    """Other programs keeping a core busy: the larger of the 1-minute load average and the tasks
    running now (``/proc/loadavg``), less this process."""
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):
        load = 0.0
    running = 0.0
    try:
        with open("/proc/loadavg", encoding="ascii") as fh:
            running = float(fh.read().split()[3].split("/")[0])
    except (OSError, IndexError, ValueError):
        pass
    return max(0.0, max(load, running) - 1.0)


def worker_processes() -> int:
    """Processes a computation split into independent tasks may use: the user's thread count
    (:func:`requested_threads`) when given, else every core this process may run on.

    Unlike BLAS threads, which wait for each other at every step and lose far more than they gain
    when another program holds a core, independent processes each progress on whatever share of a
    core they get and never spend CPU waiting: on a busy machine two processes win the user's work a
    larger share of the cores, on an idle one they use both."""
    n = requested_threads()
    if n is not None:
        return n
    return _cores()


def _parse(text: str, where: str) -> int | None:
    text = text.strip().lower()
    if text in ("", "auto"):
        return None
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"{where} must be a positive number of threads or 'auto'; got {text!r}")
    return n


def requested_threads() -> int | None:
    """The user's thread count: ``--threads`` of the running command, else ``IMPACTLAB_THREADS``;
    None: chosen per problem. A bad value of the environment variable is a ``ValueError`` naming it."""
    if _override is not None:
        return _override
    return _parse(os.environ.get(ENV_VAR, ""), f"the environment variable {ENV_VAR}")


@contextlib.contextmanager
def use_threads(n: int | None) -> Iterator[None]:
    """Within the block every kernel uses ``n`` BLAS threads (None: the environment variable or the
    rule); what ``--threads`` does for a command."""
    global _override
    if n is not None and int(n) < 1:
        raise ValueError(f"the number of threads must be >= 1; got {n}")
    before = _override
    _override = None if n is None else int(n)
    try:
        yield
    finally:
        _override = before


@contextlib.contextmanager
def command_scope() -> Iterator[None]:
    """The extent of one command: the thread count it sets (:func:`set_threads`, or ``IMPACTLAB_THREADS``
    set for its worker processes) is undone when it ends."""
    env = os.environ.get(ENV_VAR)
    try:
        with use_threads(None):
            yield
    finally:
        if env is None:
            os.environ.pop(ENV_VAR, None)
        else:
            os.environ[ENV_VAR] = env


def set_threads(n: int | None) -> None:
    """Set the user's thread count for the rest of the command (``--threads`` when it is parsed);
    :func:`analysis.command_line.cli_entry` restores the previous value when the command ends."""
    global _override
    if n is not None and int(n) < 1:
        raise ValueError(f"the number of threads must be >= 1; got {n}")
    _override = None if n is None else int(n)


@contextlib.contextmanager
def blas_threads(work: float) -> Iterator[int]:
    """Run the block with the BLAS thread count for a problem of ``work`` FRF values (module
    docstring); yields the count. Inside another :func:`blas_threads` block the outer count stays."""
    global _depth
    if _depth:
        _depth += 1
        try:
            yield 0
        finally:
            _depth -= 1
        return
    n = requested_threads()
    if n is None:
        n = choose_threads(work, _cores(), _others_running())
    try:
        # the limit reaches the pools of the libraries loaded by now: when scipy is in use, its
        # BLAS (its own OpenBLAS) is loaded first, else a kernel that reaches it later would run
        # its default thread count, which under load costs more than the work (a 50 x 50
        # triangular solve took 6 ms instead of microseconds beside two busy programs)
        if "scipy" in sys.modules:
            import scipy.linalg  # noqa: F401
        from threadpoolctl import ThreadpoolController
    except ImportError:  # an environment installed before it was a dependency: BLAS as configured
        limit: contextlib.AbstractContextManager[Any] = contextlib.nullcontext()
    else:
        limit = ThreadpoolController().limit(limits=n)
    _depth += 1
    try:
        with limit:
            yield n
    finally:
        _depth -= 1


#: the variables a BLAS library reads its thread count from when it is loaded
BLAS_ENV_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def load_blas_single_threaded() -> None:
    """Import numpy with its BLAS started on one thread, for a command's process (``python -m
    analysis``): the kernels raise the count where the problem pays for it (:func:`blas_threads`),
    and a threaded BLAS started at import costs a command CPU for threads that wait (on a busy
    2-core machine about a tenth of the default fit). Nothing is done when numpy is loaded already
    or the user set one of :data:`BLAS_ENV_VARS`; the environment is restored after the import,
    so the processes the command starts see the user's."""
    if "numpy" in sys.modules or any(os.environ.get(v) for v in BLAS_ENV_VARS):
        return
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    try:
        import numpy  # noqa: F401
    finally:
        os.environ.pop("OPENBLAS_NUM_THREADS", None)


def _frf_values(obj: Any) -> float:
    H = getattr(obj, "H", None)
    return float(getattr(H, "size", 0) or 0)


def limits_blas_threads(func: F) -> F:
    """Decorate a kernel whose first argument is an FRF set (anything with an ``H`` array): it runs
    inside :func:`blas_threads` sized by that array."""

    @functools.wraps(func)
    def run(*args: Any, **kwargs: Any) -> Any:
        with blas_threads(_frf_values(args[0]) if args else 0.0):
            return func(*args, **kwargs)

    return run  # type: ignore[return-value]
