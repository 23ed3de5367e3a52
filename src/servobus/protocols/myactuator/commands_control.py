"""MyActuator closed-loop control requests: torque, speed, position (0xA1..0xA9, 0x72, 0x73).

All of them answer with the "status 2" layout (``replies.StatusReply``; 0xA6 with
``replies.SingleTurnStatusReply``) and run only "when the motor has no fault" (myactuator-v4.md §0).
That reply carries the motor's temperature, current, speed and angle, so it is never the request's own
bytes (but for a motor at exactly 0 °C, at rest, asked for zeros): a reply that is those bytes is the
motor echoing the command without executing it, as it does with the first command after its 0xB3 trip
(2b-t/myactuator_rmd_ros pull request 4). Each class declares ``NEVER_ECHOED`` for that.
Units: amperes, dps, degrees of the output shaft; percentages of rated current / rated speed where the
manual gives them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._special import SpecialZero
from servobus.protocols.myactuator._layout import EnumField, MyActuatorCommand
from servobus.protocols.myactuator.enums import SpinDirection
from servobus.protocols.myactuator.replies import SingleTurnStatusReply, StatusReply
from servobus.protocols.myactuator.revision import ONLY_V4_4

__all__ = [
    "AbsolutePositionControl",
    "ForcePositionControl",
    "IncrementalPositionControl",
    "PositionSpeedFeedforward",
    "PositionTorqueFeedforward",
    "SingleTurnPositionControl",
    "SpeedControl",
    "TorqueControl",
]

_CURRENT = ScaledField("current_a", size=2, signed=True, counts_per_unit=100)  # 0.01 A/LSB
_SPEED = ScaledField("speed_dps", size=4, signed=True, counts_per_unit=100)  # 0.01 dps/LSB
# §4.21: maxSpeed 0 means no limit (pure PI output in direct tracking mode); asked for with None only,
# so 0 or 0.4 dps (rounding to 0) is refused instead of turning into "no limit" (issue 19).
_MAX_SPEED = SpecialZero(
    ScaledField("max_speed_dps", size=2, signed=False, counts_per_unit=1),  # 1 dps/LSB
    meaning="means no speed limit (§4.21)",
    unit="dps",
)
_ANGLE = ScaledField("angle_deg", size=4, signed=True, counts_per_unit=100)  # 0.01 °/LSB
# 0xA6: uint16 0.01°, stated range 0..35999, but both manuals' examples send 36000 (360° = 0°); the value
# is passed through unchanged, never reduced modulo 360 (§9 item 10). Above 360° nothing is documented.
_SINGLE_TURN_ANGLE = ScaledField("angle_deg", size=2, signed=False, counts_per_unit=100, lo=0.0, hi=360.0)
# 0xA2 §4.20: maxTorque 0 leaves force-limit mode off (the stall-current setting limits the torque).
_MAX_TORQUE = SpecialZero(
    IntField("max_torque_pct", 1),  # 1 % of rated current, 0..255
    meaning="means force-limit mode off: the stall-current setting limits the torque (§4.20)",
    unit="%",
)
# 0xA9 §4.24: maxTorque 0 is not described by the manuals: it cannot be sent.
_FORCE_MAX_TORQUE = SpecialZero(
    IntField("max_torque_pct", 1),
    meaning="is not described by the manuals (§4.24)",
    explicit=False,
    unit="%",
)
_FF_SPEED = IntField("feedforward_speed_pct", 1, signed=True)  # 1 % of rated speed, -128..127
_FF_TORQUE = IntField("feedforward_torque_pct", 1, signed=True)  # 1 % of rated current, -128..127


@dataclass(frozen=True, slots=True, kw_only=True)
class TorqueControl(MyActuatorCommand[StatusReply]):
    """0xA1 torque (q-axis current) closed loop. It cannot release a brake: send 0x77 first."""

    CODE: ClassVar[int] = 0xA1
    TITLE: ClassVar[str] = "torque closed-loop control"
    NEVER_ECHOED = True  # the reply carries temperature and measurements (module docstring)
    FIELDS = ((4, _CURRENT),)
    current_a: float


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedControl(MyActuatorCommand[StatusReply]):
    """0xA2 speed closed loop (output shaft), with the optional force-control limit of V4.3+.

    ``max_torque_pct`` (DATA[1], % of rated current) above the stall current, or ``None`` (sent as 0, the
    default), leaves force-limit mode off and the stall-current setting limits the torque (§4.20).
    ``max_torque_pct=0`` is refused: ask for "off" with ``None``.
    """

    CODE: ClassVar[int] = 0xA2
    TITLE: ClassVar[str] = "speed closed-loop control"
    NEVER_ECHOED = True  # the reply carries temperature and measurements (module docstring)
    FIELDS = ((1, _MAX_TORQUE), (4, _SPEED))
    speed_dps: float
    max_torque_pct: int | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class AbsolutePositionControl(MyActuatorCommand[StatusReply]):
    """0xA4 absolute multi-turn position. With position acceleration 0 (0x43 index 0), a PI tracks the
    target limited to ``max_speed_dps``; otherwise a trapezoidal profile peaks at it.

    ``max_speed_dps=None`` asks for no limit (maxSpeed 0 on the wire, §4.21). A number is rounded to
    1 dps half away from zero and must give at least 1: 0 and 0.4 are refused, never "no limit". The
    same holds for every position command with ``max_speed_dps`` (0xA6, 0xA8, 0xA9, 0x72, 0x73)."""

    CODE: ClassVar[int] = 0xA4
    TITLE: ClassVar[str] = "absolute position closed-loop control"
    NEVER_ECHOED = True  # the reply carries temperature and measurements (module docstring)
    FIELDS = ((2, _MAX_SPEED), (4, _ANGLE))
    angle_deg: float
    max_speed_dps: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class SingleTurnPositionControl(MyActuatorCommand[SingleTurnStatusReply]):
    """0xA6 single-turn position 0..360° in ``direction``. Reply: ``SingleTurnStatusReply`` (encoder).
    ``max_speed_dps=None`` asks for no speed limit (see :class:`AbsolutePositionControl`)."""

    POSITION = "single_turn"  # (host-side limits: servobus.limits)

    CODE: ClassVar[int] = 0xA6
    TITLE: ClassVar[str] = "single-turn position control"
    NEVER_ECHOED = True  # the reply carries temperature and measurements (module docstring)
    FIELDS = ((1, EnumField("direction", 1, SpinDirection)), (2, _MAX_SPEED), (4, _SINGLE_TURN_ANGLE))
    angle_deg: float
    max_speed_dps: float | None
    direction: SpinDirection


@dataclass(frozen=True, slots=True, kw_only=True)
class IncrementalPositionControl(MyActuatorCommand[StatusReply]):
    """0xA8 move by ``angle_deg`` from the current position (its sign gives the direction).
    ``max_speed_dps=None`` asks for no speed limit (see :class:`AbsolutePositionControl`)."""

    POSITION = "relative"  # (host-side limits: servobus.limits)

    CODE: ClassVar[int] = 0xA8
    TITLE: ClassVar[str] = "incremental position closed-loop control"
    NEVER_ECHOED = True  # the reply carries temperature and measurements (module docstring)
    FIELDS = ((2, _MAX_SPEED), (4, _ANGLE))
    angle_deg: float
    max_speed_dps: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class ForcePositionControl(MyActuatorCommand[StatusReply]):
    """0xA9 absolute position with a torque limit (% of rated current; above the stall current the stall
    current limits instead). ``max_torque_pct`` 0 is not described by the manuals, so it is refused
    (1..255). ``max_speed_dps=None`` asks for no speed limit (see :class:`AbsolutePositionControl`)."""

    CODE: ClassVar[int] = 0xA9
    TITLE: ClassVar[str] = "force-limited position closed-loop control"
    NEVER_ECHOED = True  # the reply carries temperature and measurements (module docstring)
    FIELDS = ((1, _FORCE_MAX_TORQUE), (2, _MAX_SPEED), (4, _ANGLE))
    angle_deg: float
    max_speed_dps: float | None
    max_torque_pct: int


@dataclass(frozen=True, slots=True, kw_only=True)
class PositionSpeedFeedforward(MyActuatorCommand[StatusReply]):
    """0x72 SF (V4.4 only): absolute position with speed feed-forward in % of rated speed. The
    feed-forward acts only in direct tracking mode (position acceleration 0); otherwise it is 0xA4.

    The manual's examples print command byte 0x73 (copied from TF); the section's own tables give 0x72,
    which is what this sends (§9 item 3). ``max_speed_dps=None`` asks for no speed limit (see
    :class:`AbsolutePositionControl`)."""

    CODE: ClassVar[int] = 0x72
    TITLE: ClassVar[str] = "position control with speed feed-forward"
    NEVER_ECHOED = True  # the reply carries temperature and measurements (module docstring)
    REVISIONS = ONLY_V4_4
    FIELDS = ((1, _FF_SPEED), (2, _MAX_SPEED), (4, _ANGLE))
    angle_deg: float
    max_speed_dps: float | None
    feedforward_speed_pct: int


@dataclass(frozen=True, slots=True, kw_only=True)
class PositionTorqueFeedforward(MyActuatorCommand[StatusReply]):
    """0x73 TF (V4.4 only): absolute position with torque feed-forward in % of rated current.
    ``max_speed_dps=None`` asks for no speed limit (see :class:`AbsolutePositionControl`)."""

    CODE: ClassVar[int] = 0x73
    TITLE: ClassVar[str] = "position control with torque feed-forward"
    NEVER_ECHOED = True  # the reply carries temperature and measurements (module docstring)
    REVISIONS = ONLY_V4_4
    FIELDS = ((1, _FF_TORQUE), (2, _MAX_SPEED), (4, _ANGLE))
    angle_deg: float
    max_speed_dps: float | None
    feedforward_torque_pct: int
