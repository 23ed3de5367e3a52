"""The Bus's safe stop (:func:`safe_stop`): every commanded motor gets the safe command, again and
again, until it acknowledged it or the time for it ended; one task per motor, in a task group."""

from __future__ import annotations

import contextlib
import logging
from typing import TYPE_CHECKING

import anyio

from servobus._tick import awaitable
from servobus.errors import MotorTimeout, TransportError
from servobus.protocols import Command

if TYPE_CHECKING:
    from servobus.bus import Bus
    from servobus.motor import Motor
    from servobus.scheduler import Request

__all__ = ["safe_stop"]

logger = logging.getLogger("servobus.bus")


async def safe_stop(bus: Bus) -> None:
    """Send ``bus.safe`` to every motor the Bus commanded, again to each one that did not answer,
    until all answered or ``bus.safe_timeout_s`` ended; sets ``bus.safe_sent`` and
    ``bus.safe_acknowledged``, and names the motors that did not answer in a warning."""
    if bus.safe is None or not bus._commanded:
        return
    if not bus.transport.is_open:
        logger.warning(
            "%s: the link is not open: the %s command cannot reach %s",
            bus.name,
            bus.safe,
            ", ".join(repr(m) for m in bus._commanded.values()),
        )
        return
    commands: dict[Motor, Command] = {}
    for motor in list(bus._commanded.values()):
        with contextlib.suppress(ValueError):
            commands[motor] = motor.codec.safe_command(bus.safe)
    attempts: dict[Motor, list[Request]] = {motor: [] for motor in commands}
    acknowledged: set[Motor] = set()

    async def stop(motor: Motor, command: Command) -> None:
        while True:
            request = bus._engine.submit(motor, command, None, 0, safe=True)
            attempts[motor].append(request)
            try:
                await awaitable(request.context)
            except MotorTimeout:
                continue  # lost on its way there or back: it is safe to repeat
            except TransportError:
                if not bus.transport.is_open:
                    return
                await anyio.sleep(bus.scheduler.min_timeout_s)  # refused (a full queue): again
                continue
            except Exception:  # (an undecodable answer: not an acknowledgement, and no retry)
                return
            if request.key is not None:  # (a command with no reply cannot be acknowledged)
                acknowledged.add(motor)
            return

    try:
        with anyio.move_on_after(bus.safe_timeout_s):
            async with anyio.create_task_group() as group:
                for motor, command in commands.items():
                    group.start_soon(stop, motor, command)
    finally:
        bus._engine.abandon(r for sent in attempts.values() for r in sent)
        bus.safe_sent = tuple(m for m, tried in attempts.items() if any(r.sent_at is not None for r in tried))
        bus.safe_acknowledged = tuple(m for m in commands if m in acknowledged)
        missing = [m for m in commands if m not in acknowledged]
        if missing:
            logger.warning(
                "%s: the %s command was not acknowledged by %s within %g s",
                bus.name,
                bus.safe,
                ", ".join(repr(m) for m in missing),
                bus.safe_timeout_s,
            )
