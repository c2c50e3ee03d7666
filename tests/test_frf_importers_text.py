"""SignalCalc ASCII ``Hxy*.txt`` and UFF 58 (FRFs with coherence) -> recordings, alone and as a
roving test with ``--points``.

Synthetic files are written here from the formats' documented layouts (the ASCII export as the
ModeLAB example files are laid out; UFF 58 by :mod:`uff58_text`, independent of pyuff and of
:mod:`analysis.uff`). The realdata tests import the real files of ../shared/data: ModeLAB
(alxhslm/ModeLAB, GPL-3.0), pyuff (ladisk/pyuff, MIT), ULiege MECA0062 (internal validation only).
"""
from __future__ import annotations

import numpy as np
import pytest
from test_importers_registry import _frf, signalcalc_ascii_text
from uff58_text import Record58, write_uff58_text

from acquisition.cli_import import main as import_main
from acquisition.errors import ImportDataError
from acquisition.frf_importers import read_uff58_frfs
from acquisition.frf_importers_ascii import read_signalcalc_ascii
from analysis.recording import Recording, load_frfset

F = np.arange(801) * 0.125
realdata = pytest.mark.realdata


def _run(argv: list, capsys) -> tuple[int, str, str]:
    code = import_main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _ascii(path, gain=1.0, **kw):
    h = _frf(F, gain)
    path.write_bytes(signalcalc_ascii_text(F, h, **kw).encode("latin-1"))
    return h


# -- SignalCalc ASCII ----------------------------------------------------------------------------

def test_signalcalc_ascii_keeps_the_file_values_labels_and_unit(tmp_path, capsys):
    src = tmp_path / "Hxysv00001.txt"
    h = _ascii(src, dofs="3-Z:7-Y")
    out = tmp_path / "r.h5"
    code, stdout, err = _run([src, "--out", out], capsys)
    assert code == 0, err
    assert "no coherence in the file" in stdout and "averages not stated" in stdout
    s = load_frfset(out)
    assert s.references == ("n:3:Z",) and s.outputs == ("n:7:Y",)
    assert s.unit == "(m/s^2)/N" and s.quantity == "accelerance"
    np.testing.assert_array_equal(s.freq_hz, [float(f"{x:.13e}") for x in F])
    expected = [complex(float(f"{v.real:16.7g}"), float(f"{v.imag:16.7g}")) for v in h]
    np.testing.assert_array_equal(s.H[0, 0], expected)
    assert s.coherence is None  # the export has none: none is made up
    with Recording(out) as rec:
        g = rec.frf_group(rec.measurement_names()[0])
        assert "coherence" not in g and g["n_averages"] == 0


@pytest.mark.parametrize("edit, words", [
    (lambda t: t.replace("Frequency\t Real\t Imaginary", "Frequency\t Magnitude\t Phase"), "only Frequency, Real"),
    (lambda t: t.replace("Ref Chan:Resp Chan\t1-Z:4-Z", "Ref Chan:Resp Chan\tA:B"), "node-direction pairs"),
    (lambda t: t.replace("Hz\t", "sec\t"), "does not start with Hz"),
    (lambda t: "\r\n".join(t.split("\r\n")[:10]), "at least two frequencies"),
    (lambda t: "\r\n".join(t.split("\r\n")[:9]), "0 data line(s)"),  # the header alone: no numpy warning
    (lambda t: t.replace("1.2500000000000e-01", "1.25e-01x"), "not three numbers per line"),
    (lambda t: t.replace("(m/s\u00b2)(N)", "(V)(N)"), "not a motion"),
    (lambda t: "Data written for 2 signals\r\n" + t, "multi-signal"),
    (lambda t: t.split("\r\n", 1)[1], "not a SignalCalc ASCII export"),
    (lambda t: t.replace("2.5000000000000e-01", "1.2500000000000e-01"), "strictly increasing"),
])
def test_malformed_signalcalc_ascii_is_one_line_naming_the_file(tmp_path, capsys, edit, words):
    src = tmp_path / "Hxysv00001.txt"
    src.write_bytes(edit(signalcalc_ascii_text(F, _frf(F))).encode("latin-1"))
    out = tmp_path / "r.h5"
    code, _, err = _run([src, "--format", "signalcalc-ascii", "--out", out], capsys)
    assert code == 2 and err.count("\n") == 1 and str(src) in err and words in err, err
    assert not out.exists()


def test_roving_ascii_files_take_their_points_from_the_map(tmp_path, capsys):
    h = [_ascii(tmp_path / f"Hxysv0000{k}.txt", gain=k) for k in (1, 2)]
    (tmp_path / "map.csv").write_text("file,reference,outputs\nHxysv00001.txt,beam:1:Z,beam:4:Z\n"
                                      "Hxysv00002.txt,beam:2:Z,beam:4:Z\n")
    out = tmp_path / "r.h5"
    code, _, err = _run(["--points", tmp_path / "map.csv", "--out", out], capsys)
    assert code == 0, err
    s = load_frfset(out)
    assert s.references == ("beam:1:Z", "beam:2:Z") and s.outputs == ("beam:4:Z",)
    assert s.coherence is None
    np.testing.assert_allclose(s.H[0, 1], h[1], rtol=1e-6)


# -- UFF 58 with coherence -------------------------------------------------------------------------

def _uff(path, coherence=True, averages="12", skip_coherence_of=None):
    recs = []
    hs, cs = {}, {}
    for node, gain in ((2, 1.0), (3, -0.5)):
        hs[node], cs[node] = _frf(F, gain), np.linspace(0.5 + 0.1 * node, 0.99, F.size)
        ids = ("FRF", f"estimator H1 averages {averages}", "", "", "")
        recs.append(Record58(4, (node, 3), (1, 3), 0.0, 0.125, hs[node], ids))
        if coherence and node != skip_coherence_of:
            recs.append(Record58(6, (node, 3), (1, 3), 0.0, 0.125, cs[node], ids))
    write_uff58_text(path, recs)
    return hs, cs


def test_uff58_frfs_with_coherence_and_averages_become_a_recording(tmp_path, capsys):
    src = tmp_path / "frfs.uff"
    hs, cs = _uff(src)
    out = tmp_path / "r.h5"
    code, stdout, err = _run([src, "--out", out], capsys)
    assert code == 0, err
    assert "12 averages" in stdout
    s = load_frfset(out)
    assert s.references == ("n:1:Z",) and s.outputs == ("n:2:Z", "n:3:Z") and s.unit == "g/N"
    for i, node in enumerate((2, 3)):
        np.testing.assert_allclose(s.H[i, 0], hs[node], rtol=1e-11)
        np.testing.assert_allclose(s.coherence[i, 0], cs[node], rtol=1e-11)
    assert s.meta["n_averages"] == [12]


def test_uff58_without_coherence_records_imports_without_coherence(tmp_path):
    src = tmp_path / "frfs.uff"
    _uff(src, coherence=False)
    imp = read_uff58_frfs(src)
    assert imp.sets[0].coherence is None and imp.n_averages == [12]


def test_uff58_with_the_coherence_of_some_frfs_only_is_refused(tmp_path, capsys):
    src = tmp_path / "frfs.uff"
    _uff(src, skip_coherence_of=3)
    code, _, err = _run([src, "--out", tmp_path / "r.h5"], capsys)
    assert code == 2 and err.count("\n") == 1 and str(src) in err and "n:3:Z/n:1:Z has no coherence record" in err


def test_uff58_cut_short_is_one_line(tmp_path, capsys):
    src = tmp_path / "frfs.uff"
    _uff(src)
    src.write_bytes(src.read_bytes()[:-500])
    code, _, err = _run([src, "--out", tmp_path / "r.h5"], capsys)
    assert code == 2 and err.count("\n") == 1 and str(src) in err and "cut short" in err


def test_readers_refuse_with_import_data_error(tmp_path):
    bad = tmp_path / "x.txt"
    bad.write_text("Units: Ratio\n")
    with pytest.raises(ImportDataError, match=str(bad)):
        read_signalcalc_ascii(bad)
    with pytest.raises(ImportDataError, match="not found"):
        read_uff58_frfs(tmp_path / "missing.uff")


# -- the real files ------------------------------------------------------------------------------

@realdata
def test_modelab_roving_hammer_ascii_files_and_map_fit_the_four_beam_modes(shared_data, tmp_path, capsys):
    from analysis.pipeline import fit_auto

    d = shared_data / "modelab_beam_roving_hammer"
    rows = "".join(f"{d / f'Hxysv0000{k}.txt'},beam:{k}:Z,beam:4:Z\n" for k in range(1, 10))
    (tmp_path / "map.csv").write_text("file,reference,outputs\n" + rows)
    out = tmp_path / "beam.h5"
    code, _, err = _run(["--points", tmp_path / "map.csv", "--out", out], capsys)
    assert code == 0, err
    s = load_frfset(out)
    assert s.H.shape == (1, 9, 51201) and s.unit == "(m/s^2)/N" and s.coherence is None
    res = fit_auto(s, band=(65.0, 1000.0))
    # the four bending modes of the ModeLAB beam (docs/validation.md: 112.0, 306.9, 596.4, 974.1 Hz)
    for f0 in (111.99, 306.85, 596.37, 974.14):
        assert np.min(np.abs(res.freq_hz - f0)) < 0.05, (f0, res.freq_hz)


@realdata
def test_pyuff_measurement_uff_imports_its_three_frfs(shared_data, tmp_path, capsys):
    out = tmp_path / "p.h5"
    code, stdout, err = _run([shared_data / "pyuff_3frf" / "measurement.uff", "--out", out], capsys)
    assert code == 0, err
    s = load_frfset(out)
    assert s.H.shape[:2] == (1, 3) and s.H.shape[2] == 1001
    direct = np.genfromtxt(shared_data / "pyuff_3frf" / "meas_point_1.txt", dtype=complex)
    # the UFF file holds the text file's FRF in single precision
    assert np.max(np.abs(s.H[0, 0] - direct)) < 1e-3 * np.max(np.abs(direct))


@realdata
def test_uliege_second_lab_files_with_a_point_map(shared_data, tmp_path, capsys):
    d = shared_data / "uliege_meca0062_plane_hammer" / "sec_lab_original"
    (tmp_path / "map.csv").write_text(f"file,reference,outputs\n{d / 'DPsv00001.mat'},plane:1:Z,acc:1:Z;acc:2:Z;acc:3:Z\n"
                                      f"{d / 'DPsv00031.mat'},plane:29:Z,acc:1:Z;acc:2:Z;acc:3:Z\n")
    out = tmp_path / "plane.h5"
    code, _, err = _run(["--points", tmp_path / "map.csv", "--analyser-exp-window", "32.9%", "--out", out], capsys)
    assert code == 0, err
    s = load_frfset(out)
    assert s.references == ("plane:1:Z", "plane:29:Z") and s.outputs == ("acc:1:Z", "acc:2:Z", "acc:3:Z")
    assert s.H.shape == (3, 2, 1601) and s.coherence is not None
    assert s.exp_window_tau_s == pytest.approx(8.0 / np.log(1 / 0.329), rel=2e-3)
