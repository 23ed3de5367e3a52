"""Opt-in: a signal (SIGTERM from a service manager, say) cancels a block, so every ``async with Bus``
in it is left through its safe stop before the process exits.

The Bus installs no signal handlers (a library must not take a process's signals). Without one,
SIGTERM kills a Python process at once, and motors keep their last command until their own
communication timeout (MyActuator 0xB3) trips, if it is set. With this helper, in the main
coroutine::

    import signal
    from servobus.signals import stop_on

    async def main() -> None:
        async with stop_on(signal.SIGTERM, signal.SIGINT):
            async with Bus(transport) as bus:
                ...                     # the control loop

    anyio.run(main)                     # or backend="trio"; SIGTERM: safe stop sent, exit status 143

On the signal the block is cancelled (an anyio cancel scope around it); the ``async with Bus`` blocks
inside it leave through their (shielded) safe stop as for any cancellation; at the end of the block
the cancellation becomes ``SystemExit(128 + signal number)``, the exit status a shell reports for a
process ended by that signal. A second signal while the safe stop runs is ignored: the stop is
bounded by the Bus's ``safe_timeout_s``. The signals are received by a task of the block's own task
group (``anyio.open_signal_receiver``), on asyncio and on trio alike, and the handlers that were there
before are put back when the block ends. An exception from the block comes out as it was raised (not
wrapped in an exception group). Put ``stop_on`` outermost: a ``SystemExit`` raised inside a task
group reaches the interpreter wrapped in a group.

Signals are delivered to the main thread only: in another thread ``stop_on`` takes none, and says so
with ``taking_signals`` False.
"""

from __future__ import annotations

import contextlib
import signal as _signal
import threading
from collections.abc import AsyncIterator, Iterator
from types import TracebackType
from typing import Any

import anyio
import anyio.abc

__all__ = ["StopOn", "stop_on"]


class StopOn:
    """The async context manager :func:`stop_on` returns.

    Attributes:
        signals: the signals it takes.
        received: the signal that came (None: none did).
        taking_signals: False where the block runs outside the main thread (no signal reaches it).
    """

    def __init__(self, signals: tuple[int, ...], *, exit: bool = True) -> None:
        if not signals:
            raise ValueError("stop_on() needs at least one signal")
        self.signals = tuple(_signal.Signals(s) for s in signals)
        self.received: _signal.Signals | None = None
        self.taking_signals = False
        self._exit = exit
        self._targets: list[anyio.CancelScope] = []
        self._cm: contextlib.AbstractAsyncContextManager[StopOn] | None = None

    @property
    def stopped(self) -> bool:
        """True when a signal came and cancelled the block (or the :meth:`scope` it was in)."""
        return self.received is not None

    @contextlib.contextmanager
    def scope(self) -> Iterator[anyio.CancelScope]:
        """A narrower block the signal cancels instead of the whole one: a loop to leave while the code
        after it (a summary, say) still runs. The innermost open one is cancelled."""
        with anyio.CancelScope() as scope:
            if self.received is not None:
                scope.cancel()
            self._targets.append(scope)
            try:
                yield scope
            finally:
                self._targets.remove(scope)

    async def _receive(self, *, task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED) -> None:
        previous = {sig: _signal.getsignal(sig) for sig in self.signals}
        try:
            with anyio.open_signal_receiver(*self.signals) as arrivals:
                self.taking_signals = True
                task_status.started()
                async for signum in arrivals:
                    if self.received is None:  # (later ones: the safe stop is under way)
                        self.received = _signal.Signals(signum)
                        if self._targets:  # (none yet: the block's scope is cancelled as it opens)
                            self._targets[-1].cancel()
        finally:
            self.taking_signals = False
            for sig, handler in previous.items():
                if handler is not None:  # (None: not installed from Python; the default stays)
                    _signal.signal(sig, handler)

    @contextlib.asynccontextmanager
    async def _block(self) -> AsyncIterator[StopOn]:
        raised: BaseException | None = None
        async with anyio.create_task_group() as group:
            if threading.current_thread() is threading.main_thread():
                await group.start(self._receive, name="servobus.signals receiver")
            with self.scope() as body:
                try:
                    yield self
                except anyio.get_cancelled_exc_class():
                    raise  # (the scopes' business)
                except BaseException as exc:  # out of the group as raised, not in an exception group
                    raised = exc
            group.cancel_scope.cancel()
        if raised is not None:
            raise raised
        if self._exit and self.received is not None and body.cancelled_caught:
            raise SystemExit(128 + self.received)

    async def __aenter__(self) -> StopOn:
        if self._cm is not None:
            raise RuntimeError("a StopOn is entered once")
        self._cm = self._block()
        return await self._cm.__aenter__()

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool | None:
        assert self._cm is not None
        return await self._cm.__aexit__(exc_type, exc, tb)

    def __enter__(self) -> Any:
        raise TypeError("stop_on() is an async context manager: use 'async with stop_on(...)'")

    def __exit__(self, *exc: object) -> None:  # pragma: no cover (never entered)
        return None


def stop_on(*signals: int, exit: bool = True) -> StopOn:
    """Cancel the ``async with`` block when one of ``signals`` arrives, then raise
    ``SystemExit(128 + signal)`` at its end (with ``exit=False``, end the block quietly: the caller
    reads :attr:`StopOn.received`); see the module docstring.

    Raises:
        ValueError: no signal given, or a number that is no signal.
    """
    return StopOn(signals, exit=exit)
