"""``impactlab SUBCOMMAND ...``: the one installed command, beside ``python -m PACKAGE SUBCOMMAND``.

Every subcommand of the three packages under one name (a console-script entry point in
``pyproject.toml``), e.g. ``impactlab capture --device sim:// --out rec.h5 --auto``,
``impactlab fit rec.h5``, ``impactlab modes``, ``impactlab devices``; ``python -m impactlab`` runs it
too. A wiring module above the three packages' faces: it only reads their command tables.
"""
from __future__ import annotations

import sys
from collections.abc import Sequence

from acquisition.__main__ import COMMANDS as ACQUISITION
from analysis.__main__ import COMMANDS as ANALYSIS
from analysis._cli_dispatch import dispatch
from simulator.__main__ import COMMANDS as SIMULATOR

#: every subcommand: name -> (module, one-line help); names are unique across the packages
COMMANDS = {**ACQUISITION, **ANALYSIS, **SIMULATOR}


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``impactlab SUBCOMMAND ...`` (``--help`` lists the subcommands, ``--version``)."""
    return dispatch("impactlab", COMMANDS, argv)


if __name__ == "__main__":
    sys.exit(main())
