"""The import registry (:mod:`acquisition.importers_registry`): every row in ``--help``, detected by
its extension and content, its options checked, an unknown file's error listing the rows; and
one sample file per row that imports through the command line (a new row without a sample here
fails :func:`test_every_row_has_a_sample`).

The samples are written here by hand in each format's documented layout: LabVIEW text, MATLAB
files (scipy.io.savemat), numpy arrays, SEP005 JSON, SignalCalc ASCII text and an ASCII UFF 58 file
(:mod:`uff58_text`, a writer independent of pyuff and of :mod:`analysis.uff`).
"""
from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from test_frf_importers import _signalcalc, _testlab
from test_importers import FS, synthetic_hits, write_lvm
from uff58_text import Record58, write_uff58_text

from acquisition.cli_import import build_parser
from acquisition.cli_import import main as import_main
from acquisition.errors import UsageError
from acquisition.importers_registry import IMPORT_FORMATS, check_options, format_for
from analysis.recording import load_frfset


def _run(argv: list, capsys) -> tuple[int, str, str]:
    code = import_main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# -- one sample per row: (files, extra arguments) ---------------------------------------------------

def _time_channels(n_hits: int = 2) -> tuple[list[np.ndarray], float]:
    """``n_hits`` hits [force N, acceleration g] of a synthetic impact test, and the sample rate (Hz)."""
    hits, _ = synthetic_hits(n_hits)
    return [np.vstack([f, x]) for f, x in hits], FS


def sample_lvm(d: Path) -> tuple[list[Path], list[str]]:
    hits, _ = synthetic_hits(2)
    p = d / "hits.lvm"
    write_lvm(p, hits)
    return [p], []


def sample_mat(d: Path) -> tuple[list[Path], list[str]]:
    hits, fs = _time_channels(1)
    t = (np.arange(hits[0].shape[1]) - 20) / fs
    p = d / "hit.mat"
    scipy.io.savemat(p, {"X1": np.column_stack([t, hits[0][0]]), "X2": np.column_stack([t, hits[0][1]]),
                         "Unit": np.array(["N", "g"]), "Sensitivity": np.array([2.25, 100.0])})
    return [p], []


def sample_npy(d: Path) -> tuple[list[Path], list[str]]:
    hits, fs = _time_channels(2)
    paths = []
    for k, h in enumerate(hits):
        paths.append(d / f"h{k}.npy")
        np.save(paths[-1], h)
    desc = d / "desc.json"
    desc.write_text(json.dumps({"sample_rate_hz": fs, "channels": [
        {"name": "f", "quantity": "force", "unit": "N", "point": "n:1:Z"},
        {"name": "a", "quantity": "acceleration", "unit": "g", "point": "n:2:Z"}]}))
    return paths, ["--describe", str(desc)]


def sample_sep005(d: Path) -> tuple[list[Path], list[str]]:
    hits, fs = _time_channels(2)
    chans = []
    for k, h in enumerate(hits):
        chans += [{"name": "force", "group": f"hit{k}", "fs": fs, "quantity": "f", "unit_str": "N", "point": "n:1:Z",
                   "data": h[0].tolist()},
                  {"name": "acc", "group": f"hit{k}", "fs": fs, "quantity": "a", "unit_str": "g", "point": "n:2:Z",
                   "data": h[1].tolist()}]
    p = d / "hits.json"
    p.write_text(json.dumps(chans))
    return [p], []


def sample_signalcalc_frf(d: Path) -> tuple[list[Path], list[str]]:
    p = d / "DPsv00001.mat"
    _signalcalc(p)
    return [p], []


def sample_testlab_frf(d: Path) -> tuple[list[Path], list[str]]:
    _testlab(d, prefix="Run__")
    return [d / "Run__FRF.mat"], ["--variables", "FRF"]


def signalcalc_ascii_text(f: np.ndarray, h: np.ndarray, dofs: str = "1-Z:4-Z", unit: str = "(m/s\u00b2)(N)") -> str:
    """A SignalCalc single-signal ASCII FRF export, laid out as the ModeLAB example files are."""
    head = ["Units: Ratio", f"Ref Chan:Resp Chan\t{dofs}", "Channel Name\t : ", "Channel Comment\t : ", "",
            "Frequency\t Real\t Imaginary", "", "Units:", f"Hz\t{unit}\t "]
    rows = [f"{x:.13e}\t{v.real:16.7g}\t{v.imag:16.7g}" for x, v in zip(f, h)]
    return "\r\n".join(head + rows) + "\r\n"


def _frf(f: np.ndarray, gain: float = 1.0) -> np.ndarray:
    w = 2 * np.pi * f
    wn, z = 2 * np.pi * 31.0, 0.01
    return -(w ** 2) * gain / (wn ** 2 - w ** 2 + 2j * z * wn * w)


def sample_signalcalc_ascii(d: Path) -> tuple[list[Path], list[str]]:
    f = np.arange(801) * 0.125
    p = d / "Hxysv00001.txt"
    p.write_bytes(signalcalc_ascii_text(f, _frf(f)).encode("latin-1"))
    return [p], []


def sample_uff58(d: Path) -> tuple[list[Path], list[str]]:
    f0, df, n = 0.0, 0.25, 401
    f = f0 + df * np.arange(n)
    recs = []
    for node, gain in ((2, 1.0), (3, -0.5)):
        ids = ("FRF", "estimator H1 averages 12", "", "", "")
        recs += [Record58(4, (node, 3), (1, 3), f0, df, _frf(f, gain), ids),
                 Record58(6, (node, 3), (1, 3), f0, df, np.linspace(0.6, 0.99, n), ids)]
    return [write_uff58_text(d / "frfs.uff", recs)], []


def _shaker_blocks(n_blocks: int = 3, n: int = 512, fs: float = 512.0) -> tuple[np.ndarray, np.ndarray]:
    """A periodic multisine force (N) and the response (g) of one resonance at 31 Hz, ``n_blocks``
    periods of ``n`` samples plus one transient period first: (force, response), each 1-D."""
    rng = np.random.default_rng(5)
    f = np.fft.rfftfreq(n, 1 / fs)
    spec = np.where((f >= 5) & (f <= 100), np.exp(2j * np.pi * rng.uniform(size=f.size)), 0)
    one = np.fft.irfft(spec, n) * n / 10
    force = np.tile(one, n_blocks + 1)
    resp_spec = np.fft.rfft(one) * _frf(f)
    resp = np.tile(np.fft.irfft(resp_spec, n), n_blocks + 1)
    return force, resp


SHAKER_DESCRIPTION = {"sample_rate_hz": 512.0, "excitation": "continuous", "block_samples": 512, "skip_blocks": 1,
                      "channels": [{"name": "Force", "quantity": "force", "unit": "N", "point": "n:1:Z"},
                                   {"name": "Acc", "quantity": "acceleration", "unit": "g", "point": "n:2:Z"}]}


def sample_csv(d: Path) -> tuple[list[Path], list[str]]:
    force, resp = _shaker_blocks()
    p = d / "shaker.csv"
    rows = ['"Force","Voltage","Acc","Fs",'] + [f"{float(a)!r},0.0,{float(b)!r},{'512' if k == 0 else ''},"
                                              for k, (a, b) in enumerate(zip(force, resp))]
    p.write_text("\n".join(rows) + "\n")
    desc = d / "shaker.json"
    desc.write_text(json.dumps({**SHAKER_DESCRIPTION, "columns": ["Force", "Acc"]}))
    return [p], ["--describe", str(desc)]


def sample_hdf5(d: Path) -> tuple[list[Path], list[str]]:
    import h5py

    force, resp = _shaker_blocks()
    p = d / "sweep.hdf5"
    with h5py.File(p, "w") as f:
        f["InputTask/data"] = np.column_stack([force, resp, np.zeros_like(force)])
        f["InputTask/sample_rate"] = 512
    desc = d / "sweep.json"
    desc.write_text(json.dumps({**SHAKER_DESCRIPTION, "dataset": "InputTask/data", "layout": "samples_first",
                                "sample_rate_hz": "InputTask/sample_rate", "columns": [0, 1]}))
    return [p], ["--describe", str(desc)]


SAMPLES: dict[str, Callable[[Path], tuple[list[Path], list[str]]]] = {
    "csv": sample_csv, "hdf5": sample_hdf5,
    "lvm": sample_lvm, "mat": sample_mat, "npy": sample_npy, "sep005": sample_sep005,
    "signalcalc-frf": sample_signalcalc_frf, "testlab-frf": sample_testlab_frf,
    "signalcalc-ascii": sample_signalcalc_ascii, "uff58": sample_uff58,
}


def test_every_row_has_a_sample():
    assert set(SAMPLES) == {r.name for r in IMPORT_FORMATS}


@pytest.mark.parametrize("row", IMPORT_FORMATS, ids=lambda r: r.name)
def test_every_row_is_detected_from_its_sample_and_imports(tmp_path, capsys, row):
    files, extra = SAMPLES[row.name](tmp_path)
    assert format_for(None, files[0]) is row  # by extension and content, without --format
    out = tmp_path / "rec.h5"
    code, stdout, err = _run([*files, *extra, "--out", out], capsys)
    assert code == 0, err
    assert "recording written" in stdout
    s = load_frfset(out)
    assert s.H.shape[2] == s.freq_hz.size and np.all(np.isfinite(s.H))


# -- --help and errors come from the rows ---------------------------------------------------------

def test_every_row_appears_in_help_with_its_extensions():
    parser = build_parser()
    text = "".join(parser.format_help().split())  # argparse wraps lines at spaces and hyphens
    choices = next(a.choices for a in parser._actions if a.dest == "format")
    assert list(choices) == [r.name for r in IMPORT_FORMATS]
    for r in IMPORT_FORMATS:
        assert "".join(r.label().split()) in text, r.name


def test_unknown_extension_error_lists_every_row(tmp_path, capsys):
    p = tmp_path / "data.xyz"
    p.write_text("1 2 3\n")
    code, _, err = _run([p, "--out", tmp_path / "r.h5"], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert str(p) in err and "unknown input format" in err and "--format" in err
    for r in IMPORT_FORMATS:
        assert f"{r.name} ({', '.join(r.extensions)})" in err, r.name


def test_a_file_whose_content_fits_no_row_of_its_extension_names_them(tmp_path, capsys):
    p = tmp_path / "notes.txt"
    p.write_text("hello\n")
    code, _, err = _run([p, "--out", tmp_path / "r.h5"], capsys)
    assert code == 2 and err.count("\n") == 1
    assert "unknown input format" in err and "read as signalcalc-ascii" in err and str(p) in err


def test_options_a_row_does_not_take_are_refused_naming_the_rows_that_do():
    lvm = format_for("lvm", Path("x.lvm"))
    with pytest.raises(UsageError, match=r"--windowed: for --format mat only, not lvm"):
        check_options(lvm, ["--windowed"])
    with pytest.raises(UsageError, match=r"--variables: for analyser FRF exports only"):
        check_options(lvm, ["--variables"])
    with pytest.raises(UsageError, match=r"--force-window: for time data only; uff58 holds the analyser's FRFs"):
        check_options(format_for("uff58", Path("x.uff")), ["--force-window"])
    with pytest.raises(UsageError, match=r"npy input needs --describe"):
        check_options(format_for("npy", Path("x.npy")), [])
    check_options(lvm, ["--force-channel", "--reference", "--overwrite"])  # its own and the common ones pass


def test_an_option_of_another_row_is_refused_by_the_command(tmp_path, capsys):
    files, _ = sample_lvm(tmp_path)
    code, _, err = _run([*files, "--windowed", "--out", tmp_path / "r.h5"], capsys)
    assert code == 2 and "--windowed: for --format mat only" in err and err.count("\n") == 1
    assert not (tmp_path / "r.h5").exists()


def test_sample_rate_is_finite_in_every_time_sample(tmp_path):
    """The time samples are what a capture would record: the registry's readers see real hits."""
    for name in ("lvm", "mat", "npy", "sep005", "csv", "hdf5"):
        files, extra = SAMPLES[name](tmp_path)
        row = format_for(None, files[0])
        from acquisition.importers_registry import ReadOptions

        describe = extra[1] if extra else None
        tests = row.read(files, ReadOptions(describe=describe))
        assert all(math.isfinite(t.fs_hz) and t.fs_hz > 0 for t in tests)


# -- the commands docs/validation.md shows ------------------------------------------------------------

COMMANDS_MD = Path(__file__).resolve().parents[1] / "benchmarks" / "accuracy" / "validation" / "commands.md"


def _documented_commands(prog: str) -> list[list[str]]:
    """The ``python -m <prog>`` command lines of the validation commands (continuation lines joined,
    shell braces ``{1,2}`` expanded as the shell would, outputs left out)."""
    import re
    import shlex

    text = COMMANDS_MD.read_text(encoding="utf-8").replace("\\\n", " ")
    out = []
    for line in text.splitlines():
        if line.startswith(f"python -m {prog} "):
            m = re.search(r"(\S*)\{([\d,]+)\}(\S*)", line)
            if m:
                line = line.replace(m.group(0), " ".join(f"{m.group(1)}{k}{m.group(3)}" for k in m.group(2).split(",")))
            out.append(shlex.split(line)[2 + len(prog.split()):])
    return out


def test_the_documented_import_commands_parse_and_name_registry_formats():
    parser = build_parser()
    commands = _documented_commands("acquisition import")
    assert len(commands) >= 8
    for argv in commands:
        args = parser.parse_args(argv)  # an unknown option or --format exits here
        for f in args.files:
            if Path(f).suffix in {e for r in IMPORT_FORMATS for e in r.extensions}:
                continue
            assert Path(f).suffix in (".csv", ".hdf5"), f  # shown refused: no row reads them


def test_every_shared_dataset_has_its_commands():
    text = COMMANDS_MD.read_text(encoding="utf-8")
    for name in ("ladisk_beam_impact", "pyfrf_hammer_5impacts", "pyuff_3frf", "modelab_beam_roving_hammer",
                 "uliege_meca0062_plane_hammer", "f16_gvt_multisine", "unesp_bert_boltedbeam_subset",
                 "ladisk_plate_sweep"):
        assert f"### {name}" in text or f"{name} and" in text or f"and {name}" in text, name
    for command in ("fit", "report", "linearity", "diagnose"):
        assert len(_documented_commands(f"analysis {command}")) >= 4, command


@pytest.mark.parametrize("name", ["csv", "hdf5"])
def test_a_continuous_excitation_is_cut_into_blocks_kept_whole_and_unwindowed(tmp_path, capsys, name):
    """A shaker's periodic record: every period after the transient one is a block, none is refused as
    a double hit, no hammer window is applied, and the FRF is the periods' H1 (the structure's FRF)."""
    from analysis.recording import Recording

    files, extra = SAMPLES[name](tmp_path)
    out = tmp_path / "r.h5"
    code, stdout, err = _run([*files, *extra, "--out", out], capsys)
    assert code == 0, err
    assert "imported 3 accepted hit(s)" in stdout
    with Recording(out) as rec:
        assert rec.n_hits == 3
        assert rec.windows.force_width_s is None and rec.windows.exp_window_tau_s is None
    s = load_frfset(out)
    band = (s.freq_hz >= 5) & (s.freq_hz <= 100)
    rel = np.abs(s.H[0, 0, band] / _frf(s.freq_hz[band]) - 1)
    assert np.median(rel) < 1e-3 and rel.max() < 1e-2  # the 16-bit counts' rounding, no window, no leakage
    # the band the shaker excites (5-100 Hz) ends the fit's band, not a hammer pulse's fall
    assert s.meta["excitation_limit_hz"] == [pytest.approx(100.0, abs=1.0)]


def test_docs_validation_shows_the_commands_section_as_generated():
    """docs/validation.md holds commands.md whole (run_all puts it there; a hand edit of either shows)."""
    validation = COMMANDS_MD.parents[3] / "docs" / "validation.md"
    assert COMMANDS_MD.read_text(encoding="utf-8").strip() in validation.read_text(encoding="utf-8")


def test_every_row_has_its_line_in_the_recording_format_docs():
    text = (COMMANDS_MD.parents[3] / "docs" / "recording-format.md").read_text(encoding="utf-8")
    for r in IMPORT_FORMATS:
        assert f"| `{r.name}` |" in text, r.name


@pytest.mark.parametrize("name, damage", [
    ("csv", lambda b: b[: len(b) // 2 - 7]),          # cut inside a line
    ("csv", lambda b: b.replace(b"Acc", b"Acx", 1)),   # the described column is gone
    ("hdf5", lambda b: b[:900]),                       # cut short
])
def test_a_damaged_described_file_is_one_line_naming_it(tmp_path, capsys, name, damage):
    files, extra = SAMPLES[name](tmp_path)
    files[0].write_bytes(damage(files[0].read_bytes()))
    out = tmp_path / "r.h5"
    code, _, err = _run([*files, *extra, "--out", out], capsys)
    assert code == 2 and err.count("\n") == 1 and str(files[0]) in err, err
    assert not out.exists()


def test_a_band_above_a_shakers_excitation_names_the_excitation_not_a_hammer(tmp_path, capsys):
    """A fit band reaching above where a shaker's continuous excitation ends is warned about as the
    excitation's band, with the remedy of a shaker (a wider band), never as a hammer's reach or tip."""
    from analysis.pipeline import fit_auto

    files, extra = SAMPLES["csv"](tmp_path)
    out = tmp_path / "r.h5"
    code, _, err = _run([*files, *extra, "--out", out], capsys)
    assert code == 0, err
    s = load_frfset(out)
    assert s.meta["excitation"] == "continuous"
    fit = fit_auto(s, band=(5.0, 180.0))
    said = [w for w in (*fit.warnings, *fit.problems) if "below the band's top" in w]
    assert said and all("the excitation's band ends at 100 Hz" in w and "excite a wider band" in w
                        and "hammer" not in w and "tip" not in w for w in said)
