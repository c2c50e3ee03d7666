"""acquisition.importers: .lvm (decimal comma, segments), DataPhysics .mat, numpy + description."""
from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.io
from scipy import signal

from acquisition.cli_import import main as import_main
from acquisition.importers import (
    ImportDataError,
    ImportedTest,
    channel_roles,
    combine_imports,
    imported_hits,
    load_description,
    quantize,
    read_dataphysics_mat,
    read_lvm,
    read_numpy,
    write_imported,
)
from analysis.recording import Recording, load_frfset

FS = 2048.0
N = 2048


def synthetic_hits(n_hits: int = 3, seed: int = 0, double_at: int = -1):
    """Force pulses into a resonator (100 Hz): returns list of (force, response) and (b, a)."""
    rng = np.random.default_rng(seed)
    b, a = signal.iirpeak(100.0, 20.0, fs=FS)
    hits = []
    for k in range(n_hits):
        f = np.zeros(N)
        f[20:26] = 50 * rng.uniform(0.8, 1.2) * np.sin(np.pi * (np.arange(6) + 0.5) / 6)
        if k == double_at:
            f[60:66] += 0.5 * f[20:26]
        x = signal.lfilter(b, a, f)
        hits.append((f, x))
    return hits, (b, a)


def write_lvm(path, hits, decimal=","):
    lines = ["LabVIEW Measurement\t", "Writer_Version\t2", "Separator\tTab", f"Decimal_Separator\t{decimal}",
             "Multi_Headings\tYes", "X_Columns\tNo", "***End_of_Header***\t", "\t"]
    for f, x in hits:
        dx = f"{1 / FS:.6E}".replace(".", decimal)
        lines += ["Channels\t2\t\t", f"Samples\t{N}\t{N}\t", "Y_Unit_Label\tNewtons\tg\t",
                  "X_Dimension\tTime\tTime\t", f"Delta_X\t{dx}\t{dx}\t", "***End_of_Header***\t\t\t",
                  "X_Value\tForce (Trigger)\tAcceleration (Trigger)\tComment"]
        for fi, xi in zip(f, x):
            lines.append(f"\t{fi:.9f}\t{xi:.9f}".replace(".", decimal))
        lines.append("")
    path.write_text("\n".join(lines) + "\n", encoding="latin-1")


def test_lvm_decimal_comma_segments(tmp_path):
    hits, (b, a) = synthetic_hits(3)
    p = tmp_path / "hits.lvm"
    write_lvm(p, hits)
    t = read_lvm(p)
    assert t.fs_hz == pytest.approx(FS, rel=1e-6)
    assert len(t.hits) == 3 and t.hits[0].shape == (2, N)
    assert [c["quantity"] for c in t.channels] == ["force", "acceleration"]
    assert [c["unit"] for c in t.channels] == ["N", "g"]
    assert np.allclose(t.hits[1][0], hits[1][0], atol=1e-9)
    out = tmp_path / "rec.h5"
    write_imported(t, out, reference="n:1:Z", outputs=["n:2:Z"])
    s = load_frfset(out)
    assert s.unit == "g/N" and s.meta["n_averages"] == [3]
    _, H = signal.freqz(b, a, worN=s.freq_hz, fs=FS)
    band = (s.freq_hz > 50) & (s.freq_hz < 150)
    # 16-bit requantisation of the import: relative error ~1e-4 where the response is strong
    assert np.max(np.abs(s.H[0, 0, band] - H[band]) / np.abs(H[band])) < 2e-3


def test_imported_hits_are_the_blocks_quantised_with_their_roles_and_triggers():
    """Each block becomes one Hit: int16 counts within a count of the float data, the file's trigger
    where it has one, else the sample the force first reaches 10 % of its peak."""
    hits, _ = synthetic_hits(2)
    chans = [{"name": "F", "quantity": "force", "unit": "N", "sensitivity": 2.25, "point": "n:1:Z"},
             {"name": "A", "quantity": "acceleration", "unit": "g", "sensitivity": float("nan"), "point": "n:2:Z"}]
    test = ImportedTest(FS, chans, [np.vstack(h) for h in hits], [], "synthetic")
    out = imported_hits(test, channel_roles(test, outputs=["n:3:Y"]))
    assert [h.sequence for h in out] == [0, 1] and all(h.sample_rate_hz == FS for h in out)
    for h, (f, x) in zip(out, hits):
        assert h.counts.dtype == np.int16 and (h.force_channel, list(h.response_channels)) == (0, [1])
        assert (h.reference, list(h.outputs), h.channel_names) == ("n:1:Z", ["n:3:Y"], ("F", "A"))
        assert np.max(np.abs(h.force - f)) <= 0.5 * h.eu_per_count[0] * (1 + 1e-12)
        assert np.max(np.abs(h.responses[0] - x)) <= 0.5 * h.eu_per_count[1] * (1 + 1e-12)
        assert h.trigger_index == int(np.argmax(np.abs(f) >= 0.1 * np.abs(f).max()))
        assert h.volts_per_count[0] == pytest.approx(h.eu_per_count[0] * 2.25e-3) and np.isnan(h.volts_per_count[1])
    given = imported_hits(ImportedTest(FS, chans, test.hits, [7, 9], "synthetic"), channel_roles(test))
    assert [h.trigger_index for h in given] == [7, 9]


def test_combined_files_keep_the_leading_triggers_and_refuse_other_shapes():
    chans = [{"name": "F", "quantity": "force", "unit": "N", "sensitivity": float("nan"), "point": "n:1:Z"}]
    one = ImportedTest(FS, chans, [np.ones((1, 8))], [3], "a")
    none = ImportedTest(FS, chans, [np.ones((1, 8))], [], "b")
    both = combine_imports([one, one, none])
    assert len(both.hits) == 3 and both.trigger_indices == [3, 3] and both.source == "a"
    assert combine_imports([none, one]).trigger_indices == []
    with pytest.raises(ImportDataError, match="differs in sample rate or block size"):
        combine_imports([one, ImportedTest(FS, chans, [np.ones((1, 9))], [], "c")])


def test_lvm_double_hit_is_stored_rejected(tmp_path):
    hits, _ = synthetic_hits(3, double_at=1)
    p = tmp_path / "hits.lvm"
    write_lvm(p, hits, decimal=".")
    out = tmp_path / "rec.h5"
    averages = write_imported(read_lvm(p), out)
    assert averages[0].n_averages == 2
    with Recording(out) as rec:
        flags = [(h.accepted, h.reasons) for h in rec.hits()]
    assert flags[0] == (True, []) and flags[2] == (True, [])
    assert flags[1][0] is False and "double hit" in flags[1][1][0]


def test_lvm_bad_files(tmp_path):
    p = tmp_path / "x.lvm"
    p.write_text("not labview\n")
    with pytest.raises(ImportDataError, match="not a LabVIEW"):
        read_lvm(p)
    with pytest.raises(ImportDataError, match="cannot read"):
        read_lvm(tmp_path / "missing.lvm")


def test_dataphysics_mat(tmp_path):
    hits, (b, a) = synthetic_hits(1)
    f, x = hits[0]
    t = (np.arange(N) - 10) / FS
    sens = np.array([[2.25], [100.0]])
    p = tmp_path / "DPsv00001.mat"
    scipy.io.savemat(p, {"X1": np.column_stack([t, f]), "X2": np.column_stack([t, x]), "W1": np.column_stack([t, f]),
                         "W2": np.column_stack([t, x]), "Sensitivity": sens, "Unit": np.array(["N", "g"])})
    test = read_dataphysics_mat(p)
    assert test.fs_hz == pytest.approx(FS)
    assert test.trigger_indices == [10]
    assert [c["sensitivity"] for c in test.channels] == [2.25, 100.0]
    out = tmp_path / "rec.h5"
    write_imported(test, out)
    with Recording(out) as rec:
        h = rec.hit(0)
        assert np.allclose(h.volts_per_count, h.eu_per_count * np.array([2.25, 100.0]) * 1e-3)
        assert h.trigger_index == 10
    with pytest.raises(ImportDataError, match="no 'X1..Xn'"):
        bad = tmp_path / "bad.mat"
        scipy.io.savemat(bad, {"Y": np.zeros(3)})
        read_dataphysics_mat(bad)


def test_numpy_with_description(tmp_path):
    hits, _ = synthetic_hits(2)
    files = []
    for k, (f, x) in enumerate(hits):
        path = tmp_path / f"hit{k}.npy"
        np.save(path, np.vstack([np.arange(N) / FS, f, x]))
        files.append(path)
    desc = {"time_row": 0, "channels": [{"name": "hammer", "unit": "N", "point": "top:4:Z"},
                                        {"name": "acc", "unit": "m/s^2", "point": "left:9:Y"}]}
    dpath = tmp_path / "desc.json"
    dpath.write_text(json.dumps(desc))
    t = read_numpy(files, load_description(dpath))
    assert t.fs_hz == pytest.approx(FS) and len(t.hits) == 2 and t.hits[0].shape == (2, N)
    out = tmp_path / "rec.h5"
    write_imported(t, out)
    s = load_frfset(out)
    assert s.references == ("top:4:Z",) and s.outputs == ("left:9:Y",) and s.unit == "(m/s^2)/N"
    with pytest.raises(ImportDataError, match="channels"):
        read_numpy(files, {"sample_rate_hz": FS})
    with pytest.raises(ImportDataError, match="sample_rate_hz"):
        read_numpy(files, {"channels": desc["channels"] + [{"name": "t"}]})


def test_quantize_error_bound():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(3, 1000)) * np.array([[1.0], [1e-3], [50.0]])
    counts, eu = quantize(d)
    assert counts.dtype == np.int16
    assert np.all(np.abs(counts * eu[:, None] - d) <= 0.5 * eu[:, None] * (1 + 1e-9))
    assert np.all(np.abs(counts).max(axis=1) == 32767)


def test_cli_import_bad_input_exit_2(tmp_path, capsys):
    p = tmp_path / "x.txt"
    p.write_text("hello")
    assert import_main([str(p), "--out", str(tmp_path / "r.h5")]) == 2
    assert "unknown input format" in capsys.readouterr().err
    assert import_main([str(tmp_path / "x.npy"), "--out", str(tmp_path / "r.h5")]) == 2
    assert "--describe" in capsys.readouterr().err


def test_cli_import_lvm(tmp_path, capsys):
    hits, _ = synthetic_hits(2)
    p = tmp_path / "hits.lvm"
    write_lvm(p, hits)
    out = tmp_path / "rec.h5"
    assert import_main([str(p), "--out", str(out), "--reference", "top:4:Z", "--outputs", "left:9:Y",
                        "--force-window", "10ms,2ms"]) == 0
    assert "imported 2 accepted hit(s)" in capsys.readouterr().out
    s = load_frfset(out)
    assert s.references == ("top:4:Z",) and s.outputs == ("left:9:Y",)
    with Recording(out) as rec:
        assert rec.windows.force_width_s == pytest.approx(0.01)
    assert import_main([str(p), "--out", str(out)]) == 2  # exists


def test_import_help_examples_are_valid_and_every_option_is_explained(capsys):
    import shlex

    from acquisition.cli_import import build_parser
    from analysis.command_examples import EXAMPLES

    parser = build_parser()
    assert all(a.help for a in parser._actions), [a.dest for a in parser._actions if not a.help]
    examples = EXAMPLES["python -m acquisition import"]
    assert examples
    for line in examples:
        args = parser.parse_args(shlex.split(line)[1:])  # an invalid --format choice would exit here
        assert args.out


def test_import_says_which_channel_became_the_force_and_the_labels(tmp_path, capsys):
    hits, _ = synthetic_hits(2)
    p = tmp_path / "hits.lvm"
    write_lvm(p, hits)
    out = tmp_path / "rec.h5"
    assert import_main([str(p), "--out", str(out), "--reference", "n:7:Z", "--outputs", "n:8:Y"]) == 0
    text = capsys.readouterr().out
    assert "force: channel 1 'ch1' [N] -> n:7:Z" in text
    assert "response: channel 2 'ch2' [g] -> n:8:Y" in text
    with Recording(out) as rec:
        assert any("force: channel 1" in e[2] for e in rec.events())
