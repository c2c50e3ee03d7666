"""analysis.uff: UFF 58 FRF/coherence/time round trips through pyuff, UFF 55 shapes, bad files."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import pyuff

from analysis.frf import FRFSet
from analysis.points import uff_direction, uff_node
from analysis.uff import UFFError, read_uff55, read_uff58, time_records, write_uff55, write_uff58

OUTS = ("left:9:Y", "top:4:X", "right:4:-Z")
REFS = ("right:6:-X", "top:2:Z")


def example_set(seed: int = 0) -> FRFSet:
    rng = np.random.default_rng(seed)
    f = np.arange(0, 200.0, 0.78125)
    H = rng.normal(size=(3, 2, f.size)) + 1j * rng.normal(size=(3, 2, f.size))
    C = rng.uniform(size=(3, 2, f.size))
    return FRFSet(f, H, "accelerance", OUTS, REFS, "(m/s^2)/N", C, 0.25, {"estimator": "H1", "n_averages": [5, 4]})


def test_frf_and_coherence_round_trip_exact(tmp_path):
    s = example_set()
    p = tmp_path / "frf.uff"
    n = write_uff58(p, s, id_lines=("impactlab FRF", "windows: exp tau 0.25 s", "test"))
    assert n == 12
    back = read_uff58(p)
    assert back.outputs == OUTS and back.references == REFS
    assert np.array_equal(back.H, s.H) and np.array_equal(back.coherence, s.coherence)
    assert np.allclose(back.freq_hz, s.freq_hz, rtol=0, atol=1e-9)
    assert back.quantity == "accelerance" and back.unit == "(m/s^2)/N"


def test_records_carry_nodes_directions_and_id_lines(tmp_path):
    s = example_set()
    p = tmp_path / "frf.uff"
    write_uff58(p, s, id_lines=("impactlab FRF", "windows: exp tau 0.25 s", "src"))
    sets = pyuff.UFF(str(p)).read_sets()
    frf = [d for d in sets if d["func_type"] == 4]
    coh = [d for d in sets if d["func_type"] == 6]
    assert len(frf) == 6 and len(coh) == 6
    d = frf[0]
    assert (d["rsp_node"], d["rsp_dir"]) == (uff_node(OUTS[0]), uff_direction(OUTS[0])) == (1009, 2)
    assert (d["ref_node"], d["ref_dir"]) == (3006, -1)
    assert d["ordinate_spec_data_type"] == 12 and d["orddenom_spec_data_type"] == 13
    assert "exp tau 0.25 s" in d["id3"] and "H1" in d["id2"] and "averages 5" in d["id2"]
    assert "out=left:9:Y ref=right:6:-X" in d["id4"]


def test_missing_pairs_are_skipped_and_read_back_as_nan(tmp_path):
    s = example_set()
    H = s.H.copy()
    H[1, 1] = np.nan
    s2 = FRFSet(s.freq_hz, H, s.quantity, s.outputs, s.references, s.unit)
    p = tmp_path / "frf.uff"
    assert write_uff58(p, s2) == 5
    back = read_uff58(p)
    assert np.all(np.isnan(back.H[1, 1])) and np.array_equal(back.H[0, 1], s.H[0, 1])


def test_time_records(tmp_path):
    rng = np.random.default_rng(1)
    data = rng.normal(size=(2, 100))
    sets = time_records(data, 1000.0, ["right:6:-X", "left:9:Y"], ["N", "m/s^2"], "right:6:-X", t0_s=-0.01)
    p = tmp_path / "t.uff"
    write_uff58(p, None, extra_sets=sets)
    back = pyuff.UFF(str(p)).read_sets()
    assert [d["func_type"] for d in back] == [1, 1]
    assert np.array_equal(back[1]["data"], data[1])
    assert back[0]["ordinate_spec_data_type"] == 13 and back[1]["ordinate_spec_data_type"] == 12
    assert back[0]["x"][0] == pytest.approx(-0.01) and back[0]["x"][1] - back[0]["x"][0] == pytest.approx(1e-3)


def test_uff55_shapes_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    poles = np.array([-1 + 100j, -3 + 400j])
    phi = rng.normal(size=(3, 2)) + 1j * rng.normal(size=(3, 2))
    p = tmp_path / "shapes.uff"
    assert write_uff55(p, poles, phi, OUTS) == 2
    lam, nodes, shapes = read_uff55(p)
    assert np.allclose(lam, poles)
    assert nodes.tolist() == [1009, 2004, 3004]
    # left:9:Y -> node 1009, y; top:4:X -> 2004, x; right:4:-Z -> 3004, z with the sign flipped
    assert np.allclose(shapes[0, 1], phi[0], rtol=1e-5)
    assert np.allclose(shapes[1, 0], phi[1], rtol=1e-5)
    assert np.allclose(shapes[2, 2], -phi[2], rtol=1e-5)
    assert np.all(shapes[0, 0] == 0)


def test_errors(tmp_path):
    s = example_set()
    p = tmp_path / "frf.uff"
    write_uff58(p, s)
    with pytest.raises(UFFError, match="exists"):
        write_uff58(p, s)
    bad = tmp_path / "bad.uff"
    bad.write_text("this is not a universal file\n")
    with pytest.raises(UFFError, match="not a readable UFF|no dataset-58"):
        read_uff58(bad)
    with pytest.raises(UFFError, match="not found"):
        read_uff58(tmp_path / "none.uff")
    with pytest.raises(UFFError, match="shape"):
        write_uff55(tmp_path / "s.uff", np.array([1j]), np.ones((2, 2)), OUTS)


def _open_files() -> set[str]:
    """The paths of the regular files this process holds open (Linux /proc)."""
    fds = Path("/proc/self/fd")
    return {str(fd.resolve()) for fd in fds.iterdir() if fd.resolve().is_file()} if fds.is_dir() else set()


def test_a_written_file_is_closed_without_a_garbage_collection(tmp_path):
    """pyuff's binary writer leaves its last handle of the file open; the handle goes with the writer's frame
    when the write returns, so write_uff58 runs no (costly) garbage collection then and the file is closed all
    the same, with no ResourceWarning later (the suite turns warnings into errors)."""
    import gc
    import warnings

    if not Path("/proc/self/fd").is_dir():
        pytest.skip("needs /proc/self/fd to list the open files")
    s = example_set()
    gc.disable()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            before = _open_files()
            write_uff58(tmp_path / "frf.uff", s)
            write_uff55(tmp_path / "shapes.uff", np.array([-1 + 100j]), np.ones((3, 1), complex), OUTS)
            assert _open_files() == before
    finally:
        gc.enable()


@pytest.mark.realdata
def test_reads_pyuff_measurement_file(shared_data):
    """ladisk/pyuff measurement.uff (MIT): the same three FRFs as the text files."""
    d = shared_data / "pyuff_3frf"
    s = read_uff58(d / "measurement.uff")
    assert s.H.shape[0] * s.H.shape[1] >= 3
    txt = [np.genfromtxt(d / f"meas_point_{k}.txt", dtype=complex) for k in (1, 2, 3)]
    flat = [s.H[i, j] for i in range(s.n_outputs) for j in range(s.n_references) if not np.all(np.isnan(s.H[i, j]))]
    assert len(flat) == 3 and s.references == ("n:1:X", "n:2:X", "n:3:X")
    for h, t in zip(flat, txt):  # the UFF file stores the DC line as 0; compare from 1 Hz on
        assert h.size == t.size and np.allclose(h[1:], t[1:], rtol=1e-5, atol=1e-9)
