"""Link-fault handling of a capture: which errors are link faults, retrying idempotent calls, and
bringing the analyser back to a known state after a fault in the middle of a measurement."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from .errors import CommandFailed, ProtocolError, TransportError
from .session_errors import SessionError

__all__ = ["LINK_FAULTS", "ILLEGAL_REQUEST", "retry_on_link_fault", "recover_link"]

log = logging.getLogger("acquisition.session")

#: errors after which the session recovers (abort, set up again, re-arm) instead of ending
LINK_FAULTS = (ProtocolError, TransportError, CommandFailed)
ILLEGAL_REQUEST = 0x5  # SCSI sense key: the request itself is wrong (not a link fault)


def retry_on_link_fault(fn: Callable[[], Any], attempts: int = 5) -> Any:
    """``fn()`` retried up to ``attempts`` times while it fails with a link fault (phase error,
    timeout, transient CHECK CONDITION: :data:`LINK_FAULTS`; the bulk-only layer has already reset
    the link); the last error is raised when every attempt failed. For idempotent calls only
    (identify, capabilities, configure)."""
    for k in range(max(1, attempts)):
        try:
            return fn()
        except LINK_FAULTS as exc:
            if k + 1 >= attempts or (isinstance(exc, CommandFailed) and exc.sense_key == ILLEGAL_REQUEST):
                raise
            log.warning("link fault (%s: %s); trying again (%d/%d)", type(exc).__name__, exc, k + 1, attempts)
    raise AssertionError("unreachable")  # pragma: no cover


def recover_link(analyser: Any, setup: Any, point: str, exc: Exception, faults_here: int, budget: int,
                 max_link_failures: int, event: Callable[[str, str], None]) -> None:
    """A command failed on the link (phase error, timeout, device gone and back, transient CHECK
    CONDITION...): log it, and bring the analyser back to a known state (abort, set-up again) so
    the next pass re-arms. The hit in flight was not accepted (a hit is accepted only after its
    whole block arrived), so nothing accepted is lost.

    The session ends with :class:`SessionError` saying why (every accepted hit stays in the
    recording) when ``max_link_failures`` recovery attempts in a row fail (the link is dead) or
    the point has met more than ``budget`` link faults (the link
    is too poor to finish)."""
    if isinstance(exc, CommandFailed) and exc.sense_key == ILLEGAL_REQUEST:
        raise exc  # the analyser refuses the request itself: retrying cannot help
    event("WARNING", f"link fault {faults_here}/{budget} at {point} ({type(exc).__name__}: {exc}); "
                     "recovering")
    if faults_here > budget:
        raise SessionError(f"the analyser link failed {faults_here} times at {point} (last: "
                           f"{type(exc).__name__}: {exc}); the recording keeps every accepted hit: check the "
                           "cable or server and resume the test (capture --resume)")
    failures = 0
    while True:
        try:
            abort = getattr(analyser, "abort", None)
            if abort is not None:
                abort()
            analyser.configure(setup)
            return
        except LINK_FAULTS as again:
            exc = again
            failures += 1
            event("WARNING", f"recovery {failures}/{max_link_failures} at {point} failed "
                             f"({type(again).__name__}: {again})")
            if failures >= max_link_failures:
                break
    raise SessionError(f"the analyser link keeps failing at {point} ({failures} recovery attempts in a row "
                       f"failed, last: {type(exc).__name__}: {exc}); the recording keeps every accepted hit: "
                       "check the cable or server and resume the test (capture --resume)")
