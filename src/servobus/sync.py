"""The Bus for code that is not async: scripts, notebooks, ROS nodes.

``servobus.sync.Bus`` runs a :class:`servobus.Bus` on one background event loop (anyio's blocking
portal) and gives the same calls, blocking::

    from servobus import sync
    from servobus.transports import CanTransport

    with sync.Bus(CanTransport("slcan", "/dev/ttyACM0", bitrate=1_000_000)) as bus:
        motor = bus.motor("myactuator", 1)
        print(motor.read_status2())
        bus.cycle([(motor, SpeedControl(speed_dps=90.0))])

Leaving the ``with`` block, or :meth:`Bus.close`, stops every commanded motor exactly as leaving
``async with`` does (an exception in the block too), then ends the background loop. Calls may come
from any thread; they are run one at a time on the Bus's loop.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable
from types import TracebackType
from typing import Any, Self

from anyio.from_thread import BlockingPortal, start_blocking_portal

from servobus import bus as _bus
from servobus.protocols._message import Command, Reply

__all__ = ["Bus", "Motor"]


class Motor:
    """A :class:`servobus.Motor` whose commands block: ``motor.read_status2()`` returns the reply."""

    def __init__(self, portal: BlockingPortal, motor: _bus.Motor) -> None:
        self._portal = portal
        self.motor = motor

    @property
    def state(self) -> Reply | None:
        """The latest reply, stream frame or error report of this motor."""
        return self.motor.state

    def request(self, command: Command, *, timeout_s: float | None = None, retries: int = 0) -> Reply | None:
        """Send ``command`` and wait for its reply (see :meth:`servobus.Motor.request`)."""
        call = functools.partial(self.motor.request, command, timeout_s=timeout_s, retries=retries)
        return self._portal.call(call)

    def __getattr__(self, name: str) -> Callable[..., Reply | None]:
        method = getattr(self.__dict__["motor"], name)  # AttributeError for unknown commands

        def call(**fields: Any) -> Reply | None:
            result: Reply | None = self._portal.call(functools.partial(method, **fields))
            return result

        call.__name__ = name
        return call

    def __repr__(self) -> str:
        return f"<sync {self.motor!r}>"


class Bus:
    """A :class:`servobus.Bus` on a background event loop; every call blocks until done.

    Args:
        transport, **options: as :class:`servobus.Bus`.

    Raises:
        TransportError: the transport cannot be opened.
    """

    def __init__(self, transport: Any, **options: Any) -> None:
        self._portal_cm = start_blocking_portal(backend="asyncio")
        self._portal = self._portal_cm.__enter__()
        self._bus = _bus.Bus(transport, **options)
        try:
            self._portal.call(self._bus.__aenter__)
        except BaseException:
            self._portal_cm.__exit__(None, None, None)
            raise
        self._open = True

    @property
    def bus(self) -> _bus.Bus:
        """The asynchronous Bus underneath (use its methods only through this object)."""
        return self._bus

    def motor(self, family: str, motor_id: int, **options: Any) -> Motor:
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

    def stats(self) -> dict[str, int]:
        return self._bus.stats()

    def close(self, exc: BaseException | None = None) -> None:
        """Stop every commanded motor, close the transport if the Bus opened it, end the loop."""
        if not self._open:
            return
        self._open = False
        try:
            self._portal.call(self._bus.__aexit__, type(exc) if exc else None, exc, None)
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
            import warnings

            warnings.warn(
                "servobus.sync.Bus was never closed: its motors were not stopped",
                ResourceWarning,
                stacklevel=1,
            )
