"""``python -m acquisition export``: a recording's FRFs (and time data) as UFF dataset 58.

    python -m acquisition export REC.h5 --uff OUT.uff [--time] [--estimator H1|H2] [--overwrite]

Writes every measured FRF (function type 4) with its coherence (type 6); ``--time`` adds the
accepted hits' time histories (type 1, one record per channel and hit). Nodes and directions
follow ``analysis.points.uff_dofs``; the ID lines carry the estimator and averages (line 2), the
exponential window (line 3, ``exp_window_tau_s=<tau s>``) and the point labels (line 4,
``out=<label> ref=<label>``), so ``analysis.uff.read_uff58`` reads back what a fit needs: a fit of
the export removes the same window damping as a fit of the recording.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from analysis.command_line import add_estimator, add_overwrite, cli_entry, errors_to_exit, with_examples
from analysis.outputs import check_outputs

__all__ = ["main", "export"]


def export(rec_path: str | Path, uff_path: str | Path, *, time_data: bool = False, estimator: str | None = None,
           overwrite: bool = False) -> int:
    """Write the UFF file; returns the number of datasets written. Refused before anything is
    written when ``uff_path`` is the recording or a file a live writer holds (:func:`check_outputs`)."""
    check_outputs([uff_path], [rec_path])
    from analysis.recording import Recording, merge_frfsets
    from analysis.uff import time_records, write_uff58

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


def export_sep005(rec_path: str | Path, out_path: str | Path, *, overwrite: bool = False,
                  accepted_only: bool = False) -> int:
    """Write the recording's hits as SEP005 channels (:mod:`analysis.sep005`, one group per hit, in
    engineering units); returns the number of channels written. Refused like :func:`export`."""
    check_outputs([out_path], [rec_path])
    from analysis.recording import Recording
    from analysis.sep005 import QUANTITY_CODES, write_sep005

    channels = []
    with Recording(rec_path) as rec:
        for h in rec.hits(accepted_only=accepted_only, skip_damaged=True):
            points = [str(c.get("point", "")) for c in rec.channels]
            points[h.force_channel] = h.reference
            for k, o in zip(h.response_channels, h.outputs):
                points[k] = o
            for i, c in enumerate(rec.channels):
                channels.append({
                    "name": str(c.get("name", f"ch{i + 1}")), "data": h.data[i], "fs": h.sample_rate_hz,
                    "unit_str": str(c.get("unit", "")), "quantity": QUANTITY_CODES.get(str(c.get("quantity")), None),
                    "group": f"hit-{h.index + 1}", "point": points[i], "trigger_index": h.trigger_index,
                    "accepted": bool(h.accepted)})
    write_sep005(out_path, channels, overwrite=overwrite)
    return len(channels)


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m acquisition export", description=__doc__.split("\n\n")[0])
    with_examples(p)
    p.add_argument("recording")
    p.add_argument("--uff", help="UFF file to write (FRFs as UFF 58)")
    p.add_argument("--time", action="store_true", help="also write the accepted hits' time histories (UFF 58 type 1)")
    p.add_argument("--sep005", metavar="OUT.json",
                   help="write every recorded hit's time data as SEP005 channels (SDyPy's exchange format, JSON)")
    add_estimator(p)
    add_overwrite(p, "replace existing output files")
    args = p.parse_args(argv)
    from analysis.sep005 import SEP005Error
    from analysis.uff import UFFError

    from .errors import RecordingError

    if not (args.uff or args.sep005):
        print("export: give --uff OUT.uff and/or --sep005 OUT.json", file=sys.stderr)
        return 2
    with errors_to_exit("export", (RecordingError, UFFError, SEP005Error, ValueError)):
        check_outputs([args.uff, args.sep005], [args.recording])
        if args.uff:
            n = export(args.recording, args.uff, time_data=args.time, estimator=args.estimator,
                       overwrite=args.overwrite)
            print(f"wrote {n} UFF 58 datasets to {args.uff}")
        if args.sep005:
            n = export_sep005(args.recording, args.sep005, overwrite=args.overwrite)
            print(f"wrote {n} SEP005 channels to {args.sep005}")
    return 0
