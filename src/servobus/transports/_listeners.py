"""A link's event listeners, and the same events as an async stream (anyio memory object streams)."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Callable

import anyio

from servobus.transports.events import StateChanged, TransportEvent, TransportState

__all__ = ["EventSource", "Listener", "Listeners"]

logger = logging.getLogger("servobus.transports")

Listener = Callable[[TransportEvent], object]


class Listeners:
    """Who hears a link's events: callbacks called in order, on the loop, whose errors are logged."""

    __slots__ = ("_listeners", "_name")

    def __init__(self, name: str) -> None:
        self._name = name
        self._listeners: list[Listener] = []

    def add(self, listener: Listener) -> None:
        self._listeners.append(listener)

    def remove(self, listener: Listener) -> None:
        """Raises ValueError when ``listener`` was not added."""
        self._listeners.remove(listener)

    def emit(self, event: TransportEvent) -> None:
        for listener in list(self._listeners):
            try:
                listener(event)
            except Exception:
                logger.exception("%s: event listener %r failed", self._name, listener)

    async def stream(self, maxsize: int) -> AsyncIterator[TransportEvent]:
        """Every event from now on, ending after a ``StateChanged`` to CLOSED.

        At most ``maxsize`` wait for the reader: when it lags further, the oldest are dropped.
        """
        if maxsize < 1:
            raise ValueError(f"maxsize={maxsize} must be at least 1")
        send, receive = anyio.create_memory_object_stream[TransportEvent](maxsize)

        def collect(event: TransportEvent) -> None:
            try:
                send.send_nowait(event)
            except anyio.WouldBlock:  # the reader lags: the oldest event makes room
                receive.receive_nowait()
                send.send_nowait(event)

        self.add(collect)
        try:
            with send, receive:
                async for event in receive:
                    yield event
                    if isinstance(event, StateChanged) and event.state is TransportState.CLOSED:
                        return
        finally:
            self.remove(collect)


class EventSource:
    """A link's name and events: listeners called on the loop, or the same events as a stream (a base
    class of Transport, which owns both)."""

    def __init__(self, name: str) -> None:
        #: a label for errors, logs and threads
        self.name = name
        self._listeners = Listeners(name)

    def add_listener(self, listener: Listener) -> None:
        """Call ``listener(event)`` on the loop for every event; its exceptions are logged, not raised."""
        self._listeners.add(listener)

    def remove_listener(self, listener: Listener) -> None:
        self._listeners.remove(listener)

    def events(self, maxsize: int = 1000) -> AsyncIterator[TransportEvent]:
        """Events as an async stream, ending after the link closes (oldest dropped when full)."""
        return self._listeners.stream(maxsize)

    def _emit(self, event: TransportEvent) -> None:
        self._listeners.emit(event)
