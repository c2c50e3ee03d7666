"""A recording's writer killed (SIGKILL) at random moments while it writes hits: how often the HDF5
file alone lost a hit the writer had reported written, and how often the recording did (read as every
tool reads it, from the journal its writer left).

    .venv/bin/python benchmarks/reliability/kill_writer.py [--kills 1500] [--seed 1] [--write]

Each trial starts a writer process that writes hits of random counts (4 channels x 8192 samples) as
fast as it can, each followed by an event, and prints a hit's index and the sum of its counts once
``write_hit`` has returned. After a random number of reported hits (3-14) and a random 0-30 ms more,
the writer is killed. Then:

* the HDF5 file is opened directly with h5py (no journal) and every reported hit is looked up by name
  and its counts summed: a failure there is a kill that landed inside libhdf5's flush, which does not
  write a flush atomically;
* the recording is read with ``analysis.recording.Recording`` (which reads a recording its writer
  left unclosed from its journal): every reported hit must be there with its sum, and every event.

A kill landing inside a flush is rare (well under 1 % of kills on an idle machine, more on a busy
one), so the run needs many kills to see one; the figure that must stay 0 is the last column.
"""
from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from benchmarks.results import add_write_option, recorded  # noqa: E402

RESULTS = Path(__file__).with_name("kill_writer.md")

WRITER = textwrap.dedent("""
    import sys, numpy as np
    from analysis.hit import Hit
    from analysis.recording_writer import RecordingWriter
    from analysis.spectra import WindowSettings
    rng = np.random.default_rng(int(sys.argv[2]))
    with RecordingWriter(sys.argv[1], instrument={"model": "x"}, setup={}, channels=[{"name": "f", "point": "n:1:Z"}],
                         windows=WindowSettings()) as w:
        i = 0
        while True:
            c = rng.integers(-30000, 30000, size=(4, 8192)).astype(np.int16)
            idx = w.write_hit(Hit(counts=c, eu_per_count=[1.0] * 4, volts_per_count=[1.0] * 4, trigger_index=10,
                                  sample_rate_hz=1000.0, sequence=i, timestamp=0.0, measurement=0, point="n:1:Z",
                                  reference="n:1:Z", outputs=["n:2:Z"] * 3, force_channel=0,
                                  response_channels=[1, 2, 3], overload=[False] * 4, accepted=True))
            w.log("INFO", f"hit {idx}")
            print(idx, int(c.sum()), flush=True)
            i += 1
""")


def _raw_file_keeps(path: Path, reported: dict[int, int]) -> bool:
    """Whether the HDF5 file itself (no journal) holds every reported hit with its counts."""
    import h5py
    import numpy as np

    try:
        with h5py.File(path, "r") as f:
            return all(int(f["hits"][f"{i:06d}"]["counts"][()].astype(np.int64).sum()) == total
                       for i, total in reported.items())
    except (OSError, KeyError, ValueError, RuntimeError):
        return False


def _recording_keeps(path: Path, reported: dict[int, int]) -> bool:
    """Whether the recording, read as every tool reads it, holds every reported hit and event."""
    from analysis.errors import RecordingError
    from analysis.recording import Recording

    try:
        with Recording(path) as rec:
            hits = {h.index: int(h.counts.sum()) for h in rec.hits(skip_damaged=True)}
            return all(hits.get(i) == total for i, total in reported.items()) and len(rec.events()) >= len(reported)
    except RecordingError:
        return False


def trial(folder: Path, script: Path, k: int, rng: random.Random) -> tuple[bool, bool, int]:
    """One kill: (HDF5 file alone kept every reported hit, the recording did, hits reported)."""
    path = folder / f"kill{k:05d}.h5"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, str(script), str(path), str(k)], stdout=subprocess.PIPE, text=True,
                            env=env, stderr=subprocess.DEVNULL)
    reported: dict[int, int] = {}
    want = rng.randint(3, 14)
    assert proc.stdout is not None
    for line in proc.stdout:
        idx, total = map(int, line.split())
        reported[idx] = total
        if len(reported) >= want:
            break
    time.sleep(rng.random() * 0.03)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc.stdout.close()
    raw, whole = _raw_file_keeps(path, reported), _recording_keeps(path, reported)
    if raw and whole:
        for p in folder.glob(f"kill{k:05d}.h5*"):
            p.unlink()
    return raw, whole, len(reported)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kills", type=int, default=1500, help="number of writers killed (default 1500)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the kill moments (default 1)")
    add_write_option(parser, RESULTS)
    args = parser.parse_args(argv)
    rng = random.Random(args.seed)
    import logging

    logging.disable(logging.WARNING)  # each recovered recording says so; the table counts them
    with tempfile.TemporaryDirectory() as d, recorded(RESULTS, args.write):
        folder = Path(d)
        script = folder / "writer.py"
        script.write_text(WRITER)
        raw_lost = lost = reported = 0
        load0 = os.getloadavg()[0]
        for k in range(args.kills):
            raw, whole, n = trial(folder, script, k, rng)
            raw_lost += not raw
            lost += not whole
            reported += n
        print(f"load average {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end\n")
        print("| kills | hits reported before the kills | kills after which the HDF5 file alone lost a reported hit "
              "| kills after which the recording lost a reported hit or event |")
        print("|---|---|---|---|")
        print(f"| {args.kills} | {reported} | {raw_lost} | {lost} |")
    return 1 if lost else 0


if __name__ == "__main__":
    raise SystemExit(main())
