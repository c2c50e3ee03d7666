"""The local resonator's fit uses the exact Jacobian of its residual vector: checked here against central
finite differences of the residual itself (predict, as the fit evaluates it), with the known processing
(finite record, exponential window) and FRF effects before it, for a resonator whose damper couples the
modes (complex modes of a block) and for a weakly coupled one beside a pseudo-mode above the band."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import eigh

from analysis.diagnosis.compare import line_weights
from analysis.diagnosis.effects import CATALOGUE, FitContext, predict
from analysis.diagnosis.resonator import _damped, _matrices, apply_local_resonator, local_resonator_derivative
from analysis.diagnosis.resonator_search import _resonator_jacobian
from analysis.frf import FRFSet
from analysis.modal import ModalModel

MASSES = np.array([2.0, 1.5, 1.0, 1.2])
K_CHAIN = 1e5 * np.array([[2.0, -1.0, 0.0, 0.0], [-1.0, 2.0, -1.0, 0.0], [0.0, -1.0, 2.0, -1.0], [0.0, 0.0, -1.0, 1.0]])
OUTS = ("1", "2", "3")


def _model(zeta: float, above: bool) -> ModalModel:
    """The chain's modes (receptance, mass-normalised shapes at masses 1-3, force at mass 1); with ``above``
    its highest mode is a pseudo-mode above the band (``meta["above_band_modes"]``)."""
    w2, phi = eigh(K_CHAIN, np.diag(MASSES))
    lam = np.sqrt(w2) * (-zeta + 1j * np.sqrt(1 - zeta ** 2))
    shapes = phi[:3]
    R = shapes[:, None, :] * shapes[[0]][None, :, :] / (2j * lam.imag)[None, None, :]
    meta: dict = {"output_shapes": shapes}
    if above:
        meta["above_band_modes"] = 1
    return ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none", outputs=OUTS,
                      references=("1",), meta=meta)


def _fd_check(model: ModalModel, x: np.ndarray, prior: tuple) -> None:
    n_all = model.poles.size
    n_free = n_all - int(model.meta.get("above_band_modes", 0))
    f = np.linspace(3.0, 1.1 * float(np.abs(model.poles[n_free - 1])) / (2 * np.pi), 400)
    rng = np.random.default_rng(3)
    H = predict(model, f, "accelerance", prior).H
    meas = FRFSet(freq_hz=f, H=H * (1 + 0.1 * rng.standard_normal(H.shape)), quantity="accelerance", outputs=OUTS,
                  references=("1",))
    w = line_weights(meas)
    ctx = FitContext(measured=meas, base=model, weights=w, sim=predict(model, f, "accelerance", prior), prior=prior)
    sw = np.sqrt(w)

    def spec(x: np.ndarray) -> dict:
        return {"effect": "local_resonator", "frequency_hz": float(x[0]), "zeta": float(np.exp(x[1])),
                "coupling": [float(v) for v in x[2:]] + [0.0] * (n_all - n_free)}

    def resid(x: np.ndarray) -> np.ndarray:
        e = (meas.H - predict(model, f, "accelerance", ctx.effects(spec(x))).H) * sw
        return np.concatenate([e.real.ravel(), e.imag.ravel()])

    jac = _resonator_jacobian(ctx, f, sw, n_free, spec, CATALOGUE.lookup)
    assert callable(jac)
    J = jac(x)
    assert J.shape == (resid(x).size, n_free + 2)
    for p in range(x.size):
        h = 1e-5 * max(abs(x[p]), 0.01)  # central differences
        up, down = x.copy(), x.copy()
        up[p] += h
        down[p] -= h
        fd = (resid(up) - resid(down)) / (2 * h)
        assert np.linalg.norm(J[:, p] - fd) <= 1e-6 * np.linalg.norm(fd), p


PRIOR = ({"effect": "record_length", "record_s": 0.8, "pretrigger_s": 0.05},
         {"effect": "exponential_window", "exp_window_tau_s": 0.5},
         {"effect": "sensor_highpass", "corner_hz": 2.0, "order": 1},
         {"effect": "time_delay", "delay_s": 2e-4},
         {"effect": "residual_modes", "upper": [[1e-7], [5e-8], [-3e-8]], "lower": [[0.0], [0.0], [0.0]]})


@pytest.mark.parametrize("prior", [(), PRIOR], ids=["plain", "processing_and_frf_effects"])
def test_the_jacobian_of_a_damper_coupling_the_modes_is_exact(prior: tuple) -> None:
    model = _model(0.002, above=False)
    wn = np.abs(model.poles)
    fa = 0.97 * float(wn[1]) / (2 * np.pi)
    g = np.array([0.12, -0.2, 0.15, 0.05])
    # the resonator's damper couples modes here: the complex modes of a block are differentiated
    assert _damped(*_matrices(wn, -model.poles.real / wn, g, 2 * np.pi * fa, 0.08)).S.size >= 2
    _fd_check(model, np.concatenate([[fa, np.log(0.08)], g]), prior)


def test_the_jacobian_of_a_weak_resonator_beside_a_pseudo_mode_is_exact() -> None:
    """Beside a pseudo-mode above the band, with a fixed FRF term (an FRF-file simulation's
    ``meta["frf_correction"]``, on lines of its own) that the resonator does not move."""
    model = _model(0.01, above=True)
    fc = np.linspace(1.0, 80.0, 57)
    corr = FRFSet(freq_hz=fc, H=(2e-7 + 1e-7j * np.sin(fc / 9.0))[None, None, :] * np.array([1.0, -0.5, 0.3])[:, None, None],
                  quantity="receptance", outputs=OUTS, references=("1",))
    model = ModalModel(poles=model.poles, residues=model.residues, quantity="receptance", residual_form="none",
                       outputs=OUTS, references=("1",), meta={**model.meta, "frf_correction": corr})
    wn = np.abs(model.poles)
    fa = float(np.sqrt(wn[0] * wn[1])) / (2 * np.pi)
    _fd_check(model, np.array([fa, np.log(0.01), 0.03, -0.05, 0.02]), PRIOR)


def test_the_derivative_keeps_the_resonated_model() -> None:
    """local_resonator_derivative's model is apply_local_resonator's, and its residue derivative matches the
    model's residues moved by a small step of the coupling."""
    model = _model(0.002, above=False)
    params = {"frequency_hz": 0.97 * float(np.abs(model.poles[1])) / (2 * np.pi), "zeta": 0.08,
              "coupling": [0.12, -0.2, 0.15, 0.05]}
    moved, dpoles, dresidues = local_resonator_derivative(model, params)
    applied = apply_local_resonator(model, params)
    assert np.array_equal(moved.poles, applied.poles) and np.array_equal(moved.residues, applied.residues)
    assert dpoles.shape == (5, 6) and dresidues.shape == (3, 1, 5, 6)
    h = 1e-7
    up = apply_local_resonator(model, {**params, "coupling": [0.12, -0.2 + h, 0.15, 0.05]})
    down = apply_local_resonator(model, {**params, "coupling": [0.12, -0.2 - h, 0.15, 0.05]})
    fd = (up.residues - down.residues) / (2 * h)
    assert np.max(np.abs(dresidues[..., 3] - fd)) <= 1e-6 * np.max(np.abs(fd))


def test_the_overdamped_fallback_is_differentiated_too() -> None:
    """A heavy resonator damped beyond the fit's range leaves too few oscillating modes: the undamped coupled
    modes with their projected damping (:func:`coupled_modes`) are the model, and their derivative is exact."""
    model = _model(0.002, above=False)
    wn = np.abs(model.poles)
    theta = np.array([46.26, 0.486, -2.75, -2.90, 1.88, 2.48])
    assert _damped(*_matrices(wn, -model.poles.real / wn, theta[2:], 2 * np.pi * theta[0], theta[1])) is None

    def moved(t: np.ndarray) -> ModalModel:
        return apply_local_resonator(model, {"frequency_hz": t[0], "zeta": t[1], "coupling": list(t[2:])})
    _, dpoles, dresidues = local_resonator_derivative(model, {"frequency_hz": theta[0], "zeta": theta[1],
                                                              "coupling": list(theta[2:])})
    for p in range(theta.size):
        h = 1e-6 * abs(theta[p])
        up, down = theta.copy(), theta.copy()
        up[p] += h
        down[p] -= h
        a, b = moved(up), moved(down)
        fd_poles, fd_res = (a.poles - b.poles) / (2 * h), (a.residues - b.residues) / (2 * h)
        assert np.max(np.abs(dpoles[:, p] - fd_poles)) <= 1e-6 * np.max(np.abs(fd_poles)), p
        assert np.max(np.abs(dresidues[..., p] - fd_res)) <= 1e-6 * np.max(np.abs(fd_res)), p


def test_an_frf_effect_that_mixes_lines_falls_back_to_finite_differences(monkeypatch: pytest.MonkeyPatch) -> None:
    """The Jacobian passes the FRF effects accepted before as a factor per line; one that is not (here a running
    sum over the lines) leaves the fit to finite differences."""
    from dataclasses import replace

    import analysis.diagnosis.effects as effects

    smear = effects.Effect("smear", "frf", lambda frf, params: replace(frf, H=np.cumsum(frf.H, axis=-1)),
                           lambda ctx, lines: {}, "none", "a running sum over the lines")
    monkeypatch.setitem(effects.EFFECTS, "smear", smear)
    model = _model(0.01, above=False)
    f = np.linspace(3.0, 60.0, 50)
    meas = predict(model, f, "accelerance")
    ctx = FitContext(measured=meas, base=model, weights=line_weights(meas), sim=meas)
    spec = {"effect": "local_resonator", "frequency_hz": 20.0, "zeta": 0.01, "coupling": [0.0] * 4}
    assert callable(_resonator_jacobian(ctx, f, np.ones((3, 1, f.size)), 4, lambda x: spec, CATALOGUE.lookup))
    mixed = replace(ctx, prior=({"effect": "smear"},))
    assert _resonator_jacobian(mixed, f, np.ones((3, 1, f.size)), 4, lambda x: spec, CATALOGUE.lookup) == "2-point"


def test_a_mass_added_to_an_frf_file_simulation_before_it_falls_back_to_finite_differences() -> None:
    """On a simulation given as FRFs a mass is added to the predicted FRFs after the resonator's modes
    (structural modification), which the exact Jacobian does not follow: the fit takes finite differences."""
    from dataclasses import replace

    model = _model(0.01, above=False)
    f = np.linspace(3.0, 60.0, 50)
    fixed = FRFSet(freq_hz=f, H=np.zeros((3, 1, f.size), complex), quantity="receptance", outputs=OUTS,
                   references=("1",))
    file_model = replace(model, meta={**model.meta, "frf_correction": fixed})
    meas = predict(file_model, f, "accelerance")
    ctx = FitContext(measured=meas, base=file_model, weights=line_weights(meas), sim=meas)
    spec = {"effect": "local_resonator", "frequency_hz": 20.0, "zeta": 0.01, "coupling": [0.0] * 4}
    assert callable(_resonator_jacobian(ctx, f, np.ones((3, 1, f.size)), 4, lambda x: spec, CATALOGUE.lookup))
    loaded = replace(ctx, prior=({"effect": "mass_loading", "mass_kg": 0.1, "sensor": "2"},))
    assert _resonator_jacobian(loaded, f, np.ones((3, 1, f.size)), 4, lambda x: spec, CATALOGUE.lookup) == "2-point"
    on_fe = replace(loaded, base=model)                 # on a modal model the mass moves the modes: exact
    assert callable(_resonator_jacobian(on_fe, f, np.ones((3, 1, f.size)), 4, lambda x: spec, CATALOGUE.lookup))
