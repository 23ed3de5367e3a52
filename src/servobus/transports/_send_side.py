"""A link's send side (private): its counters, its send queue, its send reports and its bus-off gate.

:class:`SendSide` is a base class of :class:`~servobus.transports.base.Transport` that owns what
sending needs, so that the transport keeps its life (open, close, loss, reopen) and the hot path of a
send (``Transport._enqueue``):

* the counters (``self._stats``: every part of the link counts into them);
* the bounded queue and its writer (:class:`~servobus.transports._sending.SendQueue`,
  ``self._sending``; ``self._queue`` is its deque, read on every send);
* the send reports: ``_sent(handle, at)`` when a frame left, ``_dropped(reason, handles)`` when it
  never will, to the reporter :meth:`SendSide.set_send_reporter` sets;
* the bus-off state of a CAN controller (:class:`~servobus.transports._busoff.BusOffState`,
  ``self._bus_off``), which refuses sends while the controller is off.

What it needs of the transport it is given at construction: the clock, whether the transport serves
(its loop, or the error saying why not), how to write a batch and how to report a lost device.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable, Sequence
from typing import Any, Generic, TypeVar

from servobus.frame import Frame
from servobus.runtime import Runtime
from servobus.transports._busoff import BusOffState
from servobus.transports._listeners import EventSource
from servobus.transports._sending import Outgoing, SendQueue, SendReporter
from servobus.transports.events import FramesDropped
from servobus.transports.stats import TransportStats

__all__ = ["SendSide"]

logger = logging.getLogger("servobus.transports")

TxT = TypeVar("TxT")


class SendSide(EventSource, Generic[TxT]):
    """A link's counters, send queue, send reports and bus-off gate (a base class of Transport, which
    owns them): every frame :meth:`send` accepted is reported once, by the handle it was sent with.

    Raises:
        ValueError: a queue of no frames, or a staleness that is not positive.

    Args:
        name: the link's label.
        clock: the link's clock.
        serving: the link's loop while it is open; else raises why it is not.
        queue_size, stale_after_s, batch_size: the send queue's (see Transport).
        probe_s: while bus-off, one frame this often still goes to the adapter.
        transmit, lose: the link's writing of a batch, and its loss of the device.
    """

    def __init__(
        self,
        name: str,
        clock: Callable[[], float],
        serving: Callable[[], Runtime],
        *,
        queue_size: int,
        stale_after_s: float | None,
        batch_size: int,
        probe_s: float,
        transmit: Callable[[list[Outgoing[TxT]]], Awaitable[None]],
        lose: Callable[[BaseException, int], None],
    ) -> None:
        if queue_size < 1:
            raise ValueError(f"queue_size={queue_size} must be at least 1")
        if stale_after_s is not None and stale_after_s <= 0:
            raise ValueError(f"stale_after_s={stale_after_s} must be positive (or None)")
        super().__init__(name)
        #: the link's counters (every part of the link counts into them)
        self._stats = TransportStats()
        self._reporter: SendReporter | None = None
        self._sending: SendQueue[TxT] = SendQueue(
            name,
            queue_size,
            stale_after_s,
            batch_size,
            self._stats,
            transmit,
            self._dropped,
            lose,
            clock,
            serving,
        )
        self._queue = self._sending.items  # the send queue itself (read on every send)
        self._bus_off = BusOffState(name, self._stats, self._emit, probe_s)

    @property
    def stale_after_s(self) -> float | None:
        """How long a queued frame may wait before it is dropped as stale (None: no limit)."""
        return self._sending.stale_after_s

    @property
    def queue_room(self) -> int:
        """Frames :meth:`send` accepts now without raising :class:`SendQueueFull`."""
        return self._sending.size - len(self._queue)

    async def drain(self) -> None:
        """Wait until every queued frame has been written (or dropped by policy).

        Raises:
            TransportError: the device was lost or the transport closed meanwhile.
        """
        await self._sending.drain()

    @property
    def bus_off(self) -> bool:
        """True while the CAN controller is bus-off (sends fail fast with BusOffError)."""
        return self._bus_off.since is not None

    def set_send_reporter(self, reporter: SendReporter | None) -> None:
        """Call ``reporter(handle, sent_at, None)`` for every frame that left, and
        ``reporter(handle, None, reason)`` for every one dropped after :meth:`send` accepted it.

        Called on the loop; its exceptions are logged, never raised into the transport.
        """
        self._reporter = reporter

    def _dropped(self, reason: str, handles: Sequence[Any] | int, counter: str | None = None) -> None:
        """Count frames that will never be sent (in the counter named ``counter``, or ``reason``),
        and report each one whose handle is known with ``reason``."""
        count = handles if isinstance(handles, int) else len(handles)
        if count:
            counter = counter or reason
            setattr(self._stats, counter, getattr(self._stats, counter) + count)
            self._emit(FramesDropped(counter, count, self._sending.clock()))
            reporter = self._reporter
            if reporter is not None and not isinstance(handles, int):
                for handle in handles:
                    self._call(reporter, handle, None, reason)

    def _sent(self, handle: Any, sent_at: float, frame: Frame | None = None) -> None:
        """Report that the frame sent with ``handle`` left at ``sent_at``; counting is the subclass's,
        or give the ``frame`` to count it (``frames_out``, ``bytes_out``) here."""
        if frame is not None:
            stats = self._stats
            stats.frames_out += 1
            stats.bytes_out += len(frame.data)
        if self._reporter is not None:
            self._call(self._reporter, handle, sent_at, None)

    @staticmethod
    def _handle(frame: object, handle: object) -> object:
        """The handle a report of ``frame`` carries: the one given, else the frame."""
        return frame if handle is None else handle

    def _call(self, callback: Callable[..., object], *args: object) -> None:
        try:
            callback(*args)
        except Exception:
            logger.exception("%s: callback %r failed", self.name, callback)
