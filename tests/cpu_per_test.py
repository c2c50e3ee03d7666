"""A pytest plugin that records each test's CPU time, for finding what makes the suite slow on a shared machine.

Wall times (``--durations``) measure the machine's share as much as the work when other programs run; CPU time
(user + system of the test process, plus that of the child processes it waited for: the commands run as
subprocesses, the diagnosis' forked workers) is the work. Run from the repository root, e.g.::

    PYTHONPATH=tests python -m pytest -n 0 -p cpu_per_test --cpu-per-test cpu.tsv tests/test_diagnosis_physical.py

Each line of the file (one per process of ``-n N``: ``cpu.tsv.gw0``, ...; ``cpu.tsv`` alone with ``-n 0``) holds the
test's id, its CPU seconds in this process, in its waited-for children, its wall seconds, and (Linux) the seconds the
test's thread waited to be given a core and the seconds it was blocked (sleeping, reading a pipe, waiting for a child),
tab-separated. Children not waited for (a browser, a Dask worker killed by the test) are not counted. On a loaded
machine the wall time is mostly the wait for a core; the blocked time less the children's work is what a test waits
for whatever the load (a timeout, a poll). Only the speed depends on it.
"""
from __future__ import annotations

import os
import resource
import time
from collections.abc import Iterator

import pytest

_ROWS: list[tuple[str, float, float, float, float, float]] = []


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--cpu-per-test", metavar="FILE", default=None,
                     help="write each test's CPU seconds (own, waited-for children) and wall seconds to FILE")


def _thread_sched() -> tuple[float, float]:
    """Seconds this thread ran and waited to run (Linux ``schedstat``); zeros elsewhere."""
    try:
        with open("/proc/thread-self/schedstat", encoding="ascii") as fh:
            ran, queued = fh.read().split()[:2]
    except OSError:
        return 0.0, 0.0
    return int(ran) / 1e9, int(queued) / 1e9


def _cpu() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    own0, kids0 = _cpu()
    ran0, queued0 = _thread_sched()
    wall0 = time.perf_counter()
    yield
    wall = time.perf_counter() - wall0
    own1, kids1 = _cpu()
    ran1, queued1 = _thread_sched()
    queued = queued1 - queued0
    blocked = max(0.0, wall - (ran1 - ran0) - queued) if ran1 else 0.0
    _ROWS.append((item.nodeid, own1 - own0, kids1 - kids0, wall, queued, blocked))


def pytest_sessionfinish(session: pytest.Session) -> None:
    path = session.config.getoption("--cpu-per-test")
    if not path or not _ROWS:
        return
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    with open(f"{path}.{worker}" if worker else path, "w", encoding="utf-8") as fh:
        fh.writelines(f"{name}\t{own:.3f}\t{kids:.3f}\t{wall:.3f}\t{queued:.3f}\t{blocked:.3f}\n"
                      for name, own, kids, wall, queued, blocked in _ROWS)
