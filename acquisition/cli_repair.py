"""``python -m acquisition repair``: recover the hits of a recording that no longer opens.

    python -m acquisition repair REC.h5 --out FIXED.h5 [--overwrite]

For a recording left by a writer that died mid-write (a full disk with an older impactlab, a crash
of the HDF5 library): REC.h5 is never changed; FIXED.h5 receives every complete hit that passes its
CRC-32 check, the FRF results computed from those hits only, the set-up and the event log, and
opens in ``export``, ``fit``, ``replay`` and ``capture --resume``. Prints one line, e.g.
``9 hits kept, 1 cut-off hits dropped``; exits 1 with one line when nothing can be recovered.
"""
from __future__ import annotations

from collections.abc import Sequence

from analysis.command_line import cli_entry, exit_on, recording_in_out

from .errors import RecordingError, UsageError

__all__ = ["main"]


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    p = recording_in_out("python -m acquisition repair", __doc__, "the repaired recording to write",
                         "the recording that does not open (never modified)")
    args = p.parse_args(argv)
    from analysis.recording_repair import repair_recording

    with exit_on("repair", (UsageError, 2), (RecordingError, 1)):
        result = repair_recording(args.recording, args.out, overwrite=args.overwrite)
        print(f"{result.summary()}: wrote {args.out}")
    return 0
