"""UFF 58 round trip of what a fit needs beyond the numbers: the exponential window (ID line 3,
``exp_window_tau_s=<tau>``) and every point label the project makes (ID line 4, node numbers of
their own for labels that are not ``component:node:direction``)."""
from __future__ import annotations

import logging
import warnings

import numpy as np
import pytest
import pyuff

from acquisition.cli_export import main as export_main
from analysis.frf import FRFSet
from analysis.pipeline import fit_auto
from analysis.points import FREE_NODE_BASE, label_direction, uff_dofs
from analysis.recording import load_frfset
from analysis.uff import UFFError, read_uff55, read_uff58, write_uff55, write_uff58

#: labels of the simulated frame and of the validation loaders (an F-16 shaker test, a plate swept by
#: a shaker and seen by a vibrometer's view)
FRAME = ("left:9:Y", "top:4:X", "right:4:-Z", "right:6:-X")
LOADERS = ("f16:1:Z", "f16:shaker:Z", "view0:acc:Z", "view0:shaker:Z", "view0:acc:-X")


def frf_set(outputs: tuple, references: tuple, tau: float | None = 0.3141592653589793, seed: int = 0) -> FRFSet:
    rng = np.random.default_rng(seed)
    f = np.arange(1, 257) * 0.5
    shape = (len(outputs), len(references), f.size)
    H = rng.normal(size=shape) + 1j * rng.normal(size=shape)
    return FRFSet(f, H, "accelerance", outputs, references, "(m/s^2)/N", rng.uniform(size=shape), tau,
                  {"estimator": "H1", "n_averages": 3})


@pytest.fixture(scope="module")
def capture_and_export(tmp_path_factory, sim_capture):
    """A roving-hammer capture on the simulated frame with an exponential window (5 % at the block
    end), exported by the project's own command."""
    from conftest import TWO_POINTS_EXP

    rec, uff = sim_capture(*TWO_POINTS_EXP), tmp_path_factory.mktemp("uffwin") / "rec.uff"
    assert export_main([str(rec), "--uff", str(uff)]) == 0
    return rec, uff


def test_exported_uff_is_fitted_with_the_recordings_damping(capture_and_export):
    """capture -> export UFF -> fit both: the window comes back exactly, so the fit removes the same
    apparent damping and both give the same modes (without it the UFF fit reported about 3.6 %
    for 0.4 %)."""
    rec, uff = capture_and_export
    a, b = load_frfset(rec), read_uff58(uff)
    assert a.exp_window_tau_s is not None and b.exp_window_tau_s == a.exp_window_tau_s
    assert b.outputs == a.outputs and b.references == a.references and np.array_equal(a.H, b.H)
    band = (30.0, 300.0)
    fa, fb = fit_auto(a, band=band), fit_auto(b, band=band)
    assert fa.lsfd.freq_hz.size >= 5 and fb.lsfd.freq_hz.size == fa.lsfd.freq_hz.size
    assert np.allclose(fb.lsfd.freq_hz, fa.lsfd.freq_hz, rtol=1e-9)
    assert np.allclose(fb.lsfd.damping, fa.lsfd.damping, rtol=1e-6)
    # and these are the structure's damping (the frame's modes are near 0.6 %), not the window's
    assert float(np.median(fb.lsfd.damping)) < 0.008


def test_window_is_a_key_in_id_line_3(capture_and_export):
    _, uff = capture_and_export
    frfs = [d for d in pyuff.UFF(str(uff)).read_sets() if d["func_type"] == 4]
    tau = load_frfset(capture_and_export[0]).exp_window_tau_s
    assert all(d["id3"].startswith(f"exp_window_tau_s={tau!r}; ") for d in frfs)


def test_no_window_is_written_as_none_and_read_back_as_none(tmp_path):
    p = tmp_path / "f.uff"
    write_uff58(p, frf_set(FRAME[:2], FRAME[3:], tau=None), id_lines=("t", "windows: none", "src"))
    assert all(d["id3"].startswith("exp_window_tau_s=none") for d in pyuff.UFF(str(p)).read_sets())
    assert read_uff58(p).exp_window_tau_s is None


def test_a_long_window_description_never_cuts_the_key(tmp_path):
    p = tmp_path / "f.uff"
    write_uff58(p, frf_set(FRAME[:1], FRAME[3:]), id_lines=("t", "windows: " + "x" * 200, "src"))
    d = pyuff.UFF(str(p)).read_sets()[0]
    assert len(d["id3"]) <= 80 and read_uff58(p).exp_window_tau_s == 0.3141592653589793


def _rewrite_id3(path, make) -> None:
    """Rewrite every FRF record's ID line 3 (``make(k)`` for the k-th record) of a written file."""
    sets = pyuff.UFF(str(path)).read_sets()
    k = 0
    for d in sets:
        if d["func_type"] == 4:
            d["id3"] = make(k)
            k += 1
    path.unlink()
    with warnings.catch_warnings():   # pyuff leaves its file handle open, released when the call returns
        warnings.simplefilter("ignore", ResourceWarning)
        pyuff.UFF(str(path)).write_sets(sets, "add")


def test_windows_in_words_of_older_files_are_read(tmp_path):
    """Files written before the key name the window only in words (``exp tau 0.25 s``)."""
    p = tmp_path / "old.uff"
    write_uff58(p, frf_set(FRAME[:2], FRAME[3:]))
    _rewrite_id3(p, lambda k: "windows: force 10 ms + 2 ms taper; exp tau 0.25 s")
    assert read_uff58(p).exp_window_tau_s == 0.25


def test_a_bad_or_mixed_window_is_a_clear_error(tmp_path):
    p = tmp_path / "bad.uff"
    write_uff58(p, frf_set(FRAME[:2], FRAME[3:]))
    _rewrite_id3(p, lambda k: "exp_window_tau_s=-1; windows")
    with pytest.raises(UFFError, match="ID line 3 .*exp_window_tau_s='-1', not a positive time"):
        read_uff58(p)
    _rewrite_id3(p, lambda k: "exp_window_tau_s=0.5" if k == 0 else "exp_window_tau_s=none")
    with pytest.raises(UFFError, match="different exponential windows"):
        read_uff58(p)


@pytest.mark.parametrize("outputs,references", [
    (("f16:1:Z", "f16:2:Z", "f16:3:Z"), ("f16:shaker:Z",)),
    (("view0:acc:Z",), ("view0:shaker:Z",)),
    (FRAME[:3] + ("view0:acc:Z", "view0:acc:-X"), (FRAME[3], "f16:shaker:Z")),
])
def test_every_label_the_project_makes_is_written_and_read_back_exactly(tmp_path, outputs, references):
    s = frf_set(outputs, references)
    p = tmp_path / "labels.uff"
    write_uff58(p, s, id_lines=("t", "w", "src"))
    back = read_uff58(p)
    assert back.outputs == s.outputs and back.references == s.references
    assert np.array_equal(back.H, s.H) and np.array_equal(back.coherence, s.coherence)
    dofs = {(d["rsp_node"], d["rsp_dir"]) for d in pyuff.UFF(str(p)).read_sets()}
    assert len(dofs) == len(outputs)   # one degree of freedom per output label


def test_labels_get_distinct_degrees_of_freedom():
    dofs = uff_dofs(FRAME + LOADERS + ("n:1009:Y",))
    assert dofs["left:9:Y"] == (1009, 2) and dofs["right:6:-X"] == (3006, -1)   # the documented numbers stay
    assert len(set(dofs.values())) == len(dofs)       # n:1009:Y is left:9:Y's DOF by number: it moves
    assert dofs["n:1009:Y"][0] >= FREE_NODE_BASE
    assert dofs["view0:acc:Z"][0] == dofs["view0:acc:-X"][0] >= FREE_NODE_BASE   # one location, one node
    assert (label_direction("view0:acc:-X"), label_direction("f16:shaker:Z"), label_direction("hammer")) == (-1, 3, 3)
    assert uff_dofs(["f16:shaker:Z"]) == {"f16:shaker:Z": dofs["f16:shaker:Z"]}   # stable: from the name


def test_same_dof_by_number_reads_back_as_two_labels(tmp_path):
    s = frf_set(("left:9:Y", "n:1009:Y"), ("right:6:-X",))
    p = tmp_path / "clash.uff"
    write_uff58(p, s)
    back = read_uff58(p)
    assert back.outputs == s.outputs and np.array_equal(back.H, s.H)


def test_labels_too_long_for_the_id_line_read_back_from_the_nodes(tmp_path, caplog):
    long_label = "a_very_long_component_name_of_some_tool:" + "x" * 40 + ":Z"
    s = frf_set((long_label,), ("right:6:-X",))
    p = tmp_path / "long.uff"
    with caplog.at_level(logging.WARNING, logger="analysis.uff"):
        write_uff58(p, s)
    assert "do not fit a UFF ID line" in caplog.text
    back = read_uff58(p)
    assert back.outputs == (f"n:{uff_dofs([long_label])[long_label][0]}:Z",) and back.references == ("right:6:-X",)


def test_shapes_of_any_label_are_written(tmp_path):
    rng = np.random.default_rng(4)
    points = ("f16:1:Z", "view0:acc:Z", "view0:acc:-X", "left:9:Y")
    phi = rng.normal(size=(4, 2)) + 1j * rng.normal(size=(4, 2))
    p = tmp_path / "shapes.uff"
    assert write_uff55(p, np.array([-1 + 100j, -2 + 300j]), phi, points) == 2
    _, nodes, shapes = read_uff55(p)
    dofs = uff_dofs(points)
    view = list(nodes).index(dofs["view0:acc:Z"][0])
    assert nodes.size == 3 and np.allclose(shapes[view, 2], phi[1], rtol=1e-5)
    assert np.allclose(shapes[view, 0], -phi[2], rtol=1e-5)
