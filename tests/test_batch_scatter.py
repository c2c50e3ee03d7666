"""The fleet's scatter in a flagged unit's diagnosis (:mod:`analysis.batch.scatter`): the SIM's global cause
scales every stiffness of the frame alike (members and springs), as a unit's manufacturing scatter does."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from analysis.batch.scatter import GLOBAL_CAUSE, ScatterSimulation, for_fleet, scaled_model
from analysis.diagnosis.physical import CauseSpec, ParamSpec
from analysis.modal import ModalModel, pole_from_fz, synthesize

MASS = np.diag([1.0, 2.0, 1.5])


class Chain:
    """A 3-mass chain of two member springs and one ground spring (a support) as a physical simulation:
    ``stiffness_shift`` scales the member springs only (a modulus: the support unchanged), ``support``
    scales the ground spring, ``all`` scales every spring (what the fleet's global cause is)."""

    outputs = ("a:1:X", "a:2:X", "a:3:X")
    references = ("a:1:X",)

    def causes(self) -> tuple:
        return (CauseSpec("support", (ParamSpec("factor", 0.01, 10.0),), description="the ground spring"),
                CauseSpec(GLOBAL_CAUSE, (ParamSpec("stiffness_factor", 0.6, 1.6),), description="the modulus"))

    def _eig(self, changes: list) -> tuple[np.ndarray, np.ndarray]:
        member, ground, every = 1.0, 1.0, 1.0
        for cause, p in changes:
            if cause == GLOBAL_CAUSE:
                member *= float(p["stiffness_factor"])
            elif cause == "support":
                ground *= float(p["factor"])
            elif cause == "all":
                every *= float(p["factor"])
        k0, k1, k2 = 3e4 * ground * every, 4e4 * member * every, 5e4 * member * every
        K = np.array([[k0 + k1, -k1, 0], [-k1, k1 + k2, -k2], [0, -k2, k2]])
        w2, phi = scipy.linalg.eigh(K, MASS)
        return np.sqrt(w2) / (2 * np.pi), phi

    def modes_of(self, changes: list, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        f, phi = self._eig(list(changes))
        keep = f <= max_freq_hz
        return f[keep], (phi[:, None, :] * phi[None, :1, :]).reshape(3, -1)[:, keep]

    def modes(self, cause: str | None, params: dict, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
        return self.modes_of([] if cause is None else [(cause, params)], max_freq_hz)

    exact_modes_of = modes_of

    def model_of(self, changes: list) -> ModalModel:
        f, phi = self._eig(list(changes))
        lam = pole_from_fz(f, 0.01)
        R = phi[:, None, :] * phi[None, :1, :] / (2j * lam.imag)[None, None, :]
        return ModalModel(poles=lam, residues=R, quantity="receptance", outputs=self.outputs,
                          references=self.references)

    def model(self, cause: str | None, params: dict) -> ModalModel:
        return self.model_of([] if cause is None else [(cause, params)])

    def first_pass(self, *args: object) -> None:       # bounds of the unscaled frame: not to be offered
        raise AssertionError("not to be called")


def test_the_fleets_global_cause_scales_every_stiffness_alike_and_the_other_causes_act_on_that_frame():
    chain, fleet = Chain(), ScatterSimulation(Chain())
    k = 1.03 ** 2
    every = [("all", {"factor": k})]
    # alone: every spring scaled (the support too), not the modulus only
    np.testing.assert_allclose(fleet.modes(GLOBAL_CAUSE, {"stiffness_factor": k}, 1e4)[0],
                               chain.modes_of(every, 1e4)[0], rtol=1e-12)
    assert not np.allclose(chain.modes(GLOBAL_CAUSE, {"stiffness_factor": k}, 1e4)[0] / chain.modes(None, {}, 1e4)[0],
                           1.03, rtol=1e-3)                                  # the modulus alone is not one factor
    # with a support change: the support scaled on the scaled frame; the same for the exact solver
    pair = [("support", {"factor": 0.2}), (GLOBAL_CAUSE, {"stiffness_factor": k})]
    for got in (fleet.modes_of(pair, 1e4), fleet.exact_modes_of(pair, 1e4)):
        want = chain.modes_of([("support", {"factor": 0.2}), *every], 1e4)
        np.testing.assert_allclose(got[0], want[0], rtol=1e-12)
        np.testing.assert_allclose(got[1], want[1], rtol=1e-10)
    # the other causes and the nominal frame are the simulation's own
    np.testing.assert_array_equal(fleet.modes("support", {"factor": 0.2}, 1e4)[0],
                                  chain.modes("support", {"factor": 0.2}, 1e4)[0])
    # the band asked for is the scaled frame's: its second mode just above max_freq_hz stays out
    f = fleet.modes(GLOBAL_CAUSE, {"stiffness_factor": k}, 1e4)[0]
    assert fleet.modes(GLOBAL_CAUSE, {"stiffness_factor": k}, float(f[1]) * 0.999)[0].size == 1
    # the models: FRFs of the stiffer frame, alone and with another cause
    lines = np.linspace(5.0, 80.0, 500)
    for changes in ([(GLOBAL_CAUSE, {"stiffness_factor": k})], pair):
        want = chain.model_of([*(c for c in changes if c[0] != GLOBAL_CAUSE), *every])
        np.testing.assert_allclose(synthesize(fleet.model_of(changes), lines).H, synthesize(want, lines).H, rtol=1e-9)
    np.testing.assert_allclose(synthesize(fleet.model(GLOBAL_CAUSE, {"stiffness_factor": k}), lines).H,
                               synthesize(chain.model_of(every), lines).H, rtol=1e-9)
    assert not hasattr(fleet, "first_pass")
    assert fleet.outputs == Chain.outputs
    described = {c.name: c.description for c in fleet.causes()}
    assert "springs" in described[GLOBAL_CAUSE] and described["support"] == "the ground spring"


def test_a_scaled_model_in_accelerance_is_the_stiffer_frames():
    lines = np.linspace(5.0, 80.0, 400)
    chain = Chain()

    def accelerance(m: ModalModel) -> ModalModel:
        return replace(m, residues=np.asarray(m.residues) * np.asarray(m.poles)[None, None, :] ** 2,
                       quantity="accelerance")

    got = scaled_model(accelerance(chain.model(None, {})), 1.02)
    want = accelerance(chain.model_of([("all", {"factor": 1.02 ** 2})]))
    np.testing.assert_allclose(synthesize(got, lines).H, synthesize(want, lines).H, rtol=1e-9)
    with pytest.raises(ValueError, match="residual"):
        scaled_model(replace(chain.model(None, {}), upper_residual=np.ones((3, 1))), 1.02)


def test_for_fleet_leaves_an_frf_file_and_a_simulation_without_the_global_cause_alone():
    assert isinstance(for_fleet(Chain()), ScatterSimulation)
    assert for_fleet(Path("golden.h5")) == Path("golden.h5")

    class NoGlobal(Chain):
        def causes(self) -> tuple:
            return Chain.causes(self)[:1]

    sim = NoGlobal()
    assert for_fleet(sim) is sim


class Chain5(Chain):
    """:class:`Chain` with more causes: each member spring (``m1``, ``m2``) and the last mass (``mass3``)."""

    def causes(self) -> tuple:
        one = (ParamSpec("factor", 0.1, 10.0),)
        return (*Chain.causes(self), CauseSpec("m1", one), CauseSpec("m2", one), CauseSpec("mass3", one))

    def _eig(self, changes: list) -> tuple[np.ndarray, np.ndarray]:
        f = {c: float(p.get("factor", 1.0)) for c, p in changes}
        member = float(np.prod([float(p["stiffness_factor"]) for c, p in changes if c == GLOBAL_CAUSE]))
        k0 = 3e4 * f.get("support", 1.0) * f.get("all", 1.0)
        k1 = 4e4 * member * f.get("m1", 1.0) * f.get("all", 1.0)
        k2 = 5e4 * member * f.get("m2", 1.0) * f.get("all", 1.0)
        K = np.array([[k0 + k1, -k1, 0], [-k1, k1 + k2, -k2], [0, -k2, k2]])
        M = MASS.copy()
        M[2, 2] *= f.get("mass3", 1.0)
        w2, phi = scipy.linalg.eigh(K, M)
        return np.sqrt(w2) / (2 * np.pi), phi


def test_the_scatters_global_cause_is_always_tried_on_top_of_a_first_cause():
    from analysis.diagnosis.physical import MeasuredModes, PhysicalFit
    from analysis.diagnosis.physical_verdict import _seconds

    truth = Chain5()
    f, P = truth.modes_of([("support", {"factor": 0.3}), ("m1", {"factor": 0.7})], 1e4)
    mm = MeasuredModes(freq_hz=f, freq_std_hz=1e-4 * f, shapes=P.astype(complex))
    first = PhysicalFit(cause="support", params={"factor": 0.3}, free=("factor",), chi2=1.0)
    plain, fleet = Chain5(), ScatterSimulation(Chain5())
    specs = {c.name: c for c in plain.causes()}
    best = [s.cause for s in _seconds(plain, specs, mm, 2 * float(f[-1]), first, None, n=1)]
    assert best == ["m1"]                                     # the change in the data ranks first
    tried = [s.cause for s in _seconds(fleet, specs, mm, 2 * float(f[-1]), first, None, n=1)]
    assert tried == ["m1", GLOBAL_CAUSE]                      # and a fleet's unit tries its scatter's cause too
    assert [s.cause for s in _seconds(fleet, specs, mm, 2 * float(f[-1]), first, None, n=None)][0] == "m1"


# ------------------------------------------------------------------ the fleet's simulation of the FE frame
OUTS = ["right:6:-X", "right:4:-X", "left:6:X", "top:4:Z", "top:2:Z", "left:9:Y"]
REFS = ["right:6:-X", "top:4:Z"]
FMAX = 500.0
K = 1.03


@pytest.fixture(scope="module")
def frame_fleet() -> ScatterSimulation:
    from simulator.physical import FrameVariants

    return ScatterSimulation(FrameVariants(None, OUTS, REFS))


def _moved(changes: list, i: int, name: str, v: float) -> list:
    out = list(changes)
    out[i] = (changes[i][0], {**changes[i][1], name: v})
    return out


@pytest.mark.parametrize("changes, wrt", [
    ([("element_stiffness", {"element": "top:1", "factor": 0.4}), (GLOBAL_CAUSE, {"stiffness_factor": K})],
     [(0, "factor"), (1, "stiffness_factor")]),
    ([(GLOBAL_CAUSE, {"stiffness_factor": K}),
      ("joint_stiffness", {"joint": "left:10", "factor_translational": 0.1, "factor_rotational": 0.3})],
     [(1, "factor_translational"), (0, "stiffness_factor"), (1, "factor_rotational")]),
    ([(GLOBAL_CAUSE, {"stiffness_factor": K})], [(0, "stiffness_factor")]),
    ([("support_stiffness", {"support": "left:0", "factor_translational": 0.2, "factor_rotational": 0.5}),
      (GLOBAL_CAUSE, {"stiffness_factor": K})], [(0, "factor_translational")]),
], ids=["crack+global", "global+joint", "global", "support+global(support only)"])
def test_the_fleets_modes_derivatives_are_the_scaled_full_models_differences(frame_fleet, changes, wrt):
    """The fleet's simulation of the FE frame gives the modes' derivatives (so its fits take the analytic Jacobian):
    frequencies and shape products as its ``modes_of``, derivatives as central differences of its full model (every
    stiffness scaled by the global factor) within 1e-5 (frequencies) and 1e-4 (shape products) of the largest."""
    assert frame_fleet.modes_jac_of is not None
    f, P, df, dP = frame_fleet.modes_jac_of(changes, FMAX, wrt)
    g, Q = frame_fleet.modes_of(changes, FMAX)
    np.testing.assert_allclose(f, g, rtol=1e-8)
    np.testing.assert_allclose(P, Q, atol=1e-5 * np.abs(Q).max())
    assert df.shape == (f.size, len(wrt)) and dP.shape == (*P.shape, len(wrt))
    for j, (i, name) in enumerate(wrt):
        v = float(changes[i][1][name])
        h = 1e-4 * v
        fu, Pu = frame_fleet.exact_modes_of(_moved(changes, i, name, v + h), FMAX)
        fd, Pd = frame_fleet.exact_modes_of(_moved(changes, i, name, v - h), FMAX)
        dg, dQ = (fu - fd) / (2 * h), (Pu - Pd) / (2 * h)
        assert np.max(np.abs(df[:, j] - dg)) <= 1e-5 * np.max(np.abs(dg))
        assert np.max(np.abs(dP[:, :, j] - dQ)) <= 1e-4 * max(np.max(np.abs(dQ)), np.abs(P).max() * 1e-3)


def test_the_fleets_frame_with_changes_applied_is_that_frame(frame_fleet):
    """``on_top(first)``: the fleet's frame with ``first`` (a crack and the global cause) as its nominal; its modes
    and derivatives of further changes are those of ``first + changes`` on the fleet's frame (reduced models of
    different bases: within 1e-6 on the frequencies)."""
    crack = ("element_stiffness", {"element": "top:1", "factor": 0.4})
    glob = (GLOBAL_CAUSE, {"stiffness_factor": K})
    joint = ("joint_stiffness", {"joint": "left:10", "factor_translational": 0.1, "factor_rotational": 0.3})
    for first in ([crack, glob], [glob], [crack]):
        top = frame_fleet.on_top(first)
        assert isinstance(top, ScatterSimulation)
        for more in ([joint], [glob, joint], []):
            want = frame_fleet.exact_modes_of([*first, *more], FMAX)
            got = top.modes_of(more, FMAX)
            np.testing.assert_allclose(got[0], want[0], rtol=1e-6)
            np.testing.assert_allclose(np.abs(got[1]), np.abs(want[1]), atol=1e-4 * np.abs(want[1]).max())
            np.testing.assert_allclose(top.exact_modes_of(more, FMAX)[0], want[0], rtol=1e-9)
        f, _, df, _ = top.modes_jac_of([joint], FMAX, [(0, "factor_translational")])
        f1, _, df1, _ = frame_fleet.modes_jac_of([*first, joint], FMAX, [(len(first), "factor_translational")])
        np.testing.assert_allclose(f, f1, rtol=1e-6)
        np.testing.assert_allclose(df, df1, atol=1e-4 * np.abs(df1).max())


def test_the_fleets_simulation_offers_derivatives_and_changed_frames_only_when_the_wrapped_one_does():
    fleet = ScatterSimulation(Chain())
    assert not hasattr(fleet, "modes_jac_of") and not hasattr(fleet, "on_top")


def test_a_candidate_asked_at_nearby_bands_and_factors_is_one_question_to_the_simulation():
    """Each flagged unit asks for modes up to its own band (moved by its scatter) and, with the global cause, up to
    the band over the frequency factor: the fleet's simulation asks the wrapped one up to the next step of one log
    grid (so the wrapped simulation's kept answers serve every unit) and cuts the modes at the band asked for."""
    from analysis.batch.scatter import solve_limit_hz

    class Asked(Chain):
        def __init__(self) -> None:
            self.asked: list[float] = []

        def modes_of(self, changes: list, max_freq_hz: float) -> tuple[np.ndarray, np.ndarray]:
            self.asked.append(float(max_freq_hz))
            return Chain.modes_of(self, changes, max_freq_hz)

    chain = Asked()
    fleet = ScatterSimulation(chain)
    f_all = Chain().modes(None, {}, 1e4)[0]
    step = solve_limit_hz(1.05 * float(f_all[1]))     # a step of the grid above the second mode, below the third
    assert f_all[2] > step
    band = step / 1.012
    support = ("support", {"factor": 0.5})
    for top in (band, 1.004 * band):
        for k in (1.0, 1.002 ** 2, 0.999 ** 2):
            got = fleet.modes_of([support, (GLOBAL_CAUSE, {"stiffness_factor": k})], top)
            want = Chain().modes_of([support, ("all", {"factor": k})], top)
            np.testing.assert_allclose(got[0], want[0], rtol=1e-12)        # cut at the band asked for
            np.testing.assert_allclose(got[1], want[1], rtol=1e-10)
    assert set(chain.asked) == {step}


def test_the_simulations_kept_answers_drop_the_least_recently_used(monkeypatch, frame_fleet):
    """A batch worker's simulation serves every flagged unit: the answers it keeps drop the least recently used when
    full (an answer every unit asks stays while each unit's own come and go), not all at once."""
    import simulator.physical as physical

    fv = frame_fleet.simulation
    monkeypatch.setattr(physical, "_MEMO_SIZE", 3)
    monkeypatch.setattr(fv, "_memo", {})
    solved: list = []
    real = fv._modes_reduced
    monkeypatch.setattr(fv, "_modes_reduced", lambda changes, fmax: solved.append(changes) or real(changes, fmax))

    def ask(factor: float) -> None:
        fv.modes_of([("element_stiffness", {"element": "top:1", "factor": factor})], FMAX)

    for f in (0.5, 0.6, 0.7, 0.5, 0.8, 0.5, 0.9):       # 0.5 asked again and again between the others
        ask(f)
    assert len(solved) == 5                              # 0.5 solved once
    assert len(fv._memo) == 3
    ask(0.6)                                             # the least recently used: dropped, solved again
    assert len(solved) == 6
