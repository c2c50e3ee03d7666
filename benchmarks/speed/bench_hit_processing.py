"""Per-hit processing time: hit checks + windows + spectra + accumulator update (+ coherence so far).

4 channels (1 force + 3 responses) x 8192 samples, int16 counts scaled to engineering units as the
capture session does. Requirement: under 20 ms per hit. Run: .venv/bin/python benchmarks/speed/bench_hit_processing.py
"""
from __future__ import annotations

import time

import numpy as np

from acquisition.hitcheck import check_hit
from analysis.recording import counts_crc32, scale_counts
from analysis.spectra import FRFAccumulator, WindowSettings, hit_spectra

FS = 6400.0
N = 8192
N_HITS = 200


def make_counts(rng: np.random.Generator) -> np.ndarray:
    t = np.arange(N) / FS
    f = np.where((t > 0.02) & (t < 0.0212), 1e4 * np.sin(np.pi * (t - 0.02) / 0.0012), 0.0)
    x = [2e4 * np.exp(-3 * t) * np.sin(2 * np.pi * fr * t) * (t > 0.02) for fr in (35.0, 80.0, 150.0)]
    return (np.vstack([f] + x) + rng.normal(0, 20, (4, N))).astype(np.int16)


def bench_write(blocks: list, eu: np.ndarray) -> np.ndarray:
    import tempfile
    from pathlib import Path

    from analysis.hit import Hit
    from analysis.recording_writer import RecordingWriter

    times = []
    with tempfile.TemporaryDirectory() as d:
        with RecordingWriter(Path(d) / "bench.h5", instrument={}, setup={}, channels=[], windows=WindowSettings()) as w:
            for i in range(60):
                hit = Hit(counts=blocks[i % len(blocks)], eu_per_count=eu, volts_per_count=eu, trigger_index=128,
                          sample_rate_hz=FS, sequence=i, timestamp=0.0, measurement=0, point="n:1:Z",
                          reference="n:1:Z", outputs=["n:2:Z"] * 3, force_channel=0, response_channels=[1, 2, 3],
                          overload=[False] * 4, accepted=True)
                t0 = time.perf_counter()
                w.write_hit(hit)
                times.append(time.perf_counter() - t0)
    return 1e3 * np.array(times[5:])


def main() -> None:
    rng = np.random.default_rng(0)
    blocks = [make_counts(rng) for _ in range(8)]
    eu = np.array([0.05, 0.001, 0.001, 0.001])
    win = WindowSettings(force_width_s=0.02, force_taper_s=0.005, exp_window_tau_s=0.4)
    acc = FRFAccumulator(["a", "b", "c"], "f")
    times = []
    for i in range(N_HITS):
        counts = blocks[i % len(blocks)]
        t0 = time.perf_counter()
        data = scale_counts(counts, eu)
        chk = check_hit(data[0], FS, [False] * 4)
        crc = counts_crc32(counts)
        acc.add(hit_spectra(data[0], data[1:], FS, 128, win))
        coh = float(np.mean(acc.coherence()))
        times.append(time.perf_counter() - t0)
        assert chk.force_peak_n > 0 and crc >= 0 and 0 <= coh <= 1
    ms = 1e3 * np.array(times[10:])
    wms = bench_write(blocks, eu)
    print("per-hit processing, 4 ch x 8192 samples (scale + checks + CRC + windows + spectra + average + coherence)")
    print("| hits | median ms | p95 ms | max ms | requirement |")
    print("|-----:|----------:|-------:|-------:|------------:|")
    print(f"| {ms.size} | {np.median(ms):.2f} | {np.percentile(ms, 95):.2f} | {ms.max():.2f} | < 20 ms |")
    print(f"\nwriting one hit to the recording (HDF5, int16 counts + attributes + flush): median "
          f"{np.median(wms):.2f} ms, p95 {np.percentile(wms, 95):.2f} ms")
    if np.median(ms) >= 20.0:
        raise SystemExit("per-hit processing is slower than 20 ms")


if __name__ == "__main__":
    main()
