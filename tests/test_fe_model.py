"""The user's FE model (analysis.fe_model): reading, its modes against an exactly solved chain, the
Ritz-reduced candidates against the full model, and a one-line error for each kind of bad input."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io
import scipy.sparse as sp
from fe_chain import chain_exact_hz, chain_matrices, write_chain

from analysis.errors import FEModelError
from analysis.fe_model import DENSE_MAX_DOF, FEVariants, is_fe_config, load_fe_model, sparse_modes


@pytest.mark.parametrize("n, sparse, rtol", [(8, False, 1e-13), (60, True, 1e-12), (2000, None, 2e-10)])
def test_chain_frequencies_to_machine_precision(n: int, sparse: bool | None, rtol: float) -> None:
    """n equal masses and springs fixed at one end: w_j = 2 sqrt(k/m) sin((2j-1) pi / (2(2n+1))); the
    dense and the shift-invert Lanczos solvers give them to rounding (``eps`` times the condition
    number, which grows as n^2: ~1e-10 at 2000 masses; the sparse one asked for more modes until it
    passed the top)."""
    K, M = chain_matrices(n)
    exact = chain_exact_hz(n)
    top = exact[min(n, 15) - 1] * 1.0001
    f, phi = sparse_modes(K, M, top, sparse=sparse)
    assert f.size == min(n, 15)
    np.testing.assert_allclose(f, exact[:f.size], rtol=rtol)
    # mass-normalised shapes
    np.testing.assert_allclose(phi.T @ (M @ phi), np.eye(f.size), atol=1e-9)
    if sparse is None:
        assert n > DENSE_MAX_DOF


def test_model_file_round_trip_gives_the_chain(tmp_path: Path) -> None:
    toml = write_chain(tmp_path, 6, zeta=0.02, groups={0: "base", 1: "base", 2: "top"})
    assert is_fe_config(toml) and not is_fe_config(tmp_path / "K.mtx")
    fe = load_fe_model(toml)
    assert fe.n_dof == 6 and fe.dofs["n:3:Z"] == 2 and list(fe.groups["base"]) == [0, 1]
    assert fe.total_mass_kg() == pytest.approx(6.0)
    sim = FEVariants(fe, ["n:2:Z", "n:6:-Z"], ["n:6:Z"], max_freq_hz=400.0)
    model = sim.model(None, {})
    np.testing.assert_allclose(model.freq_hz, chain_exact_hz(6), rtol=1e-9)
    np.testing.assert_allclose(model.damping, 0.02, rtol=1e-12)
    # the output measured against the map's direction has the opposite sign
    np.testing.assert_allclose(model.meta["output_shapes"][1], -model.meta["reference_shapes"][0])
    assert {c.name for c in sim.causes()} >= {"added_mass", "ground_spring", "group_stiffness", "mass_loading"}


@pytest.mark.parametrize("changes", [
    [("added_mass", {"point": "n:37", "mass_kg": 3.0})],
    [("ground_spring", {"point": "n:120", "stiffness_n_m": 4.0e5})],
    [("group_stiffness", {"group": "mid", "factor": 0.6})],
    [("mass_loading", {"mass_kg": 0.5}), ("stiffness_shift", {"stiffness_factor": 1.1})],
])
def test_reduced_candidates_equal_the_full_model(tmp_path: Path, changes: list) -> None:
    """A candidate's modes in the Ritz space (kept modes + static responses / first-order corrections)
    equal the full sparse model's, changed matrices solved from scratch."""
    n = 400
    toml = write_chain(tmp_path, n, groups={i: "mid" for i in range(150, 250)})
    sim = FEVariants(load_fe_model(toml), ["n:100:Z", "n:400:Z"], ["n:400:Z"], max_freq_hz=300.0)
    f, P = sim.modes_of(changes, 25.0)
    f_full, P_full = sim.exact_modes_of(changes, 25.0)
    K, M = sim.matrices_of(changes)
    f_ref = sparse_modes(K, M, 25.0, sparse=True)[0]
    assert f.size == f_full.size == f_ref.size >= 5
    np.testing.assert_allclose(f_full, f_ref, rtol=1e-10)
    np.testing.assert_allclose(f, f_full, rtol=1e-7)
    np.testing.assert_allclose(np.abs(P), np.abs(P_full), rtol=0, atol=1e-4 * np.abs(P_full).max())


def _bad_models() -> list:
    def nonsym(d: Path) -> Path:
        K, M = chain_matrices(5)
        K = K.tolil()
        K[1, 3] = 7.0
        return write_chain(d, 5, K=K.tocsr(), symmetric=False)

    def not_pd(d: Path) -> Path:
        K, M = chain_matrices(5)
        M = M.tolil()
        M[1, 2] = M[2, 1] = 2.0          # diagonal positive, yet indefinite
        return write_chain(d, 5, M=M.tocsr())

    def zero_mass(d: Path) -> Path:
        K, M = chain_matrices(5)
        M = M.tolil()
        M[3, 3] = 0.0
        return write_chain(d, 5, M=M.tocsr())

    def size(d: Path) -> Path:
        t = write_chain(d, 5)
        (d / "dofs.csv").write_text("dof,point\n0,n:1:Z\n1,n:2:Z\n5,n:6:Z\n")
        return t

    def mismatch(d: Path) -> Path:
        t = write_chain(d, 5)
        K, _ = chain_matrices(6)
        scipy.io.mmwrite(str(d / "K.mtx"), sp.coo_matrix(K), symmetry="symmetric")
        return t

    def label(d: Path) -> Path:
        t = write_chain(d, 5)
        (d / "dofs.csv").write_text("dof,point\n0,n:1:Z\n1,node 2\n")
        return t

    def duplicate(d: Path) -> Path:
        t = write_chain(d, 5)
        (d / "dofs.csv").write_text("dof,point\n0,n:1:Z\n1,n:2:Z\n1,n:3:Z\n")
        return t

    def missing(d: Path) -> Path:
        t = write_chain(d, 5)
        (d / "M.mtx").unlink()
        return t

    def no_damping(d: Path) -> Path:
        t = write_chain(d, 5)
        t.write_text('[fe]\nstiffness = "K.mtx"\nmass = "M.mtx"\ndofs = "dofs.csv"\n')
        return t

    return [(nonsym, "K.mtx", "not symmetric: row 2, column 4"),
            (not_pd, "M.mtx", "not positive definite"),
            (zero_mass, "M.mtx", "row 4 has diagonal 0"),
            (size, "dofs.csv", "row 4: dof 5 is outside the matrices' 5 DOFs"),
            (mismatch, "M.mtx", "stiffness"),
            (label, "dofs.csv", "row 3"),
            (duplicate, "dofs.csv", "row 4: dof 1 is mapped already on row 3"),
            (missing, "M.mtx", "cannot read"),
            (no_damping, "model.toml", "[damping]")]


@pytest.mark.parametrize("make, file, text", _bad_models(), ids=lambda x: getattr(x, "__name__", None))
def test_bad_input_is_one_line_naming_the_file_and_row(tmp_path: Path, make, file: str, text: str) -> None:
    toml = make(tmp_path)
    with pytest.raises(FEModelError) as err:
        load_fe_model(toml)
    msg = str(err.value)
    assert "\n" not in msg and str(tmp_path / file) in msg and text in msg


def test_a_measured_point_the_map_lacks_is_named(tmp_path: Path) -> None:
    fe = load_fe_model(write_chain(tmp_path, 5))
    with pytest.raises(FEModelError, match=r"dofs\.csv: no row for the measured point n:9:Z"):
        FEVariants(fe, ["n:2:Z", "n:9:Z"], ["n:5:Z"], max_freq_hz=300.0)
    with pytest.raises(FEModelError, match=r"no row for the measured point n:2:X"):
        FEVariants(fe, ["n:2:X"], ["n:5:Z"], max_freq_hz=300.0)


def test_one_change_is_solved_once_on_the_full_model(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The full model of a change checked (``exact_modes_of``) and then simulated (``model_of``, a lower top)
    is one sparse solution; the unchanged model reuses the kept modes of the Ritz space."""
    import analysis.fe_model as fm

    toml = write_chain(tmp_path, 400)
    sim = FEVariants(load_fe_model(toml), ["n:100:Z", "n:400:Z"], ["n:400:Z"], max_freq_hz=30.0)
    solved = []
    real = fm.sparse_modes

    def counting(*a, **k):
        solved.append(a[2])
        return real(*a, **k)

    monkeypatch.setattr(fm, "sparse_modes", counting)
    sim.modes(None, {}, 40.0)                        # the kept modes, to RITZ_FACTOR x 40 Hz
    assert len(solved) == 1
    nominal = sim.model(None, {})
    assert len(solved) == 1
    np.testing.assert_allclose(nominal.freq_hz, chain_exact_hz(400)[chain_exact_hz(400) <= 30.0], rtol=1e-9)
    change = [("added_mass", {"point": "n:37", "mass_kg": 3.0})]
    f, _ = sim.exact_modes_of(change, 40.0)
    model = sim.model_of(change)
    assert len(solved) == 2
    np.testing.assert_allclose(model.freq_hz, f[f <= 30.0], rtol=1e-12)
