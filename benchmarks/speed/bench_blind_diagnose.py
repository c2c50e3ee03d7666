"""CPU time of ``diagnose`` on the blind cases of ``tests/test_diagnosis_blind.py``, and a check that two
versions of the code give the same diagnoses.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/speed/bench_blind_diagnose.py --out RUN.json
    .venv/bin/python benchmarks/speed/bench_blind_diagnose.py --compare OLD.json NEW.json

The first form runs ``diagnose`` on every hidden-effect case and on the two noise-only cases, as the test
builds them (seeded) but on the frame's whole model (the test keeps its modes up to ``MODES_HZ``), and writes
per case the verdict, every cause's effect, parameters, gain (dB) and significance, the held-out error after
the extension (dB) and this process's CPU seconds of the call.
The second prints a table of the two runs' CPU seconds per case and their totals, and compares them:
verdicts, causes (names and order) and significance equal, numeric parameters within 1e-6 relative,
gains and errors within 1e-6 dB. Run each checkout with its own tree on the path (``PYTHONPATH``). CPU
time on a shared machine still varies by some 10 %; nothing here is a test.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

#: the tolerances of the comparison: relative for parameters, absolute (dB) for gains and errors
PARAM_RTOL = 1e-6
GAIN_ATOL_DB = 1e-6


def run(out: Path) -> None:
    import numpy as np

    import tests.test_diagnosis_blind as blind
    from analysis.diagnosis import diagnose

    base = blind.base_model(None, blind.OUTS, blind.REFS)
    cases = [(f"effect{c}", c) for c in range(len(blind._ORDER))] + [("null0", None), ("null1", None)]
    rows = []
    for label, c in cases:
        if c is None:
            meas = blind._measure(base, [], 50 + int(label[-1]))
        else:
            eff = blind.draw_effect(blind._ORDER[c], np.random.default_rng(c), base, blind.F)
            meas = blind._measure(base, [eff], c)
        t = time.process_time()
        diag = diagnose(meas, base)
        cpu = time.process_time() - t
        causes = [{"effect": x["effect"], "parameters": x["parameters"], "gain_db": x["gain_db"],
                   "significant": bool(x["significant"])} for x in diag.causes]
        rows.append({"case": label, "cpu_s": cpu, "verdict": diag.verdict, "causes": causes,
                     "error_after_db": diag.error_after_db})
        print(f"{label:8s} {diag.verdict:20s} {cpu:7.2f} s", flush=True)
    out.write_text(json.dumps(rows, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o)))


def _flat(x: Any, pre: str = "") -> Iterator[tuple[str, Any]]:
    if isinstance(x, dict):
        for k, v in x.items():
            yield from _flat(v, f"{pre}.{k}")
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from _flat(v, f"{pre}[{i}]")
    else:
        yield pre, x


def _differences(a: dict, b: dict) -> tuple[list[str], float, float]:
    """What differs between two runs' case ``a`` and ``b``, the largest relative parameter difference and the
    largest gain difference (dB)."""
    bad: list[str] = []
    rel = gain = 0.0
    if a["verdict"] != b["verdict"]:
        bad.append(f"verdict {a['verdict']} / {b['verdict']}")
    if [c["effect"] for c in a["causes"]] != [c["effect"] for c in b["causes"]]:
        return bad + ["causes differ"], rel, gain
    for ca, cb in zip(a["causes"], b["causes"]):
        gain = max(gain, abs(ca["gain_db"] - cb["gain_db"]))
        if abs(ca["gain_db"] - cb["gain_db"]) > GAIN_ATOL_DB or ca["significant"] != cb["significant"]:
            bad.append(f"{ca['effect']}: gain {ca['gain_db']} / {cb['gain_db']}")
        pa, pb = dict(_flat(ca["parameters"])), dict(_flat(cb["parameters"]))
        if pa.keys() != pb.keys():
            bad.append(f"{ca['effect']}: parameters {sorted(pa)} / {sorted(pb)}")
            continue
        for k, u in pa.items():
            v = pb[k]
            if isinstance(u, (int, float)) and not isinstance(u, bool):
                r = abs(u - v) / abs(u) if u != v else 0.0
                rel = max(rel, r)
                if r > PARAM_RTOL:
                    bad.append(f"{ca['effect']}{k}: {u} / {v}")
            elif u != v:
                bad.append(f"{ca['effect']}{k}: {u} / {v}")
    if abs(a["error_after_db"] - b["error_after_db"]) > GAIN_ATOL_DB:
        bad.append(f"error after {a['error_after_db']} / {b['error_after_db']} dB")
    return bad, rel, gain


def compare(old: Path, new: Path) -> int:
    a, b = json.loads(old.read_text()), json.loads(new.read_text())
    print(f"{'case':8s} {'verdict':20s} {'old s':>7s} {'new s':>7s}  differences")
    worst_rel = worst_gain = 0.0
    n_bad = 0
    for x, y in zip(a, b):
        bad, rel, gain = _differences(x, y)
        worst_rel, worst_gain, n_bad = max(worst_rel, rel), max(worst_gain, gain), n_bad + bool(bad)
        print(f"{x['case']:8s} {x['verdict']:20s} {x['cpu_s']:7.2f} {y['cpu_s']:7.2f}  {'; '.join(bad) or 'none'}")
    print(f"{'total':29s} {sum(x['cpu_s'] for x in a):7.2f} {sum(y['cpu_s'] for y in b):7.2f}")
    print(f"largest parameter difference {worst_rel:.2g} relative, largest gain difference {worst_gain:.2g} dB; "
          f"{n_bad} of {len(a)} cases differ")
    return 1 if n_bad or len(a) != len(b) else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="write this run's diagnoses and CPU seconds to this JSON file")
    ap.add_argument("--compare", type=Path, nargs=2, metavar=("OLD", "NEW"), help="compare two runs' JSON files")
    args = ap.parse_args()
    if args.compare:
        return compare(*args.compare)
    if args.out is None:
        ap.error("give --out RUN.json or --compare OLD.json NEW.json")
    run(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
