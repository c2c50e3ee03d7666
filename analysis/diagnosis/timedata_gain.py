"""The held-out gain of the time-data effects (:mod:`analysis.diagnosis.timedata`): the linear simulation's
error before and after re-simulating the effect (nonlinearity, input noise) or excluding the affected
hits (overload, double hit), scored on held-out lines as the FRF effects (``docs/diagnosis.md``)."""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from ..frf import window_pole_shift
from ..modal import ModalModel
from ..spectra import WindowSettings, exponential_window, force_window, hit_spectra, tau_from_end_fraction
from .compare import held_out_errors
from .effects import synthesize_windowed
from .rule import DEFAULT_RULE, DecisionRule, db, held_out_db
from .timedata import (
    FORCE_TAPER_S,
    FORCE_WINDOW_S,
    NOISE_GUARD,
    _check_hits,
    detect_amplitude_nonlinearity,
    detect_double_hit,
    detect_input_noise,
    detect_overload,
    pulse_bounds,
)

__all__ = ["windowed_accelerance", "HitSpectraSet", "hit_spectra_set", "diagnose_time_effects"]


def windowed_accelerance(base: ModalModel, freq_hz: np.ndarray, exp_window_tau_s: float | None,
                         factor: float = 1.0) -> np.ndarray:
    """Accelerance (m/s^2/N) of a receptance pole-residue model as estimated from exponentially
    windowed hits, with all natural frequencies times ``factor`` (stiffness times factor^2).

    Mode r with receptance residue ``R_r`` and pole ``lambda_r`` has the acceleration impulse response
    ``R_r lambda_r^2 exp(lambda_r t) + c.c.`` plus the direct term ``delta(t) sum_r 2 Re(R_r lambda_r)``
    (and ``delta'(t) sum_r 2 Re(R_r)``, zero for a physical model). The window ``exp(-t/tau)`` shifts
    every pole of that accelerance model to ``lambda_r - 1/tau`` with the same numerators, i.e.
    ``H(w) = H_acc(j w + 1/tau)``; this is :func:`analysis.diagnosis.effects.synthesize_windowed`
    (converting the shifted receptance by (j w)^2 instead errs by about 2 / (w tau) relative). With
    ``factor`` a: ``lambda -> a lambda``, ``R -> R / a`` (masses and shapes kept). Returns
    (n_out, n_ref, n_freq) complex.
    """
    if base.quantity != "receptance" or base.residual_form not in ("none", None):
        raise ValueError("windowed_accelerance needs a receptance pole-residue model without residual terms "
                         "(e.g. simulator FrameModel.modal_model(..., 'receptance'))")
    model = replace(base, poles=np.asarray(base.poles) * factor, residues=np.asarray(base.residues) / factor,
                    meta={})
    return synthesize_windowed(model, freq_hz, "accelerance", window_pole_shift(exp_window_tau_s)).H


@dataclass(frozen=True)
class HitSpectraSet:
    """Per-hit spectra of a set of hits (:func:`analysis.spectra.hit_spectra` scaling), band lines only.

    freq_hz (n_freq,); Gff (n_hits, n_freq) N^2/Hz; Gfx (n_hits, n_out, n_freq); starts: pulse start
    sample of each hit (window origin); exp_window_tau_s: exponential window; noise_gain: sum_n w_n^2 of each hit's
    force window (to turn a white noise variance into its expected G_nn); response_noise (n_out,): rms
    (EU) of the responses before the pulses (the sensor noise); response_gain: sum w^2 of the response
    window of each hit."""

    freq_hz: np.ndarray
    Gff: np.ndarray
    Gfx: np.ndarray
    starts: np.ndarray
    exp_window_tau_s: float
    noise_gain: np.ndarray
    response_noise: np.ndarray
    response_gain: np.ndarray
    force_width_s: float | None = None

    def h1(self, hits: np.ndarray | None = None) -> np.ndarray:
        """H1 (n_out, n_freq) over the selected hits (boolean mask or indices; default all)."""
        sel = slice(None) if hits is None else hits
        return np.sum(self.Gfx[sel], axis=0) / np.sum(self.Gff[sel], axis=0)


def hit_spectra_set(force: np.ndarray, responses: np.ndarray, fs_hz: float, band: Sequence[float], *,
                    exp_window_end_fraction: float = 1e-3, force_width_s: float | None = None, force_taper_s: float = 0.0,
                    ) -> HitSpectraSet:
    """Spectra of each hit with the window origin at its pulse start (:func:`pulse_bounds`), an
    exponential window reaching ``exp_window_end_fraction`` at the block end (same tau for all hits, from the median
    start) on force and responses, and optionally a force window (``force_width_s`` after the start)."""
    f = _check_hits(force)
    x = np.asarray(responses, float)
    if x.ndim == 2:
        x = x[:, None, :]
    n = f.shape[1]
    starts = np.array([pulse_bounds(r)[0] for r in f])
    tau = tau_from_end_fraction(exp_window_end_fraction, (n - float(np.median(starts))) / fs_hz)
    win = WindowSettings(force_width_s=force_width_s, force_taper_s=force_taper_s, exp_window_tau_s=tau)
    Gff, Gfx, gains, rgains = [], [], [], []
    freq = sel = None
    for i in range(f.shape[0]):
        hs = hit_spectra(f[i], x[i], fs_hz, int(starts[i]), win)
        if freq is None:
            sel = (hs.freq_hz >= band[0]) & (hs.freq_hz <= band[1])
            freq = hs.freq_hz[sel]
        Gff.append(hs.Gff[sel])
        Gfx.append(hs.Gfx[:, sel])
        w = exponential_window(n, fs_hz, int(starts[i]), tau)
        rgains.append(float(np.sum(w ** 2)))
        if force_width_s is not None:
            w = w * force_window(n, fs_hz, int(starts[i]), force_width_s, force_taper_s)
        gains.append(float(np.sum(w ** 2)))
    if freq is None or freq.size < 8:
        raise ValueError(f"the band {band} Hz holds fewer than 8 lines of these hits; widen it")
    pre = np.concatenate([x[i, :, :max(int(starts[i]) - NOISE_GUARD, 0)] for i in range(f.shape[0])], axis=1)
    rn = np.std(pre, axis=1) if pre.shape[1] >= 8 else np.zeros(x.shape[1])
    return HitSpectraSet(freq, np.array(Gff), np.array(Gfx), starts, tau, np.array(gains), rn,
                         np.array(rgains), force_width_s)


def noise_weights(spec: HitSpectraSet, H: np.ndarray, n: int, fs_hz: float,
                  floor_fraction: float = 0.01, reference_noise: float = 0.01) -> np.ndarray:
    """Line weights (n_out, 1, n_freq) of the relative squared error (as
    :func:`analysis.diagnosis.compare.line_weights`) with the H1 variance from the response noise of
    the pre-trigger samples: ``v = sum_i G_nx,i / (sum_i G_ff,i |H|^2)`` (relative), ``G_nx`` the
    expected spectrum of that white noise through the response window;
    ``w = 1 / (|H|^2 (1 + v / reference_noise^2) + floor^2)``. Noise-dominated lines (a response
    direction the reference hardly excites) then weigh little, whatever the force-side effect."""
    dt = 1.0 / fs_hz
    c = np.where(spec.freq_hz == 0, 1.0, 2.0)
    Gnx = (c[None, :] / (n * dt)) * dt ** 2 * np.sum(spec.response_gain) * spec.response_noise[:, None] ** 2
    mag2 = np.abs(H[:, 0, :]) ** 2
    v = Gnx / (np.sum(spec.Gff, axis=0)[None, :] * mag2 + 1e-300)
    floor = floor_fraction * np.median(np.abs(H[:, 0, :]), axis=1, keepdims=True)
    return (1.0 / (mag2 * (1 + v / reference_noise ** 2) + floor ** 2 + 1e-300))[:, None, :]


def _noise_psd(spec: HitSpectraSet, sigma_n: float, n: int, fs_hz: float) -> np.ndarray:
    """Expected G_nn (n_hits, n_freq) of white force noise ``sigma_n`` (N rms) through each hit's window:
    ``c_k / (n dt) * dt^2 * sigma^2 * sum w^2`` (the hit_spectra scaling)."""
    dt = 1.0 / fs_hz
    c = np.where((spec.freq_hz == 0) | (np.isclose(spec.freq_hz, fs_hz / 2)), 1.0, 2.0)
    return (c[None, :] / (n * dt)) * dt ** 2 * sigma_n ** 2 * spec.noise_gain[:, None]


def _score(measured: np.ndarray | tuple[np.ndarray, np.ndarray], before: np.ndarray,
           after_of: Callable[[np.ndarray], tuple[np.ndarray, Any]],
           weights: np.ndarray) -> dict:
    """Held-out errors: ``after_of(train_mask) -> (model H, params)`` is fitted on one fold of lines and
    scored on the other, both ways (as :mod:`analysis.diagnosis.verdict`). ``measured``/``before`` may be
    one array or a (before-measured, after-measured) pair for the exclusion effects."""
    m_b, m_a = measured if isinstance(measured, tuple) else (measured, measured)
    b, a = held_out_errors(m_b, before, np.broadcast_to(weights, m_b.shape), lambda train: after_of(train)[0], m_a)
    bd, ad, z = held_out_db(b, a)
    return {"error_before_db": bd, "error_after_db": ad, "gain_db": bd - ad, "z": z}


def _fit_nonlinearity(spec: HitSpectraSet, peaks: np.ndarray, base: ModalModel, measured: np.ndarray,
                      weights: np.ndarray, lines: np.ndarray, k0: float) -> tuple[np.ndarray, float]:
    """k (1/N) minimising the weighted error of the predicted H1 on ``lines``: a grid around the start
    ``k0`` (from the peak shift between force levels) and a bounded Brent search around the best."""
    G = spec.Gff / np.sum(spec.Gff, axis=0, keepdims=True)

    def pred(k: float) -> np.ndarray:
        H = np.zeros(measured.shape, complex)
        for g, p in zip(G, peaks):
            H += g[None, None, :] * windowed_accelerance(base, spec.freq_hz, spec.exp_window_tau_s, 1.0 - k * p)
        return H

    def cost(k: float) -> float:
        if np.any(1.0 - k * peaks <= 0.5):
            return np.inf
        e = measured[..., lines] - pred(k)[..., lines]
        return float(np.sum(weights[..., lines] * np.abs(e) ** 2))

    span = max(abs(k0), 0.002 / float(np.max(peaks)))
    grid = np.concatenate([[0.0], k0 + span * np.linspace(-0.6, 0.6, 13)])
    costs = [cost(k) for k in grid]
    kb = float(grid[int(np.argmin(costs))])
    step = 0.1 * span
    res = minimize_scalar(cost, bounds=(kb - step, kb + step), method="bounded", options={"xatol": 1e-4 * span})
    k = float(res.x) if res.fun <= min(costs) else kb
    return pred(k), k


def diagnose_time_effects(
    force: np.ndarray,
    responses: np.ndarray,
    fs_hz: float,
    base: ModalModel,
    band: Sequence[float],
    *,
    full_scale: Sequence[float] | None = None,
    overload_flags: np.ndarray | None = None,
    exp_window_end_fraction: float = 1e-3,
    outputs: Sequence[str] | None = None,
    reference: str = "",
    rule: DecisionRule = DEFAULT_RULE,
) -> dict:
    """The time-data effects of a set of hits at one reference, each with its held-out gain (module
    docs and ``docs/diagnosis.md``).

    force (n_hits, n) N; responses (n_hits, n_out, n) m/s^2; base: the linear simulation as a receptance
    pole-residue model at (outputs, reference) (e.g. ``FrameModel.modal_model(..., "receptance")``);
    band (lo, hi) Hz. The measured FRF is H1 of all hits with an exponential window (``exp_window_end_fraction`` at the
    block end, force and responses); the simulation is :func:`windowed_accelerance`. Per effect:

    * ``amplitude_nonlinearity`` (model): H1 predicted as ``sum_i G_ff,i H(f; 1 - k F_pk,i) / sum_i G_ff,i``;
      k (1/N) fitted on one fold of lines, scored on the other;
    * ``input_noise`` (model): ``H_sim * max(sum G_ff - sum G_nn, 0) / sum G_ff`` with ``G_nn`` the
      expected spectrum of the pre-trigger noise sigma through the windows (sigma from the time data,
      so no line is used to fit it);
    * ``overload`` (data quality): H1 of the hits without the overloaded ones against H1 of all hits;
    * ``double_hit`` (data quality): the same with a force window of ``FORCE_WINDOW_S`` after each
      pulse start (a double hit harms H1 only when the force window cuts the second pulse).

    Returns ``{"verdict", "causes", "error_before_db", "error_after_db", "exp_window_tau_s", "n_hits"}``; each cause
    has ``effect, kind, parameters, present, significant, gain_db, error_before_db, error_after_db, z,
    evidence``. A cause counts when its detector finds it and (model effects) its gain is significant
    by the one rule of the diagnosis (:meth:`analysis.diagnosis.rule.DecisionRule.significant` of ``rule``:
    ``gain >= min_gain_db`` and (``z >= z_min`` or ``gain >= strong_gain_db``)); the verdict is the
    counted cause with the largest gain, else ``none``.
    """
    f = _check_hits(force)
    x = np.asarray(responses, float)
    if x.ndim == 2:
        x = x[:, None, :]
    n_hits, n = f.shape
    if x.shape[0] != n_hits or x.shape[2] != n:
        raise ValueError(f"responses {x.shape} do not match force {f.shape}: need (n_hits, n_out, n)")
    if base.residues.shape[0] != x.shape[1] or base.residues.shape[1] != 1:
        raise ValueError(f"the simulation has {base.residues.shape[:2]} (outputs, references) but the hits "
                         f"have {x.shape[1]} responses at one reference; build it at the hits' points")
    spec = hit_spectra_set(f, x, fs_hz, band, exp_window_end_fraction=exp_window_end_fraction)
    Hm = spec.h1()[:, None, :]
    sim = windowed_accelerance(base, spec.freq_hz, spec.exp_window_tau_s)
    w = noise_weights(spec, Hm, n, fs_hz)
    causes = []

    def significant(s: dict) -> bool:
        return rule.significant(s["gain_db"], s["z"])

    # amplitude nonlinearity
    peaks = np.abs(f).max(axis=1)
    det = detect_amplitude_nonlinearity(f, x, fs_hz, band)
    params = dict(det["parameters"])
    if "peaks_hz" in params and params.get("df_percent"):
        lv = params["force_levels_n"]
        k0 = -params["mean_df_percent"] / 100.0 / (lv[1] - lv[0])
        s = _score(Hm, sim, lambda tr: _fit_nonlinearity(spec, peaks, base, Hm, w, tr, k0), w)
        _, k = _fit_nonlinearity(spec, peaks, base, Hm, w, np.ones(spec.freq_hz.size, bool), k0)
        params["k_per_n"] = k
        ev = det["evidence"] + (f"; softening k = {k:.3g} 1/N (frequencies x (1 - k F_pk))" if k > 0 else
                                f"; hardening k = {k:.3g} 1/N (frequencies x (1 - k F_pk))")
    else:
        s = {"error_before_db": db(float(np.mean(w * np.abs(Hm - sim) ** 2))), "z": 0.0, "gain_db": 0.0}
        s["error_after_db"] = s["error_before_db"]
        ev = det["evidence"]
    causes.append({"effect": "amplitude_nonlinearity", "kind": "model", "parameters": params,
                   "present": bool(det["present"]), **s, "significant": significant(s), "evidence": ev})

    # input noise
    det = detect_input_noise(f, fs_hz, band)
    sigma = float(det["parameters"]["noise_rms_n"])
    Gnn = _noise_psd(spec, sigma, n, fs_hz)
    ratio = np.clip((np.sum(spec.Gff, 0) - np.sum(Gnn, 0)) / np.sum(spec.Gff, 0), 0.0, 1.0)
    Hn = sim * ratio[None, None, :]
    s = _score(Hm, sim, lambda tr: (Hn, sigma), w)
    params = dict(det["parameters"], h1_bias_db_min=db(max(float(ratio.min()), 1e-12)))
    causes.append({"effect": "input_noise", "kind": "model", "parameters": params, "present": bool(det["present"]),
                   **s, "significant": significant(s),
                   "evidence": det["evidence"] + f"; re-simulated H1 bias gains {s['gain_db']:.2f} dB on held-out lines"})

    # overload (exclusion)
    data = np.concatenate([f[:, None, :], x], axis=1)
    if full_scale is not None or overload_flags is not None:
        det = detect_overload(data, full_scale, overload_flags)
        bad = np.zeros(n_hits, bool)
        bad[det["parameters"]["hits"]] = True
        s = _exclusion(Hm, spec, bad, sim, w)
        causes.append({"effect": "overload", "kind": "data_quality", "parameters": dict(det["parameters"], full_scale=(
            None if full_scale is None else [float(v) for v in full_scale])), "present": bool(det["present"]), **s,
            "significant": significant(s), "evidence": det["evidence"] + _excl_text(s, bad)})

    # double hit (exclusion, with a force window)
    det = detect_double_hit(f, fs_hz)
    bad = np.zeros(n_hits, bool)
    bad[det["parameters"]["hits"]] = True
    spec_fw = hit_spectra_set(f, x, fs_hz, band, exp_window_end_fraction=exp_window_end_fraction, force_width_s=FORCE_WINDOW_S,
                              force_taper_s=FORCE_TAPER_S)
    Hfw = spec_fw.h1()[:, None, :]
    s = _exclusion(Hfw, spec_fw, bad, sim, w)
    causes.append({"effect": "double_hit", "kind": "data_quality", "parameters": det["parameters"],
                   "present": bool(det["present"]), **s, "significant": significant(s),
                   "evidence": det["evidence"] + _excl_text(s, bad, " (force window "
                                                           f"{1e3 * FORCE_WINDOW_S:.3g} ms)")})

    for c in causes:
        c["counts"] = bool(c["present"] and (c["significant"] or c["kind"] == "data_quality"))
    causes.sort(key=lambda c: (not c["counts"], -c["gain_db"]))
    verdict = causes[0]["effect"] if causes[0]["counts"] else "none"
    before = db(float(np.mean(w * np.abs(Hm - sim) ** 2)))
    after = causes[0]["error_after_db"] if verdict != "none" else before
    return {"verdict": verdict, "causes": causes, "error_before_db": before, "error_after_db": after,
            "exp_window_tau_s": spec.exp_window_tau_s, "n_hits": n_hits, "band_hz": [float(band[0]), float(band[1])]}



def _exclusion(H_all: np.ndarray, spec: HitSpectraSet, bad: np.ndarray, sim: np.ndarray, w: np.ndarray) -> dict:
    """Held-out gain of excluding the ``bad`` hits: H1 of all hits against H1 of the others, both
    compared with the simulation (no line is used to choose the hits, so every line is held out)."""
    if not bad.any() or bad.all():
        e = db(float(np.mean(w * np.abs(H_all - sim) ** 2)))
        return {"error_before_db": e, "error_after_db": e, "gain_db": 0.0, "z": 0.0}
    H_keep = spec.h1(~bad)[:, None, :]
    return _score((H_all, H_keep), sim, lambda tr: (sim, None), w)


def _excl_text(s: dict, bad: np.ndarray, extra: str = "") -> str:
    if not bad.any():
        return ""
    return (f"; excluding those {int(bad.sum())} hits{extra} changes the held-out error "
            f"{s['error_before_db']:.1f} -> {s['error_after_db']:.1f} dB (gain {s['gain_db']:.2f} dB)")
