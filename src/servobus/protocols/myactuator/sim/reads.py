"""What the simulated MyActuator motor answers to the reads: status, angles, encoder, parameters, ids.

Every value comes from the plant and the motor's memory at the time the request is handled.
"""

from __future__ import annotations

import math

from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator import Revision
from servobus.protocols.myactuator.sim.handlers import HandledMotor, handles
from servobus.protocols.myactuator.sim.state import (
    int32,
    single_turn_encoder_reply,
    single_turn_reply,
    status3_reply,
    status_reply,
)

__all__ = ["model_replies"]


def model_replies(revision: Revision, model: str) -> list[Reply]:
    """The 0xB5 replies that carry ``model`` (one on V4.3, three parts on V4.4).

    Raises:
        ValueError: the model string is too long for them.
    """
    if revision is Revision.V4_3:
        return [ma.ModelReply(model=model)]
    if len(model) > 15:
        raise ValueError(f"model={model!r} is longer than 15 characters")
    return [ma.ModelPartReply(part=p, text=model[5 * (p - 1) : 5 * p]) for p in (1, 2, 3)]


@handles(ma.ReadStatus1)
def _on_status1(motor: HandledMotor, _command: Command, _now_s: float, _rs485: bool) -> Reply:
    return motor.status1_reply()


@handles(ma.ReadStatus2)
def _on_status2(motor: HandledMotor, _command: Command, _now_s: float, _rs485: bool) -> Reply:
    return status_reply(ma.StatusCommand.READ_STATUS_2, motor.readings())


@handles(ma.ReadStatus3)
def _on_status3(motor: HandledMotor, _command: Command, _now_s: float, _rs485: bool) -> Reply:
    return status3_reply(motor.readings(), motor.pole_pairs)


@handles(ma.ReadMultiTurnAngle)
def _on_multi_turn_angle(motor: HandledMotor, _command: Command, _now_s: float, _rs485: bool) -> Reply:
    return ma.MultiTurnAngleReply(angle_deg=int32(motor.angle_deg * 100) / 100)


@handles(ma.ReadSingleTurnAngle)
def _on_single_turn_angle(motor: HandledMotor, _command: Command, _now_s: float, _rs485: bool) -> Reply:
    return single_turn_reply(motor.readings(), motor.revision)


@handles(ma.ReadEncoderPosition, ma.ReadEncoderRaw, ma.ReadEncoderOffset, ma.ReadSingleTurnEncoder)
def _on_encoder(motor: HandledMotor, command: Command, _now_s: float, _rs485: bool) -> Reply:
    encoder, rotor = motor.encoder, motor.plant.motor_position_deg
    if isinstance(command, ma.ReadEncoderPosition):
        return ma.EncoderPositionReply(encoder_counts=int32(encoder.position_counts(rotor)))
    if isinstance(command, ma.ReadEncoderRaw):
        return ma.EncoderRawReply(raw_counts=int32(encoder.raw_counts(rotor)))
    if isinstance(command, ma.ReadEncoderOffset):
        return ma.EncoderOffsetReply(offset_counts=int32(encoder.offset_counts))
    return single_turn_encoder_reply(motor.readings(), encoder.raw_counts(rotor), encoder.offset_counts)


@handles(ma.ReadPid)
def _on_read_pid(motor: HandledMotor, command: ma.ReadPid, _now_s: float, _rs485: bool) -> Reply:
    return ma.PidReply(index=command.index, value=motor.ram.pid[command.index])


@handles(ma.ReadAcceleration)
def _on_read_acceleration(
    motor: HandledMotor, command: ma.ReadAcceleration, _now_s: float, _rs485: bool
) -> Reply:
    value = motor.ram.acceleration_dps_s[command.index]
    return ma.AccelerationReply(index=command.index, acceleration_dps_s=value)


@handles(ma.ReadRunMode)
def _on_run_mode(motor: HandledMotor, _command: Command, _now_s: float, _rs485: bool) -> Reply:
    return ma.RunModeReply(mode=motor.run_mode)


@handles(ma.ReadRunTime)
def _on_run_time(motor: HandledMotor, _command: Command, now_s: float, _rs485: bool) -> Reply:
    return ma.RunTimeReply(run_time_ms=math.floor((now_s - motor.boot_s) * 1000 + 1e-6) % (1 << 32))


@handles(ma.ReadVersionDate)
def _on_version_date(motor: HandledMotor, _command: Command, _now_s: float, _rs485: bool) -> Reply:
    return ma.VersionDateReply(version_date=motor.version_date)


@handles(ma.ReadModel, ma.ReadModelPart)
def _on_model(motor: HandledMotor, command: Command, _now_s: float, _rs485: bool) -> Reply:
    part = command.part if isinstance(command, ma.ReadModelPart) else 1
    return model_replies(motor.revision, motor.model)[part - 1]


@handles(ma.ReadCanId)
def _on_read_can_id(motor: HandledMotor, _command: Command, _now_s: float, rs485: bool) -> Reply:
    # The RS485 example puts the id in DATA[7]; the CAN example sends 0x240+ID (§4.38).
    layout = ma.CanIdLayout.DATA7 if rs485 else ma.CanIdLayout.REPLY_IDENTIFIER
    return ma.CanIdReply(motor_id=motor.motor_id, layout=layout)
