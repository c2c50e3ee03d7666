"""Fit one input of a batch (the function a Dask worker runs) and name results by content.

:func:`fit_one` never raises for a bad input: an unreadable file, a file with no FRFs or a fit
that fails becomes a result with ``status = "error"`` and the reason, so the batch goes on. A
result records the input's SHA-256 and the options (:func:`options_key`), which is what makes a
batch restartable: a result is reused only for the same content and the same options.
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import socket
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["RESULT_SCHEMA", "file_sha256", "options_key", "fit_one", "result_is_current"]

RESULT_SCHEMA = "impactlab.batch-fit/1"


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

    from ..errors import ImpactlabError
    from ..inputs import load_input
    from ..pipeline import fit_auto
    from ..report import result_to_dict

    t0, c0 = time.perf_counter(), time.process_time()
    doc: dict[str, Any] = {"schema": RESULT_SCHEMA, "input": name, "path": str(path), "sha256": sha256,
                           "options": {"band": None if band is None else [float(b) for b in band],
                                       "estimator": estimator, "key": options_key(band, estimator)},
                           "status": "ok", "error": None, "fit": None,
                           "worker": f"{socket.gethostname()}:{os.getpid()}"}
    quiet = logging.getLogger("analysis")        # its warnings go into the result, not a worker's stderr
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            frf = load_input(path, estimator=estimator)
            fit = fit_auto(frf, band=band)
        notes = list(fit.warnings) + [str(w.message) for w in caught if str(w.message) not in fit.warnings]
        doc["fit"] = result_to_dict(fit, frf, extra={"input": str(path), "warnings": notes})
        if not doc["fit"]["poles"]:
            doc.update(status="error", error="the fit found no modes in the band")
    except (ImpactlabError, OSError, ValueError, KeyError, IndexError, TypeError, ArithmeticError,
            RuntimeError) as exc:
        # a bad input (or a numerical failure on it) is a row of the batch, not the end of it
        doc.update(status="error", error=f"{type(exc).__name__}: {exc}")
    finally:
        quiet.setLevel(level)
    doc["seconds"] = time.perf_counter() - t0
    doc["cpu_seconds"] = time.process_time() - c0
    return doc


def result_is_current(path: Path, sha256: str, key: str) -> dict[str, Any] | None:
    """The stored result at ``path`` if it is for this content (``sha256``) and options (``key``)
    and is complete; None otherwise (missing, another input version, unreadable)."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    if (isinstance(doc, dict) and doc.get("schema") == RESULT_SCHEMA and doc.get("sha256") == sha256
            and (doc.get("options") or {}).get("key") == key and doc.get("status") in ("ok", "error")):
        return doc
    return None
