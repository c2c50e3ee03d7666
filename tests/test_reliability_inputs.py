"""Bad numbers in input files are refused with one line naming the file, the place and what to
do; nothing non-finite is stored or passed on, and nothing becomes 0. Work beyond what the data
support or the machine holds is refused before anything is allocated."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from acquisition.importers import ImportDataError, NonFiniteSamples, read_lvm, read_numpy

LVM_HEAD = ("LabVIEW Measurement\t\nSeparator\tTab\nDecimal_Separator\t.\n***End_of_Header***\t\n\t\n"
            "Channels\t2\t\nSamples\t6\t6\nY_Unit_Label\tN\tg\nDelta_X\t{dx}\t{dx}\n***End_of_Header***\t\n"
            "X_Value\tforce\tacc\tComment\n")


def _lvm(tmp_path: Path, rows: list[str], dx: str = "1e-4", name: str = "x.lvm") -> Path:
    p = tmp_path / name
    p.write_text(LVM_HEAD.format(dx=dx) + "".join(f"\t{r}\n" for r in rows))
    return p


ROWS = ["0\t0", "1\t0.5", "3\t1", "1\t0.2", "0\t-1", "0\t0.3"]


def test_lvm_nan_and_inf_samples_are_an_error_naming_file_channel_and_sample(tmp_path):
    for bad in ("NaN", "inf", "-Inf"):
        rows = list(ROWS)
        rows[3] = f"1\t{bad}"
        p = _lvm(tmp_path, rows)
        with pytest.raises(NonFiniteSamples) as err:
            read_lvm(p)
        msg = str(err.value)
        assert str(p) in msg and "channel 2 (ch2)" in msg and "sample 3" in msg and "--drop-nonfinite" in msg


def test_an_all_nan_lvm_is_refused_not_imported_as_zeros(tmp_path):
    p = _lvm(tmp_path, ["NaN\tNaN"] * 6)
    with pytest.raises(NonFiniteSamples, match="channel 1"):
        read_lvm(p)


def test_drop_nonfinite_leaves_out_the_bad_hits_and_counts_them(tmp_path, capsys):
    from acquisition.cli_import import main
    from analysis.recording import Recording

    good = "".join(f"\t{r}\n" for r in ROWS)
    bad_rows = list(ROWS)
    bad_rows[2] = "NaN\t1"
    bad = "".join(f"\t{r}\n" for r in bad_rows)
    seg = LVM_HEAD.format(dx="1e-4").split("***End_of_Header***\t\n\t\n", 1)[1]
    p = tmp_path / "three.lvm"
    p.write_text(LVM_HEAD.format(dx="1e-4") + good + "\n" + seg + bad + "\n" + seg + good)
    assert main([str(p), "--out", str(tmp_path / "refused.h5")]) == 2
    assert "hit 2, channel 1" in capsys.readouterr().err and not (tmp_path / "refused.h5").exists()
    assert main([str(p), "--out", str(tmp_path / "kept.h5"), "--drop-nonfinite"]) == 0
    assert "left out 1 hit(s)" in capsys.readouterr().out
    with Recording(tmp_path / "kept.h5") as rec:
        hits = list(rec.hits())
        assert len(hits) == 2 and all(np.all(np.isfinite(h.eu_per_count)) for h in hits)


def test_absurd_sample_interval_is_refused(tmp_path):
    with pytest.raises(ImportDataError, match="above the largest accepted"):
        read_lvm(_lvm(tmp_path, ROWS, dx="1e-300"))


def test_npy_inf_and_impossible_header_are_refused(tmp_path):
    desc = {"sample_rate_hz": 1000, "channels": [{"name": "f", "unit": "N"}, {"name": "a", "unit": "g"}]}
    a = np.array([[0, 1, 3, 1, 0, 0], [0, 0.5, 1, np.inf, -1, 0.3]])
    np.save(tmp_path / "inf.npy", a)
    with pytest.raises(NonFiniteSamples, match=r"channel 2 \(a\): sample 3 is inf"):
        read_numpy([tmp_path / "inf.npy"], desc)
    big = tmp_path / "big.npy"
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000, 1000000), }"
    header += " " * (117 - len(header)) + "\n"
    big.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode() + b"\0" * 64)
    with pytest.raises(ImportDataError, match=r"claims an array of shape \(1000000, 1000000\)"):
        read_numpy([big], desc)


def test_sep005_nan_names_channel_and_sample(tmp_path):
    from analysis.sep005 import SEP005Error, read_sep005

    p = tmp_path / "s.json"
    p.write_text(json.dumps([{"name": "force", "unit_str": "N", "fs": 100.0, "data": [0.0, 1.0, 2.0]},
                             {"name": "acc", "unit_str": "g", "fs": 100.0, "data": [0.0, 1.0, 2.0]}]).replace(
        "[0.0, 1.0, 2.0]}]", "[0.0, NaN, 2.0]}]"))
    with pytest.raises(SEP005Error, match=r"channel 2 \(acc\): sample 1 is nan"):
        read_sep005(p)
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 50000 + "]" * 50000)
    with pytest.raises(SEP005Error, match="not a JSON SEP005 file"):
        read_sep005(deep)


# -- UFF --------------------------------------------------------------------------------------
def _uff_bytes() -> dict[str, bytes]:
    from test_uff_fuzz import BASES

    return BASES


def test_uff_cut_short_is_refused(tmp_path):
    from analysis.uff import UFFError, read_uff58

    for kind, raw in _uff_bytes().items():
        p = tmp_path / f"{kind}.uff"
        p.write_bytes(raw[: len(raw) // 3])
        with pytest.raises(UFFError, match="cut short"):
            read_uff58(p)
        p.write_bytes(raw)
        assert read_uff58(p).H.shape[0] == 2


def test_uff_wrong_point_count_and_non_finite_values_are_refused(tmp_path):
    from analysis.uff import UFFError, read_uff58

    raw = _uff_bytes()["ascii"]
    for old, new, pattern in ((b"         8", b" 999999999", "claims 999999999 points but it holds 8"),
                              (b"         8", b"        -5", "claims -5 points"),
                              (b"  -1.32104863291e-01", b"                 inf", r"values sample 1 is \(inf"),
                              (b"   6.40422650443e-01", b"                 NaN", r"values sample 2 is \(nan"),
                              (b"2.50000e+00", b"        nan", "abscissa sample 0 is nan")):
        assert old in raw
        p = tmp_path / "bad.uff"
        p.write_bytes(raw.replace(old, new, 1))
        with pytest.raises(UFFError, match=pattern) as err:
            read_uff58(p)
        assert str(p) in str(err.value) and "response 1009:2" in str(err.value)


# -- fit JSON ---------------------------------------------------------------------------------
def _fit_doc() -> dict:
    return {"poles": [{"pole": [-1.0, 60.0]}, {"pole": [-2.0, 120.0]}],
            "residues": [{"output": "a:1:X", "reference": "b:1:X", "values": [[0.0, 1.0], [0.0, 2.0]]}],
            "band": [5.0, 30.0], "quantity": "accelerance"}


def _frf():
    from analysis.frf import FRFSet

    f = np.linspace(1.0, 40.0, 80)
    return FRFSet(f, np.ones((1, 1, f.size), complex), "accelerance", ("a:1:X",), ("b:1:X",), "(m/s^2)/N",
                  None, None, {})


@pytest.mark.parametrize("field, value, pattern", [
    ("pole", [float("nan"), 60.0], r"poles\[0\]\.pole is \(?nan"),
    ("pole", [1.0, 60.0], r"poles\[0\]\.pole .* unstable pole"),
    ("residue", [float("inf"), 0.0], r"residues .* values\[1\] is not a finite"),
    ("band", [30.0, 5.0], r"band \[30.0, 5.0\]"),
])
def test_fit_json_non_finite_or_unstable_values_name_the_field(tmp_path, field, value, pattern):
    from analysis.report_html.sources import ReportInputError, load_fit_json

    doc = _fit_doc()
    if field == "pole":
        doc["poles"][0]["pole"] = value
    elif field == "residue":
        doc["residues"][0]["values"][1] = value
    else:
        doc["band"] = value
    p = tmp_path / "fit.json"
    p.write_text(json.dumps(doc))  # writes NaN / Infinity as Python's json does
    with pytest.raises(ReportInputError, match=pattern) as err:
        load_fit_json(p, _frf())
    assert str(p) in str(err.value)
    p.write_text(json.dumps(_fit_doc()))
    assert load_fit_json(p, _frf()).model.poles.size == 2


def test_deeply_nested_fit_json_is_one_line(tmp_path):
    from analysis.report_html.sources import ReportInputError, load_fit_json

    p = tmp_path / "deep.json"
    p.write_text("[" * 50000 + "]" * 50000)
    with pytest.raises(ReportInputError, match="nested too deeply"):
        load_fit_json(p, _frf())


# -- bounded work -----------------------------------------------------------------------------
def test_model_order_beyond_the_lines_or_the_memory_is_refused_before_allocating(monkeypatch):
    from analysis import work_limits
    from analysis.lscf import lscf_poles_all_orders
    from analysis.work_limits import WorkLimitError, check_model_order

    with pytest.raises(WorkLimitError, match="the band holds 80 lines; the largest accepted here is 39"):
        lscf_poles_all_orders(_frf(), 2000)
    check_model_order(39, 80, 9)  # within both bounds: no error
    monkeypatch.setattr(work_limits, "available_memory_bytes", lambda: 2 * 10 * 2**20)  # 10 MiB usable
    with pytest.raises(WorkLimitError) as err:
        check_model_order(200, 8000, 9)
    largest = int(str(err.value).rsplit("largest accepted here is ", 1)[1].split()[0])
    assert work_limits.lscf_work_bytes(9, largest) <= 10 * 2**20 < work_limits.lscf_work_bytes(9, largest + 1)


@pytest.mark.parametrize("text, pattern", [
    ("[material]\nyoungs_modulus_pa = inf\n", "material.youngs_modulus_pa is not a finite number"),
    ("[components.left]\nn_elements = 1000000\n", "the largest accepted total here is"),
    ("[sensors.accelerometer]\nmass_kg = 1e6\n", "not below the structure's mass"),
    ("a = " + "[" * 50000 + "]" * 50000 + "\n", "nested too deeply"),
])
def test_simulator_config_bounds(tmp_path, text, pattern):
    from simulator.config import ConfigError, FrameConfig

    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=pattern):
        FrameConfig.load(p)


def test_a_report_that_fails_writes_nothing_and_names_the_nan_pole(tmp_path, capsys):
    from analysis.cli_report import main
    from analysis.uff import read_uff58, write_uff58

    uff = tmp_path / "in.uff"
    write_uff58(uff, _frf())
    back = read_uff58(uff)
    fit = tmp_path / "fit.json"
    doc = _fit_doc()
    doc["poles"][1]["pole"] = [float("nan"), 120.0]
    doc["residues"][0].update(output=back.outputs[0], reference=back.references[0])
    fit.write_text(json.dumps(doc))
    out = tmp_path / "report"
    assert main([str(uff), "--out", str(out), "--fit", str(fit)]) == 2
    err = capsys.readouterr().err
    assert f"{fit}: field poles[1].pole is" in err and err.count("\n") == 1
    assert not out.exists() and {p.name for p in tmp_path.iterdir()} == {"fit.json", "in.uff"}


def test_a_report_whose_page_fails_leaves_an_earlier_report_as_it_was(tmp_path, monkeypatch):
    from analysis.report_html import build

    out = tmp_path / "report"
    out.mkdir()
    (out / "index.html").write_text("earlier")

    def broken(doc):
        raise ValueError("Out of range float values are not JSON compliant")

    monkeypatch.setattr(build, "render_page", broken)
    with pytest.raises(ValueError):
        build.write_report(out, {"a": 1})
    assert [p.name for p in out.iterdir()] == ["index.html"] and (out / "index.html").read_text() == "earlier"
    assert [p.name for p in tmp_path.iterdir()] == ["report"]
