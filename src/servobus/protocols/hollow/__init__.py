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

from servobus.protocols._family import Family
from servobus.protocols.hollow import bound as _bound
from servobus.protocols.hollow.codec import (
    DEFAULT_REVISION,
    Revision,
    decode_reply,
    decode_reply_frame,
    decode_request,
    decode_request_frame,
    reply_frame,
    request_frame,
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
    decode_special,
    is_special_command,
)
from servobus.protocols.hollow.commands_fd import FdCommand
from servobus.protocols.hollow.converter import (
    ConverterGain,
    ConverterPdGains,
    ConverterPiMultiplier,
    decode_converter_config,
)
from servobus.protocols.hollow.ids import (
    DEFAULT_HOST_ID,
    MOTOR_IDS,
    motor_id_from_reply,
    reply_id,
    reply_key,
    request_id,
    request_key,
)
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
    decode_modbus_reply,
    decode_modbus_request,
    decode_transparent,
    encode_transparent,
)

__all__ = [
    "DEFAULT_HOST_ID",
    "DEFAULT_MODEL",
    "DEFAULT_REVISION",
    "FAMILY",
    "MODELS",
    "MODEL_3507",
    "MOTOR_IDS",
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
    "decode_converter_config",
    "decode_modbus_reply",
    "decode_modbus_request",
    "decode_reply",
    "decode_reply_frame",
    "decode_request",
    "decode_request_frame",
    "decode_special",
    "decode_transparent",
    "encode_transparent",
    "is_special_command",
    "motor_id_from_reply",
    "reply_frame",
    "reply_id",
    "reply_key",
    "request_frame",
    "request_id",
    "request_key",
]

FAMILY = Family(
    name="hollow",
    description="hollow-series joint motors: CAN normal/extended, CAN FD, RS-485 transparent and Modbus RTU",
    revisions=(Revision.HO_SERIES,),
    default_revision=DEFAULT_REVISION,
    decode_request=decode_request,
    decode_reply=decode_reply,
    links=_bound.LINKS,
    bind=_bound.bind,
    broadcast=_bound.broadcast,
)
