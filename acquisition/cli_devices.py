"""``python -m acquisition devices`` (``impactlab devices``): list what can be opened."""
from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

from analysis.command_line import Parser, parse_args, with_examples

from .discovery import list_devices

EXAMPLES = """examples:
  impactlab devices                  analysers on USB, serial ports, simulated doors
  impactlab devices --json           the same as JSON (url, kind, description)
  impactlab devices --all-usb        every USB device, not only known analysers
then open one: impactlab identify --device URL
"""


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="python -m acquisition devices", description=__doc__.split("\n")[0].split(": ", 1)[-1],
               epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    with_examples(p)
    p.add_argument("--json", action="store_true", help="print a JSON list instead of a table")
    p.add_argument("--all-usb", action="store_true", help="list every USB device, not only known analysers")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(build_parser(), argv)
    if isinstance(args, int):
        return args
    entries, notes = list_devices(all_usb=args.all_usb)
    if args.json:
        print(json.dumps({"devices": [e.as_dict() for e in entries], "notes": notes}, indent=1))
    else:
        width = max([len(e.url) for e in entries] + [10])
        for e in entries:
            print(f"{e.url:{width}s}  {e.kind:9s}  {e.description}")
    for note in notes:
        print(note, file=sys.stderr)
    return 0
