"""What a physical diagnosis keeps in memory on a fine frame, against ``DIAGNOSIS_BYTES_PER_DOF2``.

Run by hand (not a test; a minute at x 4)::

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/speed/bench_diagnosis_memory.py 2 4

For each factor the default frame's members get that many times their elements and the kept state of a diagnosis
is built the way a search builds it: the model's mesh-convergence copy (twice as fine) solved, every option of
every cause solved once on the frame (one reduced space per set of changed parts) and again on top of three first
causes (the pair search's frames, :meth:`simulator.physical.FrameVariants.on_top`). Printed: the bytes traced
(``tracemalloc``: numpy's arrays included) held at the end and at the peak, per squared degree of freedom, the
process's peak resident memory growth, and what the reduced spaces, the kept answers and the finer copy hold.
"""
from __future__ import annotations

import os
import resource
import sys
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from simulator.config import FrameConfig  # noqa: E402
from simulator.physical import DIAGNOSIS_BYTES_PER_DOF2, FrameVariants  # noqa: E402

FMAX_HZ = 900.0


def every_option(sim: FrameVariants) -> None:
    """Every cause at every option, once (its parameters off their nominal)."""
    for c in sim.causes():
        p = {s.name: (s.nominal if s.nominal is not None else 0.1) * 0.9 + 0.05 for s in c.params}
        for o in c.options or (None,):
            sim.modes(c.name, dict(p) if o is None else {**p, str(c.choice): o}, FMAX_HZ)


def space_bytes(sim: FrameVariants) -> int:
    tot = 0
    for space, at in sim._spaces.values():
        if space is not None and at is not None:
            tot += sum(a.nbytes for a in vars(space).values() if hasattr(a, "nbytes")) + at.nbytes
            tot += sum(a.nbytes for a in (*space.kparts.values(), *space.mparts.values()))
    return tot


def run(mult: int) -> None:
    cfg = FrameConfig.load(None).with_overrides({"components": {
        "left": {"n_elements": 10 * mult}, "right": {"n_elements": 10 * mult}, "top": {"n_elements": 8 * mult}}})
    outputs = [f"left:{9 * mult}:Y", f"top:{4 * mult}:X", f"right:{4 * mult}:-Z"]
    references = [f"right:{6 * mult}:-X"]
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    tracemalloc.start()
    t = time.process_time()
    fv = FrameVariants(cfg, outputs, references)
    n = fv.frame.n_dof
    fv.converged_below_hz()
    fv.refined_model()
    every_option(fv)
    e = fv.elements[3]
    firsts: list[list[tuple[str, dict[str, object]]]] = [
        [("element_stiffness", {"element": e, "factor": 0.4})],
        [("element_stiffness", {"element": e, "factor": 0.41}), ("stiffness_shift", {"stiffness_factor": 1.01})],
        [("joint_stiffness", {"joint": fv.places["joint"][0], "factor_translational": 0.1, "factor_rotational": 0.2})]]
    for first in firsts:
        every_option(fv.on_top(first))
    now, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0) * 1024
    memo = sum(a.nbytes for v in fv._memo.values() for a in v)
    fine = fv.refined(2)
    print(f"| x {mult} | {n} | {len(fv._spaces)} | {now / 1e6:.1f} ({now / n**2:.0f}) | {peak / 1e6:.1f} ({peak / n**2:.0f}) | "
          f"{rss / 1e6:.1f} ({rss / n**2:.0f}) | {space_bytes(fv) / 1e6:.1f} | {memo / 1e6:.2f} | "
          f"{(fine._K0.nbytes + fine._M0.nbytes) / 1e6:.1f} | {time.process_time() - t:.1f} |")


def main() -> None:
    print(f"DIAGNOSIS_BYTES_PER_DOF2 = {DIAGNOSIS_BYTES_PER_DOF2}\n")
    print("| elements | DOFs | spaces on the frame | kept, MB (B/DOF^2) | peak, MB (B/DOF^2) | peak RSS growth, MB "
          "(B/DOF^2) | one frame's spaces, MB | kept answers, MB | finer copy's K, M, MB | CPU (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for mult in (int(a) for a in sys.argv[1:] or ("2", "4")):
        run(mult)


if __name__ == "__main__":
    main()
