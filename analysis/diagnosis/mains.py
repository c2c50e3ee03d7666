"""Mains interference: lines at the harmonics of 50/60 Hz (single lines when synchronous with the
record, or broadened), their fit and their cross-validation by harmonics."""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace

import numpy as np

from ..frf import FRFSet, line_spacing_hz
from ..modal import ModalModel
from .effect_types import EffectError, FitContext
from .effect_types import check_positive as _check_positive
from .rule import held_out_db

__all__ = ["HUM_BASES_HZ", "hum_kernels", "mains_hum_applies", "default_hum_width", "apply_mains_hum", "fit_mains_hum",
           "held_out_mains_hum", "held_out_by_harmonics", "carried_by_one_harmonic", "half_power_mode", "off_the_mode"]

HUM_BASES_HZ = (50.0, 60.0)
#: Largest departure of the mains frequency from its nominal value that is looked for (Hz): grids hold
#: their frequency within about +-0.2 Hz; a wider search would let a "mains line" sit on a structural mode.
MAX_OFFSET_HZ = 0.2
#: Line shapes of mains lines with a width (see :func:`hum_kernels`).
LINE_SHAPES = ("lorentzian", "sinc")
#: A line's kernel is cut off this many widths from its centre.
TAIL_WIDTHS = 6.0


def _harmonics(f: np.ndarray, base_hz: float, width_hz: float, df: float) -> np.ndarray:
    """The harmonics (Hz) of ``base_hz`` that have lines on the axis ``f`` (spacing ``df`` Hz) in
    :func:`hum_kernels`."""
    fk = base_hz * np.arange(1, int(f[-1] // base_hz) + 1)
    if width_hz == 0:
        return fk[(fk >= f[0] - df / 2) & (fk <= f[-1] + df / 2)]
    return fk[fk >= f[0] - 2 * width_hz]


def _local_kernels(f: np.ndarray, fk: np.ndarray, width_hz: float, shape: str,
                   df: float) -> tuple[np.ndarray, np.ndarray]:
    """The kernels of :func:`hum_kernels` on the lines near each harmonic only: (line indices (n_harm,
    n_near), kernel values (n_harm, n_near)), an index repeated with value 0 where a harmonic's window runs
    past the axis. The kernels are zero on every other line, so a fit need not look at them: its cost then
    scales with the number of harmonics, not of lines."""
    if width_hz == 0:
        i = np.clip(np.searchsorted(f, fk), 1, f.size - 1)
        i = np.where(np.abs(f[i - 1] - fk) <= np.abs(f[i] - fk), i - 1, i)   # the nearest line, the lower on a tie
        return i[:, None], np.ones((fk.size, 1), complex)
    if shape not in LINE_SHAPES:
        raise EffectError(f"mains_hum: shape must be one of {', '.join(LINE_SHAPES)}; got {shape!r}")
    reach = TAIL_WIDTHS * width_hz
    n = int(np.ceil(2 * reach / df)) + 3
    lo = np.searchsorted(f, fk - reach) - 1
    raw = lo[:, None] + np.arange(n)[None, :]
    idx = np.clip(raw, 0, f.size - 1)
    x = (f[idx] - fk[:, None]) / width_hz
    K = 1.0 / (1 + 1j * x) if shape == "lorentzian" else np.sinc(x).astype(complex)
    return idx, np.where((np.abs(x) <= TAIL_WIDTHS) & (raw == idx), K, 0.0)


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
    if width_hz != 0 and shape not in LINE_SHAPES:
        raise EffectError(f"mains_hum: shape must be one of {', '.join(LINE_SHAPES)}; got {shape!r}")
    df = line_spacing_hz(f)
    fk = _harmonics(f, base_hz, width_hz, df)
    K = np.zeros((fk.size, f.size), complex)
    if fk.size:
        idx, Kl = _local_kernels(f, fk, width_hz, shape, df)
        np.add.at(K, (np.arange(fk.size)[:, None], idx), Kl)    # a repeated index (past the axis) adds 0
    return fk, K


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


def mains_hum_applies(ctx: FitContext) -> str:
    """Why mains lines cannot act on the measured band ("" when they can): no harmonic of any mains base
    (:data:`HUM_BASES_HZ`, up to :data:`MAX_OFFSET_HZ` off nominal) lies on the band's lines or just below
    them, where a line with a width would still reach in (a shaker's band of 2-15 Hz holds none)."""
    f = np.asarray(ctx.measured.freq_hz, float)
    if f.size < 2:
        return f"the band has {f.size} line(s)"
    lo, hi = f[0] - 2 * default_hum_width(line_spacing_hz(f)), f[-1] + line_spacing_hz(f) / 2
    for b in HUM_BASES_HZ:
        k = np.arange(1, int(hi // (b - MAX_OFFSET_HZ)) + 1)
        if np.any((k * (b + MAX_OFFSET_HZ) >= lo) & (k * (b - MAX_OFFSET_HZ) <= hi)):
            return ""
    return (f"no mains harmonic ({' or '.join(f'{b:g}' for b in HUM_BASES_HZ)} Hz and their multiples) lies in "
            f"the band {f[0]:.4g}-{f[-1]:.4g} Hz")


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
    if A.size == 0:                     # no harmonic: JSON's nested empty lists lose the last axis
        A = A.reshape(frf.H.shape[:2] + (0, 2)) if A.ndim >= 2 and A.shape[:2] == frf.H.shape[:2] else A
    given = params.get("harmonics_hz")
    if given is not None:
        A = _on_harmonics(A, np.asarray(given, float), fk, frf.H.shape[:2])
    if A.shape != frf.H.shape[:2] + (fk.size, 2):
        raise EffectError(f"mains_hum: amplitudes must have shape {frf.H.shape[:2] + (fk.size, 2)} "
                          f"(outputs, references, harmonics {list(fk)}, [re, im]); got {A.shape}")
    Ac = A[..., 0] + 1j * A[..., 1]
    return replace(frf, H=frf.H + np.einsum("ork,kf->orf", Ac, K))


def _lstsq_amplitudes(W: np.ndarray, E: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, float]:
    """Weighted least-squares amplitudes (n_out, n_ref, n_harm, [re, im]) of the kernels ``K`` (n_harm,
    n_lines) fitted per FRF to the error ``E`` with weights ``W`` (n_out, n_ref, n_lines), and the remaining
    weighted cost on those lines."""
    no, nr = E.shape[:2]
    A = np.zeros((no, nr, K.shape[0], 2))
    total = 0.0
    for o in range(no):
        for r in range(nr):
            sw = np.sqrt(W[o, r])
            M = (K * sw).T
            x, *_ = np.linalg.lstsq(M, E[o, r] * sw, rcond=None)
            A[o, r, :, 0], A[o, r, :, 1] = x.real, x.imag
            total += float(np.sum(np.abs(E[o, r] * sw - M @ x) ** 2))
    return A, total


def _hum_amplitudes(ctx: FitContext, E: np.ndarray, K: np.ndarray, lines: np.ndarray) -> tuple[np.ndarray, float]:
    """Weighted least-squares amplitudes (n_out, n_ref, n_harm, [re, im]) of the kernels ``K`` fitted to
    the error ``E`` on ``lines``, and the remaining weighted cost."""
    return _lstsq_amplitudes(ctx.weights[..., lines], E[..., lines], K[:, lines])


class _Search:
    """What every candidate of one mains search shares (computed once): the axis ``f`` (Hz), its spacing
    ``df`` (Hz), the error ``E``, the weights with the lines outside ``lines`` set to zero, the error's
    weighted cost on ``lines`` and the running count of ``lines`` (whether a harmonic has lines near it)."""

    def __init__(self, ctx: FitContext, E: np.ndarray, lines: np.ndarray) -> None:
        self.f = np.asarray(ctx.measured.freq_hz, float)
        self.df = line_spacing_hz(self.f)
        self.E = E
        self.W = np.where(lines, ctx.weights, 0.0)
        self.cost = float(np.sum(self.W * (E.real ** 2 + E.imag ** 2)))
        self.count = np.concatenate([[0], np.cumsum(lines)])
        self.lines = lines

    def seen(self, fk: np.ndarray, reach_hz: float) -> np.ndarray:
        """Per harmonic ``fk`` (Hz), whether a line of ``lines`` lies within ``reach_hz`` of it."""
        f = self.f
        n = int(np.ceil(2 * reach_hz / self.df)) + 3
        raw = (np.searchsorted(f, fk - reach_hz) - 1)[:, None] + np.arange(n)[None, :]
        idx = np.clip(raw, 0, f.size - 1)
        return np.any(self.lines[idx] & (raw == idx) & (np.abs(f[idx] - fk[:, None]) <= reach_hz), axis=1)


def _local_fit(search: _Search, idx: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, float]:
    """:func:`_hum_amplitudes` of kernels given on the lines near their harmonics only (``idx``, ``K`` of
    :func:`_local_kernels`): the lines no kernel reaches keep their error, so only the kernels' lines are
    solved. Kernels on lines of their own (the usual case: harmonics tens of Hz apart) are solved in closed
    form, all FRFs at once; kernels that share lines by least squares on the lines they reach."""
    nz = idx[K != 0]
    E, W = search.E[..., idx], search.W[..., idx]           # (n_out, n_ref, n_harm, n_near)
    no, nr = search.E.shape[:2]
    if np.unique(nz).size == nz.size:
        num = np.sum(W * np.conj(K) * E, axis=-1)
        den = np.sum(W * (K.real ** 2 + K.imag ** 2), axis=-1)
        ok = den > 0
        x = np.where(ok, num / np.where(ok, den, 1.0), 0.0)
        gain = np.where(ok, (num.real ** 2 + num.imag ** 2) / np.where(ok, den, 1.0), 0.0)
        return np.stack([x.real, x.imag], axis=-1), search.cost - float(np.sum(gain))
    cols = np.unique(idx)
    Kc = np.zeros((K.shape[0], cols.size), complex)
    np.add.at(Kc, (np.arange(K.shape[0])[:, None], np.searchsorted(cols, idx)), K)
    Wc, Ec = search.W[..., cols], search.E[..., cols]
    A, rest = _lstsq_amplitudes(Wc, Ec, Kc)
    return A, search.cost - float(np.sum(Wc * (Ec.real ** 2 + Ec.imag ** 2))) + rest


def _hum_candidates(f: np.ndarray) -> list[tuple[float, float, float, str]]:
    """(mains base Hz, offset Hz, width Hz, shape) tried: 50 and 60 Hz, offsets up to
    +-``MAX_OFFSET_HZ``, single lines (synchronous, width 0) and lines two lines wide of both shapes
    (Lorentzian, sinc)."""
    df = line_spacing_hz(f)

    def offsets(step: float) -> np.ndarray:     # 0, +-1, +-2, ... steps, up to and just past the limit
        k = np.arange(1, int(np.ceil(MAX_OFFSET_HZ / step - 1e-9)) + 1) * step
        return np.concatenate([[0.0], np.ravel(np.column_stack([k, -k]))])

    # single lines sit on the bins nearest k (base + offset): finer steps (1/32 line) find the offset
    # that puts every harmonic on its bin; a line with a width moves smoothly, 1/8 line is enough
    out = [(b, float(o), 0.0, "line") for b in HUM_BASES_HZ for o in offsets(df / 32)]
    width = default_hum_width(line_spacing_hz(f))
    return out + [(b, float(o), width, s) for b in HUM_BASES_HZ for s in LINE_SHAPES for o in offsets(df / 8)]


def _fit_candidate(search: _Search, f0_hz: float, width_hz: float,
                   shape: str) -> tuple[np.ndarray, float, int] | None:
    """Amplitudes, remaining weighted cost and number of harmonics fitted for mains lines at the
    harmonics of ``f0_hz`` on the search's lines; None when no harmonic can be fitted there. A harmonic is
    fitted only where lines within its width are given: its tails alone would fit noise. Only the lines
    near the harmonics are looked at (:func:`_local_kernels`)."""
    f, df = search.f, search.df
    fk = _harmonics(f, f0_hz, width_hz, df)
    if fk.size == 0:
        return None
    seen = search.seen(fk, max(width_hz, df / 2))
    if not seen.any():
        return None
    idx, K = _local_kernels(f, fk, width_hz, shape, df)
    A, total = _local_fit(search, idx, np.where(seen[:, None], K, 0.0))
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
    search = _Search(ctx, E, lines)
    for base, off, width, shape in _hum_candidates(f):
        fitted = _fit_candidate(search, base + off, width, shape)
        if fitted is None:
            continue
        A, total, n_seen = fitted
        tried.append((base, off, width, shape, total))
        complexity = (off != 0.0) + (width != 0.0)
        if best is None or total + 4 * line_cost * n_frf * n_seen * max(complexity - best[5], 0) < best[0]:
            best = (total, base, off, width, A, complexity, shape)
    if best is None:
        return {"base_hz": 50.0, "offset_hz": 0.0, "width_hz": default_hum_width(line_spacing_hz(f)), "shape": "lorentzian",
                "amplitudes": np.zeros(ctx.measured.H.shape[:2] + (0, 2)).tolist(), "harmonics_hz": []}
    off = best[2]
    if best[3] == 0.0 and off != 0.0:
        # single lines: the offsets that put the lines with interference on the same bins fit alike, up to
        # noise (lines without interference that one offset reaches and another does not); take the middle
        # of that run of offsets (the best guess of the true one), not the one nearest zero, so that the
        # harmonics not fitted here are predicted on the right bins
        tol = 2.0 * line_cost * n_frf
        same = sorted(o for b, o, w, _, t in tried if b == best[1] and w == 0.0 and t <= best[0] + tol)
        off = same[len(same) // 2]
        refit = _fit_candidate(search, best[1] + off, 0.0, "line")
        assert refit is not None          # the run holds the best offset, whose harmonics were seen
        best = best[:4] + (refit[0],) + best[5:]
    shape = best[6] if best[3] else "line"
    fk = _harmonics(f, best[1] + off, best[3], search.df)
    return {"base_hz": best[1], "offset_hz": off, "width_hz": best[3], "shape": shape,
            "amplitudes": best[4].tolist(), "harmonics_hz": [float(x) for x in fk]}


#: Half-width (lines) of the neighbourhood whose median error is a line's noise in :func:`_fit_penalty`.
NOISE_HALF_WIDTH_LINES = 25


def _fit_penalty(err: np.ndarray, noise_lines: np.ndarray, on: np.ndarray, n_params: int) -> np.ndarray:
    """Per line, what a fit of ``n_params`` complex amplitudes to the lines ``on`` (mask) and scored on them
    owes to be a prediction: under noise alone its residual is ``(n - p) sigma^2`` and a prediction's error
    ``(n + p) sigma^2``, so ``2 p sigma^2`` is added, spread over the ``n`` lines (Mallows' Cp). ``sigma^2``
    of a line, per FRF: the median weighted error ``err`` (n_out, n_ref, n_lines) over the lines of
    ``noise_lines`` (mask: lines near no mains harmonic) in its block of ``2 NOISE_HALF_WIDTH_LINES + 1``
    lines (all of them when the block has none), over ln 2 (the mean of a complex Gaussian's squared
    modulus): the noise there, which near a resonance is larger than elsewhere. Returns (n_out, n_ref,
    n_lines), zero off ``on``."""
    out = np.zeros(err.shape)
    n = int(on.sum())
    if n == 0 or n_params == 0 or not noise_lines.any():
        return out
    overall = np.median(err[..., noise_lines], axis=-1)
    width = 2 * NOISE_HALF_WIDTH_LINES + 1
    for lo in range(0, err.shape[-1], width):
        block = slice(lo, lo + width)
        if not on[block].any():
            continue
        quiet = noise_lines[block]
        sigma2 = np.median(err[..., block][..., quiet], axis=-1) if quiet.any() else overall
        out[..., block] = np.where(on[block], (2.0 * n_params / n * sigma2 / np.log(2.0))[..., None], 0.0)
    return out


#: Half-width (Hz) of a harmonic's neighbourhood beyond two line spacings: the largest mains offset looked for
#: (:data:`MAX_OFFSET_HZ`) and a line's width. The cross-validation by harmonics holds it out with the harmonic.
NEAR_HARMONIC_HZ = 0.6


def _near_harmonic(f: np.ndarray, fh: float, df: float) -> np.ndarray:
    """Mask of the lines ``f`` (Hz, spacing ``df``) in the neighbourhood of a harmonic at ``fh`` (Hz): within
    :data:`NEAR_HARMONIC_HZ` plus two line spacings."""
    return np.abs(f - fh) <= NEAR_HARMONIC_HZ + 2 * df


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
    predicted on every line. Every line is scored (before, after) in each fold; where amplitudes were fitted
    to the lines they are scored on (the training harmonics' on the training lines, the held-out ones' next
    to them) the residual gets :func:`_fit_penalty` (a fit scored on its own lines understates the error
    of a prediction): a model that only removes noise gains nothing on average, while interference at the
    predicted lines gives tens of dB."""
    m = ctx.measured
    f = m.freq_hz
    df = m.line_spacing_hz
    E = m.H - ctx.sim.H
    w_all = ctx.weights
    before, after = [], []
    err = w_all * np.abs(E) ** 2
    quiet = np.ones(f.size, bool)       # lines near no harmonic of either base: the noise of the penalty
    for b in HUM_BASES_HZ:
        for fh in b * np.arange(1, int(f[-1] // b) + 2):
            quiet &= ~_near_harmonic(f, fh, df)
    for parity in (0, 1):
        # the held-out harmonics' neighbourhoods (both mains bases) are left out of the fit
        near = np.zeros(f.size, bool)
        for b in HUM_BASES_HZ:
            k = np.arange(1, int(f[-1] // b) + 2)
            for fh in b * k[(k % 2) == parity]:
                near |= _near_harmonic(f, fh, df)
        params = fit_mains_hum(ctx, ~near)
        fk, K = hum_kernels(f, params["base_hz"] + params["offset_hz"], params["width_hz"], params["shape"])
        order = np.rint(fk / params["base_hz"]).astype(int)
        test_k = (order % 2) == parity
        if not test_k.any():
            before.append(err.ravel())
            after.append(err.ravel())
            continue
        R = E.copy()
        # the training harmonics' amplitudes from the training lines, the held-out harmonics' from the
        # lines next to them; each line shape's tails are then predicted on every line. Both sets of
        # amplitudes are scored on the lines they were fitted to: each fit owes its penalty there
        penalty = np.zeros(E.shape)
        for sel, on in ((~test_k, ~near), (test_k, np.any(np.abs(K[test_k]) > 1e-3, axis=0) & near)):
            if sel.any() and on.any():
                A, _ = _hum_amplitudes(ctx, E, K[sel], on)
                R = R - np.einsum("ork,kf->orf", A[..., 0] + 1j * A[..., 1], K[sel])
                seen = int(np.count_nonzero(np.any(np.abs(K[sel][:, on]) > 1e-3, axis=1)))
                penalty += _fit_penalty(err, quiet, on, seen)
        before.append(err.ravel())
        after.append((w_all * np.abs(R) ** 2 + penalty).ravel())
    return np.concatenate(before), np.concatenate(after)


def _reach(f: np.ndarray, df: float, params: Mapping) -> tuple[np.ndarray, np.ndarray]:
    """The fitted hum's harmonics (Hz) on the lines ``f`` (Hz, spacing ``df``) and, per harmonic, the mask of the
    lines it reaches: its kernel's (:func:`hum_kernels`, up to :data:`TAIL_WIDTHS` widths) and the neighbourhood
    :func:`held_out_by_harmonics` holds out with it (:func:`_near_harmonic`)."""
    fk, K = hum_kernels(f, float(params["base_hz"]) + float(params.get("offset_hz", 0.0)),
                        float(params.get("width_hz", 0.0)), str(params.get("shape", "lorentzian")))
    return fk, (np.abs(K) > 0) | np.array([_near_harmonic(f, h, df) for h in fk]).reshape(fk.size, f.size)


def carried_by_one_harmonic(ctx: FitContext, params: Mapping, before: np.ndarray, after: np.ndarray,
                            significant: Callable[[float, float], bool]) -> dict | None:
    """The one harmonic that carries a fitted mains hum's held-out gain, or None. ``before``, ``after``: the
    held-out errors of :func:`held_out_by_harmonics` (each fold's raveled (n_out, n_ref, n_lines)); ``params``:
    the fit (its ``harmonics_hz``); ``significant(gain_db, z)``: the rule the hum was found significant by. The
    harmonic whose lines (:func:`_reach`) hold the most of the gain carries it when the gain
    on every other line is not significant. Returns ``{"harmonic_hz", "share", "gain_without_db", "z_without"}``
    (``share``: its part of the gain, 0-1)."""
    m = ctx.measured
    f = np.asarray(m.freq_hz, float)
    if not params.get("harmonics_hz") or before.size != 2 * m.H.size or after.size != before.size:
        return None
    fk, near = _reach(f, m.line_spacing_hz, params)
    if fk.size == 0:
        return None
    shape = (2, *m.H.shape)
    b, a = before.reshape(shape), after.reshape(shape)
    drop = (b - a).sum(axis=(0, 1, 2))                        # what the hum removed, per line
    total = float(drop.sum())
    if total <= 0:
        return None
    shares = [float(drop[n].sum()) / total for n in near]
    k = int(np.argmax(shares))
    rest = ~near[k]
    b_rest, a_rest = b[..., rest].ravel(), a[..., rest].ravel()
    gain, z = 0.0, 0.0
    if b_rest.size:
        b_db, a_db, z = held_out_db(b_rest, a_rest)
        gain = b_db - a_db
    if significant(gain, z):
        return None
    return {"harmonic_hz": float(fk[k]), "share": shares[k], "gain_without_db": gain, "z_without": z}


def off_the_mode(f: np.ndarray, df: float, harmonic_hz: float, base_hz: float, mode: Mapping) -> np.ndarray:
    """Mask of the lines ``f`` (Hz, spacing ``df``) that no line of the fitted hum's harmonic at ``harmonic_hz``
    (of the mains base ``base_hz``, Hz) can reach wherever the mains frequency lies (within :data:`MAX_OFFSET_HZ`
    of the base, each shape's kernel out to :data:`TAIL_WIDTHS` widths, and the neighbourhood the cross-validation
    holds out, :func:`_near_harmonic`) and outside the half-power band of the mode ``mode`` (:func:`half_power_mode`'s
    ``{"mode_hz", "half_power_hz"}``): a hum fitted on them sees nothing of a misplaced mode's lobe there."""
    k = max(int(np.rint(harmonic_hz / base_hz)), 1)
    reach = max(TAIL_WIDTHS * default_hum_width(df), NEAR_HARMONIC_HZ) + 2 * df
    harmonic = (f >= k * (base_hz - MAX_OFFSET_HZ) - reach) & (f <= k * (base_hz + MAX_OFFSET_HZ) + reach)
    lobe = np.abs(f - float(mode["mode_hz"])) <= float(mode["half_power_hz"])
    return ~(harmonic | lobe)


def half_power_mode(model: ModalModel, freq_hz: float) -> dict | None:
    """The mode of ``model`` whose half-power band ``f_r (1 +- zeta_r)`` (Hz) holds ``freq_hz`` (the nearest when
    several do), or None: ``{"mode_hz", "half_power_hz"}`` (the band's half-width ``zeta_r f_r``)."""
    fr, zeta = np.asarray(model.freq_hz, float), np.asarray(model.damping, float)
    half = np.abs(zeta) * fr
    inside = np.flatnonzero((fr > 0) & (np.abs(freq_hz - fr) <= half))
    if inside.size == 0:
        return None
    j = int(inside[np.argmin(np.abs(freq_hz - fr[inside]))])
    return {"mode_hz": float(fr[j]), "half_power_hz": float(half[j])}
