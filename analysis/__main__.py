"""``python -m analysis fit|stabilization|diagnose|report|linearity|batch ...``"""
from __future__ import annotations

import sys

from analysis._cli_dispatch import dispatch

COMMANDS = {
    "fit": ("analysis.cli_fit", "fit a modal model (LSFD, Gauss-Newton or Levenberg-Marquardt)"),
    "stabilization": ("analysis.cli_stabilization", "draw a stabilization diagram"),
    "diagnose": ("analysis.cli_diagnose", "compare measurement and simulation, name the cause"),
    "report": ("analysis.cli_report", "write a self-contained HTML test report (FRFs, modes, animated shapes)"),
    "linearity": ("analysis.cli_linearity", "is the structure linear? modes compared between excitation levels"),
    "batch": ("analysis.cli_batch", "fit many recordings on Dask; flag the units whose modes stray from the fleet"),
}

if __name__ == "__main__":
    from analysis.threads import load_blas_single_threaded

    load_blas_single_threaded()
    sys.exit(dispatch("python -m analysis", COMMANDS))
