"""``python -m acquisition capture|replay|export|import|demo ...``"""
from __future__ import annotations

import sys

from analysis._cli_dispatch import dispatch

COMMANDS = {
    "capture": ("acquisition.cli_capture", "run an impact test and write a recording (HDF5)"),
    "replay": ("acquisition.cli_replay", "recompute FRFs from a recording with other settings"),
    "repair": ("acquisition.cli_repair", "recover the intact hits of a recording that no longer opens (full disk, crash)"),
    "export": ("acquisition.cli_export", "write a recording's FRFs (and time data) as UFF 58"),
    "import": ("acquisition.cli_import", "turn measured time data or an analyser's FRF exports into a recording"),
    "identify": ("acquisition.cli_identify", "open a device URL and print identity and capabilities"),
    "devices": ("acquisition.cli_devices", "list what can be opened: USB analysers, serial ports, simulated doors"),
    "station": ("acquisition.cli_station", "serve the operator's capture page (browser) for an impact test"),
    "demo": ("acquisition.cli_demo", "the make-demo job: capture on the simulated frame, fit, summarise"),
}

if __name__ == "__main__":
    sys.exit(dispatch("python -m acquisition", COMMANDS))
