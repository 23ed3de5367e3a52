"""A file descriptor's readiness as a callback, on asyncio and on trio (private).

The readers of servobus (a python-can bus's descriptor, a serial port) read a little on every wake-up:
one CAN frame, one burst of bytes. So a wake-up's cost is paid per frame. anyio's ``wait_readable`` is
the portable form, and on trio it is trio's own wait; on asyncio it costs about 23 µs per wake-up
against 4 µs for a callback the loop keeps registered (``loop.add_reader``), measured with an eventfd
ping-pong (100k wake-ups), and through CanTransport's descriptor reader (one frame per wake-up) 27
against 9 µs of CPU per frame (trio: 15). So :class:`ReadWatch` has two lanes behind one interface:

* **asyncio** (the measured fast lane): the loop's own reader callback, registered once.
* **any other backend** (trio): one task in the transport's task group that waits with
  ``anyio.wait_readable`` and calls the same callback.

:data:`ASYNCIO_CALLBACKS` set to False puts asyncio on the task lane too (the tests run both lanes).

**Callbacks that run in no task** (the callback lane's ``on_ready``, a thread's hand-over through
``call_soon_threadsafe``) run in :func:`loop_context`: a context in which sniffio names the backend, so
what they call (the Bus's intake, through the consumer) may use anyio under a plain ``asyncio.run``
too (anyio finds no backend in a bare asyncio callback otherwise). It is set once, when the callback
is registered or the thread started: nothing per call.
"""

from __future__ import annotations

import contextvars
import logging
from collections.abc import Callable
from typing import Any

import anyio

from servobus.runtime import Runtime
from servobus.transports._owned import LinkTasks

__all__ = ["ASYNCIO_CALLBACKS", "ReadWatch", "loop_context"]

logger = logging.getLogger("servobus.transports")

#: asyncio watches through the loop's reader callback (True) or a task like any backend (False)
ASYNCIO_CALLBACKS = True


def loop_context(runtime: Runtime) -> contextvars.Context:
    """A copy of the current context in which sniffio (when installed) names ``runtime``'s backend: run
    a callback that runs in no task in it (``context.run(loop.add_reader, ...)``, a thread started as
    ``Thread(target=context.run, args=(fn,))``). One context is entered by one thread at a time: take
    a fresh one per thread."""
    context = contextvars.copy_context()
    try:
        import sniffio
    except ImportError:  # anyio then finds asyncio by its running loop, callbacks included
        return context
    context.run(sniffio.current_async_library_cvar.set, runtime.name)
    return context


class ReadWatch:
    """Call ``on_ready()`` on the loop every time ``fd`` is readable, from :meth:`start` until
    :meth:`cancel` or :meth:`stop`.

    ``on_ready`` reads what is there and must not raise: an exception is logged and ends the watch
    (a descriptor left readable would otherwise wake the loop for ever).
    """

    __slots__ = ("_ended", "_fd", "_loop", "_name", "_on_ready", "_runtime", "_scope", "_tasks", "lane")

    def __init__(
        self, runtime: Runtime, tasks: LinkTasks, fd: int, on_ready: Callable[[], object], name: str
    ) -> None:
        self._fd = fd
        self._on_ready = on_ready
        self._name = name
        self._tasks = tasks
        self._runtime = runtime
        loop: Any = getattr(runtime, "loop", None) if runtime.name == "asyncio" else None
        self._loop = loop if ASYNCIO_CALLBACKS else None
        #: "callback" (asyncio's reader callback) or "task" (a task waiting with anyio.wait_readable)
        self.lane = "callback" if self._loop is not None else "task"
        self._scope: anyio.CancelScope | None = None
        self._ended: anyio.Event | None = None

    def start(self) -> None:
        if self._loop is not None:  # the callback's context is the one current at registration
            loop_context(self._runtime).run(self._loop.add_reader, self._fd, self._ready)
            return
        self._scope = anyio.CancelScope()
        self._ended = anyio.Event()
        self._tasks.start_soon(self._watch, self._scope, self._ended, name=f"{self._name} reader")

    def cancel(self) -> None:
        """Stop calling ``on_ready`` (from anywhere on the loop, ``on_ready`` itself included)."""
        if self._loop is not None:
            self._loop.remove_reader(self._fd)
        elif self._scope is not None:
            self._scope.cancel()

    async def stop(self) -> None:
        """:meth:`cancel`, and wait until the watching task has ended: the descriptor may be closed then."""
        self.cancel()
        if self._ended is not None:
            with anyio.CancelScope(shield=True):  # a cancelled task ends at once: never a long wait
                await self._ended.wait()

    def _ready(self) -> None:
        try:
            self._on_ready()
        except Exception:
            logger.exception("%s: the reader failed; the descriptor is no longer watched", self._name)
            self.cancel()

    async def _watch(self, scope: anyio.CancelScope, ended: anyio.Event) -> None:
        try:
            with scope:
                fd, on_ready = self._fd, self._on_ready
                while True:
                    await anyio.wait_readable(fd)
                    try:
                        on_ready()
                    except Exception:
                        logger.exception("%s: the reader failed; the descriptor is unwatched", self._name)
                        return
        finally:
            ended.set()
