"""The simulated MyActuator motor's dispatch: what it does on each command class.

The handlers live by concern beside this module and register themselves here (``@handles``, or
``@loop`` for a closed-loop command), so the command list is the codec's, never a second one:

* :mod:`~servobus.protocols.myactuator.sim.reads`: status, angle, encoder and parameter reads;
* :mod:`~servobus.protocols.myactuator.sim.loops`: the closed loops (set-points, motion mode), stop,
  shutdown and the brake;
* :mod:`~servobus.protocols.myactuator.sim.settings`: ROM/RAM writes, zeros, ids, protection, reset;
* :mod:`~servobus.protocols.myactuator.sim.streams`: 0xB6 active-reply streams.

A handler is ``handler(motor, command, now_s, rs485)``: it acts on the motor's state (the model
itself, whose attributes a C twin keeps in step) and returns the reply it built, if any; the reply's
form (none, an echo, a reply) is the command's declaration
(:meth:`MyActuatorMotor._execute <servobus.protocols.myactuator.sim.device.MyActuatorMotor._execute>`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator.sim.drive import Loop

if TYPE_CHECKING:
    from servobus.protocols.myactuator.sim.device import MyActuatorMotor

__all__ = ["HANDLERS", "Handler", "handles", "loop"]

Handler = Callable[[Any, Any, float, bool], "Reply | None"]
#: the handler of each command class (filled as the handler modules are imported)
HANDLERS: dict[type[Command], Handler] = {}
H = TypeVar("H", bound=Callable[..., Any])


def handles(*classes: type[Command]) -> Callable[[H], H]:
    """Register the decorated function as the handler of ``classes``."""

    def register(handler: H) -> H:
        for cls in classes:
            if cls in HANDLERS:
                raise TypeError(f"two simulator handlers for {cls.__name__}")
            HANDLERS[cls] = handler
        return handler

    return register


def loop(*classes: type[Command], releases_brake: bool = True) -> Callable[[Loop], Loop]:
    """Register closed-loop commands: ``loop(motor, command)`` gives the plant control and run mode;
    the motor runs it unless a fault is latched, and answers with its status either way."""

    def register(closed_loop: Loop) -> Loop:
        def handler(motor: MyActuatorMotor, command: Command, _now_s: float, _rs485: bool) -> Reply:
            return motor._control_command(command, closed_loop, releases_brake=releases_brake)

        handles(*classes)(handler)
        return closed_loop

    return register
