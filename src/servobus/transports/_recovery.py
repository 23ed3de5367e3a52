"""A transport's recovery: the task that reopens a lost device, with exponential backoff.

The transport owns its state and does what a loss means to it (fail its waiters, purge its queue);
this owns only the reopening: when to try again, and how long to wait between tries.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable

import anyio

from servobus.errors import TransportError
from servobus.runtime import Runtime, Waiter
from servobus.transports.stats import TransportStats

__all__ = ["Recovery"]

logger = logging.getLogger("servobus.transports")


class Recovery:
    """The task that brings a lost device back.

    The task (:meth:`watch`) runs from ``open()`` to ``close()`` in the transport's task group and
    waits for a loss (:meth:`lost`): a loss is often reported from a loop callback (a reader's
    ``add_reader`` callback, a thread's ``call_soon_threadsafe``), where no task can be started on
    asyncio.

    Args:
        name: the transport's, for logs.
        reopen: reopen by itself after a loss.
        backoff_s: (first, longest) delay between reopen attempts; it doubles each time.
        stats: the transport's counters (``losses``, ``reopens`` are counted here).
        release: releases the lost device (never raises for one already gone).
        reconnect: one attempt to reopen the device (raises while it is away): whether the
            transport still waits for it (False: it was closed meanwhile).
        reopened: the transport serves again (called once the reopen is counted).
    """

    __slots__ = (
        "_backoff_s",
        "_name",
        "_pending",
        "_reconnect",
        "_release",
        "_reopened",
        "_signal",
        "_stats",
        "reopen",
    )

    def __init__(
        self,
        name: str,
        reopen: bool,
        backoff_s: tuple[float, float],
        stats: TransportStats,
        release: Callable[[], Awaitable[None]],
        reconnect: Callable[[], Awaitable[bool]],
        reopened: Callable[[], None],
    ) -> None:
        first, longest = backoff_s
        if not 0 < first <= longest:
            raise ValueError(f"reopen_backoff_s={backoff_s} must be 0 < first <= longest")
        self._name = name
        self.reopen = reopen
        self._backoff_s = (first, longest)
        self._stats = stats
        self._release = release
        self._reconnect = reconnect
        self._reopened = reopened
        self._pending = False  # a loss not yet taken up by watch()
        self._signal: Waiter[None] | None = None  # what watch() waits on

    def lost(self, cause: BaseException) -> None:
        """The open connection's device failed: counted and logged here, released and reopened by
        the task; what the loss means to the transport's state, the transport does itself."""
        logger.warning("%s: device lost: %s", self._name, cause)
        self._stats.losses += 1
        self._pending = True
        if self._signal is not None and not self._signal.done():
            self._signal.set_result(None)

    async def watch(self, lane: Runtime) -> None:
        """Recover from every loss, until cancelled (by ``close()``)."""
        while True:
            if not self._pending:
                self._signal = signal = lane.waiter()
                try:
                    await signal
                finally:
                    self._signal = None
            self._pending = False
            await self._run()

    async def _run(self) -> None:
        """Release the lost device, then (if asked) reopen it until it answers or the transport closes."""
        try:
            await self._release()
        except Exception as exc:  # the device is gone already: nothing to release
            logger.debug("%s: disconnect after a loss: %s", self._name, exc)
        if not self.reopen:
            return
        delay, longest = self._backoff_s
        while True:
            await anyio.sleep(delay)
            try:
                waited_for = await self._reconnect()
            except Exception as exc:  # the device is still away (or refuses): try again later
                log = logger.debug if isinstance(exc, TransportError) else logger.warning
                log("%s: reopen failed: %s", self._name, exc)
                delay = min(2 * delay, longest)
                continue
            if waited_for:
                self._stats.reopens += 1
                logger.info("%s: reopened", self._name)
                self._reopened()
            return
