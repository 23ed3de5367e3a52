"""The Bus's safe stop (:func:`safe_stop`): every commanded motor gets the safe command, again and
again, until it acknowledged it or the time for it ended; one task per motor, in a task group
(:func:`stop_motors`, which the remote bridge uses too for the motors of a client that left)."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import anyio

from servobus.bus.tick import awaitable
from servobus.errors import MotorNotExecuted, MotorTimeout, TransportError
from servobus.protocols import Command
from servobus.timing import format_duration

if TYPE_CHECKING:
    from servobus.bus.engine import Engine
    from servobus.bus.motor import Motor
    from servobus.scheduler import Request

__all__ = ["SafeStopHost", "StopHost", "StopOutcome", "safe_stop", "stop_motors"]

logger = logging.getLogger("servobus.bus")


class StopHost(Protocol):
    """What :func:`stop_motors` asks of a Bus (:class:`servobus.bus.Bus` is one): its engine."""

    @property
    def engine(self) -> Engine: ...


class SafeStopHost(StopHost, Protocol):
    """What :func:`safe_stop` asks of a Bus: its safe command, the motors it commanded, and where the
    outcome goes."""

    name: str
    safe: str | None
    safe_timeout_s: float
    safe_sent: tuple[Motor, ...]
    safe_acknowledged: tuple[Motor, ...]

    @property
    def commanded(self) -> tuple[Motor, ...]: ...


async def safe_stop(bus: SafeStopHost) -> None:
    """Send ``bus.safe`` to every motor the Bus commanded, again to each one that did not answer,
    until all answered or ``bus.safe_timeout_s`` ended; sets ``bus.safe_sent`` and
    ``bus.safe_acknowledged``, and names the motors that did not answer in a warning."""
    commanded = bus.commanded
    if bus.safe is None or not commanded:
        return
    if not bus.engine.link.is_open:
        logger.warning(
            "%s: the link is not open: the %s command cannot reach %s",
            bus.name,
            bus.safe,
            ", ".join(repr(m) for m in commanded),
        )
        return
    commands: dict[Motor, Command] = {}
    for motor in commanded:
        with contextlib.suppress(ValueError):
            commands[motor] = motor.codec.safe_command(bus.safe)
    outcome = StopOutcome()
    try:
        await stop_motors(bus, commands, bus.safe_timeout_s, outcome)
    finally:
        bus.safe_sent = outcome.sent
        bus.safe_acknowledged = outcome.acknowledged
        missing = [m for m in commands if m not in outcome.acknowledged]
        if missing:
            logger.warning(
                "%s: the %s command was not acknowledged by %s within %s",
                bus.name,
                bus.safe,
                ", ".join(repr(m) for m in missing),
                format_duration(bus.safe_timeout_s),
            )


@dataclass(slots=True)
class StopOutcome:
    """What :func:`stop_motors` did: the motors whose command left, and those that acknowledged it."""

    sent: tuple[Motor, ...] = ()
    acknowledged: tuple[Motor, ...] = ()


async def stop_motors(
    bus: StopHost, commands: Mapping[Motor, Command], timeout_s: float, outcome: StopOutcome | None = None
) -> StopOutcome:
    """Send each motor its (safe) command, past the watchdog (an offline motor gets it too), again to
    each one that did not answer, until all answered or ``timeout_s`` ended.

    ``outcome`` (a new one when None) is filled in even when the caller is cancelled meanwhile.
    """
    outcome = StopOutcome() if outcome is None else outcome
    engine = bus.engine
    attempts: dict[Motor, list[Request]] = {motor: [] for motor in commands}
    acknowledged: set[Motor] = set()

    async def stop(motor: Motor, command: Command) -> None:
        while True:
            request = engine.submit(motor, command, None, 0, safe=True)
            attempts[motor].append(request)
            try:
                await awaitable(request.context)
            except MotorTimeout:
                continue  # lost on its way there or back: it is safe to repeat
            except MotorNotExecuted:
                continue  # echoed back, not executed (a tripped watchdog): not acknowledged
            except TransportError:
                if not engine.link.is_open:
                    return
                await anyio.sleep(engine.scheduler.min_timeout_s)  # refused (a full queue): again
                continue
            except Exception:  # (an undecodable answer: not an acknowledgement, and no retry)
                return
            if request.key is not None:  # (a command with no reply cannot be acknowledged)
                acknowledged.add(motor)
            return

    try:
        with anyio.move_on_after(timeout_s):
            async with anyio.create_task_group() as group:
                for motor, command in commands.items():
                    group.start_soon(stop, motor, command)
    finally:
        engine.abandon(r for sent in attempts.values() for r in sent)
        outcome.sent = tuple(m for m, tried in attempts.items() if any(r.sent_at is not None for r in tried))
        outcome.acknowledged = tuple(m for m in commands if m in acknowledged)
    return outcome
