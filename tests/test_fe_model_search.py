"""The search over every node of a user's FE model is exact: its first pass (bounds of each node's mode
count, :meth:`analysis.fe_model.FEVariants.first_pass`) orders the work and never drops a node whose exact
fit could still win (:func:`analysis.diagnosis.physical.fit_cause`)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.linalg
from fe_chain import net_matrices, write_chain, write_net

import analysis.fe_model as fm
from analysis.diagnosis import physical
from analysis.diagnosis.physical import CauseSpec, MeasuredModes, ParamSpec
from analysis.fe_model import FEVariants, load_fe_model


def _exact_counts(K: np.ndarray, M: np.ndarray, freqs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    w = np.sqrt(np.maximum(scipy.linalg.eigh(K, M, eigvals_only=True), 0.0)) / (2 * np.pi)
    return np.searchsorted(w, freqs, side="left"), np.searchsorted(w, freqs, side="right")


@pytest.mark.parametrize("cause, values", [("added_mass", [0.003, 0.3, 3.0, 30.0]),
                                           ("ground_spring", [1e3, 1e5, 1e7, 1e9])])
def test_first_pass_bounds_the_full_and_the_reduced_model(tmp_path: Path, cause: str, values: list) -> None:
    """At every frequency the first pass's counts bracket the mode count of the full model (dense solution of the
    changed matrices) and of the Ritz solution the search fits with, for nodes of three DOFs (a rank-three change)
    on a net with a part on a flexible bracket (where the kept modes alone misjudge a mass), light to heavy."""
    toml = write_net(tmp_path, 6, 8, bracket=(20, 1.0e7))
    sim = FEVariants(load_fe_model(toml), ["n:10:Z", "n:49:Z"], ["n:30:Z"], max_freq_hz=2000.0)
    fmax = 1200.0
    nodes = ["n:1", "n:21", "n:27", "n:49"]                          # an edge node, the bracket's, inner, the bracket
    freqs = np.linspace(5.0, fmax, 400)
    got = sim.first_pass(cause, nodes, np.array(values), freqs, fmax)
    assert got is not None
    at_least, at_most = got
    gaps = []
    name = "mass_kg" if cause == "added_mass" else "stiffness_n_m"
    for i, node in enumerate(nodes):
        for j, v in enumerate(values):
            change = [(cause, {"point": node, name: v})]
            K, M = sim.matrices_of(change)
            below, upto = _exact_counts(K.toarray(), M.toarray(), freqs)
            assert np.all(at_least[i, j] <= below) and np.all(upto <= at_most[i, j]), (node, v)
            f, _ = sim.modes_of(change, fmax)
            assert np.all(at_least[i, j] <= np.searchsorted(f, freqs, "left"))
            assert np.all(np.searchsorted(f, freqs, "right") <= at_most[i, j])
            gaps.append(np.mean(at_most[i, j] - at_least[i, j]))
    assert np.mean(gaps) < 0.05                                     # and tight: nearly the count itself


def test_inverse_blocks_banded_and_solved_equal_the_dense_inverse(monkeypatch: pytest.MonkeyPatch) -> None:
    """The nodes' blocks of ``(K0 - sigma M0)^-1`` by the banded selected inversion (after reverse Cuthill-McKee)
    and by column solves equal those of the dense inverse, a node of two DOFs padded."""
    K, M = net_matrices(7, 9, bracket=(30, 2.0e6))
    A = (K + 4.0e3 * M).tocsr()
    dofs = np.arange(A.shape[0]).reshape(-1, 3)
    dofs[5, 1] = -1
    Z = np.linalg.inv(A.toarray())
    idx = np.maximum(dofs, 0)
    pad = dofs < 0
    want = np.where(pad[:, :, None] | pad[:, None, :], 0.0, Z[idx[:, :, None], idx[:, None, :]])
    monkeypatch.setattr(fm, "DENSE_INVERSE_MAX_DOF", 10)
    banded = fm._inverse_blocks(A, dofs, lambda b: b)
    np.testing.assert_allclose(banded, want, rtol=0, atol=1e-12 * np.abs(want).max())
    monkeypatch.setattr(fm, "BAND_WORK_MAX", 0.0)
    solved = fm._inverse_blocks(A, dofs, None)
    np.testing.assert_allclose(solved, want, rtol=0, atol=1e-12 * np.abs(want).max())


class _Toy:
    """A simulation of 30 nodes of four modes each: node i with a mass m (kg) has ``f_j = f0_j / sqrt(1 + m a_ij)``
    (Hz, exact), each mode its own shape. ``screen_modes`` is the first-order perturbation ``f0_j (1 - m a_ij / 2)``
    (the cheap ranking an earlier search trusted); ``first_pass`` gives the exact counts (valid bounds)."""

    f0 = np.array([100.0, 150.0, 220.0, 300.0])

    def __init__(self, a: np.ndarray) -> None:
        self.a = a

    def _sorted(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        order = np.argsort(f)
        return f[order], np.eye(4)[:, order]

    def modes(self, cause: str | None, params: dict, fmax: float) -> tuple[np.ndarray, np.ndarray]:
        i = int(str(params["point"])[2:])
        return self._sorted(self.f0 / np.sqrt(1.0 + float(params["mass_kg"]) * self.a[i]))

    def screen_modes(self, cause: str | None, params: dict, fmax: float) -> tuple[np.ndarray, np.ndarray]:
        i = int(str(params["point"])[2:])
        return self._sorted(self.f0 * np.maximum(1.0 - 0.5 * float(params["mass_kg"]) * self.a[i], 1e-3))

    def first_pass(self, cause: str, options: list, values: np.ndarray, freq_hz: np.ndarray, fmax: float
                   ) -> tuple[np.ndarray, np.ndarray]:
        out = np.zeros((2, len(options), values.size, freq_hz.size), int)
        for i, opt in enumerate(options):
            for j, v in enumerate(values):
                f = self.modes(cause, {"point": opt, "mass_kg": v}, fmax)[0]
                out[0, i, j] = np.searchsorted(f, freq_hz, "left")
                out[1, i, j] = np.searchsorted(f, freq_hz, "right")
        return out[0], out[1]


def test_a_node_a_first_order_screen_ranks_low_is_still_found() -> None:
    """A heavy mass at node 29: the first-order perturbation is far off there, and 25 decoy nodes whose first-order
    modes match the measurement (their exact ones do not) rank above it. The search returns node 29 with its exact
    fit (chi2 ~ 0), the fit of every node done exactly; a search that trusted the ranking never fitted it."""
    spec = ParamSpec("mass_kg", 0.01, 10.0, nominal=0.0, unit="kg", monotone=True)
    cause = CauseSpec("added_mass", (spec,), choice="point", options=tuple(f"n:{i}" for i in range(30)))
    a_true = np.array([4.0, 0.5, 2.0, 0.1])                         # 1/kg
    ratio = 1.0 / np.sqrt(1.0 + 1.0 * a_true)                       # the truth: 1 kg at n:29
    m_decoy = spec.from_x(float(np.linspace(*spec.x_bounds, 7)[3]))
    rng = np.random.default_rng(5)
    a = rng.uniform(0.01, 0.05, (30, 4))
    a[:25] = 2.0 * (1.0 - ratio) / m_decoy * (1.0 + 1e-4 * rng.standard_normal((25, 4)))
    a[29] = a_true
    sim: Any = _Toy(a)
    f, P = sim.modes(None, {"point": "n:29", "mass_kg": 1.0}, 1e3)
    mm = MeasuredModes(f, 1e-4 * f, P.astype(complex))
    sel = np.ones(4, bool)
    grid = [spec.from_x(float(x)) for x in np.linspace(*spec.x_bounds, 7)[1:-1]]      # the ranking's grid
    first_order = sorted((min(float(np.sum(physical.residuals(mm, *sim.screen_modes(None, {"point": o, "mass_kg": m},
                                                                                             1e3)) ** 2))
                              for m in grid), o) for o in cause.options)
    assert [o for _, o in first_order].index("n:29") >= 25          # the first-order screen ranks it last but few
    p, chi2, ranked = physical.fit_cause(sim, cause, ("mass_kg",), mm, sel, 1e3)
    every = [(physical._fit_continuous(sim, cause, [spec], {"point": o}, mm, sel, 1e3)[1], o) for o in cause.options]
    best_chi2, best = min(every)
    assert p["point"] == best == "n:29"
    assert chi2 == pytest.approx(best_chi2, abs=1e-6) and chi2 < 1e-6
    assert p["mass_kg"] == pytest.approx(1.0, rel=1e-4)
    assert len(ranked) < 10                                         # the bound kept the others out


def test_search_over_every_node_equals_fitting_every_node(tmp_path: Path) -> None:
    """On a net of 49 nodes (147 DOF, X, Y, Z each) with a mass at one node: the search (first pass, then the
    screen and the fits of the nodes whose bound is below the best fit) returns what fitting every node in full
    returns: the node and its chi2."""
    toml = write_net(tmp_path, 6, 8, bracket=(20, 1.0e7))
    sim = FEVariants(load_fe_model(toml), ["n:10:Z", "n:27:Z", "n:40:Z"], ["n:33:Z"], max_freq_hz=2000.0)
    f, P = sim.exact_modes_of([("added_mass", {"point": "n:26", "mass_kg": 0.4})], 900.0)
    mm = MeasuredModes(f, 1e-4 * f, P.astype(complex))
    cause = next(c for c in sim.causes() if c.name == "added_mass")
    sel = np.ones(f.size, bool)
    fmax = 1.5 * float(f[-1])
    p, chi2, ranked = physical.fit_cause(sim, cause, ("mass_kg",), mm, sel, fmax)
    every = []
    for node in cause.options:
        s = physical._screen(sim, cause, list(cause.params), {}, mm, sel, fmax, [node])[0]
        every.append((physical._fit_continuous(sim, cause, list(cause.params), {"point": node}, mm, sel, fmax,
                                               s.params)[1], node))
    best_chi2, best = min(every)
    assert p["point"] == best == "n:26"
    assert chi2 == pytest.approx(best_chi2, rel=1e-6, abs=1e-9)
    assert p["mass_kg"] == pytest.approx(0.4, rel=1e-3)
    assert len(ranked) < len(cause.options) // 4                    # most nodes were never fitted


def test_chain_nodes_of_one_dof_are_bounded(tmp_path: Path) -> None:
    """Nodes of one mapped DOF (a chain) are padded: the counts still bracket the full model's."""
    toml = write_chain(tmp_path, 150)
    sim = FEVariants(load_fe_model(toml), ["n:40:Z"], ["n:150:Z"], max_freq_hz=300.0)
    freqs = np.linspace(1.0, 60.0, 200)
    got = sim.first_pass("added_mass", ["n:3", "n:77", "n:150"], np.array([0.1, 5.0, 50.0]), freqs, 60.0)
    assert got is not None
    lo, hi = got
    for i, node in enumerate(["n:3", "n:77", "n:150"]):
        for j, m in enumerate([0.1, 5.0, 50.0]):
            K, M = sim.matrices_of([("added_mass", {"point": node, "mass_kg": m})])
            below, upto = _exact_counts(K.toarray(), M.toarray(), freqs)
            assert np.all(lo[i, j] <= below) and np.all(upto <= hi[i, j])


def test_a_ritz_space_whose_kept_modes_span_a_whole_part_adds_no_spurious_mode(tmp_path: Path) -> None:
    """When the kept modes already span every out-of-plane (Z) motion of a small net, a node's static response in
    Z lies in their span: the Ritz space must not add it as a new vector (rounding normalised to unit length),
    which gave modes the model does not have. The reduced candidate equals the full model."""
    toml = write_net(tmp_path, 6, 8)
    sim = FEVariants(load_fe_model(toml), ["n:10:Z"], ["n:30:Z"], max_freq_hz=5000.0)
    K, M = net_matrices(6, 8)
    w = np.sqrt(scipy.linalg.eigh(K.toarray(), M.toarray(), eigvals_only=True)) / (2 * np.pi)
    top = float(w[60])                                   # the kept modes (to twice this) hold every Z mode
    change = [("added_mass", {"point": "n:20", "mass_kg": 0.3})]
    f, _ = sim.modes_of(change, top)
    f_full, _ = sim.exact_modes_of(change, top)
    assert f.size == f_full.size
    np.testing.assert_allclose(f, f_full, rtol=1e-7)
