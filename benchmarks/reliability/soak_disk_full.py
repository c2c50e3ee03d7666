"""Disk-full soak: capture, station, replay, import, export, report and batch onto a small disk that
fills up at a different moment in each run.

    .venv/bin/python benchmarks/reliability/soak_disk_full.py [--runs 12] [--size-mb 8] [--max-free-mb 5]
        [--only capture,...] [--limit] [--json]

Each run mounts a tmpfs of ``--size-mb`` (as root; elsewhere a file size limit on the child stands
in for it, ``--limit``), fills it with a file so that a different amount of room is left (from
20 kB to ``--max-free-mb``; the last run has all the room), and runs one command writing onto it.
Afterwards it checks:

* the exit code (0 when everything fitted, else 1) and that stderr holds one line, no traceback;
* capture and station: every hit in the recording is readable (its CRC-32 matches its counts) and
  identical to the same hit of a run with room (the simulated analyser is seeded), the accepted
  hits are all in the FRF results, no lock file is left, and once the filler is removed the test
  resumes (``capture --resume``) to the full plan;
* replay, import, export, report: the output is either complete or absent, and an output that
  existed before (an earlier export or report) is byte for byte unchanged; batch: its output folder
  stays for the next run (finished results are reused), every file in it whole;
* files left: anything on the disk besides the filler, the outputs and the earlier outputs.

Prints one row per command: runs, exit codes, hits accepted vs readable, problems, files left.
"""
from __future__ import annotations

import argparse
import collections
import contextlib
import hashlib
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
POINTS = "right:6:-X,top:4:Z,left:9:Y"
HITS = 2
CAPTURE = ["acquisition", "capture", "--device", "sim://?seed=1", "--hits", str(HITS), "--auto", "-q",
           "--points", POINTS]
COMMANDS = ("capture", "station", "replay", "import", "export-uff", "export-sep005", "report", "batch")


@dataclass
class Row:
    """What the runs of one command measured."""

    command: str
    runs: int = 0
    codes: collections.Counter = field(default_factory=collections.Counter)
    stopped: int = 0           # runs a full disk stopped (exit 1) that left a recording (capture, station)
    accepted: int = 0          # accepted hits those recordings hold
    readable: int = 0          # of those, readable and identical to the run with room
    in_frfs: int = 0           # of those, in the recording's FRF results
    resumed: int = 0           # runs whose test was resumed to the full plan once there was room
    kept: int = 0              # runs whose earlier output was left byte for byte
    problems: list = field(default_factory=list)
    left: collections.Counter = field(default_factory=collections.Counter)


def run(args: list[str], cwd: Path, limit: int | None, timeout: float = 600) -> subprocess.CompletedProcess:
    def limited() -> None:
        if limit is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", *args], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          preexec_fn=limited, env=env)


def error_lines(stderr: str) -> list[str]:
    """stderr without progress lines, log lines and the fit's notes."""
    return [ln for ln in stderr.strip().splitlines()
            if ln and not ln.startswith(("... ", "note: ", "INFO ", "WARNING ", "DEBUG "))]


@contextlib.contextmanager
def small_disk(size_mb: float, free: int, use_limit: bool) -> Iterator[tuple[Path, int | None]]:
    """A folder with ``free`` bytes of room: a tmpfs of ``size_mb`` filled up to that, or (``use_limit``)
    a plain folder and the file size limit ``free`` for the child."""
    where = Path(tempfile.mkdtemp(prefix="soak-disk-"))
    try:
        if use_limit:
            yield where, free
            return
        subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={int(size_mb * 1024 * 1024)}", "tmpfs", str(where)],
                       check=True, capture_output=True)
        try:
            st = os.statvfs(where)
            fill = max(0, st.f_bavail * st.f_frsize - free)
            with open(where / "filler", "wb") as fh:
                if fill:
                    os.posix_fallocate(fh.fileno(), 0, fill)
            yield where, None
        finally:
            subprocess.run(["umount", str(where)], capture_output=True)
    finally:
        shutil.rmtree(where, ignore_errors=True)


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else ""


def tree_digest(path: Path) -> str:
    if not path.is_dir():
        return digest(path)
    h = hashlib.sha256()
    for p in sorted(path.rglob("*")):
        h.update(str(p.relative_to(path)).encode())
        h.update(digest(p).encode())
    return h.hexdigest()


def reference_hits(path: Path) -> list[tuple[int, bool]]:
    """(CRC-32 of the counts, accepted) of each hit of a recording."""
    from analysis.recording import Recording
    from analysis.recording_schema import counts_crc32

    with Recording(path) as rec:
        return [(counts_crc32(h.counts), bool(h.accepted)) for h in rec.hits()]


def check_recording(row: Row, rec_path: Path, ref: list[tuple[int, bool]], disk: Path, stopped: bool) -> None:
    """Hits readable and identical to the run with room; accepted hits in the FRFs; a test the full
    disk ``stopped`` resumable with room."""
    from analysis.errors import RecordingError
    from analysis.recording import Recording

    if not rec_path.exists() or not stopped:
        return  # no room for the first hit: nothing recorded, nothing to lose; or a run with room
    try:
        got = reference_hits(rec_path)
        with Recording(rec_path) as rec:
            in_frfs = {int(i) for name in rec.measurement_names() for i in rec.frf_group(name)["hits"]}
            accepted = [h.index for h in rec.hits(accepted_only=True)]
    except (RecordingError, OSError, ValueError) as exc:
        row.problems.append(f"recording unreadable: {exc}")
        return
    row.stopped += 1
    row.accepted += sum(a for _, a in got)
    row.readable += sum(1 for k, g in enumerate(got) if k < len(ref) and g == ref[k] and g[1])
    row.in_frfs += len(in_frfs & set(accepted))
    if (disk / (rec_path.name + ".lock")).exists():
        row.problems.append("lock file left")
    copy = disk.parent / f"resume-{os.getpid()}.h5"
    shutil.copyfile(rec_path, copy)  # resume with room: a copy on the big disk
    try:
        done = run(["acquisition", "capture", "--auto", "-q", "--resume", str(copy)], disk.parent, None)
        if done.returncode == 0:
            with Recording(copy) as rec:
                if sum(1 for _ in rec.hits(accepted_only=True)) == 3 * HITS:
                    row.resumed += 1
                else:
                    row.problems.append("resumed test incomplete")
        else:
            row.problems.append(f"resume failed: {error_lines(done.stderr)[-1:]}")
    finally:
        copy.unlink(missing_ok=True)


def station(out: Path, cwd: Path, limit: int | None) -> tuple[int, str]:
    """Run the station in auto mode until its test is finished or has failed; (exit code, stderr)."""
    def limited() -> None:
        if limit is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "acquisition", "station", "--device", "sim://?seed=1", "--out",
                             str(out), "--hits", str(HITS), "--auto", "--points", POINTS, "-q"], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=limited, env=env)
    assert proc.stdout is not None
    url = proc.stdout.readline().strip()
    state_url = url.replace("/?token=", "/api/state?token=")
    phase = ""
    for _ in range(600):
        try:
            with urllib.request.urlopen(state_url, timeout=5) as resp:
                phase = json.load(resp).get("phase", "")
        except OSError:
            phase = ""
        if phase in ("finished", "error"):
            break
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err


def launch(command: str, disk: Path, scratch: Path, limit: int | None, row: Row) -> tuple[int, str, set, dict]:
    """Run ``command`` writing onto ``disk``: (exit code, stderr, its outputs, earlier outputs by name)."""
    earlier: dict[str, str] = {}
    if command == "station":
        code, err = station(disk / "rec.h5", scratch, limit)
        return code, err, {"rec.h5"}, earlier
    if command == "capture":
        args, outputs = [*CAPTURE, "--out", str(disk / "rec.h5")], {"rec.h5"}
    elif command == "replay":
        args, outputs = ["acquisition", "replay", str(scratch / "src.h5"), "--out", str(disk / "rep.h5")], {"rep.h5"}
    elif command == "import":
        args, outputs = ["acquisition", "import", str(scratch / "hits.json"), "--out", str(disk / "imp.h5"),
                         "--reference", "right:6:-X"], {"imp.h5"}
    elif command in ("export-uff", "export-sep005"):
        name, flag = ("out.uff", "--uff") if command == "export-uff" else ("out.json", "--sep005")
        earlier[name] = "an earlier export"
        (disk / name).write_text(earlier[name])
        args = ["acquisition", "export", str(scratch / "src.h5"), flag, str(disk / name), "--overwrite"] + (
            ["--time"] if command == "export-uff" else [])
        outputs = {name}
    elif command == "report":
        (disk / "rep").mkdir()
        (disk / "rep" / "notes.txt").write_text("the user's own file")
        before = tree_digest(disk / "rep")
        done = run(["analysis", "report", str(scratch / "src.h5"), "--out", str(disk / "rep")], scratch, limit)
        if done.returncode != 0 and tree_digest(disk / "rep") == before:
            row.kept += 1
        return done.returncode, done.stderr, {"rep"}, earlier
    elif command == "batch":
        args, outputs = ["analysis", "batch", str(scratch / "src.h5"), str(scratch / "src2.h5"), "--out",
                         str(disk / "batch"), "--workers", "1", "-q"], {"batch"}
    else:
        raise ValueError(command)
    done = run(args, scratch, limit)
    return done.returncode, done.stderr, outputs, earlier


def one_run(command: str, k: int, runs: int, args: argparse.Namespace, scratch: Path, row: Row,
            ref: list[tuple[int, bool]]) -> None:
    total = int(args.size_mb * 1024 * 1024)
    top = min(total, int(args.max_free_mb * 1024 * 1024))
    # from 20 kB to --max-free-mb over the runs but the last, which has all the room
    free = total if k == runs - 1 else int(20_000 + (top - 20_000) * k / max(1, runs - 2))
    with small_disk(args.size_mb, free, args.limit) as (disk, limit):
        code, err, outputs, earlier = launch(command, disk, scratch, limit, row)
        row.runs += 1
        row.codes[code] += 1
        lines = error_lines(err)
        if code not in (0, 1):
            row.problems.append(f"exit {code}: {lines[-1:]}")
        if code == 1 and (len(lines) != 1 or "Traceback" in err):
            row.problems.append(f"{len(lines)} stderr lines: {lines[:3]}")
        for name, text in earlier.items():
            now = (disk / name).read_text(errors="replace") if (disk / name).is_file() else ""
            if code != 0 and now == text:
                row.kept += 1
            elif code != 0:
                row.problems.append(f"earlier {name} changed")
        if command in ("capture", "station"):
            check_recording(row, disk / "rec.h5", ref, disk, code != 0)
        elif command == "batch":
            if code != 0:
                check_batch_folder(row, disk / "batch")
        elif code != 0:
            row.problems.extend(f"partial {name} left" for name in outputs - set(earlier) - {"rep"}
                                if (disk / name).exists())
        files_left(row, disk, outputs)


def check_batch_folder(row: Row, folder: Path) -> None:
    """A batch's output folder stays for the next run (its results are reused): every file in it is
    whole (no temporary left, every JSON parses)."""
    if not folder.is_dir():
        return
    for p in folder.rglob("*"):
        if p.name.endswith(".part"):
            row.problems.append(f"temporary {p.relative_to(folder)} left in the batch folder")
        elif p.suffix == ".json":
            try:
                json.loads(p.read_text())
            except ValueError:
                row.problems.append(f"half-written {p.relative_to(folder)}")
        elif p.is_file() and not p.name.startswith("."):
            row.left[f"batch/{p.relative_to(folder)}"] += 1


def files_left(row: Row, disk: Path, outputs: set) -> None:
    """Count what is on the disk besides the filler and the outputs (and hidden files in a report folder)."""
    for p in disk.iterdir():
        if p.name not in outputs | {"filler"}:
            row.left[p.name] += 1
    if (disk / "rep").is_dir():
        for p in (disk / "rep").iterdir():
            if p.name.startswith("."):
                row.left["rep/" + p.name] += 1


def prepare(scratch: Path) -> list[tuple[int, bool]]:
    """The inputs on a disk with room: the run with room (reference hits), a second unit, the SEP005 export."""
    for name, seed in (("src.h5", 1), ("src2.h5", 2)):
        done = run([*CAPTURE[:3], f"sim://?seed={seed}", *CAPTURE[4:], "--out", name], scratch, None)
        if done.returncode != 0:
            raise SystemExit(f"cannot make the inputs: {done.stderr[-500:]}")
    done = run(["acquisition", "export", "src.h5", "--sep005", "hits.json"], scratch, None)
    if done.returncode != 0:
        raise SystemExit(f"cannot export the hits: {done.stderr[-500:]}")
    return reference_hits(scratch / "src.h5")


def mount_permitted() -> bool:
    where = Path(tempfile.mkdtemp(prefix="soak-probe-"))
    try:
        ok = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(where)],
                            capture_output=True).returncode == 0
        if ok:
            subprocess.run(["umount", str(where)], capture_output=True)
        return ok
    except OSError:
        return False
    finally:
        shutil.rmtree(where, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=12, help="runs per command (the room left is spread over them)")
    p.add_argument("--size-mb", type=float, default=8.0, help="size of the small disk (MB)")
    p.add_argument("--max-free-mb", type=float, default=5.0, help="most room left in a run but the last (MB)")
    p.add_argument("--only", default=",".join(COMMANDS), help="commands to run, comma-separated")
    p.add_argument("--limit", action="store_true", help="a file size limit instead of a tmpfs (no root needed)")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    args = p.parse_args(argv)
    if not args.limit and not mount_permitted():
        print("mounting a tmpfs is not permitted here: using a file size limit (--limit)", file=sys.stderr)
        args.limit = True
    sys.path.insert(0, str(ROOT))
    rows = []
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="soak-inputs-") as tmp:
        scratch = Path(tmp)
        ref = prepare(scratch)
        for command in args.only.split(","):
            row = Row(command)
            for k in range(args.runs):
                one_run(command, k, args.runs, args, scratch, row, ref)
            rows.append(row)
            print(f"... {command}: {row.runs} runs, exit codes {dict(row.codes)}", file=sys.stderr, flush=True)
    wall = time.monotonic() - t0
    if args.json:
        print(json.dumps([{**vars(r), "codes": dict(r.codes), "left": dict(r.left)} for r in rows], indent=1))
        return 0
    print(f"disk: {'file size limit' if args.limit else 'tmpfs'} {args.size_mb:g} MB, room left spread over "
          f"{args.runs} runs per command; {wall:.0f} s")
    print("stopped: runs ended by the full disk that left a recording; accepted, readable, in FRFs: its hits;\n"
          "resumed: of those, completed with room; kept: earlier outputs left unchanged by a stopped run")
    print(f"{'command':14s} {'runs':>4s}  {'exit codes':14s} {'stopped':>7s} {'accepted':>8s} {'readable':>8s} "
          f"{'in FRFs':>7s} {'resumed':>7s} {'kept':>4s}  problems / files left")
    for r in rows:
        codes = " ".join(f"{c}x{n}" for c, n in sorted(r.codes.items()))
        left = ", ".join(f"{k} x{n}" for k, n in sorted(r.left.items())) or "none"
        print(f"{r.command:14s} {r.runs:4d}  {codes:14s} {r.stopped:7d} {r.accepted:8d} {r.readable:8d} {r.in_frfs:7d} "
              f"{r.resumed:7d} {r.kept:4d}  {len(r.problems)} problem(s); left: {left}")
        for prob in r.problems[:5]:
            print(f"{'':16s}- {prob}")
    return 0 if not any(r.problems for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
