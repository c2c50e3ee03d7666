"""Replay: a recording's FRFs recomputed from its raw hits with other windows or without some hits,
into a new recording (the original is never modified). With the original windows and no exclusions
the FRFs equal the original ones bit for bit."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from analysis.outputs import check_outputs
from analysis.spectra import WindowSettings

from .errors import UsageError

__all__ = ["replay"]


def replay(src: str | Path, out: str | Path, *, windows: WindowSettings | None = None,
           exclude: Sequence[int] | set[int] = (), estimator: str = "H1", overwrite: bool = False) -> list:
    """Recompute the FRFs of ``src`` into a new recording ``out``; returns the new averages."""
    from analysis.recording import Recording
    from analysis.recording_writer import RecordingWriter, whole_recording

    from .session import average_recorded_hits

    src, out = Path(src), Path(out)
    check_outputs([out], [src])  # replay never modifies the original, also through a link
    with Recording(src) as rec:
        win = windows or rec.windows
        all_hits = list(rec.hits())
        unknown = set(exclude) - {h.index for h in all_hits}
        if unknown:
            raise UsageError(f"--exclude-hits names hit(s) {sorted(unknown)} that {src} does not hold "
                             f"(it has 0..{len(all_hits) - 1})")
        keep = [h for h in all_hits if h.accepted and h.index not in set(exclude)]
        averages = average_recorded_hits(keep, win, rec.channels, record_s=rec.record_s,
                                         pretrigger_s=rec.pretrigger_s)
        with whole_recording(out, overwrite) as tmp, RecordingWriter(
                tmp, instrument=rec.instrument, setup=rec.setup, channels=rec.channels,
                windows=averages[0].windows, plan=rec.plan, overwrite=True, journal=False) as w:
            for t, level, msg in rec.events():
                w.log(level, f"[original {t:.3f}] {msg}")
            for h in all_hits:
                w.write_hit(h)
            w.log("INFO", f"replayed from {src} with windows {averages[0].windows.describe()}; excluded hits "
                          f"{sorted(exclude) or 'none'}; preferred estimator {estimator}")
            for a in averages:
                a.write(w)
            w.set_attr("preferred_estimator", estimator.upper())
    return averages
