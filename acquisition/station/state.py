"""The station's session state, held by the server: what every tab shows (a reload or a second tab
sees the same), with a version number that grows on each change, and the control lease.

``snapshot()`` is the small state (phase, point, counts, verdict, messages); the plots' data are
"blobs" (``hit``, ``frf``, ``setup``) fetched separately when their version changes, so a slow
link carries the few hundred bytes of state at once and the plot data only when asked for.
"""
from __future__ import annotations

import collections
import json
import threading
import time
from typing import Any

__all__ = ["Lease", "StationState"]

#: messages kept for the page
MAX_MESSAGES = 200


class Lease:
    """One controlling tab: the client id that holds control until ``ttl_s`` after its last renewal.

    Another tab may take control explicitly (``take=True``), or freely once the holder stopped
    renewing (closed or lost tab)."""

    def __init__(self, ttl_s: float = 15.0, clock: Any = time.monotonic) -> None:
        self.ttl_s = float(ttl_s)
        self._clock = clock
        self.holder: str | None = None
        self._until = 0.0

    def acquire(self, client: str, take: bool = False) -> bool:
        now = self._clock()
        if self.holder in (None, client) or take or now >= self._until:
            self.holder = client
            self._until = now + self.ttl_s
            return True
        return False

    def holds(self, client: str | None) -> bool:
        return client is not None and client == self.holder and self._clock() < self._until


class StationState:
    """Thread-safe state; ``cond`` is notified on every change (server-sent events wait on it)."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.version = 0
        self.hit_seq = 0
        self.lease = Lease()
        self._fields: dict[str, Any] = {}
        self._messages: collections.deque = collections.deque(maxlen=MAX_MESSAGES)
        self._n_messages = 0
        self._blobs: dict[str, tuple[int, bytes]] = {}

    def _changed(self) -> None:
        self.version += 1
        self.cond.notify_all()

    def update(self, **fields: Any) -> None:
        with self.cond:
            self._fields.update(fields)
            self._changed()

    def get(self, key: str, default: Any = None) -> Any:
        with self.cond:
            return self._fields.get(key, default)

    def next_hit_seq(self) -> int:
        with self.cond:
            self.hit_seq += 1
            return self.hit_seq

    def message(self, level: str, text: str) -> None:
        with self.cond:
            self._n_messages += 1
            self._messages.append({"id": self._n_messages, "time": time.time(), "level": str(level),
                                   "text": str(text)})
            self._changed()

    def set_blob(self, name: str, payload: dict) -> None:
        data = json.dumps(payload, allow_nan=False, separators=(",", ":")).encode()
        with self.cond:
            self._blobs[name] = (self.version + 1, data)
            self._changed()

    def blob(self, name: str) -> bytes | None:
        with self.cond:
            item = self._blobs.get(name)
            return None if item is None else item[1]

    def snapshot(self) -> dict:
        with self.cond:
            out = dict(self._fields)
            out["version"] = self.version
            out.setdefault("hit_seq", 0)  # published with its verdict (never ahead of it)
            out["messages"] = list(self._messages)[-50:]
            out["blobs"] = {k: v for k, (v, _) in self._blobs.items()}
            out["controller"] = self.lease.holder
            return out

    def wait_change(self, seen: int, timeout_s: float) -> int:
        """Block until the version passes ``seen`` or ``timeout_s`` passes; the version."""
        with self.cond:
            self.cond.wait_for(lambda: self.version > seen, timeout=timeout_s)
            return self.version
