"""Small adapters of the station engine: session log records as page messages, an analyser that notes
when each block arrives."""
from __future__ import annotations

import logging
from typing import Any

__all__ = ["LogToPage", "Timed"]


class LogToPage(logging.Handler):
    """Session events (link faults, rejections, resumes) as page messages."""

    def __init__(self, state: Any) -> None:
        super().__init__(logging.INFO)
        self.state = state

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.state.message(record.levelname, record.getMessage())
        except Exception:  # noqa: BLE001 - a log handler must never break the session
            self.handleError(record)


class Timed:
    """The analyser with the arrival time of each block noted (for the latency figures)."""

    def __init__(self, analyser: Any, engine: Any) -> None:
        self._a = analyser
        self._engine = engine

    def __getattr__(self, name: str) -> Any:
        return getattr(self._a, name)

    def read_block(self, *args: Any, **kwargs: Any) -> Any:
        block = self._a.read_block(*args, **kwargs)
        self._engine.mark_block()
        return block

