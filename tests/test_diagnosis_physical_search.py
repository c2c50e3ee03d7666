"""The search over a cause's choice keeps every option that could win.

A cause with a choice (a node, an element) is screened on a grid of its parameters; the screen orders the
options and bounds each one's chi2 from below (the frequencies at the corners of a box of monotone parameters
bound every frequency inside it). An option is left unfitted only when its bound is above the best fit: the
search returns what fitting every option in full returns. The data: noise-free modes of the frame with a
change the fitted variant does not hold exactly (a heavy mass with a plate's rotary inertia fitted as a mass
with a cube's), where the grid's best points rank the options poorly.
"""
from __future__ import annotations

import numpy as np
import pytest
from shared_frames import frame_variants
from test_diagnosis_physical import OUTS, REFS, _noise_free_modes

from analysis.diagnosis.physical import _chi2_bound, _fit_continuous, _nominal, _screen, fit_cause
from simulator.physical import FrameVariants

FMAX = 700.0


def _exhaustive(fv: FrameVariants, spec, free: tuple, mm) -> tuple[float, str]:  # the least chi2, its option
    """Every option fitted in full (from the nominal and from the best point of a grid): the least chi2 and its option."""
    specs = [s for s in spec.params if s.name in free]
    fixed = {k: v for k, v in _nominal(spec).items() if k not in free}
    sel = np.ones(mm.freq_hz.size, bool)
    return min((_fit_continuous(fv, spec, specs, {**fixed, spec.choice: o}, mm, sel, FMAX)[1], o) for o in spec.options)


@pytest.mark.parametrize("node", ["right:8", "left:5"])
def test_a_heavy_mass_fitted_with_the_wrong_inertia_gets_the_exhaustive_searchs_option(node) -> None:
    """5 kg with six times a cube's rotary inertia, fitted as a mass with a cube's: the search's fit is at least
    as good as fitting every node in full (a screen that kept its five best grid points returned top:0 at chi2
    754 for right:8, where right:6 fits at 608)."""
    fv = frame_variants(None, OUTS, REFS)
    spec = {c.name: c for c in fv.causes()}["added_mass"]
    mm = _noise_free_modes(fv, [("added_mass", {"point": node, "mass_kg": 5.0, "inertia_factor": 6.0})])
    p, chi2, ranked = fit_cause(fv, spec, ("mass_kg",), mm, np.ones(mm.freq_hz.size, bool), FMAX)
    best, _ = _exhaustive(fv, spec, ("mass_kg",), mm)
    assert chi2 <= best * (1 + 1e-6) + 1e-9
    assert len(ranked) < len(spec.options)          # the bound left options unfitted, and none of them could win


def test_a_mass_with_its_rotary_inertia_is_found_at_its_node() -> None:
    """5 kg with six times a cube's rotary inertia, both fitted: found exactly at its node."""
    fv = frame_variants(None, OUTS, REFS)
    spec = {c.name: c for c in fv.causes()}["added_mass"]
    mm = _noise_free_modes(fv, [("added_mass", {"point": "right:2", "mass_kg": 5.0, "inertia_factor": 6.0})])
    p, chi2, _ = fit_cause(fv, spec, ("mass_kg", "inertia_factor"), mm, np.ones(mm.freq_hz.size, bool), FMAX)
    assert p["point"] == "right:2" and chi2 < 1e-4
    assert p["mass_kg"] == pytest.approx(5.0, rel=1e-3)
    assert p["inertia_factor"] == pytest.approx(6.0, rel=1e-3)


@pytest.mark.parametrize("cause, free, option", [("added_mass", ("mass_kg", "inertia_factor"), "top:3"),
                                                 ("element_stiffness", ("factor",), "left:4"),
                                                 ("support_stiffness", ("factor_translational", "factor_rotational"),
                                                  "left:0")])
def test_the_bound_of_a_box_is_below_the_chi2_everywhere_inside_it(cause, free, option) -> None:
    """The screen's lower bound of a box holds at random points inside it (monotone parameters: a mass or a
    stiffness added moves every frequency one way)."""
    fv = frame_variants(None, OUTS, REFS)
    spec = {c.name: c for c in fv.causes()}[cause]
    mm = _noise_free_modes(fv, [("added_mass", {"point": "left:7", "mass_kg": 2.0}),
                                ("element_stiffness", {"element": "top:3", "factor": 0.5})])
    sel = np.ones(mm.freq_hz.size, bool)
    specs = [s for s in spec.params if s.name in free]
    fixed = {k: v for k, v in _nominal(spec).items() if k not in free}
    (screened,) = _screen(fv, spec, specs, fixed, mm, sel, FMAX, [option])
    rng = np.random.default_rng(7)
    from analysis.diagnosis.physical import residuals

    for bound, box in screened.cells:
        corners = [screened.at.at(x)[1] for x in np.array(np.meshgrid(*box)).reshape(len(box), -1).T]
        assert _chi2_bound(mm, sel, corners) == pytest.approx(bound)
        for _ in range(3):
            x = [rng.uniform(a, b) for a, b in box]
            p = {**fixed, spec.choice: option, **{s.name: s.from_x(xi) for s, xi in zip(specs, x)}}
            chi2 = float(np.sum(residuals(mm, *fv.modes(cause, p, FMAX))[sel] ** 2))
            assert chi2 >= bound - 1e-9


def test_a_stiffer_right_column_is_that_member() -> None:
    """The right column's second moments x 1.4 (its section in the configuration, its mass unchanged): every
    member is fitted in full and the right column comes back with its factor; the left column, the closest
    other option, fits far worse."""
    from test_diagnosis_physical import _sensor_masses

    from analysis.diagnosis.physical import MeasuredModes
    from simulator.config import FrameConfig
    from simulator.fem import FrameModel, section_properties

    base = FrameConfig.load()
    sp = section_properties(base.sections[base.components["right"].section])
    cfg = base.with_overrides({"sections": {"stiff": {"shape": "explicit", "area_m2": sp.A, "iy_m4": 1.4 * sp.Iy,
                                                      "iz_m4": 1.4 * sp.Iz, "j_m4": sp.J}},
                               "components": {"right": {"section": "stiff"}}})
    model = FrameModel.from_config(cfg, _sensor_masses(cfg)).modal_model(OUTS, REFS, "receptance")
    keep = (model.freq_hz > 1.0) & (model.freq_hz < 460.0)
    mm = MeasuredModes(model.freq_hz[keep], np.zeros(int(keep.sum())), model.residues[..., keep].reshape(-1, int(keep.sum())))
    fv = frame_variants(None, OUTS, REFS)
    spec = {c.name: c for c in fv.causes()}["member_stiffness"]
    p, chi2, ranked = fit_cause(fv, spec, ("factor",), mm, np.ones(mm.freq_hz.size, bool), FMAX)
    assert p["component"] == "right" and p["factor"] == pytest.approx(1.4, rel=0.01)
    assert [o for _, o, _ in ranked] == ["right", "left", "top"] and ranked[1][0] > 100 * max(chi2, 1.0)
