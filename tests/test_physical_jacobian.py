"""The physical diagnosis's derivatives: the frame's natural frequencies and shape products differentiated in
the Ritz space (:meth:`simulator.physical.FrameVariants.modes_jac_of`) and the residuals' Jacobian
(:func:`analysis.diagnosis.physical.residuals_jac`), each against central differences of the full model."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis.physical import CHI2_RESOLUTION, MeasuredModes, ParamSpec, off_edges, residuals, residuals_jac
from simulator.physical import FrameVariants

OUTS = ["right:6:-X", "right:4:-X", "left:6:X", "top:4:Z", "top:2:Z", "left:9:Y"]
REFS = ["right:6:-X", "top:4:Z"]
FMAX = 500.0

CASES = [
    ([("element_stiffness", {"element": "top:1", "factor": 0.3}), ("stiffness_shift", {"stiffness_factor": 1.02})],
     [(0, "factor"), (1, "stiffness_factor")]),
    ([("joint_stiffness", {"joint": "left:10", "factor_translational": 0.1, "factor_rotational": 0.3})],
     [(0, "factor_translational"), (0, "factor_rotational")]),
    ([("added_mass", {"point": "top:4", "mass_kg": 2.0, "inertia_factor": 3.0})], [(0, "mass_kg"), (0, "inertia_factor")]),
    ([("member_mass", {"component": "left", "factor": 1.2}),
      ("support_stiffness", {"support": "all", "factor_translational": 0.5, "factor_rotational": 2.0})],
     [(0, "factor"), (1, "factor_rotational")]),
    ([("mass_loading", {"mass_kg": 0.1})], [(0, "mass_kg")]),
]


@pytest.fixture(scope="module")
def fv() -> FrameVariants:
    return FrameVariants(None, OUTS, REFS)


def _moved(changes: list, i: int, name: str, v: float) -> list:
    out = list(changes)
    out[i] = (changes[i][0], {**changes[i][1], name: v})
    return out


def _central(fv: FrameVariants, changes: list, i: int, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Central differences (step 1e-4 relative: truncation ~1e-7, rounding of the solves ~1e-10) of the full model's frequencies and shape products."""
    v = float(changes[i][1][name])
    h = 1e-4 * v
    fu, Pu = fv.exact_modes_of(_moved(changes, i, name, v + h), FMAX)
    fd, Pd = fv.exact_modes_of(_moved(changes, i, name, v - h), FMAX)
    return (fu - fd) / (2 * h), (Pu - Pd) / (2 * h)


@pytest.mark.parametrize("changes, wrt", CASES, ids=lambda v: "+".join(c for c, _ in v) if isinstance(v[0], tuple)
                         and isinstance(v[0][0], str) and isinstance(v[0][1], dict) else "")
def test_the_modes_derivatives_are_the_full_models_differences(fv: FrameVariants, changes: list, wrt: list) -> None:
    """Frequencies and shape products equal :meth:`modes_of`'s, and their derivatives equal central differences
    of the full model within 1e-5 (frequencies) and 1e-4 (shape products) of the largest."""
    f, P, df, dP = fv.modes_jac_of(changes, FMAX, wrt)
    g, Q = fv.modes_of(changes, FMAX)
    np.testing.assert_allclose(f, g, rtol=1e-8)
    np.testing.assert_allclose(P, Q, atol=1e-5 * np.abs(Q).max())
    for j, (i, name) in enumerate(wrt):
        dg, dQ = _central(fv, changes, i, name)
        assert np.max(np.abs(df[:, j] - dg)) <= 1e-5 * np.max(np.abs(dg))
        assert np.max(np.abs(dP[:, :, j] - dQ)) <= 1e-4 * np.max(np.abs(dQ))


def test_the_full_model_is_differentiated_alike(fv: FrameVariants) -> None:
    """Solved on the full model (``reduced`` False), the derivatives are the reduced model's."""
    changes, wrt = CASES[0]
    full = FrameVariants(None, OUTS, REFS)
    full.reduced = False
    a = fv.modes_jac_of(changes, FMAX, wrt)
    b = full.modes_jac_of(changes, FMAX, wrt)
    np.testing.assert_allclose(a[0], b[0], rtol=1e-8)
    np.testing.assert_allclose(a[2], b[2], rtol=1e-6, atol=1e-6 * np.abs(a[2]).max())


def test_the_residuals_jacobian_is_their_differences(fv: FrameVariants) -> None:
    """:func:`residuals_jac` against central differences of :func:`residuals` (the pairing held) on measured
    modes of another frame (one mode without a shape, one mode's shape rotated), both parameters of a joint."""
    truth = [("joint_stiffness", {"joint": "left:10", "factor_translational": 0.15, "factor_rotational": 1.0})]
    model = fv.model_of(truth)
    keep = model.freq_hz < 400.0
    R = model.residues[..., keep].reshape(-1, int(keep.sum())).astype(complex)
    R[:, 1] = 0.0
    R[:, 2] = R[:, 2] * np.exp(0.3j) + 0.2 * np.abs(R[:, 2]).max()
    f0 = model.freq_hz[keep] * (1 + 0.004 * np.sin(np.arange(int(keep.sum()))))
    mm = MeasuredModes(f0, 0.0005 * f0, R)
    changes = [("joint_stiffness", {"joint": "left:10", "factor_translational": 0.2, "factor_rotational": 0.3})]
    wrt = [(0, "factor_translational"), (0, "factor_rotational")]
    r, J = residuals_jac(mm, *fv.modes_jac_of(changes, FMAX, wrt))
    np.testing.assert_allclose(r, residuals(mm, *fv.modes_of(changes, FMAX)), atol=1e-9)
    assert np.any(J[:, 1] != 0) and np.all(J[1, 1] == 0)          # shapes count, but not the one without
    for j, (i, name) in enumerate(wrt):
        v = float(changes[i][1][name])
        h = 1e-4 * v
        up = residuals(mm, *fv.exact_modes_of(_moved(changes, i, name, v + h), FMAX))
        dn = residuals(mm, *fv.exact_modes_of(_moved(changes, i, name, v - h), FMAX))
        np.testing.assert_allclose(J[..., j], (up - dn) / (2 * h), atol=1e-4 * np.abs(J[..., j]).max())


def test_a_factor_at_a_flat_edge_is_moved_inside() -> None:
    """:func:`off_edges`: a log-factor stopped at its upper edge where chi2 falls by less than
    ``CHI2_RESOLUTION`` from just inside is moved just inside (and no longer at the edge); one where chi2
    falls steeply, a plain parameter and a factor inside its range stay where they are."""
    rot = ParamSpec("factor_rotational", 1e-3, 1e2)
    steep = ParamSpec("factor_translational", 1e-4, 1e2)
    plain = ParamSpec("mass_kg", 0.0, 1.0, log=False)
    x = np.array([rot.to_x(100.0), steep.to_x(1e-4), plain.to_x(0.0), rot.to_x(3.0)])
    specs = [rot, steep, plain, rot]

    def chi2_at(y: np.ndarray) -> float:       # flat in the first (1e-4 per decade), steep in the second
        return 1.0 - 1e-4 * y[0] + 5.0 * (y[1] - steep.x_bounds[0])

    y, c = off_edges(specs, x, chi2_at(x), chi2_at)
    assert not rot.at_edge(rot.from_x(y[0])) and rot.from_x(y[0]) > 50.0
    assert c <= chi2_at(x) + CHI2_RESOLUTION
    np.testing.assert_array_equal(y[1:], x[1:])
