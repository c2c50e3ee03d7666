"""ladisk_beam_impact: free-free steel beams, FRFs estimated here from raw hammer time data.

Source: GitHub ladisk/open_source_research_in_structural_dynamics (University of Ljubljana, LADISK),
``data/acceleration.lvm`` (HEAD f5d6fd5d) and ``data/acceleration_multi.lvm`` (commit 5b97e4b0), MIT.
Read with the project's :func:`acquisition.importers.read_lvm` (decimal comma, one segment per hit).

* ``acceleration.lvm``: one hit at 50 kHz, 50 030 samples, [acceleration g, force N].
* ``acceleration_multi.lvm``: four hits on a different beam at 25.6 kHz, 25 620 samples each,
  [force N, acceleration m/s^2, an unidentified voltage].

Known truth: for a free-free Euler-Bernoulli beam the bending frequencies scale as ``(beta_n L)^2`` with
``beta_n L = 4.7300, 7.8532, 10.9956, 14.1372``: ratios to the first 1, 2.757, 5.404, 8.933. Shear and
rotary inertia (Timoshenko) lower the higher ratios a little; a wrong pole bookkeeping would not.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from acquisition.importers import read_lvm
from analysis.frf import FRFSet
from analysis.spectra import WindowSettings

from .case import compare, peer_repeats, scatter_table
from .common import CaseReport, consistency_table, fit_ours_from_poles
from .timedata import impact_frf, per_hit_frfs

NAME = "ladisk_beam_impact"
SOURCE = ("GitHub ladisk/open_source_research_in_structural_dynamics, data/acceleration.lvm (HEAD f5d6fd5d) and "
          "data/acceleration_multi.lvm (commit 5b97e4b0), MIT")
G = 9.80665
BETA_L = np.array([4.7300, 7.8532, 10.9956, 14.1372])
BAND_SINGLE = (300.0, 6500.0)
BAND_MULTI = (200.0, 3000.0)
#: the analyst's key for the single hit, written from the evidence before the band rule for FRFs without
#: force spectra was tuned: the bending series 1-4 (ratios 1, 2.728, 5.277, 8.588 to the first against
#: Euler-Bernoulli's 2.757, 5.404, 8.933, lowered by shear as expected); two weak modes outside the series
#: (residues 1/30 and 1/80 of their neighbours', stable to 0.01 % between the recording's and the UFF
#: export's fits: torsion or the other bending plane); the two suspension modes of the free-free beam
#: (peaks 14 and 25 dB high, 19 times below the first bending mode); the force's end: its autospectrum
#: 20 dB below its low-frequency level at 6.42 kHz (import's default windows) to 6.58 kHz (WIN_SINGLE).
#: Above it the FRF still shows the fifth bending mode (8.75 kHz) but the force is 30 dB down: no pole there.
KEY_SINGLE_BENDING_HZ = (695.7, 1898.1, 3671.2, 5975.0)
KEY_SINGLE_WEAK_HZ = (2777.8, 5608.0)
KEY_SINGLE_SUSPENSION_HZ = (18.0, 37.0)
KEY_SINGLE_FORCE_END_HZ = 6600.0
WIN_SINGLE = WindowSettings(force_width_s=0.002, force_taper_s=0.001)
#: the multi-hit records still ring at 1.5 % of the peak at the block end: exponential window to 10 %
WIN_MULTI = WindowSettings(force_width_s=0.002, force_taper_s=0.001, exp_window_tau_s=1.0 / np.log(10.0))


def load_single(data_dir: Path) -> FRFSet:
    """FRF of the single 50 kHz hit (accelerance, (m/s^2)/N)."""
    t = read_lvm(Path(data_dir) / NAME / "acceleration.lvm")
    h = t.hits[0]
    return impact_frf([(h[1], h[0] * G)], t.fs_hz, WIN_SINGLE, outputs=("beam1:2:Z",), reference="beam1:1:Z",
                      unit="(m/s^2)/N", meta={"source": "acceleration.lvm"})


def multi_hits(data_dir: Path) -> tuple[list, float]:
    t = read_lvm(Path(data_dir) / NAME / "acceleration_multi.lvm")
    return [(h[0], h[1]) for h in t.hits], t.fs_hz


def load_multi(data_dir: Path) -> FRFSet:
    """H1 averaged over the four 25.6 kHz hits."""
    hits, fs = multi_hits(data_dir)
    return impact_frf(hits, fs, WIN_MULTI, outputs=("beam2:2:Z",), reference="beam2:1:Z", unit="(m/s^2)/N",
                      meta={"source": "acceleration_multi.lvm"})


def bending_ratios(f_hz: np.ndarray) -> list[tuple[float, float, float]]:
    """For each free-free bending ratio, the fitted mode closest to ``f_1 * ratio`` within 10 %:
    (f Hz, measured ratio, Euler-Bernoulli ratio). ``f_1`` is the lowest fitted mode."""
    f = np.sort(np.asarray(f_hz))
    truth = (BETA_L / BETA_L[0]) ** 2
    out = []
    for r in truth:
        k = int(np.argmin(np.abs(f / f[0] - r)))
        if abs(f[k] / f[0] - r) / r < 0.1:
            out.append((float(f[k]), float(f[k] / f[0]), float(r)))
    return out


def _ratios(f: np.ndarray) -> str:
    rows = bending_ratios(f)
    return ", ".join(f"{a:.5g} Hz: {b:.3f} ({c:.3f})" for a, b, c in rows)


def run(data_dir: Path, out_dir: Path) -> CaseReport:
    one = load_single(data_dir)
    o1, p1, b1, s1, pl1 = compare(NAME + " (1 hit, 50 kHz)", one, out_dir, band=BAND_SINGLE, pair=(0, 0),
                                  plot_name=f"{NAME}_single.png", title="ladisk beam, 1 hit @ 50 kHz")
    multi = load_multi(data_dir)
    o2, p2, b2, s2, pl2 = compare(NAME + " (4 hits, 25.6 kHz)", multi, out_dir, band=BAND_MULTI, pair=(0, 0),
                                  plot_name=f"{NAME}_multi.png", title="ladisk beam, 4 hits @ 25.6 kHz")
    hits, fs = multi_hits(data_dir)
    frfs = per_hit_frfs(hits, fs, WIN_MULTI, outputs=("beam2:2:Z",), reference="beam2:1:Z")
    per = [fit_ours_from_poles(fr, o2.result.poles_raw, o2.band).result for fr in frfs]
    tab, arr = consistency_table([f"hit {k + 1}" for k in range(len(per))], per, o2.result.freq_hz)
    pf, pz = (peer_repeats(frfs, o2.band, max(o2.stab.orders), o2.result.freq_hz) if p2.ok else (None, None))
    stab_tab = scatter_table(o2.result.freq_hz, arr, pf, pz)
    md = [
        "FRFs estimated here from the raw time data with `analysis.spectra` (force window 2 ms + 1 ms taper from "
        "10 samples before the force onset; H1). The single 50 kHz hit decays to 0.04 % of its peak within the "
        "block, so no exponential window; the four 25.6 kHz hits still ring at 1.5 %, so an exponential window "
        f"decaying to 10 % at the block end (tau = {WIN_MULTI.exp_window_tau_s:.4g} s) is applied and removed by the fitter "
        "(`exp_window_tau_s`).",
        "",
        "### One hit at 50 kHz",
        "",
        b1,
        "",
        f"Frequency ratios f_n/f_1 (free-free Euler-Bernoulli in brackets): {_ratios(o1.result.freq_hz)}.",
        "",
        "### Four hits at 25.6 kHz (averaged H1)",
        "",
        b2,
        "",
        f"Frequency ratios f_n/f_1 (free-free Euler-Bernoulli in brackets): {_ratios(o2.result.freq_hz)}.",
        "",
        "Hit-to-hit consistency (each hit's own H1, LSFD from the averaged fit's poles):",
        "",
        tab,
        "",
        "Scatter over the four hits, impactlab vs sdypy-EMA (same hints for every hit):",
        "",
        stab_tab,
    ]
    s1["case"], s2["case"] = "ladisk_beam (1 hit)", "ladisk_beam (4 hits)"
    return CaseReport(NAME, "LADISK free-free beams, raw hammer time data", SOURCE, "\n".join(md), [s1, s2], pl1 + pl2)
