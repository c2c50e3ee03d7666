"""Station latency and idle cost: time from a hit arriving from the analyser to the page showing its
plots (p50/p95 over N hits, target p95 < 250 ms), and the server's CPU while the page is open and idle.

    .venv/bin/python benchmarks/speed/bench_station.py [--hits 100] [--idle-s 10]

A station process on ``sim://`` and a headless Chromium page. Each hit: the script arms through the
API (as a second tab holding control), the page receives the state by server-sent events, fetches
the hit's plot data and draws force, responses and spectrum; the latency is the page's clock after
drawing minus the server's clock when the block arrived (same machine, same clock). Needs chromium,
chromedriver and selenium (``pip install -e '.[test]'``).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from tempfile import TemporaryDirectory

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

from station_support import Api, StationProcess, chrome  # noqa: E402


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hits", type=int, default=100)
    ap.add_argument("--idle-s", type=float, default=10.0)
    args = ap.parse_args()
    import numpy as np

    with TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        try:
            driver = chrome(tmp_path)
        except BaseException as exc:  # pytest's skip outside pytest: the browser or selenium is missing
            if type(exc).__name__ in ("Skipped", "Failed"):
                print(f"bench_station: {exc}")
                return 0
            raise
        s = StationProcess(["--device", "sim://?seed=1", "--out", str(tmp_path / "rec.h5"), "--points", "right:6:-X",
                            "--hits", str(args.hits)], tmp_path)
        lat_ms = []
        try:
            driver.get(s.url)
            api = Api(s, "bench")
            api.wait(lambda st: st["phase"] == "setup", "the station")
            deadline = time.monotonic() + 60
            while driver.execute_script("return document.body.dataset.phase") != "setup":
                if time.monotonic() > deadline:
                    raise SystemExit("the page did not load")
                time.sleep(0.05)
            # idle: page open, nothing happening
            c0, t0 = _cpu_s(s.proc.pid), time.monotonic()
            time.sleep(args.idle_s)
            idle_pct = 100 * (_cpu_s(s.proc.pid) - c0) / (time.monotonic() - t0)
            assert api.lease(take=True) == (200, True)
            while len(lat_ms) < args.hits:
                st = api.state()
                if st["phase"] == "complete":
                    break
                seq = st["hit_seq"]
                assert api.act("arm")[0] == 200
                st = api.wait(lambda x, q=seq: x["hit_seq"] > q and x["phase"] in ("decide", "ready", "complete"),
                              "a hit")
                seq = st["hit_seq"]
                end = time.monotonic() + 60
                shown = None
                while shown is None:
                    shown = driver.execute_script(f"return window.stationStats.shown[{seq}] || null")
                    if shown is None:
                        if time.monotonic() > end:
                            raise SystemExit(f"hit {seq} never shown")
                        time.sleep(0.005)
                hit = api.request("GET", "/api/blob/hit")[1]
                assert hit["seq"] == seq
                lat_ms.append(shown - 1000 * hit["t_block"])
                if st["phase"] == "decide":
                    assert api.act_here("accept")[0] == 200
                    api.wait(lambda x: x["phase"] in ("ready", "complete"), "the accept")
            size = len(api.request("GET", "/api/blob/hit", raw=None)[1].__repr__())
        finally:
            driver.quit()
            s.stop()
    lat = np.asarray(lat_ms)
    print("station: hit arrival (server) -> plots drawn (page), headless Chromium, sim://")
    print(f"{'hits':>6} {'p50 ms':>8} {'p95 ms':>8} {'max ms':>8} {'target p95':>11}   idle server CPU")
    print(f"{lat.size:6d} {np.percentile(lat, 50):8.1f} {np.percentile(lat, 95):8.1f} {lat.max():8.1f} "
          f"{'< 250 ms':>11}   {idle_pct:.2f} % of one core over {args.idle_s:g} s")
    print(f"hit plot data ~{size / 1024:.0f} kB per hit (JSON)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
