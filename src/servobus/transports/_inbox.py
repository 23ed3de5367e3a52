"""A transport's receive side: push delivery to one consumer, or a bounded buffer its readers wait on."""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import AsyncIterator, Callable, Sequence
from typing import Generic, TypeVar

from servobus.errors import TransportError
from servobus.runtime import Runtime
from servobus.transports._waiters import WaiterList

__all__ = ["Inbox", "ReceiveSide"]

logger = logging.getLogger("servobus.transports")

RxT = TypeVar("RxT")


class Inbox(Generic[RxT]):
    """Received frames: to the consumer when there is one, else buffered (the oldest dropped).

    Args:
        name: the transport's, for logs.
        capacity: frames buffered for readers before the oldest are dropped.
        overflow: ``overflow(count)`` when frames were dropped for want of a reader.
        serving: the transport's loop while it is open; else raises why it is not (a reader waits
            only on an open transport).
        closed: whether the transport is closed (an ``async for`` then ends instead of raising).

    Raises:
        ValueError: a capacity of no frames.
    """

    __slots__ = ("_capacity", "_name", "_overflow", "closed", "consumer", "frames", "readers", "serving")

    def __init__(
        self,
        name: str,
        capacity: int,
        overflow: Callable[[int], object],
        serving: Callable[[], Runtime],
        closed: Callable[[], bool],
    ) -> None:
        if capacity < 1:
            raise ValueError(f"rx_buffer={capacity} must be at least 1")
        self._name = name
        self._capacity = capacity
        self._overflow = overflow
        self.serving = serving
        self.closed = closed
        self.frames: deque[RxT] = deque()
        self.readers = WaiterList()
        self.consumer: Callable[[list[RxT]], object] | None = None

    def set_consumer(self, consumer: Callable[[list[RxT]], object] | None) -> None:
        self.consumer = consumer
        if consumer is not None and self.frames:
            frames = list(self.frames)
            self.frames.clear()
            self._hand(consumer, frames)

    def deliver(self, frames: Sequence[RxT]) -> None:
        consumer = self.consumer
        if consumer is not None:
            self._hand(consumer, frames if isinstance(frames, list) else list(frames))
            return
        buffered = self.frames
        buffered.extend(frames)
        if (overflow := len(buffered) - self._capacity) > 0:
            for _ in range(overflow):
                buffered.popleft()
            self._overflow(overflow)
        self.readers.wake_all()

    def _hand(self, consumer: Callable[[list[RxT]], object], frames: list[RxT]) -> None:
        try:
            consumer(frames)
        except Exception:
            logger.exception("%s: consumer %r failed", self._name, consumer)

    async def wait(self) -> None:
        """Until frames arrive (or the readers are failed).

        Raises:
            TransportError: the transport is not open.
        """
        await self.readers.park(self.serving())

    def take(self, max_frames: int | None) -> list[RxT]:
        buffered = self.frames
        if max_frames is None or max_frames >= len(buffered):
            frames = list(buffered)
            buffered.clear()
            return frames
        return [buffered.popleft() for _ in range(max_frames)]


class ReceiveSide(Generic[RxT]):
    """A link's receiving API over the :class:`Inbox` it owns (a base class of Transport)."""

    def __init__(self, inbox: Inbox[RxT]) -> None:
        self._inbox = inbox

    def set_consumer(self, consumer: Callable[[list[RxT]], object] | None) -> None:
        """Push delivery: call ``consumer(frames)`` on the loop with every received batch.

        With a consumer, nothing is buffered for :meth:`receive`; frames already buffered are handed
        to it at once. Its exceptions are logged, never raised into the reader. None goes back to
        buffering.
        """
        self._inbox.set_consumer(consumer)

    def _deliver(self, frames: Sequence[RxT]) -> None:
        """Hand received frames to the consumer, or to readers (call on the loop)."""
        self._inbox.deliver(frames)

    async def receive(self) -> RxT:
        """The next received frame (frames received before a loss or close come first).

        Raises:
            TransportError: the device is lost or the transport closed, and nothing is buffered.
        """
        inbox = self._inbox
        buffered = inbox.frames
        while not buffered:
            await inbox.wait()
        return buffered.popleft()

    async def receive_batch(self, max_frames: int | None = None) -> list[RxT]:
        """Every buffered frame (at most ``max_frames``), waiting for at least one."""
        inbox = self._inbox
        while not inbox.frames:
            await inbox.wait()
        return inbox.take(max_frames)

    async def __aiter__(self) -> AsyncIterator[RxT]:
        """Received frames until the transport is closed; a loss raises TransportError."""
        while True:
            try:
                yield await self.receive()
            except TransportError:
                if self._inbox.closed():
                    return
                raise
