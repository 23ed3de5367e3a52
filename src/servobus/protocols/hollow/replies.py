"""Replies of the hollow series (hollow.md §4.5, §5.3, §7.3): one class per reply layout.

All replies go to the host id and carry the sender's motor id (D0 in classic CAN, the Slave ID byte
D15 in CAN FD). The classic layout's length tells the CAN mode: 6 bytes in normal mode, 8 in
extended mode (§3, §5.1). Reported values are measurements, whatever the control mode (§4.4).

Each layout is declared once (:class:`~servobus.protocols.hollow._packed.Packed`: the packer, the
size and the fields with their limits); the codec's table of replies is derived from these classes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Self, TypeAlias

from servobus.protocols._fields import round_half_away
from servobus.protocols._message import Reply
from servobus.protocols.bits import BitField, Bits, Choice, Code, Flag, OffsetBinary, Signed
from servobus.protocols.hollow._packed import Packed
from servobus.protocols.hollow.enums import ControlMode
from servobus.protocols.hollow.ids import MOTOR_IDS
from servobus.protocols.hollow.model import COUNTS_PER_TURN, DEFAULT_MODEL, HollowModel

__all__ = [
    "EXTENDED_POSITION_LIMITS_DEG",
    "FD_PAYLOAD_SIZE",
    "FD_TEMPERATURE_LIMITS_C",
    "ClassicReply",
    "ExtendedReply",
    "FdReply",
    "HollowReply",
    "NormalReply",
    "classic_fields",
    "fd_motion_fields",
    "reply_classes",
]

FD_PAYLOAD_SIZE = 16
_MOTOR_ID = Code("motor_id", (0, 8), MOTOR_IDS.start, MOTOR_IDS.stop - 1)
# §5.3: X is int32 counts, 20-bit single turn, so -2048 .. +2048 turns minus one count (A10).
EXTENDED_POSITION_LIMITS_DEG = (
    -(1 << 31) * 360.0 / COUNTS_PER_TURN,
    ((1 << 31) - 1) * 360.0 / COUNTS_PER_TURN,
)
# Manual §VII (CAN FD reply): "Temperature -125-125 degrees" (spec §7.3, A39): carried as int8, but a
# value outside -125..125 is outside what the motor reports, so it does not decode.
FD_TEMPERATURE_LIMITS_C = (-125, 125)


def classic_fields(position: str, at: tuple[Bits, Bits, Bits]) -> tuple[BitField, BitField, BitField]:
    """(``position`` or step, speed, current) at the bits ``at``: offset binary within ±Pmax turns,
    ±ω_fs and ±I_fs of the model (§4.3)."""
    p, v, t = at
    return (
        OffsetBinary(position, p, lambda m: m.position_full_scale_deg),
        OffsetBinary("speed_rad_s", v, lambda m: m.speed_full_scale_rad_s),
        OffsetBinary("current_a", t, lambda m: m.current_full_scale_a),
    )


# §4.5: D0 the motor id, then position 16, speed 12, current 12 bits (the setpoint's order).
_POSITION, _SPEED, _CURRENT = classic_fields("position_deg", ((8, 16), (24, 12), (36, 12)))


def fd_motion_fields(mode_label: str) -> tuple[BitField, BitField, BitField, BitField]:
    """Pos, Vel, Cur and the mode byte (``mode_label``: its name in the manual): the first 12 bytes
    of the CAN FD request and reply, big-endian (§7.2, §7.3)."""
    return (
        Signed("position_deg", (0, 40), COUNTS_PER_TURN, span=360.0),
        Signed("velocity_rpm", (40, 32), lambda m: m.fd_velocity_counts_per_rpm),
        Code("current_raw", (72, 16), -(1 << 15), (1 << 15) - 1),  # int16, unit not stated (A27)
        Choice("mode", (88, 8), ControlMode, mode_label),
    )


class HollowReply(Reply):
    """A motor -> host CAN or CAN FD reply of the hollow family, with the frame kind it travels in.

    ``FD`` and ``SIZE`` tell the layouts apart (§3): the codec's table of replies is derived from them.
    """

    __slots__ = ()
    FD: ClassVar[bool] = False
    SIZE: ClassVar[int]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "__dataclass_fields__" in cls.__dict__:  # the finished (slotted) dataclass, once
            _REPLIES.append(cls)

    @classmethod
    def decode(cls, data: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode the payload with ``model``'s scales."""
        raise NotImplementedError(cls.__name__)


_REPLIES: list[type[HollowReply]] = []


def reply_classes() -> tuple[type[HollowReply], ...]:
    """Every CAN / CAN FD reply layout, in definition order."""
    return tuple(_REPLIES)


@dataclass(frozen=True, slots=True, kw_only=True)
class NormalReply(Packed, HollowReply):
    """The 6-byte normal-mode reply (§4.5): motor id, absolute position, speed, current.

    Scaled as the setpoint (§4.3). Outside ±Pmax turns the position code sticks at 0x0000/0xFFFF
    (A34): :attr:`position_saturated` tells.

    Attributes:
        motor_id: the sender's CAN id (D0), 0..100.
        position_deg: position from the mechanical zero, within ±360·Pmax.
        speed_rad_s: measured speed, within ±ω_fs.
        current_a: measured current, within ±I_fs.
        model: the scaling of the motor.
    """

    PACKER: ClassVar[str] = "normal_reply"
    SIZE: ClassVar[int] = 6
    WHAT: ClassVar[str] = "normal-mode reply"
    FIELDS = (_MOTOR_ID, _POSITION, _SPEED, _CURRENT)
    motor_id: int
    position_deg: float
    speed_rad_s: float
    current_a: float
    model: HollowModel = field(default=DEFAULT_MODEL, repr=False)

    @property
    def position_saturated(self) -> bool:
        """True when the position is at (or beyond) ±Pmax: the code is 0x0000 or 0xFFFF (A34)."""
        return self.encode()[1:3] in (b"\x00\x00", b"\xff\xff")  # the code, as the packer rounds it


@dataclass(frozen=True, slots=True, kw_only=True)
class ExtendedReply(Packed, HollowReply):
    """The 8-byte extended-mode reply (§5.3): motor id, 32-bit multi-turn position, speed, current.

    The position is signed, 1,048,576 counts per turn, without offset (D1-D2 low half, D6-D7 high
    half); speed and current are coded as in normal mode.

    Attributes:
        motor_id: the sender's CAN id (D0), 0..100.
        position_deg: multi-turn position, within ±2048 turns (A10).
        speed_rad_s: measured speed, within ±ω_fs.
        current_a: measured current, within ±I_fs.
        model: the scaling of the motor.
    """

    PACKER: ClassVar[str] = "extended_reply"
    SIZE: ClassVar[int] = 8
    WHAT: ClassVar[str] = "extended-mode reply"
    FIELDS = (
        _MOTOR_ID,
        # §5.3: X is int32 counts, D1-D2 its low half and D6-D7 its high half
        Signed("position_deg", ((48, 16), (8, 16)), COUNTS_PER_TURN, span=360.0),
        _SPEED,
        _CURRENT,
    )
    motor_id: int
    position_deg: float
    speed_rad_s: float
    current_a: float
    model: HollowModel = field(default=DEFAULT_MODEL, repr=False)

    @property
    def position_counts(self) -> int:
        """X, the position in counts (1,048,576 per turn)."""
        return round_half_away(self.position_deg * COUNTS_PER_TURN / 360.0)


ClassicReply: TypeAlias = NormalReply | ExtendedReply
"""What a classic-CAN request gets: the layout of the motor's CAN mode (6 bytes normal, 8 extended)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class FdReply(Packed, HollowReply):
    """The 16-byte CAN FD reply (§7.3), also the payload of transparent and Modbus replies (§9).

    Attributes:
        position_deg: Pos, 40-bit signed counts (1,048,576 per turn), in degrees.
        velocity_rpm: Vel, int32 electrical frequency scaled to shaft rpm by the model's pole
            pairs (§7.4).
        current_raw: Cur, int16, unit not stated (A27).
        mode: the active control mode.
        running: Run Status, True when started.
        reserved: D13, "not yet available", 0 in every example; kept as received so the frame
            re-encodes unchanged, never interpreted.
        temperature_c: °C, -125..125 as the manual states (int8 on the wire; -128..-126 and 126..127
            are a ProtocolError).
        slave_id: D15, the sending motor's id, 0..100 (the hollow encoder answers with 0, §12).
        model: scaling (pole pairs) of the motor.
    """

    FD: ClassVar[bool] = True
    PACKER: ClassVar[str] = "fd_reply"
    SIZE: ClassVar[int] = FD_PAYLOAD_SIZE
    WHAT: ClassVar[str] = "CAN FD reply"
    FIELDS = (
        *fd_motion_fields("Mode"),
        Flag("running", (96, 8)),
        Code("reserved", (104, 8), 0, 0xFF),
        Code("temperature_c", (112, 8), *FD_TEMPERATURE_LIMITS_C),
        Code("slave_id", (120, 8), MOTOR_IDS.start, MOTOR_IDS.stop - 1),
    )
    position_deg: float = 0.0
    velocity_rpm: float = 0.0
    current_raw: int = 0
    mode: ControlMode = ControlMode.TORQUE
    running: bool = False
    reserved: int = 0
    temperature_c: int = 0
    slave_id: int
    model: HollowModel = field(default=DEFAULT_MODEL, repr=False)

    @property
    def position_counts(self) -> int:
        """Pos in counts (1,048,576 per turn)."""
        return round_half_away(self.position_deg * COUNTS_PER_TURN / 360.0)

    @property
    def electrical_hz(self) -> float:
        """Vel as the manual's electrical frequency (§7.4)."""
        return self.velocity_rpm * self.model.pole_pairs / 60.0
