"""The local resonator's fit from several kinds of start, on a chain of lumped masses and springs (fixed at
both ends) with a spring-mass attached between the measured points, solved exactly per line
``(K + j w C - w^2 M)^-1`` with the resonator's own degree of freedom (not from modes). Three of the eight
masses are measured; the resonator (1.1 % of the chain's mass) sits at an unmeasured mass, tuned between
the second and third modes, and couples strongly to both."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import eigh

import analysis.diagnosis.resonator_search as search
from analysis.diagnosis.compare import line_weights
from analysis.diagnosis.effects import FitContext, fit_local_resonator, predict
from analysis.frf import FRFSet
from analysis.modal import ModalModel

MASSES = np.array([1.0, 1.4, 0.8, 1.1, 0.9, 1.3, 1.0, 1.2])              # kg
SPRINGS = np.array([3e5, 2e5, 4e5, 2.5e5, 3.5e5, 2e5, 3e5, 2.8e5, 3.2e5])   # N/m, the first and last to ground
OUTS, REF = [0, 3, 6], 0
LABELS = tuple(f"chain:{i}:X" for i in OUTS)
AT, MASS, ZETA = 2, 0.1, 0.01


def _chain() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = MASSES.size
    K = np.zeros((n, n))
    for i, k in enumerate(SPRINGS):
        if i >= 1:
            K[i - 1, i - 1] += k
        if i < n:
            K[i, i] += k
        if 1 <= i < n:
            K[i - 1, i] -= k
            K[i, i - 1] -= k
    M = np.diag(MASSES)
    return K, 4e-7 * K + 0.2 * M, M


def _case() -> tuple[FitContext, float, np.ndarray]:
    K, C, M = _chain()
    n = MASSES.size
    w2, V = eigh(K, M)
    wn = np.sqrt(w2)
    zeta = np.einsum("ir,ij,jr->r", V, C, V) / (2 * wn)
    lam = wn * (-zeta + 1j * np.sqrt(1 - zeta ** 2))
    fn = wn / (2 * np.pi)
    model = ModalModel(poles=lam, residues=V[OUTS][:, None, :] * V[[REF]][None] / (2j * lam.imag),
                       quantity="receptance", residual_form="none", outputs=LABELS, references=(LABELS[REF],),
                       meta={"output_shapes": V[OUTS]})
    fa = float(fn[1] * (fn[2] / fn[1]) ** 0.4)
    ka, ca = MASS * (2 * np.pi * fa) ** 2, 2 * ZETA * MASS * 2 * np.pi * fa
    Ka, Ca, Ma = (np.zeros((n + 1, n + 1)) for _ in range(3))
    Ka[:n, :n], Ca[:n, :n], Ma[:n, :n] = K, C, M
    Ma[n, n] = MASS
    u = np.zeros(n + 1)
    u[AT], u[n] = 1.0, -1.0
    Ka += ka * np.outer(u, u)
    Ca += ca * np.outer(u, u)
    f = np.linspace(0.5 * fn[0], 0.95 * fn[5], 800)
    H = np.empty((len(OUTS), 1, f.size), complex)
    for k, w in enumerate(2 * np.pi * f):
        H[:, 0, k] = np.linalg.solve(Ka - w ** 2 * Ma + 1j * w * Ca, np.eye(n + 1)[:, REF])[OUTS]
    exact = H.copy()
    rng = np.random.default_rng(1)
    H = H + 0.005 * np.abs(H) * (rng.standard_normal(H.shape) + 1j * rng.standard_normal(H.shape)) / np.sqrt(2)
    meas = FRFSet(freq_hz=f, H=H, quantity="receptance", outputs=LABELS, references=(LABELS[REF],))
    return FitContext(measured=meas, base=model, weights=line_weights(meas), sim=predict(model, f, "receptance")), fa, exact


def test_the_attached_starts_reach_a_strongly_coupled_resonator(monkeypatch: pytest.MonkeyPatch) -> None:
    ctx, fa, exact = _case()
    lines = np.ones(ctx.measured.freq_hz.size, bool)
    found = fit_local_resonator(ctx, lines)
    assert found["frequency_hz"] == pytest.approx(fa, rel=0.01)
    # started only from the first-order coupling of an extra mode (midway between the modes, the three
    # cheapest starts each refined to the end), the fit stops at a local minimum
    monkeypatch.setattr(search, "RESONATOR_SCREEN_RATIOS", ())
    monkeypatch.setattr(search, "RESONATOR_BETWEEN", (0.5,))
    monkeypatch.setattr(search, "RESONATOR_REFINED", 3)
    monkeypatch.setattr(search, "RESONATOR_SHORT", 60)
    monkeypatch.setattr(search, "RESONATOR_CONTINUED", 1)
    alone = fit_local_resonator(ctx, lines)
    assert abs(alone["frequency_hz"] / fa - 1) > 0.05

    def cost(params: dict) -> float:
        return ctx.cost(predict(ctx.base, ctx.measured.freq_hz, "receptance",
                                [{"effect": "local_resonator", **params}]).H, lines)
    # the fit reaches the noise (the exact FRFs' error); the local minimum stays far above it
    assert cost(found) < 1.05 * ctx.cost(exact, lines)
    assert cost(alone) > 10 * ctx.cost(exact, lines)


def test_a_resonator_is_named_over_a_mass_only_beyond_it_and_inside_the_band() -> None:
    from analysis.diagnosis.rule import DEFAULT_RULE
    from analysis.diagnosis.verdict import _at_range_edge, _resonator_beyond_mass

    more = DEFAULT_RULE.resonator_over_mass_db

    def causes(res_gain: float) -> list:
        return [{"effect": "local_resonator", "gain_db": res_gain, "significant": True, "evidence": ""},
                {"effect": "mass_loading", "gain_db": 10.0, "significant": True, "evidence": ""}]
    close = causes(10.0 + more - 0.1)
    _resonator_beyond_mass(close)
    assert not close[0]["significant"] and "stiff limit" in close[0]["evidence"] and close[1]["significant"]
    beyond = causes(10.0 + more + 0.1)
    _resonator_beyond_mass(beyond)
    assert beyond[0]["significant"] and beyond[1]["significant"]
    # its own frequency stopped at the band's end is the edge of its range, not inside it
    assert "own frequency" in _at_range_edge("local_resonator", {"frequency_hz": 500.0}, (10.0, 500.0))
    assert "own frequency" in _at_range_edge("local_resonator", {"frequency_hz": 10.0}, (10.0, 500.0))
    assert _at_range_edge("local_resonator", {"frequency_hz": 300.0}, (10.0, 500.0)) == ""
