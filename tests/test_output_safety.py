"""An output never replaces an input: every command with an output option refuses, before anything
is opened for writing, an output that is one of its inputs (the same path, a symbolic link or a hard
link to it), with one line and exit 2, and the input stays byte for byte as it was. ``report --out``
never replaces report files already in the folder unless ``--overwrite``, and never an input."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from acquisition.cli_capture import main as capture_main
from acquisition.cli_export import main as export_main
from acquisition.cli_import import main as import_main
from acquisition.cli_replay import main as replay_main
from acquisition.cli_station import main as station_main
from analysis.cli_batch import main as batch_main
from analysis.cli_diagnose import main as diagnose_main
from analysis.cli_fit import main as fit_main
from analysis.cli_linearity import main as linearity_main
from analysis.cli_report import main as report_main
from analysis.cli_stabilization import main as stabilization_main
from analysis.outputs import check_outputs, same_file


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """One small capture on the simulated frame (1 point x 2 hits)."""
    rec = tmp_path_factory.mktemp("rec") / "rec.h5"
    assert capture_main(["--device", "sim://", "--seed", "2", "--out", str(rec), "--hits", "2", "--auto", "-q"]) == 0
    return rec


@pytest.fixture
def rec(recording, tmp_path) -> Path:
    """A fresh copy of the recording in this test's folder."""
    path = tmp_path / "rec.h5"
    shutil.copyfile(recording, path)
    return path


def link(kind: str, target: Path, name: str) -> Path:
    """``target`` itself, or a symbolic or hard link to it named ``name`` beside it."""
    if kind == "same":
        return target
    path = target.with_name(name)
    if kind == "symlink":
        path.symlink_to(target.name)
    else:
        os.link(target, path)
    return path


def refused(capsys, code: int, protected: Path, before: str) -> str:
    """The command ended with exit 2 and one line saying the output is an input; the input is unchanged."""
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, err
    assert len(err) == 1 and "is the input" in err[0] and "never replaces an input" in err[0], err
    assert protected.is_file() and sha(protected) == before
    return err[0]


FACES: dict[str, Callable[[Path, Path], list[str]]] = {
    "export --uff": lambda rec, out: [str(rec), "--uff", str(out), "--overwrite"],
    "export --sep005": lambda rec, out: [str(rec), "--sep005", str(out), "--overwrite"],
    "fit --json": lambda rec, out: [str(rec), "--json", str(out), "--overwrite"],
    "fit --plot": lambda rec, out: [str(rec), "--plot", str(out), "--overwrite"],
    "fit --uff": lambda rec, out: [str(rec), "--uff", str(out), "--overwrite"],
    "stabilization --png": lambda rec, out: [str(rec), "--png", str(out)],
    "stabilization --json": lambda rec, out: [str(rec), "--png", str(out.with_name("s.png")), "--json", str(out)],
    "linearity --json": lambda rec, out: [str(rec), str(rec.with_name("level2.h5")), "--levels", "1,2", "--json",
                                          str(out)],
    "diagnose --json": lambda rec, out: ["--measured", str(rec), "--simulated", str(rec.with_name("sim.h5")), "--json",
                                         str(out)],
    "replay --out": lambda rec, out: [str(rec), "--out", str(out), "--overwrite"],
    "capture --out": lambda rec, out: ["--device", f"sim://?replay={rec}", "--out", str(out), "--overwrite", "--auto",
                                       "-q"],
}
MAINS = {"export": export_main, "fit": fit_main, "stabilization": stabilization_main, "linearity": linearity_main,
         "diagnose": diagnose_main, "replay": replay_main, "capture": capture_main}


@pytest.mark.parametrize("kind", ["same", "symlink", "hardlink"])
@pytest.mark.parametrize("face", list(FACES))
def test_an_output_that_is_the_input_is_refused_and_the_input_kept(rec, capsys, face, kind):
    for name in ("level2.h5", "sim.h5"):  # the second input of linearity and diagnose
        shutil.copyfile(rec, rec.with_name(name))
    before = sha(rec)
    out = link(kind, rec, "out.h5")
    code = MAINS[face.split()[0]](FACES[face](rec, out))
    refused(capsys, code, rec, before)


@pytest.mark.parametrize("kind", ["same", "symlink", "hardlink"])
def test_diagnose_report_folder_never_replaces_the_measured_input(rec, capsys, kind):
    folder = rec.parent / "diag"
    folder.mkdir()
    shutil.copyfile(rec, rec.with_name("sim.h5"))
    if kind == "same":
        measured = folder / "diagnosis.json"
        shutil.copyfile(rec, measured)
    else:
        measured = rec
        (folder / "diagnosis.json").symlink_to(rec) if kind == "symlink" else os.link(rec, folder / "diagnosis.json")
    before = sha(measured)
    code = diagnose_main(["--measured", str(measured), "--simulated", str(rec.with_name("sim.h5")), "--json",
                          str(rec.with_name("d.json")), "--report", str(folder)])
    refused(capsys, code, measured, before)


def test_import_refuses_an_output_that_is_one_of_its_files(tmp_path, capsys):
    src = tmp_path / "test.json"
    src.write_text(json.dumps([{"name": "force", "data": [0.0, 1.0, 0.0, 0.0], "fs": 100.0, "unit_str": "N"}]))
    before = sha(src)
    for out in (src, link("symlink", src, "rec.h5")):
        refused(capsys, import_main([str(src), "--out", str(out), "--overwrite"]), src, before)


def test_station_and_batch_refuse_an_output_that_is_an_input(rec, tmp_path, capsys):
    setup = tmp_path / "setup.toml"
    setup.write_text("# the user's set-up\n")
    before = sha(setup)
    code = station_main(["--device", "sim://", "--out", str(link("hardlink", setup, "st.h5")), "--setup", str(setup),
                         "--overwrite"])
    refused(capsys, code, setup, before)
    out = tmp_path / "fleet"
    out.mkdir()
    reference = out / "fleet.json"  # the reference fit kept where the batch writes its fleet.json
    reference.write_text('{"poles": []}\n')
    before = sha(reference)
    refused(capsys, batch_main([str(rec), "--out", str(out), "--reference", str(reference)]), reference, before)


def test_two_outputs_on_one_file_are_refused(rec, capsys):
    code = export_main([str(rec), "--uff", str(rec.with_name("x.out")), "--sep005", str(rec.with_name("x.out"))])
    err = capsys.readouterr().err
    assert code == 2 and "is also given as the output" in err and not rec.with_name("x.out").exists()


def test_check_outputs_compares_files_not_names(tmp_path):
    a = tmp_path / "a.h5"
    a.write_bytes(b"x")
    (tmp_path / "sub").mkdir()
    assert same_file(a, tmp_path / "sub" / ".." / "a.h5") and not same_file(a, tmp_path / "missing")
    check_outputs([tmp_path / "new.json", None], [a, None])  # a new file and options not given: fine
    with pytest.raises(ValueError, match="through a link"):
        check_outputs([link("symlink", a, "b.h5")], [a])


def test_report_into_a_folder_keeps_the_users_files_unless_overwrite(rec, tmp_path, capsys):
    out = tmp_path / "site"
    out.mkdir()
    (out / "index.html").write_text("<p>my own page</p>\n")
    (out / "report.css").write_text("body {}\n")
    code = report_main([str(rec), "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "already holds index.html, report.css" in err[0] and "--overwrite" in err[0]
    assert (out / "index.html").read_text() == "<p>my own page</p>\n" and (out / "report.css").read_text() == "body {}\n"
    assert sorted(p.name for p in out.iterdir()) == ["index.html", "report.css"]

    fit = tmp_path / "fit.json"  # with --overwrite, still never a file that is an input
    (out / "index.html").unlink()
    fit.write_text('{"poles": []}\n')
    os.link(fit, out / "index.html")
    before = sha(fit)
    code = report_main([str(rec), "--out", str(out), "--fit", str(fit), "--overwrite"])
    refused(capsys, code, fit, before)
