"""``python -m simulator modes|serve|fleet ...``"""
from __future__ import annotations

import sys

from analysis._cli_dispatch import dispatch

COMMANDS = {
    "modes": ("simulator.cli_modes", "print the simulated frame's modes (natural frequency, damping, shapes)"),
    "serve": ("simulator.cli_serve", "run the simulated analyser as a TCP or pty server"),
    "fleet": ("simulator.cli_fleet", "record a production fleet of frames (scatter, a few defective units)"),
}

if __name__ == "__main__":
    sys.exit(dispatch("python -m simulator", COMMANDS))
