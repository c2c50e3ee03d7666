"""``python -m acquisition export``: a recording's FRFs (and time data) as UFF dataset 58.

    python -m acquisition export REC.h5 --uff OUT.uff [--time] [--estimator H1|H2] [--overwrite]

Writes every measured FRF (function type 4) with its coherence (type 6); ``--time`` adds the
accepted hits' time histories (type 1, one record per channel and hit). Nodes and directions
follow ``analysis.points.uff_node/uff_direction``; the ID lines carry the estimator, averages and
windows. Read back with ``analysis.uff.read_uff58``.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Optional, Sequence

from analysis.command_line import with_examples
from analysis.command_line import add_overwrite, cli_entry, errors_to_exit, add_estimator

__all__ = ["main", "export"]


def export(rec_path: "str | Path", uff_path: "str | Path", *, time_data: bool = False, estimator: "str | None" = None,
           overwrite: bool = False) -> int:
    """Write the UFF file; returns the number of datasets written."""
    from analysis.uff import time_records, write_uff58

    from analysis.recording import Recording, merge_frfsets

    with Recording(rec_path) as rec:
        frf = merge_frfsets(rec.frfsets(estimator))
        extra = []
        if time_data:
            for h in rec.hits(accepted_only=True):
                points = [""] * h.counts.shape[0]
                points[h.force_channel] = h.reference
                for k, o in zip(h.response_channels, h.outputs):
                    points[k] = o
                for i, p in enumerate(points):
                    points[i] = p or rec.channels[i]["point"]
                units = [str(c.get("unit", "")) for c in rec.channels]
                extra += time_records(h.data, h.sample_rate_hz, points, units, h.reference,
                                      id_line=f"hit {h.index} time response", t0_s=-h.trigger_index / h.sample_rate_hz)
        win = rec.windows.describe()
        source = f"{Path(rec_path).name} {rec.instrument.get('model', '')}".strip()
    return write_uff58(uff_path, frf, id_lines=(f"impactlab FRF {frf.quantity}", f"windows: {win}", source),
                       extra_sets=extra, overwrite=overwrite)


@cli_entry
def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(prog="python -m acquisition export", description=__doc__.split("\n\n")[0])
    with_examples(p)
    p.add_argument("recording")
    p.add_argument("--uff", required=True, help="UFF file to write")
    p.add_argument("--time", action="store_true", help="also write the accepted hits' time histories")
    add_estimator(p)
    add_overwrite(p, "replace an existing --uff file")
    args = p.parse_args(argv)
    from analysis.uff import UFFError

    from .errors import RecordingError

    with errors_to_exit("export", (RecordingError, UFFError, ValueError)):
        n = export(args.recording, args.uff, time_data=args.time, estimator=args.estimator, overwrite=args.overwrite)
    print(f"wrote {n} UFF 58 datasets to {args.uff}")
    return 0
