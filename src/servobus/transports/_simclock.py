"""The in-process bus's clock: what wakes :class:`~servobus.transports.sim.SimTransport` at the
network's next event, in two lanes behind one interface (``poke(when)``, ``stop()``).

* :class:`TaskClock` (any backend, trio's lane): one task in the transport's task group, idle on a
  runtime waiter while nothing is armed, else asleep until the armed time; arming sooner wakes it
  (the waiter) or cuts its sleep short (a cancel scope), and it fires on its next turn.
* :class:`LoopClock` (asyncio's measured fast lane): the loop's own ``call_at``, as before anyio.
  A task's wake-up costs one more loop iteration per event than a timer callback: under looptime
  the 32-motor scenarios of tests/transports/test_sim.py took 1.4x to 4x the wall time with the
  task, and a reply due before a Bus's time-out timer could lose to it on a stalled loop. The
  callback runs on the loop, is cancelled by ``stop()``, and outlives nothing.

Both fire ``fire(generation)`` on the loop at or after the armed loop time, never before it.
"""

from __future__ import annotations

import contextvars
from collections.abc import Callable
from typing import Any, Protocol

import anyio
import anyio.lowlevel

from servobus.runtime import Runtime
from servobus.transports._owned import LinkTasks
from servobus.transports._waiters import Alarm

__all__ = ["Clock", "LoopClock", "TaskClock", "start_clock"]


class Clock(Protocol):
    def poke(self, when: float) -> None:
        """The armed time moved sooner, to loop time ``when`` (:func:`start_clock`'s ``next_at``)."""

    def stop(self) -> None:
        """Never fire again."""


class LoopClock:
    """asyncio's lane: one ``loop.call_at`` handle on the armed time."""

    __slots__ = ("_context", "_fire", "_generation", "_handle", "_loop")

    def __init__(self, loop: Any, fire: Callable[[int], object], generation: int) -> None:
        self._loop = loop
        self._fire = fire
        self._generation = generation
        self._handle: Any = None
        self._context = _asyncio_context()

    def poke(self, when: float) -> None:
        if self._handle is not None:
            self._handle.cancel()
        self._handle = self._loop.call_at(when, self._on_time, context=self._context)

    def _on_time(self) -> None:
        self._handle = None
        self._fire(self._generation)

    def stop(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None


def _asyncio_context() -> contextvars.Context:
    """The current context, with sniffio (when installed) told that asyncio runs it."""
    context = contextvars.copy_context()
    try:
        import sniffio
    except ImportError:  # anyio then finds asyncio by its running loop, callbacks included
        return context
    context.run(sniffio.current_async_library_cvar.set, "asyncio")
    return context


class TaskClock:
    """Any backend's lane: one task in the transport's task group (see the module's docstring)."""

    __slots__ = ("_alarm", "_fire", "_generation", "_lane", "_next_at", "_stop", "_wait")

    def __init__(
        self,
        lane: Runtime,
        next_at: Callable[[], float | None],
        fire: Callable[[int], object],
        generation: int,
    ) -> None:
        self._lane = lane
        self._next_at = next_at
        self._fire = fire
        self._generation = generation
        self._stop = anyio.CancelScope()
        self._wait: anyio.CancelScope | None = None
        self._alarm = Alarm()  # rung while it idles with nothing armed

    def poke(self, when: float) -> None:
        if self._alarm.waiting:  # idle: wake it (no cancellation)
            self._alarm.ring()
        elif self._wait is not None:  # asleep until a later time: cut the sleep short
            self._wait.cancel()
        # (otherwise it is firing now, and reads the armed time when done)

    def stop(self) -> None:
        self._stop.cancel()

    async def run(self) -> None:
        """Idle on a waiter while nothing is armed, else sleep until the armed time; fire."""
        lane = self._lane
        with self._stop:
            while True:
                when = self._next_at()
                if when is None:
                    await self._alarm.wait(lane)
                    continue
                delay = when - lane.time()
                if delay > 0:
                    # A sleep, not a deadline: the common case (a reply due at a known time) then
                    # costs one timer and no cancellation; only a sooner event cancels it.
                    with anyio.CancelScope() as wait:
                        self._wait = wait
                        await anyio.sleep(delay)
                    self._wait = None
                    if wait.cancel_called:  # armed sooner meanwhile
                        continue
                else:
                    await anyio.lowlevel.checkpoint()  # due already: let the loop turn once
                self._fire(self._generation)


def start_clock(
    lane: Runtime,
    tasks: LinkTasks,
    next_at: Callable[[], float | None],
    fire: Callable[[int], object],
    generation: int,
    *,
    name: str,
    task_lane: bool = False,
) -> Clock:
    """The clock for one connection: asyncio's ``call_at`` lane, or a task (on trio, or when asked)."""
    loop = getattr(lane, "loop", None)  # asyncio's lane carries its loop
    if loop is not None and not task_lane:
        return LoopClock(loop, fire, generation)
    clock = TaskClock(lane, next_at, fire, generation)
    tasks.start_soon(clock.run, name=name)
    return clock
