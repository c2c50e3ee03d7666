"""Every example a user is shown runs as written: each fenced Python block of README.md and docs/,
and each example line at the end of every command's ``--help`` (:data:`analysis.command_examples.EXAMPLES`,
the README's tour says the same).

They run in one temporary folder (shared by the module, like a user's working folder) holding a
recording made first by the first ``capture`` example itself; the other files an example reads are
made on demand by :data:`MAKERS` (a second recording, its UFF export, a MATLAB file, a soft and a hard
test, a small fleet, ...). The few examples that cannot run here are listed in :data:`SPECIAL` with the
reason: a server that runs until stopped, a device that is not attached, a remote Dask scheduler, or
an example too long for the suite (run with smaller options). Examples that read the real measurements
in ``../shared/data`` skip when the folder is absent.
"""
from __future__ import annotations

import contextlib
import glob
import os
import re
import shlex
import shutil
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from conftest import SHARED_DATA

from analysis.command_examples import EXAMPLES
from impactlab import COMMANDS
from impactlab import main as impactlab

ROOT = Path(__file__).resolve().parents[1]
FIRST_CAPTURE = EXAMPLES["python -m acquisition capture"][0]

#: examples that cannot run as written in the suite -> (what runs instead, why). ``None``: the line
#: is only parsed by the command's own parser (its options must exist and be valid).
SPECIAL: dict[str, tuple[str | None, str]] = {
    EXAMPLES["python -m acquisition capture"][1]: (
        "SERVED", "needs an analyser at socket://127.0.0.1:5025: run against 'serve --tcp' with key presses on stdin"),
    EXAMPLES["python -m acquisition identify"][1]: (
        "NO_DEVICE", "needs a USB analyser attached: must fail with a one-line 'no USB device' message (without libusb 'no USB backend'), exit 1"),
    EXAMPLES["python -m acquisition station"][0]: (None, "serves the operator page until stopped"),
    EXAMPLES["python -m acquisition station"][1]: (None, "serves the operator page until stopped"),
    EXAMPLES["python -m simulator serve"][0]: ("SERVE", "serves until stopped: started, its URL read, stopped"),
    EXAMPLES["python -m simulator serve"][1]: (None, "serves a pseudo-terminal until stopped"),
    EXAMPLES["python -m simulator fleet"][0]: (
        "fleet --units 4 --out fleet/ --scatter 2 --defects 1 --seed 1 --hits 2 --jobs 1",
        "200 units take minutes: 4 units, 2 hits each, in this process"),
    EXAMPLES["python -m analysis batch"][0]: (
        "CHILD", "a local Dask cluster: run in a child process, as every Dask test does (a process that has used a "
                 "Dask client keeps its threads, and analysis._isolated forks its readers only from a single-threaded "
                 "process: the rest of the session would start each isolated read as a new interpreter)"),
    EXAMPLES["python -m analysis batch"][1]: (None, "needs a Dask scheduler at tcp://10.0.0.5:8786"),
}


def _expanded(line: str) -> list[str]:
    """The arguments of ``line`` after the shell's glob expansion."""
    expanded: list[str] = []
    for a in shlex.split(line, comments=True):
        expanded.extend(sorted(glob.glob(a)) or [a] if "*" in a else [a])
    return expanded


def _run(line: str) -> tuple[int, str]:
    """``impactlab LINE`` in this process, with the shell's glob expansion; (exit code, stdout+stderr)."""
    expanded = _expanded(line)
    out, err = _Capture(), _Capture()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):  # type: ignore[type-var]
        try:
            code = impactlab(expanded)
        except SystemExit as exc:  # argparse's own exit, as the shell would see it
            code = exc.code if isinstance(exc.code, int) else 1
    return code, out.getvalue() + err.getvalue()


class _Capture:
    """A text sink for redirect_stdout that commands may query like a terminal's stream."""

    def __init__(self) -> None:
        self.parts: list[str] = []

    def write(self, s: str) -> int:
        self.parts.append(s)
        return len(s)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False

    def getvalue(self) -> str:
        return "".join(self.parts)


def _ok(line: str) -> str:
    code, text = _run(line)
    assert code == 0 and "Traceback" not in text, f"impactlab {line}: exit {code}\n{text[-3000:]}"
    return text


def _sim_capture(url: str, out: str) -> None:
    _ok(f'capture --device "{url}" --out {out} --hits 3 --points right:6:-X --auto -q')


def _mat_file(name: str) -> None:
    """A DataPhysics .mat export (X1 force in N, X2 response in g) of the recording's first hit."""
    import scipy.io

    from analysis.recording import Recording

    with Recording("rec.h5") as rec:
        hit = rec.hit(0)
        data, fs, trig = hit.data, hit.sample_rate_hz, hit.trigger_index
    t = (np.arange(data.shape[1]) - trig) / fs
    scipy.io.savemat(name, {"X1": np.column_stack([t, data[0]]), "X2": np.column_stack([t, data[1] / 9.81]),
                            "Sensitivity": np.array([[2.25], [100.0]]), "Unit": np.array(["N", "g"])})


#: input files the examples read -> how they are made (in the work folder)
MAKERS: dict[str, Callable[[], object]] = {
    "simulator/frame.toml": lambda: (Path("simulator").mkdir(exist_ok=True),
                                     shutil.copy(ROOT / "simulator" / "frame.toml", "simulator/frame.toml")),
    "my_frame.toml": lambda: shutil.copy(ROOT / "simulator" / "frame.toml", "my_frame.toml"),
    "rec.uff": lambda: _ok("export rec.h5 --uff rec.uff"),
    "meas.uff": lambda: _ok("export rec.h5 --uff meas.uff"),
    "sim.uff": lambda: (_sim_capture("sim://?seed=2", "sim.h5"), _ok("export sim.h5 --uff sim.uff")),
    "hits.mat": lambda: _mat_file("hits.mat"),
    "soft.h5": lambda: _sim_capture("sim://?seed=3&levels=0.25", "soft.h5"),
    "hard.h5": lambda: _sim_capture("sim://?seed=4", "hard.h5"),
    "low.uff": lambda: _ok("export soft.h5 --uff low.uff"),
    "high.uff": lambda: _ok("export hard.h5 --uff high.uff"),
    "fit.json": lambda: _ok("fit rec.h5 --json fit.json"),
    "diag.json": lambda: _ok("diagnose --measured rec.h5 --simulated sim.uff --json diag.json"),
    "fleet/*.h5": lambda: _ok(SPECIAL[EXAMPLES["python -m simulator fleet"][0]][0] or ""),
    "golden.json": lambda: _ok("fit fleet/unit_0001.h5 --json golden.json"),
    "levels.h5": lambda: _ok(next(line for line in EXAMPLES["python -m acquisition capture"] if "levels.h5" in line)),
}
#: options whose value is written, not read
OUTPUT_OPTIONS = {"--out", "--json", "--uff", "--plot", "--png", "--report"}


def _inputs(line: str) -> list[str]:
    """The files of MAKERS that ``line`` reads (not those it writes)."""
    args = shlex.split(line, comments=True)
    return [a for i, a in enumerate(args) if a in MAKERS and (i == 0 or args[i - 1] not in OUTPUT_OPTIONS)]


#: files a maker itself reads
NEEDS = {"diag.json": ("sim.uff",), "golden.json": ("fleet/*.h5",), "low.uff": ("soft.h5",), "high.uff": ("hard.h5",)}


def _make(name: str) -> None:
    for need in NEEDS.get(name, ()):
        _make(need)
    if not glob.glob(name):
        MAKERS[name]()


def _prepare(line: str) -> None:
    """The inputs ``line`` reads made (:data:`MAKERS`); an output file of ``line`` that another example or a maker
    wrote before is removed first unless ``line`` replaces it (``--overwrite``), so that each example runs as in a
    folder without it whichever order the examples run in (a maker makes it again for a later reader)."""
    for name in _inputs(line):
        _make(name)
    args = shlex.split(line, comments=True)
    if "--overwrite" not in args:
        for i, a in enumerate(args[1:], 1):
            if args[i - 1] in OUTPUT_OPTIONS and Path(a).is_file():
                Path(a).unlink()


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Iterator[dict]:
    """The user's working folder with the recording of the first capture example (its exit code and
    output kept for that example's own test)."""
    folder = tmp_path_factory.mktemp("examples")
    old = Path.cwd()
    os.chdir(folder)
    try:
        code, text = _run(FIRST_CAPTURE)
        yield {"folder": folder, "first_capture": (code, text)}
    finally:
        os.chdir(old)


@pytest.fixture
def in_work(work, monkeypatch) -> Path:
    monkeypatch.chdir(work["folder"])
    monkeypatch.setenv("MPLBACKEND", "Agg")
    return work["folder"]


def _help_examples() -> list[tuple[str, str]]:
    return [(prog, line) for prog, lines in EXAMPLES.items() for line in lines]


def test_every_command_with_examples_is_a_command_and_every_example_names_its_command() -> None:
    names = {prog.split()[-1] for prog in EXAMPLES}
    assert names <= set(COMMANDS), names - set(COMMANDS)
    for prog, line in _help_examples():
        assert line.split()[0] == prog.split()[-1], (prog, line)


def _parse_only(line: str) -> None:
    """The command's own parser accepts the line (an unknown option or bad choice exits 2)."""
    import importlib

    module = importlib.import_module(COMMANDS[line.split()[0]][0])
    build = getattr(module, "build_parser", None) or module._build_parser  # serve keeps its parser private
    build().parse_args(shlex.split(line, comments=True)[1:])


@contextlib.contextmanager
def _served() -> Iterator[str]:
    """``serve --tcp 127.0.0.1:0`` (the serve example) in a child process; yields the URL it prints."""
    serve = subprocess.Popen([sys.executable, "-m", "impactlab", *shlex.split(EXAMPLES["python -m simulator serve"][0],
                                                                               comments=True), "--seed", "5"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert serve.stdout is not None
        first = serve.stdout.readline()
        url = re.search(r"socket://127\.0\.0\.1:\d+", first)
        assert url, first
        yield url.group(0)
    finally:
        serve.terminate()
        serve.communicate(timeout=30)  # reaps it and closes its pipes


@pytest.fixture(scope="module")
def served() -> Iterator[Callable[[], str]]:
    """The URL of the serve example's server (:func:`_served`), started at the first example that asks for it
    and shared by the module's examples: it builds a fresh analyser for each client, so the capture example
    and the serve example's ``identify`` each talk to their own, as with a server of their own."""
    with contextlib.ExitStack() as stack:
        urls: list[str] = []

        def url() -> str:
            if not urls:
                urls.append(stack.enter_context(_served()))
            return urls[0]

        yield url


def _served_capture(line: str, url: str) -> None:
    """The capture example against a served simulated analyser, one Enter per hit on stdin."""
    args = shlex.split(line.replace("socket://127.0.0.1:5025", url).replace("rec.h5", "served.h5"), comments=True)
    res = subprocess.run([sys.executable, "-m", "impactlab", *args], input="\n" * 40, capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert "recording written: served.h5" in res.stdout


@pytest.fixture
def no_thread_left() -> Iterator[None]:
    """The example leaves no thread running in this process: the suite's process stays single-threaded, so
    analysis._isolated forks its isolated readers (a thread left behind, such as Dask's offload thread
    after a Dask client, makes each later isolated read of the session start a new interpreter)."""
    before = set(threading.enumerate())
    yield
    left = [t for t in threading.enumerate() if t not in before]
    for t in left:
        t.join(5.0)                                    # a thread that is ending gets the time to end
    running = [t.name for t in left if t.is_alive()]
    assert not running, f"the example left threads running: {running} (run it in a child process)"


def _usb_backend_present() -> bool:
    """Whether pyusb finds a backend (libusb) on this machine."""
    import usb.backend.libusb0
    import usb.backend.libusb1
    import usb.backend.openusb
    return any(m.get_backend() is not None for m in (usb.backend.libusb1, usb.backend.libusb0, usb.backend.openusb))


@pytest.mark.parametrize(("prog", "line"), _help_examples(), ids=[line for _, line in _help_examples()])
def test_every_help_example_runs(in_work: Path, work: dict, served: Callable[[], str], no_thread_left: None, prog: str,
                                 line: str) -> None:
    if line == FIRST_CAPTURE:
        code, text = work["first_capture"]
        assert code == 0 and (in_work / "rec.h5").is_file(), text[-3000:]
        return
    if "../shared/data" in line:
        if not SHARED_DATA.is_dir():
            pytest.skip(f"needs the real measurements at {SHARED_DATA}")
        line = line.replace("../shared/data", str(SHARED_DATA))
    instead, _why = SPECIAL.get(line, (line, ""))
    if instead is None:
        _parse_only(line)
    elif instead == "SERVED":
        _served_capture(line, served())
    elif instead == "NO_DEVICE":
        code, text = _run(line)
        # without libusb on the machine pyusb has no backend at all: the one-line error says so instead
        expected = "no USB device" if _usb_backend_present() else "no USB backend"
        assert code == 1 and expected in text and "Traceback" not in text, text
    elif instead == "SERVE":
        _ok(f"identify --device {served()}")
    elif instead == "CHILD":
        _prepare(line)
        res = subprocess.run([sys.executable, "-m", "impactlab", *_expanded(line)], capture_output=True, text=True,
                             timeout=240)
        assert res.returncode == 0 and "Traceback" not in res.stderr, res.stdout[-2000:] + res.stderr[-2000:]
    else:
        _prepare(instead)
        _ok(instead)


def _python_blocks() -> list[tuple[str, int, str]]:
    """(file, line number, code) of every fenced Python block of README.md and docs/."""
    out = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        text = path.read_text()
        for m in re.finditer(r"^```python\n(.*?)^```", text, flags=re.S | re.M):
            out.append((str(path.relative_to(ROOT)), text.count("\n", 0, m.start()) + 1, m.group(1)))
    return out


def test_the_docs_have_python_examples() -> None:
    files = {f for f, _, _ in _python_blocks()}
    assert {"README.md", "docs/fitting.md", "docs/recording-format.md", "docs/diagnosis.md"} <= files, files


@pytest.mark.parametrize(("doc", "lineno", "code"), _python_blocks(), ids=[f"{f}:{n}" for f, n, _ in _python_blocks()])
def test_every_python_example_of_the_docs_runs(in_work: Path, doc: str, lineno: int, code: str) -> None:
    if doc == "README.md":
        pytest.skip("the README's example runs in tests/test_readme_api.py, which also checks its results")
    if "shared/data" in code:
        if not SHARED_DATA.is_dir():
            pytest.skip(f"needs the real measurements at {SHARED_DATA}")
        code = code.replace("../shared/data", str(SHARED_DATA))
    for name in ("run.h5", "test.h5"):  # the docs' names for a recording: the capture made first
        if not Path(name).exists():
            os.symlink("rec.h5", name)
    _prepare(" ".join(sorted(n for n in MAKERS if n in code)))
    scope: dict = {"__name__": "__example__"}
    exec(compile(code, f"{doc}:{lineno}", "exec"), scope)  # noqa: S102 - our own documentation
