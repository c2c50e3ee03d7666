"""f16_gvt_multisine: F-16 ground vibration test, periodic random-phase multisine 2-15 Hz.

Source: GitHub emckenzie11/F16_Benchmark_Restoring_Force_ODE (HEAD e45e0a98),
``diagnostics/F16Data_FullMSine_Level1.csv``. Original: F-16 ground vibration test benchmark measured at
the Siemens LMS GVT Master Class 2014; cite J.P. Noel, M. Schoukens, "F-16 aircraft benchmark based on
ground vibration test data", Workshop on Nonlinear System Identification Benchmarks, Brussels, 2017.
The project imports it with ``acquisition import --describe`` (a CSV row, blocks of one period);
:func:`read_f16_csv` reads it here for the independent period-averaged FRF below.

FRF by period averaging
-----------------------
9 periods of N = 8192 samples at 400 Hz (df = 400/8192 = 0.0488 Hz). The first period is transient and
dropped. With ``F_p(k), X_p(k)`` the DFT of period p (p = 1..P, P = 8) at line k,

    H(k) = mean_p X_p(k) / mean_p F_p(k)

(exact for a periodic steady state: no leakage, no window). Noise from the period-to-period scatter:
``sigma_H^2(k) = var_p(X_p - H F_p) / (P |mean_p F_p|^2)`` (the output-noise variance of the averaged
FRF; ``var_p`` with P - 1 degrees of freedom). Only the excited lines (2..15 Hz) are used.
Acceleration units are not stated in the file (the FRF unit is written "EU/N").
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from analysis.frf import FRFSet
from analysis.uncertainty import crlb_poles

from .case import compare, peer_repeats, scatter_table
from .common import CaseReport, consistency_table, fit_ours_from_poles, fmt, md_table

NAME = "f16_gvt_multisine"
SOURCE = ("GitHub emckenzie11/F16_Benchmark_Restoring_Force_ODE (HEAD e45e0a98), "
          "diagnostics/F16Data_FullMSine_Level1.csv; J.P. Noel, M. Schoukens, F-16 aircraft benchmark based on "
          "ground vibration test data, Workshop on Nonlinear System Identification Benchmarks, Brussels, 2017")
N_PER = 8192
FS = 400.0
EXCITED = (2.0, 15.0)
BAND = (2.5, 14.5)


def read_f16_csv(path: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """(force[n] N, accelerations[3, n], fs Hz) from the benchmark CSV."""
    a = np.genfromtxt(path, delimiter=",", skip_header=1, usecols=(0, 2, 3, 4))
    with open(path, encoding="utf-8") as fh:
        fh.readline()
        fs = float(fh.readline().split(",")[5])
    if a.ndim != 2 or a.shape[1] != 4 or a.shape[0] % N_PER:
        raise ValueError(f"{path}: expected columns Force, Voltage, Acceleration1..3, Fs and a multiple of {N_PER} rows")
    return a[:, 0], a[:, 1:].T, fs


def period_frf(force: np.ndarray, acc: np.ndarray, fs: float, drop: int = 1) -> tuple[FRFSet, np.ndarray, np.ndarray]:
    """Period-averaged FRF over the excited lines, its noise std per line (3, n) and the per-period FRFs."""
    P = force.size // N_PER
    F = np.fft.rfft(force.reshape(P, N_PER)[drop:], axis=1)
    X = np.fft.rfft(acc.reshape(3, P, N_PER)[:, drop:], axis=2)
    f = np.fft.rfftfreq(N_PER, 1 / fs)
    k = (f >= EXCITED[0]) & (f <= EXCITED[1])
    Fm = F.mean(axis=0)
    H = X.mean(axis=1) / Fm[None, :]
    E = X - H[:, None, :] * F[None, :, :]
    var = np.sum(np.abs(E - E.mean(axis=1, keepdims=True)) ** 2, axis=1) / (X.shape[1] - 1)
    sig = np.sqrt(var / (X.shape[1] * np.abs(Fm) ** 2))
    Hp = X / F[None, :, :]
    frf = FRFSet(freq_hz=f[k], H=H[:, None, k], quantity="accelerance", outputs=("f16:1:Z", "f16:2:Z", "f16:3:Z"),
                 references=("f16:shaker:Z",), unit="EU/N", meta={"source": SOURCE, "periods": X.shape[1]})
    return frf, sig[:, k], Hp[:, :, k]


def load(data_dir: Path) -> FRFSet:
    force, acc, fs = read_f16_csv(Path(data_dir) / NAME / "F16Data_FullMSine_Level1.csv")
    return period_frf(force, acc, fs)[0]


def run(data_dir: Path, out_dir: Path) -> CaseReport:
    force, acc, fs = read_f16_csv(Path(data_dir) / NAME / "F16Data_FullMSine_Level1.csv")
    frf, sig, Hp = period_frf(force, acc, fs)
    # transient check: the first period's FRF against the steady-state average
    frf_all, _, Hp_all = period_frf(force, acc, fs, drop=0)
    d_first = np.linalg.norm(Hp_all[:, 0] - frf.H[:, 0]) / np.linalg.norm(frf.H[:, 0])
    d_other = np.median([np.linalg.norm(Hp_all[:, p] - frf.H[:, 0]) / np.linalg.norm(frf.H[:, 0])
                         for p in range(1, Hp_all.shape[1])])
    ours, peer, block, summary, plots = compare(NAME, frf, out_dir, band=BAND, plot_name=f"{NAME}.png", title=NAME)
    res = ours.result
    sub = frf.band(*ours.band)
    ks = (frf.freq_hz >= ours.band[0]) & (frf.freq_hz <= ours.band[1])
    noise_pp = float(np.mean(sig[:, ks] ** 2))
    snr = float(np.mean(np.abs(sub.H) ** 2) / noise_pp)
    cr = crlb_poles(res.model, sub.freq_hz, noise_pp)
    rows = [[fmt(res.freq_hz[i], 6), fmt(100 * res.damping[i], 3), fmt(res.freq_hz_std[i], 2), fmt(cr.freq_hz_std[i], 2),
             fmt(100 * res.damping_std[i], 2), fmt(100 * cr.damping_std[i], 2)] for i in np.argsort(res.freq_hz)]
    # period-to-period consistency: each steady-state period's FRF X_p / F_p fitted from the global poles
    periods = [FRFSet(freq_hz=frf.freq_hz, H=Hp[:, p, None, :], quantity="accelerance", outputs=frf.outputs,
                      references=frf.references, unit=frf.unit) for p in range(Hp.shape[1])]
    per = [fit_ours_from_poles(fr, res.poles_raw, ours.band).result for fr in periods]
    tab, arr = consistency_table([f"period {p + 2}" for p in range(len(per))], per, res.freq_hz)
    mm = max(ours.stab.orders)
    pf, pz = peer_repeats(periods, ours.band, mm, res.freq_hz) if peer.ok else (None, None)
    stab_tab = scatter_table(res.freq_hz, arr, pf, pz)
    md = [
        f"Three acceleration FRFs from the period-averaged spectra of 8 steady-state periods (the first, transient "
        f"period dropped: its FRF differs from the average by {100 * d_first:.3g} % against {100 * d_other:.3g} % "
        f"for a typical steady-state period). df = {fs / N_PER:.4g} Hz, excited lines 2..15 Hz.",
        "",
        block,
        "",
        md_table(["noise variance per line, E abs(e)^2", "value"], [
            ["from the period-to-period scatter (mean over lines and FRFs)", f"{noise_pp:.3g}"],
            ["from the LSFD residual (`noise_var`)", f"{res.noise_var:.3g}"],
            ["ratio fit / scatter", fmt(res.noise_var / noise_pp, 3)],
            ["mean abs(H)^2 / scatter noise (SNR)", f"{snr:.3g}"]]),
        "",
        "A fit/scatter ratio near 1 means the model leaves only noise; well above 1 means model error "
        "(unmodelled modes, nonlinearity: the F-16 benchmark has nonlinear wing-payload joints) dominates the residual, "
        "and the fit's standard deviations (from the residual) are then larger than the noise-only Cramer-Rao bound.",
        "",
        "Our standard deviations (from the residual) against the Cramer-Rao bound at the period-scatter noise level:",
        "",
        md_table(["f [Hz]", "zeta [%]", "fit std f", "CRLB f (scatter noise)", "fit std zeta [%]",
                  "CRLB zeta [%] (scatter noise)"], rows),
        "",
        "Period-to-period consistency (each steady-state period's FRF alone, LSFD from the averaged fit's poles; "
        "one period has 8 times the noise variance of the average, so the scatter should be about "
        "sqrt(8) times the CRLB above):",
        "",
        stab_tab,
    ]
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.nanmedian(arr["f_std"], axis=0) / np.nanstd(arr["f"], axis=0, ddof=1)
    summary["figures"] = {**summary.get("figures", {}), "noise_fit": float(res.noise_var), "noise_scatter": noise_pp,
                          "std_over_scatter_min": float(np.nanmin(ratio)), "std_over_scatter_max": float(np.nanmax(ratio)),
                          "std_over_scatter_median": float(np.nanmedian(ratio))}
    return CaseReport(NAME, "F-16 GVT, multisine", SOURCE, "\n".join(md), summary, plots)
