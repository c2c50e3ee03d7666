"""The changes a recording's writer makes, each a function that applies it to an open HDF5 file
(:data:`OPS`), and the rebuilding of a recording from its journal with the same functions
(:func:`replay_journal`, :func:`recover`): the live writer (``analysis.recording_writer``) journals a
change (``analysis.recording_journal``) and then applies it, so a recording rebuilt from its journal
holds what the live writer wrote."""
from __future__ import annotations

import json
import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .atomic import atomic_path
from .errors import RecordingError
from .recording_journal import Journal, journal_path, read_journal
from .recording_lock import writer_alive
from .recording_schema import _DAMAGE, SCHEMA, SCHEMA_VERSION, _as_str, _channel_table, _h5py

__all__ = ["OPS", "replay_journal", "journal_left", "recover"]

log = logging.getLogger(__name__)


def _op_create(f: Any, args: dict) -> None:
    """The recording's header and its empty groups."""
    h5py = _h5py()
    f.attrs["schema"] = SCHEMA
    f.attrs["schema_version"] = SCHEMA_VERSION
    f.attrs["created_utc"] = args["created_utc"]
    f.attrs["software"] = args["software"]
    instrument = args["instrument"]
    g = f.create_group("instrument")
    g.attrs["json"] = json.dumps(instrument, default=str)
    for k, v in instrument.items():
        if isinstance(v, (str, int, float, bool)):
            g.attrs[k] = v
    s = f.create_group("setup")
    s.attrs["json"] = json.dumps(args["setup"], default=str)
    s.create_dataset("channels", data=_channel_table(args["channels"]))
    f.create_group("windows").attrs["json"] = json.dumps(args["windows"])
    f.attrs["plan_json"] = json.dumps(args["plan"], default=str)
    f.create_group("hits")
    f.create_group("frf")
    ev = f.create_group("events")
    sdt = h5py.string_dtype()
    ev.create_dataset("time_unix_s", shape=(0,), maxshape=(None,), dtype="f8", chunks=(256,))
    ev.create_dataset("level", shape=(0,), maxshape=(None,), dtype=sdt, chunks=(256,))
    ev.create_dataset("message", shape=(0,), maxshape=(None,), dtype=sdt, chunks=(256,))


def _op_hit(f: Any, args: dict) -> None:
    """One hit's group: its counts, then its attributes (``complete`` last)."""
    g = f["hits"].create_group(f"{int(args['index']):06d}")
    g.create_dataset("counts", data=args["counts"])
    g.attrs.update(args["attrs"])


def _op_withdraw(f: Any, args: dict) -> None:
    """An accepted hit marked not accepted, with the reason added."""
    a = f["hits"][f"{int(args['index']):06d}"].attrs
    a["accepted"] = False  # first: a crash between the two writes leaves the hit out, not in
    a["reasons"] = json.dumps(json.loads(_as_str(a["reasons"])) + [str(args["reason"])])


def _op_frf(f: Any, args: dict) -> None:
    """A measurement point's FRF group, written or replaced whole."""
    grp = f["frf"]
    if args["name"] in grp:
        del grp[args["name"]]
    g = grp.create_group(args["name"])
    for key, val in args["datasets"].items():
        g.create_dataset(key, data=val)
    g.attrs.update(args["attrs"])


def _op_event(f: Any, args: dict) -> None:
    """One event appended to the log."""
    ev = f["events"]
    n = ev["time_unix_s"].shape[0]
    for name in ("time_unix_s", "level", "message"):
        ev[name].resize((n + 1,))
        ev[name][n] = args[name]


def _op_attr(f: Any, args: dict) -> None:
    """A root attribute set (``closed_utc`` and the set-up's other attributes)."""
    f.attrs[args["key"]] = args["value"]


def _op_drop_hits(f: Any, args: dict) -> None:
    """Hits cut short by a crash removed, and the mark of a clean close (a resumed recording is open)."""
    for name in args["names"]:
        del f["hits"][name]
    if "closed_utc" in f.attrs:
        del f.attrs["closed_utc"]


#: each change a writer journals, by name: the function that applies it to an HDF5 file
OPS = {"create": _op_create, "hit": _op_hit, "withdraw": _op_withdraw, "frf": _op_frf, "event": _op_event,
       "attr": _op_attr, "drop_hits": _op_drop_hits}


def _replay(ops: Sequence[tuple[str, dict]], out: Path) -> None:
    """Write the recording the changes ``ops`` make to ``out``, a temporary file of the caller's (new,
    or created empty)."""
    if not ops or ops[0][0] != "create":
        raise RecordingError("its journal does not start with the recording's header")
    with _h5py().File(out, "w") as f:
        for op, args in ops:
            if op not in OPS:
                raise RecordingError(f"its journal holds a change this impactlab does not know ({op!r}): use the "
                                     "impactlab release that wrote it")
            OPS[op](f, args)


def replay_journal(path: str | Path, out: str | Path) -> tuple[int, bool]:
    """Rebuild the recording ``path`` from its journal into ``out``, a temporary file (new, or created empty);
    returns (number of changes replayed, whether the journal ended with a change cut short). Raises
    :class:`RecordingError` when the journal is not one or cannot be replayed."""
    jp = journal_path(path)
    contents = read_journal(jp)
    if contents.damage:
        log.warning("%s: %s; the changes before it are used", jp, contents.damage)
    try:
        _replay(contents.ops, Path(out))
    except RecordingError as exc:
        raise RecordingError(f"{jp} cannot be replayed: {exc}") from None
    except _DAMAGE as exc:
        raise RecordingError(f"{jp} cannot be replayed ({type(exc).__name__}: {exc})") from None
    return len(contents.ops), contents.torn


def journal_left(path: str | Path) -> bool:
    """Whether ``path`` has a journal that no live writer holds: its writer stopped without closing
    the recording, and the journal holds what it wrote."""
    return os.path.lexists(journal_path(path)) and not writer_alive(path)


def recover(path: str | Path) -> bool:
    """Rebuild a recording whose writer stopped without closing it from its journal, in place (the
    file rebuilt beside it replaces it, then the journal is removed); False when there is nothing to
    recover. The caller holds the recording's writer lock."""
    p = Path(path)
    jp = journal_path(p)
    if not os.path.lexists(jp):
        return False
    with atomic_path(p) as tmp:
        n, torn = replay_journal(p, tmp)
    log.warning("%s was not closed by its writer: rebuilt from its journal (%d changes%s)", p, n,
                ", the last one cut short and left out" if torn else "")
    Journal.discard(jp)
    return True
