"""Mains interference: lines at the harmonics of 50/60 Hz (single lines when synchronous with the
record, or broadened), their fit and their cross-validation by harmonics."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from ..frf import FRFSet, line_spacing_hz
from .effect_types import EffectError, FitContext
from .effect_types import check_positive as _check_positive

__all__ = ["HUM_BASES_HZ", "hum_kernels", "default_hum_width", "apply_mains_hum", "fit_mains_hum",
           "held_out_mains_hum", "held_out_by_harmonics"]

HUM_BASES_HZ = (50.0, 60.0)
#: Largest departure of the mains frequency from its nominal value that is looked for (Hz): grids hold
#: their frequency within about +-0.2 Hz; a wider search would let a "mains line" sit on a structural mode.
MAX_OFFSET_HZ = 0.2
#: Line shapes of mains lines with a width (see :func:`hum_kernels`).
LINE_SHAPES = ("lorentzian", "sinc")
#: A line's kernel is cut off this many widths from its centre.
TAIL_WIDTHS = 6.0


def hum_kernels(freq_hz: np.ndarray, base_hz: float, width_hz: float,
                shape: str = "lorentzian") -> tuple[np.ndarray, np.ndarray]:
    """(harmonic frequencies (Hz), kernels (n_harm, n_freq)) of the mains lines at the harmonics of
    ``base_hz``.

    ``width_hz = 0``: interference synchronous with the record, on the one line nearest each harmonic
    (kernel 1 there, 0 elsewhere; harmonics more than half a line outside the lines are dropped).
    ``width_hz > 0``: a line with a width, of ``shape`` "lorentzian" ``1/(1 + j x)`` (a decaying or
    drifting tone) or "sinc" ``sin(pi x)/(pi x)`` (a steady tone off the line grid, leaked by the
    record's rectangular window), ``x = (f - fk)/width``; either is cut off beyond ``TAIL_WIDTHS``
    widths from its centre, so a line's amplitude is fitted to the lines around it and not to the
    broad structure of the whole band."""
    f = np.asarray(freq_hz, float)
    fk = base_hz * np.arange(1, int(f[-1] // base_hz) + 1)
    if width_hz == 0:
        df = line_spacing_hz(f)
        fk = fk[(fk >= f[0] - df / 2) & (fk <= f[-1] + df / 2)]
        K = np.zeros((fk.size, f.size), complex)
        K[np.arange(fk.size), np.argmin(np.abs(f[None, :] - fk[:, None]), axis=1)] = 1.0
        return fk, K
    if shape not in LINE_SHAPES:
        raise EffectError(f"mains_hum: shape must be one of {', '.join(LINE_SHAPES)}; got {shape!r}")
    fk = fk[fk >= f[0] - 2 * width_hz]
    x = (f[None, :] - fk[:, None]) / width_hz
    K = 1.0 / (1 + 1j * x) if shape == "lorentzian" else np.sinc(x).astype(complex)
    return fk, np.where(np.abs(x) <= TAIL_WIDTHS, K, 0.0)


def default_hum_width(spacing_hz: float) -> float:
    """Line width (Hz) of the hum model: two line spacings (``spacing_hz``: the FRFs'
    :attr:`~analysis.frf.FRFSet.line_spacing_hz`)."""
    return 2.0 * float(spacing_hz)


def _on_harmonics(A: np.ndarray, given_hz: np.ndarray, fk: np.ndarray, frfs: tuple) -> np.ndarray:
    """Amplitudes ``A`` (n_out, n_ref, len(given_hz), 2) of the harmonics ``given_hz`` (Hz) placed on the
    harmonics ``fk`` of another band: a harmonic the fit did not see has no amplitude, one outside the band
    is dropped."""
    if A.shape != tuple(frfs) + (given_hz.size, 2):
        raise EffectError(f"mains_hum: amplitudes must have shape {tuple(frfs) + (given_hz.size, 2)} "
                          f"(outputs, references, harmonics_hz {list(given_hz)}, [re, im]); got {A.shape}")
    out = np.zeros(tuple(frfs) + (fk.size, 2))
    for i, h in enumerate(given_hz):
        j = np.flatnonzero(np.abs(fk - h) <= 1e-9 * max(abs(h), 1.0))
        if j.size:
            out[..., j[0], :] = A[..., i, :]
    return out


def apply_mains_hum(frf: FRFSet, params: Mapping) -> FRFSet:
    """Add lines at the harmonics of ``base_hz``: ``amplitudes[o][r][k] = [re, im]`` (FRF units), one per
    harmonic in the FRFs' band, or one per harmonic of ``harmonics_hz`` (Hz; the fit's band) when given
    (then a harmonic of this band the fit did not see has none)."""
    f0 = _check_positive("base_hz", params.get("base_hz"), "mains_hum") + float(params.get("offset_hz", 0.0))
    w = params.get("width_hz")
    width = default_hum_width(frf.line_spacing_hz) if w is None else float(w)
    if not (np.isfinite(width) and width >= 0):
        raise EffectError(f"mains_hum: width_hz must be >= 0 (0: single lines), got {w!r}")
    fk, K = hum_kernels(frf.freq_hz, f0, width, str(params.get("shape", "lorentzian")))
    A = np.asarray(params.get("amplitudes"), float)
    given = params.get("harmonics_hz")
    if given is not None:
        A = _on_harmonics(A, np.asarray(given, float), fk, frf.H.shape[:2])
    if A.shape != frf.H.shape[:2] + (fk.size, 2):
        raise EffectError(f"mains_hum: amplitudes must have shape {frf.H.shape[:2] + (fk.size, 2)} "
                          f"(outputs, references, harmonics {list(fk)}, [re, im]); got {A.shape}")
    Ac = A[..., 0] + 1j * A[..., 1]
    return replace(frf, H=frf.H + np.einsum("ork,kf->orf", Ac, K))


def _hum_amplitudes(ctx: FitContext, E: np.ndarray, K: np.ndarray, lines: np.ndarray) -> tuple[np.ndarray, float]:
    """Weighted least-squares amplitudes (n_out, n_ref, n_harm, [re, im]) of the kernels ``K`` fitted to
    the error ``E`` on ``lines``, and the remaining weighted cost."""
    no, nr = E.shape[:2]
    A = np.zeros((no, nr, K.shape[0], 2))
    total = 0.0
    Kl = K[:, lines]
    for o in range(no):
        for r in range(nr):
            sw = np.sqrt(ctx.weights[o, r, lines])
            M = (Kl * sw).T
            x, *_ = np.linalg.lstsq(M, E[o, r, lines] * sw, rcond=None)
            A[o, r, :, 0], A[o, r, :, 1] = x.real, x.imag
            total += float(np.sum(np.abs(E[o, r, lines] * sw - M @ x) ** 2))
    return A, total


def _hum_candidates(df: float) -> list[tuple[float, float, float, str]]:
    """(mains base Hz, offset Hz, width Hz, shape) tried: 50 and 60 Hz, offsets up to
    +-``MAX_OFFSET_HZ``, single lines (synchronous, width 0) and lines two lines wide of both shapes
    (Lorentzian, sinc); ``df``: the FRFs' line spacing (Hz)."""

    def offsets(step: float) -> np.ndarray:     # 0, +-1, +-2, ... steps, up to and just past the limit
        k = np.arange(1, int(np.ceil(MAX_OFFSET_HZ / step - 1e-9)) + 1) * step
        return np.concatenate([[0.0], np.ravel(np.column_stack([k, -k]))])

    # single lines sit on the bins nearest k (base + offset): finer steps (1/32 line) find the offset
    # that puts every harmonic on its bin; a line with a width moves smoothly, 1/8 line is enough
    out = [(b, float(o), 0.0, "line") for b in HUM_BASES_HZ for o in offsets(df / 32)]
    width = default_hum_width(df)
    return out + [(b, float(o), width, s) for b in HUM_BASES_HZ for s in LINE_SHAPES for o in offsets(df / 8)]


def _fit_candidate(ctx: FitContext, E: np.ndarray, lines: np.ndarray, f0_hz: float, width_hz: float,
                   shape: str) -> tuple[np.ndarray, float, int] | None:
    """Amplitudes, remaining weighted cost and number of harmonics fitted for mains lines at the
    harmonics of ``f0_hz`` on ``lines``; None when no harmonic can be fitted there. A harmonic is
    fitted only where lines within its width are given: its tails alone would fit noise."""
    f, df = ctx.measured.freq_hz, ctx.measured.line_spacing_hz
    fk, K = hum_kernels(f, f0_hz, width_hz, shape)
    seen = np.array([np.any(lines & (np.abs(f - x) <= max(width_hz, df / 2))) for x in fk], bool)
    if not seen.any():
        return None
    A, total = _hum_amplitudes(ctx, E, np.where(seen[:, None], K, 0.0), lines)
    return A, total, int(seen.sum())


def fit_mains_hum(ctx: FitContext, lines: np.ndarray) -> dict:
    """Base (50/60 Hz), offset, line shape and per-harmonic amplitudes: the candidate of
    :func:`_hum_candidates` with the least weighted cost on ``lines`` (the amplitudes are linear); an
    offset or a line width must pay for itself (the cost of fitting noise with them)."""
    f = ctx.measured.freq_hz
    E = ctx.measured.H - ctx.sim.H
    best = None
    # a candidate less simple than the best so far (offset, then line width) must lower the cost by more
    # than fitting noise would: 4 x the typical line's cost per harmonic and FRF
    line_cost = float(np.median(ctx.weights[..., lines] * np.abs(E[..., lines]) ** 2))
    n_frf = E.shape[0] * E.shape[1]
    tried: list[tuple[float, float, float, str, float]] = []
    for base, off, width, shape in _hum_candidates(ctx.measured.line_spacing_hz):
        fitted = _fit_candidate(ctx, E, lines, base + off, width, shape)
        if fitted is None:
            continue
        A, total, n_seen = fitted
        tried.append((base, off, width, shape, total))
        complexity = (off != 0.0) + (width != 0.0)
        if best is None or total + 4 * line_cost * n_frf * n_seen * max(complexity - best[5], 0) < best[0]:
            best = (total, base, off, width, A, complexity, shape)
    if best is None:
        return {"base_hz": 50.0, "offset_hz": 0.0, "width_hz": default_hum_width(ctx.measured.line_spacing_hz),
                "shape": "lorentzian", "amplitudes": np.zeros(ctx.measured.H.shape[:2] + (0, 2)).tolist(), "harmonics_hz": []}
    off = best[2]
    if best[3] == 0.0 and off != 0.0:
        # single lines: the offsets that put the lines with interference on the same bins fit alike, up to
        # noise (lines without interference that one offset reaches and another does not); take the middle
        # of that run of offsets (the best guess of the true one), not the one nearest zero, so that the
        # harmonics not fitted here are predicted on the right bins
        tol = 2.0 * line_cost * n_frf
        same = sorted(o for b, o, w, _, t in tried if b == best[1] and w == 0.0 and t <= best[0] + tol)
        off = same[len(same) // 2]
        refit = _fit_candidate(ctx, E, lines, best[1] + off, 0.0, "line")
        assert refit is not None          # the run holds the best offset, whose harmonics were seen
        best = best[:4] + (refit[0],) + best[5:]
    shape = best[6] if best[3] else "line"
    fk = hum_kernels(f, best[1] + off, best[3], shape)[0]
    return {"base_hz": best[1], "offset_hz": off, "width_hz": best[3], "shape": shape,
            "amplitudes": best[4].tolist(), "harmonics_hz": [float(x) for x in fk]}


def held_out_mains_hum(ctx: FitContext) -> tuple[np.ndarray, np.ndarray]:
    """The cross-validation of ``mains_hum``: by harmonics (:func:`held_out_by_harmonics`), for single
    lines and lines with a width alike (neighbouring lines of a line with a width are not independent,
    so interleaved folds would let a fold fit what it is scored on)."""
    return held_out_by_harmonics(ctx)


def held_out_by_harmonics(ctx: FitContext) -> tuple[np.ndarray, np.ndarray]:
    """Cross-validation of mains lines by harmonics, not by interleaved lines (interference on single
    lines is invisible to a fold that does not hold those lines, and its amplitudes are free per
    harmonic): the harmonics are split into odd and even ones; the line shape, base and offset are
    fitted with the lines near the other fold's harmonics left out, and must *predict where* the
    held-out harmonics lie and their line shape; only their amplitudes are then fitted on the lines
    next to them (the training harmonics' on the training lines), and the line shapes' tails are
    predicted on every line. Every line is scored (before, after) in each fold: a model that only
    removes the noise of the few lines it points at gains about ``4.34 n_harm / n_lines`` dB
    (hundredths), while interference at the predicted lines gives tens of dB."""
    m = ctx.measured
    f, df = m.freq_hz, m.line_spacing_hz
    E = m.H - ctx.sim.H
    w_all = ctx.weights
    before, after = [], []
    for parity in (0, 1):
        # the held-out harmonics' neighbourhoods (both mains bases) are left out of the fit
        near = np.zeros(f.size, bool)
        for b in HUM_BASES_HZ:
            k = np.arange(1, int(f[-1] // b) + 2)
            for fh in b * k[(k % 2) == parity]:
                near |= np.abs(f - fh) <= 0.6 + 2 * df
        params = fit_mains_hum(ctx, ~near)
        fk, K = hum_kernels(f, params["base_hz"] + params["offset_hz"], params["width_hz"], params["shape"])
        order = np.rint(fk / params["base_hz"]).astype(int)
        test_k = (order % 2) == parity
        if not test_k.any():
            before.append((w_all * np.abs(E) ** 2).ravel())
            after.append((w_all * np.abs(E) ** 2).ravel())
            continue
        R = E.copy()
        # the training harmonics' amplitudes from the training lines, the held-out harmonics' from the
        # lines next to them; each line shape's tails are then predicted on every line
        for sel, on in ((~test_k, ~near), (test_k, np.any(np.abs(K[test_k]) > 1e-3, axis=0) & near)):
            if sel.any() and on.any():
                A, _ = _hum_amplitudes(ctx, E, K[sel], on)
                R = R - np.einsum("ork,kf->orf", A[..., 0] + 1j * A[..., 1], K[sel])
        before.append((w_all * np.abs(E) ** 2).ravel())
        after.append((w_all * np.abs(R) ** 2).ravel())
    return np.concatenate(before), np.concatenate(after)
