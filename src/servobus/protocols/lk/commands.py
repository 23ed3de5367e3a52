"""LK requests that read state or change the motor's mode, zero, brake or acceleration (no set-points).

Set-point commands (0xA0..0xA8, 0x280) are in :mod:`~servobus.protocols.lk.commands_control`,
parameter commands (0x40/0x42/0x44, 0xC0/0xC1) in :mod:`~servobus.protocols.lk.params`.
Spec sections are cited per class; [001] = V2.36 manual, [003] = V2.35 manual.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Self

from servobus.protocols._fields import ScaledField
from servobus.protocols.lk._base import (
    V2_35_ONLY,
    V2_36_ONLY,
    LkCommand,
    build,
    check_encoder_count,
    enum_byte,
    expect,
    payload,
)
from servobus.protocols.lk.model import DEFAULT_MODEL, LkModel, check_encoder_bits, check_member
from servobus.protocols.lk.states import BrakeAction

__all__ = [
    "BrakeControl",
    "CalibrateEncoder",
    "ClearErrors",
    "FixedCommand",
    "MotorOff",
    "MotorRun",
    "MotorStop",
    "ReadAcceleration",
    "ReadEncoder",
    "ReadMultiTurnAngle",
    "ReadSingleTurnAngle",
    "ReadStatus1",
    "ReadStatus2",
    "ReadStatus3",
    "SetZeroRam",
    "SetZeroRom",
    "WriteAcceleration",
    "WriteEncoderOffset",
]

ENCODER_OFFSET_AT = 6  # 0x91 / 0x19: uint16 LE in DATA[6..7] (spec §4.22, §4.23)
ACCELERATION = ScaledField("acceleration_dps2", size=4, signed=True, counts_per_unit=1)  # spec §4.31


class FixedCommand(LkCommand):
    """A request whose 8 bytes are fixed: the command byte and seven NULL bytes."""

    __slots__ = ()
    CODE: ClassVar[int]

    def encode(self) -> bytes:
        return payload(self.CODE)

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        expect(data, cls.CODE, cls.__name__)
        return cls()


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadStatus1(FixedCommand):
    """0x9A: read temperature, voltage (V2.36: bus current, motor state) and error flags (spec §4.1)."""

    CODE: ClassVar[int] = 0x9A


@dataclass(frozen=True, slots=True, kw_only=True)
class ClearErrors(FixedCommand):
    """0x9B: clear the error flags; they stay set while the fault persists (spec §4.2)."""

    CODE: ClassVar[int] = 0x9B


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadStatus2(FixedCommand):
    """0x9C: read temperature, iq (MS: power), speed and encoder (spec §4.3)."""

    CODE: ClassVar[int] = 0x9C


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadStatus3(FixedCommand):
    """0x9D: read the phase currents ([001]: no effect on MS) (spec §4.4)."""

    CODE: ClassVar[int] = 0x9D


@dataclass(frozen=True, slots=True, kw_only=True)
class MotorOff(FixedCommand):
    """0x80: motor off; clears the turn count and the last control command; reply is an echo (spec §4.5)."""

    CODE: ClassVar[int] = 0x80


@dataclass(frozen=True, slots=True, kw_only=True)
class MotorStop(FixedCommand):
    """0x81: stop the motor without clearing its state; reply is an echo (spec §4.6)."""

    CODE: ClassVar[int] = 0x81


@dataclass(frozen=True, slots=True, kw_only=True)
class MotorRun(FixedCommand):
    """0x88: V2.36 OFF -> ON; V2.35 resume after 0x81; reply is an echo (spec §4.7)."""

    CODE: ClassVar[int] = 0x88


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadEncoder(FixedCommand):
    """0x90: read encoder position, raw position and zero offset (spec §4.20)."""

    CODE: ClassVar[int] = 0x90


@dataclass(frozen=True, slots=True, kw_only=True)
class CalibrateEncoder(FixedCommand):
    """0x18, V2.36 only: calibrate the encoder (writes ROM; replies after several seconds) (spec §4.21)."""

    CODE: ClassVar[int] = 0x18
    REVISIONS = V2_36_ONLY


@dataclass(frozen=True, slots=True, kw_only=True)
class SetZeroRom(FixedCommand):
    """0x19: current position becomes the zero after the next power cycle (writes ROM) (spec §4.22)."""

    CODE: ClassVar[int] = 0x19


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadMultiTurnAngle(FixedCommand):
    """0x92: read the multi-turn angle (spec §4.24)."""

    CODE: ClassVar[int] = 0x92


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadSingleTurnAngle(FixedCommand):
    """0x94: read the single-turn angle (reply layout differs per revision) (spec §4.25)."""

    CODE: ClassVar[int] = 0x94


@dataclass(frozen=True, slots=True, kw_only=True)
class SetZeroRam(FixedCommand):
    """0x95: current position becomes zero in RAM ([001]: then motor-stop state); echo (spec §4.26)."""

    CODE: ClassVar[int] = 0x95


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadAcceleration(FixedCommand):
    """0x33, V2.35 only: read acceleration. **Inferred layout** (spec §4.30, A18).

    [003] lists 0x33 but its section 4.4 is missing from the OCR text. We send the fixed request
    ``33 00 00 00 00 00 00 00`` every payload-free LK request has, and read the reply like the 0x34
    echo (``Accel`` int32 at DATA[4..7]) — the spec's "by symmetry" guess, not a documented layout.
    """

    CODE: ClassVar[int] = 0x33
    REVISIONS = V2_35_ONLY


@dataclass(frozen=True, slots=True, kw_only=True)
class BrakeControl(LkCommand):
    """0x8C, V2.36 only: engage or release the holding brake, or read its state (spec §4.8).

    Attributes:
        action: ENGAGE (de-energise), RELEASE (energise) or READ (no change).
    """

    CODE: ClassVar[int] = 0x8C
    REVISIONS = V2_36_ONLY
    action: BrakeAction

    def __post_init__(self) -> None:
        check_member("action", self.action, BrakeAction)

    def encode(self) -> bytes:
        return payload(self.CODE, (1, bytes([self.action])))

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        expect(data, cls.CODE, cls.__name__)
        return build(cls, data, action=enum_byte(BrakeAction, data, 1, what=cls.__name__))


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteEncoderOffset(LkCommand):
    """0x91, V2.35 only: set the encoder zero offset (spec §4.23; RAM or ROM not stated, A21).

    Attributes:
        offset_counts: encoder zero offset in counts (uint16 DATA[6..7]; within the encoder width).
        encoder_bits: the encoder width the offset must fit.
    """

    CODE: ClassVar[int] = 0x91
    REVISIONS = V2_35_ONLY
    offset_counts: int
    encoder_bits: int

    def __post_init__(self) -> None:
        check_encoder_bits(self.encoder_bits)
        check_encoder_count("offset_counts", self.offset_counts, self.encoder_bits)

    def encode(self) -> bytes:
        return payload(self.CODE, (ENCODER_OFFSET_AT, self.offset_counts.to_bytes(2, "little")))

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        expect(data, cls.CODE, cls.__name__)
        offset = int.from_bytes(data[ENCODER_OFFSET_AT : ENCODER_OFFSET_AT + 2], "little")
        return build(cls, data, offset_counts=offset, encoder_bits=model.encoder_bits)


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteAcceleration(LkCommand):
    """0x34, V2.35 only: write the acceleration limit to RAM; reply is an echo (spec §4.31).

    Attributes:
        acceleration_dps2: acceleration in degrees per second squared (int32 DATA[4..7], 1 dps/s).
    """

    CODE: ClassVar[int] = 0x34
    REVISIONS = V2_35_ONLY
    acceleration_dps2: float

    def __post_init__(self) -> None:
        ACCELERATION.check(self.acceleration_dps2)

    def encode(self) -> bytes:
        return payload(self.CODE, (4, ACCELERATION.encode(self.acceleration_dps2)))

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        expect(data, cls.CODE, cls.__name__)
        return build(cls, data, acceleration_dps2=ACCELERATION.decode(data, 4))
