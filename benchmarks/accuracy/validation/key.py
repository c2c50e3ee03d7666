"""The analyst's key of every real dataset of docs/validation.md: which resonances a careful analyst accepts,
which poles are spurious, what is doubtful, and where the excitation ends. Written from the evidence, before
the fit's resonance rule was tuned against it; the fit is scored against it by
``benchmarks/studies/realdata_key.py``.

Evidence used (figures from the data over the whole recorded range; CMIF = first singular value of the FRF
matrix per line, its prominence above the neighbouring minima):

* **uliege_plane** (222 FRFs, 3 accelerometers x 74 hammer points, analyser H1 averaged over several hits,
  coherence 0.98-1.0 from 10 to 200 Hz). Thirteen resonances: CMIF peaks at 18.9 (19 dB), 40.1 (29 dB),
  89.6 (18 dB), 97.1 (33 dB), 105.3 (52 dB), 118.0 (8 dB), 125.4 (23 dB), 130.3, 143.5 (11 dB), 166.4 (8 dB);
  87.8 Hz under the 89.6 Hz peak (FE mode 3, MAC 0.72; recovered in every weighted fit); 39.72 Hz under the
  40.16 Hz peak (in each accelerometer alone: two poles cut the misfit by more than 30 %); 135.3 Hz (FE mode
  11, MAC 0.88). The 125.4 Hz resonance may be a close pair (125.24 / 125.69 Hz in the global fit, one pole
  in a third of the hammer points): one or two poles there are accepted. Spurious: 190.2 Hz (1.1 %
  damping, no CMIF peak within its bandwidth, FE MAC <= 0.41, MAC 0.05 between the two accelerometers that
  see it most) and 55.4 Hz (no CMIF peak, MAC 0.01 between accelerometers). Doubtful: the humps of 3-7 dB in
  the CMIF at 25.1, 27.1 and 30.8 Hz (each a peak in only 1-3 of the 222 FRFs) and the 6 dB CMIF hump at
  197.1 Hz, 3 Hz from the data's end. The data end (200 Hz) is the upper limit.
* **modelab_beam** (9 FRFs, one accelerometer, roving hammer, no coherence). The free-free bending series
  112.0, 306.9, 596.4, 974.1 Hz (ratios 1, 2.74, 5.33, 8.70 against Euler-Bernoulli's 2.76, 5.40, 8.93; each
  a peak in 9 of 9 FRFs, CMIF 49-65 dB). 5.31 Hz (CMIF 21 dB, 1/21 of the first bending mode): the
  suspension. 0.45 Hz (23 lines from zero): doubtful.
* **ladisk_single**: the key of :mod:`.ladisk_beam` (bending 695.7, 1898.1, 3671.2, 5975.0 Hz; weak 2777.8,
  5608.0 Hz; suspension 18.0, 37.0 Hz; the force ends at 6.6 kHz).
* **ladisk_multi** (4 hits): bending 315.7, 858.7, 1668.0, 2730.8 Hz (ratios 1, 2.72, 5.28, 8.65);
  suspension 18.0 and 36.0 Hz (CMIF 9 and 13 dB, 1/9 of the first bending mode); 3217.6 Hz doubtful
  (coherence 0.48 at its line, CMIF 3 dB, 1 % below where the force ends, 3255 Hz).
* **pyfrf_5impacts** (1 FRF, 5 hits): the resonances of 700-1700 Hz of docs/validation.md: 810.3, 823.6,
  831.0, 851.5, 899.9, 905.5, 1518.1, 1520.1 Hz (the 905.5 Hz shoulder of the 900 Hz peak halves the
  misfit when fitted; 1518/1521 Hz are two CMIF peaks). Above 1700 Hz the dense spectrum of this
  undocumented structure is not keyed: poles there count neither way. The force ends at 7.0 kHz.
* **f16_gvt** (3 FRFs, multisine 2-15 Hz): 3.48, 3.97, 5.19, 6.61, 7.32, 9.17 Hz (CMIF peaks of 7-29 dB;
  both fitters find them); 12.43 Hz doubtful (no CMIF peak, no FRF peak). Excitation 2-15 Hz.
* **plate_sweep** (1 FRF, swept sine 60-500 Hz): 126, 215, 264, 347-352 and 450-456 Hz (CMIF peaks of
  15-60 dB, each within its scatter over the four runs); 77, 286.5 and 310.3 Hz doubtful (fit standard
  deviations of 1.3-3.2 Hz). Nothing is excited outside 60-500 Hz: a pole there is spurious.
* **pyuff_3frf** (3 FRFs, df 1 Hz, no coherence): 51.5, 142.2, 278.7, 460.4, 687.2, 958.5 Hz, each a peak in
  3 of 3 FRFs and in the CMIF (33-52 dB), the lighter ones a single line wide.
* **unesp_boltedbeam** (4 FRFs, 54 averages): 18.8, 98.4, 271.2 Hz (peaks in 4 of 4 FRFs) and 54.01 Hz;
  300 and 420 Hz are 60 Hz mains lines (spurious if fitted); the coherence falls for good at
  468 Hz: a pole above (478 Hz, coherence 0.45-0.57) is above the excitation.
  54.01 Hz was first keyed doubtful (42 dB in one accelerometer, 10 dB in a second, no CMIF peak of 6 dB;
  the poles the fit then tried there took 1.8-3 % damping). Looked at again from all the evidence, it is
  a resonance: one pole shared by the 4 FRFs over 53.2-54.9 Hz (a residue per FRF, a constant and a
  slope each) cuts their misfit there 150 times (65 -> 0.44, relative to each FRF's level), at 54.012 Hz
  and 0.078 % damping (half-power width 0.08 Hz, 1.3 lines: a pole of 1.8-3 % is 2-3 Hz wide and
  does not fit it); it shows on the same line in every FRF (beam:2 a peak between two antiresonances, its
  phase turning 130-150 degrees; beam:3 a 4-8 dB peak-dip; beam:1 and beam:4 dips of 1-2 dB), the
  coherence at its top is 0.88-0.98 (so the response there is what the drive caused: no hum, whose
  coherence would fall), the drive voltage's spectrum has no line or notch at 54 Hz, and 54 Hz is no
  harmonic or subharmonic of the 60 Hz grid (0.9 x 60). At 0.30 V the same fit gives 53.965 Hz and
  0.158 %: it softens and gains damping with level as the bolted joint's modes do (-0.09 %, against
  -0.2 to -1.1 % for 18.8-271 Hz), so it is no stray tone of the lab. Whether it is a mode of the
  beam weakly seen by vertical accelerometers (a torsional or lateral one) or of the shaker and stinger,
  it is a pole of these FRFs (drive voltage to acceleration): accepted.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Accepted", "DatasetKey", "KEYS", "score"]


@dataclass(frozen=True)
class Accepted:
    """An accepted resonance: its frequency (Hz), the window (lo, hi Hz) a pole of it lies in, and how many
    poles it may have (a possible close pair: 2)."""

    freq_hz: float
    window: tuple[float, float]
    max_poles: int = 1


def _acc(f: float, rel: float = 0.005, max_poles: int = 1, window: tuple[float, float] | None = None) -> Accepted:
    return Accepted(f, window or (f * (1 - rel), f * (1 + rel)), max_poles)


@dataclass(frozen=True)
class DatasetKey:
    """One dataset's key: accepted resonances, windows where a pole is spurious (named), windows where a
    pole counts neither way (doubtful, suspension, or not keyed), and the excitation's range (Hz): a pole
    outside it is spurious."""

    accepted: tuple[Accepted, ...]
    excitation_hz: tuple[float, float]
    spurious: tuple[tuple[float, float], ...] = ()
    doubtful: tuple[tuple[float, float], ...] = ()
    suspension: tuple[tuple[float, float], ...] = ()
    not_keyed: tuple[tuple[float, float], ...] = field(default_factory=tuple)


def _win(f: float, rel: float = 0.01) -> tuple[float, float]:
    return (f * (1 - rel), f * (1 + rel))


KEYS: dict[str, DatasetKey] = {
    "uliege_plane": DatasetKey(
        accepted=(_acc(18.85), _acc(39.72, window=(39.55, 39.92)), _acc(40.16, window=(40.0, 40.35)),
                  _acc(87.80), _acc(89.62), _acc(97.12), _acc(105.24), _acc(118.03),
                  _acc(125.4, max_poles=2, window=(124.9, 126.1)), _acc(130.03, window=(129.4, 130.6)),
                  _acc(135.31), _acc(143.38, window=(142.6, 144.1)), _acc(166.30)),
        excitation_hz=(0.0, 200.0),
        spurious=(_win(55.4), _win(190.2)),
        doubtful=((24.0, 32.0), (194.0, 200.0)),
    ),
    "modelab_beam": DatasetKey(
        accepted=(_acc(111.99), _acc(306.85), _acc(596.37), _acc(974.14)),
        excitation_hz=(0.0, 1000.0), suspension=(_win(5.31, 0.05),), doubtful=((0.0, 1.0),),
    ),
    "ladisk_single": DatasetKey(
        accepted=tuple(_acc(f) for f in (695.7, 1898.1, 2777.8, 3671.2, 5608.0, 5975.0)),
        excitation_hz=(0.0, 6600.0), suspension=(_win(18.0, 0.05), _win(37.0, 0.05)),
    ),
    "ladisk_multi": DatasetKey(
        accepted=tuple(_acc(f) for f in (315.7, 858.7, 1668.0, 2730.8)),
        excitation_hz=(0.0, 3255.0), suspension=(_win(18.0, 0.05), _win(36.0, 0.05)),
        doubtful=(_win(3217.6),),
    ),
    "pyfrf_5impacts": DatasetKey(
        accepted=(_acc(810.3, 0.003), _acc(823.6, window=(821.0, 826.5)), _acc(831.0, window=(828.5, 834.0)),
                  _acc(851.5, 0.003), _acc(899.9, window=(898.0, 902.5)), _acc(905.5, window=(903.0, 908.0)),
                  _acc(1518.1, window=(1516.0, 1519.2)), _acc(1520.1, window=(1519.2, 1523.0))),
        excitation_hz=(0.0, 7023.0), not_keyed=((1700.0, 7023.0),),
    ),
    "f16_gvt": DatasetKey(
        accepted=tuple(_acc(f, 0.02) for f in (3.48, 3.97, 5.19, 6.61, 7.32, 9.17)),
        excitation_hz=(2.0, 15.0), doubtful=(_win(12.43, 0.03),),
    ),
    "plate_sweep": DatasetKey(
        accepted=(_acc(126.0, 0.01), _acc(215.0, 0.01), _acc(264.0, 0.01), _acc(349.0, window=(340.0, 358.0)),
                  _acc(452.0, window=(442.0, 462.0))),
        excitation_hz=(60.0, 500.0), doubtful=(_win(77.0, 0.05), _win(286.5, 0.02), _win(310.3, 0.02)),
    ),
    "pyuff_3frf": DatasetKey(
        accepted=tuple(_acc(f) for f in (51.52, 142.18, 278.67, 460.40, 687.17, 958.54)),
        excitation_hz=(0.0, 1000.0),
    ),
    "unesp_boltedbeam": DatasetKey(
        accepted=(_acc(18.80), _acc(54.01, window=(53.7, 54.3)), _acc(98.38, 0.01), _acc(271.2, 0.01)),
        excitation_hz=(0.0, 468.4), spurious=((299.5, 300.5), (419.5, 420.5)),
    ),
}


def _inside(x: float, windows: Sequence[tuple[float, float]]) -> bool:
    return any(a <= x <= b for a, b in windows)


def score(key: DatasetKey, fitted_hz: Sequence[float] | np.ndarray, success: bool) -> dict:
    """Score a fit's natural frequencies (Hz) and its ``success`` against ``key``: accepted resonances
    fitted (a pole in the window; more than ``max_poles`` there are spurious), spurious poles (in a named
    spurious window, outside the excitation, or in no window of the key), poles in doubtful, suspension or
    not-keyed windows (counted neither way), and whether ``success`` is what the key says it should be
    (true exactly when every accepted resonance is fitted and no pole is spurious)."""
    f = np.sort(np.asarray(fitted_hz, dtype=float).ravel())
    used = np.zeros(f.size, dtype=bool)
    missed: list[float] = []
    spurious: list[float] = []
    for a in key.accepted:
        idx = [i for i, x in enumerate(f) if a.window[0] <= x <= a.window[1] and not used[i]]
        if not idx:
            missed.append(a.freq_hz)
            continue
        idx.sort(key=lambda i: abs(f[i] - a.freq_hz))
        for i in idx[:a.max_poles]:
            used[i] = True
        for i in idx[a.max_poles:]:
            used[i] = True
            spurious.append(float(f[i]))
    ignored: list[float] = []
    lo, hi = key.excitation_hz
    for i, x in enumerate(f):
        if used[i]:
            continue
        if x < lo or x > hi or _inside(x, key.spurious):
            spurious.append(float(x))
        elif _inside(x, key.doubtful) or _inside(x, key.suspension) or _inside(x, key.not_keyed):
            ignored.append(float(x))
        else:
            spurious.append(float(x))
    expected = not missed and not spurious
    return {"accepted": len(key.accepted), "fitted": len(key.accepted) - len(missed), "missed": missed,
            "spurious": sorted(spurious), "ignored": ignored, "success": bool(success),
            "success_expected": expected, "honest": bool(success) == expected}
