"""Worked examples shown at the end of every command's ``--help`` (one place, so that the README's
tour and the help pages say the same). Keys are the commands' ``prog`` names."""
from __future__ import annotations

__all__ = ["EXAMPLES", "examples_epilog"]

EXAMPLES: dict[str, tuple[str, ...]] = {
    "python -m acquisition capture": (
        'capture --device "sim://?seed=1" --out rec.h5 --hits 5 --auto          # simulated frame, accept every good hit',
        "capture --device socket://127.0.0.1:5025 --out rec.h5 --points right:6:-X,top:4:Z --hits 5",
        "capture --device \"sim://?seed=1\" --out levels.h5 --hits 5 --soft-hard --auto   # 5 soft, then 5 hard hits",
        "capture --resume rec.h5                                                  # after a crash or 'q'",
    ),
    "python -m acquisition replay": (
        "replay rec.h5 --out h2.h5 --estimator H2 --exp-window 5%",
        'replay rec.h5 --out clean.h5 --exclude-hits 2,3-4 --window "force=10ms,2ms;exp=none"',
    ),
    "python -m acquisition repair": (
        "repair rec.h5 --out fixed.h5        # a recording that no longer opens: keep every intact hit",
    ),
    "python -m acquisition export": (
        "export rec.h5 --uff rec.uff --time        # FRFs (UFF 58) and the hits' time data",
        "export rec.h5 --uff rec.uff --overwrite   # replace an earlier export",
    ),
    "python -m acquisition import": (
        "import ../shared/data/ladisk_beam_impact/acceleration.lvm --out beam.h5 --force-window 2ms,1ms",
        "import hits.mat --format mat --out test.h5 --overwrite",
        "import ../shared/data/uliege_meca0062_plane_hammer/first_lab/DPsv00001.mat --format signalcalc-frf "
        "--out plane.h5",
    ),
    "python -m acquisition identify": (
        'identify --device "sim://?seed=1"',
        "identify --device usb://1209:0001 --json",
    ),
    "python -m acquisition station": (
        'station --device "sim://?seed=1" --out rec.h5 --hits 5     # prints http://127.0.0.1:PORT/?token=...',
        "station --resume rec.h5",
    ),
    "python -m acquisition demo": (
        "demo --out demo-output",
    ),
    "python -m analysis fit": (
        "fit rec.h5                                   # automatic band and poles, table on the terminal",
        "fit rec.h5 --json fit.json --plot fit.png --uff modes.uff",
        "fit rec.h5 --band 4:215 --poles 12.9,35.1,50.4 --method gn --json fit.json --overwrite",
    ),
    "python -m analysis stabilization": (
        "stabilization rec.h5 --png stab.png",
        "stabilization rec.h5 --png stab.png --band 4:215 --max-order 30 --method lsce --json stab.json",
    ),
    "python -m analysis diagnose": (
        "diagnose --measured rec.h5 --simulated simulator/frame.toml",
        "diagnose --measured rec.h5 --simulated sim.uff --json diag.json --report diag/",
        "diagnose --measured low.uff high.uff --levels 0.25,1 --simulated sim.uff   # one structure at two drive levels",
    ),
    "python -m analysis report": (
        "report rec.h5 --out report/",
        "report rec.h5 --out full-report/ --fit fit.json --diagnosis diag.json --geometry frame",
    ),
    "python -m analysis linearity": (
        "linearity soft.h5 hard.h5 --json lin.json        # levels read from the hits' peak forces",
        "linearity low.uff high.uff --levels 0.05,0.30 --band 10:400",
        "linearity levels.h5                              # one recording: its soft and hard hits (capture --soft-hard)",
    ),
    "python -m analysis batch": (
        "batch fleet/*.h5 --out results/                       # a local Dask cluster, one worker per core",
        "batch fleet/*.h5 --out results/ --scheduler tcp://10.0.0.5:8786 --reference golden.json --band 4:1100",
    ),
    "python -m simulator modes": (
        "modes",
        "modes --config my_frame.toml --json",
    ),
    "python -m simulator fleet": (
        "fleet --units 200 --out fleet/ --scatter 2 --defects 10 --seed 1",
    ),
    "python -m simulator serve": (
        "serve --tcp 127.0.0.1:0     # prints socket://127.0.0.1:PORT",
        "serve --pty                 # prints /dev/pts/N",
    ),
}


def examples_epilog(prog: str) -> str:
    """The ``--help`` epilog of ``prog``: its examples, each as ``impactlab`` runs it."""
    lines = EXAMPLES.get(prog, ())
    if not lines:
        return ""
    return "examples:\n" + "\n".join(f"  impactlab {line}" for line in lines)
