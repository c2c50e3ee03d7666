"""Monte Carlo of the LSFD fit against the Cramer-Rao lower bound.

Case "close": 4 modes (20 Hz 1 %, 40 Hz 0.8 %, 41.6 Hz 1 % -- a pair 4 % apart -- and 75 Hz
0.5 %), 3 outputs x 2 references, accelerance, residual form "paper" with a visible LR/w^2
term (it dominates the FRF below ~12 Hz), band 8..100 Hz at 0.1 Hz (921 lines).
Case "table1": the paper's Table 1 model (one FRF, 5..200 Hz at 0.0625 Hz).

For each relative noise level (circular complex Gaussian, standard deviation = level x RMS of
the clean FRFs) ``--runs`` seeded fits by Levenberg-Marquardt start from the true poles
perturbed by 0.5 % in frequency and 20 % in damping. Per mode: RMS error of f and zeta, the
CRLB (``analysis.uncertainty.crlb_poles`` with the true model and noise variance), the ratio,
and the mean reported standard deviation over the CRLB. Pooled ratio = sqrt(mean(ratio^2))
over modes and (f, zeta). Target: pooled RMS/CRLB <= 1.1.

Run: ``.venv/bin/python benchmarks/accuracy/bench_lsfd_crlb.py [--runs 100] [--levels 0.01 0.05] [--case close table1]``
"""
from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")   # small problems: threads only add overhead

import numpy as np  # noqa: E402

from analysis.lsfd import fit_lsfd  # noqa: E402
from analysis.modal import ModalModel, pole_from_fz, synthesize  # noqa: E402
from analysis.uncertainty import crlb_poles  # noqa: E402


def case_close() -> tuple[ModalModel, np.ndarray]:
    rng = np.random.default_rng(0)
    fn = np.array([20.0, 40.0, 41.6, 75.0])
    zeta = np.array([0.010, 0.008, 0.010, 0.005])
    lam = pole_from_fz(fn, zeta)
    psi = rng.normal(size=(3, 4)) + 0.1j * rng.normal(size=(3, 4))
    L = rng.normal(size=(4, 2)) + 0.05j * rng.normal(size=(4, 2))
    R = np.einsum("or,rj->ojr", psi, L) * 1j * np.abs(lam)
    ur = 0.3 * (rng.normal(size=(3, 2)) + 1j * rng.normal(size=(3, 2)))
    lr = 3e5 * (rng.normal(size=(3, 2)) + 1j * rng.normal(size=(3, 2)))
    model = ModalModel(lam, R, quantity="accelerance", residual_form="paper", upper_residual=ur, lower_residual=lr)
    return model, np.arange(8.0, 100.0 + 1e-9, 0.1)


def case_table1() -> tuple[ModalModel, np.ndarray]:
    fn = np.array([12.884, 34.884, 50.769, 81.690, 158.982])
    zeta = np.array([0.86, 0.39, 0.24, 0.52, 0.54]) / 100
    R = np.array([-0.663 - 2.431j, 0.596 + 3.016j, 3.842 - 3.421j, 1.567 - 0.095j, -0.136 - 0.090j])
    model = ModalModel(pole_from_fz(fn, zeta), R[None, None, :], quantity="accelerance", residual_form="paper",
                       upper_residual=-0.053 + 0.011j, lower_residual=-2.750 + 1.095j)
    return model, np.arange(5.0, 200.0 + 1e-9, 0.0625)


CASES = {"close": case_close, "table1": case_table1}


def monte_carlo(model: ModalModel, freq: np.ndarray, level: float, runs: int, seed: int, method: str) -> dict:
    clean = synthesize(model, freq)
    rms = np.sqrt(np.mean(np.abs(clean.H) ** 2))
    sd = level * rms
    rng = np.random.default_rng(seed)
    m = model.poles.size
    sign = np.where(np.arange(m) % 2 == 0, 1.0, -1.0)
    p0 = pole_from_fz(model.freq_hz * (1 + 0.005 * sign), model.damping * (1 + 0.2 * sign[::-1]))
    ef, ez, sf, sz = [], [], [], []
    fails = 0
    t0 = time.perf_counter()
    for _ in range(runs):
        noise = sd / np.sqrt(2) * (rng.normal(size=clean.H.shape) + 1j * rng.normal(size=clean.H.shape))
        frf = type(clean)(freq, clean.H + noise, quantity=clean.quantity)
        res = fit_lsfd(frf, p0, method=method, residual_form=model.residual_form)
        if not res.success:
            fails += 1
            continue
        ef.append(res.freq_hz - model.freq_hz)
        ez.append(res.damping - model.damping)
        sf.append(res.freq_hz_std)
        sz.append(res.damping_std)
    elapsed = time.perf_counter() - t0
    b = crlb_poles(model, freq, sd ** 2)
    ef, ez = np.array(ef), np.array(ez)
    out = {
        "rms_f": np.sqrt(np.mean(ef ** 2, axis=0)), "rms_z": np.sqrt(np.mean(ez ** 2, axis=0)),
        "bias_f": ef.mean(axis=0), "bias_z": ez.mean(axis=0),
        "crlb_f": b.freq_hz_std, "crlb_z": b.damping_std,
        "rep_f": np.mean(sf, axis=0), "rep_z": np.mean(sz, axis=0),
        "fails": fails, "n": len(ef), "time": elapsed,
    }
    ratios = np.concatenate([out["rms_f"] / out["crlb_f"], out["rms_z"] / out["crlb_z"]])
    out["pooled"] = float(np.sqrt(np.mean(ratios ** 2)))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="LSFD Monte Carlo against the Cramer-Rao bound")
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--levels", type=float, nargs="+", default=[0.01, 0.05])
    ap.add_argument("--case", nargs="+", default=["close", "table1"], choices=sorted(CASES))
    ap.add_argument("--method", default="lm", choices=["lm", "gn"])
    ap.add_argument("--seed", type=int, default=2026)
    a = ap.parse_args(argv)
    worst = 0.0
    for name in a.case:
        model, freq = CASES[name]()
        for level in a.levels:
            r = monte_carlo(model, freq, level, a.runs, a.seed + int(round(1e4 * level)), a.method)
            worst = max(worst, r["pooled"])
            print(f"\ncase {name}: noise {level:.0%} of RMS, {r['n']} successful fits of {a.runs} "
                  f"({r['fails']} failed), method {a.method}, {r['time']:.1f} s")
            print(f"{'mode':>4} {'f [Hz]':>9} {'zeta[%]':>8} | {'RMS df':>9} {'CRLB f':>9} {'ratio':>6} {'rep/CRLB':>8}"
                  f" | {'RMS dz':>9} {'CRLB z':>9} {'ratio':>6} {'rep/CRLB':>8} | {'bias f/CRLB':>11} {'bias z/CRLB':>11}")
            for k in range(model.poles.size):
                print(f"{k + 1:>4} {model.freq_hz[k]:9.3f} {100 * model.damping[k]:8.3f} | "
                      f"{r['rms_f'][k]:9.3g} {r['crlb_f'][k]:9.3g} {r['rms_f'][k] / r['crlb_f'][k]:6.3f} "
                      f"{r['rep_f'][k] / r['crlb_f'][k]:8.3f} | "
                      f"{r['rms_z'][k]:9.3g} {r['crlb_z'][k]:9.3g} {r['rms_z'][k] / r['crlb_z'][k]:6.3f} "
                      f"{r['rep_z'][k] / r['crlb_z'][k]:8.3f} | "
                      f"{r['bias_f'][k] / r['crlb_f'][k]:11.3f} {r['bias_z'][k] / r['crlb_z'][k]:11.3f}")
            print(f"pooled RMS/CRLB = {r['pooled']:.3f}  (Monte Carlo spread of a ratio from {r['n']} runs: "
                  f"about +-{1 / np.sqrt(2 * r['n']):.3f})")
    print(f"\nworst pooled RMS/CRLB: {worst:.3f} (target <= 1.1): {'PASS' if worst <= 1.1 else 'FAIL'}")
    return 0 if worst <= 1.1 else 1


if __name__ == "__main__":
    sys.exit(main())
