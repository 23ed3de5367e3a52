"""MyActuator RS485 motion-mode frames (header FE EE, float32 fields, CRC32; V4.4, [000] §6 only).

Only as much as myactuator-v4.md §6 reconstructs from the OCR'd manual is implemented:

Request, 28 bytes (offsets 0-based here; the manual numbers bytes from 1)::

    0-1 FE EE | 2 motor id (0xBB: broadcast, no reply) | 3 mode (0x00 stop, 0x0A servo)
    4-7 t_ff N·m | 8-11 v_des rad/s | 12-15 p_des rad | 16-19 kp | 20-23 kd     (float32 LE)
    24-27 CRC32

Reply, 24 bytes::

    0-1 FE EE | 2 motor id | 3 mode | 4 temperature int8 °C | 5-6 error flags uint16 LE | 7 reserved
    8-11 torque N·m | 12-15 speed rad/s | 16-19 position rad                          (float32 LE)
    20-23 CRC32

What is **not known** (nothing here invents it; all of it needs checking on hardware):

* The CRC32: algorithm, coverage and byte order are not specified (§6, §9 item 20). The default rule,
  :func:`crc32_iso_hdlc_le`, is the spec's "reasonable first guess": CRC-32/ISO-HDLC (zlib) over every
  byte before the CRC, least significant byte first. It is pluggable: pass ``crc=`` to encode/decode,
  or ``crc=None`` to decode without checking.
* The field boundaries come from OCR'd row numbers (labels at the middle rows of each 4-byte group).
* Motor_Err bit 0x0080 is "component over-temperature" in this frame but "calibration parameter write
  error" in 0x9A, whose table puts component over-temperature at 0x0800 (§4.14). The bits are decoded
  into :class:`ErrorFlags` by the 0x9A table; read 0x0080 here with that conflict in mind.
* The reply's mode byte values beyond 0x00/0x0A, the reserved byte's content, and the timing of replies
  are not described. Undefined mode values are kept as ints; the reserved byte is ignored.
* Whether the frame shares the bus with the 0x3E standard frames is not stated; the 0x3E de-framer does
  not cut FE EE frames, and this module offers no stream de-framer for them.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Self

from servobus.core import crc32_ieee
from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator._layout import (
    EnumField,
    FieldCodec,
    FlagsField,
    Float32Field,
    MyActuatorMessage,
    OpenEnumField,
    check_fields,
    construct,
)
from servobus.protocols.myactuator.enums import ErrorFlags, Rs485MotionMode
from servobus.protocols.myactuator.ids import MOTOR_IDS
from servobus.protocols.myactuator.revision import ONLY_V4_4

__all__ = [
    "RS485_MOTION_BROADCAST_ID",
    "RS485_MOTION_HEADER",
    "Crc32Rule",
    "Rs485MotionCommand",
    "Rs485MotionReply",
    "crc32_iso_hdlc_le",
]

RS485_MOTION_HEADER = b"\xfe\xee"
RS485_MOTION_BROADCAST_ID = 0xBB
REQUEST_SIZE = 28
REPLY_SIZE = 24

#: A CRC rule: the frame bytes before the CRC in, the 4 CRC bytes as sent out.
Crc32Rule = Callable[[bytes], bytes]


def crc32_iso_hdlc_le(body: bytes) -> bytes:
    """The default (UNVERIFIED) CRC rule: CRC-32/ISO-HDLC over ``body``, least significant byte first."""
    return crc32_ieee(body).to_bytes(4, "little")


def _check_crc(frame: bytes, crc: Crc32Rule | None, what: str) -> None:
    if crc is None:
        return
    expected = crc(frame[:-4])
    if frame[-4:] != expected:
        raise ProtocolError(
            f"{what}: CRC32 {frame[-4:].hex(' ').upper()} should be {expected.hex(' ').upper()} "
            "(the CRC rule is unverified; pass crc=None to skip it)",
            raw=frame,
        )


def _check_frame(frame: bytes, size: int, what: str) -> None:
    if len(frame) != size:
        raise ProtocolError(f"{what}: expected {size} bytes, got {len(frame)}", raw=frame)
    if frame[:2] != RS485_MOTION_HEADER:
        raise ProtocolError(f"{what}: header {frame[:2].hex(' ').upper()} is not FE EE", raw=frame)


class _Rs485MotionFrame(MyActuatorMessage):
    """Fields at ``FIELDS`` offsets of a whole frame; ``encode`` appends the default CRC."""

    __slots__ = ()
    REVISIONS = ONLY_V4_4
    SIZE: ClassVar[int]
    FIELDS: ClassVar[tuple[tuple[int, FieldCodec], ...]]

    def __post_init__(self) -> None:
        check_fields(self, self.FIELDS)

    def encode(self, *, crc: Crc32Rule = crc32_iso_hdlc_le) -> bytes:
        """The whole frame, header to CRC (``crc``: the CRC rule, default the unverified guess)."""
        body = bytearray(self.SIZE - 4)
        body[0:2] = RS485_MOTION_HEADER
        for offset, spec in self.FIELDS:
            body[offset : offset + spec.size] = spec.encode(getattr(self, spec.name))
        return bytes(body) + crc(bytes(body))

    @classmethod
    def decode(cls, data: bytes, *, crc: Crc32Rule | None = crc32_iso_hdlc_le) -> Self:
        """Decode a whole frame.

        Args:
            data: the frame, header to CRC.
            crc: the CRC rule to check it with; None skips the check (the rule is unverified).

        Raises:
            ProtocolError: wrong size or header, CRC mismatch, or a value the class does not accept.
        """
        what = cls.__name__
        data = bytes(data)
        _check_frame(data, cls.SIZE, what)
        _check_crc(data, crc, what)
        try:
            values: dict[str, Any] = {spec.name: spec.decode(data, offset) for offset, spec in cls.FIELDS}
        except ValueError as exc:
            raise ProtocolError(f"{what}: {exc}", raw=data) from None
        return construct(cls, data, values)

    @classmethod
    def field_specs(cls) -> dict[str, FieldCodec]:
        """The field codecs by attribute name."""
        return {spec.name: spec for _, spec in cls.FIELDS}


_MOTOR_ID_OR_BROADCAST = IntField("motor_id", 1, lo=1, hi=RS485_MOTION_BROADCAST_ID)


@dataclass(frozen=True, slots=True, kw_only=True)
class Rs485MotionReply(_Rs485MotionFrame, Reply):
    """RS485 motion-mode reply (V4.4 only). ``errors`` uses the 0x9A bit names (see the module notes on
    0x0080); ``mode`` keeps undefined values as ints."""

    TITLE: ClassVar[str] = "RS485 motion mode reply"
    SIZE = REPLY_SIZE
    FIELDS = (
        (2, IntField("motor_id", 1, lo=1, hi=32)),
        (3, OpenEnumField("mode", 1, Rs485MotionMode)),
        (4, IntField("temperature_c", 1, signed=True)),
        (5, FlagsField("errors", 2, ErrorFlags)),
        (8, Float32Field("torque_nm")),
        (12, Float32Field("speed_rad_s")),
        (16, Float32Field("position_rad")),
    )
    motor_id: int
    mode: Rs485MotionMode | int
    temperature_c: int
    torque_nm: float
    speed_rad_s: float
    position_rad: float
    errors: ErrorFlags = ErrorFlags.NONE


#: what kp = 0 leaves unused (Command.inactive)
_POSITION = frozenset({"position_rad"})


@dataclass(frozen=True, slots=True, kw_only=True)
class Rs485MotionCommand(_Rs485MotionFrame, Command[Rs485MotionReply]):
    """RS485 motion-mode request (V4.4 only): the CAN motion mode's control law with float32 values.

    ``motor_id`` 1..32, or 0xBB to address every motor (they do not reply). Values are any finite
    float32; the manual states no ranges for this frame.
    """

    TITLE: ClassVar[str] = "RS485 motion mode command"
    SIZE = REQUEST_SIZE
    FIELDS = (
        (2, _MOTOR_ID_OR_BROADCAST),
        (3, EnumField("mode", 1, Rs485MotionMode)),
        (4, Float32Field("torque_ff_nm")),
        (8, Float32Field("velocity_rad_s")),
        (12, Float32Field("position_rad")),
        (16, Float32Field("kp")),
        (20, Float32Field("kd")),
    )
    motor_id: int
    position_rad: float
    velocity_rad_s: float
    kp: float
    kd: float
    torque_ff_nm: float
    mode: Rs485MotionMode = Rs485MotionMode.SERVO

    def inactive(self) -> frozenset[str]:
        """With kp = 0 the position is not acted on (a speed or torque set-point): see Command."""
        return _POSITION if self.kp == 0 else frozenset()

    def __post_init__(self) -> None:
        _Rs485MotionFrame.__post_init__(self)
        if self.motor_id not in MOTOR_IDS and self.motor_id != RS485_MOTION_BROADCAST_ID:
            raise ValueError(f"motor_id={self.motor_id!r} is outside [1, 32] and is not the broadcast 0xBB")


def float32(value: float) -> float:
    """``value`` rounded to the nearest float32 (what these frames carry)."""
    result: float = struct.unpack("<f", struct.pack("<f", value))[0]
    return result
