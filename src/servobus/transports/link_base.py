"""The plumbing every in-process :class:`~servobus.transports.contract.FrameLink` shares (test doubles,
bench links), on anyio: it runs on asyncio and on trio.

A subclass writes ``send(frame, handle=None)`` and, on the loop, reports with
``self._sent(handle, sent_at)`` / ``self._dropped(reason, handles)`` and delivers with
``self._deliver(frames)`` (each counts into :meth:`LinkBase.stats`); it declares its line with a
``rules`` class attribute (:class:`~servobus.transports.contract.LineRules`, default
``LineRules()``). Opening, closing, the task group, the callbacks, the counters and the listeners
are here, once:

* ``open()`` takes the loop's :class:`~servobus.runtime.Runtime` into ``self._runtime`` (``time``,
  ``call_soon``, ``waiter``) and enters the link's task group (``self._tasks``: a subclass starts
  its background tasks there); ``close()``, from the same task, cancels them, waits for them and
  leaves it (a task's error is raised there). ``async with link:`` does both. Start tasks from a
  task (anyio cannot start one from a bare loop callback on asyncio).
* ``self._loop`` is the asyncio loop when the link runs on asyncio (None on trio), for subclasses
  written against asyncio's ``call_at`` (they run on asyncio only).
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Callable, Sequence
from types import TracebackType
from typing import Any, Self

from servobus import runtime as _runtime
from servobus.errors import TransportError
from servobus.frame import Frame
from servobus.transports._listeners import Listener, Listeners
from servobus.transports._owned import LinkTasks, OwnedTaskGroup, owned_exit
from servobus.transports._sending import SendReporter
from servobus.transports.contract import Consumer, LineRules
from servobus.transports.events import FramesDropped, StateChanged, TransportEvent, TransportState
from servobus.transports.stats import TransportStats

__all__ = ["LinkBase"]

logger = logging.getLogger("servobus.transports")


class LinkBase:
    """Open/close in one task with a task group, the consumer, the send reporter, counters, listeners."""

    name = "link"
    #: the line's rules (the FrameLink contract); a subclass declares its own
    rules: LineRules = LineRules()

    def __init__(self) -> None:
        self._open = False
        self._runtime: _runtime.Runtime | None = None
        self._loop: Any = None
        self._owned = OwnedTaskGroup(self.name)
        self._consumer: Consumer | None = None
        self._reporter: SendReporter | None = None
        self._listeners = Listeners(self.name)
        self._stats = TransportStats()

    @property
    def is_open(self) -> bool:
        return self._open

    @property
    def _tasks(self) -> LinkTasks:
        """The link's task group (between ``open()`` and ``close()``)."""
        tasks = self._owned.tasks
        if tasks is None:
            raise RuntimeError(f"{self.name}: no task group: the link is not open")
        return tasks

    def _now(self) -> float:
        """The loop's clock (``anyio.current_time()``)."""
        if self._runtime is None:
            raise TransportError(f"{self.name}: not open")
        return self._runtime.time()

    async def open(self) -> None:
        """Take the running loop and enter the link's task group.

        Raises:
            RuntimeError: already open.
        """
        if self._open:
            raise RuntimeError(f"{self.name} is already open")
        self._runtime = lane = _runtime.current()
        self._loop = getattr(lane, "loop", None)
        await self._owned.enter()
        self._open = True
        self._emit(StateChanged(TransportState.OPEN, lane.time()))

    async def close(self) -> None:
        """Cancel the link's tasks, wait for them and leave its task group (from the opening task).

        Closing twice is harmless.

        Raises:
            RuntimeError: called from another task than the one that opened the link.
            BaseExceptionGroup: a task of the link failed.
        """
        await self._close(None, None, None)

    async def _close(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool:
        if not self._open:
            return False
        self._owned.check_owner("close()")
        self._open = False
        try:
            return await self._owned.leave(exc_type, exc, tb)
        finally:
            if self._runtime is not None:
                self._emit(StateChanged(TransportState.CLOSED, self._runtime.time()))

    async def __aenter__(self) -> Self:
        await self.open()
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool:
        return await self._close(*owned_exit(exc_type, exc, tb))

    # ---- the FrameLink surface ----

    def send(self, frame: Frame, handle: object = None) -> None:
        """Hand ``frame`` over; its report carries ``handle`` (``frame`` when None)."""
        raise NotImplementedError

    def set_consumer(self, consumer: Consumer | None) -> None:
        self._consumer = consumer

    def set_send_reporter(self, reporter: SendReporter | None) -> None:
        self._reporter = reporter

    def add_listener(self, listener: Listener) -> None:
        self._listeners.add(listener)

    def remove_listener(self, listener: Listener) -> None:
        self._listeners.remove(listener)

    def stats(self) -> TransportStats:
        """The counters kept by :meth:`_sent`, :meth:`_dropped` and :meth:`_deliver`."""
        snapshot = copy.copy(self._stats)
        snapshot.state = TransportState.OPEN if self._open else TransportState.CLOSED
        return snapshot

    # ---- for subclasses ----

    def _sent(self, handle: object, sent_at: float, frame: Frame | None = None) -> None:
        """Report the frame sent with ``handle`` as left at ``sent_at`` (``frame``: to count its bytes)."""
        self._stats.frames_out += 1
        if frame is not None:
            self._stats.bytes_out += len(frame.data)
        if self._reporter is not None:
            self._guarded(self._reporter, handle, sent_at, None)

    def _dropped(self, reason: str, handles: Sequence[object]) -> None:
        """Report the frames sent with ``handles`` as never to leave, for ``reason`` (a counter of
        :class:`~servobus.transports.stats.TransportStats`: ``"stale"``, ``"purged"``, ...)."""
        if not handles:
            return
        if hasattr(self._stats, reason):
            setattr(self._stats, reason, getattr(self._stats, reason) + len(handles))
        if self._runtime is not None:
            self._emit(FramesDropped(reason, len(handles), self._runtime.time()))
        if self._reporter is not None:
            for handle in handles:
                self._guarded(self._reporter, handle, None, reason)

    def _deliver(self, frames: list[Frame]) -> None:
        """Hand received frames to the consumer (on the loop)."""
        self._stats.frames_in += len(frames)
        self._stats.bytes_in += sum(len(frame.data) for frame in frames)
        if self._consumer is not None:
            self._guarded(self._consumer, frames)

    def _guarded(self, callback: Callable[..., object], *args: object) -> None:
        """Call the owner's consumer or reporter: its error is logged, as a Transport does, and
        never reaches the link's own code (a task of it, or a callback on trio's queue)."""
        try:
            callback(*args)
        except Exception:
            logger.exception("%s: callback %r failed", self.name, callback)

    def _emit(self, event: TransportEvent) -> None:
        self._listeners.emit(event)

    @staticmethod
    def _handle(frame: Frame, handle: object) -> object:
        """The handle a report of ``frame`` carries: the one given, else the frame."""
        return frame if handle is None else handle

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name} {'open' if self._open else 'closed'}>"
