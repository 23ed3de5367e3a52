"""LK set-point requests: open loop 0xA0, torque 0xA1, speed 0xA2, position 0xA3..0xA8, 0x280 multi-motor.

Every reply to these is the status-2 shape (:class:`~servobus.protocols.lk.replies.Status2Reply`, spec
§8.1): each class is ``LkCommand[Status2Reply]``. Where the request layout differs between revisions
(0xA2, 0xA5, 0xA6; spec §9 D7, D8) there is one class per layout; the V2.35 one has the ``V235`` suffix.

Torque current: spec §8.2. A command that carries iq also carries ``motor_type``, so ``encode()`` is
self-contained: MF/MG give amperes (``current_a``), MH gives raw counts (``iq_counts``; its scale is
not stated, A23). Angles are 0.01 °/LSB, speeds 0.01 dps/LSB (0xA2) or 1 dps/LSB (maxSpeed).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import ClassVar

from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._special import SpecialZero
from servobus.protocols.lk._base import (
    V2_35_ONLY,
    V2_36_ONLY,
    IqField,
    IqSlot,
    LkCommand,
    MemberField,
)
from servobus.protocols.lk.model import MotorType, Revision
from servobus.protocols.lk.replies import Status2Reply
from servobus.protocols.lk.states import SpinDirection

__all__ = [
    "MULTI_MOTOR_SLOTS",
    "IncrementalPosition",
    "IncrementalPositionSpeed",
    "MultiMotorTorque",
    "MultiTurnPosition",
    "MultiTurnPositionSpeed",
    "OpenLoopControl",
    "SingleTurnPosition",
    "SingleTurnPositionSpeed",
    "SingleTurnPositionSpeedV235",
    "SingleTurnPositionV235",
    "SpeedControl",
    "SpeedControlV235",
    "TorqueControl",
]

# Spec §4.9: powerControl -850..850, unitless.
POWER = IntField("power_counts", size=2, signed=True, lo=-850, hi=850)
# Spec §4.10 / §8.2: iqControl -2048..2048.
TORQUE = IqSlot("current_a", {MotorType.MH: "iq_counts"}, max_counts=2048)
# Spec §4.11 [001]: the 0xA2 torque limit has 0xA1's scale; MS has no iq scale either, so raw counts.
TORQUE_LIMIT = IqSlot(
    "current_limit_a", {MotorType.MH: "iq_limit_counts", MotorType.MS: "iq_limit_counts"}, max_counts=2048
)
SPEED = ScaledField("speed_dps", size=4, signed=True, counts_per_unit=100)
ANGLE = ScaledField("angle_deg", size=4, signed=True, counts_per_unit=100)
INCREMENT = ScaledField("increment_deg", size=4, signed=True, counts_per_unit=100)
# Spec §4.13/§4.15/§4.17 and A2/A6: maxSpeed uint16, 1 dps/LSB (the text, not [003]'s example label).
# maxSpeed 0 is not defined by the LK manuals (MyActuator's V4 manual, of the same firmware line, reads it
# as "no limit"): it is sent only when asked for with None, never for 0 or 0.4 dps (issue 19).
MAX_SPEED = SpecialZero(
    ScaledField("max_speed_dps", size=2, signed=False, counts_per_unit=1),
    meaning="is not defined by the LK manuals (MyActuator V4 reads it as no speed limit) (§4.13)",
    unit="dps",
)
# Spec §4.14 D8: single-turn target uint32 on V2.36 (range not stated), uint16 0..35999 on V2.35.
SINGLE_TURN = ScaledField("angle_deg", size=4, signed=False, counts_per_unit=100)
SINGLE_TURN_V235 = ScaledField("angle_deg", size=2, signed=False, counts_per_unit=100, lo=0, hi=35999 / 100)
# Spec §5: 0x280 iqControl -2000..2000 per motor, motors 1..4 in DATA[0..7].
MULTI_MOTOR_SLOTS = 4
MULTI_TORQUE = IqSlot("currents_a", {MotorType.MH: "iq_counts"}, max_counts=2000)


# The field kinds of the classes below, by what they carry.
_TORQUE = IqField(TORQUE)
# Spec §4.11: neither manual says what a limit of 0 does, so none is sent (or decoded).
_TORQUE_LIMIT = IqField(
    TORQUE_LIMIT,
    zero="iqControl 0, which is not defined by the manuals (§4.11): it cannot be sent; "
    "give a limit of at least one count",
)
_DIRECTION = MemberField("direction", SpinDirection)


@dataclass(frozen=True, slots=True, kw_only=True)
class OpenLoopControl(LkCommand[Status2Reply]):
    """0xA0: open-loop output ([001]: MS only, open-loop voltage; [003]: "torque open loop") (spec §4.9).

    Attributes:
        power_counts: powerControl, -850..850, unitless (int16 DATA[4..5]); not limited by Max Power.
    """

    CODE: ClassVar[int] = 0xA0
    MOTOR_TYPES = MappingProxyType({Revision.V2_36: frozenset({MotorType.MS})})
    FIELDS = ((4, POWER),)
    power_counts: int


@dataclass(frozen=True, slots=True, kw_only=True)
class TorqueControl(LkCommand[Status2Reply]):
    """0xA1: torque (iq) closed loop; not limited by Max Torque Current (spec §4.10).

    Attributes:
        motor_type: MF or MG (``current_a``) or MH (``iq_counts``); MS has no torque loop.
        current_a: torque current in A, ±2048 counts (MF ±16.5 A, MG ±33 A).
        iq_counts: MH only: iqControl as raw counts, -2048..2048.
    """

    CODE: ClassVar[int] = 0xA1
    MOTOR_TYPES = MappingProxyType(
        {r: frozenset({MotorType.MF, MotorType.MH, MotorType.MG}) for r in Revision}
    )
    MODEL = ("motor_type",)
    MODEL_FIELDS = ((4, _TORQUE),)
    motor_type: MotorType
    current_a: float | None = None
    iq_counts: int | None = None

    @property
    def counts(self) -> int:
        """iqControl as sent."""
        return _TORQUE.counts(self)[0]


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedControl(LkCommand[Status2Reply]):
    """0xA2, V2.36 layout: speed closed loop with a torque-current limit (spec §4.11, D7).

    Attributes:
        speed_dps: target speed (int32 DATA[4..7], 0.01 dps/LSB); limited by Max Speed.
        motor_type: MF/MG give ``current_limit_a``; MH/MS give ``iq_limit_counts``.
        current_limit_a: torque-current limit in A (int16 DATA[2..3], ±2048 counts, 0xA1's scale);
            one that encodes to 0 counts is refused (not defined by the manuals, §4.11).
        iq_limit_counts: MH/MS only: the limit as raw counts, -2048..2048.
    """

    CODE: ClassVar[int] = 0xA2
    REVISIONS = V2_36_ONLY
    MODEL = ("motor_type",)
    FIELDS = ((4, SPEED),)
    MODEL_FIELDS = ((2, _TORQUE_LIMIT),)
    speed_dps: float
    motor_type: MotorType
    current_limit_a: float | None = None
    iq_limit_counts: int | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedControlV235(LkCommand[Status2Reply]):
    """0xA2, V2.35 layout: speed closed loop, DATA[1..3] NULL (spec §4.11, D7).

    Sent to a V2.36 drive these bytes would mean a torque limit of 0 (spec §4.11 hazard), which is
    why the two layouts are two classes.

    Attributes:
        speed_dps: target speed (int32 DATA[4..7], 0.01 dps/LSB).
    """

    CODE: ClassVar[int] = 0xA2
    REVISIONS = V2_35_ONLY
    FIELDS = ((4, SPEED),)
    speed_dps: float


@dataclass(frozen=True, slots=True, kw_only=True)
class MultiTurnPosition(LkCommand[Status2Reply]):
    """0xA3: multi-turn absolute position (spec §4.12).

    Attributes:
        angle_deg: target (int32 DATA[4..7], 0.01 °/LSB); direction = sign of target - current.
    """

    CODE: ClassVar[int] = 0xA3
    FIELDS = ((4, ANGLE),)
    angle_deg: float


@dataclass(frozen=True, slots=True, kw_only=True)
class MultiTurnPositionSpeed(LkCommand[Status2Reply]):
    """0xA4: multi-turn absolute position with a speed limit (spec §4.13).

    Attributes:
        angle_deg: target (int32 DATA[4..7], 0.01 °/LSB).
        max_speed_dps: speed limit (uint16 DATA[2..3], 1 dps/LSB), rounded half away from zero; it
            must give at least 1. ``None`` sends 0, which the LK manuals do not define.
    """

    CODE: ClassVar[int] = 0xA4
    FIELDS = ((2, MAX_SPEED), (4, ANGLE))
    angle_deg: float
    max_speed_dps: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class SingleTurnPosition(LkCommand[Status2Reply]):
    """0xA5, V2.36 layout: single-turn position, angle uint32 DATA[4..7] (spec §4.14, D8).

    Attributes:
        angle_deg: target, 0.01 °/LSB, 0..42949672.95 (uint32; the manual states no range).
        direction: CLOCKWISE or COUNTER_CLOCKWISE (DATA[1]).
    """

    POSITION = "single_turn"  # (host-side limits: servobus.limits)

    CODE: ClassVar[int] = 0xA5
    REVISIONS = V2_36_ONLY
    FIELDS = ((1, _DIRECTION), (4, SINGLE_TURN))
    angle_deg: float
    direction: SpinDirection


@dataclass(frozen=True, slots=True, kw_only=True)
class SingleTurnPositionV235(SingleTurnPosition):
    """0xA5, V2.35 layout: angle uint16 DATA[4..5], 0..359.99° (spec §4.14, D8)."""

    REVISIONS = V2_35_ONLY
    FIELDS = ((1, _DIRECTION), (4, SINGLE_TURN_V235))


@dataclass(frozen=True, slots=True, kw_only=True)
class SingleTurnPositionSpeed(LkCommand[Status2Reply]):
    """0xA6, V2.36 layout: single-turn position with speed limit, angle uint32 (spec §4.15, D8).

    Attributes:
        angle_deg: target, 0.01 °/LSB (uint32 DATA[4..7]).
        direction: CLOCKWISE or COUNTER_CLOCKWISE (DATA[1]).
        max_speed_dps: speed limit (uint16 DATA[2..3], 1 dps/LSB), rounded half away from zero; it
            must give at least 1. ``None`` sends 0, which the LK manuals do not define.
    """

    POSITION = "single_turn"  # (host-side limits: servobus.limits)

    CODE: ClassVar[int] = 0xA6
    REVISIONS = V2_36_ONLY
    FIELDS = ((1, _DIRECTION), (2, MAX_SPEED), (4, SINGLE_TURN))
    angle_deg: float
    direction: SpinDirection
    max_speed_dps: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class SingleTurnPositionSpeedV235(SingleTurnPositionSpeed):
    """0xA6, V2.35 layout: angle uint16 DATA[4..5], 0..359.99°, DATA[6..7] NULL (spec §4.15, D8)."""

    REVISIONS = V2_35_ONLY
    FIELDS = ((1, _DIRECTION), (2, MAX_SPEED), (4, SINGLE_TURN_V235))


@dataclass(frozen=True, slots=True, kw_only=True)
class IncrementalPosition(LkCommand[Status2Reply]):
    """0xA7: move by an increment from the current position (spec §4.16).

    Attributes:
        increment_deg: angleIncrement (int32 DATA[4..7], 0.01 °/LSB); the sign is the direction.
    """

    POSITION = "relative"  # (host-side limits: servobus.limits)

    CODE: ClassVar[int] = 0xA7
    FIELDS = ((4, INCREMENT),)
    increment_deg: float


@dataclass(frozen=True, slots=True, kw_only=True)
class IncrementalPositionSpeed(LkCommand[Status2Reply]):
    """0xA8: incremental move with a speed limit (spec §4.17; worked examples W5, W6).

    ``max_speed_dps`` follows both manuals' text, 1 dps/LSB (spec A2, A6): [003]'s example labels
    the same bytes 0.01 dps/LSB ("36 dps = 3600"); see the vector tests for both readings.

    Attributes:
        increment_deg: angleIncrement (int32 DATA[4..7], 0.01 °/LSB); the sign is the direction.
        max_speed_dps: speed limit (uint16 DATA[2..3], 1 dps/LSB), rounded half away from zero; it
            must give at least 1. ``None`` sends 0, which the LK manuals do not define.
    """

    POSITION = "relative"  # (host-side limits: servobus.limits)

    CODE: ClassVar[int] = 0xA8
    FIELDS = ((2, MAX_SPEED), (4, INCREMENT))
    increment_deg: float
    max_speed_dps: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class MultiMotorTorque(LkCommand[Status2Reply]):
    """Identifier 0x280, V2.35 only: torque set-points for motors 1..4 in one frame (spec §5).

    The byte table is missing from the OCR text (A17); the layout is the spec's inference: four
    int16 LE iqControl values, motor 1 in DATA[0..1] .. motor 4 in DATA[6..7], no command byte.
    Range -2000..2000 counts ("-32A~32A": MG's 66/4096 A/LSB gives ±32.2 A). Each motor replies on
    0x140+ID with a 0xA1 status-2 reply, in ascending ID order. All four motors share ``motor_type``.

    Attributes:
        motor_type: MF/MG give ``currents_a``; MH gives ``iq_counts``.
        currents_a: torque currents in A for motors 1..4 (0 for a motor that should not move).
        iq_counts: MH only: iqControl raw counts for motors 1..4.
    """

    CODE: ClassVar[int | None] = None
    HAS_CODE = False
    REVISIONS = V2_35_ONLY
    INFERRED = "0x280 byte table missing (spec §5, A17): 4 x int16 LE, motors 1..4"
    MODEL = ("motor_type",)
    MODEL_FIELDS = (
        (0, IqField(MULTI_TORQUE, "motor", tuple(str(m) for m in range(1, MULTI_MOTOR_SLOTS + 1)))),
    )
    motor_type: MotorType
    currents_a: tuple[float, float, float, float] | None = None
    iq_counts: tuple[int, int, int, int] | None = None
