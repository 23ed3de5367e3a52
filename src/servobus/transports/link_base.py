"""The plumbing every in-process :class:`~servobus.bus.FrameLink` shares (test doubles, bench links).

A subclass writes ``send(frame)`` and delivers with ``self._consumer`` / ``self._reporter``, on
``self._loop``; opening, closing, the callbacks and the listeners are here, once.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from servobus.frame import Frame
from servobus.transports.events import TransportEvent

__all__ = ["LinkBase"]


class LinkBase:
    """Open/close on the running loop, the consumer, the send reporter and the event listeners."""

    name = "link"

    def __init__(self) -> None:
        self._open = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._consumer: Callable[[list[Frame]], object] | None = None
        self._reporter: Callable[[Frame, float | None, str | None], object] | None = None
        self._listeners: list[Callable[[TransportEvent], object]] = []

    @property
    def is_open(self) -> bool:
        return self._open

    async def open(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._open = True

    async def close(self) -> None:
        self._open = False

    def set_consumer(self, consumer: Callable[[list[Frame]], object] | None) -> None:
        self._consumer = consumer

    def set_send_reporter(self, reporter: Callable[[Frame, float | None, str | None], object] | None) -> None:
        self._reporter = reporter

    def add_listener(self, listener: Callable[[TransportEvent], object]) -> None:
        self._listeners.append(listener)

    def remove_listener(self, listener: Callable[[TransportEvent], object]) -> None:
        self._listeners.remove(listener)
