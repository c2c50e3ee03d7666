"""Command-line conventions: one installed ``impactlab`` command, ``--version``, ``devices``, and
output into a closed pipe (``... | head``) that neither fails the command nor stops it writing files."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from acquisition.discovery import list_doors, list_usb
from impactlab import COMMANDS, main

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def test_impactlab_has_every_subcommand_of_the_three_packages(capsys) -> None:
    from acquisition.__main__ import COMMANDS as ACQ
    from analysis.__main__ import COMMANDS as ANA
    from simulator.__main__ import COMMANDS as SIM

    assert set(COMMANDS) == set(ACQ) | set(ANA) | set(SIM)
    assert len(COMMANDS) == len(ACQ) + len(ANA) + len(SIM)  # no name hides another
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in COMMANDS)
    assert main(["nonsense"]) == 2


def test_the_installed_console_script_runs_and_prints_its_version() -> None:
    exe = BIN / "impactlab"
    if not exe.exists():
        pytest.skip(f"{exe} not installed (pip install -e . creates it)")
    out = subprocess.run([str(exe), "--version"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.startswith("impactlab (impactlab) ")
    for pkg in ("acquisition", "analysis", "simulator"):
        res = subprocess.run([sys.executable, "-m", pkg, "--version"], capture_output=True, text=True, timeout=60)
        assert res.returncode == 0 and "impactlab" in res.stdout


def test_devices_lists_the_simulated_doors_and_a_usb_analyser_through_pyusb() -> None:
    from simulator.usb_backend import SimUsbBackend

    urls = [e.url for e in list_doors()]
    assert "sim://" in urls and "usbsim://" in urls
    entries, note = list_usb(SimUsbBackend(options={"seed": 1}))
    assert note is None
    assert [e.url.split("/")[2] for e in entries] == ["1209:0001"] and entries[0].kind == "usb"


def test_devices_json(capsys) -> None:
    from acquisition.cli_devices import main as devices

    assert devices(["--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert {"sim://", "usbsim://"} <= {d["url"] for d in doc["devices"]}


def _closed_pipe_run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """Run a command whose stdout reader has gone before it writes anything (as ``| head`` after
    its lines): every write meets EPIPE, whatever the timing."""
    proc = subprocess.Popen(args, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    proc.stdout.close()
    _, err = proc.communicate(timeout=300)
    return subprocess.CompletedProcess(args, proc.returncode, "", err)


def test_output_into_a_closed_pipe_still_writes_the_json_and_exits_0(tmp_path: Path) -> None:
    from acquisition.cli_capture import main as capture_main

    rec = tmp_path / "rec.h5"  # the recording is made in-process: the pipe is the fit's and identify's
    assert capture_main(["--device", "sim://?seed=2", "--out", str(rec), "--hits", "2", "--points", "right:6:-X",
                         "--auto", "-q"]) == 0
    res = _closed_pipe_run([sys.executable, "-m", "analysis", "fit", str(rec), "--json", str(tmp_path / "f.json"),
                            "--band", "4:215"], tmp_path)
    assert res.returncode == 0, res.stderr
    assert "BrokenPipe" not in res.stderr and "Traceback" not in res.stderr
    assert json.loads((tmp_path / "f.json").read_text())["poles"]
    ident = _closed_pipe_run([sys.executable, "-m", "acquisition", "identify", "--device", "sim://?seed=1", "--json"],
                             tmp_path)
    assert ident.returncode == 0 and "Traceback" not in ident.stderr, ident.stderr


@pytest.mark.parametrize("command", [["impactlab", "--help"], ["analysis", "--help"], ["impactlab", "--version"]])
def test_the_command_lists_into_a_closed_pipe_exit_cleanly(tmp_path: Path, command: list[str]) -> None:
    res = _closed_pipe_run([sys.executable, "-m", *command], tmp_path)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr


def test_the_same_bad_url_gives_the_same_exit_code_everywhere(tmp_path, capsys):
    """A bad device URL is a usage error (exit 2) in identify as in capture."""
    from acquisition.cli_capture import main as capture_main
    from acquisition.cli_identify import main as identify_main

    assert identify_main(["--device", "bogus://x"]) == 2
    assert capture_main(["--device", "bogus://x", "--out", str(tmp_path / "x.h5"), "--auto"]) == 2
    err = capsys.readouterr().err
    assert err.count("invalid device URL 'bogus://x'") == 2


def test_every_command_takes_v_and_q_and_q_keeps_output_short(tmp_path, capsys):
    """-v/-q on all commands; -q prints no progress and no per-note lines."""
    import contextlib
    import importlib
    import io

    from acquisition.__main__ import COMMANDS as ACQ
    from analysis.__main__ import COMMANDS as ANA
    from simulator.__main__ import COMMANDS as SIM

    for name, (module, _) in {**ACQ, **ANA, **SIM}.items():
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            try:
                importlib.import_module(module).main(["--help"])
            except SystemExit:
                pass
        text = buf.getvalue()
        assert "-v, --verbose" in text and "-q, --quiet" in text, name
    from acquisition.cli_capture import main as capture_main
    from analysis.cli_fit import main as fit_main

    rec = tmp_path / "r.h5"
    assert capture_main(["--device", "sim://?seed=4", "--out", str(rec), "--hits", "2", "--auto", "-q"]) == 0
    capsys.readouterr()
    assert fit_main([str(rec)]) == 0
    loud = capsys.readouterr()
    assert "... fit: stabilization" in loud.err and "note: " in loud.err
    assert fit_main([str(rec), "-q"]) == 0
    quiet = capsys.readouterr()
    assert "... fit:" not in quiet.err and "note: " not in quiet.err
    assert len(quiet.err.splitlines()) <= 2 and "pole I " in quiet.out
