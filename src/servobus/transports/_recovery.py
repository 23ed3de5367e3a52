"""A transport's loss and recovery: fail everything at once, then reopen with exponential backoff."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

import anyio

from servobus.errors import TransportError
from servobus.runtime import Runtime, Waiter
from servobus.transports.events import TransportState

if TYPE_CHECKING:
    from servobus.transports.base import Transport

__all__ = ["Recovery"]

logger = logging.getLogger("servobus.transports")


class Recovery:
    """What a transport does when its device fails, and the task that brings it back.

    The task (:meth:`watch`) runs from ``open()`` to ``close()`` in the transport's task group and
    waits for a loss: a loss is often reported from a loop callback (a reader's ``add_reader``
    callback, a thread's ``call_soon_threadsafe``), where no task can be started on asyncio.

    Args:
        transport: the transport (its state, waiters, queue and ``_connect``/``_disconnect``).
        reopen: reopen by itself after a loss.
        backoff_s: (first, longest) delay between reopen attempts; it doubles each time.
    """

    __slots__ = ("_backoff_s", "_pending", "_signal", "_transport", "reopen")

    def __init__(self, transport: Transport[Any, Any], reopen: bool, backoff_s: tuple[float, float]) -> None:
        first, longest = backoff_s
        if not 0 < first <= longest:
            raise ValueError(f"reopen_backoff_s={backoff_s} must be 0 < first <= longest")
        self._transport = transport
        self.reopen = reopen
        self._backoff_s = (first, longest)
        self._pending = False  # a loss not yet taken up by watch()
        self._signal: Waiter[None] | None = None  # what watch() waits on

    def lose(self, cause: BaseException) -> None:
        """The open connection's device failed (the transport checked it is the open one)."""
        transport = self._transport
        logger.warning("%s: device lost: %s", transport.name, cause)
        transport._stats.losses += 1
        transport._generation += 1
        transport._failure = ("device lost", cause)
        transport._set_state(TransportState.LOST, cause)
        transport._sending.stop()
        transport._sending.purge("purged")
        transport._inbox.readers.fail_all(transport._error)
        transport._sending.idle.fail_all(transport._error)
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
        transport = self._transport
        try:
            await transport._disconnect()
        except Exception as exc:  # the device is gone already: nothing to release
            logger.debug("%s: disconnect after a loss: %s", transport.name, exc)
        if not self.reopen:
            return
        delay, longest = self._backoff_s
        while transport._state is TransportState.LOST:
            await anyio.sleep(delay)
            transport._generation += 1
            try:
                await transport._connect()
            except Exception as exc:  # the device is still away (or refuses): try again later
                log = logger.debug if isinstance(exc, TransportError) else logger.warning
                log("%s: reopen failed: %s", transport.name, exc)
                delay = min(2 * delay, longest)
                continue
            if transport._state is not TransportState.LOST:  # closed meanwhile: close() releases it
                return
            transport._stats.reopens += 1
            logger.info("%s: reopened", transport.name)
            transport._connected()
