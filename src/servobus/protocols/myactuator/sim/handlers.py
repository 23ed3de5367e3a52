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
form (none, an echo, a reply) is the command's declaration (:func:`execute`). What a handler may use
of the motor is :class:`HandledMotor`: the handlers are typed against that contract, never against
the motor's class, so the model imports its handlers and nothing here imports the model.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, TypeVar, cast

from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator import Revision, StreamableCommand
from servobus.protocols.myactuator.sim.drive import Loop
from servobus.protocols.myactuator.sim.state import EncoderFrame, ErrorLatch, Readings, Settings, Stream
from servobus.sim.plant import Control, Plant

__all__ = ["HANDLERS", "HandledMotor", "Handler", "execute", "handles", "loop"]


class HandledMotor(Protocol):
    """What the command handlers read and change of the simulated motor (MyActuatorMotor is one)."""

    revision: Revision
    version_date: int
    model: str
    has_brake: bool
    pole_pairs: int
    rom: Settings
    ram: Settings
    encoder: EncoderFrame
    errors: ErrorLatch
    run_mode: ma.RunMode
    brake_released: bool
    feedforward_pct: int | None
    streams: dict[StreamableCommand, Stream]
    boot_s: float

    @property
    def motor_id(self) -> int: ...
    @property
    def plant(self) -> Plant: ...
    @property
    def enabled(self) -> bool: ...
    @property
    def angle_deg(self) -> float: ...
    def readings(self) -> Readings: ...
    def tally(self, kind: str, n: int = 1) -> None: ...
    def control_command(self, command: Command, loop: Loop, *, releases_brake: bool) -> Reply: ...
    def set_control(self, control: Control, run_mode: ma.RunMode) -> None: ...
    def apply_plant(self) -> None: ...
    def current_limit_a(self, pct: int | None) -> float | None: ...
    def target_deg(self, angle_deg: float) -> float: ...
    def status1_reply(self) -> Reply: ...
    def update_reports(self, now_s: float) -> None: ...
    def power_up(self, now_s: float) -> None: ...


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
        def handler(motor: HandledMotor, command: Command, _now_s: float, _rs485: bool) -> Reply:
            return motor.control_command(command, closed_loop, releases_brake=releases_brake)

        handles(*classes)(handler)
        return closed_loop

    return register


def execute(motor: HandledMotor, command: Command, now_s: float, *, rs485: bool) -> Reply | None:
    """Run ``command``'s handler on ``motor``; what comes back follows the command's declaration:
    nothing for NO_REPLY, an echo of the request for ``[Echo]``, otherwise the reply the handler built.

    Raises:
        TypeError: no handler for the command's class.
    """
    cls = type(command)
    handler = HANDLERS.get(cls)
    if handler is None:
        raise TypeError(f"the simulated motor has no handler for {cls.__name__}")
    reply = handler(motor, command, now_s, rs485)
    if cls.NO_REPLY is not None:
        return None
    if cls.REPLY is ma.Echo:
        return ma.Echo(command=cast(ma.MyActuatorCommand[Any], command))
    assert reply is not None, cls
    return reply
