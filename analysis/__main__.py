"""``python -m analysis fit|stabilization|diagnose ...``"""
import sys

from analysis._cli_dispatch import dispatch

COMMANDS = {
    "fit": ("analysis.cli_fit", "fit a modal model (LSFD, Gauss-Newton or Levenberg-Marquardt)"),
    "stabilization": ("analysis.cli_stabilization", "draw a stabilization diagram"),
    "diagnose": ("analysis.cli_diagnose", "compare measurement and simulation, name the cause"),
}

if __name__ == "__main__":
    sys.exit(dispatch("python -m analysis", COMMANDS))
