"""BLAS threads of the numerical kernels: the rule (a pure function), the user's choice (``--threads``,
``IMPACTLAB_THREADS``) reaching the BLAS pools, and fit results that do not depend on the count."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg  # noqa: F401  (loads SciPy's BLAS, so both pools are seen)
from test_pipeline import make_frf
from threadpoolctl import threadpool_info

from analysis import threads
from analysis.cli_fit import build_parser
from analysis.command_line import cli_entry
from analysis.pipeline import fit_auto
from analysis.threads import (
    ENV_VAR,
    WORK_PER_THREAD,
    blas_threads,
    choose_threads,
    limits_blas_threads,
    requested_threads,
    use_threads,
)


def blas_counts() -> set[int]:
    counts = {int(i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"}
    assert counts, "no BLAS library found by threadpoolctl"
    return counts


@pytest.mark.parametrize("work, cores, others, expected", [
    (3 * 1100, 2, 0.0, 1),                       # a default capture: single-threaded even on an idle machine
    (WORK_PER_THREAD - 1, 8, 0.0, 1),
    (2 * WORK_PER_THREAD, 8, 0.0, 2),            # one thread per WORK_PER_THREAD values
    (3000 * 8000, 2, 0.0, 2),                    # scanning vibrometer, idle: every core
    (3000 * 8000, 2, 2.0, 1),                    # ... two other programs running: one thread
    (3000 * 8000, 8, 2.6, 5),                    # fractional load: rounded
    (3000 * 8000, 2, 9.0, 1),                    # never fewer than one
    (0, 4, 0.0, 1),
])
def test_rule_from_size_and_free_cores(work, cores, others, expected):
    assert choose_threads(work, cores, others) == expected


def test_rule_rejects_no_cores():
    with pytest.raises(ValueError, match="cores must be >= 1"):
        choose_threads(1e9, 0, 0.0)


@limits_blas_threads
def _kernel(frf) -> set[int]:
    """A stand-in kernel: what the BLAS pools are set to while it runs."""
    return blas_counts()


class _Big:
    H = np.zeros((1, 1, 1))

    def __init__(self, n: int) -> None:
        self.H = np.broadcast_to(np.zeros(1), (n,))


def test_small_problem_runs_single_threaded(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    assert _kernel(_Big(10)) == {1}


def test_user_choice_reaches_the_blas_pools_and_is_undone(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    before = blas_counts()
    with use_threads(2):
        assert requested_threads() == 2
        assert _kernel(_Big(10)) == {2}
    assert requested_threads() is None
    assert blas_counts() == before


def test_environment_variable_reaches_the_blas_pools(monkeypatch):
    monkeypatch.setenv(ENV_VAR, "2")
    assert _kernel(_Big(10)) == {2}
    monkeypatch.setenv(ENV_VAR, "auto")
    assert _kernel(_Big(10)) == {1}
    with use_threads(1):                      # --threads wins over the environment
        monkeypatch.setenv(ENV_VAR, "2")
        assert _kernel(_Big(10)) == {1}


@pytest.mark.parametrize("bad", ["0", "-3", "two"])
def test_bad_environment_variable_is_named(monkeypatch, bad):
    monkeypatch.setenv(ENV_VAR, bad)
    with pytest.raises(ValueError, match=ENV_VAR):
        _kernel(_Big(10))


def test_nested_kernels_keep_the_outer_choice(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    with use_threads(2):
        with blas_threads(0) as outer:
            assert outer == 2
            with use_threads(1):          # an inner kernel does not change the pools again
                assert _kernel(_Big(10)) == {2}


def test_threads_option_holds_for_one_command(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    seen = []

    @cli_entry
    def main(argv):
        build_parser().parse_args(argv)
        seen.append(requested_threads())
        return 0

    assert main(["rec.h5", "--threads", "3"]) == 0
    assert seen == [3]
    assert threads.requested_threads() is None   # restored after the command


def test_threads_option_rejects_zero():
    out = subprocess.run([sys.executable, "-m", "analysis", "fit", "rec.h5", "--threads", "0"],
                         capture_output=True, text=True)
    assert out.returncode == 2
    assert "--threads" in out.stderr and "positive" in out.stderr


def test_fit_identical_with_one_and_two_threads(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    frf, _ = make_frf(noise=0.01, seed=4, n_out=6, n_f=1200)
    fits = []
    for n in (1, 2):
        with use_threads(n):
            fits.append(fit_auto(frf).lsfd)
    a, b = fits
    assert a.poles.size == b.poles.size > 0
    np.testing.assert_allclose(b.poles, a.poles, rtol=1e-12, atol=0)
    np.testing.assert_allclose(b.model.residues, a.model.residues, rtol=1e-12, atol=1e-12 * np.abs(a.model.residues).max())


_START = """
import os, sys
from analysis.threads import load_blas_single_threaded
load_blas_single_threaded()
import numpy
from threadpoolctl import threadpool_info
from analysis.threads import use_threads, blas_threads
counts = sorted({int(i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"})
with use_threads(2), blas_threads(0) as n:
    raised = sorted({int(i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"})
print(counts, raised, os.environ.get("OPENBLAS_NUM_THREADS"))
"""


@pytest.mark.parametrize("user, expected", [(None, "[1] [2] None"), ("2", "[2] [2] 2")])
def test_commands_load_blas_single_threaded_and_kernels_raise_it(user, expected):
    """``python -m analysis`` loads numpy's BLAS on one thread (the environment restored after the
    import), a kernel still raises the count (here the user's ``--threads 2``); a BLAS thread count
    the user set is left alone."""
    import os

    env = {k: v for k, v in os.environ.items() if k not in threads.BLAS_ENV_VARS}
    if user is not None:
        env["OPENBLAS_NUM_THREADS"] = user
    out = subprocess.run([sys.executable, "-c", _START], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == expected


def test_physical_causes_fork_one_process_per_core_unless_the_user_says_otherwise(monkeypatch):
    """The physical diagnosis' default (processes=None): one forked process per core this process may run
    on (at most one per cause), one with ``IMPACTLAB_THREADS=1`` (as the suite sets it) or ``--threads 1``."""
    import threading

    from analysis.diagnosis.physical import _cause_processes

    monkeypatch.delenv(ENV_VAR, raising=False)
    alone = threading.active_count() == 1          # a process with other threads never forks (their locks)
    assert _cause_processes(9, None) == (min(threads._cores(), 9) if alone else 1)
    assert _cause_processes(9, 2) == 2 and _cause_processes(1, None) == 1
    monkeypatch.setenv(ENV_VAR, "1")
    assert _cause_processes(9, None) == 1
    monkeypatch.setenv(ENV_VAR, "auto")
    with use_threads(1):
        assert _cause_processes(9, None) == 1
