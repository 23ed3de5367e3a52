"""LK requests that read state or change the motor's mode, zero, brake or acceleration (no set-points).

Set-point commands (0xA0..0xA8, 0x280) are in :mod:`~servobus.protocols.lk.commands_control`,
parameter commands (0x40/0x42/0x44, 0xC0/0xC1) in :mod:`~servobus.protocols.lk.params`.
Spec sections are cited per class; [001] = V2.36 manual, [003] = V2.35 manual. Each class states its
reply (the type argument), whether it only reads (``READ``), writes ROM or moves the brake
(``SLOW``), and the revisions that have it; everything else is derived from that.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import ClassVar

from servobus.protocols._fields import ScaledField
from servobus.protocols.lk._base import (
    V2_35_ONLY,
    V2_36_ONLY,
    EncoderCountField,
    LkCommand,
    MemberField,
)
from servobus.protocols.lk.model import Revision
from servobus.protocols.lk.replies import (
    BrakeReply,
    EchoReply,
    Status1Reply,
    Status1ReplyV235,
    Status2Reply,
    Status3Reply,
    Status3ReplyV235,
)
from servobus.protocols.lk.replies_position import (
    AccelerationReply,
    CalibrationReply,
    EncoderOffsetReply,
    EncoderReply,
    MultiTurnAngleReply,
    SingleTurnAngleReply,
    SingleTurnAngleReplyV235,
)
from servobus.protocols.lk.states import BrakeAction

__all__ = [
    "BrakeControl",
    "CalibrateEncoder",
    "ClearErrors",
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
#: [001] §21: 0x18 turns the motor "for several seconds" before it replies.
CALIBRATION_TIMEOUT_S = 10.0


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadStatus1(LkCommand[Status1Reply | Status1ReplyV235]):
    """0x9A: read temperature, voltage (V2.36: bus current, motor state) and error flags (spec §4.1)."""

    CODE: ClassVar[int] = 0x9A
    READ = True


@dataclass(frozen=True, slots=True, kw_only=True)
class ClearErrors(LkCommand[Status1Reply | Status1ReplyV235]):
    """0x9B: clear the error flags; they stay set while the fault persists (spec §4.2).

    The reply is the status-1 layout; [003] prints its DATA[0] as 0x9A (A4), which V2.35 accepts.
    """

    CODE: ClassVar[int] = 0x9B
    REPLY_ALIASES = MappingProxyType({Revision.V2_35: 0x9A})


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadStatus2(LkCommand[Status2Reply]):
    """0x9C: read temperature, iq (MS: power), speed and encoder (spec §4.3)."""

    CODE: ClassVar[int] = 0x9C
    READ = True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadStatus3(LkCommand[Status3Reply | Status3ReplyV235]):
    """0x9D: read the phase currents ([001]: no effect on MS) (spec §4.4)."""

    CODE: ClassVar[int] = 0x9D
    READ = True


@dataclass(frozen=True, slots=True, kw_only=True)
class MotorOff(LkCommand[EchoReply]):
    """0x80: motor off; clears the turn count and the last control command; reply is an echo (spec §4.5).

    [001]: control commands sent while OFF are answered but not executed until 0x88.
    """

    CODE: ClassVar[int] = 0x80


@dataclass(frozen=True, slots=True, kw_only=True)
class MotorStop(LkCommand[EchoReply]):
    """0x81: stop the motor without clearing its state; reply is an echo (spec §4.6)."""

    CODE: ClassVar[int] = 0x81


@dataclass(frozen=True, slots=True, kw_only=True)
class MotorRun(LkCommand[EchoReply]):
    """0x88: V2.36 OFF -> ON; V2.35 resume after 0x81; reply is an echo (spec §4.7, D15).

    The revisions differ in what it resumes: [001] only leaves OFF, [003] restarts the control
    command that 0x81 stopped.
    """

    CODE: ClassVar[int] = 0x88


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadEncoder(LkCommand[EncoderReply]):
    """0x90: read encoder position, raw position and zero offset (spec §4.20)."""

    CODE: ClassVar[int] = 0x90
    READ = True


@dataclass(frozen=True, slots=True, kw_only=True)
class CalibrateEncoder(LkCommand[CalibrationReply]):
    """0x18, V2.36 only: calibrate the encoder (writes ROM; replies after several seconds) (spec §4.21)."""

    CODE: ClassVar[int] = 0x18
    REVISIONS = V2_36_ONLY
    SLOW = True
    TIMEOUT_S = CALIBRATION_TIMEOUT_S


@dataclass(frozen=True, slots=True, kw_only=True)
class SetZeroRom(LkCommand[EncoderOffsetReply]):
    """0x19: current position becomes the zero after the next power cycle (writes ROM) (spec §4.22).

    The reply carries the new offset; it takes effect only after a power cycle.
    """

    CODE: ClassVar[int] = 0x19
    SLOW = True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadMultiTurnAngle(LkCommand[MultiTurnAngleReply]):
    """0x92: read the multi-turn angle (spec §4.24)."""

    CODE: ClassVar[int] = 0x92
    READ = True


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadSingleTurnAngle(LkCommand[SingleTurnAngleReply | SingleTurnAngleReplyV235]):
    """0x94: read the single-turn angle (the reply layout differs per revision, D9) (spec §4.25)."""

    CODE: ClassVar[int] = 0x94
    READ = True


@dataclass(frozen=True, slots=True, kw_only=True)
class SetZeroRam(LkCommand[EchoReply]):
    """0x95: current position becomes zero in RAM ([001]: then motor-stop state); echo (spec §4.26)."""

    CODE: ClassVar[int] = 0x95


@dataclass(frozen=True, slots=True, kw_only=True)
class ReadAcceleration(LkCommand[AccelerationReply]):
    """0x33, V2.35 only: read acceleration. **Inferred layout** (spec §4.30, A18).

    [003] lists 0x33 but its section 4.4 is missing from the OCR text. We send the fixed request
    ``33 00 00 00 00 00 00 00`` every payload-free LK request has, and read the reply like the 0x34
    echo (``Accel`` int32 at DATA[4..7]) — the spec's "by symmetry" guess, not a documented layout.
    """

    CODE: ClassVar[int] = 0x33
    REVISIONS = V2_35_ONLY
    READ = True
    INFERRED = "V2.35 lists 0x33 but its section is missing (spec §4.30, A18): fixed request, reply as 0x34"


@dataclass(frozen=True, slots=True, kw_only=True)
class BrakeControl(LkCommand[BrakeReply]):
    """0x8C, V2.36 only: engage or release the holding brake, or read its state (spec §4.8).

    Attributes:
        action: ENGAGE (de-energise), RELEASE (energise) or READ (no change).
    """

    CODE: ClassVar[int] = 0x8C
    REVISIONS = V2_36_ONLY
    SLOW = True
    FIELDS = ((1, MemberField("action", BrakeAction)),)
    action: BrakeAction


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteEncoderOffset(LkCommand[EncoderOffsetReply]):
    """0x91, V2.35 only: set the encoder zero offset (spec §4.23; RAM or ROM not stated, A21).

    Attributes:
        offset_counts: encoder zero offset in counts (uint16 DATA[6..7]; within the encoder width).
        encoder_bits: the encoder width the offset must fit.
    """

    CODE: ClassVar[int] = 0x91
    REVISIONS = V2_35_ONLY
    SLOW = True
    MODEL = ("encoder_bits",)
    MODEL_FIELDS = ((ENCODER_OFFSET_AT, EncoderCountField("offset_counts")),)
    offset_counts: int
    encoder_bits: int


@dataclass(frozen=True, slots=True, kw_only=True)
class WriteAcceleration(LkCommand[AccelerationReply]):
    """0x34, V2.35 only: write the acceleration limit to RAM; reply is an echo (spec §4.31).

    Attributes:
        acceleration_dps2: acceleration in degrees per second squared (int32 DATA[4..7], 1 dps/s).
    """

    CODE: ClassVar[int] = 0x34
    REVISIONS = V2_35_ONLY
    ECHO = True
    FIELDS = ((4, ACCELERATION),)
    acceleration_dps2: float
