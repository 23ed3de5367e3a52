"""Helpers shared by the simulated-MyActuator tests: talk to one motor through the family codec."""

from __future__ import annotations

from typing import Any, TypeVar

from servobus.frame import Frame
from servobus.protocols import Reply
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.codec import request_frame
from servobus.protocols.myactuator.sim.device import DEFAULT_TURNAROUND_S, MyActuatorMotor

R = TypeVar("R", bound=Reply)
TURNAROUND = DEFAULT_TURNAROUND_S


def frame_for(motor: MyActuatorMotor, command: Any, *, broadcast: bool = False) -> Frame:
    """The CAN frame the host sends ``command`` in (revision checked by the codec)."""
    return request_frame(command, motor.motor_id, revision=motor.revision, broadcast=broadcast)


def ask(motor: MyActuatorMotor, command: Any, at: float, expected: type[R]) -> R:
    """Deliver ``command`` at ``at``; return its one reply, decoded by the host codec, as ``expected``."""
    emissions = motor.receive(frame_for(motor, command), at)
    assert len(emissions) == 1, emissions
    (emission,) = emissions
    assert emission.ready_s == at + motor.turnaround_s
    reply = ma.decode_reply(
        emission.frame.arbitration_id,
        emission.frame.data,
        revision=motor.revision,
        motion_scales=motor.motion_scales,
    )
    assert isinstance(reply, expected), reply
    return reply


def tell(motor: MyActuatorMotor, command: Any, at: float) -> None:
    """Deliver an echo command and check the echo."""
    reply = ask(motor, command, at, ma.Echo)
    assert reply.command == command


def status(motor: MyActuatorMotor, at: float) -> ma.StatusReply:
    return ask(motor, ma.ReadStatus2(), at, ma.StatusReply)


def status1(motor: MyActuatorMotor, at: float) -> ma.Status1Reply:
    return ask(motor, ma.ReadStatus1(), at, ma.Status1Reply)


def angle(motor: MyActuatorMotor, at: float) -> float:
    return ask(motor, ma.ReadMultiTurnAngle(), at, ma.MultiTurnAngleReply).angle_deg


# ---- every request vector of both manuals, from the device side ----
