"""The clients' liveliness tokens, from Zenoh to the bridge's event loop (:class:`Tokens`).

No Python runs per token event on Zenoh's side: the liveliness subscriber queues the samples in
Zenoh's own FIFO channel (Rust, no GIL), and the loop takes everything waiting every
``POLL_S``, coalesced per client: per public id, whether its token went (at least once) and whether
it lives now. So a peer that declares and undeclares thousands of tokens a second costs the other
Python threads no GIL hand-over per event and the loop one batch per poll, and a legitimate client's
coming or going waits for at most one poll, never behind thousands of queued calls. Nothing is
dropped: were the loop to leave ``WAITING`` events untaken (``WAITING / POLL_S`` a second, far more
than a Zenoh session delivers), Zenoh's thread would wait for it rather than lose one.

The rule of a batch: a token that went, even if it came back within the same batch, took the
client's motors with it (its session was lost or it undeclared the token: whatever it held is
stopped); a token that lives at the end of the batch makes the client live again, holding nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import anyio
import zenoh

from servobus.remote._session import sample_kind

POLL_S = 0.005  # how often the loop takes the token events waiting, at least (each bus's tick takes them too)
TAKEN = 4096  # token events taken at most at once (the rest at the next poll)
WAITING = 1 << 16  # token events that may wait in Zenoh's channel before its thread waits for the loop


def channel() -> Any:
    """The handler to declare the liveliness subscriber of ``servobus/N/_clients/*`` with."""
    return zenoh.handlers.FifoChannel(WAITING)


class Tokens:
    """Takes the samples of a liveliness subscriber declared with :func:`channel` and calls
    ``on_batch({public id: (went, alive)})`` on the loop: ``went``, its token vanished at least once
    since the last batch; ``alive``, it lives now."""

    def __init__(self, subscriber: Any, on_batch: Callable[[dict[str, tuple[bool, bool]]], object]) -> None:
        self._subscriber = subscriber
        self._on_batch = on_batch

    async def run(self) -> None:
        """Take the waiting events every ``POLL_S``, until cancelled."""
        while True:
            batch = self.take()
            if batch:
                self._on_batch(batch)
            await anyio.sleep(POLL_S)

    def take(self) -> dict[str, tuple[bool, bool]]:
        """The events waiting, coalesced per client."""
        batch: dict[str, tuple[bool, bool]] = {}
        for _ in range(TAKEN):  # (however fast they come, the loop gets back to its work)
            sample = self._subscriber.try_recv()
            if sample is None:
                break
            client = str(sample.key_expr).rsplit("/", 1)[-1]
            put = sample_kind(sample) == "PUT"
            went, _ = batch.get(client, (False, False))
            batch[client] = (went or not put, put)
        return batch
