"""Opt-in: a signal (SIGTERM from a service manager, say) cancels the main task, so every
``async with Bus`` in it is left through its safe stop before the process exits.

The Bus installs no signal handlers (a library must not take a process's signals). Without one,
SIGTERM kills a Python process at once, and motors keep their last command until their own
communication timeout (MyActuator 0xB3) trips, if it is set. With this helper, in the main
coroutine::

    import signal
    from servobus.signals import stop_on

    async def main() -> None:
        with stop_on(signal.SIGTERM, signal.SIGINT):
            async with Bus(transport) as bus:
                ...                     # the control loop

    asyncio.run(main())                 # SIGTERM: safe stop sent, then exit status 143

On the signal, the task that entered ``stop_on`` is cancelled; the ``async with Bus`` blocks inside it
leave through their (shielded) safe stop as for any cancellation; when the cancellation reaches the
end of the ``with stop_on`` block it becomes ``SystemExit(128 + signal number)``, the exit status
a shell reports for a process ended by that signal. A second signal while the safe stop runs is
ignored: the stop is bounded by the Bus's ``safe_timeout_s``.
"""

from __future__ import annotations

import asyncio
import signal as _signal
from types import TracebackType

__all__ = ["StopOn", "stop_on"]


class StopOn:
    """The context manager :func:`stop_on` returns.

    Attributes:
        received: the signal that came (None: none did).
    """

    def __init__(self, signals: tuple[int, ...], task: asyncio.Task[object] | None) -> None:
        if not signals:
            raise ValueError("stop_on() needs at least one signal")
        self.signals = tuple(_signal.Signals(s) for s in signals)
        self.received: _signal.Signals | None = None
        self._task = task
        self._loop: asyncio.AbstractEventLoop | None = None
        self._previous: dict[int, object] = {}

    def __enter__(self) -> StopOn:
        self._loop = loop = asyncio.get_running_loop()
        if self._task is None:
            self._task = asyncio.current_task()
            if self._task is None:
                raise RuntimeError("stop_on() is used inside a task (the main coroutine)")
        for sig in self.signals:
            try:
                loop.add_signal_handler(sig, self._on_signal, sig)
            except (NotImplementedError, RuntimeError):  # no loop signal support (Windows): plain handler
                self._previous[sig] = _signal.signal(
                    sig, lambda signum, frame: loop.call_soon_threadsafe(self._on_signal, signum)
                )
        return self

    def _on_signal(self, signum: int) -> None:
        if self.received is not None:
            return  # the safe stop is under way
        self.received = _signal.Signals(signum)
        assert self._task is not None
        self._task.cancel(f"servobus.signals: {self.received.name}")

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool | None:
        assert self._loop is not None
        for sig in self.signals:
            if sig in self._previous:
                _signal.signal(sig, self._previous.pop(sig))  # type: ignore[arg-type]
            else:
                self._loop.remove_signal_handler(sig)
        if (
            self.received is not None
            and exc_type is not None
            and issubclass(exc_type, asyncio.CancelledError)
        ):
            assert self._task is not None
            self._task.uncancel()
            raise SystemExit(128 + self.received) from exc
        return None


def stop_on(*signals: int, task: asyncio.Task[object] | None = None) -> StopOn:
    """Cancel ``task`` (default: the current one) when one of ``signals`` arrives; see the module
    docstring.

    Raises:
        ValueError: no signal given, or a number that is no signal.
        RuntimeError: entered outside a task.
    """
    return StopOn(signals, task)
