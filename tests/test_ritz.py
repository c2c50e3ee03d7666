"""The reduced (Rayleigh-Ritz) candidate models against the full FE model, on changes larger than the
diagnosis meets, and the diagnosis's fits unchanged by the reduction."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from analysis.diagnosis.physical import MeasuredModes, fit_cause, physical_causes
from simulator.physical import FrameVariants
from simulator.ritz import MAX_FRACTION, Part, RitzReduction, inverse_eigh, inverse_eigh_at

OUTS = ["right:6:-X", "right:4:-X", "left:6:X", "top:4:Z", "top:2:Z", "left:9:Y"]
REFS = ["right:6:-X"]

LARGE = [
    [("added_mass", {"point": "left:5", "mass_kg": 3.0})],
    [("added_mass", {"point": "top:4", "mass_kg": 5.0})],
    [("added_mass", {"point": "right:9", "mass_kg": 30.0})],
    [("support_stiffness", {"factor_translational": 0.1, "factor_rotational": 0.1})],
    [("support_stiffness", {"factor_translational": 1e-3, "factor_rotational": 0.01})],
    [("joint_stiffness", {"factor_translational": 1e-4, "factor_rotational": 1e-3})],
    [("element_stiffness", {"element": "left:1", "factor": 0.02})],
    [("member_stiffness", {"component": "top", "factor": 0.3})],
    [("member_stiffness", {"component": "right", "factor": 2.0})],
    [("member_mass", {"component": "left", "factor": 2.0})],
    [("member_mass", {"component": "top", "factor": 0.5})],
    [("mass_loading", {"mass_kg": 1.0})],
    [("stiffness_shift", {"stiffness_factor": 1.6})],
    [("added_mass", {"point": "left:5", "mass_kg": 4.0}),
     ("support_stiffness", {"factor_translational": 1.0, "factor_rotational": 0.1})],
    [("member_stiffness", {"component": "top", "factor": 1.5}), ("mass_loading", {"mass_kg": 0.3})],
]


def assert_as_the_full_model(f: np.ndarray, P: np.ndarray, g: np.ndarray, Q: np.ndarray) -> None:
    """Reduced modes ``f`` (Hz), shape products ``P`` against the full model's ``g``, ``Q``: the same count
    (at least 12), frequencies within 1e-6 (relative), shape products within 1e-3 of their largest value
    for the modes below 450 Hz."""
    assert f.size == g.size and g.size >= 12
    np.testing.assert_allclose(f, g, rtol=1e-6)
    low = g < 450.0
    err = np.max(np.abs(P[:, low] - Q[:, low]), axis=0) / np.max(np.abs(Q[:, low]), axis=0)
    assert np.all(err < 1e-3)


@pytest.fixture(scope="module")
def fv() -> FrameVariants:
    return FrameVariants(None, OUTS, REFS)


@pytest.mark.parametrize("changes", LARGE, ids=lambda c: "+".join(n for n, _ in c))
def test_reduced_modes_equal_the_full_models(fv: FrameVariants, changes: list) -> None:
    """Natural frequencies within 1e-6 (relative) of the full model's up to 700 Hz (the full solve's own
    rounding is ~1e-7), and the shape products at the measured points within 1e-3 of their largest
    value for the modes up to 450 Hz (the diagnosis compares up to ten modes, ~420 Hz on this frame;
    the largest errors, a few 1e-4, are where two modes lie close)."""
    fmax = 700.0
    f, P = fv.modes_of(changes, fmax)
    g, Q = fv.exact_modes_of(changes, fmax)
    assert_as_the_full_model(f, P, g, Q)


def test_the_reduction_is_used_and_small(fv: FrameVariants) -> None:
    """A local change is solved in a space of a few tens of unknowns (the frame has 186) and gives the
    full model's modes: 2 kg on the translations of top:3."""
    K0, M0 = fv.matrices(None, {})
    red = RitzReduction(K0, M0)
    dofs = 6 * fv.frame.node("top:3") + np.arange(3)
    lump = {("lump", "top:3"): Part(dofs, np.eye(3))}
    space = red.space({}, lump, red.n_modes((2 * np.pi * 700.0) ** 2))
    assert space is not None and space.size <= 45 < fv.frame.n_dof
    w2, _ = space.eigen({}, {("lump", "top:3"): 2.0}, 1.0, (2 * np.pi * 700.0) ** 2)
    M = M0.copy()
    M[dofs, dofs] += 2.0
    ref = scipy.linalg.eigh(K0, M, subset_by_value=(1.0, (2 * np.pi * 700.0) ** 2), eigvals_only=True)
    np.testing.assert_allclose(np.sqrt(w2), np.sqrt(ref), rtol=1e-6)


#: springs up to the spring causes' upper bound (x 100) on the frame's light rotations
STIFF_SPRINGS = [
    [("joint_stiffness", {"joint": "left:10", "factor_translational": 1.0, "factor_rotational": 96.0}),
     ("joint_stiffness", {"factor_translational": 100.0, "factor_rotational": 100.0})],
    [("support_stiffness", {"factor_translational": 100.0, "factor_rotational": 100.0}),
     ("joint_stiffness", {"factor_translational": 100.0, "factor_rotational": 100.0})],
]


def _energy_quotient(fv: FrameVariants, changes: list, phi: np.ndarray) -> np.ndarray:
    """Rayleigh quotients ``phi^T K phi / phi^T M phi`` (rad/s)^2 of the columns of ``phi`` with each matrix
    summed as its parts' energies (each positive semi-definite block's quadratic form on its own few DOFs,
    never the assembled matrix's products with their cancellations): an independent reference, stationary
    at an eigenvector, so its error is quadratic in the vector's."""
    scale, k, m = fv._coefficients(changes)

    def form(parts: dict, coefficients: dict) -> np.ndarray:
        return sum(c * np.einsum("im,ij,jm->m", phi[parts[key].dofs], parts[key].block, phi[parts[key].dofs])
                   for key, c in coefficients.items())

    return scale * form(fv._kparts, k) / form(fv._mparts, m)


@pytest.mark.parametrize("changes", STIFF_SPRINGS, ids=["one joint x96 + every joint x100", "all springs x100"])
def test_stiff_springs_are_solved_accurately(fv: FrameVariants, changes: list) -> None:
    """With springs x 100 the full model's and the reduced model's natural frequencies equal an independent
    reference to 1e-8 (relative): the energy quotients of the direct solve ``eigh(K, M)``'s eigenvectors. That
    solve's own eigenvalues are off by 1e-5..1e-3 here (its largest eigenvalue, ~1e13 times the lowest mode's,
    sets their absolute error), so the full model solves the inverse pencil."""
    fmax = 700.0
    K, M = fv.matrices_of(changes)
    w2, phi = scipy.linalg.eigh(K, M, subset_by_value=(1.0, (2 * np.pi * fmax) ** 2))
    ref = np.sqrt(_energy_quotient(fv, changes, phi)) / (2 * np.pi)
    assert np.max(np.abs(np.sqrt(w2) / (2 * np.pi) / ref - 1)) > 1e-6       # the direct solve is not
    g, _ = fv.exact_modes_of(changes, fmax)
    f, _ = fv.modes_of(changes, fmax)
    assert g.size == f.size == ref.size >= 12
    np.testing.assert_allclose(g, ref, rtol=1e-8)
    np.testing.assert_allclose(f, ref, rtol=1e-8)


UNIFORM_PLUS_LOCAL = [
    ("support_stiffness", {"support": "left:0", "factor_translational": 0.3, "factor_rotational": 0.3}, 1.02),
    ("support_stiffness", {"support": "right:0", "factor_translational": 0.01, "factor_rotational": 3.0}, 0.95),
    ("joint_stiffness", {"joint": "left:10", "factor_translational": 0.1, "factor_rotational": 0.1}, 0.95),
    ("element_stiffness", {"element": "top:2", "factor": 0.4}, 1.02),
    ("added_mass", {"point": "top:4", "mass_kg": 2.0}, 1.05),
]


@pytest.mark.parametrize("cause, params, modulus", UNIFORM_PLUS_LOCAL, ids=lambda v: str(v))
def test_a_uniform_stiffness_change_with_a_local_one_is_solved_reduced(
        monkeypatch: pytest.MonkeyPatch, cause: str, params: dict, modulus: float) -> None:
    """Young's modulus (every member, not the springs) scaled with one local change, modes up to 700 Hz
    (30 nominal modes; the uniform change needs the static responses of every spring: with the local
    change 100-111 unknowns of the frame's 186): solved in the reduced space, not on the full model, with
    the full model's natural frequencies to 1e-6 and shape products within 1e-3 below 450 Hz."""
    fv = FrameVariants(None, OUTS, REFS)
    changes = [(cause, params), ("stiffness_shift", {"stiffness_factor": modulus})]
    fmax = 700.0

    def full_model(*args: object) -> None:
        raise AssertionError("solved on the full model")

    with monkeypatch.context() as m:
        m.setattr(fv, "exact_modes_of", full_model)
        f, P = fv.modes_of(changes, fmax)
    ((space, _),) = fv._spaces.values()
    assert space is not None and 0.5 * fv.frame.n_dof < space.size <= MAX_FRACTION * fv.frame.n_dof
    g, Q = fv.exact_modes_of(changes, fmax)
    assert_as_the_full_model(f, P, g, Q)


def test_answers_are_kept_and_read_only(fv: FrameVariants) -> None:
    a = fv.modes("added_mass", {"point": "top:2", "mass_kg": 1.5}, 500.0)
    b = fv.modes("added_mass", {"point": "top:2", "mass_kg": 1.5}, 500.0)
    assert a[0] is b[0] and not a[0].flags.writeable


def test_derivatives_are_kept_and_read_only(fv: FrameVariants) -> None:
    """The folds of a cross-validation all start from the whole fit's optimum: the derivatives there are solved
    once and given read-only."""
    changes = [("added_mass", {"point": "top:2", "mass_kg": 1.5, "inertia_factor": 2.0})]
    wrt = [(0, "mass_kg"), (0, "inertia_factor")]
    a = fv.modes_jac_of(changes, 500.0, wrt)
    b = fv.modes_jac_of([("added_mass", dict(changes[0][1]))], 500.0, list(wrt))
    assert a is not None and b is not None
    assert all(x is y and not x.flags.writeable for x, y in zip(a, b))
    c = fv.modes_jac_of(changes, 500.0, wrt[:1])
    assert c is not None and c[2].shape == (a[2].shape[0], 1) and np.array_equal(c[2][:, 0], a[2][:, 0])


def _measured(fv: FrameVariants, changes: list, top_hz: float = 460.0) -> MeasuredModes:
    model = fv.model_of(changes)
    keep = model.freq_hz < top_hz
    return MeasuredModes(model.freq_hz[keep], np.zeros(int(keep.sum())),
                         model.residues[..., keep].reshape(-1, int(keep.sum())))


@pytest.mark.parametrize("changes, cause, free", [
    ([("added_mass", {"point": "left:5", "mass_kg": 3.5})], "added_mass", ("mass_kg",)),
    ([("support_stiffness", {"factor_translational": 1.0, "factor_rotational": 0.1})], "support_stiffness",
     ("factor_rotational",)),
])
def test_fits_are_the_full_models_fits(changes: list, cause: str, free: tuple) -> None:
    """A cause fitted with the reduced candidates and with the full model: the same choice, the same
    parameters (1e-5) and chi2."""
    fast, full = FrameVariants(None, OUTS, REFS), FrameVariants(None, OUTS, REFS)
    full.reduced = False
    mm = _measured(full, changes)
    mm = MeasuredModes(mm.freq_hz * (1 + 0.003 * np.sin(np.arange(mm.freq_hz.size))), mm.freq_std_hz, mm.shapes)
    spec = {c.name: c for c in full.causes()}[cause]
    allsel = np.ones(mm.freq_hz.size, bool)
    options = ["left:4", "left:5", "left:6", "top:4"] if spec.choice == "point" else None
    p1, c1, _ = fit_cause(fast, spec, free, mm, allsel, 700.0, options)
    p2, c2, _ = fit_cause(full, spec, free, mm, allsel, 700.0, options)
    assert p1.keys() == p2.keys()
    for k in p1:
        assert p1[k] == p2[k] if isinstance(p1[k], str) else p1[k] == pytest.approx(p2[k], rel=1e-5)
    assert c1 == pytest.approx(c2, rel=1e-4, abs=1e-6)


class _Skewed:
    """A simulation whose candidates are off by 1 % in frequency except through ``exact_modes_of``."""

    def __init__(self, fv: FrameVariants) -> None:
        self.fv = fv

    def causes(self):
        return [c for c in self.fv.causes() if c.name == "stiffness_shift"]

    def modes(self, cause, params, fmax):
        return self.modes_of([] if cause is None else [(cause, params)], fmax)

    def modes_of(self, changes, fmax):
        f, P = self.fv.modes_of(changes, fmax)
        return f * 1.01, P

    def exact_modes_of(self, changes, fmax):
        return self.fv.exact_modes_of(changes, fmax)

    def model(self, cause, params):
        return self.fv.model(cause, params)

    def model_of(self, changes):
        return self.fv.model_of(changes)


def test_a_chosen_fit_is_checked_on_the_full_model(fv: FrameVariants) -> None:
    """A fit whose approximate candidates disagree with the full model is refitted on the full model:
    the stiffness factor comes back right although the approximation is 1 % off in frequency."""
    truth = [("stiffness_shift", {"stiffness_factor": 1.08})]
    mm = _measured(fv, truth, 150.0)
    (fit,) = physical_causes(_Skewed(fv), mm, 250.0)
    assert fit.params["stiffness_factor"] == pytest.approx(1.08, rel=1e-4)


def test_other_points_keep_the_accelerometers(fv: FrameVariants) -> None:
    """The same frame at other measured points carries the test's accelerometers (their masses where
    the test's sensors are), in its full and in its reduced candidates."""
    assert fv.sensor_mass_kg > 0
    other = fv.at_points(["top:4:Z"], ["top:1:Z"])
    np.testing.assert_array_equal(other.matrices(None, {})[1], fv.matrices(None, {})[1])
    change = [("added_mass", {"point": "left:3", "mass_kg": 1.0})]
    np.testing.assert_allclose(other.modes_of(change, 400.0)[0], fv.exact_modes_of(change, 400.0)[0], rtol=1e-6)


def test_ranked_causes_are_the_full_models() -> None:
    """Causes fitted and cross-validated (leave one mode out) with reduced candidates and with the full
    model: the same ranking, the same parameters (1e-4) and held-out errors, on modes of a frame with a
    softer support and measured frequencies scattered by 0.3 %."""
    fast, full = FrameVariants(None, OUTS, REFS), FrameVariants(None, OUTS, REFS)
    full.reduced = False
    mm = _measured(full, [("support_stiffness", {"factor_translational": 1.0, "factor_rotational": 0.3})], 140.0)
    mm = MeasuredModes(mm.freq_hz * (1 + 0.003 * np.cos(np.arange(mm.freq_hz.size))), mm.freq_std_hz, mm.shapes)
    names = ["support_stiffness", "stiffness_shift"]
    a, b = physical_causes(fast, mm, 210.0, names), physical_causes(full, mm, 210.0, names)
    assert [f.cause for f in a] == [f.cause for f in b]
    for x, y in zip(a, b):
        assert x.free == y.free and x.params.keys() == y.params.keys()
        for k in x.params:
            assert x.params[k] == y.params[k] if isinstance(x.params[k], str) else \
                x.params[k] == pytest.approx(y.params[k], rel=1e-4)
        np.testing.assert_allclose(x.cv_per_mode, y.cv_per_mode, rtol=1e-2, atol=0.05)
        assert x.chi2_cv == pytest.approx(y.chi2_cv, rel=1e-2)


def test_causes_fitted_in_forked_processes_are_the_same(fv: FrameVariants) -> None:
    """The causes fitted in two forked processes give the very fits of one process (same order, same
    numbers): a block of 2 kg on left:5 with the supports' rotational springs x 0.5."""
    truth = [("added_mass", {"point": "left:5", "mass_kg": 2.0}),
             ("support_stiffness", {"factor_translational": 1.0, "factor_rotational": 0.5})]
    mm = _measured(fv, truth, 300.0)
    names = ["mass_loading", "stiffness_shift"]
    one = physical_causes(FrameVariants(None, OUTS, REFS), mm, 450.0, names, processes=1)
    two = physical_causes(FrameVariants(None, OUTS, REFS), mm, 450.0, names, processes=2)
    assert [f.cause for f in one] == [f.cause for f in two] and len(one) == 2
    for a, b in zip(one, two):
        assert a.params == b.params and a.free == b.free and a.chi2 == b.chi2
        np.testing.assert_array_equal(a.cv_per_mode, b.cv_per_mode)


def test_a_kept_space_holds_nothing_of_the_frames_size() -> None:
    """A search keeps one reduced space per set of changed parts (hundreds on a fine frame): each keeps its
    projected matrices and its basis at the measured points, not the basis itself (the frame's size), and
    solves the same modes as the full model."""
    fv = FrameVariants(None, OUTS, REFS)
    n = fv.frame.n_dof
    changes = [("element_stiffness", {"element": "top:3", "factor": 0.4})]
    f, P = fv.modes_of(changes, 700.0)
    ((space, at),) = fv._spaces.values()
    assert space is not None and at is not None
    arrays = [a for a in vars(space).values() if isinstance(a, np.ndarray)]
    arrays += [*space.kparts.values(), *space.mparts.values()]
    assert arrays and max(max(a.shape) for a in arrays) == space.size < n
    assert np.array_equal(np.abs(at), np.abs(space.at)) and at.shape == (len(OUTS) + len(REFS), space.size)
    g, Q = fv.exact_modes_of(changes, 700.0)
    assert_as_the_full_model(f, P, g, Q)


def _reduced_pencils(fv: FrameVariants) -> list[tuple[str, np.ndarray, np.ndarray | None]]:
    """A candidate's reduced ``K`` and ``M`` (None: the identity) as the search solves them: springs x 100 and a
    soft joint (stiffness only), 2 kg with its rotary inertia on top:3 and a member's mass (a changed mass)."""
    out = []
    for name, changes in (("stiff springs", STIFF_SPRINGS[0]),
                          ("soft joint", [("joint_stiffness", {"joint": "right:10", "factor_translational": 0.07,
                                                               "factor_rotational": 0.06})]),
                          ("2 kg", [("added_mass", {"point": "top:3", "mass_kg": 2.0})]),
                          ("member mass", [("member_mass", {"component": "left", "factor": 1.5})])):
        scale, k, m = fv._coefficients(changes)
        dk, dm = fv._changed(k, m)
        red = RitzReduction(fv._K0, fv._M0)
        space = red.space({q: fv._kparts[q] for q in dk}, {q: fv._mparts[q] for q in dm}, 30)
        assert space is not None
        K, M = space.matrices(dk, dm)
        out.append((name, K, M))
    return out


def test_the_solve_at_a_few_dofs_is_the_full_solve_there(fv: FrameVariants) -> None:
    """``inverse_eigh_at`` (the modes' search: the vectors seen at the measured points only, never formed) gives
    ``inverse_eigh``'s eigenvalues and ``A @ Y`` for the modes up to 1.5 kHz, each column up to its sign, with a
    stiffness change (K^-1's eigenproblem) and with a changed mass (the generalized one, M-normalised)."""
    rng = np.random.default_rng(3)
    for name, K, M in _reduced_pencils(fv):
        A = rng.standard_normal((7, K.shape[0]))
        w2, Y = inverse_eigh(K, M)
        v2, AY = inverse_eigh_at(K, M, A)
        low = w2 < (2 * np.pi * 1500.0) ** 2
        assert low.sum() >= 12, name
        np.testing.assert_allclose(v2[low], w2[low], rtol=1e-12, err_msg=name)
        ref = A @ Y[:, low]
        sign = np.sign(np.sum(ref * AY[:, low], axis=0))
        assert np.max(np.abs(AY[:, low] * sign - ref)) < 1e-9 * np.max(np.abs(ref)), name


def test_the_solve_of_a_band_alone_is_the_full_solve_there(fv: FrameVariants) -> None:
    """``inverse_eigh_at`` asked for the modes of a band alone (a search's band: each eigenvector found by inverse
    iteration after the eigenvalues) gives the band's eigenvalues and ``A @ Y`` of the solve of every mode, each column
    up to its sign; a band that holds no mode gives none."""
    rng = np.random.default_rng(4)
    for name, K, M in _reduced_pencils(fv):
        A = rng.standard_normal((7, K.shape[0]))
        w2, AY = inverse_eigh_at(K, M, A)
        band = (w2 > (2 * np.pi * 30.0) ** 2) & (w2 < (2 * np.pi * 700.0) ** 2)
        assert 6 <= band.sum() < w2.size, name
        v2, AZ = inverse_eigh_at(K, M, A, lambda w: (w > (2 * np.pi * 30.0) ** 2) & (w < (2 * np.pi * 700.0) ** 2))
        np.testing.assert_allclose(v2, w2[band], rtol=1e-12, err_msg=name)
        ref = AY[:, band]
        sign = np.sign(np.sum(ref * AZ, axis=0))
        assert np.max(np.abs(AZ * sign - ref)) < 1e-9 * np.max(np.abs(ref)), name
        none = inverse_eigh_at(K, M, A, lambda w: w < 0.0)
        assert none[0].size == 0 and none[1].shape == (7, 0), name


def test_a_change_of_masses_alone_is_solved_on_the_nominal_stiffness_s_factor(fv: FrameVariants) -> None:
    """A candidate that changes masses alone (a block, a member's mass) keeps ``K0``: its space solves the inverse
    pencil on ``K0``'s Cholesky factor and the reduced masses made once (the nominal's and each part's), with the
    eigenpairs of the solve of its matrices (every mode, and the band at a few DOFs), each column up to its sign."""
    red = RitzReduction(fv._K0, fv._M0)
    rng = np.random.default_rng(5)
    for changes in ([("added_mass", {"point": "top:3", "mass_kg": 2.0, "inertia_x": 3.0})],
                    [("member_mass", {"component": "left", "factor": 1.5})]):
        scale, k, m = fv._coefficients(changes)
        dk, dm = fv._changed(k, m)
        assert not dk and dm
        space = red.space({}, {q: fv._mparts[q] for q in dm}, 30)
        assert space is not None
        K, M = space.matrices(dk, dm)
        w2, Y = inverse_eigh(K, M)
        v2, Z = space.eigen_all(dk, dm)
        low = w2 < (2 * np.pi * 1500.0) ** 2
        np.testing.assert_allclose(v2[low], w2[low], rtol=1e-12)
        np.testing.assert_allclose(v2, w2, rtol=1e-10)       # the highest: to the largest one's rounding
        sign = np.sign(np.sum(Y * Z, axis=0))
        assert np.max(np.abs(Z[:, low] * sign[low] - Y[:, low])) < 1e-9 * np.max(np.abs(Y[:, low]))
        A = rng.standard_normal((5, K.shape[0]))
        u2, AZ = space.eigen_at(dk, dm, 1.0, (2 * np.pi * 700.0) ** 2, A)
        band = w2 < (2 * np.pi * 700.0) ** 2
        np.testing.assert_allclose(u2, w2[band], rtol=1e-12)
        ref = A @ Y[:, band]
        sign = np.sign(np.sum(ref * AZ, axis=0))
        assert np.max(np.abs(AZ * sign - ref)) < 1e-9 * np.max(np.abs(ref))
        assert set(space._mass_pencils) == set(dm)            # each part's reduced mass made once, kept


def test_the_inverse_solve_is_an_eigendecomposition(fv: FrameVariants) -> None:
    """``inverse_eigh``: ascending eigenvalues, vectors M-normalised (``Y^T M Y = I``) that solve ``K Y = M Y
    diag(omega^2)`` (the residual at rounding against ``|K| |y|``), equal to LAPACK's direct solve within that
    solve's rounding; a ``K`` that is not positive definite (a mechanism) is solved directly."""
    for name, K, M in _reduced_pencils(fv):
        Mm = np.eye(K.shape[0]) if M is None else M
        w2, Y = inverse_eigh(K, M)
        assert np.all(np.diff(w2) >= 0), name
        np.testing.assert_allclose(Y.T @ Mm @ Y, np.eye(w2.size), atol=1e-12, err_msg=name)
        low = w2 < (2 * np.pi * 1500.0) ** 2
        res = K @ Y[:, low] - Mm @ Y[:, low] * w2[low]          # backward error: against |K| |y|
        assert np.max(np.abs(res)) < 1e-13 * np.max(np.abs(K)) * np.max(np.abs(Y[:, low])), name
        # LAPACK's direct solve is exact to its own rounding, a few machine epsilons times the pencil's largest
        # eigenvalue (on the stiff springs 1e-3 of the lowest mode: test_stiff_springs_...); the two agree to it
        direct = scipy.linalg.eigh(K, Mm, eigvals_only=True)
        rounding = np.finfo(float).eps * np.max(direct)
        assert np.max(np.abs(w2[low] - direct[low])) < 20 * rounding, name
    mechanism = np.diag([-1.0, 2.0, 5.0]) + 0.1
    for M in (None, np.diag([1.0, 2.0, 3.0])):
        w2, Y = inverse_eigh(mechanism, M)
        np.testing.assert_allclose(w2, scipy.linalg.eigh(mechanism, M, eigvals_only=True), rtol=1e-12)
        v2, AY = inverse_eigh_at(mechanism, M, np.eye(3)[:2])
        np.testing.assert_allclose(v2, w2, rtol=1e-12)
        np.testing.assert_allclose(np.abs(AY), np.abs(Y[:2]), atol=1e-12)


def test_a_basis_is_mass_orthonormal(fv: FrameVariants) -> None:
    """Every reduced space's basis is M0-orthonormal to rounding (``V^T M0 V = I`` within 1e-13; the solve of a
    stiffness change takes the mass matrix as the identity) and its nominal stiffness is the nominal modes' on
    their block (``V^T K0 V`` = diag(omega^2) there, to the nominal solve's own 3e-10)."""
    red = RitzReduction(fv._K0, fv._M0)
    for dk, dm in (({("elem", "top:3"): 1.0}, {}), ({("spring", "joint", "rotational", "right:10"): 1.0}, {}),
                   ({}, {("lump", "top:3"): 1.0, ("rot", "top:3", "x"): 1.0}), ({}, {("mass", "left"): 1.0})):
        space = red.space({q: fv._kparts[q] for q in dk}, {q: fv._mparts[q] for q in dm}, 30)
        assert space is not None and space.size > 30
        np.testing.assert_allclose(space.M0, np.eye(space.size), atol=1e-13)
        np.testing.assert_allclose(np.diag(space.K0)[:30], red.w2[:30], rtol=1e-9)
