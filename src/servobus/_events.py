"""What a motor tells of itself, and commands it did not execute (:class:`MotorEvents`, a part of the
Bus's frame intake, servobus.delivery).

* An event frame (a reply class that declares ``EVENT``: MyActuator's 0xF1, its communication
  watchdog tripped) is counted under its name, each frame; it shows in ``motor.fault`` until the motor
  executes a command again; the status listeners hear it and the log says it once per episode.
* A request the motor echoed instead of executing (the scheduler failed it with MotorNotExecuted) is
  settled with that error; the log says it once per motor.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from servobus.errors import MotorFault

if TYPE_CHECKING:
    from servobus.engine import Engine
    from servobus.motor import Motor
    from servobus.protocols import Reply
    from servobus.scheduler import Received

__all__ = ["MotorEvents"]

logger = logging.getLogger("servobus.bus")


class MotorEvents:
    """Events and echoes of one bus's motors."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self.name = engine.name
        #: motors (by codec id) whose last event has not been followed by an executed command; the
        #: intake reads it on every reply, so it stays a plain dict (empty: nothing to do)
        self.tripped: dict[int, Motor] = {}
        self._echo_logged: set[int] = set()

    def event(self, motor: Motor, reply: Reply, at: float) -> None:
        """``motor`` sent an event frame: counted, shown in ``motor.fault``, told (once per episode)."""
        name = reply.EVENT
        assert name is not None
        self.engine.scheduler.motor_counts[id(motor.codec)][name] += 1
        if id(motor.codec) in self.tripped:
            return  # the same episode: the motor repeats it (0xF1: about every second)
        self.tripped[id(motor.codec)] = motor
        reason = reply.EVENT_REASON or name
        motor.fault = MotorFault(
            f"{motor!r}: {reason}: its output is off until it executes a command again",
            flags=None,
            motor_id=motor.motor_id,
        )
        logger.warning("%s: %s", self.name, motor.fault)
        self.engine.watchdog.event(motor, at, reason)

    def executed(self, motor: Motor) -> None:
        """``motor`` answered a request for real: the episode of its last event is over."""
        if self.tripped.pop(id(motor.codec), None) is None:
            return
        if motor.fault is not None and motor.fault.flags is None:
            motor.fault = None
        logger.info("%s: %r executes commands again", self.name, motor)

    def not_executed(self, got: Received) -> None:
        """The scheduler failed ``got.request``: the motor echoed it back instead of executing it."""
        request = got.request
        assert request is not None and got.codec is not None
        if id(got.codec) not in self._echo_logged:  # once per motor, not once per frame
            self._echo_logged.add(id(got.codec))
            logger.warning("%s: %s", self.name, request.error)
        else:
            logger.debug("%s: %s", self.name, request.error)
        self.engine.settle(request, request.error)
