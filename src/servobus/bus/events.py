"""What a motor tells of itself, and commands it did not execute (:class:`MotorEvents`, a part of the
Bus's frame intake, servobus.bus.delivery).

* An event frame (a reply class that declares ``EVENT``: MyActuator's 0xF1, its communication
  watchdog tripped) is counted under its name, each frame; it shows in ``motor.fault`` until the motor
  executes a command again; the status listeners hear it and the log says it once per episode.
* A request the motor echoed instead of executing (the scheduler failed it with MotorNotExecuted) is
  settled with that error; the log says it once per motor.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

from servobus.errors import MotorFault

if TYPE_CHECKING:
    from servobus.bus.motor import MotorRecord
    from servobus.bus.watchdog import Watchdog
    from servobus.protocols import BoundCodec, Reply
    from servobus.scheduler import Received, Request

__all__ = ["MotorEvents"]

logger = logging.getLogger("servobus.bus")


class MotorEvents:
    """Events and echoes of one bus's motors.

    Args:
        name: the bus's label, for the log.
        count: ``count(codec, counter)``, the engine's per-motor counter.
        settle: ``settle(request, error)``, the engine's.
        watchdog: the Bus's watchdog (it tells the status listeners).
    """

    def __init__(
        self,
        name: str,
        count: Callable[[BoundCodec, str], None],
        settle: Callable[[Request, BaseException | None], None],
        watchdog: Watchdog,
    ) -> None:
        self.name = name
        self._count = count
        self._settle = settle
        self._watchdog = watchdog
        #: the motors whose last event has not been followed by an executed command; the intake
        #: reads it on every reply, so it stays a plain set (empty: nothing to do)
        self.tripped: set[MotorRecord] = set()

    def event(self, record: MotorRecord, reply: Reply, at: float) -> None:
        """``record``'s motor sent an event frame: counted, shown in ``motor.fault``, told (once per
        episode)."""
        name = reply.EVENT
        assert name is not None
        self._count(record.codec, name)
        if record in self.tripped:
            return  # the same episode: the motor repeats it (0xF1: about every second)
        self.tripped.add(record)
        reason = reply.EVENT_REASON or name
        motor = record.motor
        motor.fault = MotorFault(
            f"{motor!r}: {reason}: its output is off until it executes a command again",
            flags=None,
            motor_id=motor.motor_id,
        )
        logger.warning("%s: %s", self.name, motor.fault)
        self._watchdog.event(motor, at, reason)

    def executed(self, record: MotorRecord) -> None:
        """``record``'s motor answered a request for real: the episode of its last event is over."""
        if record not in self.tripped:
            return
        self.tripped.discard(record)
        motor = record.motor
        if motor.fault is not None and motor.fault.flags is None and motor.fault.code is None:
            motor.fault = None  # (the event's: a fault told by flags or a code stays until they clear)
        logger.info("%s: %r executes commands again", self.name, motor)

    def not_executed(self, got: Received, record: MotorRecord | None) -> None:
        """The scheduler failed ``got.request``: the motor echoed it back instead of executing it."""
        request = got.request
        assert request is not None
        if record is not None and not record.echo_logged:  # once per motor, not once per frame
            record.echo_logged = True
            logger.warning("%s: %s", self.name, request.error)
        else:
            logger.debug("%s: %s", self.name, request.error)
        self._settle(request, request.error)
