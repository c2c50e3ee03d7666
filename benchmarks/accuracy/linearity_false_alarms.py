"""False alarms of the linearity check on a linear structure, and its detection of a real nonlinearity.

Each pair is two recordings made through the simulated analyser (``sim://``, the default set-up:
6400 Hz, 1.28 s records, 5 % exponential window; three hammer points right:6:-X, left:6:X, top:4:Z,
5 accepted hits each, the default three accelerometers), one with the hammer's nominal peak force at
40 N and one at 200 N, each with its own seed; the two are compared by
:func:`analysis.linearity.compare_levels` (levels: the recordings' median peak force, band from the
soft level's data) as ``python -m analysis linearity soft.h5 hard.h5`` does.

* ``linear frame``: the default frame; a ``nonlinear`` verdict is a false alarm (0 expected).
* ``friction joint``: the right column-beam joint as an Iwan micro-slip spring (2e4 N m/rad, slip
  moment 1.5 N m, ``simulator.nonlinear_joint``); a ``nonlinear`` verdict is a detection.

Each row is judged twice on the same fits: with the standard deviations the check uses (the fits' own,
widened per mode to the noise the data show on that mode's lines: coherence and window,
``analysis.uncertainty.mode_noise_factor``) and with the fits' own alone (one noise level for the whole
band, as before that widening). ``largest |z|``: the largest change over its standard deviation among
the judged modes (frequency or damping) over all pairs.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/accuracy/linearity_false_alarms.py [--pairs 30] [--joint-pairs 10]

Run by hand (minutes); the figures of the last run are in ``linearity_false_alarms.results.md``.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path
from unittest import mock

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from acquisition.cli_capture import main as capture  # noqa: E402
from analysis import linearity  # noqa: E402
from analysis.inputs import load_input  # noqa: E402

sys.path.insert(0, str(ROOT))  # the repository, for benchmarks.results
from benchmarks.results import add_write_option, recorded  # noqa: E402

#: this benchmark's results file (``--write`` replaces it with the run's figures)
RESULTS = Path(__file__).with_name("linearity_false_alarms.results.md")

POINTS = "right:6:-X,left:6:X,top:4:Z"
LEVELS_N = (40.0, 200.0)
JOINT = ('[nonlinear]\nlaw = "iwan"\njoint = "right:10"\naxis = "ry"\nslip_moment_nm = 1.5\n'
         "stiffness_nm_per_rad = 2e4\n")


def _record(folder: Path, name: str, force_n: float, seed: int, joint: bool) -> Path:
    cfg = folder / f"{name}.toml"
    cfg.write_text(f"[hammer]\namplitude_n = {force_n}\n" + (JOINT if joint else ""))
    out = folder / f"{name}.h5"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        rc = capture(["--device", f"sim://?seed={seed}&config={cfg}", "--out", str(out), "--points", POINTS,
                      "--hits", "5", "--auto", "-q", "--overwrite"])
    if rc != 0:
        raise RuntimeError(f"capture {name} (seed {seed}) failed with exit code {rc}")
    return out


def _level(path: Path) -> float:
    got = linearity.recording_hits(path)
    assert got is not None
    return float(np.median([np.max(np.abs(h.force)) for h in got[0]]))


def _largest_z(res: linearity.LinearityResult) -> float:
    z = [max(abs(m.df_percent) / m.df_std_percent, abs(m.dzeta_percent) / m.dzeta_std_percent)
         for m in res.modes if m.determined and m.df_std_percent > 0 and m.dzeta_std_percent > 0]
    return max(z, default=0.0)


def pairs(n: int, joint: bool, seed0: int, folder: Path) -> dict:
    """``n`` pairs; per rule (``data``: the check's, ``fit``: the fits' own) the nonlinear verdicts and the
    largest |z|, and one line per pair."""
    out: dict = {"data": [0, 0.0], "fit": [0, 0.0], "rows": []}
    for i in range(n):
        t = time.perf_counter()
        soft = _record(folder, "soft", LEVELS_N[0], seed0 + 2 * i, joint)
        hard = _record(folder, "hard", LEVELS_N[1], seed0 + 2 * i + 1, joint)
        sets, levels = [load_input(soft), load_input(hard)], [_level(soft), _level(hard)]
        res = linearity.compare_levels(sets, levels)
        with mock.patch.object(linearity, "data_noise_factor", lambda fit, frf, band: np.ones(fit.poles_raw.size)):
            own = linearity.compare_levels(sets, levels)            # the same fits (deterministic), their own sd
        line = [f"  pair {i + 1:2d}: {levels[0]:5.1f} / {levels[1]:5.1f} N"]
        for key, r in (("data", res), ("fit", own)):
            out[key][0] += r.verdict == "nonlinear"
            out[key][1] = max(out[key][1], _largest_z(r))
            sig = ", ".join(f"{m.freq_hz:.0f} Hz df {m.df_percent:+.3f} % dzeta {m.dzeta_percent:+.1f} %"
                            for m in r.modes if m.significant)
            line.append(f"{key}: {r.verdict}" + (f" ({sig})" if sig else ""))
        out["rows"].append("  ".join(line) + f"  [{time.perf_counter() - t:.0f} s]")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pairs", type=int, default=30, help="pairs of the linear frame (default 30)")
    ap.add_argument("--joint-pairs", type=int, default=10, help="pairs of the frame with the friction joint")
    ap.add_argument("-v", "--verbose", action="store_true", help="one line per pair")
    add_write_option(ap, RESULTS)
    args = ap.parse_args()
    with recorded(RESULTS, args.write):
        _run(args)


def _run(args: argparse.Namespace) -> None:
    """The run itself (what :func:`main` records with ``--write``)."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        lin = pairs(args.pairs, False, 5000, Path(tmp))
        nl = pairs(args.joint_pairs, True, 7000, Path(tmp)) if args.joint_pairs else None
    print(f"linearity at {LEVELS_N[0]:.0f} N and {LEVELS_N[1]:.0f} N, captured through sim:// "
          f"(3 points x 5 hits per level)\n")
    print(f"{'structure':16s} {'pairs':>5s}  {'standard deviations':34s} {'nonlinear':>9s}  {'largest |z|':>11s}")
    rows = [("linear frame", args.pairs, lin)] + ([("friction joint", args.joint_pairs, nl)] if nl else [])
    for name, n, r in rows:
        for key, what in (("data", "fit's, widened to the data's noise"), ("fit", "fit's own (one noise level)")):
            print(f"{name:16s} {n:5d}  {what:34s} {r[key][0]:4d} / {n:<3d}  {r[key][1]:11.1f}")
    if args.verbose:
        for name, _, r in rows:
            print(f"\n{name}:")
            print("\n".join(r["rows"]))
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
