"""The hollow-series ("HO") family: classic CAN normal/extended mode, CAN FD, the RS-485 converter.

Sans-IO codecs between typed commands/replies in physical units and payload bytes (hollow.md):

* classic CAN, normal mode: special commands (:class:`Start`, :class:`Stop`, :class:`SelectMode`,
  :class:`SetZero`), :class:`Setpoint`, the 6-byte :class:`NormalReply` (§4);
* classic CAN, extended mode: :class:`CanModeSwitch` (extended id), :class:`IncrementalSetpoint`,
  the 8-byte :class:`ExtendedReply` (§5); :class:`PiMultiplier` (extended id, §6);
* CAN FD: :class:`FdCommand` and :class:`FdReply`, 16 bytes each (§7);
* the 485 -> CANFD converter: transparent frames (:class:`TransparentRequest`,
  :class:`TransparentReply`), Modbus RTU (:class:`ModbusWrite`, :class:`ModbusRead` and their
  replies), and its own configuration frames (§9).

Frames are told apart by identifier kind, FD flag and length, so :func:`decode_request` and
:func:`decode_reply` take those flags as keywords (see :mod:`servobus.protocols.hollow.codec`).
Scales that the manual leaves per motor model live in :class:`HollowModel`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from servobus.protocols._family import Family, SerialLine, command_classes
from servobus.protocols.hollow import bound as _bound
from servobus.protocols.hollow.codec import (
    Revision,
    decode_reply,
    decode_request,
)
from servobus.protocols.hollow.commands import (
    CanMode,
    CanModeSwitch,
    ControlMode,
    HollowCommand,
    IncrementalSetpoint,
    PiGain,
    PiMultiplier,
    SelectMode,
    Setpoint,
    SetZero,
    SpecialCommand,
    Start,
    Stop,
)
from servobus.protocols.hollow.commands_fd import FdCommand
from servobus.protocols.hollow.converter import (
    ConverterGain,
    ConverterPdGains,
    ConverterPiMultiplier,
)
from servobus.protocols.hollow.ids import (
    DEFAULT_HOST_ID,
)
from servobus.protocols.hollow.ids import MOTOR_IDS as _MOTOR_IDS
from servobus.protocols.hollow.model import DEFAULT_MODEL, MODEL_3507, MODELS, HollowModel
from servobus.protocols.hollow.replies import ExtendedReply, FdReply, HollowReply, NormalReply
from servobus.protocols.hollow.rs485 import (
    ModbusException,
    ModbusFunction,
    ModbusRead,
    ModbusReadReply,
    ModbusWrite,
    ModbusWriteAck,
    TransparentReply,
    TransparentRequest,
)

if TYPE_CHECKING:  # the typed motor class; imported when a Bus asks (it imports the Bus)
    from servobus.protocols.hollow._motor import Motor


# A declaration: related arguments share a line.
# fmt: off
FAMILY: Family[Motor] = Family(
    name="hollow", package=__name__,  # the typed Motor (_motor.py) and the sim, cli, dbc parts are there
    description="hollow-series joint motors: CAN normal/extended, CAN FD, RS-485 transparent and Modbus RTU",
    revisions=_bound.REVISIONS, default_revision=_bound.REVISIONS[0],
    decode_request=decode_request, decode_reply=decode_reply,
    links=_bound.LINKS, bind=_bound.bind, broadcast=_bound.broadcast, motor_ids=_MOTOR_IDS,
    # The requests a link of the bound codec carries; the whole serial frames (TransparentRequest) and
    # the converter's configuration frames (no stated port) are encoded directly, not sent by a Motor.
    commands=tuple(cls for cls in command_classes(globals().values()) if getattr(cls, "LINKS", ())),
    serial=(  # the converter's two RS-485 modes, each at its fixed rate, 8N1 (hollow.md §9.4, §9.5, A36)
        SerialLine(
            name=_bound.TransparentFraming.name, framing=_bound.TransparentFraming, bauds=(1_000_000,)
        ),
        SerialLine(
            name=_bound.ModbusFraming.name,
            framing=_bound.ModbusFraming,
            bauds=(19_200,),
            aliases=("modbus-rtu",),
        ),
    ),
)
# fmt: on

__all__ = [
    "DEFAULT_HOST_ID",
    "DEFAULT_MODEL",
    "FAMILY",
    "MODELS",
    "MODEL_3507",
    "CanMode",
    "CanModeSwitch",
    "ControlMode",
    "ConverterGain",
    "ConverterPdGains",
    "ConverterPiMultiplier",
    "ExtendedReply",
    "FdCommand",
    "FdReply",
    "HollowCommand",
    "HollowModel",
    "HollowReply",
    "IncrementalSetpoint",
    "ModbusException",
    "ModbusFunction",
    "ModbusRead",
    "ModbusReadReply",
    "ModbusWrite",
    "ModbusWriteAck",
    "NormalReply",
    "PiGain",
    "PiMultiplier",
    "Revision",
    "SelectMode",
    "SetZero",
    "Setpoint",
    "SpecialCommand",
    "Start",
    "Stop",
    "TransparentReply",
    "TransparentRequest",
    "decode_reply",
    "decode_request",
]
