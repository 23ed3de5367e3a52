"""A transport's receive side: push delivery to one consumer, or a bounded buffer its readers wait on."""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Sequence
from typing import Generic, TypeVar

from servobus.runtime import Runtime
from servobus.transports._waiters import WaiterList

__all__ = ["Inbox"]

logger = logging.getLogger("servobus.transports")

RxT = TypeVar("RxT")


class Inbox(Generic[RxT]):
    """Received frames: to the consumer when there is one, else buffered (the oldest dropped).

    Args:
        name: the transport's, for logs.
        capacity: frames buffered for readers before the oldest are dropped.
        overflow: ``overflow(count)`` when frames were dropped for want of a reader.
    """

    __slots__ = ("_capacity", "_name", "_overflow", "consumer", "frames", "readers")

    def __init__(self, name: str, capacity: int, overflow: Callable[[int], object]) -> None:
        self._name = name
        self._capacity = capacity
        self._overflow = overflow
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

    async def wait(self, runtime: Runtime) -> None:
        """Until frames arrive (or the readers are failed)."""
        await self.readers.park(runtime)

    def take(self, max_frames: int | None) -> list[RxT]:
        buffered = self.frames
        if max_frames is None or max_frames >= len(buffered):
            frames = list(buffered)
            buffered.clear()
            return frames
        return [buffered.popleft() for _ in range(max_frames)]
