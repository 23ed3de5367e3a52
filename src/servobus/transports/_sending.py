"""A transport's send side: the bounded queue, and the one writer task per connection that empties it."""

from __future__ import annotations

from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import anyio

from servobus.errors import TransportError
from servobus.runtime import Runtime
from servobus.transports._owned import LinkTasks
from servobus.transports._waiters import Alarm, WaiterList
from servobus.transports.stats import TransportStats

__all__ = [
    "BusOffError",
    "Outgoing",
    "SendQueue",
    "SendQueueFull",
    "SendReporter",
    "not_sent_error",
]

#: ``reporter(handle, sent_at, reason)`` (contract.SendReporter; the handle typed Any, so that a
#: sender whose reporter takes its own handle type, a Bus's Request, type-checks against it)
SendReporter = Callable[[Any, float | None, str | None], object]

TxT = TypeVar("TxT")


class SendQueueFull(TransportError):
    """A send found a queue full: the transport's own (back off, or ``await drain()`` first), or the
    adapter's (ENOBUFS: the frame was not sent, later ones may be).

    (No longer an ``asyncio.QueueFull``: the transports are not asyncio's; catch this, or
    TransportError.)
    """

    #: the send-report reason of a frame this refused (a request's ``not_sent_queue_full``)
    reason = "queue_full"


class BusOffError(TransportError):
    """The CAN controller is bus-off: nothing is sent until it restarts. A state of the link, not a
    lost device: the transport stays open, and sends work again once the controller is back."""

    reason = "bus_off"


#: send-report reasons whose refused frames fail with an error of their own
_NOT_SENT: dict[str, type[TransportError]] = {"queue_full": SendQueueFull, "bus_off": BusOffError}


def not_sent_error(reason: str, message: str) -> TransportError:
    """The error a frame refused for ``reason`` fails with (a TransportError for the other reasons)."""
    return _NOT_SENT.get(reason, TransportError)(message)


@dataclass(slots=True)
class Outgoing(Generic[TxT]):
    """One queued frame: what to write, when it was queued, how long the line stays ours after it,
    and the handle its send report echoes (the item itself when the sender gave none)."""

    item: TxT
    queued_at: float
    hold_s: float | None = None
    handle: Any = None


class SendQueue(Generic[TxT]):
    """Frames waiting for the wire, and the writer task (one per connection) that hands them over.

    The queue owns its items and its writer; the transport owns everything else and hands the
    queue what it needs: ``transmit(batch)`` (its device), ``dropped(reason, handles)`` (its
    reports and counters), ``lose(cause, generation)`` (its recovery), its counters (a full queue
    is counted in ``queue_full``), its ``clock`` and ``serving()`` (its loop while it is open, else
    raises why not: what :meth:`drain` waits on). The writer takes up to ``batch_size`` frames at a
    time, drops those older than ``stale_after_s``, and awaits ``transmit(batch)``. It runs in the
    transport's task group, inside a cancel scope of its own that a loss or a close cancels
    (:meth:`stop`).
    """

    __slots__ = (
        "_alarm",
        "_dropped",
        "_lose",
        "_name",
        "_scope",
        "_stats",
        "_transmit",
        "batch_size",
        "clock",
        "idle",
        "items",
        "serving",
        "size",
        "stale_after_s",
        "transmitting",
    )

    def __init__(
        self,
        name: str,
        size: int,
        stale_after_s: float | None,
        batch_size: int,
        stats: TransportStats,
        transmit: Callable[[list[Outgoing[TxT]]], Awaitable[None]],
        dropped: Callable[[str, list[Any]], None],
        lose: Callable[[BaseException, int], None],
        clock: Callable[[], float],
        serving: Callable[[], Runtime],
    ) -> None:
        self._name = name
        self.size = size
        self.stale_after_s = stale_after_s
        self.batch_size = batch_size
        self._stats = stats
        self._transmit = transmit
        self._dropped = dropped
        self._lose = lose
        self.clock = clock
        self.serving = serving
        self.items: deque[Outgoing[TxT]] = deque()
        self.transmitting = False
        #: tasks in the transport's drain(), woken when the queue is empty and nothing is being written
        self.idle = WaiterList()
        self._alarm = Alarm()  # the writer's, while the queue is empty
        self._scope: anyio.CancelScope | None = None

    @property
    def busy(self) -> bool:
        """Frames are queued or being written."""
        return bool(self.items) or self.transmitting

    def put(self, outgoing: Outgoing[TxT]) -> None:
        if len(self.items) >= self.size:
            self._stats.queue_full += 1
            raise SendQueueFull(
                f"{self._name}: send queue full ({self.size} frames); await drain() before sending more"
            )
        self.items.append(outgoing)
        self._alarm.ring()

    async def drain(self) -> None:
        """Until every queued frame has been written or dropped.

        Raises:
            TransportError: the link is not open, or stops being open meanwhile.
        """
        serving = self.serving
        while self.busy:
            await self.idle.park(serving())
        serving()

    def start(self, tasks: LinkTasks, runtime: Runtime, generation: int) -> None:
        """Start this connection's writer (a loss or a close stops it: :meth:`stop`)."""
        self.stop()
        self._scope = scope = anyio.CancelScope()
        tasks.start_soon(self._run, scope, runtime, generation, name=f"{self._name} writer")

    def stop(self) -> None:
        if self._scope is not None:
            self._scope.cancel()
            self._scope = None
        self.transmitting = False

    def fail(self, error: Callable[[], BaseException]) -> None:
        """The device is gone or the transport closed: stop the writer, purge what is queued (reported
        ``"purged"``), and every task in drain() raises ``error()``."""
        self.stop()
        self.purge("purged")
        self.idle.fail_all(error)

    def purge(self, reason: str) -> None:
        """Drop every queued frame (counted and reported with ``reason``)."""
        if self.items:
            dropped = list(self.items)
            self.items.clear()
            self._dropped(reason, [o.handle for o in dropped])

    async def _run(self, scope: anyio.CancelScope, runtime: Runtime, generation: int) -> None:
        items = self.items
        with scope:
            while True:
                if not items:
                    self.idle.wake_all()
                    await self._alarm.wait(runtime)
                    continue
                batch = [items.popleft() for _ in range(min(self.batch_size, len(items)))]
                batch = self._drop_stale(batch, runtime.time())
                if not batch:
                    continue
                self.transmitting = True
                try:
                    await self._transmit(batch)
                except anyio.get_cancelled_exc_class():
                    raise
                except Exception as exc:  # a transmit bug must not leave the queue stuck forever
                    self._lose(exc, generation)
                    return
                finally:
                    self.transmitting = False
                    # not written: lost, closed or failed
                    self._dropped("purged", [o.handle for o in batch])
                if scope.cancel_called:  # the transmit lost the device (stop() cancelled this writer)
                    return

    def _drop_stale(self, batch: list[Outgoing[TxT]], now: float) -> list[Outgoing[TxT]]:
        limit = self.stale_after_s
        if limit is None or now - batch[0].queued_at <= limit:  # the oldest is first
            return batch
        self._dropped("stale", [o.handle for o in batch if now - o.queued_at > limit])
        return [o for o in batch if now - o.queued_at <= limit]
