"""Shared fixtures. Real measured data lives in ../shared/data and is never committed."""
from __future__ import annotations

import os
import sys
from pathlib import Path

# The tests solve many small linear-algebra problems; threaded OpenBLAS on the shared 2-core
# machine is 10-100x slower for them under contention. Must be set before numpy is imported.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# The physical diagnosis fits its causes in one forked process per core unless the user's thread count says
# otherwise (analysis.threads.worker_processes). `make test` already keeps both cores busy with its
# processes: the forks there gain no time and cost about a tenth more CPU (the forks' start and copies, the
# fits' results sent back), so the suite asks for one. The forked fits are tested by name
# (tests/test_ritz.py, processes=2) and the default by tests/test_threads.py, which unset the variable.
os.environ.setdefault("IMPACTLAB_THREADS", "1")

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: the real measurements (IMPACTLAB_SHARED_DATA overrides, e.g. from a git worktree elsewhere)
SHARED_DATA = Path(os.environ.get("IMPACTLAB_SHARED_DATA", ROOT.parent / "shared" / "data"))


@pytest.fixture
def shared_data() -> Path:
    """Path to ../shared/data; skips the test when the folder is absent (fresh clone elsewhere)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real measured data not found at {SHARED_DATA} (only present in the workplace)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def report_case(tmp_path_factory) -> dict:
    """The report tests' small simulated test, its fit and report folders (tests/report_data.py), made once
    per test session whichever process of ``make test`` asks first (shared: read it, do not change it)."""
    from report_data import make_report_case, report_case_in

    folder = _shared_folder(tmp_path_factory, "report-case")
    _once(folder / "done", lambda: make_report_case(folder))
    return report_case_in(folder)


@pytest.fixture(scope="session")
def sim_capture(tmp_path_factory):
    """``sim_capture(*capture_args)``: the path of a recording that ``acquisition capture`` wrote on the
    simulated analyser with those arguments (``--device sim://...``, ``--points``, ``--hits``...; ``--out``
    and ``-q`` are added). Each set of arguments is captured once per test session, whichever process
    of ``make test`` asks first (the others wait for it and reuse the file). The file is shared: read
    it, or copy it before changing it."""
    import contextlib
    import hashlib
    import io

    folder = _shared_folder(tmp_path_factory, "sim-captures")

    def capture(*args: str) -> Path:
        from acquisition.cli_capture import main

        name = hashlib.sha256("\0".join(args).encode()).hexdigest()[:16]
        path = folder / f"{name}.h5"

        def make() -> None:
            tmp = folder / f"{name}.partial.h5"
            with contextlib.redirect_stdout(io.StringIO()):
                code = main([*args, "--out", str(tmp), "-q"])
            assert code == 0, f"capture {' '.join(args)} failed"
            os.replace(tmp, path)

        _once(path, make)
        return path

    return capture


def _shared_folder(tmp_path_factory: pytest.TempPathFactory, name: str) -> Path:
    """A folder of this test session that every process of ``make test`` sees (the workers' common parent)."""
    shared = tmp_path_factory.getbasetemp().parent if _xdist_worker() else tmp_path_factory.getbasetemp()
    folder = shared / name
    folder.mkdir(exist_ok=True)
    return folder


def _once(done: Path, make) -> None:
    """``make()`` unless ``done`` exists (``make`` creates it last), by one process: the others wait for it."""
    import fcntl

    with open(done.with_name(done.name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            make()


#: a roving-hammer capture on the simulated frame: 2 points x 3 hits, exponential window 5 % (``sim_capture``)
TWO_POINTS_EXP = ("--device", "sim://", "--seed", "3", "--points", "right:6:-X,top:4:Z", "--hits", "3", "--auto",
                  "--exp-window", "5%")


def _xdist_worker() -> bool:
    return bool(os.environ.get("PYTEST_XDIST_WORKER"))


# --- how `make test` shares the suite between processes (pytest-xdist, --dist loadfile) ---
# A test file is one unit of work, kept on one process (its module fixtures are made once), except
# the files of SPREAD: their tests are heavy and independent (no costly module fixture), so each
# test is a unit of its own and the processes share them. The units are handed out heaviest
# first (the SPREAD tests, then the files of HEAVY in its order, heaviest first, then the rest in
# file order) and the light files fill in behind, so the processes end together. Only the
# speed depends on these lists.
SPREAD = ("test_diagnosis_blind.py", "test_diagnosis_physical.py", "test_importers_fuzz.py",
          "test_recording_fuzz.py", "test_crash_safety.py", "test_station_resume.py",
          "test_diagnosis_frf_beam.py", "test_diagnosis_frf_mass.py", "test_diagnosis_physical_verdict.py",
          "test_diagnosis_frame_untuned.py", "test_diagnosis_pairs_one_kind.py",
          "test_diagnosis_pair_search.py", "test_diagnosis_one_place.py", "test_realdata_key.py")
HEAVY = ("test_examples_run.py", "test_diagnosis_pair_counts.py", "test_batch_dask.py", "test_batch_diagnose.py",
         "test_station_browser.py",                     # not spread: one Chromium (its module fixture) for both tests
         "test_station_api.py", "test_disk_full.py", "test_fuzz_protocol.py", "test_faults.py", "test_diagnosis_cli.py")


def pytest_collection(session: pytest.Session) -> None:
    config = session.config
    tests = Path(__file__).resolve().parent
    here = config.invocation_params.dir
    if _xdist_worker() and any((here / a.split("::")[0]).resolve() in (tests, tests.parent) for a in config.args):
        worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:] or 0)
        rewrite_in_turn(config, sorted(tests.glob("test_*.py")), worker,
                        int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))


def rewrite_in_turn(config: pytest.Config, files: list[Path], worker: int, workers: int) -> int:
    """pytest rewrites a test module's asserts on its first import and keeps the result (a pyc in __pycache__).
    In a fresh clone every process of ``make test`` would rewrite all the test modules (about 4 s of CPU each):
    before collecting the whole tests folder, process ``worker`` of ``workers`` rewrites ``files`` starting at
    its own share of them, so a file is rewritten about once and the others read its pyc (written whole:
    pytest's own atomic write). A pyc newer than its source is left alone. Returns the count rewritten. Only
    the speed depends on it: pytest's import still checks every pyc against its source (pytest's internals:
    without them, nothing is done here; a file pytest cannot rewrite is left to pytest, which reports it)."""
    try:
        from _pytest.assertion.rewrite import (
            PYC_TAIL,
            _rewrite_test,
            _write_pyc,
            assertstate_key,
            get_cache_dir,
            try_makedirs,
        )
    except ImportError:
        return 0
    if sys.dont_write_bytecode or config.getoption("assertmode") != "rewrite" or not files:
        return 0
    start = len(files) * worker // max(1, workers)
    state = config.stash[assertstate_key]
    done = 0
    for fn in files[start:] + files[:start]:
        cache = get_cache_dir(fn)
        pyc = cache / (fn.name[:-3] + PYC_TAIL)
        if pyc.exists() and pyc.stat().st_mtime >= fn.stat().st_mtime:
            continue
        try:
            if not try_makedirs(cache):
                return done
            source_hash, co = _rewrite_test(fn, config)
            _write_pyc(state, co, source_hash, pyc)
        except (SyntaxError, ValueError, OSError):
            continue
        except (TypeError, AttributeError, KeyError):   # pytest's internals changed: leave it all to pytest
            return done
        done += 1
    return done


def _file(nodeid: str) -> str:
    return nodeid.split("::")[0].rsplit("/", 1)[-1]


def _rank(nodeid: str) -> tuple[int, int]:
    name = _file(nodeid)
    return (0, 0) if name in SPREAD else (1, HEAVY.index(name)) if name in HEAVY else (2, 0)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if hasattr(config, "workerinput"):                 # an xdist worker: the order the units are handed out
        items.sort(key=lambda item: _rank(item.nodeid))    # stable: the files keep their order


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object:
    """--dist loadfile with the SPREAD files' tests as units of their own, in collection order."""
    if config.getoption("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class SpreadScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return nodeid if _file(nodeid) in SPREAD else super()._split_scope(nodeid)

    config.option.loadscopereorder = False             # the order above, not by the files' test counts
    return SpreadScheduling(config, log)
