"""The ULiege plane's 74-point roving test through ``acquisition import --points`` and ``analysis fit``: the
second lab's packed measurements written back out as the lab's DataPhysics files
(benchmarks/studies/uliege_roving_files.py, into a temporary folder), imported with the point map from
``node_shock.csv``, fitted as the 222-FRF set is. Skips without the shared data."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

_ROOT = str(Path(__file__).resolve().parents[1])
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)

from benchmarks.studies import uliege_roving_files as rv  # noqa: E402


def _folder(shared_data: Path) -> Path:
    d = shared_data / rv.FOLDER
    if not (d / "sec_lab_all_H1_coh_time.npz").is_file() or not (d / "sec_lab_original").is_dir():
        pytest.skip(f"{d} holds not the packed second-lab measurements and the original files")
    return d


def _import(points: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from acquisition.cli_import import main as import_main

    assert import_main(["--points", str(points), "--analyser-exp-window", rv.EXP_WINDOW_OPTION,
                        "--out", str(out)]) == 0, capsys.readouterr().err


@pytest.mark.realdata
def test_written_lab_files_equal_the_originals_and_the_map_imports_222_labelled_frfs(shared_data, tmp_path, capsys):
    """The three files the shared data hold are written back equal in every variable written (so the other 71
    are the lab's files too), and the 74 files with the map import as one recording of 3 outputs x 74 hammer
    points, each labelled by its row of node_shock.csv (the last six struck in x), H1 and coherence as packed."""
    import scipy.io

    from analysis.recording import load_frfset

    folder = _folder(shared_data)
    points = rv.write_lab_files(shared_data, tmp_path / "files")
    rows = points.read_text(encoding="utf-8").splitlines()
    assert len(rows) == 75 and rows[1].endswith(",plane:1:Z,acc:1:Z;acc:2:Z;acc:3:Z")
    assert rows[-1].split(",")[1] == "plane:74:X" and rows[68].split(",")[1] == "plane:68:Z"
    for orig in sorted((folder / "sec_lab_original").glob("DPsv*.mat")):
        mine = tmp_path / "files" / orig.name
        if not mine.exists():
            continue   # a file of undocumented purpose (not an impact point)
        a, b = scipy.io.loadmat(str(orig)), scipy.io.loadmat(str(mine))
        written = [k for k in b if not k.startswith("__") and k != "DP_Info"]
        assert len(written) == 4 + 4 + 3 + 3 + 5, written
        for k in written:
            assert np.array_equal(np.asarray(a[k]), np.asarray(b[k])), k
        info = [str(x).strip() for x in np.ravel(b["DP_Info"])]
        assert "Signal H1_2" in info and "Signal S1" not in info
    rec = tmp_path / "plane74.h5"
    _import(points, rec, capsys)
    frf = load_frfset(rec)
    assert frf.H.shape == (3, 74, 1601) and frf.outputs == rv.OUTPUTS
    assert frf.references[0] == "plane:1:Z" and frf.references[28] == "plane:29:Z"
    assert frf.references[-1] == "plane:74:X"
    d = np.load(folder / "sec_lab_all_H1_coh_time.npz")
    i = list(d["file_id"]).index(31)
    k = frf.references.index("plane:29:Z")
    assert np.allclose(frf.coherence[:, k, :], d["coherence"][i], atol=1e-6)
    assert frf.exp_window_tau_s is not None and frf.exp_window_tau_s > 0


@pytest.mark.realdata
@pytest.mark.long
def test_74_files_and_the_point_map_fit_thirteen_modes_and_a_success(shared_data, tmp_path, capsys):
    """``acquisition import`` of the 74 written files with the map, then the automatic fit (about 40 s): the
    plane's 13 accepted modes, nothing spurious (no 190 Hz pole), a success, as the 222-FRF set read directly."""
    from analysis.pipeline import fit_auto
    from analysis.recording import load_frfset
    from benchmarks.accuracy.validation.key import KEYS, score

    _folder(shared_data)
    points = rv.write_lab_files(shared_data, tmp_path / "files")
    rec = tmp_path / "plane74.h5"
    _import(points, rec, capsys)
    res = fit_auto(load_frfset(rec))
    s = score(KEYS["uliege_plane"], res.freq_hz, res.success)
    assert s["fitted"] == 13 and s["spurious"] == [], s
    assert res.success and s["honest"], res.problems
