"""The local resonator effect against the exact coupled solution of a spring-mass model with an
attached spring-mass (solved directly per line, not from modes)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import eigh

from analysis.diagnosis.effects import EffectError, predict
from analysis.diagnosis.resonator import apply_local_resonator
from analysis.modal import ModalModel


def _chain(zeta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, ModalModel]:
    M = np.diag([2.0, 1.5, 1.0])
    K = 1e5 * np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]])
    w2, phi = eigh(K, M)                                   # mass-normalised shapes
    wn = np.sqrt(w2)
    lam = wn * (-zeta + 1j * np.sqrt(1 - zeta ** 2))
    R = phi[:, None, :] * phi[[0]][None, :, :] / (2j * lam.imag)[None, None, :]
    model = ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none",
                       outputs=("1", "2", "3"), references=("1",), meta={"output_shapes": phi})
    C = M @ phi @ np.diag(2 * zeta * wn) @ phi.T @ M     # the chain's own (modal) damping
    return M, K, C, model


def _exact(M, K, C, point, ma, fa, za, f):
    """Receptance at the three masses, force at mass 1, the resonator solved with them (4 DOF)."""
    ka, ca = ma * (2 * np.pi * fa) ** 2, 2 * za * ma * 2 * np.pi * fa
    Ma, Ka, Ca = (np.zeros((4, 4)) for _ in range(3))
    Ma[:3, :3], Ka[:3, :3], Ca[:3, :3] = M, K, C
    Ma[3, 3] = ma
    u = np.zeros(4)
    u[point], u[3] = 1.0, -1.0
    Ka += ka * np.outer(u, u)
    Ca += ca * np.outer(u, u)
    H = np.empty((3, f.size), complex)
    for k, w in enumerate(2 * np.pi * f):
        H[:, k] = np.linalg.solve(Ka - w ** 2 * Ma + 1j * w * Ca, np.eye(4)[:, 0])[:3]
    return H, Ka, Ma


def test_local_resonator_matches_the_coupled_solution():
    M, K, C, model = _chain(1e-4)
    spec = {"effect": "local_resonator", "point": "3", "mass_kg": 0.08, "frequency_hz": 45.0, "zeta": 1e-4}
    f = np.linspace(5.0, 120.0, 2301)
    H, Ka, Ma = _exact(M, K, C, 2, 0.08, 45.0, 1e-4, f)
    ext = predict(model, f, "receptance", [spec]).H[:, 0]
    # one mode more; the undamped frequencies are the coupled system's to machine precision
    applied = apply_local_resonator(model, spec)
    assert applied.poles.size == 4
    assert np.allclose(np.sort(np.abs(applied.poles)), np.sqrt(eigh(Ka, Ma, eigvals_only=True)), rtol=1e-6)
    # what is left: the damping's coupling of modes below DAMPING_COUPLING, kept as projected damping
    assert np.max(np.abs(ext - H)) / np.max(np.abs(H)) < 1e-4
    # and without the resonator the model misses by far more
    bare = predict(model, f, "receptance").H[:, 0]
    assert np.max(np.abs(bare - H)) / np.max(np.abs(H)) > 0.1


def test_a_damped_resonator_beside_a_light_mode_is_exact():
    """A resonator 50 times more damped than the chain, tuned near its second mode: its damper couples the
    modes (no modal damping), and the complex modes give the exact FRFs and poles of the coupled system."""
    from scipy.linalg import eig

    M, K, C, model = _chain(0.001)
    f2 = float(np.sort(np.abs(model.poles))[1]) / (2 * np.pi)
    spec = {"effect": "local_resonator", "point": "2", "mass_kg": 0.05, "frequency_hz": 0.95 * f2, "zeta": 0.05}
    f = np.linspace(5.0, 120.0, 2301)
    Ca = np.zeros((4, 4))
    H, Ka, Ma = _exact(M, K, C, 1, 0.05, 0.95 * f2, 0.05, f)
    u = np.array([0.0, 1.0, 0.0, -1.0])
    Ca[:3, :3] = C
    Ca += 2 * 0.05 * 0.05 * 2 * np.pi * 0.95 * f2 * np.outer(u, u)
    A = np.block([[np.zeros((4, 4)), np.eye(4)], [-np.linalg.solve(Ma, Ka), -np.linalg.solve(Ma, Ca)]])
    lam = eig(A, right=False)
    lam = np.sort_complex(lam[lam.imag > 0])
    applied = apply_local_resonator(model, spec)
    assert np.allclose(np.sort_complex(applied.poles), lam, rtol=1e-9)
    ext = predict(model, f, "receptance", [spec]).H[:, 0]
    assert np.max(np.abs(ext - H)) / np.max(np.abs(H)) < 1e-9


def test_coupling_form_equals_point_form_and_bad_input_is_named():
    _, _, _, model = _chain(0.01)
    f = np.linspace(5.0, 120.0, 301)
    phi = model.meta["output_shapes"]
    a = predict(model, f, "receptance", [{"effect": "local_resonator", "point": "2", "mass_kg": 0.05,
                                         "frequency_hz": 30.0, "zeta": 0.02}]).H
    b = predict(model, f, "receptance", [{"effect": "local_resonator", "coupling": list(np.sqrt(0.05) * phi[1]),
                                         "frequency_hz": 30.0, "zeta": 0.02}]).H
    assert np.allclose(a, b, rtol=1e-12, atol=0)
    with pytest.raises(EffectError, match="point"):
        predict(model, f, "receptance", [{"effect": "local_resonator", "point": "9", "frequency_hz": 30.0}])
    bare = ModalModel(poles=model.poles, residues=model.residues, quantity="receptance", residual_form="none",
                      outputs=model.outputs, references=model.references)
    with pytest.raises(EffectError, match="output_shapes"):
        predict(bare, f, "receptance", [{"effect": "local_resonator", "point": "2", "frequency_hz": 30.0}])


def _measured(H: np.ndarray, f: np.ndarray, seed: int, relative: float = 0.005):
    """The exact receptances (force at mass 1) as a measurement with complex noise of ``relative`` x |H|."""
    from analysis.frf import FRFSet

    rng = np.random.default_rng(seed)
    noise = (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2)
    return FRFSet(freq_hz=f, H=(H + relative * np.abs(H) * noise)[:, None, :], quantity="receptance",
                  outputs=("1", "2", "3"), references=("1",))


def test_a_heavier_sensor_is_a_mass_not_a_resonator():
    """A mass at output 2 (the exact chain with that mass, every mode in the model): the mass at that
    output is found and fits it several times better than the best resonator (a resonator of its own
    frequency in the band cannot act as a mass at every frequency)."""
    from analysis.diagnosis.compare import line_weights
    from analysis.diagnosis.effects import FitContext, fit_local_resonator, fit_mass_loading

    M, K, C, model = _chain(0.005)
    f = np.linspace(5.0, 120.0, 300)
    Ml = M.copy()
    Ml[1, 1] += 0.1
    H = np.empty((3, f.size), complex)
    for k, w in enumerate(2 * np.pi * f):
        H[:, k] = np.linalg.solve(K - w ** 2 * Ml + 1j * w * C, np.eye(3)[:, 0])
    meas = _measured(H, f, 4)
    ctx = FitContext(measured=meas, base=model, weights=line_weights(meas), sim=predict(model, f, "receptance"))
    lines = np.ones(f.size, bool)
    mass = fit_mass_loading(ctx, lines)
    assert mass["sensor"] == "2" and mass["mass_kg"] == pytest.approx(0.1, rel=0.02)
    res = fit_local_resonator(ctx, lines)

    def cost(name: str, params: dict) -> float:
        return ctx.cost(predict(model, f, "receptance", [{"effect": name, **params}]).H, lines)
    assert cost("mass_loading", mass) < 0.5 * cost("local_resonator", res), res
