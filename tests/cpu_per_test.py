"""A pytest plugin that records each test's CPU time, for finding what makes the suite slow on a shared machine.

Wall times (``--durations``) measure the machine's share as much as the work when other programs run; CPU time
(user + system of the test process, plus that of the child processes it waited for: the commands run as
subprocesses, the diagnosis' forked workers) is the work. Run from the repository root, e.g.::

    PYTHONPATH=tests python -m pytest -n 0 -p cpu_per_test --cpu-per-test cpu.tsv tests/test_diagnosis_physical.py

Each line of the file (one per process of ``-n N``: ``cpu.tsv.gw0``, ...; ``cpu.tsv`` alone with ``-n 0``) holds the
test's id, its CPU seconds in this process, in its waited-for children and its wall seconds, tab-separated. Children
not waited for (a browser, a Dask worker killed by the test) are not counted. Only the speed depends on it.
"""
from __future__ import annotations

import os
import resource
import time
from collections.abc import Iterator

import pytest

_ROWS: list[tuple[str, float, float, float]] = []


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--cpu-per-test", metavar="FILE", default=None,
                     help="write each test's CPU seconds (own, waited-for children) and wall seconds to FILE")


def _cpu() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    own0, kids0 = _cpu()
    wall0 = time.perf_counter()
    yield
    own1, kids1 = _cpu()
    _ROWS.append((item.nodeid, own1 - own0, kids1 - kids0, time.perf_counter() - wall0))


def pytest_sessionfinish(session: pytest.Session) -> None:
    path = session.config.getoption("--cpu-per-test")
    if not path or not _ROWS:
        return
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    with open(f"{path}.{worker}" if worker else path, "w", encoding="utf-8") as fh:
        fh.writelines(f"{name}\t{own:.3f}\t{kids:.3f}\t{wall:.3f}\n" for name, own, kids, wall in _ROWS)
