"""Replies of the hollow series (hollow.md §4.5, §5.3, §7.3): one class per reply layout.

All replies go to the host id and carry the sender's motor id (D0 in classic CAN, the Slave ID byte
D15 in CAN FD). The classic layout's length tells the CAN mode: 6 bytes in normal mode, 8 in
extended mode (§3, §5.1). Reported values are measurements, whatever the control mode (§4.4).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Self

from servobus.protocols._fields import round_half_away
from servobus.protocols._message import Reply
from servobus.protocols.hollow._checks import (
    build,
    check_flag,
    check_int,
    check_real,
    decode_enum,
    require_size,
    to_enum,
)
from servobus.protocols.hollow.commands import ControlMode, check_model
from servobus.protocols.hollow.commands_fd import FD_PAYLOAD_SIZE, check_fd_motion
from servobus.protocols.hollow.ids import MOTOR_IDS
from servobus.protocols.hollow.model import COUNTS_PER_TURN, DEFAULT_MODEL, HollowModel, packers

__all__ = [
    "EXTENDED_POSITION_LIMITS_DEG",
    "ExtendedReply",
    "FdReply",
    "HollowReply",
    "NormalReply",
]

_MOTOR_ID_LIMITS = (MOTOR_IDS.start, MOTOR_IDS.stop - 1)
# §5.3: X is int32 counts, 20-bit single turn, so -2048 .. +2048 turns minus one count (A10).
EXTENDED_POSITION_LIMITS_DEG = (
    -(1 << 31) * 360.0 / COUNTS_PER_TURN,
    ((1 << 31) - 1) * 360.0 / COUNTS_PER_TURN,
)
# Manual §VII (CAN FD reply): "Temperature -125-125 degrees" (spec §7.3, A39): carried as int8, but a
# value outside -125..125 is outside what the motor reports, so it does not decode.
_TEMPERATURE_LIMITS = (-125, 125)


class HollowReply(Reply):
    """A motor -> host CAN or CAN FD reply of the hollow family, with the frame kind it travels in."""

    __slots__ = ()
    FD: ClassVar[bool] = False


def _check_classic(model: HollowModel, motor_id: object, speed: object, current: object) -> None:
    check_model(model)
    check_int("motor_id", motor_id, *_MOTOR_ID_LIMITS)
    check_real("speed_rad_s", speed, -model.speed_full_scale_rad_s, model.speed_full_scale_rad_s)
    check_real("current_a", current, -model.current_full_scale_a, model.current_full_scale_a)


@dataclass(frozen=True, slots=True, kw_only=True)
class NormalReply(HollowReply):
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

    motor_id: int
    position_deg: float
    speed_rad_s: float
    current_a: float
    model: HollowModel = field(default=DEFAULT_MODEL, repr=False)

    def __post_init__(self) -> None:
        _check_classic(self.model, self.motor_id, self.speed_rad_s, self.current_a)
        full = self.model.position_full_scale_deg
        check_real("position_deg", self.position_deg, -full, full)

    @property
    def position_saturated(self) -> bool:
        """True when the position is at (or beyond) ±Pmax: the code is 0x0000 or 0xFFFF (A34)."""
        return self.encode()[1:3] in (b"\x00\x00", b"\xff\xff")  # the code, as the packer rounds it

    def encode(self) -> bytes:
        return packers(self.model).normal_reply.pack(
            [self.motor_id, self.position_deg, self.speed_rad_s, self.current_a]
        )

    @classmethod
    def decode(cls, data: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode a 6-byte normal-mode reply.

        Raises:
            ProtocolError: wrong length, or a motor id outside 0..100.
        """
        require_size(data, 6, what="normal-mode reply")
        motor_id, position, speed, current = packers(model).normal_reply.unpack(data)
        return build(
            cls,
            data,
            motor_id=int(motor_id),
            position_deg=position,
            speed_rad_s=speed,
            current_a=current,
            model=model,
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class ExtendedReply(HollowReply):
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

    motor_id: int
    position_deg: float
    speed_rad_s: float
    current_a: float
    model: HollowModel = field(default=DEFAULT_MODEL, repr=False)

    def __post_init__(self) -> None:
        _check_classic(self.model, self.motor_id, self.speed_rad_s, self.current_a)
        check_real("position_deg", self.position_deg, *EXTENDED_POSITION_LIMITS_DEG)

    @property
    def position_counts(self) -> int:
        """X, the position in counts (1,048,576 per turn)."""
        return round_half_away(self.position_deg * COUNTS_PER_TURN / 360.0)

    def encode(self) -> bytes:
        return packers(self.model).extended_reply.pack(
            [self.motor_id, self.position_deg, self.speed_rad_s, self.current_a]
        )

    @classmethod
    def decode(cls, data: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode an 8-byte extended-mode reply.

        Raises:
            ProtocolError: wrong length, or a motor id outside 0..100.
        """
        require_size(data, 8, what="extended-mode reply")
        motor_id, position, speed, current = packers(model).extended_reply.unpack(data)
        return build(
            cls,
            data,
            motor_id=int(motor_id),
            position_deg=position,
            speed_rad_s=speed,
            current_a=current,
            model=model,
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class FdReply(HollowReply):
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
    position_deg: float = 0.0
    velocity_rpm: float = 0.0
    current_raw: int = 0
    mode: ControlMode = ControlMode.TORQUE
    running: bool = False
    reserved: int = 0
    temperature_c: int = 0
    slave_id: int
    model: HollowModel = field(default=DEFAULT_MODEL, repr=False)

    def __post_init__(self) -> None:
        check_fd_motion(self.model, self.position_deg, self.velocity_rpm, self.current_raw)
        object.__setattr__(self, "mode", to_enum("mode", self.mode, ControlMode))
        object.__setattr__(self, "running", check_flag("running", self.running))
        check_int("reserved", self.reserved, 0, 0xFF)
        check_int("temperature_c", self.temperature_c, *_TEMPERATURE_LIMITS)
        check_int("slave_id", self.slave_id, *_MOTOR_ID_LIMITS)

    @property
    def position_counts(self) -> int:
        """Pos in counts (1,048,576 per turn)."""
        return round_half_away(self.position_deg * COUNTS_PER_TURN / 360.0)

    @property
    def electrical_hz(self) -> float:
        """Vel as the manual's electrical frequency (§7.4)."""
        return self.velocity_rpm * self.model.pole_pairs / 60.0

    def encode(self) -> bytes:
        return packers(self.model).fd_reply.pack(
            [
                self.position_deg,
                self.velocity_rpm,
                self.current_raw,
                self.mode,
                self.running,
                self.reserved,
                self.temperature_c,
                self.slave_id,
            ]
        )

    @classmethod
    def decode(cls, data: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode a 16-byte CAN FD reply.

        Raises:
            ProtocolError: wrong length, an unknown mode, a Run Status other than 0/1, a temperature
                outside -125..125 °C, or a slave id outside 0..100.
        """
        require_size(data, FD_PAYLOAD_SIZE, what="CAN FD reply")
        position, velocity, current, mode, run, reserved, temperature, slave = packers(model).fd_reply.unpack(
            data
        )
        return build(
            cls,
            data,
            position_deg=position,
            velocity_rpm=velocity,
            current_raw=int(current),
            mode=decode_enum("Mode", int(mode), ControlMode, data, motor_id=int(slave)),
            running=int(run),
            reserved=int(reserved),
            temperature_c=int(temperature),
            slave_id=int(slave),
            model=model,
        )
