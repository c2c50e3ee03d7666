"""The automatic fit is complete and honest: every visible resonance is fitted, or named with
``success`` False (analysis.visibility, analysis.missing_modes)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from analysis.frf import FRFSet
from analysis.lsfd import fit_lsfd
from analysis.missing_modes import unfitted_resonances
from analysis.modal import ModalModel, pole_from_fz, synthesize
from analysis.pipeline import fit_auto
from analysis.visibility import VisiblePeak, unaccounted_peaks, visible_peaks


def modal_frf(freqs, zetas, shapes, participation, *, fmax=300.0, n_f=1500, noise=0.0, seed=0) -> FRFSet:
    """Accelerance FRFs of a known modal model: residues ``shapes[o, m] participation[m, r]``,
    with constant coherence 0.99 (clean data, several averages)."""
    rng = np.random.default_rng(seed)
    poles = pole_from_fz(np.asarray(freqs, float), np.asarray(zetas, float))
    R = np.einsum("om,mr->orm", np.asarray(shapes, float), np.asarray(participation, float)) * poles.imag / 2j
    n_out, n_ref = R.shape[:2]
    model = ModalModel(poles, R, quantity="accelerance", residual_form="physical",
                       upper_residual=np.zeros((n_out, n_ref)), lower_residual=np.zeros((n_out, n_ref)))
    frf = synthesize(model, np.linspace(fmax / n_f, fmax, n_f))
    if noise:
        n = (rng.standard_normal(frf.H.shape) + 1j * rng.standard_normal(frf.H.shape)) / np.sqrt(2)
        frf = replace(frf, H=frf.H + noise * np.abs(frf.H) * n)
    return replace(frf, coherence=np.full(frf.H.shape, 0.99), meta={"n_averages": [5]})


PAIR = (140.0, 142.0)


def pair_frf(n_ref: int, noise: float = 0.002) -> FRFSet:
    """Modes at 70 Hz, a close pair 140.0 / 142.0 Hz (1.4 % apart, half-power bandwidths 0.9 Hz) and
    230 Hz; the pair's shapes are orthogonal, so a second reference excites them differently."""
    shapes = np.array([[1.0, 1.0, 1.0, 0.5], [0.6, -1.0, 1.0, 1.0], [-0.8, 0.5, 0.7, 0.9]])
    part = np.array([[1.0, 0.8], [1.0, -0.6], [1.0, 1.0], [1.0, 0.7]])[:, :n_ref]
    return modal_frf([70.0, PAIR[0], PAIR[1], 230.0], [0.005, 0.003, 0.003, 0.005], shapes, part, noise=noise)


def test_close_pair_resolved_with_two_references():
    frf = pair_frf(2)
    fit = fit_auto(frf)
    assert fit.success, fit.message
    f = np.sort(fit.freq_hz)
    assert f.size == 4, (f, fit.warnings)
    np.testing.assert_allclose(f, [70.0, PAIR[0], PAIR[1], 230.0], rtol=2e-4)


def test_pair_fitted_by_one_pole_is_reported_as_a_possible_pair():
    """One reference: the pair shows as two maxima of one FRF. A model with one pole for both
    leaves the weaker peak unaccounted for: named as a possible close pair, a problem of the fit."""
    frf = pair_frf(1)
    band = (20.0, 290.0)
    peaks = visible_peaks(frf, band)
    assert any(abs(v.freq_hz - PAIR[0]) < 0.4 for v in peaks) and any(abs(v.freq_hz - PAIR[1]) < 0.4 for v in peaks)
    one = fit_lsfd(frf, pole_from_fz(np.array([70.0, 141.0, 230.0]), np.full(3, 0.005)), band=band)
    problems, notes = unfitted_resonances(frf, peaks, one)
    pair = [p for p in problems if "possible close pair" in p]
    assert len(pair) == 1 and notes == [], problems
    assert any(f"resonance at {x:.5g} Hz" in pair[0] for x in PAIR), pair
    # the automatic fit resolves this pair from the data (one reference, three outputs)
    fit = fit_auto(frf, band=band)
    assert fit.success, fit.message
    np.testing.assert_allclose(np.sort(fit.freq_hz), [70.0, PAIR[0], PAIR[1], 230.0], rtol=2e-4)


def test_a_mode_left_out_is_named_and_the_fit_is_not_a_success():
    frf = pair_frf(2)
    fit = fit_auto(frf, n_modes=3)   # the user's model size leaves one visible mode out
    assert not fit.success and fit.status == "implausible"
    f = np.sort(fit.freq_hz)
    left = [x for x in (70.0, PAIR[0], PAIR[1], 230.0) if np.min(np.abs(f - x)) > 0.3]
    assert len(left) == 1
    assert any(f"{left[0]:.5g}" in p for p in fit.problems), (left, fit.problems)


def test_peaks_of_different_frfs_a_line_apart_share_a_pole_but_two_maxima_of_one_frf_do_not():
    a = VisiblePeak(100.0, 30.0, "a", 0, (99.0, 101.0))
    b = VisiblePeak(100.5, 20.0, "b", 1, (100.0, 101.0))     # one line away in another FRF: the same mode
    c = VisiblePeak(100.5, 20.0, "a", 0, (100.0, 101.0))     # a second maximum of the same FRF
    d = VisiblePeak(103.0, 20.0, "b", 1, (102.5, 103.5))     # 6 lines away in another FRF: another mode
    assert unaccounted_peaks([a, b], np.array([100.2]), df=0.5) == ([], [])
    missed, pairs = unaccounted_peaks([a, c], np.array([100.2]), df=0.5)
    assert missed == [] and pairs == [(c, 100.2)]
    assert unaccounted_peaks([a, c], np.array([100.1, 100.6]), df=0.5) == ([], [])
    missed, pairs = unaccounted_peaks([a, d], np.array([100.2]), df=0.5)
    assert missed == [d] and pairs == []
    missed, _ = unaccounted_peaks([a], np.array([120.0]), df=0.5)
    assert missed == [a]


def test_the_same_resonance_reach_is_measured_from_each_of_its_peaks():
    # the frame's 525.2 Hz mode in three FRFs of a default capture (0.78 Hz lines): the most
    # prominent peak is itself a line low, the weakest 2.3 lines high of the 525.0 Hz peak and 3
    # lines from the most prominent one; one mode, one pole
    df = 0.78125
    top = VisiblePeak(524.21875, 46.5, "top:4:X/left:9:Y", 5, (521.1, 528.9))
    mid = VisiblePeak(525.0, 43.8, "left:9:Y/right:6:-X", 0, (521.9, 528.9))
    weak = VisiblePeak(526.5625, 12.8, "top:4:X/right:6:-X", 3, (523.4, 532.8))
    assert unaccounted_peaks([top, mid, weak], np.array([525.19]), df) == ([], [])
    # without the peak between them they are still one: the weak peak lies within the half-power
    # width of the strong one's top (6.2 Hz), where a mode's peak moves between FRFs
    assert unaccounted_peaks([top, weak], np.array([525.19]), df) == ([], [])
    # two sharp peaks (tops of two lines) 2.3 lines apart in different FRFs are two resonances
    # sharing one pole: a possible pair
    sharp = replace(top, top_hz=(523.4, 525.0))
    sharp_weak = replace(weak, top_hz=(525.8, 527.3))
    missed, pairs = unaccounted_peaks([sharp, sharp_weak], np.array([525.19]), df)
    assert missed == [] and pairs == [(sharp_weak, 525.19)]


def test_a_noise_spike_without_coherence_is_not_a_visible_peak():
    frf = pair_frf(1)
    H = frf.H.copy()
    k = int(np.argmin(np.abs(frf.freq_hz - 100.0)))
    H[0, 0, k] *= 30.0          # one line: a spike, not a resonance
    peaks = visible_peaks(replace(frf, H=H, coherence=None), (20.0, 290.0))
    assert not any(abs(v.freq_hz - frf.freq_hz[k]) < 0.1 for v in peaks)
    assert any(abs(v.freq_hz - 70.0) < 0.3 for v in peaks)


@pytest.fixture(scope="module")
def one_point_capture(tmp_path_factory):
    """One-point capture of the simulated frame through the simulated analyser (hammer right:6:-X, seed 1)."""
    from acquisition.cli_capture import main as capture_main
    from analysis.recording import load_frfset

    rec = tmp_path_factory.mktemp("fitcomplete") / "rec.h5"
    assert capture_main(["--device", "sim://?seed=1", "--out", str(rec), "--points", "right:6:-X", "--hits", "5",
                         "--auto", "-q"]) == 0
    return load_frfset(rec)


def test_capture_close_pair_of_the_frame_is_resolved(one_point_capture):
    """The frame's 160.0 / 161.0 Hz pair in 4..215 Hz: each peak stands out in the data; both are
    fitted (one pole of 0.73 % damping before), and so are the fainter 50.4 and 81.7 Hz modes."""
    from simulator.stand import TestStand

    truth = TestStand(seed=1).model.modes(215.0).freq_hz
    fit = fit_auto(one_point_capture, band=(4.0, 215.0))
    assert fit.success, fit.message
    for t in truth[(truth > 10.0) & (truth < 215.0)]:
        assert np.min(np.abs(fit.freq_hz - t)) <= 0.005 * t, (t, fit.freq_hz)


def test_a_start_pole_at_a_visible_peak_takes_the_modes_damping_or_its_half_power_width():
    """A peak the diagram missed starts a pole with the selected modes' damping, or without one the
    damping its own 3 dB width gives (the diagram's poles near a missed mode are mathematical ones,
    0.001 % or none)."""
    from analysis.modal import damping_ratio, natural_freq_hz
    from analysis.visibility import peak_poles

    frf = modal_frf([100.0, 200.0], [0.01, 0.004], [[1.0, 0.7]], [[1.0], [1.0]])   # df 0.2 Hz
    peaks = visible_peaks(frf, (50.0, 290.0))
    p = peak_poles(peaks, frf.line_spacing_hz)
    np.testing.assert_allclose(natural_freq_hz(p), [100.0, 200.0], atol=0.2)
    np.testing.assert_allclose(damping_ratio(p), [0.01, 0.004], rtol=0.3)
    np.testing.assert_allclose(damping_ratio(peak_poles(peaks, frf.line_spacing_hz, 0.006)), [0.006, 0.006])
    # an exponential window's decay (1/s) is added as the data show it: far more damping at 100 Hz
    shifted = peak_poles(peaks, frf.line_spacing_hz, 0.006, pole_shift=2.4)
    np.testing.assert_allclose(shifted.real, pole_from_fz(natural_freq_hz(p), np.full(2, 0.006)).real - 2.4)


def test_a_peak_is_reproduced_only_within_the_noise_the_coherence_gives():
    """A model 15 % low over a peak's top misfits it by 2.25 % of its energy: within the 3 % rule,
    but 9 times the noise of a 0.99 coherence over 5 averages, so the peak is not reproduced; with
    a coherence of 0.9 (noise 2.8 % of the energy) or without a count of averages it is."""
    from analysis.visibility import reproduced

    frf = modal_frf([100.0], [0.01], [[1.0]], [[1.0]])
    peak = visible_peaks(frf, (50.0, 290.0))[0]
    low = lambda f: 0.85 * np.asarray(frf.H)[..., np.searchsorted(frf.freq_hz, f)]  # noqa: E731
    assert not reproduced(frf, peak, low)
    assert reproduced(replace(frf, coherence=np.full(frf.H.shape, 0.9)), peak, low)
    assert reproduced(replace(frf, meta={}), peak, low)
    assert reproduced(frf, peak, lambda f: np.asarray(frf.H)[..., np.searchsorted(frf.freq_hz, f)])


def test_a_peak_beside_a_shared_pole_that_the_model_reproduces_is_not_a_possible_pair():
    df = 0.78125
    top = VisiblePeak(524.21875, 46.5, "top:4:X/left:9:Y", 5, (521.1, 528.9))
    weak = VisiblePeak(527.34375, 12.0, "top:4:X/right:6:-X", 3, (523.4, 534.4))
    assert unaccounted_peaks([top, weak], np.array([525.19]), df, lambda v: True) == ([], [])
    missed, pairs = unaccounted_peaks([top, weak], np.array([525.19]), df, lambda v: v is not weak)
    assert missed == [] and pairs == [(weak, 525.19)]


def test_three_overlapping_modes_are_all_fitted():
    """Three modes 0.5 % and 0.75 % apart, each within a half-power bandwidth of the next (the
    frame's 995.2 / 1000.2 / 1007.5 Hz at 0.6 %), one reference, three outputs each led by one of
    them (a peak of each in its own FRF): all three are fitted."""
    truth = [995.2, 1000.2, 1007.5]
    shapes = np.array([[1.0, 1.0, 0.2, 0.2], [0.4, 0.3, 1.0, 0.2], [-0.7, 0.1, 0.3, 1.0]])
    frf = modal_frf([800.0] + truth, [0.006] * 4, shapes, [[1.0]] * 4, fmax=1100.0, n_f=1408, noise=0.01)
    fit = fit_auto(frf, band=(900.0, 1100.0))
    assert fit.success, (fit.message, fit.freq_hz)
    f = np.sort(fit.freq_hz)
    assert f.size == 3, f
    np.testing.assert_allclose(f, truth, rtol=0.005)


def test_the_default_capture_fits_every_visible_mode_without_a_false_pair(one_point_capture):
    """The default-band fit of a one-point capture (hammer right:6:-X): the 525.2 Hz mode's weak peak
    2.7 lines beside the others in top:4:X, which the model reproduces within the noise, is no
    possible close pair; the fit is a success. The capture has the default exponential window: the
    995.2 / 1000.2 Hz modes a bandwidth apart show two peaks; the pole tried at the one the first
    model misses gains only a quarter of the local cost, but makes the model reproduce that peak
    within the noise, so it is kept (one pole and a possible close pair before)."""
    from simulator.stand import TestStand

    assert one_point_capture.exp_window_tau_s is not None
    fit = fit_auto(one_point_capture)
    assert fit.success, fit.problems
    assert not any("close pair" in p for p in fit.problems)
    modes = TestStand(seed=1).model.modes(1100.0)
    truth = np.asarray(modes.freq_hz, float)
    for t in truth[(truth > 990.0) & (truth < 1002.0)]:
        assert np.min(np.abs(fit.freq_hz - t)) <= 0.005 * t, (t, fit.freq_hz)
    # the slowest mode no longer leaks through the 1.28 s record: its damping within 2 %
    k = int(np.argmin(np.abs(fit.freq_hz - 12.9)))
    z_true = float(np.asarray(modes.damping, float)[int(np.argmin(np.abs(truth - 12.9)))])
    assert abs(float(fit.damping[k]) - z_true) <= 0.02 * z_true, (fit.damping[k], z_true)


def test_a_pole_between_two_resonances_accounts_for_the_nearer_one():
    """A pole 1.1 Hz from one resonance and 4.4 Hz from another (both within its 0.5 % reach) goes to
    the nearer one, whatever their prominences; the other, not reproduced, is a possible close pair."""
    df = 0.78125
    far = VisiblePeak(993.75, 12.8, "top:4:X/right:6:-X", 1, (989.8, 1001.6))
    near = VisiblePeak(999.22, 12.7, "right:4:-Z/right:6:-X", 2, (989.8, 1007.0))
    missed, pairs = unaccounted_peaks([far, near], np.array([998.15]), df, lambda v: v is near)
    assert missed == [] and pairs == [(far, 998.15)]


def test_a_resonance_beside_a_mains_harmonic_is_not_taken_for_a_mains_line():
    """A sharp mode 1.25 lines from the 200 Hz mains harmonic, three lines wide at 3 dB (wider than
    a steady line of the record), left out of the model: a problem of the fit, not a mains note;
    a one-line spike on 250 Hz is a mains note."""
    from analysis.missing_modes import mains_line_max_lines

    shapes = np.array([[1.0, 1.0, 0.8], [0.7, -0.9, 1.0]])
    frf = modal_frf([80.0, 199.75, 260.0], [0.005, 0.0014, 0.005], shapes, np.ones((3, 1)))
    df = float(frf.line_spacing_hz)
    k = int(np.argmin(np.abs(frf.freq_hz - 250.0)))
    H = frf.H.copy()
    H[..., k] += 30.0 * np.abs(H[..., k])   # a steady line, on one line
    frf = replace(frf, H=H)
    band = (20.0, 290.0)
    peaks = visible_peaks(frf, band)
    mode = [v for v in peaks if abs(v.freq_hz - 199.75) < 0.5]
    assert mode and all(round((v.top_hz[1] - v.top_hz[0]) / df) - 1 == 3 for v in mode), mode
    assert any(abs(v.freq_hz - frf.freq_hz[k]) < 0.1 for v in peaks)
    two = fit_lsfd(frf, pole_from_fz(np.array([80.0, 260.0]), np.full(2, 0.005)), band=band)
    problems, notes = unfitted_resonances(frf, peaks, two)
    assert any("199.8 Hz" in p for p in problems), problems
    assert not any("199." in n for n in notes), notes
    assert len(notes) == 1 and "250" in notes[0] and "mains line" in notes[0], notes
    # the widest steady line: two lines of the record, more through a strong exponential window
    assert mains_line_max_lines(0.78125) == 2
    assert mains_line_max_lines(0.78125, 1.28 / np.log(20.0)) == 2      # window to 5 % of a 1.28 s record
    assert mains_line_max_lines(0.78125, 0.1) == 6                      # 1/(pi tau) = 3.2 Hz: 4 lines more


def test_a_peak_only_a_few_frfs_of_a_large_set_show_is_not_a_resonance_of_the_structure():
    """40 FRFs: a hump in one FRF (not in the CMIF) is named, not counted; a peak the CMIF shows, or one
    that 5 % of the FRFs show, is the structure's; in a set of three FRFs one FRF is enough."""
    from analysis.visibility import structure_resonances

    df = 0.125
    hump = VisiblePeak(25.5, 30.0, "acc:2/plane:7", 7, (25.0, 26.0))
    mode = [VisiblePeak(97.1, 40.0, "CMIF", -1, (96.8, 97.4)), VisiblePeak(97.125, 35.0, "acc:1/plane:1", 1, (96.8, 97.4))]
    shared = [VisiblePeak(60.0, 12.0, f"acc:1/plane:{k}", k, (59.8, 60.2)) for k in (3, 4)]
    kept, left = structure_resonances([hump, *mode, *shared], 40, df)
    assert [g[0] for g in left] == [hump]
    assert set(kept) == {*mode, *shared}
    kept, left = structure_resonances([hump], 3, df)
    assert kept == [hump] and left == []


def test_peaks_of_one_mode_are_merged_within_its_half_power_band_and_a_pole_reaches_its_bandwidth():
    """A broad mode (2 % damping at 350 Hz: 14 Hz wide) peaks 2.5 Hz from where its pole is fitted: the
    pole accounts for it (within its bandwidth), where a fixed 0.5 % (1.75 Hz) would call it missed."""
    df = 0.5
    peak = VisiblePeak(352.0, 25.0, "CMIF", -1, (345.0, 359.0))
    missed, pairs = unaccounted_peaks([peak], np.array([349.5]), df)
    assert missed == [peak]                                    # no bandwidth given: the fixed reach
    assert unaccounted_peaks([peak], np.array([349.5]), df, fitted_bandwidth_hz=np.array([14.0])) == ([], [])


def test_a_one_line_resonance_without_coherence_is_visible_and_a_spike_is_not():
    """1 Hz lines, a mode at 0.02 % damping (0.05 Hz wide): its top is one line, but its flanks stand far
    above the noise, so it counts; a one-line spike of the same height without flanks does not."""
    f = np.arange(1.0, 301.0)
    frf = modal_frf([100.3, 200.0], [0.0002, 0.01], np.array([[1.0, 1.0]]), np.array([[1.0], [1.0]]),
                    fmax=300.0, n_f=300)
    frf = replace(frf, freq_hz=f, coherence=None)
    peaks = visible_peaks(frf, (5.0, 295.0))
    assert any(abs(v.freq_hz - 100.0) <= 1.0 for v in peaks)
    H = frf.H.copy()
    H[0, 0, 149] = 30 * np.abs(H[0, 0, 149])            # 150 Hz: a spike
    assert not any(abs(v.freq_hz - 150.0) < 0.5 for v in visible_peaks(replace(frf, H=H), (5.0, 295.0)))


def test_one_average_coherence_confirms_nothing():
    """A set that says it holds one average has a coherence of 1 on every line: its one-line noise spikes
    are not visible peaks, as without coherence."""
    frf = pair_frf(1)
    H = frf.H.copy()
    k = int(np.argmin(np.abs(frf.freq_hz - 100.0)))
    H[0, 0, k] *= 30.0
    one = replace(frf, H=H, coherence=np.ones(frf.H.shape), meta={"n_averages": [1]})
    assert not any(abs(v.freq_hz - frf.freq_hz[k]) < 0.1 for v in visible_peaks(one, (20.0, 290.0)))
    five = replace(one, meta={"n_averages": [5]})
    assert any(abs(v.freq_hz - frf.freq_hz[k]) < 0.1 for v in visible_peaks(five, (20.0, 290.0)))


def test_a_pole_without_cmif_support_and_with_inconsistent_shapes_is_unsupported():
    """Three outputs, four references, modes at 70 and 230 Hz: their residue matrices are rank one and the
    CMIF peaks at them. A pole at 150 Hz whose residues have no one shape (rank three) where no FRF peaks
    is flagged; the modes are not."""
    from analysis.fit_checks import unsupported_poles

    shapes = np.array([[1.0, 0.5], [0.6, 1.0], [-0.8, 0.9]])
    part = np.array([[1.0, 0.8], [1.0, -0.6], [0.5, 1.0], [1.0, 0.7]])
    frf = modal_frf([70.0, 230.0], [0.005, 0.005], shapes, part.T, noise=0.002)
    poles = pole_from_fz([70.0, 150.0, 230.0], [0.005, 0.005, 0.005])
    R = np.zeros((3, 4, 3), dtype=complex)
    R[..., 0] = np.outer(shapes[:, 0], part[:, 0]) * poles[0].imag / 2j
    R[..., 2] = np.outer(shapes[:, 1], part[:, 1]) * poles[2].imag / 2j
    R[..., 1] = 0.01 * np.eye(3, 4) * poles[1].imag    # each output sees another reference: no one shape
    bad, why = unsupported_poles(frf, poles, R)
    assert list(bad) == [False, True, False] and "150 Hz" in why[0]
    one = frf.select(outputs=[frf.outputs[0]])
    assert not np.any(unsupported_poles(one, poles, R[:1])[0])   # one output: no shape to compare


def test_a_close_pair_peak_inside_its_neighbours_half_power_band_is_fitted(tmp_path):
    """The simulated frame struck softly (40 N) at three points: its 995.2 Hz mode shows as a peak in
    top:4:X/right:6:-X 3 Hz from the 1000.2 Hz mode's peak in right:4:-Z/top:4:Z, inside that one's
    half-power band, so the two peaks group as one resonance that the 1000 Hz pole accounts for. The
    peak the model does not make in its own FRF is still tried: the fit holds both modes, and each fitted
    mode is one of the frame's (no extra pole)."""
    import contextlib
    import io

    from acquisition.cli_capture import main as capture
    from analysis.linearity import recording_hits
    from simulator.config import FrameConfig
    from simulator.fem import FrameModel

    cfg = tmp_path / "f.toml"
    cfg.write_text("[hammer]\namplitude_n = 40.0\n")
    path = str(tmp_path / "f.h5")
    with contextlib.redirect_stdout(io.StringIO()):
        assert capture(["--device", f"sim://?seed=5006&config={cfg}", "--out", path, "--points",
                        "right:6:-X,left:6:X,top:4:Z", "--hits", "5", "--auto", "-q"]) == 0
    hits = recording_hits(path)
    assert hits is not None
    fit = fit_auto(hits[2][0])
    assert fit.success, fit.problems
    frame = FrameConfig.load(str(cfg))
    masses = {p: frame.sensors.accelerometer.mass_kg for p in frame.test_plan.sensors} if frame.sensors.mass_loading else {}
    truth = FrameModel.from_config(frame, masses).modes(1100.0).freq_hz
    pair = truth[(truth > 990.0) & (truth < 1003.0)]
    assert pair.size == 2
    f = np.asarray(fit.freq_hz)
    assert all(np.min(np.abs(f - x)) < 1.0 for x in pair), (pair, f)
    assert all(np.min(np.abs(truth - x)) < 0.005 * x for x in f), f
