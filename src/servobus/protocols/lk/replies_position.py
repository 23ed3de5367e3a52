"""LK replies about encoder, zero point, angles and acceleration (spec §4.20..§4.26, §4.30, §4.31).

One class per reply layout (spec §13); where a layout differs per revision (0x94, D9) the V2.35
class has the ``V235`` suffix. Encoder counts must fit the declared ``encoder_bits``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols.lk._base import (
    V2_35_ONLY,
    V2_36_ONLY,
    CommandField,
    EncoderCountField,
    FlagByteField,
    LkReply,
)
from servobus.protocols.lk.states import AlignState

__all__ = [
    "AccelerationReply",
    "CalibrationReply",
    "EncoderOffsetReply",
    "EncoderReply",
    "MultiTurnAngleReply",
    "SingleTurnAngleReply",
    "SingleTurnAngleReplyV235",
]

# int64 sent as 7 bytes (A7). A float angle round-trips through its count (count / 100 * 100) only
# while the count stays well inside 2**53, so the range stops at ±2**48 counts (±2.8e12 degrees,
# 7.8e9 turns); a 56-bit count beyond it is a ProtocolError rather than a silently rounded angle.
MULTI_TURN = ScaledField(
    "angle_deg", size=7, signed=True, counts_per_unit=100, lo=-(2**48) / 100, hi=2**48 / 100
)
CIRCLE = ScaledField("angle_deg", size=4, signed=False, counts_per_unit=100)  # V2.36 uint32 DATA[4..7]
CIRCLE_V235 = ScaledField("angle_deg", size=2, signed=False, counts_per_unit=100)  # V2.35 uint16 DATA[6..7]
ALIGN_VALUE = IntField("align_value", size=4)
ALIGN_RATIO = IntField("align_ratio", size=2)
ACCELERATION = ScaledField("acceleration_dps2", size=4, signed=True, counts_per_unit=1)


@dataclass(frozen=True, slots=True, kw_only=True)
class EncoderReply(LkReply):
    """0x90 reply ``<BxHHH`` (spec §4.20).

    Attributes:
        encoder_bits: width each count must fit.
        encoder_counts: encoderRaw - encoderOffset.
        raw_counts: encoderRaw.
        offset_counts: encoderOffset (the motor-angle zero).
    """

    CODE: ClassVar[int] = 0x90
    MODEL = ("encoder_bits",)
    MODEL_FIELDS = (
        (2, EncoderCountField("encoder_counts")),
        (4, EncoderCountField("raw_counts")),
        (6, EncoderCountField("offset_counts")),
    )
    encoder_bits: int
    encoder_counts: int
    raw_counts: int
    offset_counts: int


@dataclass(frozen=True, slots=True, kw_only=True)
class CalibrationReply(LkReply):
    """0x18 reply ``<BIHB``, V2.36 only: encoder calibration result (spec §4.21, §7.5).

    Attributes:
        align_value: AlignValue (uint32).
        align_ratio: AlignRatio (uint16), ideally about 1000.
        align_state: SUCCESS (bit 0), PHASE_INVERTED (bit 4); other bits kept.
    """

    CODE: ClassVar[int] = 0x18
    REVISIONS = V2_36_ONLY
    FIELDS = ((1, ALIGN_VALUE), (5, ALIGN_RATIO), (7, FlagByteField("align_state", AlignState)))
    align_value: int
    align_ratio: int
    align_state: AlignState

    @property
    def succeeded(self) -> bool:
        return AlignState.SUCCESS in self.align_state

    @property
    def phase_inverted(self) -> bool:
        return AlignState.PHASE_INVERTED in self.align_state


@dataclass(frozen=True, slots=True, kw_only=True)
class EncoderOffsetReply(LkReply):
    """0x19 and 0x91 reply ``<BxxxxxH``: the new encoder zero offset (spec §4.22, §4.23).

    Attributes:
        command: 0x19 (zero to ROM, both revisions) or 0x91 (write offset, V2.35).
        encoder_bits: width the offset must fit.
        offset_counts: encoderOffset.
    """

    MODEL = ("encoder_bits",)
    MODEL_FIELDS = ((0, CommandField()), (6, EncoderCountField("offset_counts")))
    command: int
    encoder_bits: int
    offset_counts: int


@dataclass(frozen=True, slots=True, kw_only=True)
class MultiTurnAngleReply(LkReply):
    """0x92 reply: motorAngle, an int64 of which DATA[1..7] carry the low 7 bytes (spec §4.24, A7).

    Attributes:
        angle_deg: cumulative angle, 0.01 °/LSB; positive clockwise (56-bit two's complement).
    """

    CODE: ClassVar[int] = 0x92
    FIELDS = ((1, MULTI_TURN),)
    angle_deg: float


@dataclass(frozen=True, slots=True, kw_only=True)
class SingleTurnAngleReply(LkReply):
    """0x94 reply, V2.36 layout ``<BxxxI``: circleAngle uint32 in DATA[4..7] (spec §4.25, D9).

    Attributes:
        angle_deg: single-turn angle from the encoder zero, 0.01 °/LSB, 0..36000*ratio-1 counts.
    """

    CODE: ClassVar[int] = 0x94
    SINGLE_TURN: ClassVar[bool] = True  # (not the motor's position: servobus.limits)
    REVISIONS = V2_36_ONLY
    FIELDS = ((4, CIRCLE),)
    angle_deg: float


@dataclass(frozen=True, slots=True, kw_only=True)
class SingleTurnAngleReplyV235(LkReply):
    """0x94 reply, V2.35 layout ``<BxxxxxH``: circleAngle uint16 in DATA[6..7], one motor turn
    (spec §4.25, D9)."""

    CODE: ClassVar[int] = 0x94
    SINGLE_TURN: ClassVar[bool] = True  # (not the motor's position: servobus.limits)
    REVISIONS = V2_35_ONLY
    FIELDS = ((6, CIRCLE_V235),)
    angle_deg: float


@dataclass(frozen=True, slots=True, kw_only=True)
class AccelerationReply(LkReply):
    """0x34 echo and 0x33 reply ``<Bxxxi``, V2.35 only (spec §4.31; 0x33 layout inferred, §4.30).

    Attributes:
        command: 0x33 (read) or 0x34 (write, echo).
        acceleration_dps2: acceleration, 1 dps/s per LSB.
    """

    REVISIONS = V2_35_ONLY
    FIELDS = ((4, ACCELERATION),)
    MODEL_FIELDS = ((0, CommandField()),)
    command: int
    acceleration_dps2: float
