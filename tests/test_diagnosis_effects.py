"""The effect catalogue: each model extension against its analytic result."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.diagnosis import EFFECTS, EffectError, predict
from analysis.diagnosis.effects import WINDOW_SHIFT_KEY
from analysis.modal import ModalModel, damping_ratio, natural_freq_hz, pole_from_fz

F = np.linspace(1.0, 100.0, 400)


def _model(shapes=True) -> ModalModel:
    fn, z = np.array([10.0, 30.0, 70.0]), np.array([0.01, 0.005, 0.02])
    lam = pole_from_fz(fn, z)
    phi = np.array([[0.3, -0.2, 0.1], [0.1, 0.25, -0.3]])       # 2 outputs
    ref = phi[:1]                                                # reference = output 0
    R = np.einsum("om,rm->orm", phi, ref) / (2j * lam.imag)
    meta = {"output_shapes": phi} if shapes else {}
    return ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none",
                      outputs=("a:1:X", "a:2:X"), references=("a:1:X",), meta=meta)


def test_catalogue_names_are_the_fixed_eleven():
    assert set(EFFECTS) == {"residual_modes", "sensor_highpass", "time_delay", "mass_loading", "local_resonator",
                            "missing_mode",
                            "stiffness_shift", "damping_change", "exponential_window", "sensitivity_error",
                            "mains_hum"}


def test_stiffness_shift_scales_frequencies_and_matches_exact_receptance():
    m = _model()
    a = 1.05
    out = EFFECTS["stiffness_shift"].apply(m, {"factor": a})
    np.testing.assert_allclose(natural_freq_hz(out.poles), a * m.freq_hz, rtol=1e-12)
    np.testing.assert_allclose(damping_ratio(out.poles), m.damping, rtol=1e-12)
    # exact: receptance of stiffness a^2 K is H(w / a) / a^2
    H0 = predict(m, F / a, "receptance").H
    H1 = predict(m, F, "receptance", [{"effect": "stiffness_shift", "factor": a}]).H
    np.testing.assert_allclose(H1, H0 / a ** 2, rtol=1e-10)
    assert m.poles[0] == pole_from_fz(10.0, 0.01)  # input untouched


def test_damping_and_window_change_decay_as_stated():
    m = _model()
    d = EFFECTS["damping_change"].apply(m, {"factor": 2.0})
    np.testing.assert_allclose(damping_ratio(d.poles), 2 * m.damping, rtol=1e-12)
    np.testing.assert_allclose(natural_freq_hz(d.poles), m.freq_hz, rtol=1e-12)
    w = EFFECTS["exponential_window"].apply(m, {"exp_window_tau_s": 0.5})
    assert w.meta[WINDOW_SHIFT_KEY] == 2.0 and WINDOW_SHIFT_KEY not in m.meta    # input untouched
    w2 = EFFECTS["exponential_window"].apply(w, {"exp_window_tau_s": 0.25})                 # windows compound
    assert w2.meta[WINDOW_SHIFT_KEY] == 6.0
    # in its own form, the window moves every pole by -1/tau with the same residues
    shifted = ModalModel(poles=m.poles - 2.0, residues=m.residues, quantity="receptance", residual_form="none")
    np.testing.assert_allclose(predict(m, F, "receptance", [{"effect": "exponential_window", "exp_window_tau_s": 0.5}]).H,
                               predict(shifted, F, "receptance").H, rtol=1e-12)
    with pytest.raises(EffectError, match="exp_window_tau_s"):
        EFFECTS["exponential_window"].apply(m, {"exp_window_tau_s": -1.0})
    # effect specs written before the parameter had its name
    assert EFFECTS["exponential_window"].apply(m, {"tau_s": 0.5}).meta[WINDOW_SHIFT_KEY] == 2.0


def test_mass_loading_rayleigh_shift():
    """To first order in the mass, the Rayleigh quotient omega^2 / (1 + m sum phi^2); the coupling of
    the modes by the mass is of second order."""
    m = _model()
    for kg in (1e-3, 1e-4):
        out = EFFECTS["mass_loading"].apply(m, {"mass_kg": kg})
        mu = kg * np.sum(m.meta["output_shapes"] ** 2, axis=0)
        rayleigh = m.freq_hz / np.sqrt(1 + mu)
        np.testing.assert_allclose(natural_freq_hz(out.poles), rayleigh, rtol=50 * float(np.max(mu)) ** 2)
        assert not np.allclose(natural_freq_hz(out.poles), m.freq_hz, rtol=float(np.max(mu)) / 4)
    with pytest.raises(EffectError, match="output_shapes"):
        EFFECTS["mass_loading"].apply(_model(shapes=False), {"mass_kg": 0.5})


def test_frf_effects_analytic():
    m = _model()
    base = predict(m, F, "accelerance")
    hp = predict(m, F, "accelerance", [{"effect": "sensor_highpass", "corner_hz": 5.0, "order": 1}])
    k = np.argmin(np.abs(F - 5.0))
    assert abs(hp.H[0, 0, k] / base.H[0, 0, k]) == pytest.approx(1 / np.sqrt(1 + (5.0 / F[k]) ** 2), rel=1e-12)
    td = predict(m, F, "accelerance", [{"effect": "time_delay", "delay_s": 1e-3}])
    np.testing.assert_allclose(td.H / base.H, np.broadcast_to(np.exp(-2j * np.pi * F * 1e-3), td.H.shape), rtol=1e-12)
    se = predict(m, F, "accelerance", [{"effect": "sensitivity_error", "gains": {"a:2:X": 1.1}}])
    np.testing.assert_allclose(se.H[1], 1.1 * base.H[1], rtol=1e-12)
    np.testing.assert_allclose(se.H[0], base.H[0], rtol=1e-12)
    rm = predict(m, F, "accelerance", [{"effect": "residual_modes", "upper": [[1e-6], [0.0]], "lower": [[0.0], [0.0]]}])
    np.testing.assert_allclose(rm.H[0, 0] - base.H[0, 0], -(2 * np.pi * F) ** 2 * 1e-6, rtol=1e-9)


def test_missing_mode_and_hum_add_terms():
    m = _model()
    base = predict(m, F, "receptance")
    mm = predict(m, F, "receptance", [{"effect": "missing_mode", "freq_hz": 50.0, "zeta": 0.01,
                                       "residue": [[[0.0, -1e-3]], [[0.0, 0.0]]]}])
    lam = pole_from_fz(50.0, 0.01)
    R = -1e-3j
    jw = 2j * np.pi * F
    np.testing.assert_allclose(mm.H[0, 0] - base.H[0, 0], R / (jw - lam) + np.conj(R) / (jw - np.conj(lam)), rtol=1e-9)
    df = F[1] - F[0]
    from analysis.diagnosis.effects import hum_kernels
    fk, _ = hum_kernels(F, 50.0, 2 * df)
    A = np.zeros((2, 1, fk.size, 2))
    A[0, 0, 0] = [1e-6, 0.0]
    hum = predict(m, F, "receptance", [{"effect": "mains_hum", "base_hz": 50.0, "amplitudes": A.tolist()}])
    k = np.argmin(np.abs(F - 50.0))
    assert abs(hum.H[0, 0, k] - base.H[0, 0, k]) == pytest.approx(1e-6 / abs(1 + 1j * (F[k] - 50) / (2 * df)), rel=1e-9)


def test_bad_effect_specs_are_named():
    m = _model()
    with pytest.raises(EffectError, match="unknown effect"):
        predict(m, F, "receptance", [{"effect": "gremlins"}])
    with pytest.raises(EffectError, match="factor"):
        predict(m, F, "receptance", [{"effect": "stiffness_shift", "factor": -1}])
    with pytest.raises(EffectError, match="residue"):
        predict(m, F, "receptance", [{"effect": "missing_mode", "freq_hz": 5.0, "zeta": 0.01, "residue": [1, 2]}])


def test_stiffness_shift_warps_a_fixed_frf_term_exactly():
    """A simulation given as FRFs only (no modes, all in meta["frf_correction"]) is warped like a model."""
    from analysis.frf import FRFSet
    m = _model()
    fine = np.linspace(0.5, 120.0, 20000)
    acc = predict(m, fine, "accelerance")
    empty = ModalModel(poles=np.zeros(0, complex), residues=np.zeros((2, 1, 0)), quantity="accelerance",
                       residual_form="none", outputs=m.outputs, references=m.references,
                       meta={"frf_correction": FRFSet(freq_hz=fine, H=acc.H, quantity="accelerance")})
    a = 1.03
    got = predict(empty, F, "accelerance", [{"effect": "stiffness_shift", "factor": a}]).H
    want = predict(m, F, "accelerance", [{"effect": "stiffness_shift", "factor": a}]).H
    np.testing.assert_allclose(got, want, rtol=2e-3, atol=1e-3 * np.abs(want).max())


def _two_modes():
    """A physical 2-mode receptance model (13 and 41 Hz, 1 % damping, mass-normalised shapes)."""
    lam = pole_from_fz(np.array([13.0, 41.0]), np.array([0.01, 0.01]))
    phi = np.array([[0.4, -0.3], [0.2, 0.5]])
    R = np.einsum("om,rm->orm", phi, phi[:1]) / (2j * lam.imag)
    return lam, R


def test_exponential_window_is_exact_for_accelerance_and_mobility():
    """A window exp(-t/tau) on the measured acceleration: the FRF is the FFT of the windowed acceleration
    impulse response, h_a(t) = sum_r N_r exp(lambda_r t) + c.c. + D delta(t) (N = R lambda^2,
    D = sum 2 Re(R lambda)), i.e. H_acc(j w + 1/tau); tau = 0.5 s gives 2 / (w tau) = 4.9 % at 13 Hz."""
    lam, R = _two_modes()
    tau = 0.5
    a = 1.0 / tau
    rec = ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none",
                     outputs=("a:1:X", "a:2:X"), references=("a:1:X",))
    N = R * lam ** 2
    D = np.sum(2 * np.real(R * lam), axis=2)
    # the same structure as an accelerance pole-residue model: the feed-through D is the physical
    # accelerance lower residual (basis -1)
    acc = ModalModel(poles=lam, residues=N, quantity="accelerance", residual_form="physical",
                     lower_residual=-D, outputs=rec.outputs, references=rec.references)
    fpk = np.abs(lam) / (2 * np.pi) * np.sqrt(1 - 2 * 0.01 ** 2)     # near the peaks
    fs, T = 65536.0, 8.0        # exp(-T / tau) = 1e-7 of the start, discretisation ~ (w dt)^2 / 12
    t = np.arange(int(fs * T)) / fs
    w = np.exp(-t / tau)
    h = np.real(np.einsum("orm,mn->orn", 2 * N, np.exp(np.outer(lam, t)))) * w
    # trapezoidal Fourier integral of the windowed response (the jump at t = 0 counted half), plus the delta
    E = np.exp(-2j * np.pi * np.outer(t, fpk))
    want = (h @ E - 0.5 * h[..., :1]) / fs + D[..., None]
    spec = [{"effect": "exponential_window", "exp_window_tau_s": tau}]
    for model in (rec, acc):
        got = predict(model, fpk, "accelerance", spec).H
        np.testing.assert_allclose(got, want, rtol=1e-6)
    # the direct form: H_acc(j w + a) of the accelerance pole-residue model
    s = 2j * np.pi * F + a
    direct = (np.einsum("orm,mk->ork", N, 1 / (s - lam[:, None])) +
              np.einsum("orm,mk->ork", np.conj(N), 1 / (s - np.conj(lam)[:, None])) + D[..., None])
    np.testing.assert_allclose(predict(rec, F, "accelerance", spec).H, direct, rtol=1e-9, atol=1e-12 * np.abs(direct).max())
    # mobility: H_mob(j w + a) = s H_rec(s) at s = j w + a
    mob = s * (np.einsum("orm,mk->ork", R, 1 / (s - lam[:, None])) +
               np.einsum("orm,mk->ork", np.conj(R), 1 / (s - np.conj(lam)[:, None])))
    np.testing.assert_allclose(predict(rec, F, "mobility", spec).H, mob, rtol=1e-9, atol=1e-12 * np.abs(mob).max())
    # the former shortcut (window in receptance form, then times (j w)^2) misses by ~2 / (w tau) at 13 Hz
    shifted = ModalModel(poles=lam - a, residues=R, quantity="receptance", residual_form="none")
    old = predict(shifted, fpk, "accelerance").H
    assert abs(old[0, 0, 0] / want[0, 0, 0] - 1) > 0.03


def test_missing_mode_starts_within_the_lines_it_is_fitted_on():
    """The measurement has two extra modes: a strong one above the lines the fit may use and a weak one
    inside them. The fit starts only from residual peaks it may reach, and finds the weak mode (it stopped
    with an error when the strong peak beyond its lines was one of its starts)."""
    from analysis.diagnosis.effects import FitContext
    from analysis.frf import FRFSet

    m = _model()
    sim = predict(m, F, "receptance")
    extra = [{"effect": "missing_mode", "freq_hz": 90.0, "zeta": 0.005, "residue": [[[0.0, -0.2]], [[0.0, 0.1]]]},
             {"effect": "missing_mode", "freq_hz": 45.0, "zeta": 0.01, "residue": [[[0.0, -0.02]], [[0.0, 0.01]]]}]
    H = predict(m, F, "receptance", extra).H
    meas = FRFSet(freq_hz=F, H=H, quantity="receptance", outputs=m.outputs, references=m.references)
    ctx = FitContext(measured=meas, base=m, weights=np.ones(H.shape), sim=sim)
    lines = F <= 60.0
    got = EFFECTS["missing_mode"].fit(ctx, lines)
    # the strong mode's tail, not in the fitted model, pulls it a little
    assert got["freq_hz"] == pytest.approx(45.0, rel=0.01)


def test_mains_hum_fitted_on_part_of_the_band_predicts_the_whole_band():
    """Mains lines fitted below 60 Hz (one harmonic seen, at 50 Hz) and predicted on 1-100 Hz: the fitted
    harmonic keeps its amplitude, the harmonic the fit did not see (100 Hz) has none."""
    from analysis.diagnosis.compare import line_weights
    from analysis.diagnosis.effects import FitContext, hum_kernels
    from analysis.frf import FRFSet

    m = _model()
    sim = predict(m, F, "receptance")
    fk, _ = hum_kernels(F, 50.0, 0.0)
    A = np.zeros((2, 1, fk.size, 2))
    A[:, 0, 0] = [[2e-5, 1e-5], [-1e-5, 3e-5]]
    H = predict(m, F, "receptance", [{"effect": "mains_hum", "base_hz": 50.0, "width_hz": 0.0, "amplitudes": A.tolist()}]).H
    low = F <= 60.0
    meas = FRFSet(freq_hz=F[low], H=H[..., low], quantity="receptance", outputs=m.outputs, references=m.references)
    ctx = FitContext(measured=meas, base=m, weights=line_weights(meas), sim=_lines_of(sim, low))
    got = EFFECTS["mains_hum"].fit(ctx, np.ones(low.sum(), bool))
    assert got["harmonics_hz"] == [pytest.approx(50.0, abs=0.2)]
    whole = predict(m, F, "receptance", [{"effect": "mains_hum", **got}]).H
    np.testing.assert_allclose(whole, H, rtol=0, atol=1e-9)
    with pytest.raises(EffectError, match="harmonics_hz"):
        predict(m, F, "receptance", [{"effect": "mains_hum", **got, "harmonics_hz": [50.0, 100.0]}])


def _lines_of(frf, lines):
    """``frf`` on the boolean mask ``lines``."""
    from dataclasses import replace
    return replace(frf, freq_hz=frf.freq_hz[lines], H=frf.H[..., lines])
