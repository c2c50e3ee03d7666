"""HTML test report of the ULiege plane (222 FRFs x 1241 lines, 14 modes) and the ModeLAB beam.

Targets: the ULiege report written in < 5 s (content collected from the FRFs, the fit and
its stabilization, and the folder written; the fit itself is timed apart), the page < 15 MB (the
whole folder, plotly.js included), loaded and drawn by headless Chromium in < 3 s (navigation start
to the page's "drawn" mark). Needs ../shared/data, plotly (the report extra), and for the browser
column selenium + chromium + chromium-driver. Prints a table; writes the reports to --out
(default: a temporary folder, removed).

    .venv/bin/python benchmarks/speed/bench_report.py [--out DIR]
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
DATA = Path(os.environ.get("IMPACTLAB_SHARED_DATA", ROOT.parent / "shared" / "data"))   # as the tests find it

from analysis.geometry import Geometry  # noqa: E402
from analysis.report_html import build_document, run_fit, write_report  # noqa: E402
from benchmarks.accuracy.validation import modelab_beam, uliege_plane  # noqa: E402

TARGET_WRITE_S, TARGET_MB, TARGET_DRAW_S = 5.0, 15.0, 3.0


def uliege_geometry() -> Geometry:
    """The 74 impact points of ``node_shock.csv`` (mm -> m), labelled as the loader's references."""
    xyz = np.loadtxt(DATA / uliege_plane.NAME / "node_shock.csv", delimiter=",", skiprows=1) / 1000.0
    return Geometry(tuple(f"plane:{k + 1}" for k in range(xyz.shape[0])), xyz, (), name="ULiege plane: node_shock.csv")


def draw_time_s(index: Path) -> float:
    """Headless Chromium: navigation start to the page's drawn mark (s); NaN without a browser."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
        from selenium.webdriver.support.ui import WebDriverWait
    except ImportError:
        return float("nan")
    opts = webdriver.ChromeOptions()
    opts.binary_location = "/usr/bin/chromium"
    with tempfile.TemporaryDirectory() as profile:
        for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                    "--disable-component-update", "--no-first-run", "--window-size=1280,1000",
                    f"--user-data-dir={profile}"):
            opts.add_argument(arg)
        d = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=opts)
        try:
            d.get(index.resolve().as_uri())
            WebDriverWait(d, 60).until(lambda drv: drv.execute_script("return document.body.dataset.ready"))
            return float(d.execute_script("return Number(document.body.dataset.drawnMs)")) / 1000.0
        finally:
            d.quit()


def case(name: str, frf, fit_options: dict, geometry, out: Path) -> dict:
    t0 = time.perf_counter()
    fit = run_fit(frf, **fit_options)
    t_fit = time.perf_counter() - t0
    t0 = time.perf_counter()
    doc = build_document(frf, fit, geometry=geometry, input_name=name)
    index = write_report(out / name, doc)
    t_write = time.perf_counter() - t0
    size = sum(p.stat().st_size for p in index.parent.iterdir()) / 1e6
    return {"case": name, "frfs": frf.n_outputs * frf.n_references, "lines": frf.freq_hz.size,
            "modes": len(doc["modal"]["modes"]), "fit_s": t_fit, "write_s": t_write, "mb": size,
            "draw_s": draw_time_s(index), "index": index}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", help="keep the reports in this folder")
    args = p.parse_args()
    if not DATA.is_dir():
        print(f"skipped: real data not found at {DATA}")
        return 0
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_report_"))
    rows = [case("uliege_plane", uliege_plane.load(DATA), {"band": uliege_plane.BAND}, uliege_geometry(), out),
            case("modelab_beam", modelab_beam.load(DATA), {"band": modelab_beam.BAND}, None, out)]
    print(f"{'case':14s} {'FRFs':>5s} {'lines':>6s} {'modes':>5s} {'fit [s]':>8s} {'write [s]':>10s} "
          f"{'page [MB]':>10s} {'drawn [s]':>10s}")
    for r in rows:
        print(f"{r['case']:14s} {r['frfs']:5d} {r['lines']:6d} {r['modes']:5d} {r['fit_s']:8.2f} {r['write_s']:10.2f} "
              f"{r['mb']:10.2f} {r['draw_s']:10.2f}")
    u = rows[0]
    ok = u["write_s"] < TARGET_WRITE_S and u["mb"] < TARGET_MB and not u["draw_s"] >= TARGET_DRAW_S
    print(f"targets (ULiege): write < {TARGET_WRITE_S:g} s, page < {TARGET_MB:g} MB, drawn < {TARGET_DRAW_S:g} s: "
          f"{'met' if ok else 'NOT met'}")
    if args.out:
        print(f"reports: {', '.join(str(r['index']) for r in rows)}")
    else:
        shutil.rmtree(out, ignore_errors=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
