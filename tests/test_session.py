"""acquisition.session: the capture loop through the real firmware, bulk-only protocol and driver.

Part 1 runs on a small resonator stand (exact digital physics, known FRF) over the loopback link;
part 2 runs the simulated frame over ``sim://`` and compares with its analytic FRF.
"""
from __future__ import annotations

import io
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal

from acquisition.driver import Analyser
from acquisition.loopback import LoopbackTransport
from acquisition.session import (
    CaptureSession,
    HitSummary,
    OperatorQuit,
    SessionError,
    TestPlan,
    average_recorded_hits,
    channel_table,
)
from acquisition.setup import AcquisitionSetup, ChannelSetup, TriggerSetup
from acquisition.terminal import terminal_decider
from analysis.recording import Recording, load_frfset
from analysis.recording_writer import RecordingWriter
from analysis.spectra import WindowSettings

FS = 6400.0
N = 2048
PRE = 64
GAINS = (1.0, -0.5, 2.0)


def small_setup() -> AcquisitionSetup:
    hammer = ChannelSetup("force", "right:6:-X", "force", 2.25, "mV/N", "AC", True, 1.0)
    accels = tuple(ChannelSetup(f"acc{i + 1}", p, "acceleration", 100.0, "mV/g", "AC", True, 5.0)
                   for i, p in enumerate(("left:9:Y", "top:4:X", "right:4:-Z")))
    return AcquisitionSetup(FS, N, (hammer,) + accels, TriggerSetup(0, 20.0, "rising", PRE))


def resonator():
    """Two resonances (300 and 900 Hz) as a digital filter: response = lfilter(b, a, force) * gain."""
    b1, a1 = signal.iirpeak(300.0, 15.0, fs=FS)
    b2, a2 = signal.iirpeak(900.0, 30.0, fs=FS)
    b = np.polyadd(np.convolve(b1, a2), np.convolve(b2, a1))
    a = np.convolve(a1, a2)
    return 5.0 * b, a


class ResonatorStand:
    """Exact, seeded physics: a half-sine hammer pulse into :func:`resonator`; strikes listed in
    ``double`` get a second blow (40 %, 4 ms later), those in ``overload`` are 40 x too hard."""

    def __init__(self, seed: int = 0, double=(), overload=(), noise: float = 0.0, amplitude: float = 100.0):
        self.rng = np.random.default_rng(seed)
        self.double, self.overload = set(double), set(overload)
        self.noise, self.amplitude = noise, amplitude
        self.strikes = 0
        self.channel_points: list = []
        self.b, self.a = resonator()

    def set_channels(self, channels) -> None:
        self.channels = list(channels)
        self.channel_points.append([c.point for c in channels])

    def strike(self, fs_hz, n_samples, pretrigger):
        self.strikes += 1
        t = (np.arange(n_samples) - pretrigger - 3) / fs_hz
        width = 0.0012
        amp = self.amplitude * self.rng.uniform(0.9, 1.1)
        f = np.where((t >= 0) & (t < width), amp * np.sin(np.pi * np.clip(t, 0, width) / width), 0.0)
        if self.strikes in self.double:
            t2 = t - 0.004
            f = f + np.where((t2 >= 0) & (t2 < width), 0.4 * amp * np.sin(np.pi * np.clip(t2, 0, width) / width), 0)
        if self.strikes in self.overload:
            f = 40 * f
        x = signal.lfilter(self.b, self.a, f)
        values = [f] + [g * x for g in GAINS]
        volts = np.array([v * c.sensitivity for v, c in zip(values, self.channels)])
        volts = volts + self.noise * self.rng.normal(size=volts.shape)
        return SimpleNamespace(volts=volts, info={})


def make_analyser(stand) -> Analyser:
    from simulator.firmware import Firmware

    return Analyser(LoopbackTransport(Firmware(stand, strike_after_polls=0)), poll_interval_s=0.001)


WIN = WindowSettings(force_width_s=0.01, force_taper_s=0.002)


def run(tmp_path, stand, plan, decide=lambda s: True, name="rec.h5", windows=WIN):
    setup = small_setup()
    path = tmp_path / name
    lines: list[str] = []
    with make_analyser(stand) as an, RecordingWriter(path, instrument=an.identify().as_dict(), setup=setup.to_dict(),
                                                     channels=channel_table(setup), windows=windows) as w:
        result = CaptureSession(an, setup, plan, writer=w, windows=windows, decide=decide,
                                progress=lines.append).run()
    return result, path, lines


def test_roving_hammer_rejects_double_hit_and_overload(tmp_path):
    stand = ResonatorStand(seed=1, double=[2], overload=[4])
    plan = TestPlan("roving_hammer", ("right:6:-X", "top:4:Z"), hits_per_point=3)
    result, path, lines = run(tmp_path, stand, plan)
    assert result.accepted == 6 and len(result.rejected) == 2
    (m1, _, i1, r1), (m2, _, i2, r2) = result.rejected
    assert (m1, i1, m2, i2) == (0, 1, 0, 3)
    assert "double hit" in r1[0] and "overload on channel 1 (force right:6:-X)" in r2[0]
    # the stand saw the hammer move: force channel point per measurement
    assert [p[0] for p in stand.channel_points] == ["right:6:-X", "top:4:Z"]
    assert any("REJECTED: double hit" in line for line in lines)
    with Recording(path) as rec:
        hits = list(rec.hits())
        assert len(hits) == 8 and [h.accepted for h in hits].count(False) == 2
        assert [h.measurement for h in hits] == [0] * 5 + [1] * 3
        assert "double hit" in hits[1].reasons[0] and hits[3].overload[0]
        assert any("rejected" in e[2] for e in rec.events())
    s = load_frfset(path)
    assert s.H.shape[:2] == (3, 2) and s.references == ("right:6:-X", "top:4:Z")
    assert s.meta["n_averages"] == [3, 3]


def test_h1_matches_the_known_frf_and_replay_is_bit_exact(tmp_path):
    stand = ResonatorStand(seed=2)
    result, path, _ = run(tmp_path, stand, TestPlan(hits_per_point=4))
    s = load_frfset(path)
    b, a = resonator()
    _, H = signal.freqz(b, a, worN=s.freq_hz, fs=FS)
    band = (s.freq_hz > 100) & (s.freq_hz < 1000)  # the 1.2 ms pulse has its first spectral zero at 1250 Hz
    for i, g in enumerate(GAINS):
        rel = np.abs(s.H[i, 0, band] - g * H[band]) / np.abs(g * H[band])
        assert np.median(rel) < 2e-3 and rel.max() < 0.05  # 16-bit ADC (worst at the antiresonance)
    # recomputing from the recorded counts gives the session's FRFs bit for bit
    with Recording(path) as rec:
        again = average_recorded_hits(list(rec.hits(accepted_only=True)), rec.windows, rec.channels)
    assert np.array_equal(again[0].acc.h1(), result.averages[0].acc.h1())
    assert np.array_equal(again[0].acc.coherence(), s.coherence[:, 0, :])


def test_operator_rejects_roll_back_the_average(tmp_path):
    offered: list[HitSummary] = []

    def every_other(summary: HitSummary) -> bool:
        offered.append(summary)
        return len(offered) % 2 == 1

    stand = ResonatorStand(seed=3, noise=2e-3)
    result, path, _ = run(tmp_path, stand, TestPlan(hits_per_point=3), decide=every_other)
    assert len(offered) == 5 and result.accepted == 3
    assert all(r[3] == ["rejected by the operator"] for r in result.rejected)
    assert offered[0].coherence_so_far is None and offered[1].coherence_so_far is not None
    assert offered[2].accepted == 1  # the rejected hit was rolled back
    with Recording(path) as rec:
        kept = list(rec.hits(accepted_only=True))
        assert [h.index for h in kept] == [0, 2, 4]
        again = average_recorded_hits(kept, rec.windows, rec.channels)
    assert np.array_equal(again[0].acc.h1(), result.averages[0].acc.h1())


def test_operator_quit_keeps_what_was_measured(tmp_path):
    calls = []

    def quit_on_third(summary):
        calls.append(summary)
        if len(calls) == 3:
            raise OperatorQuit("operator pressed q")
        return True

    result, path, _ = run(tmp_path, ResonatorStand(seed=4), TestPlan("roving_hammer", ("right:6:-X", "top:4:Z"), 5),
                          decide=quit_on_third)
    assert result.aborted and result.accepted == 2
    with Recording(path) as rec:
        assert [h.accepted for h in rec.hits()] == [True, True, False]
        assert rec.measurement_names() == ["m000"]
        assert any("ended early" in e[2] for e in rec.events())
    assert load_frfset(path).meta["n_averages"] == [2]


def test_roving_accelerometer_plan_moves_first_accelerometer(tmp_path):
    stand = ResonatorStand(seed=5)
    plan = TestPlan("roving_accelerometer", ("top:2:Z", "top:6:Z"), hits_per_point=2, reference="left:6:X")
    result, path, _ = run(tmp_path, stand, plan)
    assert stand.channel_points == [["left:6:X", "top:2:Z", "top:4:X", "right:4:-Z"],
                                    ["left:6:X", "top:6:Z", "top:4:X", "right:4:-Z"]]
    s = load_frfset(path)
    assert s.references == ("left:6:X",)
    assert s.outputs == ("top:2:Z", "top:4:X", "right:4:-Z", "top:6:Z")


def test_no_trigger_gives_a_session_error(tmp_path):
    stand = ResonatorStand(seed=6, amplitude=5.0)  # below the 20 N trigger level
    setup = small_setup()
    with make_analyser(stand) as an:
        session = CaptureSession(an, setup, TestPlan(hits_per_point=1), timeout_s=0.05, max_timeouts=2)
        with pytest.raises(SessionError, match="no trigger in 2 tries"):
            session.run()


def test_terminal_decider_keys():
    out = io.StringIO()
    answers = iter(["x", "r", "a", "q"])
    decide = terminal_decider(lambda prompt: next(answers), out)
    assert decide(None) is False and "press a, r or q" in out.getvalue()
    assert decide(None) is True
    with pytest.raises(OperatorQuit):
        decide(None)

    def eof(prompt):
        raise EOFError

    with pytest.raises(OperatorQuit, match="input closed"):
        terminal_decider(eof, out)(None)


def test_plan_validation():
    with pytest.raises(ValueError, match="reference only for a roving accelerometer"):
        TestPlan("roving_hammer", reference="left:6:X")
    with pytest.raises(ValueError, match="bad point label"):
        TestPlan(points=("nowhere",))
    with pytest.raises(ValueError, match="mode"):
        TestPlan("roving_shaker")
    m = TestPlan().measurements(small_setup())
    assert len(m) == 1 and m[0].reference == "right:6:-X" and m[0].outputs == ("left:9:Y", "top:4:X", "right:4:-Z")


# ---------------------------------------------------------------------- part 2: the simulated frame over sim://
def sim_session(url: str, points, hits: int, windows: WindowSettings, setup=None, **options):
    """A roving-hammer session on ``url`` with ``setup`` (default: the default set-up; no recording)."""
    from acquisition.setup import default_setup

    setup = setup or default_setup()
    with Analyser(url, timeout_s=30.0) as an:
        result = CaptureSession(an, setup, TestPlan("roving_hammer", tuple(points), hits), windows=windows,
                                **options).run()
    return setup, result


def windowed_truth(setup, hammer_point: str, outputs, freq_hz, exp_window_tau_s: float, config=None) -> np.ndarray:
    """The simulated frame's exact accelerance seen through the test chain, as the windowed estimate sees it.

    An exponential window exp(-t/tau) on force and response turns every mode's pole lambda into
    lambda - 1/tau, i.e. the FRF is evaluated at the complex frequency w - j/tau (same residues). The
    channels' first-order high-passes (IEPE: 0.5 Hz accelerometers, 0.01 Hz force; the AC coupling is
    common) enter as their ratio. The anti-alias filter is common to all channels and cancels.
    """
    from simulator.stand import TestStand

    stand = TestStand(config=config, seed=0)
    chans = [{"point": hammer_point if c.quantity == "force" else c.point, "quantity": c.quantity,
              "sensitivity": c.sensitivity, "sensitivity_unit": c.sensitivity_unit, "iepe": c.iepe,
              "coupling": c.coupling} for c in setup.channels]
    stand.set_channels(chans)  # the same accelerometer layout (mass loading) as in the test
    model = stand.model
    modes = model.modes()
    wt = 2 * np.pi * np.asarray(freq_hz) - 1j / exp_window_tau_s
    wr = modes.omega
    po = model.shape_at(list(outputs), modes)
    pr = model.shape_at([hammer_point], modes)
    den = wr[:, None] ** 2 - wt[None, :] ** 2 + 2j * modes.damping[:, None] * wr[:, None] * wt[None, :]
    H = np.einsum("om,rm,mk->ok", po, pr, 1.0 / den) * (1j * wt) ** 2
    hp = lambda fc: 1j * wt / (1j * wt + 2 * np.pi * fc)  # noqa: E731
    cfg = stand.config.sensors
    return H * hp(cfg.accelerometer.iepe_highpass_hz) / hp(cfg.force.iepe_highpass_hz)


def _tau(setup, fraction: float) -> float:
    from analysis.spectra import tau_from_end_fraction

    return tau_from_end_fraction(fraction, (setup.block_size - setup.trigger.pretrigger_samples) / setup.sample_rate_hz)


def test_sim_h1_agrees_with_the_analytic_frf():
    """Noise on (default sensors): H1 equals the frame's exact FRF within the random error of the
    estimate, eps = sqrt(1 - gamma^2) / (gamma sqrt(2 n)) (Bendat & Piersol), plus a 1 % floor.

    Band 15..400 Hz: the stand drives its modes with the piecewise-linear (FOH) force while the
    analyser samples the pulse itself, which puts a factor sinc^2(f/fs) on every simulated FRF
    (0.987 at 400 Hz, 0.92 at 1 kHz for fs = 6400 Hz): the stand's business, not the estimator's.
    Checked paths: right:6:-X -> top:4:X and the driving point left:9:Y (normalised error median
    0.1-0.9 over seeds 5, 6). The weak cross paths (right:6:-X -> right:4:-Z, left:9:Y -> top:4:X,
    left:9:Y -> right:4:-Z: responses of a few ADC counts, where the converter's own noise of half a
    count dominates) lie at the noise floor (normalised error median 1.1-3): not asserted here.
    """
    from dataclasses import replace

    from acquisition.setup import default_setup

    # 8192-sample blocks (1.28 s), the record these bounds are calibrated on: with the default 5.12 s
    # record and the window at 5 % of it, the noisy tail weighs 4x longer and the weak path
    # right:6:-X -> top:4:X has a median relative error of 5 % (0.3 % at the driving point)
    short = replace(default_setup(), block_size=8192)
    tau = _tau(short, 0.05)
    win = WindowSettings(force_width_s=0.02, force_taper_s=0.005, exp_window_tau_s=tau)
    setup, result = sim_session("sim://?seed=5", ("right:6:-X", "left:9:Y"), 5, win, setup=short)
    for avg, out in zip(result.averages, ("top:4:X", "left:9:Y")):
        i = avg.outputs.index(out)
        f, n = avg.acc.freq_hz, avg.n_averages
        H1, coh = avg.acc.h1()[i], avg.acc.coherence()[i]
        truth = windowed_truth(setup, avg.reference, [out], f, tau)[0]
        good = (f > 15) & (f < 400) & (coh > 0.5)
        assert good.sum() > 400
        rel = np.abs(H1[good] - truth[good]) / np.abs(truth[good])
        eps = np.sqrt(1 - coh[good]) / np.sqrt(2 * n * coh[good])
        e = rel / np.sqrt(eps ** 2 + 0.01 ** 2)
        assert np.median(e) < 1.5, (avg.reference, out)
        assert np.mean(e < 3) > 0.8, (avg.reference, out)
        clean = coh[good] >= 0.99   # where the coherence leaves little random error, H1 is within 2 %
        assert clean.sum() > 300 and np.median(rel[clean]) < 0.02, (avg.reference, out)


NOISY = """
[sensors.force]
noise_density_n_per_rthz = 0.06
[sensors.accelerometer]
noise_density_g_per_rthz = 1.0e-3
"""


def test_sim_noisy_channels_h1_h2_bracket_truth_and_coherence_dips_at_antiresonances(tmp_path):
    """With noise on the force (no force window) and on the response: |H1| <= |H| <= |H2| as theory
    says (H1 low by the force noise, H2 high by the response noise), and the coherence drops at the
    antiresonances of the driving-point FRF."""
    from scipy.signal import find_peaks

    from acquisition.setup import default_setup

    cfg = tmp_path / "noisy.toml"
    cfg.write_text(NOISY)
    tau = _tau(default_setup(), 0.05)
    win = WindowSettings(force_width_s=None, exp_window_tau_s=tau)
    # the force noise (3.4 N rms per sample) would pass for double hits at the default 10 % threshold
    from acquisition.hitcheck import HitCheckSettings

    setup, result = sim_session(f"sim://?seed=5&config={cfg}", ("left:9:Y",), 10, win,
                                check_settings=HitCheckSettings(double_hit_fraction=0.3))
    avg = result.averages[0]
    i = avg.outputs.index("left:9:Y")  # driving point
    f = avg.acc.freq_hz
    H = windowed_truth(setup, "left:9:Y", ["left:9:Y"], f, tau, config=cfg)[0]
    band = (f > 20) & (f < 400)
    H1, H2, coh = avg.acc.h1()[i], avg.acc.h2()[i], avg.acc.coherence()[i]
    assert np.all(np.abs(H1[band]) <= np.abs(H2[band]) * (1 + 1e-12))
    mag = np.where(band, np.abs(H), 0.0)
    peaks, _ = find_peaks(mag)
    troughs, _ = find_peaks(np.where(band, -np.abs(H), -np.inf))
    assert len(peaks) >= 3 and len(troughs) >= 3
    # around the resonances (|H| > 3 x its band median) the response noise is negligible: H1 shows the
    # force-noise bias Gff / (Gff + Gnn) < 1, H2 (biased only by response noise) stays on the truth
    strong = band & (np.abs(H) > 3 * np.median(np.abs(H[band])))
    assert strong.sum() >= 20
    r1 = np.mean(np.abs(H1[strong]) / np.abs(H[strong]))
    r2 = np.mean(np.abs(H2[strong]) / np.abs(H[strong]))
    # seeds 5..11 gave r1 = 0.91..0.94 and r2 = 0.99..1.03
    assert r1 < 0.97
    assert r2 == pytest.approx(1.0, abs=0.05) and r2 > r1 + 0.03
    # over the band (medians: the magnitude of a noisy estimate is biased up where |H| ~ noise)
    assert np.median(np.abs(H2[band]) / np.abs(H[band])) > 1.05
    assert np.median(coh[troughs]) < np.median(coh[peaks]) - 0.1


class RecordingOperator:
    """A non-terminal front end (as a browser station would be): decides from the event it gets and
    keeps every per-hit event."""

    def __init__(self, reject_attempts=()):
        self.reject_attempts = set(reject_attempts)
        self.events: list = []
        self.lines: list[str] = []

    def decide(self, summary):
        return summary.attempt not in self.reject_attempts

    def progress(self, text):
        self.lines.append(text)

    def on_hit(self, summary):
        self.events.append(summary)


def test_operator_callbacks_get_each_hit_with_data_verdict_and_reasons_after_it_is_written(tmp_path):
    stand = ResonatorStand(seed=3, double=[3])
    setup = small_setup()
    op = RecordingOperator(reject_attempts=[2])
    order: list = []
    with make_analyser(stand) as an, RecordingWriter(tmp_path / "op.h5", instrument=an.identify().as_dict(),
                                                     setup=setup.to_dict(), channels=channel_table(setup),
                                                     windows=WIN) as w:
        arm = an.arm
        an.arm = lambda: (order.append("arm"), arm())[1]
        real_on_hit = op.on_hit
        op.on_hit = lambda s: (order.append(("hit", s.hit_index)), real_on_hit(s))
        result = CaptureSession(an, setup, TestPlan(hits_per_point=2), writer=w, windows=WIN, operator=op).run()
    assert result.accepted == 2 and len(op.events) == 4
    assert [e.decision for e in op.events] == [True, False, False, True]
    assert op.events[1].reasons == ["rejected by the operator"] and "double hit" in op.events[2].reasons[0]
    assert [e.hit_index for e in op.events] == [0, 1, 2, 3]
    assert all(e.sample_rate_hz == FS and e.data.shape == (4, N) for e in op.events)
    # every hit is written and reported before the next arm
    assert order == ["arm", ("hit", 0), "arm", ("hit", 1), "arm", ("hit", 2), "arm", ("hit", 3)]
    assert any("REJECTED: double hit" in line for line in op.lines)
    with Recording(tmp_path / "op.h5") as rec:
        assert [h.accepted for h in rec.hits()] == [True, False, False, True]
