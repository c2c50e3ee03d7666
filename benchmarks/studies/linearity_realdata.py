"""Linearity of real structures: the bolted beam at two drive levels, and the natural force spread of
the five pyFRF hits and the four LADISK hits.

* ``unesp_bert_boltedbeam_subset`` (UNESP-BERT, SHM Lab UNESP Ilha Solteira; non-commercial research):
  analyser H1 at 0.05 V and 0.30 V random drive, compared by :func:`analysis.linearity.compare_levels`
  (and by ``python -m analysis linearity`` on the two levels written as UFF 58 files).
* ``pyfrf_hammer_5impacts`` (ladisk/pyFRF, MIT) and ``ladisk_beam_impact`` ``acceleration_multi.lvm``
  (LADISK, MIT): every hit is its own level (its peak force); each hit's FRF is fitted by LSFD from the
  average's poles, and per mode the frequency is regressed on log10(peak force): the slope (% per decade
  of force) with its standard deviation from the fits' own.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/studies/linearity_realdata.py [--data ../shared/data]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from analysis.linearity import compare_levels  # noqa: E402
from benchmarks.accuracy.validation import ladisk_beam, pyfrf_5impacts, unesp_boltedbeam  # noqa: E402
from benchmarks.accuracy.validation.timedata import per_hit_frfs  # noqa: E402


def bolted_beam(data: Path) -> None:
    lo, hi = unesp_boltedbeam.load(data, "0p05"), unesp_boltedbeam.load(data, "0p30")
    res = compare_levels([lo, hi], [0.05, 0.30], band=(10.0, 400.0))
    print("bolted beam, 0.05 V -> 0.30 V, band 10-400 Hz:", res.verdict)
    print(f"{'f [Hz]':>9s} {'df [%]':>8s} {'+-':>6s} {'dzeta [%]':>9s} {'+-':>6s} {'df/dec':>7s} significant")
    for m in res.modes:
        print(f"{m.freq_hz:9.3f} {m.df_percent:+8.3f} {m.df_std_percent:6.3f} {m.dzeta_percent:+9.1f} "
              f"{m.dzeta_std_percent:6.1f} {m.df_percent_per_decade:+7.3f} {'yes' if m.significant else 'no'}")
    from analysis.uff import write_uff58

    with tempfile.TemporaryDirectory() as d:
        paths = [str(Path(d) / "bolted_0p05.uff"), str(Path(d) / "bolted_0p30.uff")]
        write_uff58(paths[0], lo)
        write_uff58(paths[1], hi)
        cmd = [sys.executable, "-m", "analysis", "linearity", *paths, "--levels", "0.05,0.30", "--band", "10:400"]
        out = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=600)
        print("python -m analysis linearity bolted_0p05.uff bolted_0p30.uff --levels 0.05,0.30 --band 10:400")
        print(out.stdout.rstrip())


def natural_spread(name: str, hits: list, fs: float, windows, band, **kw) -> None:
    peaks = np.array([float(np.max(np.abs(f))) for f, _ in hits])
    sets = per_hit_frfs(hits, fs, windows, **kw)
    order = np.argsort(peaks)
    res = compare_levels([sets[i] for i in order], list(peaks[order]), band=band)
    x = np.log10(peaks[order])
    print(f"\n{name}: {len(hits)} hits, peak forces {', '.join(f'{p:.4g}' for p in np.sort(peaks))} N "
          f"(x {peaks.max() / peaks.min():.2f}, {np.log10(peaks.max() / peaks.min()):.3f} decade); softest against "
          f"hardest hit: {res.verdict}")
    print(f"{'f [Hz]':>9s} {'slope [%/dec]':>13s} {'+-':>7s} {'max |df| hit to hit [%]':>24s} {'zeta [%]':>8s}")
    for k, m in enumerate(res.modes):
        f = res.freq_hz[:, k]
        s = np.maximum(res.freq_hz_std[:, k], 1e-12)
        w = 1.0 / s ** 2
        xm = np.sum(w * x) / np.sum(w)
        slope = np.sum(w * (x - xm) * f) / np.sum(w * (x - xm) ** 2)
        sd = 1.0 / np.sqrt(np.sum(w * (x - xm) ** 2))
        print(f"{m.freq_hz:9.2f} {100 * slope / m.freq_hz:+13.3f} {100 * sd / m.freq_hz:7.3f} "
              f"{100 * (f.max() - f.min()) / m.freq_hz:24.3f} {100 * m.zeta:8.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    data = Path(ap.parse_args().data)
    if not data.is_dir():
        sys.exit(f"real data not found at {data}: give --data DIR")
    bolted_beam(data)
    hits, fs = pyfrf_5impacts.hits(data)
    natural_spread("pyfrf_hammer_5impacts", hits, fs, pyfrf_5impacts.WINDOWS, pyfrf_5impacts.BAND,
                   outputs=("s:2:Z",), reference="s:1:Z")
    hits, fs = ladisk_beam.multi_hits(data)
    natural_spread("ladisk_beam_impact (acceleration_multi.lvm)", hits, fs, ladisk_beam.WIN_MULTI,
                   ladisk_beam.BAND_MULTI, outputs=("beam2:2:Z",), reference="beam2:1:Z")


if __name__ == "__main__":
    main()
