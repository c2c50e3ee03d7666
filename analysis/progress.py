"""Progress of long steps (a fit of a long FRF set, a stabilization diagram, a diagnosis): one
logger, ``impactlab.progress``, that the command lines show on stderr unless ``-q`` is given;
library callers see it only when they configure logging themselves."""
from __future__ import annotations

import logging

__all__ = ["PROGRESS_LOGGER", "progress"]

PROGRESS_LOGGER = "impactlab.progress"
_log = logging.getLogger(PROGRESS_LOGGER)


def progress(message: str, *args: object) -> None:
    """Report a step of a long computation (``message % args``)."""
    _log.info(message, *args)
