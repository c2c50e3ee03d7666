"""A scripted Transport for byte-exact driver tests (PyMeasure ``expected_protocol`` style).

The script is a list of steps:

* ``(sent, reply)``: the host must write exactly ``sent`` (over one or more writes); then the
  device answers ``reply``: ``bytes`` (one stream / one transfer), a list of transfers (each item
  ``bytes`` or an exception instance raised at that read), or ``b""`` for nothing;
* ``RESET``: the host must call ``reset_recovery()`` here;
* ``CLEAR_IN``: the host must call ``clear_halt(True)`` here.

Any mismatch fails at once; :meth:`ScriptedTransport.check_done` fails if steps or reply bytes
are left over.
"""
from __future__ import annotations

import collections

from acquisition.errors import TransportTimeout
from acquisition.transport import Transport

RESET = "RESET"
CLEAR_IN = "CLEAR_IN"


class ScriptedTransport(Transport):
    def __init__(self, script, packetized: bool = False, url: str = "scripted://") -> None:
        self.script = collections.deque(script)
        self.packetized = packetized
        self.url = url
        self._sent = bytearray()
        self._rx: collections.deque = collections.deque()
        self.closed = False

    def _head(self, what: str):
        assert self.script, f"host did {what} after the script ended"
        return self.script[0]

    def write(self, data: bytes, timeout_s: float) -> None:
        assert timeout_s > 0, "every write must be bounded"
        assert not self._rx, f"host wrote {bytes(data).hex()} with {sum(map(len, self._rx))} reply bytes unread"
        step = self._head(f"write({bytes(data).hex()})")
        assert step not in (RESET, CLEAR_IN), f"expected {step}, host wrote {bytes(data).hex()}"
        expected, reply = step
        self._sent += data
        assert expected[:len(self._sent)] == bytes(self._sent), (
            f"host sent {bytes(self._sent).hex()}\n      expected {expected.hex()}")
        if len(self._sent) == len(expected):
            self.script.popleft()
            self._sent = bytearray()
            items = reply if isinstance(reply, list) else ([reply] if reply else [])
            self._rx.extend(items)

    def read(self, n: int, timeout_s: float) -> bytes:
        assert timeout_s > 0, "every read must be bounded"
        assert not self._sent, f"host reads while its command {bytes(self._sent).hex()} is incomplete"
        if not self._rx:
            raise TransportTimeout(f"scripted: nothing to read (asked {n} bytes)")
        head = self._rx[0]
        if isinstance(head, BaseException):
            self._rx.popleft()
            raise head
        if self.packetized:
            out, rest = head[:n], head[n:]
            if rest:
                self._rx[0] = rest
            else:
                self._rx.popleft()
            return bytes(out)
        buf = bytearray()
        while len(buf) < n and self._rx and not isinstance(self._rx[0], BaseException):
            head = self._rx.popleft()
            take = n - len(buf)
            buf += head[:take]
            if len(head) > take:
                self._rx.appendleft(head[take:])
        if len(buf) < n:
            raise TransportTimeout(f"scripted: only {len(buf)} of {n} bytes")
        return bytes(buf)

    def reset_recovery(self, timeout_s: float = 1.0) -> None:
        step = self._head("reset_recovery()")
        assert step == RESET, f"host did reset recovery; expected {step!r}"
        self.script.popleft()
        self._rx.clear()

    def clear_halt(self, direction_in: bool) -> None:
        step = self._head("clear_halt()")
        assert direction_in and step == CLEAR_IN, f"host cleared halt (in={direction_in}); expected {step!r}"
        self.script.popleft()

    def close(self) -> None:
        self.closed = True

    def check_done(self) -> None:
        assert not self.script, f"{len(self.script)} scripted steps never happened: {list(self.script)[:2]}"
        assert not self._rx, "reply bytes were left unread"
        assert not self._sent, "a command was only partly written"
