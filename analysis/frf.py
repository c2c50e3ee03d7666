"""The FRF set: the plain data container that flows from estimation to fitting.

Axis order of ``H``: ``(n_outputs, n_references, n_freq)``: response point, excitation
(reference) point, frequency line. ``freq_hz`` is in Hz, strictly increasing.

``quantity`` names the FRF form, all per newton of force:

=============  ==========  ==================================
quantity       unit        relation to receptance H_d
=============  ==========  ==================================
receptance     m/N         H_d
mobility       (m/s)/N     j*omega * H_d
accelerance    (m/s^2)/N   -omega^2 * H_d
=============  ==========  ==================================

Other units (g/N, V/V) may be carried in ``unit``; the form is what matters to the fitter.

``exp_window_tau_s`` records the time constant tau (s) of an exponential window
w(t) = exp(-t/tau) applied to the responses: it adds sigma_w = 1/tau (rad/s) to
every pole's decay rate, which a fitter removes (apparent damping sigma_w/omega_n).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

__all__ = ["FRFSet", "QUANTITIES", "QUANTITY_POWER", "QUANTITY_UNIT", "convert_quantity", "analyser_band_hz", "window_pole_shift",
           "frf_pairs_by_level", "line_spacing_hz"]

QUANTITIES = ("receptance", "mobility", "accelerance")
#: the power p of (j omega) that turns a receptance (m/N) into each quantity: H_q = (j omega)^p H_receptance
QUANTITY_POWER = {"receptance": 0, "mobility": 1, "accelerance": 2}
#: the SI unit of each quantity, per newton of force (the table above; other units travel in ``FRFSet.unit``)
QUANTITY_UNIT = {"receptance": "m/N", "mobility": "(m/s)/N", "accelerance": "(m/s^2)/N"}


def window_pole_shift(exp_window_tau_s: float | None) -> float:
    """The decay rate (1/s) an exponential window ``exp(-t / tau)`` adds to every pole: ``1 / tau``;
    0 without a window (None or 0). The one place windowed and structural poles are related (the
    fitter removes it, the diagnosis adds it to a simulation)."""
    if not exp_window_tau_s:
        return 0.0
    tau = float(exp_window_tau_s)
    if not (np.isfinite(tau) and tau > 0):
        raise ValueError(f"exp_window_tau_s must be a positive time in seconds; got {exp_window_tau_s!r}")
    return 1.0 / tau


def line_spacing_hz(freq_hz: np.ndarray) -> float:
    """The line spacing (Hz) of a frequency axis (Hz): the median spacing of its lines, 0 for a single
    line. An FRF set carries it as :attr:`FRFSet.line_spacing_hz`; this is for a bare axis."""
    f = np.asarray(freq_hz, float)
    return float(np.median(np.diff(f))) if f.size > 1 else 0.0


def analyser_band_hz(sample_rate_hz: float) -> float:
    """Upper end (Hz) of a dynamic signal analyser's flat, alias-free band at ``sample_rate_hz`` (Hz):
    ``fs / 2.56``, the oversampling every such analyser uses (its anti-alias filter's roll-off)."""
    return float(sample_rate_hz) / 2.56


@dataclass(frozen=True)
class FRFSet:
    """FRFs of one test: ``H[o, r, k]`` from reference ``r`` to output ``o`` at ``freq_hz[k]``.

    Parameters
    ----------
    freq_hz : (n_freq,) float, Hz, strictly increasing.
    H : (n_out, n_ref, n_freq) complex.
    quantity : "receptance", "mobility" or "accelerance".
    outputs, references : point labels (``component:node:direction``), one per axis entry.
    unit : unit string of H, e.g. "(m/s^2)/N" or "g/N".
    coherence : optional (n_out, n_ref, n_freq) float in [0, 1].
    exp_window_tau_s : optional time constant (s) of an exponential window on the responses.
    meta : free-form provenance (estimator, number of averages, source file...).
    sample_rate_hz : the acquisition's sample rate (Hz) when known (recordings, captures): the
        analyser's flat band ends at ``sample_rate_hz / 2.56``. None for FRFs of unknown origin
        (a UFF file); consumers then fall back to the frequency axis.
    record_s : length of the time record each FRF was computed from (s), when known.
    pretrigger_s : time recorded before the trigger (s), when known; the response after the hammer
        pulse is seen for ``record_s - pretrigger_s``.

    The line spacing is :attr:`line_spacing_hz` (one formula for every consumer).
    """

    freq_hz: np.ndarray
    H: np.ndarray
    quantity: str = "accelerance"
    outputs: tuple = ()
    references: tuple = ()
    unit: str = ""
    coherence: np.ndarray | None = None
    exp_window_tau_s: float | None = None
    meta: dict = field(default_factory=dict)
    sample_rate_hz: float | None = None
    record_s: float | None = None
    pretrigger_s: float | None = None

    def __post_init__(self) -> None:
        f = np.asarray(self.freq_hz, dtype=float)
        H = np.asarray(self.H)
        if H.ndim == 1:
            H = H[None, None, :]
        elif H.ndim == 2:
            H = H[:, None, :]
        H = H.astype(complex)
        if H.ndim != 3:
            raise ValueError(f"H must have axes (n_out, n_ref, n_freq); got shape {H.shape}")
        if f.ndim != 1 or f.size != H.shape[2]:
            raise ValueError(f"freq_hz has {f.size} lines but H has {H.shape[2]} (shape {H.shape})")
        if f.size > 1 and np.any(np.diff(f) <= 0):
            raise ValueError("freq_hz must be strictly increasing")
        if self.quantity not in QUANTITIES:
            raise ValueError(f"quantity {self.quantity!r} is not one of {QUANTITIES}")
        outs = tuple(str(o) for o in self.outputs) or tuple(f"n:{i + 1}:Z" for i in range(H.shape[0]))
        refs = tuple(str(r) for r in self.references) or tuple(f"n:{1000 + j}:Z" for j in range(H.shape[1]))
        if len(outs) != H.shape[0] or len(refs) != H.shape[1]:
            raise ValueError(
                f"{len(outs)} output and {len(refs)} reference labels for H of shape {H.shape}"
            )
        if self.sample_rate_hz is not None:
            fs = float(self.sample_rate_hz)
            if not (np.isfinite(fs) and fs > 0):
                raise ValueError(f"sample_rate_hz must be a positive number of Hz; got {self.sample_rate_hz!r}")
            object.__setattr__(self, "sample_rate_hz", fs)
        for name in ("record_s", "pretrigger_s"):
            value = getattr(self, name)
            if value is not None:
                t = float(value)
                if not (np.isfinite(t) and t >= 0):
                    raise ValueError(f"{name} must be a time >= 0 s; got {value!r}")
                object.__setattr__(self, name, t)
        coh = None
        if self.coherence is not None:
            coh = np.asarray(self.coherence, dtype=float).reshape(H.shape)
        f.setflags(write=False)
        H.setflags(write=False)
        if coh is not None:
            coh.setflags(write=False)
        object.__setattr__(self, "freq_hz", f)
        object.__setattr__(self, "H", H)
        object.__setattr__(self, "outputs", outs)
        object.__setattr__(self, "references", refs)
        object.__setattr__(self, "coherence", coh)

    def __repr__(self) -> str:
        fs = f", sample rate {self.sample_rate_hz:g} Hz" if self.sample_rate_hz else ""
        win = f", exp. window tau {self.exp_window_tau_s:g} s" if self.exp_window_tau_s else ""
        est = f", {self.meta['estimator']}" if isinstance(self.meta.get("estimator"), str) else ""
        return (f"FRFSet({self.n_outputs} outputs x {self.n_references} references x {self.freq_hz.size} lines, "
                f"{self.freq_hz[0]:.6g}..{self.freq_hz[-1]:.6g} Hz, {self.quantity} [{self.unit}]{est}{fs}{win})")

    def _repr_html_(self) -> str:
        import html

        refs = ", ".join(html.escape(r) for r in self.references)
        outs = ", ".join(html.escape(o) for o in self.outputs)
        return (f"<p><b>FRFSet</b> {html.escape(repr(self))}</p>"
                f"<table><tr><th>references</th><td>{refs}</td></tr><tr><th>outputs</th><td>{outs}</td></tr>"
                f"<tr><th>coherence</th><td>{'yes' if self.coherence is not None else 'no'}</td></tr></table>")

    def plot(self, max_frfs: int = 12) -> Any:
        """Magnitude (dB) of up to ``max_frfs`` FRFs and their coherence; returns the matplotlib
        ``Figure`` (notebooks show it)."""
        from matplotlib.figure import Figure

        fig = Figure(figsize=(9, 5.5))
        axm, axc = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
        pairs = [(o, r) for o in range(self.n_outputs) for r in range(self.n_references)][:max_frfs]
        for o, r in pairs:
            with np.errstate(divide="ignore"):
                axm.plot(self.freq_hz, 20 * np.log10(np.abs(self.H[o, r])), lw=0.8,
                         label=f"{self.outputs[o]} / {self.references[r]}")
            if self.coherence is not None:
                axc.plot(self.freq_hz, self.coherence[o, r], lw=0.6)
        axm.set_ylabel(f"|H| [dB re 1 {self.unit or self.quantity}]")
        axc.set_ylabel("coherence")
        axc.set_xlabel("frequency [Hz]")
        axm.legend(fontsize=7, ncol=2)
        total = self.n_outputs * self.n_references
        axm.set_title(f"{len(pairs)} of {total} FRFs" if len(pairs) < total else f"{total} FRFs", fontsize=9)
        fig.tight_layout()
        return fig

    @property
    def line_spacing_hz(self) -> float:
        """Frequency resolution (Hz): the median spacing of the lines (0 for a single line)."""
        return line_spacing_hz(self.freq_hz)

    @property
    def analyser_band_hz(self) -> float | None:
        """Upper end of the analyser's flat (alias-free) band, ``sample_rate_hz / 2.56`` (Hz), when
        the sample rate is known."""
        return None if self.sample_rate_hz is None else analyser_band_hz(self.sample_rate_hz)

    @property
    def omega(self) -> np.ndarray:
        """Angular frequency (rad/s)."""
        return 2 * np.pi * self.freq_hz

    @property
    def n_outputs(self) -> int:
        return self.H.shape[0]

    @property
    def n_references(self) -> int:
        return self.H.shape[1]

    def band(self, lo_hz: float, hi_hz: float) -> FRFSet:
        """A new FRF set restricted to lo_hz <= f <= hi_hz."""
        sel = (self.freq_hz >= lo_hz) & (self.freq_hz <= hi_hz)
        if sel.sum() < 2:
            raise ValueError(
                f"band {lo_hz}:{hi_hz} Hz holds {int(sel.sum())} lines; data span "
                f"{self.freq_hz[0]:.4g}..{self.freq_hz[-1]:.4g} Hz"
            )
        coh = None if self.coherence is None else self.coherence[..., sel]
        return replace(self, freq_hz=self.freq_hz[sel], H=self.H[..., sel], coherence=coh)

    def select(self, outputs: Sequence[str] | None = None, references: Sequence[str] | None = None) -> FRFSet:
        """A new FRF set with the named outputs/references (in the order given)."""
        oi = [self.outputs.index(str(o)) for o in outputs] if outputs else list(range(self.n_outputs))
        ri = [self.references.index(str(r)) for r in references] if references else list(range(self.n_references))
        coh = None if self.coherence is None else self.coherence[np.ix_(oi, ri)]
        return replace(
            self,
            H=self.H[np.ix_(oi, ri)],
            outputs=tuple(self.outputs[i] for i in oi),
            references=tuple(self.references[i] for i in ri),
            coherence=coh,
        )

    def as_quantity(self, quantity: str) -> FRFSet:
        """The same FRFs in another form (see :func:`convert_quantity`)."""
        return replace(self, H=convert_quantity(self.H, self.freq_hz, self.quantity, quantity), quantity=quantity,
                       unit="")


def convert_quantity(H: np.ndarray, freq_hz: np.ndarray, src: str, dst: str) -> np.ndarray:
    """Convert FRFs between receptance, mobility and accelerance: multiply by (j omega)^(p_dst - p_src).

    Lines at f = 0 are undefined when dividing and come back as NaN.
    """
    for q in (src, dst):
        if q not in QUANTITIES:
            raise ValueError(f"quantity {q!r} is not one of {QUANTITIES}")
    p = QUANTITY_POWER[dst] - QUANTITY_POWER[src]
    jw = 1j * 2 * np.pi * np.asarray(freq_hz, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = jw ** p if p >= 0 else np.where(jw == 0, np.nan, 1.0 / np.where(jw == 0, 1, jw) ** (-p))
    return np.asarray(H) * factor


def frf_pairs_by_level(frf: FRFSet, output: str | None = None) -> list[tuple[int, int]]:
    """The (output, reference) index pairs of ``frf`` by RMS level over all lines, strongest first
    (usually the driving point), all-zero FRFs left out. The first pair is always the strongest FRF
    of ``output`` when it is given (an output name of ``frf``), else the strongest of all.
    Raises ValueError for an output ``frf`` does not have."""
    rms = np.sqrt(np.nanmean(np.abs(frf.H) ** 2, axis=2))  # (n_out, n_ref), the H's units
    if output is not None:
        if output not in frf.outputs:
            raise ValueError(f"{output!r} is not an output; outputs: {', '.join(frf.outputs)}")
        row = frf.outputs.index(output)
        first = (row, int(np.argmax(rms[row])))
    else:
        i_out, i_ref = np.unravel_index(int(np.argmax(rms)), rms.shape)
        first = (int(i_out), int(i_ref))
    order = [(int(k // rms.shape[1]), int(k % rms.shape[1])) for k in np.argsort(-rms, axis=None)]
    return [first] + [p for p in order if p != first and rms[p] > 0]
