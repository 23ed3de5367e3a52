"""The event loop the Bus and the transports run on, asyncio or trio, behind one small interface.

anyio gives servobus its structured concurrency on both backends: task groups own every background
task, cancel scopes carry every deadline, ``anyio.sleep``, ``anyio.wait_readable``. What anyio has
no cheap form of is the per-request hot path: the clock read without a lookup, "call this soon"
(from the loop's thread or from another one), and a one-shot waiter a reply resolves. Each backend
has a lane for those three, chosen once when a Bus or a transport opens (:func:`current`):

* **asyncio**: the loop's own methods; a waiter is an ``asyncio.Future`` (the measured fast lane:
  a future per request is the floor the bus benchmark compares against).
* **trio**: ``trio.current_time``, the run's token, and :class:`TrioWaiter`, built on
  ``trio.lowlevel.wait_task_rescheduled`` as trio's own primitives are.

Both lanes are tested by the same tests (tests/test_runtime.py, and the Bus and transport tests on
both backends). Nothing else in servobus imports asyncio or trio for these.
"""

from __future__ import annotations

import asyncio
import logging
import sys
from collections.abc import Callable, Generator
from typing import Any, Generic, Protocol, TypeVar

__all__ = ["Runtime", "RuntimeMismatch", "Waiter", "WaiterCancelled", "current"]

T = TypeVar("T")

logger = logging.getLogger("servobus.runtime")


class WaiterCancelled(Exception):
    """What :meth:`Waiter.result` raises on a cancelled waiter (the one awaiting it stopped)."""


class RuntimeMismatch(RuntimeError):
    """A call from another event loop, or from outside any, than the one an object was opened on."""


class Waiter(Protocol[T]):
    """A one-shot outcome, awaited by one task; others observe it through done callbacks.

    ``asyncio.Future``'s interface, of which servobus uses: the outcome is set once; ``cancel``
    means the awaiting task gave up; callbacks run soon after the outcome, on the loop.
    """

    def done(self) -> bool: ...

    def cancelled(self) -> bool: ...

    def set_result(self, value: T) -> None: ...

    def set_exception(self, exc: BaseException) -> None: ...

    def cancel(self) -> bool: ...

    def result(self) -> T: ...

    def exception(self) -> BaseException | None: ...

    def add_done_callback(self, fn: Callable[[Any], object]) -> None: ...

    def __await__(self) -> Generator[Any, None, T]: ...


class Runtime(Protocol):
    """One event loop's hot-path operations (see the module's docstring)."""

    #: "asyncio" or "trio"
    name: str
    #: the loop's clock (``anyio.current_time()``'s, without the lookup)
    time: Callable[[], float]
    #: ``call_soon(fn, *args)``: run ``fn(*args)`` on the loop soon, in order (from the loop's thread)
    call_soon: Callable[..., object]
    #: the same from any thread (a reader thread handing frames over); never blocks
    call_soon_threadsafe: Callable[..., object]

    def waiter(self) -> Waiter[Any]: ...

    def is_current(self) -> bool:
        """True when called from this loop (a task or a callback of it)."""
        ...


class _AsyncioRuntime:
    name = "asyncio"

    __slots__ = ("call_soon", "call_soon_threadsafe", "loop", "time", "waiter")

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.time = loop.time
        self.call_soon = loop.call_soon
        self.call_soon_threadsafe = loop.call_soon_threadsafe
        self.waiter = loop.create_future

    def is_current(self) -> bool:
        # asyncio's public get_running_loop() raises off the loop: 1.7 us against 0.3 us per call
        # measured from a thread, where a can.Notifier's thread asks it for every message it reads.
        return asyncio._get_running_loop() is self.loop  # noqa: SLF001 (hot from threads: see above)

    def __repr__(self) -> str:
        return f"<runtime asyncio {self.loop!r}>"


_PENDING, _DONE, _CANCELLED = 0, 1, 2


class TrioWaiter(Generic[T]):
    """:class:`Waiter` on trio: the awaiting task parks with ``wait_task_rescheduled`` and the
    outcome reschedules it; a cancelled await cancels the waiter (its outcome is then dropped)."""

    __slots__ = ("_callbacks", "_runtime", "_state", "_task", "_value")

    def __init__(self, runtime: _TrioRuntime) -> None:
        self._runtime = runtime
        self._state = _PENDING
        self._value: Any = None
        self._task: Any = None
        self._callbacks: list[Callable[[Any], object]] | None = None

    def done(self) -> bool:
        return self._state != _PENDING

    def cancelled(self) -> bool:
        return self._state == _CANCELLED

    def set_result(self, value: T) -> None:
        self._end(_DONE, value)

    def set_exception(self, exc: BaseException) -> None:
        self._end(_DONE, _Raised(exc))

    def cancel(self) -> bool:
        if self._state != _PENDING:
            return False
        self._end(_CANCELLED, None)
        return True

    def _end(self, state: int, value: Any) -> None:
        if self._state != _PENDING:
            raise RuntimeError("the waiter's outcome was already set")
        self._state = state
        self._value = value
        task, self._task = self._task, None
        if task is not None:
            self._runtime.reschedule(task)
        if self._callbacks:
            callbacks, self._callbacks = self._callbacks, None
            for callback in callbacks:
                self._runtime.call_soon(callback, self)

    def result(self) -> T:
        if self._state == _PENDING:
            raise RuntimeError("the waiter has no outcome yet")
        if self._state == _CANCELLED:
            raise WaiterCancelled("the waiter was cancelled")
        value = self._value
        if isinstance(value, _Raised):
            raise value.exc
        return value  # type: ignore[no-any-return]

    def exception(self) -> BaseException | None:
        if self._state == _PENDING:
            raise RuntimeError("the waiter has no outcome yet")
        if self._state == _CANCELLED:
            raise WaiterCancelled("the waiter was cancelled")
        value = self._value
        return value.exc if isinstance(value, _Raised) else None

    def add_done_callback(self, fn: Callable[[Any], object]) -> None:
        if self._state != _PENDING:
            self._runtime.call_soon(fn, self)
        else:
            self._callbacks = [*(self._callbacks or ()), fn]

    def __await__(self) -> Generator[Any, None, T]:
        if self._state == _PENDING:
            if self._task is not None:
                raise RuntimeError("a waiter is awaited by one task at a time")
            self._task = self._runtime.current_task()
            yield from self._runtime.park(self._abort).__await__()
        return self.result()

    def _abort(self, raise_cancel: object) -> Any:
        self._task = None
        self.cancel()
        return self._runtime.abort_succeeded


class _Raised:
    __slots__ = ("exc",)

    def __init__(self, exc: BaseException) -> None:
        self.exc = exc


def _logged(fn: Callable[..., object], args: tuple[object, ...]) -> None:
    """Run a callback handed to trio's queue: an exception is logged, as asyncio does with a
    callback's (in trio's queue it would end the whole run with TrioInternalError)."""
    try:
        fn(*args)
    except Exception:
        logger.exception("callback %r failed", fn)


class _TrioRuntime:
    name = "trio"

    def __init__(self) -> None:
        import trio

        self.token = trio.lowlevel.current_trio_token()
        self.time = trio.current_time
        run_sync_soon = self.token.run_sync_soon

        # (run_sync_soon is thread-safe; from the loop's thread it is the same queue, in order)
        def call_soon(fn: Callable[..., object], *args: object) -> None:
            run_sync_soon(_logged, fn, args)

        self.call_soon = self.call_soon_threadsafe = call_soon
        self.reschedule = trio.lowlevel.reschedule
        self.current_task = trio.lowlevel.current_task
        self.park = trio.lowlevel.wait_task_rescheduled
        self.abort_succeeded = trio.lowlevel.Abort.SUCCEEDED
        self._current_token = trio.lowlevel.current_trio_token

    def waiter(self) -> TrioWaiter[Any]:
        return TrioWaiter(self)

    def is_current(self) -> bool:
        try:
            return self._current_token() is self.token
        except RuntimeError:
            return False

    def __repr__(self) -> str:
        return f"<runtime trio {self.token!r}>"


def current() -> Runtime:
    """The running loop's :class:`Runtime` (asyncio's, or trio's).

    Raises:
        RuntimeMismatch: no asyncio or trio loop runs in this thread.
    """
    try:
        loop = asyncio.get_running_loop()
    except RuntimeError:  # no asyncio loop here: trio's, or none (once per open: not a hot path)
        pass
    else:
        return _AsyncioRuntime(loop)  # type: ignore[return-value]
    trio = sys.modules.get("trio")
    if trio is not None and trio.lowlevel.in_trio_run():
        return _TrioRuntime()  # type: ignore[return-value]
    raise RuntimeMismatch(
        "no event loop runs here: run servobus under anyio.run(), asyncio.run() or trio.run()"
    )
