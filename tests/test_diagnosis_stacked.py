"""The diagnosis' grids evaluated at once give what each candidate gives alone: the synthesis of a model's
variants (stacked poles and residues), the loaded modes of a grid of masses, the resonator's start costs; and
the missing-mode fit made once per context and lines is the fit itself."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.linalg import eigh

from analysis.diagnosis.compare import line_weights
from analysis.diagnosis.effects import (
    CATALOGUE,
    FitContext,
    _fit_missing_mode,
    _loaded_modes,
    _mass_loaded,
    apply_mass_loading,
    fit_missing_mode,
    predict,
    synthesize_windowed,
)
from analysis.diagnosis.processing import RECORD_KEY, WINDOW_SHIFT_KEY, windowed_transfer
from analysis.diagnosis.resonator_search import _start_costs
from analysis.modal import ModalModel, pole_from_fz, pole_kernels, transfer

LABELS = ("a:1:X", "b:1:X", "c:1:X")


def _model(residual: bool = True) -> ModalModel:
    rng = np.random.default_rng(3)
    poles = pole_from_fz(np.array([12.0, 31.0, 47.0, 80.0]), np.array([0.01, 0.02, 0.015, 0.03]))
    shapes = rng.standard_normal((3, 4))
    residues = shapes[:, None, :] * shapes[[0]][None] / (2j * poles.imag)
    return ModalModel(poles=poles, residues=residues, quantity="receptance",
                      residual_form="physical" if residual else "none", outputs=LABELS, references=(LABELS[0],),
                      upper_residual=1e-7 * rng.standard_normal((3, 1)) if residual else None,
                      lower_residual=1e-3 * rng.standard_normal((3, 1)) if residual else None,
                      meta={"output_shapes": shapes})


def _variants(model: ModalModel, n: int = 5) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(4)
    scale = 1 + 0.05 * rng.standard_normal((n, model.poles.size))
    return model.poles[None] * scale, model.residues[None] * (1 + 0.1 * rng.standard_normal((n, 1, 1, model.poles.size)))


def test_transfer_of_stacked_variants_is_each_variants_own() -> None:
    model = _model()
    poles, residues = _variants(model)
    s = 2j * np.pi * np.linspace(1.0, 100.0, 157) + 0.7
    H = transfer(model, s, poles, residues)
    assert H.shape == (5, 3, 1, 157)
    for i in range(5):
        assert np.array_equal(H[i], transfer(replace(model, poles=poles[i], residues=residues[i]), s))
    assert np.array_equal(transfer(model, s, model.poles, model.residues), transfer(model, s))
    # the kernels given (as the windowed synthesis shares them with the record's tail) change nothing
    assert np.array_equal(transfer(model, s, poles, residues, pole_kernels(poles, s)), H)


def test_windowed_synthesis_of_stacked_variants_is_each_variants_own() -> None:
    """Through an exponential window and a finite record (the tail), converted to accelerance."""
    model = replace(_model(), meta={**_model().meta, WINDOW_SHIFT_KEY: 0.8, RECORD_KEY: 1.5})
    poles, residues = _variants(model)
    f = np.linspace(1.0, 100.0, 99)
    for quantity in ("receptance", "accelerance"):
        H = windowed_transfer(model, f, quantity, poles=poles, residues=residues)
        for i in range(5):
            one = synthesize_windowed(replace(model, poles=poles[i], residues=residues[i]), f, quantity)
            assert np.array_equal(H[i], one.H)


def test_the_loaded_modes_of_a_mass_grid_are_scipys_generalized_eigenvectors() -> None:
    model = _model()
    phi = np.asarray(model.meta["output_shapes"])
    wn = np.abs(model.poles)
    masses = np.linspace(0.0, 2.0, 41)
    w2, V = _loaded_modes(wn, phi[[0, 2]], masses)
    Mr = np.eye(4)[None] + (masses[:, None, None] * phi[[0, 2]].T[None]) @ phi[[0, 2]][None]
    w2_ref, V_ref = eigh(np.broadcast_to(np.diag(wn ** 2), Mr.shape), Mr)
    assert np.array_equal(w2, w2_ref) and np.array_equal(V, V_ref)
    # each mass of the grid as applied alone
    for i, loaded in enumerate(_mass_loaded(model, np.ones(3, bool), masses[::10])):
        alone = apply_mass_loading(model, {"mass_kg": masses[::10][i]})
        assert np.array_equal(loaded.poles, alone.poles) and np.array_equal(loaded.residues, alone.residues)


def _ctx(model: ModalModel) -> FitContext:
    f = np.linspace(5.0, 95.0, 181)
    true = replace(model, poles=np.append(model.poles, pole_from_fz(60.0, 0.02)),
                   residues=np.concatenate([model.residues, 2e-4j * np.ones((3, 1, 1))], axis=2))
    H = predict(true, f, "accelerance").H
    H = H * (1 + 0.01 * np.random.default_rng(5).standard_normal(H.shape))
    meas = predict(true, f, "accelerance")
    meas = replace(meas, H=H)
    return FitContext(measured=meas, base=model, weights=line_weights(meas), sim=predict(model, f, "accelerance"))


def test_the_missing_mode_fit_is_made_once_per_context_and_lines() -> None:
    ctx = _ctx(_model(residual=False))
    lines = np.arange(ctx.measured.freq_hz.size) % 2 == 0
    first = fit_missing_mode(ctx, lines)
    assert first == _fit_missing_mode(ctx, lines)
    assert abs(first["freq_hz"] - 60.0) < 0.5
    first["residue"][0][0][0] = 123.0                     # a caller's copy: changing it changes no later answer
    again = fit_missing_mode(ctx, lines)
    assert again == _fit_missing_mode(ctx, lines) and again["residue"][0][0][0] != 123.0
    other = fit_missing_mode(ctx, ~lines)                  # other lines: another fit
    assert other == _fit_missing_mode(ctx, ~lines) and other != again


def test_the_resonators_start_costs_at_once_are_each_starts_cost() -> None:
    ctx = _ctx(_model(residual=False))
    lines = np.ones(ctx.measured.freq_hz.size, bool)
    f, Hm, sw = ctx.measured.freq_hz, ctx.measured.H, np.sqrt(ctx.weights)

    def spec(x: np.ndarray) -> dict:
        return {"effect": "local_resonator", "frequency_hz": float(x[0]), "zeta": float(np.exp(x[1])),
                "coupling": [float(v) for v in x[2:]]}

    def cost(x: np.ndarray) -> float:
        e = (Hm - predict(ctx.base, f, "accelerance", ctx.effects(spec(x))).H) * sw
        return float(np.sum(e.real ** 2) + np.sum(e.imag ** 2))

    rng = np.random.default_rng(6)
    starts = [np.concatenate([[fc, np.log(0.02)], 0.05 * rng.standard_normal(4)]) for fc in (20.0, 40.0, 60.0, 70.0)]
    costs = _start_costs(ctx, f[lines], Hm, sw, spec, cost, CATALOGUE)(starts)
    np.testing.assert_allclose(costs, [cost(x) for x in starts], rtol=1e-12)
    # a start's cost does not depend on the others screened with it
    assert _start_costs(ctx, f, Hm, sw, spec, cost, CATALOGUE)(starts[2:3])[0] == costs[2]
