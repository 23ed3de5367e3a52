"""The Bus for code that is not async: scripts, notebooks, ROS nodes.

``servobus.sync.Bus`` runs a :class:`servobus.Bus` on one background event loop (anyio's blocking
portal) and gives the same calls, blocking::

    from servobus import sync
    from servobus.protocols.myactuator import SpeedControl
    from servobus.transports import CanTransport

    with sync.Bus(CanTransport("slcan", "/dev/ttyACM0", bitrate=1_000_000)) as bus:
        motor = bus.motor("myactuator", 1)
        print(motor.read_status2())
        bus.cycle([(motor, SpeedControl(speed_dps=90.0))])

Leaving the ``with`` block, or :meth:`Bus.close`, stops every commanded motor exactly as leaving
``async with`` does (an exception in the block too), then ends the background loop. A Bus still open
when the interpreter exits is closed the same way then (with a ``ResourceWarning``). SIGTERM, by
default, does what Ctrl-C does: opened in the main thread where SIGTERM has its default
disposition, the Bus has the signal raise ``SystemExit(143)`` there, so the block is left through the
safe stop and the process exits 143 (``sigterm=False``: not this Bus; :mod:`servobus.signals`). Calls may come
from any thread; they are run one at a time on the Bus's loop. Motor commands take their fields by
position too, in the command's order: ``motor.set_comm_timeout(100)``.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import logging
import warnings
import weakref
from collections.abc import Callable, Iterable, Iterator
from types import TracebackType
from typing import Any, Self, TypeVar

from anyio.from_thread import BlockingPortal, start_blocking_portal

from servobus import bus as _bus
from servobus.limits import Limits
from servobus.metrics import Metrics
from servobus.protocols import Command, Family, Reply
from servobus.scheduler import Traffic
from servobus.signals import raise_on_sigterm
from servobus.ticks import Tick

_logger = logging.getLogger("servobus.sync")

__all__ = ["Bus", "Motor"]

R = TypeVar("R")


class Motor:
    """A :class:`servobus.Motor` whose commands block: ``motor.read_status2()`` returns the reply."""

    def __init__(self, portal: BlockingPortal, motor: _bus.Motor) -> None:
        self._portal = portal
        self.motor = motor

    @property
    def state(self) -> Reply | None:
        """The latest reply, stream frame or error report of this motor."""
        return self.motor.state

    @property
    def motor_id(self) -> int:
        return self.motor.motor_id

    @property
    def online(self) -> bool | None:
        """The watchdog's verdict (see :class:`servobus.Motor`)."""
        return self.motor.online

    @property
    def last_seen(self) -> float | None:
        return self.motor.last_seen

    @property
    def fault(self) -> Any:
        """The faults of its latest report, or None (see :class:`servobus.Motor`)."""
        return self.motor.fault

    @property
    def limits(self) -> Limits | None:
        """Its host-side limits (see :class:`servobus.Motor`); settable from this thread (the
        Bus's next command meets the new ones: a reference swap)."""
        return self.motor.limits

    @limits.setter
    def limits(self, limits: Limits | None) -> None:
        self.motor.limits = limits

    def metrics(self) -> Metrics:
        """This motor's counters and latency (see :meth:`servobus.Motor.metrics`)."""
        result: Metrics = self._portal.call(self.motor.metrics)
        return result

    def request(self, command: Command[R], *, timeout_s: float | None = None, retries: int = 0) -> R:
        """Send ``command`` and wait for its reply (see :meth:`servobus.Motor.request`)."""
        call = functools.partial(self.motor.request, command, timeout_s=timeout_s, retries=retries)
        result: R = self._portal.call(call)
        return result

    def __getattr__(self, name: str) -> Callable[..., Reply | None]:
        method = getattr(self.__dict__["motor"], name)  # AttributeError for unknown commands

        def call(*args: Any, **fields: Any) -> Reply | None:
            result: Reply | None = self._portal.call(functools.partial(method, *args, **fields))
            return result

        call.__name__ = name
        return call

    def __repr__(self) -> str:
        return f"<sync {self.motor!r}>"


class Bus:
    """A :class:`servobus.Bus` on a background event loop; every call blocks until done.

    The Bus is entered and left by one task of the background loop (the portal's
    ``wrap_async_context_manager``), as ``async with`` would: the task groups the Bus and its
    transport own are entered and left in the same task, as anyio requires.

    Args:
        transport, **options: as :class:`servobus.Bus` (``sigterm=False``: SIGTERM is not taken).
        backend: the background loop's, "asyncio" (default) or "trio" (through anyio).

    Raises:
        TransportError: the transport cannot be opened.
    """

    def __init__(self, transport: Any, *, backend: str = "asyncio", **options: Any) -> None:
        self._portal_cm = start_blocking_portal(backend=backend)
        self._portal = self._portal_cm.__enter__()
        try:
            self._bus = _bus.Bus(transport, **options)
            self._inside = self._portal.wrap_async_context_manager(self._bus)
            self._inside.__enter__()
        except BaseException:
            self._portal_cm.__exit__(None, None, None)
            raise
        self._open = True
        _OPEN.add(self)
        # (the Bus inside runs in the portal's thread, where no signal comes: taken here)
        self._sigterm = raise_on_sigterm() if options.get("sigterm", True) else None

    @property
    def bus(self) -> _bus.Bus:
        """The asynchronous Bus underneath (use its methods only through this object)."""
        return self._bus

    def motor(self, family: Family[Any] | str, motor_id: int, **options: Any) -> Motor:
        """The motor ``motor_id`` of ``family`` (see :meth:`servobus.Bus.motor`)."""
        return Motor(self._portal, self._bus.motor(family, motor_id, **options))

    def cycle(self, items: Iterable[tuple[Motor, Command]], *, timeout_s: float | None = None) -> list[Any]:
        """One control tick (see :meth:`servobus.Bus.cycle`)."""
        pairs = [(m.motor, c) for m, c in items]
        return self._portal.call(functools.partial(self._bus.cycle, pairs, timeout_s=timeout_s))

    def broadcast(
        self, command: Command, motors: Iterable[Motor], *, timeout_s: float | None = None
    ) -> dict[int, Any]:
        """One frame to several motors (see :meth:`servobus.Bus.broadcast`)."""
        handles = [m.motor for m in motors]
        return self._portal.call(
            functools.partial(self._bus.broadcast, command, handles, timeout_s=timeout_s)
        )

    @property
    def commanded(self) -> tuple[Motor, ...]:
        """The motors this Bus sent a command that is not a read (see :attr:`servobus.Bus.commanded`)."""
        return tuple(Motor(self._portal, m) for m in self._bus.commanded)

    def request(
        self, motor: Motor, command: Command[R], *, timeout_s: float | None = None, retries: int = 0
    ) -> R:
        """:meth:`Motor.request`."""
        return motor.request(command, timeout_s=timeout_s, retries=retries)

    def subscribe(self, callback: Callable[[_bus.Motor, Traffic, Reply], object]) -> None:
        """Call ``callback(motor, traffic, reply)`` for every decoded frame (see
        :meth:`servobus.Bus.subscribe`). It runs on the Bus's background thread: keep it short, and
        hand work to your own thread if it blocks. ``motor`` is the asynchronous motor; its
        ``motor_id`` and ``state`` may be read there.

        Raises:
            TypeError: ``callback`` is a coroutine function.
        """
        self._portal.call(self._bus.subscribe, callback)

    def subscribe_status(self, callback: Callable[[_bus.MotorStatus], object]) -> None:
        """Call ``callback(status)`` when a motor goes offline or online (see
        :meth:`servobus.Bus.subscribe_status`); on the background thread, as :meth:`subscribe`.

        Raises:
            TypeError: ``callback`` is a coroutine function.
        """
        self._portal.call(self._bus.subscribe_status, callback)

    def ticks(self, hz: float, *, spin_s: float = 0.0012, count: int | None = None) -> Iterator[Tick]:
        """A fixed-rate pacer, blocking: ``for tick in bus.ticks(100): bus.cycle(...)`` (see
        :func:`servobus.ticks.ticks`; the ticks are timed on the Bus's loop)."""
        pacer = self._bus.ticks(hz, spin_s=spin_s, count=count)

        async def next_tick() -> Tick | None:
            try:
                return await anext(pacer)
            except StopAsyncIteration:
                return None

        try:
            while (tick := self._portal.call(next_tick)) is not None:
                yield tick
        finally:
            aclose = getattr(pacer, "aclose", None)
            if self._open and aclose is not None:
                self._portal.call(aclose)

    def stats(self) -> dict[str, int]:
        """The scheduler's counters (see :meth:`servobus.Bus.stats`)."""
        result: dict[str, int] = self._portal.call(self._bus.stats)
        return result

    def metrics(self) -> Metrics:
        """This bus's counters, latency and load (see :meth:`servobus.Bus.metrics`)."""
        result: Metrics = self._portal.call(self._bus.metrics)
        return result

    def close(self, exc: BaseException | None = None) -> None:
        """Stop every commanded motor, close the transport if the Bus opened it, end the loop."""
        if not self._open:
            return
        self._open = False
        _OPEN.discard(self)
        with self._sigterm or contextlib.nullcontext():
            try:
                self._inside.__exit__(type(exc) if exc else None, exc, exc.__traceback__ if exc else None)
            finally:
                self._portal_cm.__exit__(None, None, None)

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close(exc)

    def __del__(self) -> None:
        if getattr(self, "_open", False):
            warnings.warn(
                "servobus.sync.Bus was never closed: its motors were not stopped",
                ResourceWarning,
                stacklevel=1,
            )


#: The Buses not yet closed. At interpreter exit their background loops would be stopped by garbage
#: collection after the daemon threads that run them are frozen (a hang, or "Exception ignored in
#: __del__"): they are closed first, motors stopped, here.
_OPEN: weakref.WeakSet[Bus] = weakref.WeakSet()


@atexit.register
def _close_at_exit() -> None:
    for bus in list(_OPEN):
        warnings.warn(
            "servobus.sync.Bus was never closed: closed at exit (its motors stopped)",
            ResourceWarning,
            stacklevel=1,
        )
        try:
            bus.close()
        except Exception as exc:  # the exit goes on; say why the stop did not complete
            _logger.error("closing %r at exit failed: %s", bus.bus, exc)
