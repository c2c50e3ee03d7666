"""Real measured data through the project's importers, spectra and LSFD (``benchmarks/accuracy/validation``).

Each test reads one dataset of ``../shared/data`` (skipped when the folder is absent) and checks a fact
known independently of the fitter: the analyser's window constant, a free-free beam's frequency ratios,
a driving point's residue phase, the import path against the direct spectra, the window correction of
the poles, the softening of a bolted joint. The heavy comparisons (sdypy-EMA, stabilization, all modes)
live in ``benchmarks/accuracy/validation`` (``python -m benchmarks.accuracy.validation.run_all``).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from analysis.lsfd import fit_lsfd
from analysis.modal import ModalModel, pole_from_fz, synthesize

# benchmarks/ is not an installed package: make the project root importable under plain `pytest` too
_ROOT = str(Path(__file__).resolve().parents[1])
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)

from benchmarks.accuracy.validation.common import consistency_table, match_poles, synthesis_error  # noqa: E402

realdata = pytest.mark.realdata


# ------------------------------------------------------------------ helpers (no data needed)
def test_match_poles_pairs_nearest_and_leaves_strangers_unpaired():
    pairs = match_poles(np.array([10.0, 20.0, 30.0]), np.array([20.1, 9.9, 50.0]), tol=0.03)
    assert (0, 1) in pairs and (1, 0) in pairs
    assert (2, None) in pairs and (None, 2) in pairs


def test_synthesis_error_is_relative_frobenius_norm():
    H = np.array([[3.0 + 4.0j, 0.0]])
    G = np.array([[3.0, 0.0]])
    assert synthesis_error(H, G) == pytest.approx(100 * 4 / 5)


def test_consistency_table_recovers_the_repeated_poles():
    poles = pole_from_fz([50.0, 80.0], [0.01, 0.02])
    f = np.linspace(30, 100, 400)
    model = ModalModel(poles, np.array([[[1.0 - 2j, 0.5 + 1j]]]), quantity="receptance", residual_form="none")
    H = synthesize(model, f)
    res = fit_lsfd(H, poles * (1 + 0.002), residual_form="none")
    _, arr = consistency_table(["a", "b"], [res, res], np.array([80.0, 50.0]))
    assert arr["f"][0] == pytest.approx([50.0, 80.0], rel=1e-9)
    assert arr["zeta"][1] == pytest.approx([0.01, 0.02], rel=1e-6)


def test_dataset_table_names_every_validated_dataset_with_its_loader_and_band():
    """The one table of real datasets (used by the report's browser test and the automatic-band study) holds
    every dataset of docs/validation.md under its name there, each with a loader and an increasing band."""
    from benchmarks.accuracy.validation.datasets import DATASETS
    from benchmarks.accuracy.validation.run_all import CASE_KEYS, CASES

    assert len({d.key for d in DATASETS}) == len(DATASETS)
    assert {d.module for d in DATASETS} == set(CASES)
    for d in DATASETS:                 # docs/validation.md's name, or with the variant of the fit in brackets
        assert any(k == d.label or k.startswith(f"{d.label} (") for k in CASE_KEYS), d.label
        lo, hi = d.fit_band()
        assert 0 <= lo < hi, d.key
        assert callable(d.loader_function()), d.key


# ------------------------------------------------------------------ real data
@realdata
def test_uliege_window_constant_and_raw_h1(shared_data):
    from benchmarks.accuracy.validation import uliege_plane as u

    wt = u.window_tau(shared_data)
    # the analyser's exponential decays to 0.329 over the 8 s block: tau = 8 / ln(1/0.329)
    assert wt["block_s"] == pytest.approx(8.0)
    assert wt["exp_window_tau_s"] == pytest.approx(8.0 / math.log(1 / 0.329), rel=2e-3)
    # our H1 of the stored last hit, with the analyser's windows, agrees with the analyser's (averaged) H1
    frf = u.load(shared_data, band=u.BAND, exp_window_tau_s=wt["exp_window_tau_s"])
    raw = u.raw_h1(shared_data, wt["exp_window_tau_s"], wt["force_window_end_s"], band=u.BAND)
    good = frf.coherence > 0.98
    rel = np.abs(raw.H - frf.H) / np.abs(frf.H)
    assert good.sum() > 10000
    assert np.median(rel[good]) < 0.08


@realdata
def test_uliege_first_lab_window_and_dataphysics_importer(shared_data):
    from benchmarks.accuracy.validation import uliege_plane as u

    lab1, tau1 = u.first_lab(shared_data)
    # 16 s blocks in the first lab: the same 0.329 end value gives twice the second lab's tau
    assert tau1 == pytest.approx(16.0 / math.log(1 / 0.329), rel=2e-3)
    assert lab1.H.shape == (3, 3, 3201)
    assert u.importer_check(shared_data) < 1e-12


@realdata
def test_uliege_exponential_window_is_removed_from_every_pole(shared_data):
    from benchmarks.accuracy.validation import uliege_plane as u

    tau = 8.0 / math.log(1 / 0.329)
    frf = u.load(shared_data, band=(37.0, 43.0), exp_window_tau_s=tau)
    res = fit_lsfd(frf, pole_from_fz([40.17], [0.003]), residual_form="physical")
    assert res.success
    assert res.poles.real - res.poles_raw.real == pytest.approx([1.0 / tau], rel=1e-12)
    assert res.freq_hz[0] == pytest.approx(40.17, abs=0.02)
    # window damping 1/(tau omega) = 0.055 % removed: the structure keeps about 0.25 %
    assert 0.0015 < res.damping[0] < 0.0035
    assert res.damping[0] < -res.poles_raw.real[0] / abs(res.poles_raw[0])


@realdata
def test_ladisk_beam_bending_ratios_match_free_free_theory(shared_data):
    from benchmarks.accuracy.validation import ladisk_beam as lb

    frf = lb.load_single(shared_data)
    f = []
    for lo, hi, f0 in ((600.0, 800.0, 696.0), (1800.0, 2000.0, 1898.0)):
        res = fit_lsfd(frf, pole_from_fz([f0], [0.004]), band=(lo, hi))
        assert res.success
        f.append(res.freq_hz[0])
    # Euler-Bernoulli free-free: (7.8532 / 4.7300)^2 = 2.757; shear lowers it slightly
    assert f[1] / f[0] == pytest.approx((7.8532 / 4.7300) ** 2, rel=0.03)


@realdata
def test_modelab_driving_point_residue_is_imaginary(shared_data):
    from benchmarks.accuracy.validation import modelab_beam as mb

    frf = mb.load(shared_data, band=(108.0, 116.0))
    assert frf.H.shape[:2] == (1, 9)
    assert np.median(np.diff(frf.freq_hz)) == pytest.approx(1000.0 / 51200, rel=1e-6)
    res = fit_lsfd(frf, pole_from_fz([112.0], [0.0002]))
    assert res.success and res.freq_hz[0] == pytest.approx(112.0, abs=0.1)
    phase = mb.driving_point_phases(res)[0]
    assert abs(phase + 90.0) < 10.0


@realdata
def test_pyfrf_import_path_and_close_modes(shared_data):
    from benchmarks.accuracy.validation import pyfrf_5impacts as p

    frf = p.load(shared_data)
    rec = p.recording_frf(shared_data)
    sel = (frf.freq_hz > 700) & (frf.freq_hz < 1700)
    rel = np.abs(rec.H[..., sel] - frf.H[..., sel]) / np.abs(frf.H[..., sel])
    assert rec.meta["n_averages"] == 5
    assert np.median(rel) < 0.01
    peaks = p.peak_frequencies(frf, (790.0, 870.0))
    assert len(peaks) == 3
    res = fit_lsfd(frf, pole_from_fz(peaks, [0.0013] * 3), band=(790.0, 870.0))
    assert res.success
    f = np.sort(res.freq_hz)
    assert np.all(np.abs(f - np.asarray(peaks)) < 1.0)
    assert np.min(np.diff(f)) > 10.0


@realdata
def test_f16_first_period_is_the_transient_one(shared_data):
    from benchmarks.accuracy.validation import f16_gvt as f16

    force, acc, fs = f16.read_f16_csv(shared_data / f16.NAME / "F16Data_FullMSine_Level1.csv")
    assert fs == 400.0 and force.size == 9 * f16.N_PER
    frf, sig, Hp = f16.period_frf(force, acc, fs, drop=0)
    steady = Hp[:, 1:].mean(axis=1)
    dev = [np.linalg.norm(Hp[:, p] - steady) / np.linalg.norm(steady) for p in range(Hp.shape[1])]
    assert dev[0] > 5 * np.median(dev[1:])
    # noise from the period scatter is far below the FRF
    assert np.mean(sig ** 2) < 1e-3 * np.mean(np.abs(frf.H) ** 2)


@realdata
def test_plate_sweep_spans_60_to_500_hz_within_the_record(shared_data):
    from benchmarks.accuracy.validation import plate_sweep as ps

    force, acc, fs = ps.read_plate_hdf5(shared_data / ps.NAME / "view_0.hdf5")
    assert fs == 25600.0 and force.size == 51200
    b, t_a, t_b, mis = ps.sweep_rate(force, fs)
    assert 0.0 <= t_a < t_b <= force.size / fs
    assert mis < 0.1
    assert b > 0


@realdata
def test_pyuff_reader_matches_text_copies(shared_data):
    from benchmarks.accuracy.validation import pyuff_3frf as pu

    frf = pu.load(shared_data)
    txt = pu.load_text(shared_data)
    assert frf.H.shape == (1, 3, 1001) and frf.quantity == "accelerance"
    assert np.max(np.abs(frf.H[0, :, 1:] - txt[:, 1:])) < 1e-9 * np.max(np.abs(txt))


@realdata
def test_unesp_bolted_joint_softens_at_the_higher_level(shared_data):
    from benchmarks.accuracy.validation import unesp_boltedbeam as ub

    f = {}
    for level in ("0p05", "0p30"):
        frf = ub.load(shared_data, level)
        assert frf.H.shape == (4, 1, 8192)
        res = fit_lsfd(frf, pole_from_fz([98.0], [0.012]), band=(90.0, 106.0))
        assert res.success
        f[level] = res.freq_hz[0]
    assert f["0p30"] < f["0p05"] - 0.3


@realdata
def test_unesp_coherence_is_matched_to_the_frfs_by_channel(shared_data):
    """The coherence file holds five curves (four accelerometers and a laser vibrometer) for four
    FRFs: each FRF gets its own accelerometer's, and a missing channel is a clear error."""
    from benchmarks.accuracy.validation import unesp_boltedbeam as ub

    d = shared_data / ub.NAME
    f, _, channels = ub._lms(d / "Rand__Rand0p05__FRF.mat", "FRF")
    _, C, names = ub._lms(d / "Rand__Rand0p05__Coherence.mat", "Coherence")
    assert len(names) == 5 and "Laser:+X/Shaker:-X" in names and channels == [f"Acc{k}:+X/Shaker:-X" for k in range(1, 5)]
    frf = ub.load(shared_data, "0p05")
    assert frf.coherence is not None and frf.coherence.shape == (4, 1, 8192)
    for k, c in enumerate(channels):
        np.testing.assert_array_equal(frf.coherence[k, 0], np.clip(C[names.index(c), 1:].real, 0.0, 1.0))
    with pytest.raises(ValueError, match="no coherence for Acc9"):
        ub._matched_coherence(d / "Rand__Rand0p05__Coherence.mat", f, ["Acc9:+X/Shaker:-X"])


@realdata
def test_peer_pole_bookkeeping_defect(shared_data):
    pytest.importorskip("sdypy.EMA")
    from benchmarks.accuracy.validation.peer_defects import reproduce

    r = reproduce()
    # the reported poles come from the model order after the one get_constants uses
    assert np.all(r["reported_from_order_index"] == r["pole_ind"][:, 0] + 1)


# ------------------------------------------------------------------ the discussion's filled-in figures
def test_discussion_placeholders_are_known_case_figures_with_valid_formats():
    import string

    from benchmarks.accuracy.validation.run_all import CASE_KEYS, DISCUSSION, Figures, fill_discussion

    text = DISCUSSION.read_text(encoding="utf-8")
    fields = [(name, spec) for _, name, spec, _ in string.Formatter().parse(text) if name is not None]
    assert len(fields) > 50
    prefixes = sorted(set(CASE_KEYS.values()), key=len, reverse=True)
    for name, spec in fields:
        assert name.isidentifier(), name
        assert any(name.startswith(p + "_") for p in prefixes), f"{name} names no case of CASE_KEYS"
        if spec:
            format(1.2345, spec)  # a float figure formats with the spec the text gives
    # nothing computed: every placeholder is marked, none is left raw, nothing raises
    out, missing = fill_discussion(text, Figures())
    assert set(missing) == {n for n, _ in fields}
    assert "not computed" in out and "{uliege_" not in out
    # computed values are used with their format; None (peer unavailable) counts as not computed
    out, missing = fill_discussion("{a_err:.3g} / {a_peer:.3g}", Figures(a_err=12.3456, a_peer=None))
    assert out == "12.3 / [a_peer: not computed]" and missing == []


@realdata
def test_pyfrf_has_a_905_hz_mode_the_peak_list_misses(shared_data):
    from benchmarks.accuracy.validation import pyfrf_5impacts as p

    frf = p.load(shared_data)
    peaks = p.peak_frequencies(frf, p.BAND)
    assert min(abs(x - 905.5) for x in peaks) > 3.0  # a shoulder of the 900 Hz peak, not a 6 dB peak
    band = (780.0, 960.0)
    near = [x for x in peaks if band[0] < x < band[1]]
    sub = frf.band(*band)

    def err(freqs):
        res = fit_lsfd(frf, pole_from_fz(freqs, [0.0013] * len(freqs)), band=band)
        return res, synthesis_error(sub.H, synthesize(res.model, sub.freq_hz).H)

    _, e_peaks = err(near)
    res, e_plus = err(near + [905.5])
    assert e_plus < 0.5 * e_peaks
    assert np.min(np.abs(res.freq_hz - 905.5)) < 0.5


@realdata
def test_uliege_weak_39_7_hz_mode_is_in_every_accelerometer(shared_data):
    from benchmarks.accuracy.validation import uliege_plane as u

    tau = 8.0 / math.log(1 / 0.329)
    band = (37.2, 42.7)
    frf = u.load(shared_data, band=band, exp_window_tau_s=tau)
    start = pole_from_fz([39.72, 40.16], [0.0035, 0.0021]) - 1.0 / tau
    for o in range(3):
        one = frf.select(outputs=[frf.outputs[o]])
        two = fit_lsfd(one, start, band=band)
        single = fit_lsfd(one, start[1:], band=band)
        e2 = synthesis_error(one.H, synthesize(two.model_raw, one.freq_hz).H)
        e1 = synthesis_error(one.H, synthesize(single.model_raw, one.freq_hz).H)
        f = np.sort(two.freq_hz)
        assert f[0] == pytest.approx(39.71, abs=0.05) and f[1] == pytest.approx(40.16, abs=0.03)
        assert e2 < 0.7 * e1
