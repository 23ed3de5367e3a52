"""The clients' liveliness tokens, from Zenoh's threads to the bridge's event loop (:class:`Tokens`).

Each token's coming (PUT) and going (DELETE) is never dropped, but it is coalesced per client on
Zenoh's thread: what waits for the loop is, per public id, whether its token went (at least once)
and whether it lives now, and the loop is woken once per batch, not once per event. So a peer that
declares and undeclares thousands of tokens a second costs the loop one call per batch, and a
legitimate client's coming or going waits for one batch, never behind thousands of queued events.

The rule of a batch: a token that went, even if it came back within the same batch, took the
client's motors with it (its session was lost or it undeclared the token: whatever it held is
stopped); a token that lives at the end of the batch makes the client live again, holding nothing.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from servobus import runtime
from servobus.remote._session import sample_kind, to_loop


class Tokens:
    """Coalesces the liveliness samples of ``servobus/N/_clients/*`` for ``on_batch``, which the loop
    of ``lane`` calls with ``{public id: (went, alive)}``: ``went``, its token vanished at least once
    since the last batch; ``alive``, it lives now."""

    def __init__(
        self, lane: runtime.Runtime, on_batch: Callable[[dict[str, tuple[bool, bool]]], object]
    ) -> None:
        self._lane = lane
        self._on_batch = on_batch
        self._pending: dict[str, tuple[bool, bool]] = {}
        self._scheduled = False
        self._lock = threading.Lock()

    def callback(self, sample: Any) -> None:
        """(Zenoh's thread) one token came or went."""
        client = str(sample.key_expr).rsplit("/", 1)[-1]
        put = sample_kind(sample) == "PUT"
        with self._lock:
            went, _ = self._pending.get(client, (False, False))
            self._pending[client] = (went or not put, put)
            if self._scheduled:
                return
            self._scheduled = True
        to_loop(self._lane, self._flush)

    def _flush(self) -> None:
        with self._lock:
            batch, self._pending = self._pending, {}
            self._scheduled = False
        self._on_batch(batch)
