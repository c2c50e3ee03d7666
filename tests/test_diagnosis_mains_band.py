"""Mains lines on bands without a harmonic and on long FRFs: the effect is skipped where it cannot act,
and its search reads only the lines near the harmonics (its cost does not grow with the band's lines)."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis import mains, predict
from analysis.diagnosis.compare import line_weights
from analysis.diagnosis.effect_types import NOT_APPLICABLE
from analysis.diagnosis.effects import FitContext
from analysis.diagnosis.verdict import diagnose_frfs
from analysis.frf import FRFSet
from analysis.modal import ModalModel, pole_from_fz


def _model(fn: tuple[float, ...]) -> ModalModel:
    lam = pole_from_fz(np.asarray(fn), np.full(len(fn), 0.01))
    phi = np.array([np.linspace(0.3, -0.2, len(fn)), np.linspace(0.1, 0.25, len(fn))])
    R = np.einsum("om,rm->orm", phi, phi[:1]) / (2j * lam.imag)
    return ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none",
                      outputs=("a:1:X", "a:2:X"), references=("a:1:X",))


def _measured(model: ModalModel, f: np.ndarray, seed: int, effects: tuple = ()) -> FRFSet:
    H = predict(model, f, "receptance", list(effects)).H
    rng = np.random.default_rng(seed)
    noise = 1e-3 * np.abs(H).mean() * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape))
    return FRFSet(freq_hz=f, H=H + noise, quantity="receptance", outputs=model.outputs, references=model.references)


def test_a_band_without_mains_harmonic_skips_mains_hum_in_one_line():
    """A shaker's band of 2-15 Hz holds no harmonic of 50 or 60 Hz: the diagnosis completes, mains_hum is
    not applicable (said why) and is not among the causes; the other effects are still tried."""
    m = _model((4.0, 9.0, 12.5))
    f = np.arange(2.0, 15.0, 0.05)
    diag = diagnose_frfs(_measured(m, f, seed=3), m, effects=["mains_hum", "time_delay"])
    why = diag.skipped["mains_hum"]
    assert why.startswith(NOT_APPLICABLE) and "2-14.95 Hz" in why and "\n" not in why
    assert [c["effect"] for c in diag.causes] == ["time_delay"]
    assert diag.verdict == "none"


def test_a_band_reaching_a_harmonic_keeps_mains_hum():
    """A band that holds 50 Hz (or reaches 60 Hz just off nominal) is not skipped."""
    m = _model((20.0, 45.0))
    for hi in (55.0, 59.85):
        f = np.arange(10.0, hi, 0.05)
        ctx = FitContext(measured=_measured(m, f, seed=4), base=m, weights=np.ones((2, 1, f.size)),
                         sim=predict(m, f, "receptance"))
        assert mains.mains_hum_applies(ctx) == ""


def test_mains_hum_without_harmonics_predicts_no_change():
    """A fit that found no harmonic (amplitudes [[[]], [[]]] once written as JSON) is applied as no lines."""
    m = _model((4.0, 9.0))
    f = np.arange(2.0, 15.0, 0.05)
    spec = {"effect": "mains_hum", "base_hz": 50.0, "offset_hz": 0.0, "width_hz": 0.1, "shape": "lorentzian",
            "amplitudes": [[[]], [[]]], "harmonics_hz": []}
    np.testing.assert_array_equal(predict(m, f, "receptance", [spec]).H, predict(m, f, "receptance").H)


def _dense_fit(ctx: FitContext, lines: np.ndarray, f0: float, width: float, shape: str) -> tuple[np.ndarray, float]:
    """The reference: every harmonic seen on ``lines`` fitted with the kernels on the whole axis."""
    f = ctx.measured.freq_hz
    df = float(np.median(np.diff(f)))
    fk, K = mains.hum_kernels(f, f0, width, shape)
    seen = np.array([np.any(lines & (np.abs(f - x) <= max(width, df / 2))) for x in fk], bool)
    return mains._hum_amplitudes(ctx, ctx.measured.H - ctx.sim.H, np.where(seen[:, None], K, 0.0), lines)


@pytest.mark.parametrize("step_hz, width_lines, shape", [(0.25, 0.0, "line"), (0.25, 2.0, "lorentzian"),
                                                         (0.25, 2.0, "sinc"), (4.0, 2.0, "lorentzian")])
def test_the_local_search_fits_as_the_whole_axis_does(step_hz, width_lines, shape):
    """Each candidate of the search, fitted on the lines near its harmonics, has the amplitudes and the cost
    of the fit on the whole axis (also when coarse lines make the harmonics' kernels share lines)."""
    m = _model((30.0, 70.0, 140.0))
    f = np.arange(step_hz, 400.0, step_hz)
    hum = {"effect": "mains_hum", "base_hz": 50.0, "offset_hz": 0.07, "width_hz": 0.0,
           "amplitudes": np.full((2, 1, 7, 2), 3e-6).tolist()}
    meas = _measured(m, f, seed=5, effects=(hum,))
    ctx = FitContext(measured=meas, base=m, weights=line_weights(meas), sim=predict(m, f, "receptance"))
    lines = np.random.default_rng(6).uniform(size=f.size) > 0.3
    search = mains._Search(ctx, meas.H - ctx.sim.H, lines)
    for f0 in (50.0, 50.07, 59.93):
        A, cost, _ = mains._fit_candidate(search, f0, width_lines * step_hz, shape)
        A0, cost0 = _dense_fit(ctx, lines, f0, width_lines * step_hz, shape)
        np.testing.assert_allclose(A, A0, rtol=1e-7, atol=1e-12 * np.abs(A0).max())
        assert cost == pytest.approx(cost0, rel=1e-9)


def test_the_search_reads_only_the_lines_near_the_harmonics(monkeypatch):
    """On a long FRF (20 000 lines) the search builds no kernel on the whole axis and solves no system
    larger than a harmonic's neighbourhood, for any of its hundreds of candidates: its cost grows with
    the number of harmonics, not with the lines times the candidates."""
    m = _model((30.0, 70.0, 140.0))
    f = np.arange(0.0, 400.0, 0.02)
    hum = {"effect": "mains_hum", "base_hz": 50.0, "width_hz": 0.0, "amplitudes": np.full((2, 1, 7, 2), 3e-6).tolist()}
    meas = _measured(m, f, seed=7, effects=(hum,))
    ctx = FitContext(measured=meas, base=m, weights=line_weights(meas), sim=predict(m, f, "receptance"))
    rows: list[int] = []
    dense: list[int] = []
    lstsq, kernels = np.linalg.lstsq, mains.hum_kernels
    monkeypatch.setattr(np.linalg, "lstsq", lambda M, *a, **k: (rows.append(M.shape[0]), lstsq(M, *a, **k))[1])
    monkeypatch.setattr(mains, "hum_kernels", lambda *a, **k: (dense.append(1), kernels(*a, **k))[1])
    got = mains.fit_mains_hum(ctx, np.ones(f.size, bool))
    assert got["base_hz"] == 50.0 and got["width_hz"] == 0.0 and len(got["harmonics_hz"]) == 7
    assert dense == [] and max(rows, default=0) <= 100
