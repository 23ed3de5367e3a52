"""Signals that end a process while it drives motors: every ``async with Bus`` is left through its
safe stop before the process exits.

**SIGTERM by default.** Python's default for SIGTERM (systemd, ``docker stop``, ``timeout``) kills
the process where it stands, and motors keep their last command until their own communication
timeout (MyActuator 0xB3) trips, if it is set. So while a Bus is open in the main thread and SIGTERM
has that default disposition (``SIG_DFL``), the Bus takes it (:func:`take_sigterm`): SIGTERM does
what Ctrl-C does, the ``async with Bus`` block is cancelled, the safe stop goes out, and the oldest
Bus open leaves with ``SystemExit(143)`` (128 + 15, the status a shell reports for SIGTERM), on
asyncio and on trio (the Buses opened inside it are left quietly, their blocks cancelled too). A
second SIGTERM while the safe stop runs is ignored. One handler serves every Bus open at once; the
default is put back when the last one closes, after its safe stop. A handler the program set itself
(or :func:`stop_on`, as the CLI uses) is left alone: the Bus takes nothing then. Opt out with
``Bus(..., sigterm=False)``. With several Buses in sibling tasks of a task group, the ``SystemExit``
leaves the group wrapped in an exception group: use :func:`stop_on` outermost there.
:class:`servobus.sync.Bus` runs its loop in a thread of its own, where no signal arrives; opened
in the main thread it takes SIGTERM there (:func:`raise_on_sigterm`): the signal raises
``SystemExit(143)`` in the main thread, which leaves its ``with`` block (or reaches the interpreter's
exit, which closes it) through the safe stop. A SIGTERM while a sync Bus closes is held until the
close is over.

**Opt-in, any signal: stop_on.** A signal cancels a block, so every ``async with Bus`` in it is left
through its safe stop. In the main coroutine::

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
import os
import signal as _signal
import threading
from collections.abc import AsyncIterator, Callable, Iterator
from types import TracebackType
from typing import Any

import anyio
import anyio.abc

__all__ = ["SigtermTaken", "StopOn", "raise_on_sigterm", "stop_on", "take_sigterm"]


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


# ---- SIGTERM by default, for the Bus ----


class SigtermTaken:
    """One open Bus's share of the default SIGTERM handler (:func:`take_sigterm`): the cancel scope
    around its block, cancelled on the signal. :meth:`release` when the block is left."""

    def __init__(self, scope: anyio.CancelScope, call_soon_threadsafe: Callable[..., object]) -> None:
        self.scope = scope
        self._call_soon = call_soon_threadsafe

    @property
    def received(self) -> bool:
        """True when SIGTERM came while this block was open."""
        return _SIGTERM.received_by is not None and self in _SIGTERM.received_by

    @property
    def exits(self) -> bool:
        """True when this block is the one that turns the signal into ``SystemExit(143)`` (the
        oldest open when it came: the others are left quietly, inside it or beside it)."""
        return _SIGTERM.exiting is self

    def cancel_soon(self) -> None:
        """Cancel the block's scope from its own loop, soon (the signal handler calls this).

        Raises:
            RuntimeError: that loop is closed.
        """
        self._call_soon(self.scope.cancel)

    def release(self) -> None:
        """The block was left: the default disposition is back when it was the last one."""
        _SIGTERM.release(self)


class _SigtermDefault:
    """The process's one SIGTERM handler for the Buses open in the main thread (module state, since
    a signal's disposition is the process's)."""

    def __init__(self) -> None:
        self.open: dict[SigtermTaken, None] = {}  # in the order they were taken: the oldest first
        self.received_by: tuple[SigtermTaken, ...] | None = None
        self.exiting: SigtermTaken | None = None
        self._handler = self._on_signal  # (one bound method, compared with getsignal()'s)

    def take(
        self, scope: anyio.CancelScope, call_soon_threadsafe: Callable[..., object]
    ) -> SigtermTaken | None:
        if threading.current_thread() is not threading.main_thread():
            return None  # (signals reach the main thread only)
        if not self.open:
            if _signal.getsignal(_signal.SIGTERM) is not _signal.SIG_DFL:
                return None  # the program's own handler, or stop_on's: theirs to act
            _signal.signal(_signal.SIGTERM, self._handler)
            self.received_by, self.exiting = None, None
        taken = SigtermTaken(scope, call_soon_threadsafe)
        self.open[taken] = None
        if self.received_by is not None:  # opened while the others leave: leave too
            scope.cancel()
        return taken

    def release(self, taken: SigtermTaken) -> None:
        last = self.open.pop(taken, 0) is None and not self.open
        if last and _signal.getsignal(_signal.SIGTERM) == self._handler:  # (one set since stays)
            _signal.signal(_signal.SIGTERM, _signal.SIG_DFL)

    def _on_signal(self, signum: int, frame: object) -> None:
        # A Python-level handler runs between two bytecodes of the main thread, which may be in the
        # middle of the loop's own work: the scopes are cancelled from the loop, soon.
        if self.received_by is not None:
            return  # a second one while the safe stop runs: that stop is bounded by safe_timeout_s
        self.received_by = tuple(self.open)
        self.exiting = next(iter(self.open), None)
        reached = False
        for taken in self.received_by:
            try:
                taken.cancel_soon()
                reached = True
            except RuntimeError:  # its loop is closed (a Bus never left): nothing to stop there
                continue
        if not reached:  # no Bus could be told: the default action, as if none had taken the signal
            _signal.signal(_signal.SIGTERM, _signal.SIG_DFL)
            os.kill(os.getpid(), _signal.SIGTERM)


_SIGTERM = _SigtermDefault()


def take_sigterm(
    scope: anyio.CancelScope, call_soon_threadsafe: Callable[..., object]
) -> SigtermTaken | None:
    """Have SIGTERM cancel ``scope`` (an open Bus's block), through ``call_soon_threadsafe`` (its
    loop's), where the default disposition allows (see the module docstring): the handle, or None
    where nothing was taken (not the main thread, or SIGTERM already has a handler)."""
    return _SIGTERM.take(scope, call_soon_threadsafe)


class _SigtermRaised:
    """SIGTERM for the blocking Buses (servobus.sync) open in the main thread: raised there as
    ``SystemExit(143)``, as Ctrl-C raises KeyboardInterrupt, so the code blocked on the Bus leaves
    through its ``with`` block. Held while one of them closes (its safe stop runs then)."""

    def __init__(self) -> None:
        self.open = 0
        self.closing = 0
        self.held = False
        self.raised = False
        self._handler = self._on_signal

    def take(self) -> bool:
        if threading.current_thread() is not threading.main_thread():
            return False
        if not self.open:
            if _signal.getsignal(_signal.SIGTERM) is not _signal.SIG_DFL:
                return False  # the program's own handler (or an async Bus's): theirs to act
            _signal.signal(_signal.SIGTERM, self._handler)
            self.held = self.raised = False
        self.open += 1
        return True

    @contextlib.contextmanager
    def closing_one(self) -> Iterator[None]:
        """One of them closes: a SIGTERM meanwhile waits for the end of the close, then raises (once,
        when the last one closed), and the default disposition is back after the last."""
        self.closing += 1
        try:
            yield
        finally:
            self.closing -= 1
            self.open -= 1
            if not self.open and _signal.getsignal(_signal.SIGTERM) == self._handler:
                _signal.signal(_signal.SIGTERM, _signal.SIG_DFL)
            if self.held and not self.closing:
                self.held = False
                raise SystemExit(128 + _signal.SIGTERM)

    def _on_signal(self, signum: int, frame: object) -> None:
        if self.raised:
            return  # a second one: the first is on its way out through the safe stop
        self.raised = True
        if self.closing:
            self.held = True
            return
        raise SystemExit(128 + signum)


_SIGTERM_RAISED = _SigtermRaised()


def raise_on_sigterm() -> contextlib.AbstractContextManager[None] | None:
    """For a blocking Bus opening in the main thread where SIGTERM has its default disposition: from
    now on SIGTERM raises ``SystemExit(143)`` in the main thread (see the module docstring). Gives the
    context to close the Bus in (it holds a SIGTERM that comes meanwhile and puts the default back
    after the last), or None where nothing was taken."""
    return _SIGTERM_RAISED.closing_one() if _SIGTERM_RAISED.take() else None
