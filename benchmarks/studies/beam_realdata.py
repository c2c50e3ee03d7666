"""The ModeLAB free-free beam (real roving-hammer FRFs) against a beam model we write (docs/diagnosis-realdata.md,
section 4).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/studies/beam_realdata.py [--data ../shared/data] [--diagnose]

Data: ``modelab_beam_roving_hammer`` (GitHub alxhslm/ModeLAB, GPL-3.0): nine accelerance FRFs, hammer at
0.1 ... 1.2 m, one accelerometer at 0.5 m (point 4, the driving point). The beam's length, section and
material are not documented: the length is taken as 1.3 m (the hammer points lie symmetric about 0.65 m
and the first mode's nodes, between the hammer points at 0.25/0.375 m and 0.925/1.05 m, sit at 0.224 L
from the ends of a 1.3 m beam), steel (E/rho of aluminium is within 1 % of steel's, so the frequencies do
not tell them apart), the section's height fitted to the first mode, its width to the first mode's
driving-point residue would give the mass, but the
measured FRFs' scale is doubtful (see the printed driving-point values), so the width is taken as 30 mm:
the frequencies and the shapes, which the comparison uses, do not depend on it.

Steps:
1. The measured modes: the automatic fit (:func:`analysis.pipeline.fit_auto`, band 65-1000 Hz).
2. The model we write (``benchmarks/studies/beam_model.py``): an Euler-Bernoulli beam. What it gets wrong:
   the frequency ratios f_n / f_1.
3. Extensions, each with the stiffness scale free (the section is not known) and one parameter: the
   accelerometer's mass at 0.5 m (kg), or the section's rotary inertia, its shear deformation, or both
   (Timoshenko), each with the section's height h (its slenderness) as the parameter. Each measured mode is predicted by the extension fitted to the
   other three (leave one mode out); gain = 20 log10(rms held-out error of the plain model / of the
   extension).
4. With ``--diagnose``: ``python -m analysis diagnose`` on the real FRFs (written as UFF 58) with the
   Euler-Bernoulli beam as the simulation (``[fe]`` TOML), the FE model's causes (``mass_loading``,
   ``added_mass``, ``stiffness_shift``, ``mass_scale``, ``ground_spring``).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy.optimize import minimize_scalar  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from beam_model import beam_matrices, node_at, write_beam  # noqa: E402

from analysis.fe_model import sparse_modes  # noqa: E402

LENGTH_M = 1.3
N_EL = 520
SENSOR_M = 0.5
WIDTH0_M = 0.03


def beam_hz(theory: str, height_m: float, sensor_kg: float = 0.0, width_m: float = WIDTH0_M,
            n_modes: int = 4) -> tuple[np.ndarray, float]:
    """The first ``n_modes`` flexible natural frequencies (Hz) and the mass-normalised first mode's value at
    the sensor (1/sqrt(kg))."""
    import scipy.sparse as sp

    K, M = beam_matrices(LENGTH_M, height_m, width_m, N_EL, theory)
    if sensor_kg:
        d = np.zeros(K.shape[0])
        d[2 * node_at(SENSOR_M, LENGTH_M, N_EL)] = sensor_kg
        M = sp.csr_matrix(M + sp.diags(d))
    f, phi = sparse_modes(K, M, 1500.0 * height_m / 0.0366)
    flex = f > 1.0
    return f[flex][:n_modes], float(phi[2 * node_at(SENSOR_M, LENGTH_M, N_EL), np.flatnonzero(flex)[0]])


def measured_modes(data: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """Natural frequencies (Hz), their standard deviations and the first mode's mass-normalised shape at the
    driving point (1/sqrt(kg)) of the ModeLAB FRFs."""
    from analysis.diagnosis.entry import driving_point_shapes
    from analysis.pipeline import fit_auto
    from benchmarks.accuracy.validation import modelab_beam

    frf = modelab_beam.load(data)
    res = fit_auto(frf, band=modelab_beam.BAND)
    order = np.argsort(res.freq_hz)
    model = res.model
    shapes = driving_point_shapes(model)
    assert shapes is not None
    return (np.asarray(res.freq_hz)[order], np.asarray(res.lsfd.freq_hz_std)[order],
            float(abs(shapes[0, order[0]])))


def fit_scale(f_model: np.ndarray, f_meas: np.ndarray) -> float:
    """The stiffness scale's frequency factor that fits ``f_model`` to ``f_meas`` best (mean log ratio)."""
    return float(np.exp(np.mean(np.log(f_meas / f_model))))


def loo(predict, f_meas: np.ndarray, bounds: tuple[float, float] | None) -> tuple[np.ndarray, float]:
    """Held-out relative errors (%) of each mode (the candidate fitted to the others: its parameter by a
    bounded 1-D search, the scale in closed form) and the parameter fitted to all modes."""
    def cost(p: float, sel: np.ndarray) -> float:
        f = predict(p)
        s = fit_scale(f[sel], f_meas[sel])
        return float(np.sum(np.log(s * f[sel] / f_meas[sel]) ** 2))

    def fitted(sel: np.ndarray) -> float:
        if bounds is None:
            return 0.0
        return float(minimize_scalar(lambda p: cost(p, sel), bounds=bounds, method="bounded",
                                     options={"xatol": 1e-6 * (bounds[1] - bounds[0])}).x)

    out = np.empty(f_meas.size)
    for k in range(f_meas.size):
        sel = np.arange(f_meas.size) != k
        p = fitted(sel)
        f = predict(p)
        out[k] = 100 * (fit_scale(f[sel], f_meas[sel]) * f[k] / f_meas[k] - 1)
    return out, fitted(np.ones(f_meas.size, bool))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path(os.environ.get("IMPACTLAB_SHARED_DATA", ROOT.parent / "shared" / "data")))
    ap.add_argument("--diagnose", action="store_true", help="also run python -m analysis diagnose on the real FRFs")
    a = ap.parse_args()
    if not (a.data / "modelab_beam_roving_hammer").is_dir():
        sys.exit(f"the ModeLAB beam is not in {a.data}: give --data DIR")
    f_meas, f_std, phi1 = measured_modes(a.data)
    print("measured (Hz):", " ".join(f"{f:.3f} (+-{s:.1g})" for f, s in zip(f_meas, f_std)),
          "ratios", " ".join(f"{f / f_meas[0]:.3f}" for f in f_meas[1:]))
    # the section: height from the first mode (Euler-Bernoulli), width from the driving point's mass scaling
    f_eb, phi_model = beam_hz("euler", 0.0366)
    h = 0.0366 * f_meas[0] / f_eb[0]
    f_eb, phi_model = beam_hz("euler", h)
    width = WIDTH0_M
    print(f"section: h = {1e3 * h:.2f} mm (first mode), b = {1e3 * width:.1f} mm (assumed), mass "
          f"{7850 * LENGTH_M * h * width:.2f} kg; first mode at the driving point: measured {phi1:.3g}, "
          f"model {phi_model:.3g} 1/sqrt(kg)")
    print("Euler-Bernoulli (Hz):", " ".join(f"{f:.2f}" for f in f_eb), "errors %",
          " ".join(f"{100 * (f / m - 1):+.2f}" for f, m in zip(f_eb, f_meas)),
          "ratios", " ".join(f"{f / f_eb[0]:.3f}" for f in f_eb[1:]))
    mass = 7850 * LENGTH_M * h * width
    cands = {
        "Euler-Bernoulli (scale)": (lambda p: beam_hz("euler", h, width_m=width)[0], None),
        "+ sensor mass at 0.5 m (scale, kg)": (lambda p: beam_hz("euler", h, p, width_m=width)[0], (0.0, 0.2 * mass)),
        "rotary inertia (scale, h)": (lambda p: beam_hz("rotary", p, width_m=width)[0], (0.3 * h, 6 * h)),
        "shear deformation (scale, h)": (lambda p: beam_hz("shear", p, width_m=width)[0], (0.3 * h, 6 * h)),
        "Timoshenko: shear + rotary inertia (scale, h)": (lambda p: beam_hz("timoshenko", p, width_m=width)[0],
                                                          (0.3 * h, 6 * h)),
    }
    base = None
    print("| model (free parameters) | fitted | held-out errors % (modes 1-4) | rms % | gain dB |")
    print("|---|---|---|---|---|")
    for name, (pred, bounds) in cands.items():
        t0 = time.perf_counter()
        err, p = loo(pred, f_meas, bounds)
        rms = float(np.sqrt(np.mean(err ** 2)))
        base = rms if base is None else base
        shown = "-" if bounds is None else (f"{p:.3g} kg" if "kg" in name else f"h = {1e3 * p:.2f} mm")
        print(f"| {name} | {shown} | {' '.join(f'{e:+.3f}' for e in err)} | {rms:.3f} | "
              f"{20 * np.log10(base / rms):+.1f} | ({time.perf_counter() - t0:.1f} s)")
    # the section's height from the first mode with steel's E / rho (no fit but the stiffness scale)
    for theory in ("rotary", "shear", "timoshenko"):
        f_t = beam_hz(theory, h, width_m=width)[0]
        s = fit_scale(f_t, f_meas)
        err = 100 * (s * f_t / f_meas - 1)
        print(f"{theory}, h = {1e3 * h:.2f} mm (steel's E / rho and the first mode), scale only: "
              + " ".join(f"{s * f:.2f}" for f in f_t) + " Hz, errors % " + " ".join(f"{e:+.3f}" for e in err)
              + f", rms {np.sqrt(np.mean(err ** 2)):.3f} %")
    if a.diagnose:
        diagnose_real(a.data, h, width)


def diagnose_real(data: Path, h: float, width: float) -> None:
    """``python -m analysis diagnose`` on the ModeLAB FRFs with the Euler-Bernoulli beam as the simulation."""
    from analysis.cli_diagnose import main as diagnose_main
    from analysis.uff import write_uff58
    from benchmarks.accuracy.validation import modelab_beam

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        uff = d / "modelab.uff"
        write_uff58(str(uff), modelab_beam.load(data, modelab_beam.BAND))
        toml = write_beam(d / "euler", length_m=LENGTH_M, height_m=h, width_m=width, n_el=N_EL, theory="euler")
        cmd = ["--measured", str(uff), "--simulated", str(toml), "--band", "65:1000", "--json", str(d / "d.json")]
        print("python -m analysis diagnose --measured modelab.uff --simulated euler/model.toml --band 65:1000")
        t0 = time.perf_counter()
        rc = diagnose_main(cmd)
        print(f"exit {rc}, {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
