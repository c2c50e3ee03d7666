"""The physical diagnosis's kernel: accuracy of the eigen-solves with stiff springs, the cost of a reduced
and a full solve by basis size, and the cost of one candidate with and without derivatives.

Run by hand (not a test; on one core about a minute)::

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/speed/bench_diagnosis_kernel.py

1. Accuracy: the lowest natural frequencies up to 700 Hz of the default frame with springs stiffened up to x 100,
   by the direct solve ``eigh(K, M)``, the full model (:meth:`simulator.physical.FrameVariants.exact_modes_of`)
   and the reduced model (``modes_of``), against the energy quotients of the modes (each matrix summed as its
   parts' energies: an independent reference, stationary at an eigenvector).
2. Basis size: the reduced solve of a uniform stiffness change with a local one (the springs' static responses
   make the basis large) and of one local change, against the full solve, at 420, 700 and 900 Hz.
3. One candidate: an element's stiffness searched on top of a uniform stiffness change (the pair search's
   commonest candidate), its modes with the residuals, and with their derivatives (the fits' Jacobian).
CPU times (``time.process_time``), milliseconds. ``--write`` replaces ``bench_diagnosis_kernel.md`` with the run;
the records of the kernel's changes measured before and after (fleet units, the diagnosis tests) are in that
file's history in version control.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import scipy.linalg  # noqa: E402

import simulator.ritz as ritz  # noqa: E402
from analysis.diagnosis.physical import MeasuredModes, residuals, residuals_jac  # noqa: E402
from analysis.diagnosis.physical_pairs import OnTop  # noqa: E402
from benchmarks.results import add_write_option, recorded  # noqa: E402
from simulator.physical import FrameVariants  # noqa: E402

#: this benchmark's results file (``--write`` replaces it with the run's figures)
RESULTS = Path(__file__).with_name("bench_diagnosis_kernel.md")

OUTS = ["right:6:-X", "right:4:-X", "left:6:X", "top:4:Z", "top:2:Z", "left:9:Y"]
REFS = ["right:6:-X"]
STIFF = {
    "one joint's rotational springs x 96": [
        ("joint_stiffness", {"joint": "left:10", "factor_translational": 1.0, "factor_rotational": 96.0})],
    "and every joint's x 100": [
        ("joint_stiffness", {"joint": "left:10", "factor_translational": 1.0, "factor_rotational": 96.0}),
        ("joint_stiffness", {"factor_translational": 100.0, "factor_rotational": 100.0})],
    "every support's and joint's x 100": [
        ("support_stiffness", {"factor_translational": 100.0, "factor_rotational": 100.0}),
        ("joint_stiffness", {"factor_translational": 100.0, "factor_rotational": 100.0})],
    "unchanged": [],
}
SHIFT = ("stiffness_shift", {"stiffness_factor": 1.02})
SIZES = {
    "crack + uniform": [("element_stiffness", {"element": "top:1", "factor": 0.3}), SHIFT],
    "soft joint + uniform": [("joint_stiffness", {"joint": "left:10", "factor_translational": 0.1,
                                                  "factor_rotational": 1.0}), SHIFT],
    "2 kg + uniform": [("added_mass", {"point": "top:4", "mass_kg": 2.0}), SHIFT],
    "crack": [("element_stiffness", {"element": "top:1", "factor": 0.3})],
}


def energy_quotient(fv: FrameVariants, changes: list, phi: np.ndarray) -> np.ndarray:
    scale, k, m = fv._coefficients(changes)

    def form(parts: dict, coefficients: dict) -> np.ndarray:
        return sum(c * np.einsum("im,ij,jm->m", phi[parts[q].dofs], parts[q].block, phi[parts[q].dofs])
                   for q, c in coefficients.items())

    return scale * form(fv._kparts, k) / form(fv._mparts, m)


def per_call_ms(fn, n: int) -> float:
    t = time.process_time()
    for _ in range(n):
        fn()
    return (time.process_time() - t) / n * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        run()


def run() -> None:
    """The three parts, printed as markdown tables."""
    fv = FrameVariants(None, OUTS, REFS)
    print("## 1. Natural frequencies up to 700 Hz with stiff springs: largest relative error against the energy "
          "quotients\n")
    print("| springs | eigh(K, M) | full model | reduced model |\n|---|---|---|---|")
    for name, changes in STIFF.items():
        K, M = fv.matrices_of(changes)
        w2, phi = scipy.linalg.eigh(K, M, subset_by_value=(1.0, (2 * np.pi * 700.0) ** 2))
        ref = np.sqrt(energy_quotient(fv, changes, phi)) / (2 * np.pi)
        direct = np.sqrt(w2) / (2 * np.pi)
        full = fv.exact_modes_of(changes, 700.0)[0]
        red = fv.modes_of(changes, 700.0)[0] if changes else full
        print(f"| {name} | {np.max(np.abs(direct / ref - 1)):.1e} | {np.max(np.abs(full / ref - 1)):.1e} | "
              f"{np.max(np.abs(red / ref - 1)):.1e} |")

    print("\n## 2. A candidate's solve by basis size (ms per candidate; the basis built once)\n")
    print(f"frame: {fv.frame.n_dof} unknowns; MAX_FRACTION = {ritz.MAX_FRACTION}\n")
    print("| change | band (Hz) | basis | fraction of n | reduced (ms) | full (ms) | basis (ms) | largest difference |")
    print("|---|---|---|---|---|---|---|---|")
    saved = ritz.MAX_FRACTION
    ritz.MAX_FRACTION = 1.0
    try:
        for fmax in (420.0, 700.0, 900.0):
            for name, changes in SIZES.items():
                fv._memo.clear()
                fv._spaces.clear()
                t = time.process_time()
                fv._modes_reduced(changes, fmax)
                tb = (time.process_time() - t) * 1e3
                ((space, _),) = fv._spaces.values()
                tr = per_call_ms(lambda c=changes, b=fmax: fv._modes_reduced(c, b), 40)
                te = per_call_ms(lambda c=changes, b=fmax: fv.exact_modes_of(c, b), 40)
                f = fv._modes_reduced(changes, fmax)[0]
                g = fv.exact_modes_of(changes, fmax)[0]
                print(f"| {name} | {fmax:.0f} | {space.size} | {space.size / fv.frame.n_dof:.2f} | {tr:.2f} | {te:.2f} | "
                      f"{tb:.1f} | {np.max(np.abs(f / g - 1)):.0e} |")
    finally:
        ritz.MAX_FRACTION = saved
        fv._spaces.clear()
        fv._memo.clear()

    print("\n## 3. One candidate: a crack on top of a uniform stiffness change (ms, with the residuals)\n")
    model = fv.model_of([("element_stiffness", {"element": "top:1", "factor": 0.4})])
    keep = model.freq_hz < 420.0
    mm = MeasuredModes(model.freq_hz[keep], 1e-4 * model.freq_hz[keep],
                       model.residues[..., keep].reshape(-1, int(keep.sum())))
    values = np.exp(np.linspace(np.log(0.02), np.log(2.0), 25))
    elements = fv.elements[:20]
    top = OnTop(fv, [SHIFT])

    def direct() -> None:
        for e in elements:
            for v in values:
                residuals(mm, *fv.modes_of([SHIFT, ("element_stiffness", {"element": e, "factor": float(v)})], 420.0))

    def on_top() -> None:
        for e in elements:
            for v in values:
                residuals(mm, *top.modes("element_stiffness", {"element": e, "factor": float(v)}, 420.0))

    def with_jacobian() -> None:
        for e in elements:
            for v in values:
                residuals_jac(mm, *top.modes_jac_of([("element_stiffness", {"element": e, "factor": float(v)})], 420.0,
                                                    [(0, "factor")]))

    n = len(elements) * values.size
    for name, fn in (("modes, both changes in one basis", direct), ("modes, on top of the uniform change", on_top),
                     ("modes and derivatives, on top", with_jacobian)):
        fn()                                  # the bases built, then the candidates timed afresh
        fv._memo.clear()
        top._top._memo.clear()                # type: ignore[union-attr]
        t = time.process_time()
        fn()
        print(f"- {name}: {(time.process_time() - t) / n * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
