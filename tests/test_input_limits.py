"""Every input file is read with a bound: a FIFO or a character device (``/dev/zero``) given as a file
is refused at once (never a wait, never an endless read), a file beyond its kind's size is refused
before it is read, each with one line naming the option and the limit. The work an input asks for is
bounded before it starts: given poles by the band's lines, a diagnosis's FE model by what a diagnosis
allocates, a simulator configuration's numbers by clear ranges."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
OUTS = ("left:9:Y", "top:4:X", "right:6:-X")
REF = "right:6:-X"


def _frf(f_hi: float = 40.0, n: int = 80):
    from analysis.frf import FRFSet
    from analysis.modal import ModalModel, pole_from_fz, synthesize

    f = np.linspace(1.0, f_hi, n)
    poles = pole_from_fz(np.array([0.3, 0.6]) * f_hi, np.array([0.01, 0.01]))
    R = np.array([[[1.0, 0.5]], [[0.4, -1.0]], [[0.8, 0.3]]]) * poles.imag / 2j
    H = synthesize(ModalModel(poles, R, quantity="accelerance", residual_form="none"), f).H
    return FRFSet(f, H, "accelerance", OUTS, (REF,), "(m/s^2)/N", None, None, {})


@pytest.fixture(scope="module")
def uff(tmp_path_factory) -> Path:
    from analysis.uff import write_uff58

    p = tmp_path_factory.mktemp("lim") / "in.uff"
    write_uff58(p, _frf())
    return p


@pytest.fixture
def fifo(tmp_path) -> Path:
    p = tmp_path / "pipe.json"
    os.mkfifo(p)
    return p


def _readers() -> list[tuple[str, Callable[[Path], object], str]]:
    """(what the message names, reader of one path, the limit it gives)."""
    from acquisition.importers import load_description, read_lvm
    from acquisition.setup import load_setup
    from analysis.batch.unit_modes import read_reference
    from analysis.geometry import read_uff_geometry
    from analysis.picks import read_picks
    from analysis.report_html.sources import load_diagnosis, load_fit_json
    from analysis.sep005 import read_sep005
    from simulator.config import FrameConfig
    from simulator.serve import firmware_factory

    return [("--poles file", read_picks, "4 MiB"),
            ("--fit file", lambda p: load_fit_json(p, _frf()), "256 MiB"),
            ("--diagnosis file", load_diagnosis, "256 MiB"),
            ("--reference file", read_reference, "256 MiB"),
            ("set-up file (--setup)", load_setup, "4 MiB"),
            ("description (--describe)", load_description, "4 MiB"),
            ("config file", FrameConfig.load, "4 MiB"),
            (".lvm file", read_lvm, "at most"),
            ("SEP005 file", read_sep005, "at most"),
            ("--geometry file", read_uff_geometry, "at most"),
            ("--precomputed file", lambda p: firmware_factory({}, str(p)), "at most")]


@pytest.mark.timeout(30)
@pytest.mark.parametrize("k", range(11))
def test_a_fifo_is_refused_at_once_naming_the_option_and_the_limit(fifo, k):
    from analysis.errors import ImpactlabError

    what, read, limit = _readers()[k]
    with pytest.raises(ImpactlabError) as err:
        read(fifo)  # the old readers blocked here, waiting for a writer
    msg = str(err.value)
    assert f"{what} {fifo} is a FIFO (named pipe), not a regular file" in msg and limit in msg
    assert "\n" not in msg


#: reads /dev/zero with every reader in a child process whose memory is capped (an endless read ends in
#: MemoryError there, never in this test process) and prints what each reader said
_DEV_ZERO_CHILD = """
import json, resource, sys
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, resource.getrlimit(resource.RLIMIT_AS)[1]))
sys.path.insert(0, sys.argv[1])
from pathlib import Path
from test_input_limits import _readers
said = []
for what, read, limit in _readers():
    try:
        read(Path("/dev/zero"))
        said.append([what, "read without error"])
    except MemoryError:
        said.append([what, "MemoryError: read without end"])
    except Exception as exc:
        said.append([what, str(exc)])
print(json.dumps(said))
"""


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero on this system")
def test_dev_zero_is_refused_instead_of_read_forever():
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, "-c", _DEV_ZERO_CHILD, str(ROOT / "tests")], capture_output=True, text=True,
                         timeout=120, env=env, cwd=ROOT)
    assert run.returncode == 0, run.stderr[-2000:]
    said = json.loads(run.stdout.splitlines()[-1])
    assert [w for w, _ in said] == [w for w, _, _ in _readers()]
    for (what, msg), (_, _, limit) in zip(said, _readers()):
        assert msg.startswith(f"{what} /dev/zero is a character device, not a regular file: give a regular file of "
                              "at most"), msg
        assert limit in msg


@pytest.mark.timeout(60)
def test_commands_refuse_a_fifo_in_one_line(tmp_path, fifo, uff):
    (tmp_path / "d.json").write_text(json.dumps({"sample_rate_hz": 1000, "channels": [{"name": "f", "unit": "N"}]}))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    for cmd, says in ((["analysis", "fit", str(uff), "--poles", str(fifo)], "--poles file"),
                      (["analysis", "batch", str(fifo), "--out", str(tmp_path / "b")], f"input {fifo} is a FIFO"),
                      (["acquisition", "import", str(fifo), "--format", "npy", "--describe", str(tmp_path / "d.json"),
                        "--out", str(tmp_path / "x.h5")], "input file (npy)"),
                      (["acquisition", "capture", "--device", "sim://", "--setup", str(fifo), "--out",
                        str(tmp_path / "c.h5")], "set-up file (--setup)")):
        run = subprocess.run([sys.executable, "-m", *cmd], capture_output=True, text=True, timeout=50, env=env,
                             cwd=tmp_path)
        assert run.returncode == 2, (cmd, run.stderr)
        assert says in run.stderr and "FIFO" in run.stderr and run.stderr.count("\n") == 1, run.stderr
        assert not (tmp_path / "x.h5").exists() and not (tmp_path / "c.h5").exists()


def test_a_file_beyond_its_limit_is_refused_before_it_is_read(tmp_path, monkeypatch):
    from acquisition.errors import ImportDataError
    from acquisition.importers import read_lvm
    from analysis import work_limits
    from analysis.inputs import InputError
    from analysis.picks import read_picks

    poles = tmp_path / "poles.txt"
    poles.write_bytes(b"12.5\n" + b" " * (4 << 20))
    with pytest.raises(InputError, match=r"--poles file .* holds 4 MiB, more than the 4 MiB accepted"):
        read_picks(poles)
    # a text data file: a 16th of the memory one computation may use (here 32 KiB of 512 KiB)
    monkeypatch.setattr(work_limits, "available_memory_bytes", lambda: 2 * 512 * 1024)
    lvm = tmp_path / "big.lvm"
    lvm.write_text("LabVIEW Measurement\t\n" + "0\t0\n" * 20000)
    with pytest.raises(ImportDataError, match=r"\.lvm file .* holds 78\.1 KiB, more than the 32 KiB accepted"):
        read_lvm(lvm)


# -- the work an input asks for -----------------------------------------------------------------
def test_given_poles_beyond_the_bands_lines_are_refused_before_any_work(monkeypatch):
    from analysis import pipeline
    from analysis.work_limits import WorkLimitError

    def no_stabilization(*a, **k):
        raise AssertionError("stabilization ran for poles the band cannot carry")

    monkeypatch.setattr(pipeline, "stabilization", no_stabilization)
    with pytest.raises(WorkLimitError) as err:
        pipeline.fit_auto(_frf(), band=(1.0, 40.0), initial=np.linspace(2.0, 38.0, 20000))
    assert str(err.value) == ("the given poles: 20000 modes in the band 1..40 Hz is too large: the band holds 80 "
                              "lines; the largest accepted here is 39 (or widen the band)")


def test_fit_with_20000_picked_poles_ends_at_once(tmp_path, uff, capsys):
    from analysis.cli_fit import main

    picks = tmp_path / "picks.json"
    picks.write_text(json.dumps({"schema": "impactlab.poles/1", "band_hz": [1.0, 40.0],
                                 "poles": [{"freq_hz": 2.0 + 0.0018 * i, "damping": 0.01} for i in range(20000)]}))
    assert main([str(uff), "--poles", str(picks)]) == 2
    err = capsys.readouterr().err
    assert "20000 modes in the band 1..40 Hz is too large" in err and "largest accepted here is 39" in err
    assert err.count("\n") == 1


def test_fit_poles_messages_say_plain_numbers_and_the_band_used(tmp_path, uff, capsys):
    from analysis.cli_fit import main
    from analysis.selection import poles_from_frequencies

    picks = tmp_path / "picks.json"
    picks.write_text(json.dumps({"schema": "impactlab.poles/1", "band_hz": [300, 400], "poles": [{"freq_hz": 12.0}]}))
    assert main([str(uff), "--poles", str(picks)]) == 2
    err = capsys.readouterr().err
    assert "band 300..400 Hz (the band the --poles file" in err and "lies outside the data (1..40 Hz)" in err
    assert "None" not in err
    picks.write_text(json.dumps({"schema": "impactlab.poles/1", "poles": [{"freq_hz": 5e-324, "damping": 0.999}]}))
    assert main([str(uff), "--poles", str(picks)]) == 2
    err = capsys.readouterr().err
    assert "pole 1: freq_hz 4.94066e-324 Hz with damping 0.999 gives no oscillation" in err
    assert "np.float64" not in err
    with pytest.raises(ValueError) as verr:
        poles_from_frequencies(np.array([-3e-323]))
    assert str(verr.value) == "frequencies must be positive numbers in Hz; got -2.96439e-323 Hz"


def _measured(tmp_path: Path) -> Path:
    from analysis.uff import write_uff58

    p = tmp_path / "m.uff"
    write_uff58(p, _frf(150.0, 300))
    return p


def test_diagnose_judges_the_fe_size_by_what_a_diagnosis_allocates(tmp_path, monkeypatch, capsys):
    from analysis import work_limits
    from analysis.cli_diagnose import main
    from simulator import physical
    from simulator.config import FE_BYTES_PER_DOF2, FrameConfig

    budget = 600 * 2**20
    monkeypatch.setattr(work_limits, "available_memory_bytes", lambda: 2 * budget)
    cfg = tmp_path / "fine.toml"
    cfg.write_text("[components.left]\nn_elements = 100\n[components.right]\nn_elements = 100\n"
                   "[components.top]\nn_elements = 80\n")
    n_dof = 6 * (280 + 3)
    assert FE_BYTES_PER_DOF2 * n_dof**2 < budget < physical.DIAGNOSIS_BYTES_PER_DOF2 * n_dof**2
    FrameConfig.load(cfg)  # one model fits: the frame itself is accepted

    def built(*a, **k):
        raise AssertionError("the diagnosis built its models before judging their size")

    monkeypatch.setattr(physical.FrameVariants, "__init__", built)
    assert main(["--measured", str(_measured(tmp_path)), "--simulated", str(cfg), "--json",
                 str(tmp_path / "d.json")]) == 2
    err = capsys.readouterr().err
    assert "280 elements" in err and "for a diagnosis" in err and err.count("\n") == 1
    largest = int(err.rsplit("largest accepted total here is ", 1)[1].split()[0])
    per = physical.DIAGNOSIS_BYTES_PER_DOF2
    assert per * (6 * (largest + 3)) ** 2 <= budget < per * (6 * (largest + 4)) ** 2
    assert not (tmp_path / "d.json").exists()


@pytest.mark.parametrize("text, pattern", [
    ("[modes]\nmax_freq_hz = 1e300\n", r"modes\.max_freq_hz = 1e\+300 must be in \[1, 1e\+06\] Hz"),
    ("[modes]\nmax_freq_hz = 1e-300\n", r"modes\.max_freq_hz = 1e-300 must be in \[1, 1e\+06\] Hz"),
    ("[components.left]\nend_m = [0.0, 0.0, 1e20]\n", r"components\.left: start_m and end_m must be numbers within "
                                                      r"\+-1000 m"),
    ("[supports]\nstiffness = [1e300, 1e9, 1e9, 1e6, 1e6, 1e6]\n", r"supports\.stiffness\[0\] = 1e\+300 is beyond "
                                                                   r"the 1e\+20 accepted"),
    ("[supports]\nstiffness = [0, 0, 0, 0, 0, 0]\n", r"\[supports\] holds the frame in no direction"),
    ("[supports]\nnodes = []\n", r"\[supports\] holds the frame in no direction"),
])
def test_simulator_config_numbers_have_clear_bounds(tmp_path, text, pattern):
    from simulator.config import ConfigError, FrameConfig

    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=pattern):
        FrameConfig.load(p)


def test_diagnose_with_an_absurd_max_freq_is_one_line(tmp_path, capsys):
    from analysis.cli_diagnose import main

    cfg = tmp_path / "c.toml"
    cfg.write_text("[modes]\nmax_freq_hz = 1e300\n")
    assert main(["--measured", str(_measured(tmp_path)), "--simulated", str(cfg), "--json",
                 str(tmp_path / "d.json")]) == 2
    err = capsys.readouterr().err
    assert "modes.max_freq_hz = 1e+300 must be in [1, 1e+06] Hz" in err and err.count("\n") == 1


def test_a_frame_that_moves_freely_is_refused_naming_the_supports(tmp_path):
    from simulator.fem import ModelError
    from simulator.physical import FrameVariants

    p = tmp_path / "c.toml"  # pinned bases and hinged joints: a mechanism, no LAPACK message
    p.write_text("[supports]\nstiffness = [1e9, 1e9, 1e9, 0, 0, 0]\n[joints]\nstiffness = [1e9, 1e9, 1e9, 0, 0, 0]\n")
    frame = FrameVariants(p, list(OUTS), [REF])
    with pytest.raises(ModelError, match=r"stiffness matrix is singular.*give \[supports\] nodes and stiffness"):
        frame.modes("added_mass", {"point": "top:4", "mass_kg": 1.0}, 500.0)


def test_block_size_is_checked_on_its_own_before_the_windows(tmp_path, capsys):
    from acquisition.cli_capture import main
    from acquisition.errors import SetupError
    from acquisition.setup import default_setup, load_setup, setup_to_toml

    text = setup_to_toml(default_setup())
    assert "block_size = 8192" in text
    for bad in ("2", "0", "2.5"):
        p = tmp_path / f"s{bad}.toml"
        p.write_text(text.replace("block_size = 8192", f"block_size = {bad}"))
        with pytest.raises(SetupError, match=rf"set-up block_size = {bad} must be a whole number of samples above "
                                             r"the trigger's pretrigger_samples \(\d+\)"):
            load_setup(p)
    assert main(["--device", "sim://", "--setup", str(tmp_path / "s2.toml"), "--out", str(tmp_path / "r.h5"),
                 "--hits", "1", "--auto"]) == 2
    err = capsys.readouterr().err
    assert "block_size = 2" in err and "window" not in err and not (tmp_path / "r.h5").exists()
