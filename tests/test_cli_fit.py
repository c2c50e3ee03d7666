"""``python -m analysis fit`` and ``python -m analysis stabilization`` on a UFF 58 file written with pyuff."""
from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from analysis import cli_fit, cli_stabilization
from analysis.modal import ModalModel, natural_freq_hz, pole_from_fz, synthesize
from analysis.points import uff_direction, uff_node

F_TRUE = np.array([30.0, 62.0, 64.5, 120.0, 175.0])
Z_TRUE = np.array([0.008, 0.01, 0.012, 0.01, 0.015])
OUTPUTS = ["left:9:Y", "left:4:Y", "top:4:X", "right:4:-Z", "right:9:Y"]
REFERENCE = "right:6:-X"
ROOT = Path(__file__).resolve().parents[1]


def _write_uff58_with_pyuff(path: Path, noise: float = 0.005) -> None:
    """A UFF file of accelerance FRFs (type 4, ordinate 12 acceleration / 13 force) by pyuff itself."""
    import pyuff

    rng = np.random.default_rng(7)
    poles = pole_from_fz(F_TRUE, Z_TRUE)
    phi = rng.standard_normal((len(OUTPUTS), poles.size))
    R = phi[:, None, :] * poles.imag / 2j
    model = ModalModel(poles, R, quantity="accelerance", residual_form="physical",
                       upper_residual=1e-6 * np.ones((len(OUTPUTS), 1)), lower_residual=2.0 * np.ones((len(OUTPUTS), 1)))
    f = np.arange(1, 1001) * 0.25
    H = synthesize(model, f).H
    H = H + noise * np.abs(H) * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2)
    sets = []
    for i, out in enumerate(OUTPUTS):
        sets.append(pyuff.prepare_58(
            binary=1, func_type=4, data=H[i, 0], x=f, abscissa_spacing=1, abscissa_spec_data_type=18,
            abscissa_axis_units_lab="Hz", rsp_node=uff_node(out), rsp_dir=uff_direction(out),
            ref_node=uff_node(REFERENCE), ref_dir=uff_direction(REFERENCE), rsp_ent_name="frame",
            ref_ent_name="frame", ordinate_spec_data_type=12, orddenom_spec_data_type=13,
            ordinate_axis_units_lab="m/s^2", orddenom_axis_units_lab="N", id1="synthetic FRF", id4=out,
        ))
    # pyuff's binary writer leaves a file handle open (a ResourceWarning, pyuff's own leak, after the data are
    # complete), released when the call returns: inside this block only
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        pyuff.UFF(str(path)).write_sets(sets, "add", force_double=True)


@pytest.fixture(scope="module")
def uff_file(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("cli") / "frame.uff"
    _write_uff58_with_pyuff(p)
    return p


def test_fit_writes_json_plot_and_uff(uff_file, tmp_path, capsys):
    out_json, out_png, out_uff = tmp_path / "fit.json", tmp_path / "fit.png", tmp_path / "modes.uff"
    rc = cli_fit.main([str(uff_file), "--json", str(out_json), "--plot", str(out_png), "--uff", str(out_uff),
                       "--method", "gn"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    # the terminal table in the manner of the paper's Table 1
    assert "pole I " in cap.out and "pole V " in cap.out and "sum of square errors: S =" in cap.out
    assert "upper residual term UR" in cap.out and "lower residual term LR" in cap.out
    doc = json.loads(out_json.read_text())
    for key in ("poles", "residues", "upper_residual", "lower_residual", "sse", "iterations", "history", "status",
                "message", "method", "band", "quantity", "residual_form", "outputs", "references"):
        assert key in doc, key
    assert doc["method"] == "gn" and doc["quantity"] == "accelerance" and doc["residual_form"] == "physical"
    assert doc["outputs"] == OUTPUTS and doc["references"] == [REFERENCE]
    freqs = [p["freq_hz"] for p in doc["poles"]]
    np.testing.assert_allclose(freqs, F_TRUE, rtol=1e-4)
    np.testing.assert_allclose([p["damping"] for p in doc["poles"]], Z_TRUE, rtol=0.05)
    for p in doc["poles"]:
        assert {"freq_hz", "damping", "freq_hz_std", "damping_std", "damped_freq_hz"} <= set(p)
        assert 0 < p["freq_hz_std"] < 0.01
    r0 = doc["residues"][0]
    assert r0["output"] == OUTPUTS[0] and r0["reference"] == REFERENCE
    assert len(r0["values"]) == F_TRUE.size and len(r0["values"][0]) == 2  # [re, im]
    assert len(doc["upper_residual"][0]["value"]) == 2
    assert doc["history"][0] >= doc["history"][-1] == pytest.approx(doc["sse"])
    assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # UFF 55 shapes and UFF 58 synthesised FRFs read back
    from analysis.uff import read_uff55, read_uff58

    lam, nodes, shapes = read_uff55(out_uff)
    # modes in order of frequency in the file, as in the table and the JSON
    np.testing.assert_allclose(natural_freq_hz(lam), F_TRUE, rtol=1e-4)
    assert np.all(np.diff(natural_freq_hz(lam)) > 0) and np.all(np.diff(freqs) > 0)
    synth = read_uff58(out_uff)
    assert synth.outputs == tuple(OUTPUTS) and synth.H.shape[0] == len(OUTPUTS)
    # the geometry beside the shapes (UFF 15 nodes, 82 trace lines) holds every shape's node
    from analysis.geometry import read_uff_geometry
    from analysis.points import uff_node

    geo = read_uff_geometry(out_uff)
    assert geo.covers(OUTPUTS + [REFERENCE]) == [] and len(geo.lines) >= 1
    assert {uff_node(o) for o in OUTPUTS} <= {int(n) for n in np.atleast_1d(nodes)}


def test_fit_user_poles_band_and_modes(uff_file, tmp_path, capsys):
    out = tmp_path / "a.json"
    rc = cli_fit.main([str(uff_file), "--json", str(out), "--poles", "30,62,64.5", "--band", "10:100",
                       "--residuals", "paper"])
    assert rc == 0, capsys.readouterr().err
    doc = json.loads(out.read_text())
    assert len(doc["poles"]) == 3 and doc["residual_form"] == "paper"
    np.testing.assert_allclose([p["freq_hz"] for p in doc["poles"]], F_TRUE[:3], rtol=1e-4)
    # the same output again: refused without --overwrite, replaced with it
    assert cli_fit.main([str(uff_file), "--json", str(out), "--modes", "2"]) == 2
    assert "add --overwrite" in capsys.readouterr().err and len(json.loads(out.read_text())["poles"]) == 3
    rc = cli_fit.main([str(uff_file), "--json", str(out), "--modes", "2", "--order", "12", "--initial", "lsce",
                       "--overwrite"])
    assert rc == 0
    assert len(json.loads(out.read_text())["poles"]) == 2


def test_stabilization_command(uff_file, tmp_path, capsys):
    png, js = tmp_path / "s.png", tmp_path / "s.json"
    rc = cli_stabilization.main([str(uff_file), "--png", str(png), "--json", str(js), "--max-order", "14",
                                 "--method", "lscf"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = json.loads(js.read_text())
    assert len(doc["orders"]) == 14
    np.testing.assert_allclose(sorted(s["freq_hz"] for s in doc["selected"]), F_TRUE, rtol=1e-3)


def _bad_cases(uff: Path, tmp: Path):
    (tmp / "notes.json").write_text("{}")
    (tmp / "broken.uff").write_text("    -1\n    58\ngarbage\n")
    return [
        ([str(tmp / "missing.uff"), "--json", str(tmp / "o.json")], "not found"),
        ([str(tmp / "notes.json"), "--json", str(tmp / "o.json")], "cannot tell the format"),
        ([str(tmp / "broken.uff"), "--json", str(tmp / "o.json")], "cannot read UFF"),
        ([str(uff), "--json", str(tmp / "o.json"), "--band", "5-100"], "bad band"),
        ([str(uff), "--json", str(tmp / "o.json"), "--band", "100:5"], "bad band"),
        ([str(uff), "--json", str(tmp / "o.json"), "--band", "900:1000"], "outside the data"),
        ([str(uff), "--json", str(tmp / "o.json"), "--poles", "30,abc"], "not a number"),
        ([str(uff), "--json", str(tmp / "o.json"), "--modes", "0"], ">= 1"),
        ([str(uff), "--json", str(tmp / "no" / "dir" / "o.json")], "does not exist"),
        ([str(uff), "--json", str(tmp / "o.json"), "--method", "newton"], "invalid choice"),
        ([str(uff), "--json", str(tmp / "notes.json")], "exists: choose another JSON file or add --overwrite"),
    ]


def test_fit_bad_inputs_exit_2_without_traceback(uff_file, tmp_path, capsys):
    for argv, text in _bad_cases(uff_file, tmp_path):
        rc = cli_fit.main(argv)
        err = capsys.readouterr().err
        assert rc == 2, argv
        assert text in err, (argv, err)
        assert "Traceback" not in err


def test_stabilization_bad_inputs(uff_file, tmp_path, capsys):
    cases = [
        ([str(tmp_path / "missing.uff"), "--png", str(tmp_path / "s.png")], "not found"),
        ([str(uff_file), "--png", str(tmp_path / "s.png"), "--band", "x:y"], "bad band"),
        ([str(uff_file), "--png", str(tmp_path / "s.png"), "--max-order", "0"], ">= 1"),
        ([str(uff_file)], "required"),
    ]
    for argv, text in cases:
        assert cli_stabilization.main(argv) == 2, argv
        err = capsys.readouterr().err
        assert text in err and "Traceback" not in err


def test_module_entry_point(uff_file, tmp_path):
    """Through the dispatcher, as a user types it."""
    r = subprocess.run([sys.executable, "-m", "analysis", "fit", str(uff_file), "--json", str(tmp_path / "x.json"),
                        "--band", "abc"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2 and "bad band" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-m", "analysis", "fit", "--help"], capture_output=True, text=True, cwd=ROOT,
                       timeout=120)
    assert r.returncode == 0 and "--poles" in r.stdout


def test_report_helpers():
    from analysis.report import complex_pair, roman

    assert [roman(k) for k in (1, 4, 5, 9, 14, 40, 90)] == ["I", "IV", "V", "IX", "XIV", "XL", "XC"]
    with pytest.raises(ValueError):
        roman(0)
    assert complex_pair(1 - 2j) == [1.0, -2.0]
    assert complex_pair(complex(np.nan, 0)) is None


def test_fit_scatter_std_and_std_note(uff_file, tmp_path, capsys):
    out = tmp_path / "s.json"
    rc = cli_fit.main([str(uff_file), "--json", str(out), "--scatter-std"])
    assert rc == 0, capsys.readouterr().err
    doc = json.loads(out.read_text())
    assert "perfect model" in doc["std_note"]
    # one reference: the five outputs are split into three interleaved groups
    assert doc["scatter_groups"] == ["outputs left:9:Y, right:4:-Z", "outputs left:4:Y, right:9:Y", "outputs top:4:X"]
    for p in doc["poles"]:
        assert p["freq_hz_scatter_std"] is not None and 0 <= p["freq_hz_scatter_std"] < 0.05 * p["freq_hz"]
    # the synthesis error against the data uses the poles as measured
    assert doc["synthesis_error"]["poles"].startswith("raw") and doc["synthesis_error"]["relative_rms"] < 0.05


def test_uff_export_of_windowed_data_is_synthesised_as_measured(tmp_path):
    """Regression: the exported synthesised FRFs used the window-corrected poles, so they did not
    match the (exponentially windowed) FRFs they were fitted to."""
    from dataclasses import replace

    from analysis.lsfd import fit_lsfd
    from analysis.uff import read_uff58

    tau = 1.5
    lam = pole_from_fz(F_TRUE[:2], Z_TRUE[:2])
    R = np.array([[[1.0 - 1j, 0.5 + 0.2j]], [[-0.3 + 1j, 1.0]]]) * lam.imag / 2j
    f = np.arange(40, 401) * 0.25
    frf = synthesize(ModalModel(lam - 1 / tau, R, "accelerance", "none"), f)
    frf = replace(frf, outputs=tuple(OUTPUTS[:2]), references=(REFERENCE,), exp_window_tau_s=tau)
    res = fit_lsfd(frf, lam - 1 / tau, residual_form="none")
    np.testing.assert_allclose(res.poles, lam, rtol=1e-9)  # the structure
    path = tmp_path / "w.uff"
    cli_fit._write_uff(str(path), frf, res)
    synth = read_uff58(path)
    np.testing.assert_allclose(synth.H, frf.H, rtol=1e-6, atol=1e-9 * np.abs(frf.H).max())


def test_fit_frf_weights_option(uff_file, tmp_path, capsys):
    docs = {}
    for w in ("rms", "none"):
        out = tmp_path / f"{w}.json"
        assert cli_fit.main([str(uff_file), "--json", str(out), "--frf-weights", w]) == 0, capsys.readouterr().err
        docs[w] = json.loads(out.read_text())
        np.testing.assert_allclose([p["freq_hz"] for p in docs[w]["poles"]], F_TRUE, rtol=1e-4)
    # weighted and unweighted are different problems: S differs (the weights are 1/RMS scaled to max 1)
    assert docs["rms"]["sse"] != pytest.approx(docs["none"]["sse"], rel=1e-3)
    assert cli_fit.main([str(uff_file), "--json", str(tmp_path / "x.json"), "--frf-weights", "snr"]) == 2


def test_fit_exclude_lines_and_mains_options(uff_file, tmp_path, capsys):
    out = tmp_path / "x.json"
    rc = cli_fit.main([str(uff_file), "--json", str(out), "--exclude-lines", "50", "--exclude-mains", "60",
                       "--mains", "none"])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert "left out of the fit" in err
    doc = json.loads(out.read_text())
    assert len(doc["poles"]) >= 1
    rc = cli_fit.main([str(uff_file), "--json", str(out), "--mains", "-5"])
    assert rc == 2 and "-5" in capsys.readouterr().err


def test_fit_prints_its_table_without_json(uff_file, tmp_path, capsys):
    """The table on the terminal needs no --json."""
    assert cli_fit.main([str(uff_file), "--modes", "3"]) == 0
    out = capsys.readouterr().out
    assert "pole I " in out and "results written" not in out


def test_every_subcommand_help_documents_its_options_with_an_example():
    """Each --help page ends with worked examples, every option has a help text,
    and no raw reStructuredText markup leaks into the pages."""
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
                code = importlib.import_module(module).main(["--help"])
            except SystemExit as exc:  # plain argparse exits after --help
                code = exc.code
        assert code in (0, None), name
        text = buf.getvalue()
        assert "examples:\n  impactlab " + name in text, name
        assert "``" not in text, (name, "raw markup")
        options = [ln.split()[0] for ln in text.splitlines() if ln.startswith("  --")]
        assert options, name


def test_frf_pairs_by_level_strongest_first_and_all_zero_left_out():
    from analysis.frf import FRFSet, frf_pairs_by_level

    f = np.arange(1.0, 6.0)
    H = np.zeros((3, 2, f.size), complex)
    H[0, 0], H[0, 1], H[1, 0], H[2, 1] = 1.0, 4.0, 2.0, 3.0  # (1, 1) and (2, 0) stay all-zero
    frf = FRFSet(freq_hz=f, H=H, quantity="accelerance", outputs=("a:1:X", "b:1:X", "c:1:X"),
                 references=("a:1:X", "c:1:X"))
    assert frf_pairs_by_level(frf) == [(0, 1), (2, 1), (1, 0), (0, 0)]
    assert frf_pairs_by_level(frf, "b:1:X") == [(1, 0), (0, 1), (2, 1), (0, 0)]
    with pytest.raises(ValueError, match="'z:1:X' is not an output"):
        frf_pairs_by_level(frf, "z:1:X")
