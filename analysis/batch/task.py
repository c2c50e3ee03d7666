"""Fit one input of a batch (the function a Dask worker runs) and name results by content.

:func:`fit_one` never raises for a bad input: an unreadable file, a file with no FRFs or a fit
that fails becomes a result with ``status = "error"`` and the reason, so the batch goes on. A
result records the input's SHA-256 and the options (:func:`options_key`), which is what makes a
batch restartable: a result is reused only for the same content and the same options.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import socket
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from ..errors import ImpactlabError

__all__ = ["RESULT_SCHEMA", "ROW_ERRORS", "file_sha256", "options_key", "fit_one", "result_is_current", "batch_row",
           "stored_if_current"]

RESULT_SCHEMA = "impactlab.batch-fit/1"

#: what one unit's work may raise that makes its row an error (a bad input, a numerical failure on it),
#: not the end of the batch
ROW_ERRORS: tuple[type[BaseException], ...] = (ImpactlabError, OSError, ValueError, KeyError, IndexError, TypeError,
                                               ArithmeticError, RuntimeError)


@contextlib.contextmanager
def batch_row(doc: dict[str, Any]) -> Iterator[None]:
    """Run one unit's work (a fit, a diagnosis) as a row of the batch: the ``analysis`` logger quiet
    below ERROR meanwhile (its messages go into the row, not a worker's stderr); an error of
    :data:`ROW_ERRORS` becomes the row's ``status = "error"`` and ``error`` (its type and message);
    ``doc["seconds"]`` and ``doc["cpu_seconds"]`` get the wall and process CPU time (s) of the work."""
    t0, c0 = time.perf_counter(), time.process_time()
    quiet = logging.getLogger("analysis")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        yield
    except ROW_ERRORS as exc:
        doc.update(status="error", error=f"{type(exc).__name__}: {exc}")
    finally:
        quiet.setLevel(level)
    doc["seconds"] = time.perf_counter() - t0
    doc["cpu_seconds"] = time.process_time() - c0


def stored_if_current(path: str | os.PathLike[str], schema: str, sha256: str, key: str,
                      key_of: Callable[[dict], Any]) -> dict[str, Any] | None:
    """The stored row at ``path`` if it is complete (status ok or error), of ``schema``, of this
    content (``sha256``) and of these options (``key_of(doc) == key``); None otherwise (missing,
    unreadable, another input version or other options)."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    if (isinstance(doc, dict) and doc.get("schema") == schema and doc.get("sha256") == sha256
            and key_of(doc) == key and doc.get("status") in ("ok", "error")):
        return doc
    return None


def file_sha256(path: str | os.PathLike[str], chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file's bytes (read in 1 MiB pieces)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while True:
            block = fh.read(chunk)
            if not block:
                break
            h.update(block)
    return h.hexdigest()


def options_key(band: Sequence[float] | None, estimator: str | None) -> str:
    """A short fingerprint of the options that change a fit (band in Hz, FRF estimator)."""
    text = json.dumps({"schema": RESULT_SCHEMA, "band": None if band is None else [float(b) for b in band],
                       "estimator": estimator}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def fit_one(path: str, name: str, sha256: str, band: Sequence[float] | None = None,
            estimator: str | None = None) -> dict[str, Any]:
    """Load ``path`` (recording or UFF 58), run the automatic fit (:func:`analysis.pipeline.fit_auto`)
    in ``band`` (Hz; None: the band the data support) and return the result document:
    ``{schema, input, path, sha256, options, status: "ok"|"error", error, fit, seconds, cpu_seconds, worker}``
    where ``fit`` is the ``analysis fit --json`` document (poles, damping, standard deviations,
    mode shapes), ``seconds`` the wall time and ``cpu_seconds`` the process's CPU time (s) of the
    load and fit (on a busy machine the CPU time is the work, the wall time also the waiting)."""
    import warnings

    from ..inputs import load_input
    from ..pipeline import fit_auto
    from ..report import result_to_dict

    doc: dict[str, Any] = {"schema": RESULT_SCHEMA, "input": name, "path": str(path), "sha256": sha256,
                           "options": {"band": None if band is None else [float(b) for b in band],
                                       "estimator": estimator, "key": options_key(band, estimator)},
                           "status": "ok", "error": None, "fit": None,
                           "worker": f"{socket.gethostname()}:{os.getpid()}"}
    with batch_row(doc):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            frf = load_input(path, estimator=estimator)
            fit = fit_auto(frf, band=band)
        notes = list(fit.warnings) + [str(w.message) for w in caught if str(w.message) not in fit.warnings]
        doc["fit"] = result_to_dict(fit, frf, extra={"input": str(path), "warnings": notes})
        if not doc["fit"]["poles"]:
            doc.update(status="error", error="the fit found no modes in the band")
    return doc


def result_is_current(path: Path, sha256: str, key: str) -> dict[str, Any] | None:
    """The stored result at ``path`` if it is for this content (``sha256``) and options (``key``)
    and is complete; None otherwise (missing, another input version, unreadable)."""
    return stored_if_current(path, RESULT_SCHEMA, sha256, key, lambda d: (d.get("options") or {}).get("key"))
