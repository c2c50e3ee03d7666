"""Principal response functions: the pole search of a large FRF set on a few virtual FRFs.

A scanning vibrometer measures thousands of FRFs that share a few tens of poles. Every FRF
(one output/reference pair) is a *real* linear combination of the same ``P = 2 m + 2 n_res``
complex functions of frequency (the mode terms ``1/(jw - lambda) + 1/(jw - conj lambda)``,
``j/(jw - lambda) - j/(jw - conj lambda)`` and the residual terms, :mod:`analysis._lsfd_kernels`),
so the real matrix ``X`` whose row ``o`` holds ``[Re H_o, Im H_o]`` over the lines of the band has
rank ``P`` at most, whatever the number of FRFs. Its leading left singular vectors ``U`` (real,
orthonormal, one entry per FRF) give the *principal response functions* ``PRF_j = sum_o U_oj H_o``:
real combinations of FRFs, so each is an FRF of the same structure, with the same poles, and
together they keep every mode of the set (every mode whose contribution stands above the
noise). The automatic fit (:func:`analysis.pipeline.fit_auto`) runs its pole search
(stabilization, selection, LSFD, the search for missing modes) on them and then one LSFD over
all FRFs with the poles found: the residues are linear in the data and cost one projection of
the whole set (:func:`analysis.lsfd.lsfd_at_poles`).

Why the poles are not worse: with ``U`` spanning the signal, the data split into ``X U`` (signal
and noise) and ``X U_perp`` (noise only), whose distribution does not depend on the poles; the
least-squares poles of the PRFs are then those of the whole set (up to the small dependence of
``U`` on the noise). ``benchmarks/accuracy/bench_crlb_compressed.py`` checks the estimates
against the Cramer-Rao bound of the whole set.

The FRFs are weighted first (the fit's per-FRF weights, ``1 / noise level``), so that the noise is
alike in every row and the PRFs are combinations the fit itself would weigh so.

How many PRFs (the rank kept)
-----------------------------
1. A randomized range finder (:func:`_sketch`): ``Z = X Omega`` with a seeded Gaussian ``Omega``
   of ``L = 2 max_modes + 2 n_res + OVERSAMPLE`` columns, ``Q`` an orthonormal basis of ``Z``, and
   the singular values ``s`` of ``Q^T X`` (the sketch: ``L`` PRFs).
2. The noise level of every FRF: the energy of its row the sketch leaves out is noise (when the
   signal is inside the sketch), the share ``1 - L / n_frf`` of its noise: ``sigma_o^2`` per real
   value. The largest singular value of a noise matrix with rows of these levels is about the
   largest row norm plus the column norm, ``max_o sigma_o sqrt(2 n_lines) + sqrt(sum_o sigma_o^2)``
   (for equal rows the Marchenko-Pastur edge ``sigma (sqrt(2 n_lines) + sqrt(n_frf))``);
   ``EDGE_MARGIN`` times that is the noise edge: singular values above it are signal. The PRFs
   kept are those, plus ``KEEP_MARGIN``.
3. When the sketch is all signal (fewer than ``OVERSAMPLE`` of its singular values are below the
   edge) it may have cut modes off: ``L`` is doubled and the sketch repeated.
4. The check that no resonance is lost: the energy per line of the part of the data the kept
   PRFs leave out (``sum_o |w_o H_o|^2 - sum_j |PRF_j|^2``) is noise, smooth over frequency; a
   resonance left out shows there as a bump. Lines where it exceeds its baseline (the medians of
   blocks of ``BASELINE_FRACTION`` of the band, interpolated) by ``LOST_SIGMAS`` of its own
   scatter fail the check; then
   every PRF of the sketch is kept, then the sketch grows, and when it would hold more than
   ``MAX_FRACTION`` of the FRFs the set is fitted uncompressed. (Singular values below
   ``DYNAMIC_RANGE`` of the largest and left-out energy below ``ROUNDING_FLOOR`` of a line's are
   rounding: noise-free data compress to their exact rank.)

Below ``MIN_FRFS`` FRFs (or with ``compress=False``) nothing of this is done.
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from .frf import FRFSet
from .lscf import EQUAL_NOISE
from .modal import residual_basis

__all__ = ["Compression", "principal_responses", "worth_compressing", "MIN_FRFS"]

log = logging.getLogger(__name__)

#: FRF sets with fewer FRFs are fitted as they are
MIN_FRFS = 64
#: extra columns of the range finder beyond the largest rank the model can have
OVERSAMPLE = 16
#: the noise edge is taken this much above its estimate
EDGE_MARGIN = 1.1
#: singular values below this fraction of the largest are not signal (120 dB: the single-precision
#: sketch's own rounding; no measurement reaches it)
DYNAMIC_RANGE = 1e-6
#: left-out energy below this fraction of a line's energy is rounding, never a lost resonance
ROUNDING_FLOOR = 1e-10
#: PRFs kept beyond those whose singular value is above the noise edge
KEEP_MARGIN = 4
#: the range finder never holds more than this fraction of the FRFs (else: no compression)
MAX_FRACTION = 0.5
#: block of the lost-resonance check's baseline, as a fraction of the band's lines
BASELINE_FRACTION = 0.1
#: a line of the left-out energy this many (robust) standard deviations above its baseline fails
LOST_SIGMAS = 6.0
#: seed of the range finder's random matrix (the result is deterministic)
SEED = 20240611


@dataclass(frozen=True)
class Compression:
    """The principal response functions of an FRF set.

    frf : the PRFs as an FRF set ``(k, 1, n_freq)`` over all lines of the original (same
        frequency axis, quantity, window, sample rate; outputs ``prf:1..k``; the coherence, when
        the original has one, is the median over its FRFs, the same for every PRF).
    basis : (n_frf, k) real, orthonormal columns: ``PRF_j = sum_o basis[o, j] weights_o H_o``
        (FRFs in C order of (output, reference)).
    weights : (n_out, n_ref) the FRF weights applied before the compression.
    singular_values : (L,) singular values of the weighted band data in the final sketch.
    noise_edge : the singular value a pure-noise matrix of that shape would reach.
    n_signal : singular values above the noise edge.
    """

    frf: FRFSet
    basis: np.ndarray
    weights: np.ndarray
    singular_values: np.ndarray
    noise_edge: float
    n_signal: int

    @property
    def kept(self) -> int:
        """Number of PRFs."""
        return int(self.basis.shape[1])

    def describe(self) -> str:
        """One line for the fit's warnings/log: what was compressed to what, and why that rank."""
        n = self.basis.shape[0]
        return (f"pole search on {self.kept} principal response functions of the {n} FRFs ({self.n_signal} "
                f"singular values above the noise edge {self.noise_edge:.3g} of {self.singular_values.size} "
                "sketched); residues fitted on all FRFs")


def worth_compressing(frf: FRFSet) -> bool:
    """Whether the set has enough FRFs for the compression to pay (``MIN_FRFS``)."""
    return frf.n_outputs * frf.n_references >= MIN_FRFS


def _weighted_rows(frf: FRFSet, weights: np.ndarray, sel: slice) -> np.ndarray:
    """``w_o H_o`` over the lines ``sel``, (n_frf, n) complex, C-contiguous (a new array)."""
    H = np.asarray(frf.H)[:, :, sel]
    n_frf = frf.n_outputs * frf.n_references
    out = np.empty((n_frf, H.shape[-1]), dtype=complex)
    np.multiply(H.reshape(n_frf, -1), np.asarray(weights, float).reshape(-1, 1), out=out)
    return out


def _sketch(X: np.ndarray, L: int, rng: np.random.Generator) -> np.ndarray:
    """Orthonormal basis (n_frf, L) of the range of ``X`` (n_frf, 2n real, single precision) by a
    Gaussian sketch and one power iteration (the signal directions come out with an error of order
    ``(noise edge / singular value)^3`` instead of its first power). Single precision is enough for
    a basis: the PRFs are formed in double precision and are exact combinations of the FRFs
    whatever basis is used."""
    Q, _ = np.linalg.qr(X @ rng.standard_normal((X.shape[1], L), dtype=np.float32))
    Q, _ = np.linalg.qr(X @ (X.T @ Q))
    Q, _ = np.linalg.qr(Q.astype(np.float64))
    return Q


def _lost_lines(left: np.ndarray, energy: np.ndarray, n_dirs: int) -> np.ndarray:
    """Lines where the left-out energy per line ``left`` stands out of its running median by
    ``LOST_SIGMAS`` of its scatter (``n_dirs`` real noise directions per line) and above the
    rounding of the line's ``energy``."""
    n = left.size
    win = max(9, int(BASELINE_FRACTION * n))
    # the baseline: the median of every block of ``win`` lines, interpolated between the blocks'
    # middles (a bump narrower than half a block does not move it)
    n_blocks = max(1, n // win)
    edges = np.linspace(0, n, n_blocks + 1).astype(int)
    mids = 0.5 * (edges[:-1] + edges[1:] - 1)
    meds = np.array([np.median(left[a:b]) for a, b in zip(edges[:-1], edges[1:])])
    base = np.maximum(np.interp(np.arange(n), mids, meds), 1e-300)
    ratio = left / base - 1.0
    # the scatter of a sum of n_dirs squared Gaussians relative to its mean is sqrt(2 / n_dirs);
    # the measured robust scatter is used when larger (noise that is not white over the FRFs)
    mad = 1.4826 * float(np.median(np.abs(ratio - np.median(ratio))))
    scatter = max(mad, np.sqrt(2.0 / max(n_dirs, 1)))
    return np.flatnonzero((ratio > LOST_SIGMAS * scatter) & (left > ROUNDING_FLOOR * energy))


def principal_responses(frf: FRFSet, band: Sequence[float], weights: np.ndarray, max_modes: int,
                        residual_form: str = "physical") -> Compression | None:
    """The principal response functions of ``frf`` (module docstring); None when the set is too
    small for them to pay or no rank below ``MAX_FRACTION`` of the FRFs keeps every resonance.

    band : (lo, hi) Hz whose lines decide the basis; weights : (n_out, n_ref) FRF weights;
    max_modes : the largest model the pole search will try (sets the first sketch size)."""
    n_frf = frf.n_outputs * frf.n_references
    if n_frf < MIN_FRFS:
        return None
    f = frf.freq_hz
    i0 = int(np.searchsorted(f, float(band[0]), side="left"))
    i1 = int(np.searchsorted(f, float(band[1]), side="right"))
    n_band = i1 - i0
    n_res = residual_basis(f[:1], frf.quantity, residual_form).shape[0]
    Y = _weighted_rows(frf, weights, slice(0, f.size))
    if not np.all(np.isfinite(Y[:, i0:i1])):
        return None
    X = Y.view(np.float64)[:, 2 * i0:2 * i1]   # (n_frf, 2 n_band): Re and Im interleaved (a column order)
    row_energy = np.einsum("ij,ij->i", X, X)
    energy_line = np.einsum("ij,ij->j", X, X).reshape(-1, 2).sum(axis=1)
    X32 = X.astype(np.float32)
    rng = np.random.default_rng(SEED)
    cap = int(MAX_FRACTION * n_frf)
    L = min(2 * int(max_modes) + 2 * n_res + OVERSAMPLE, cap)
    while L > OVERSAMPLE:
        Q = _sketch(X32, L, rng)
        B_all = (Q.T @ Y.view(np.float64)).view(complex)   # (L, n_freq): the sketch's PRFs
        Ub, s, _ = np.linalg.svd(B_all[:, i0:i1].view(np.float64), full_matrices=False)
        basis_all = Q @ Ub                        # (n_frf, L) orthonormal, by decreasing singular value
        # noise per FRF: its energy the sketch leaves out, spread over the n_frf - L directions left
        left_row = np.maximum(row_energy - np.sum((basis_all * s) ** 2, axis=1), 0.0)
        sigma2 = left_row / (2 * n_band) * n_frf / (n_frf - L)
        edge = EDGE_MARGIN * float(np.sqrt(np.max(sigma2) * 2 * n_band) + np.sqrt(np.sum(sigma2)))
        edge = max(edge, DYNAMIC_RANGE * float(s[0]))
        n_signal = int(np.sum(s > edge))
        if n_signal > L - OVERSAMPLE:
            log.info("compression: %d of %d sketched singular values above the noise edge; a larger sketch",
                     n_signal, L)
            L = 0 if L == cap else min(2 * L, cap)
            continue
        prf_all = Ub.T @ B_all                    # (L, n_freq) complex, by decreasing singular value
        for k in (min(L, n_signal + KEEP_MARGIN), L):
            pb = prf_all[:k, i0:i1]
            left = energy_line - np.sum(pb.real ** 2 + pb.imag ** 2, axis=0)
            lost = _lost_lines(left, energy_line, 2 * (n_frf - k))
            if lost.size == 0:
                basis = np.ascontiguousarray(basis_all[:, :k])
                comp = Compression(_prf_set(frf, prf_all[:k]), basis, np.asarray(weights, float), s, edge, n_signal)
                log.info("compression: %s", comp.describe())
                return comp
            log.info("compression: with %d PRFs the left-out data peak at %d line(s) near %.6g Hz", k, lost.size,
                     float(f[i0 + lost[np.argmax(left[lost])]]))
        L = 0 if L == cap else min(2 * L, cap)
    log.info("compression: no rank below %.0f %% of the %d FRFs keeps every resonance; fitted uncompressed",
             100 * MAX_FRACTION, n_frf)
    return None


def _prf_set(frf: FRFSet, prf: np.ndarray) -> FRFSet:
    """The PRFs ``prf`` (k, n_freq) as an FRF set (see :class:`Compression`)."""
    k = prf.shape[0]
    coh = None
    if frf.coherence is not None:
        c = np.nanmedian(np.asarray(frf.coherence).reshape(-1, frf.freq_hz.size), axis=0)
        coh = np.broadcast_to(c, (k, 1, c.size))
    meta = dict(frf.meta)
    n_avg = np.atleast_1d(np.asarray(meta.get("n_averages", []), dtype=float))
    if n_avg.size:
        meta["n_averages"] = [float(np.min(n_avg))] * k
    meta["compressed_from"] = frf.n_outputs * frf.n_references
    meta[EQUAL_NOISE] = True
    return replace(frf, H=prf[:, None, :], outputs=tuple(f"prf:{j + 1}:X" for j in range(k)), references=("prf:0:X",),
                   coherence=coh, meta=meta)
