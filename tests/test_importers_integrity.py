"""Importers never store data that differ from the file read: what cannot be read faithfully is
refused with one line naming the file, the field and what to do (or read right).

Each test builds the smallest file showing one way data used to be altered silently (exit 0):
complex .mat blocks, an infinite sensitivity, LVM segments at other sample intervals or with their
columns in another order, comma as both separator and decimal mark, a glitch that 16-bit samples
cannot hold beside the rest of the channel, two different UFF records for one pair, SEP005 hits
whose channels come in another order.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.io

from acquisition.cli_import import main as import_main
from acquisition.importers import (
    ImportDataError,
    ImportedTest,
    channel_roles,
    combine_imports,
    read_dataphysics_mat,
    read_lvm,
    read_sep005_test,
    write_imported,
)
from analysis.frf import FRFSet
from analysis.recording import Recording
from analysis.uff import UFFError, read_uff58, write_uff58

FS = 1024.0
N = 256


def pulse_and_response(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A half-sine hammer pulse (N) and a decaying 60 Hz response (g), ``N`` samples at ``FS``."""
    rng = np.random.default_rng(seed)
    f = np.zeros(N)
    f[10:16] = 40.0 * rng.uniform(0.8, 1.2) * np.sin(np.pi * (np.arange(6) + 0.5) / 6)
    t = np.arange(N) / FS
    x = np.where(t >= 10 / FS, np.exp(-8.0 * t) * np.sin(2 * np.pi * 60.0 * (t - 10 / FS)), 0.0)
    return f, x


def lvm_segment(columns: list[tuple[str, str, np.ndarray]], dx: float, sep: str = "\t",
                decimal: str = ".") -> list[str]:
    """The lines of one LVM segment; ``columns`` are (heading, unit label, samples)."""
    def num(v: float) -> str:
        return f"{v:.9f}".replace(".", decimal)

    n_ch = len(columns)
    d = f"{dx:.6E}".replace(".", decimal)
    lines = [sep.join(["Channels", str(n_ch), ""]), sep.join(["Samples"] + [str(N)] * n_ch),
             sep.join(["Y_Unit_Label"] + [u for _, u, _ in columns]),
             sep.join(["Delta_X"] + [d] * n_ch), sep.join(["***End_of_Header***"] + [""] * n_ch),
             sep.join(["X_Value"] + [h for h, _, _ in columns] + ["Comment"])]
    for k in range(N):
        lines.append(sep.join([""] + [num(c[2][k]) for c in columns]))
    return lines + [""]


def write_lvm(path, segments: list[list[str]], sep_name: str = "Tab", decimal: str = ".", key_sep: str = "\t"):
    head = ["LabVIEW Measurement", f"Writer_Version{key_sep}2", f"Separator{key_sep}{sep_name}",
            f"Decimal_Separator{key_sep}{decimal}", f"Multi_Headings{key_sep}Yes", f"X_Columns{key_sep}No",
            "***End_of_Header***", ""]
    path.write_text("\n".join(head + [line for s in segments for line in s]) + "\n", encoding="latin-1")


# --- a. a .mat block with complex values -------------------------------------------------------

def test_mat_block_with_complex_values_is_refused_naming_the_block(tmp_path, capsys):
    f, x = pulse_and_response()
    t = (np.arange(N) - 8) / FS
    p = tmp_path / "cplx.mat"
    scipy.io.savemat(p, {"X1": np.column_stack([t, f]), "X2": np.column_stack([t, x + 0.5j * x]),
                         "Unit": np.array(["N", "g"])})
    with pytest.raises(ImportDataError, match=r"cplx\.mat.*X2.*imaginary"):
        read_dataphysics_mat(p)
    out = tmp_path / "rec.h5"
    assert import_main([str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "X2" in err
    assert not out.exists()


def test_mat_block_with_zero_imaginary_part_is_read_exactly(tmp_path):
    f, x = pulse_and_response()
    t = (np.arange(N) - 8) / FS
    p = tmp_path / "real_as_complex.mat"
    scipy.io.savemat(p, {"X1": np.column_stack([t, f]), "X2": np.column_stack([t, x]).astype(complex),
                         "Unit": np.array(["N", "g"])})
    test = read_dataphysics_mat(p)
    assert np.array_equal(test.hits[0][1], x)


# --- b. an infinite sensitivity ----------------------------------------------------------------

@pytest.mark.parametrize("bad", [np.inf, -np.inf, 0.0])
def test_mat_sensitivity_that_is_not_a_finite_nonzero_number_is_refused(tmp_path, bad):
    f, x = pulse_and_response()
    t = (np.arange(N) - 8) / FS
    p = tmp_path / "sens.mat"
    scipy.io.savemat(p, {"X1": np.column_stack([t, f]), "X2": np.column_stack([t, x]),
                         "Unit": np.array(["N", "g"]), "Sensitivity": np.array([2.25, bad])})
    with pytest.raises(ImportDataError, match=r"sens\.mat.*channel 2.*ensitivity"):
        read_dataphysics_mat(p)


def test_unknown_sensitivity_stays_unknown_and_a_known_one_scales_volts(tmp_path):
    f, x = pulse_and_response()
    t = (np.arange(N) - 8) / FS
    p = tmp_path / "sens.mat"
    scipy.io.savemat(p, {"X1": np.column_stack([t, f]), "X2": np.column_stack([t, x]),
                         "Unit": np.array(["N", "g"]), "Sensitivity": np.array([2.25, np.nan])})
    out = tmp_path / "rec.h5"
    write_imported(read_dataphysics_mat(p), out)
    with Recording(out) as rec:
        hit = rec.hit(0)
        vpc = np.asarray(hit.volts_per_count)
        assert vpc[0] == pytest.approx(hit.eu_per_count[0] * 2.25e-3) and np.isnan(vpc[1])


# --- c. LVM segments at different sample intervals ---------------------------------------------

def test_lvm_segments_with_different_delta_x_are_refused(tmp_path):
    f, x = pulse_and_response()
    cols = [("Force", "Newtons", f), ("Acceleration", "g", x)]
    p = tmp_path / "rates.lvm"
    write_lvm(p, [lvm_segment(cols, 1 / FS), lvm_segment(cols, 2 / FS)])
    with pytest.raises(ImportDataError, match=r"rates\.lvm.*segment 2.*Delta_X"):
        read_lvm(p)


def test_lvm_channels_of_one_segment_with_different_delta_x_are_refused(tmp_path):
    f, x = pulse_and_response()
    seg = lvm_segment([("Force", "Newtons", f), ("Acceleration", "g", x)], 1 / FS)
    seg[3] = "\t".join(["Delta_X", f"{1 / FS:.6E}", f"{0.5 / FS:.6E}"])
    p = tmp_path / "mixed.lvm"
    write_lvm(p, [seg])
    with pytest.raises(ImportDataError, match=r"mixed\.lvm.*segment 1.*Delta_X"):
        read_lvm(p)


# --- d. LVM segments whose columns come in another order ---------------------------------------

def test_lvm_segments_with_swapped_columns_are_matched_by_heading(tmp_path):
    f1, x1 = pulse_and_response(1)
    f2, x2 = pulse_and_response(2)
    p = tmp_path / "swapped.lvm"
    write_lvm(p, [lvm_segment([("Force", "Newtons", f1), ("Acceleration", "g", x1)], 1 / FS),
                  lvm_segment([("Acceleration", "g", x2), ("Force", "Newtons", f2)], 1 / FS)])
    test = read_lvm(p)
    assert [c["quantity"] for c in test.channels] == ["force", "acceleration"]
    assert np.allclose(test.hits[1][0], f2, atol=1e-9) and np.allclose(test.hits[1][1], x2, atol=1e-9)


def test_lvm_segments_with_other_headings_are_refused(tmp_path):
    f, x = pulse_and_response()
    p = tmp_path / "other.lvm"
    write_lvm(p, [lvm_segment([("Force", "Newtons", f), ("Acceleration", "g", x)], 1 / FS),
                  lvm_segment([("Force", "Newtons", f), ("Acceleration 2", "g", x)], 1 / FS)])
    with pytest.raises(ImportDataError, match=r"other\.lvm.*segment 2.*Acceleration 2"):
        read_lvm(p)


def test_lvm_segment_whose_units_change_under_the_same_heading_is_refused(tmp_path):
    f, x = pulse_and_response()
    p = tmp_path / "units.lvm"
    write_lvm(p, [lvm_segment([("A", "Newtons", f), ("B", "g", x)], 1 / FS),
                  lvm_segment([("A", "g", x), ("B", "Newtons", f)], 1 / FS)])
    with pytest.raises(ImportDataError, match=r"units\.lvm.*segment 2.*Y_Unit_Label"):
        read_lvm(p)


# --- e. comma as separator and decimal mark ----------------------------------------------------

def test_lvm_comma_separator_with_decimal_comma_is_refused(tmp_path):
    f, x = pulse_and_response()
    p = tmp_path / "commas.lvm"
    write_lvm(p, [lvm_segment([("Force", "Newtons", f), ("Acceleration", "g", x)], 1 / FS, sep=",", decimal=",")],
              sep_name="Comma", decimal=",")
    with pytest.raises(ImportDataError, match=r"commas\.lvm.*Separator.*Decimal_Separator"):
        read_lvm(p)


@pytest.mark.parametrize("key_sep", ["\t", ","])
def test_lvm_comma_separated_with_decimal_point_reads_the_numbers(tmp_path, key_sep):
    f, x = pulse_and_response()
    p = tmp_path / "csv.lvm"
    write_lvm(p, [lvm_segment([("Force", "Newtons", f), ("Acceleration", "g", x)], 1 / FS, sep=",")],
              sep_name="Comma", key_sep=key_sep)
    test = read_lvm(p)
    assert test.fs_hz == pytest.approx(FS, rel=1e-6)
    assert np.allclose(test.hits[0][0], f, atol=1e-9) and np.allclose(test.hits[0][1], x, atol=1e-9)


# --- f. a glitch 16-bit samples cannot hold beside the rest of the channel ----------------------

def glitch_test(glitch: float) -> ImportedTest:
    f, _ = pulse_and_response()
    t = np.arange(N) / FS
    x = 0.1 * np.sin(2 * np.pi * 60.0 * t)
    x[100] = glitch
    channels = [{"name": "hammer", "quantity": "force", "unit": "N", "sensitivity": np.nan, "point": "n:1:Z"},
                {"name": "acc", "quantity": "acceleration", "unit": "g", "sensitivity": np.nan, "point": "n:2:Z"}]
    return ImportedTest(FS, channels, [np.vstack([f, x])], [], "glitch.lvm", {"format": "lvm"})


def test_a_glitch_that_would_zero_the_rest_of_the_channel_is_refused_and_nothing_written(tmp_path):
    out = tmp_path / "rec.h5"
    with pytest.raises(ImportDataError, match=r"glitch\.lvm: hit 1, channel 2 \(acc\): sample 101 .*1e\+04"):
        write_imported(glitch_test(1e4), out)
    assert not out.exists()


def test_a_modest_peak_keeps_the_rest_of_the_channel_within_the_16_bit_step(tmp_path):
    test = glitch_test(2.0)
    out = tmp_path / "rec.h5"
    write_imported(test, out)
    with Recording(out) as rec:
        stored = rec.hit(0).data[1]
    step = 2.0 / 32767
    assert np.max(np.abs(stored - test.hits[0][1])) <= 0.5 * step * (1 + 1e-9)


# --- g. two different UFF records for one response/reference pair ------------------------------

def one_frf(scale: complex = 1.0) -> FRFSet:
    f = np.linspace(0.0, 100.0, 11)
    H = (scale * (1.0 + 0.1j * f) / (1.0 + f)).reshape(1, 1, -1)
    return FRFSet(freq_hz=f, H=H, quantity="accelerance", outputs=("n:2:Z",), references=("n:1:Z",), unit="g/N")


def uff_with_two_records(path, second: FRFSet) -> None:
    from analysis.uff import _frf_set_dicts

    write_uff58(path, one_frf(), extra_sets=_frf_set_dicts(second, ()))


def test_uff_with_two_different_records_for_one_pair_is_refused_naming_both(tmp_path):
    p = tmp_path / "twice.uff"
    uff_with_two_records(p, one_frf(2.0))
    with pytest.raises(UFFError, match=r"twice\.uff.*records 1 and 2"):
        read_uff58(p)


def test_uff_with_an_identical_repeated_record_reads(tmp_path):
    p = tmp_path / "same.uff"
    uff_with_two_records(p, one_frf())
    s = read_uff58(p)
    assert s.H.shape == (1, 1, 11) and np.array_equal(s.H, one_frf().H)


# --- h. SEP005 hits whose channels come in another order ---------------------------------------

def sep005_doc(groups: list[list[tuple[str, str, np.ndarray]]]) -> list[dict]:
    units = {"f": "N", "a": "g"}
    return [{"name": name, "unit_str": units[q], "quantity": q, "fs": FS, "group": f"hit-{g + 1}",
             "data": data.tolist(), "point": {"hammer": "n:1:Z", "acc": "n:2:Z"}[name]}
            for g, chans in enumerate(groups) for name, q, data in chans]


def test_sep005_channels_are_matched_by_name_in_every_hit(tmp_path):
    f1, x1 = pulse_and_response(1)
    f2, x2 = pulse_and_response(2)
    p = tmp_path / "order.json"
    p.write_text(json.dumps(sep005_doc([[("hammer", "f", f1), ("acc", "a", x1)],
                                        [("acc", "a", x2), ("hammer", "f", f2)]])))
    test = read_sep005_test(p)
    assert [c["name"] for c in test.channels] == ["hammer", "acc"]
    assert np.array_equal(test.hits[1][0], f2) and np.array_equal(test.hits[1][1], x2)
    roles = channel_roles(test)
    assert roles.force_channel == 0 and roles.outputs == ["n:2:Z"]


def test_sep005_hit_with_other_channel_names_is_refused(tmp_path):
    f, x = pulse_and_response()
    doc = sep005_doc([[("hammer", "f", f), ("acc", "a", x)], [("hammer", "f", f), ("acc", "a", x)]])
    doc[3]["name"] = "acc2"
    p = tmp_path / "names.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(ImportDataError, match=r"names\.json.*hit-2.*acc2"):
        read_sep005_test(p)


def test_sep005_channels_of_one_hit_with_different_lengths_are_refused(tmp_path):
    f, x = pulse_and_response()
    doc = sep005_doc([[("hammer", "f", f), ("acc", "a", x[:-10])]])
    p = tmp_path / "short.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(ImportDataError, match=r"short\.json.*acc.*246"):
        read_sep005_test(p)


def test_uff_frfs_of_different_quantities_are_refused(tmp_path):
    mobility = FRFSet(freq_hz=one_frf().freq_hz, H=one_frf().H, quantity="mobility", outputs=("n:3:Z",),
                      references=("n:1:Z",), unit="m/s/N")
    p = tmp_path / "kinds.uff"
    uff_with_two_records(p, mobility)
    with pytest.raises(UFFError, match=r"kinds\.uff: records 1 and 2 .*ordinate_spec_data_type"):
        read_uff58(p)


def test_lvm_segment_shorter_than_its_samples_header_is_refused(tmp_path):
    f, x = pulse_and_response()
    seg = lvm_segment([("Force", "Newtons", f), ("Acceleration", "g", x)], 1 / FS)
    p = tmp_path / "cut.lvm"
    write_lvm(p, [seg[:-50]])
    with pytest.raises(ImportDataError, match=r"cut\.lvm: segment 1 holds 207 rows .*Samples 256"):
        read_lvm(p)


def test_files_of_one_import_with_their_channels_in_another_order_are_refused():
    f, x = pulse_and_response()
    force = {"name": "hammer", "quantity": "force", "unit": "N", "sensitivity": np.nan, "point": "n:1:Z"}
    acc = {"name": "acc", "quantity": "acceleration", "unit": "g", "sensitivity": np.nan, "point": "n:2:Z"}
    a = ImportedTest(FS, [force, acc], [np.vstack([f, x])], [], "a.json")
    b = ImportedTest(FS, [acc, force], [np.vstack([x, f])], [], "b.json")
    assert len(combine_imports([a, a]).hits) == 2
    with pytest.raises(ImportDataError, match=r"b\.json: channel 1 has name 'acc', in a\.json 'hammer'"):
        combine_imports([a, b])


def test_cli_refuses_a_glitch_in_one_line_and_writes_nothing(tmp_path, capsys):
    f, x = pulse_and_response()
    x = 0.1 * x
    x[200] = 1e4
    p = tmp_path / "glitch.lvm"
    write_lvm(p, [lvm_segment([("Force", "Newtons", f), ("Acceleration", "g", x)], 1 / FS)])
    out = tmp_path / "rec.h5"
    assert import_main([str(p), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "channel 2 (ch2): sample 201 is 1e+04" in err
    assert not out.exists()


@pytest.mark.parametrize("peak", [1.7976931348623157e308, 5e-324])
def test_a_peak_16_bit_steps_cannot_scale_is_refused(tmp_path, peak):
    """Found by fuzzing: the largest float overflowed the stored samples to inf, a subnormal one
    divided by a zero step."""
    test = glitch_test(0.1)
    test.hits[0][1] = 0.0
    test.hits[0][1][3] = peak
    out = tmp_path / "rec.h5"
    with pytest.raises(ImportDataError, match=r"glitch\.lvm: hit 1, channel 2 \(acc\): its largest sample is .*units"):
        write_imported(test, out)
    assert not out.exists()
