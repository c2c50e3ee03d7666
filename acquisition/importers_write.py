"""Write an import as a recording: the hits checked, stored, averaged into FRFs as a capture's."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from analysis.hit import Hit
from analysis.outputs import check_outputs
from analysis.recording_writer import RecordingWriter, whole_recording
from analysis.spectra import WindowSettings

from .errors import ImportDataError
from .hitcheck import HitCheckSettings, check_hit
from .importers_data import ImportedTest, source_files
from .importers_quantise import imported_hits
from .importers_roles import ChannelRoles, channel_roles

__all__ = ["write_imported"]

def write_imported(
    test: ImportedTest,
    out: str | Path,
    *,
    windows: WindowSettings = WindowSettings(),
    reference: str | None = None,
    outputs: Sequence[str] | None = None,
    force_channel: int | None = None,
    response_channels: Sequence[int] | None = None,
    check_settings: HitCheckSettings = HitCheckSettings(),
    overwrite: bool = False,
    roles: ChannelRoles | None = None,
) -> list:
    """Write ``test`` as a recording (one measurement) and return its averages.

    Refused before anything is written (:func:`analysis.outputs.check_outputs`) when ``out`` is
    one of the files ``test`` was read from or a recording a live writer holds.

    Hits failing the automatic checks (double hits) are stored as rejected with the reason; blocks of
    a continuous excitation (``test.meta["excitation"] == "continuous"``: a shaker) have no hammer
    pulse and are all kept.
    ``reference``/``outputs`` relabel the force and response channels (point labels); ``roles``,
    when given, are the channel roles already made by :func:`channel_roles` (the four relabelling
    arguments are then not used).
    """
    from .session import average_recorded_hits  # session imports this module's siblings; keep it local

    check_outputs([out], source_files(test))  # never onto a file it was read from, nor one a live writer holds
    if roles is None:
        roles = channel_roles(test, reference=reference, outputs=outputs, force_channel=force_channel,
                              response_channels=response_channels)
    chans, ref = roles.channels, roles.reference
    setup = {"sample_rate_hz": test.fs_hz, "block_size": int(test.hits[0].shape[1]),
             "channels": chans, "imported_from": test.source, "format": test.meta.get("format"),
             "excitation": test.meta.get("excitation", "impact")}
    instrument = {"vendor": "imported", "model": str(test.meta.get("format", "")), "source": test.source}
    hits = imported_hits(test, roles)  # refuses what 16-bit counts cannot hold before the file is opened
    with whole_recording(out, overwrite) as tmp, RecordingWriter(
            tmp, instrument=instrument, setup=setup, channels=chans, windows=windows,
            plan={"mode": "imported", "points": [ref]}, overwrite=True, journal=False) as w:
        w.log("INFO", f"imported {len(test.hits)} hit(s) from {test.source}; " + "; ".join(roles.describe()))
        kept: list[Hit] = []
        continuous = test.meta.get("excitation") == "continuous"  # a shaker's blocks: no hammer pulse to check
        for k, hit in enumerate(hits):
            if continuous:
                hit = hit.with_verdict(True, [], {"excitation": "continuous", "accept": True, "reasons": []})
            else:
                chk = check_hit(hit.force, hit.sample_rate_hz, [False] * len(chans), list(hit.channel_names),
                                check_settings)
                hit = hit.with_verdict(chk.verdict.accept is not False, chk.verdict.reasons, chk.to_dict())
            hit = hit.with_index(w.write_hit(hit))
            if not hit.accepted:
                w.log("INFO", f"hit {k} rejected: {'; '.join(hit.reasons)}")
            else:
                kept.append(hit)
        if not kept:
            raise ImportDataError(f"{test.source}: every hit failed the checks (double hits); nothing to average")
        averages = average_recorded_hits(kept, windows, chans)
        for avg in averages:
            avg.write(w)
    return averages
