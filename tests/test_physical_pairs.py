"""Two physical causes at once: the first cause's choice made again with the second change applied."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis.physical import MeasuredModes, PhysicalFit, fit_cause
from analysis.diagnosis.physical_pairs import OnTop, fit_pair, refit_on_top
from simulator.physical import FrameVariants

OUTS = ["left:9:Y", "top:4:X", "right:4:-Z"]
REFS = ["right:6:-X", "right:4:-X", "left:6:X", "top:4:Z", "top:2:Z", "left:9:Y"]


def test_a_mass_placed_wrong_beside_a_second_change_finds_its_node() -> None:
    """Noise-free modes of a 2 kg mass at top:6 with the supports' rotational springs x 0.3. A first fit of
    the mass put at top:4 (as a single-cause fit pulled aside by the supports may): with the supports'
    change applied, the mass is searched over every node again and the pair gives both back."""
    fv = FrameVariants(None, OUTS, REFS)
    truth = [("added_mass", {"point": "top:6", "mass_kg": 2.0}),
             ("support_stiffness", {"factor_translational": 1.0, "factor_rotational": 0.3})]
    model = fv.model_of(truth)
    keep = model.freq_hz < 460.0
    mm = MeasuredModes(model.freq_hz[keep], np.zeros(int(keep.sum())),
                       model.residues[..., keep].reshape(-1, int(keep.sum())))
    specs = {c.name: c for c in fv.causes()}
    allsel = np.ones(mm.freq_hz.size, bool)
    wrong = PhysicalFit("added_mass", {"point": "top:4", "mass_kg": 1.5}, ("mass_kg",), np.inf)
    pb, cb, _ = fit_cause(OnTop(fv, [(wrong.cause, wrong.params)]), specs["support_stiffness"], ("factor_rotational",),
                          mm, allsel, 700.0)
    second = PhysicalFit("support_stiffness", pb, ("factor_rotational",), cb)
    again = refit_on_top(fv, specs["added_mass"], wrong, second, mm, 700.0)
    assert again.params["point"] == "top:6" and again.ranked[0][1] == "top:6"
    pair = fit_pair(fv, [specs["added_mass"], specs["support_stiffness"]], [again, second], mm, 700.0)
    assert pair.params[0]["point"] == "top:6"
    assert pair.params[0]["mass_kg"] == pytest.approx(2.0, rel=1e-3)
    assert pair.params[1]["factor_rotational"] == pytest.approx(0.3, rel=1e-3)
    assert pair.chi2_cv < 1e-3
    # a cause without a choice is left to the pair's refinement
    assert refit_on_top(fv, specs["support_stiffness"], second, again, mm, 700.0) is second
