"""Tasks parked until something happens to a transport, woken together or failed together.

One list per condition (frames received, the send queue empty, the device open again, ...). A task
parks on a one-shot :meth:`~servobus.runtime.Runtime.waiter` of the loop the transport was opened
on (an ``asyncio.Future``, or trio's :class:`~servobus.runtime.TrioWaiter`); a loss fails every
parked task at once with its own error, which is why these are not ``anyio.Event``s (an event
cannot carry an exception).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

from servobus.runtime import Runtime, Waiter

__all__ = ["Alarm", "WaiterList"]


class WaiterList:
    """Tasks waiting for one condition."""

    __slots__ = ("_waiters",)

    def __init__(self) -> None:
        self._waiters: list[Waiter[Any]] = []

    def __len__(self) -> int:
        return len(self._waiters)

    async def park(self, runtime: Runtime) -> None:
        """Wait until :meth:`wake_all` (return) or :meth:`fail_all` (raise its error)."""
        waiter = runtime.waiter()
        self._waiters.append(waiter)
        try:
            await waiter
        finally:
            with contextlib.suppress(ValueError):  # already taken off by wake_all or fail_all
                self._waiters.remove(waiter)

    def wake_all(self) -> None:
        """Let every parked task go on (they stay listed until they run, then leave)."""
        for waiter in self._waiters:
            if not waiter.done():
                waiter.set_result(None)

    def fail_all(self, error: Callable[[], BaseException]) -> None:
        """Raise a fresh ``error()`` in every parked task, and forget them."""
        for waiter in self._waiters:
            if not waiter.done():
                waiter.set_exception(error())
        self._waiters.clear()


class Alarm:
    """One task's wake-up: it parks in :meth:`wait` until :meth:`ring` (a ring while it does not
    wait is dropped: the task looks at its work again before it parks)."""

    __slots__ = ("_waiter",)

    def __init__(self) -> None:
        self._waiter: Waiter[None] | None = None

    @property
    def waiting(self) -> bool:
        return self._waiter is not None

    async def wait(self, runtime: Runtime) -> None:
        self._waiter = waiter = runtime.waiter()
        try:
            await waiter
        finally:
            self._waiter = None

    def ring(self) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)
