"""The operator at a terminal: one key per hit (accept, reject, quit) and the end-of-test summary
(hits, FRF peaks, coherence and the hammer's excitation band per point)."""
from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any, TextIO

import numpy as np

from analysis.bands import unsupported_band_text
from analysis.spectra import excitation_band

from .operator import HitSummary
from .session_errors import OperatorQuit

__all__ = ["read_key", "terminal_decider", "summary_text"]


def read_key(prompt: str) -> str:
    """One key press at a terminal (no Enter needed); a whole line when stdin is not a terminal."""
    if not sys.stdin.isatty():
        return input(prompt)
    import termios
    import tty

    fd = sys.stdin.fileno()
    old = termios.tcgetattr(fd)
    try:
        # one key at a time before the prompt shows: keys struck before it are discarded (a key pressed
        # during the hit answers nothing), a key struck once it shows is always read
        tty.setcbreak(fd, termios.TCSAFLUSH)
        print(prompt, end="", flush=True)
        key = sys.stdin.read(1)
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, old)
    print(key)
    if key in ("\x03", "\x04"):  # Ctrl-C, Ctrl-D
        raise EOFError
    return key


def terminal_decider(input_fn: Callable[[str], str] = read_key, out: TextIO = sys.stdout) -> Callable[[HitSummary], bool]:
    """An operator at a terminal (the capture CLI's ``decide``): key ``a`` (or Enter) accept, ``r`` reject, ``q`` quit (raises
    :class:`OperatorQuit`). ``input_fn(prompt) -> str`` reads the answer (default :func:`read_key`)."""

    def decide(summary: HitSummary) -> bool:
        while True:
            try:
                key = input_fn("accept (a), reject (r), quit (q)? ").strip().lower()
            except EOFError:
                raise OperatorQuit("input closed: ending the test") from None
            if key in ("a", "", "\n", "\r"):
                return True
            if key == "r":
                return False
            if key == "q":
                raise OperatorQuit("operator pressed q")
            print("please press a, r or q", file=out)

    return decide


def summary_text(result: Any, estimator: str = "H1", n_peaks: int = 8, quiet: bool = False) -> str:
    """Hits accepted/rejected with reasons (``quiet``: counted by reason), an FRF peak table and the
    mean coherence per FRF."""
    from collections import Counter

    from scipy.signal import find_peaks

    lines = [f"hits accepted: {result.accepted}, rejected: {len(result.rejected)}"]
    if quiet and result.rejected:
        why = Counter(r.split(":")[0] for *_, reasons in result.rejected for r in reasons[:1])
        lines.append("  rejected: " + ", ".join(f"{n} x {reason}" for reason, n in why.most_common()))
    for m, point, idx, reasons in ([] if quiet else sorted(result.rejected, key=lambda r: r[2])):
        lines.append(f"  rejected hit #{idx + 1} at point {m + 1} ({point}): {'; '.join(reasons)}")
    avgs = [a for a in result.averages if a.n_averages > 0]
    if not avgs:
        lines.append("no FRF: no point has an accepted hit")
        return "\n".join(lines)
    for a in avgs:
        s = a.frfset(estimator)
        f = s.freq_hz
        hi = s.analyser_band_hz or np.inf  # alias-free band, from the acquisition's sample rate
        band = (f > 2.0) & (f <= hi)
        mag = np.abs(s.H[:, 0, :])
        live = [i for i in range(s.n_outputs) if np.any(a.acc.spectra()[1][i] > 0)]  # outputs with any signal
        # peaks of the sum of the live outputs' magnitudes, each normalised to its own maximum
        total = sum((np.where(band, mag[i], 0.0) / max(float(np.nanmax(np.where(band, mag[i], 0.0))), 1e-300)
                     for i in live), np.zeros(f.size))
        pk, prop = find_peaks(np.nan_to_num(total), prominence=0.02 * max(float(np.nanmax(total)), 1e-300))
        top = np.sort(pk[np.argsort(prop["prominences"])[::-1][:n_peaks]])
        tau = f"{s.exp_window_tau_s:.4g} s" if s.exp_window_tau_s else "none"
        lines.append(f"point {a.index + 1}: reference {a.reference}, {a.n_averages} averages, {estimator} "
                     f"[{s.unit}], exponential window tau {tau}")
        lines.append("  peak Hz " + "".join(f"{o:>24s}" for o in s.outputs))
        for k in top:
            cells = "".join(f"{mag[i, k]:12.4g} (coh {s.coherence[i, 0, k]:.3f})" if i in live else f"{'-':>24s}"
                            for i in range(s.n_outputs))
            lines.append(f"  {f[k]:7.2f} {cells}")
        coh = ", ".join(f"{o} {np.mean(s.coherence[i, 0, band]):.3f}" if i in live else f"{o} no signal (below 1 LSB)"
                        for i, o in enumerate(s.outputs))
        lines.append(f"  mean coherence 2..{hi:.0f} Hz: {coh}")
        gff = a.acc.spectra()[0]
        edges = excitation_band(f, 10 * np.log10(np.maximum(gff, max(float(np.max(gff)), 1e-300) * 1e-30)))
        e10, e20 = edges[10.0], edges[20.0]
        lines.append("  excitation band (force spectrum): "
                     + ", ".join(f"-{d:g} dB at {'beyond ' + format(hi, '.0f') if e is None or e > hi else format(e, '.0f')} Hz"
                                 for d, e in ((10, e10), (20, e20))))
        short = None if e20 is None else unsupported_band_text(hi, {"excitation": e20}, where="this point")
        if short:
            lines.append(f"  warning: {short}")
    return "\n".join(lines)
