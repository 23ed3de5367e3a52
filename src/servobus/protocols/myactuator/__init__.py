"""MyActuator V3-driver protocol, revisions V4.3 and V4.4: sans-IO codec (myactuator-v4.md).

Modules, one job each:

* :mod:`.revision`: ``Revision`` and the rule choosing it from the 0xB2 version date.
* :mod:`.ids`: CAN identifiers (0x140/0x240/0x280/0x300/0x400/0x500) and match keys.
* :mod:`.enums`: indexes, modes, error flags, the fault table.
* :mod:`.commands`, :mod:`.commands_control`: one class per 8-byte request.
* :mod:`.motion`: CAN motion (MIT) mode, with per-revision ranges.
* :mod:`.replies`: one class per reply layout, and ``Echo``.
* :mod:`.codec`: decoder tables, ``decode_request``/``decode_reply``, revision availability.
* :mod:`.rs485`: the ``3E`` RS485 frame; :mod:`.rs485_motion`: the ``FE EE`` RS485 motion frame (V4.4).

Usage::

    from servobus.protocols import myactuator as ma

    command = ma.AbsolutePositionControl(angle_deg=360, max_speed_dps=500)
    data = ma.encode_request(command, revision=ma.Revision.V4_4)  # A4 00 F4 01 A0 8C 00 00
    reply = ma.decode_reply(0x241, bytes.fromhex("A4 32 64 00 F4 01 2D 00"))  # StatusReply(...)
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from servobus.protocols._family import Family, SerialLine, command_classes
from servobus.protocols.myactuator import bound as _bound
from servobus.protocols.myactuator.codec import (
    decode_reply,
    decode_request,
)
from servobus.protocols.myactuator.commands import (
    ActiveReply,
    BrakeLock,
    BrakeRelease,
    FunctionControl,
    MotorShutdown,
    MotorStop,
    MyActuatorCommand,
    ReadAcceleration,
    ReadCanId,
    ReadEncoderOffset,
    ReadEncoderPosition,
    ReadEncoderRaw,
    ReadModel,
    ReadModelPart,
    ReadMultiTurnAngle,
    ReadPid,
    ReadRunMode,
    ReadRunTime,
    ReadSingleTurnAngle,
    ReadSingleTurnEncoder,
    ReadStatus1,
    ReadStatus2,
    ReadStatus3,
    ReadVersionDate,
    SetBaudRate,
    SetCanId,
    SetCommTimeout,
    SystemReset,
    WriteAcceleration,
    WriteCurrentPositionAsZero,
    WriteEncoderZero,
    WritePidRam,
    WritePidRom,
)
from servobus.protocols.myactuator.commands_control import (
    AbsolutePositionControl,
    ForcePositionControl,
    IncrementalPositionControl,
    PositionSpeedFeedforward,
    PositionTorqueFeedforward,
    SingleTurnPositionControl,
    SpeedControl,
    TorqueControl,
)
from servobus.protocols.myactuator.enums import (
    BAUD_RATE_INDEXES,
    ERROR_FLAG_INFO,
    FAULTS,
    FUNCTION_VALUES,
    AccelIndex,
    BaudRateSetting,
    ErrorFlagInfo,
    ErrorFlags,
    Fault,
    FunctionIndex,
    IndicatorLevel,
    PidIndex,
    Rs485MotionMode,
    RunMode,
    SpinDirection,
    StatusCommand,
    StreamableCommand,
)
from servobus.protocols.myactuator.ids import MOTOR_IDS as _MOTOR_IDS
from servobus.protocols.myactuator.ids import (
    IdKind,
)
from servobus.protocols.myactuator.motion import MOTION_SCALES, MotionCommand, MotionReply, MotionScales
from servobus.protocols.myactuator.replies import (
    AccelerationReply,
    CanIdLayout,
    CanIdReply,
    CircleAngleReply,
    Echo,
    EncoderOffsetReply,
    EncoderPositionReply,
    EncoderRawReply,
    ModelPartReply,
    ModelReply,
    MultiTurnAngleReply,
    MyActuatorReply,
    PidReply,
    RunModeReply,
    RunTimeReply,
    SingleTurnAngleReply,
    SingleTurnEncoderReply,
    SingleTurnStatusReply,
    Status1Reply,
    Status3Reply,
    StatusReply,
    VersionDateReply,
    ZeroOffsetReply,
    guess_single_turn_revision,
    join_model,
)
from servobus.protocols.myactuator.revision import V4_4_MANUAL_DATE, Revision, revision_from_version_date
from servobus.protocols.myactuator.rs485_motion import (
    Crc32Rule,
    Rs485MotionCommand,
    Rs485MotionReply,
)

__all__ = [
    "BAUD_RATE_INDEXES",
    "ERROR_FLAG_INFO",
    "FAMILY",
    "FAULTS",
    "FUNCTION_VALUES",
    "MOTION_SCALES",
    "V4_4_MANUAL_DATE",
    "AbsolutePositionControl",
    "AccelIndex",
    "AccelerationReply",
    "ActiveReply",
    "BaudRateSetting",
    "BrakeLock",
    "BrakeRelease",
    "CanIdLayout",
    "CanIdReply",
    "CircleAngleReply",
    "Crc32Rule",
    "Echo",
    "EncoderOffsetReply",
    "EncoderPositionReply",
    "EncoderRawReply",
    "ErrorFlagInfo",
    "ErrorFlags",
    "Fault",
    "ForcePositionControl",
    "FunctionControl",
    "FunctionIndex",
    "IdKind",
    "IncrementalPositionControl",
    "IndicatorLevel",
    "ModelPartReply",
    "ModelReply",
    "MotionCommand",
    "MotionReply",
    "MotionScales",
    "MotorShutdown",
    "MotorStop",
    "MultiTurnAngleReply",
    "MyActuatorCommand",
    "MyActuatorReply",
    "PidIndex",
    "PidReply",
    "PositionSpeedFeedforward",
    "PositionTorqueFeedforward",
    "ReadAcceleration",
    "ReadCanId",
    "ReadEncoderOffset",
    "ReadEncoderPosition",
    "ReadEncoderRaw",
    "ReadModel",
    "ReadModelPart",
    "ReadMultiTurnAngle",
    "ReadPid",
    "ReadRunMode",
    "ReadRunTime",
    "ReadSingleTurnAngle",
    "ReadSingleTurnEncoder",
    "ReadStatus1",
    "ReadStatus2",
    "ReadStatus3",
    "ReadVersionDate",
    "Revision",
    "Rs485MotionCommand",
    "Rs485MotionMode",
    "Rs485MotionReply",
    "RunMode",
    "RunModeReply",
    "RunTimeReply",
    "SetBaudRate",
    "SetCanId",
    "SetCommTimeout",
    "SingleTurnAngleReply",
    "SingleTurnEncoderReply",
    "SingleTurnPositionControl",
    "SingleTurnStatusReply",
    "SpeedControl",
    "SpinDirection",
    "Status1Reply",
    "Status3Reply",
    "StatusCommand",
    "StatusReply",
    "StreamableCommand",
    "SystemReset",
    "TorqueControl",
    "VersionDateReply",
    "WriteAcceleration",
    "WriteCurrentPositionAsZero",
    "WriteEncoderZero",
    "WritePidRam",
    "WritePidRom",
    "ZeroOffsetReply",
    "decode_reply",
    "decode_request",
    "guess_single_turn_revision",
    "join_model",
    "revision_from_version_date",
]

if TYPE_CHECKING:
    from servobus.protocols.myactuator._motor import Motor


def _motor() -> type[Motor]:
    """The typed motor class (it imports the Bus, so only when a Bus asks)."""
    from servobus.protocols.myactuator._motor import Motor

    return Motor


FAMILY: Family[Motor] = Family(
    name="myactuator",
    description="MyActuator RMD-X and similar on V3 drivers, protocol V4.3/V4.4 (CAN, RS485, motion mode)",
    revisions=(Revision.V4_4, Revision.V4_3),
    default_revision=Revision.V4_4,
    decode_request=decode_request,
    decode_reply=decode_reply,
    links=_bound.LINKS,
    bind=_bound.bind,
    broadcast=_bound.broadcast,
    commands=command_classes(globals().values()),
    motor=_motor,
    motor_ids=_MOTOR_IDS,
    serial=(  # 8N1 at the rates the manuals list, none named the default (myactuator-v4.md §1.2)
        SerialLine(
            name=_bound.Rs485Framing.name,
            framing=_bound.Rs485Framing,
            bauds=(115_200, 500_000, 1_000_000, 1_500_000, 2_500_000),
            aliases=("myactuator",),
        ),
    ),
    parts={
        "sim": "servobus.protocols.myactuator.sim:SIM",
        "cli": "servobus.protocols.myactuator.cli:CLI",
        "dbc": "servobus.protocols.myactuator.dbc:DBC",
    },
)
