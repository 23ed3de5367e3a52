"""The CAN FD request of the hollow series (hollow.md §7.2): one 16-byte frame carries everything.

There are no special commands in CAN FD mode: start/stop, mode, gains and zeroing are fields of every
frame. The same 16 bytes travel inside the RS-485 converter's transparent frames and Modbus RTU write
registers (§9.4, §9.5), so :mod:`servobus.protocols.hollow.rs485` wraps this class.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Self

from servobus.protocols._fields import round_half_away
from servobus.protocols.hollow._checks import (
    build,
    check_flag,
    check_int,
    check_real,
    decode_enum,
    require_size,
    to_enum,
)
from servobus.protocols.hollow.commands import ControlMode, HollowCommand, check_model
from servobus.protocols.hollow.model import COUNTS_PER_TURN, DEFAULT_MODEL, HollowModel, packers

__all__ = [
    "FD_GAIN_MAX",
    "FD_PAYLOAD_SIZE",
    "FdCommand",
    "check_fd_motion",
    "fd_position_limits_deg",
    "fd_velocity_limits_rpm",
]

FD_PAYLOAD_SIZE = 16
FD_GAIN_MAX = 0xFF  # §7.2: Kp, Kd 0..255
_CURRENT_LIMITS = (-(1 << 15), (1 << 15) - 1)  # int16, unit not stated (A27)


def fd_position_limits_deg() -> tuple[float, float]:
    """The 40-bit signed position in degrees (1,048,576 counts per turn, §7.2)."""
    top = 1 << 39
    return (-top * 360.0 / COUNTS_PER_TURN, (top - 1) * 360.0 / COUNTS_PER_TURN)


def fd_velocity_limits_rpm(model: HollowModel) -> tuple[float, float]:
    """The int32 velocity in shaft rpm for ``model``'s pole pairs (§7.4)."""
    per_rpm = model.fd_velocity_counts_per_rpm
    return (-(1 << 31) / per_rpm, ((1 << 31) - 1) / per_rpm)


_POSITION_LIMITS = fd_position_limits_deg()


def check_fd_motion(
    model: HollowModel, position_deg: object, velocity_rpm: object, current_raw: object
) -> None:
    """The range checks shared by the CAN FD request and reply (ValueError naming field and limit)."""
    check_model(model)
    check_real("position_deg", position_deg, *_POSITION_LIMITS)
    check_real("velocity_rpm", velocity_rpm, *fd_velocity_limits_rpm(model))
    check_int("current_raw", current_raw, *_CURRENT_LIMITS)


@dataclass(frozen=True, slots=True, kw_only=True)
class FdCommand(HollowCommand):
    """The 16-byte CAN FD request (§7.2); all defaults give the all-zero status poll [H20].

    Pos/Vel/Cur mean, by analogy with classic CAN (§7.2 [I]): position mode - target position,
    maximum speed, maximum current; velocity mode - target speed, maximum current; torque mode -
    target current.

    Attributes:
        position_deg: Pos, 40-bit signed counts from the zero (1,048,576 per turn), in degrees;
            absolute (A29).
        velocity_rpm: Vel, int32 of the electrical frequency (Hz = Vel / 8388.608); shaft rpm =
            Hz · 60 / pole_pairs of the model (§7.4, A27: the reply's scale).
        current_raw: Cur, int16; the manual states no unit or scale (A27).
        mode: Mode Sel, switchable at any time.
        run: Run Cmd, True starts the motor, False frees it.
        kp: position-loop Kp 0..255.
        kd: position-loop Kd 0..255.
        zero: set the present position as zero (only while not running; not persisted). The motor
            re-zeroes on every frame with it set, so clear it in the next frame (§7.2).
        model: scaling (pole pairs) of the motor.
    """

    FD: ClassVar[bool] = True
    position_deg: float = 0.0
    velocity_rpm: float = 0.0
    current_raw: int = 0
    mode: ControlMode = ControlMode.TORQUE
    run: bool = False
    kp: int = 0
    kd: int = 0
    zero: bool = False
    model: HollowModel = field(default=DEFAULT_MODEL, repr=False)

    def __post_init__(self) -> None:
        check_fd_motion(self.model, self.position_deg, self.velocity_rpm, self.current_raw)
        object.__setattr__(self, "mode", to_enum("mode", self.mode, ControlMode))
        object.__setattr__(self, "run", check_flag("run", self.run))
        check_int("kp", self.kp, 0, FD_GAIN_MAX)
        check_int("kd", self.kd, 0, FD_GAIN_MAX)
        object.__setattr__(self, "zero", check_flag("zero", self.zero))

    @property
    def position_counts(self) -> int:
        """Pos as the counts the frame carries."""
        return round_half_away(self.position_deg * COUNTS_PER_TURN / 360.0)

    @property
    def electrical_hz(self) -> float:
        """Vel as the manual's electrical frequency (§7.4)."""
        return self.velocity_rpm * self.model.pole_pairs / 60.0

    def encode(self) -> bytes:
        return packers(self.model).fd_command.pack(
            [
                self.position_deg,
                self.velocity_rpm,
                self.current_raw,
                self.mode,
                self.run,
                self.kp,
                self.kd,
                self.zero,
            ]
        )

    @classmethod
    def decode(cls, data: bytes, *, model: HollowModel = DEFAULT_MODEL) -> Self:
        """Decode a 16-byte CAN FD request.

        Raises:
            ProtocolError: wrong length, or Mode Sel / Run Cmd / Zero bytes outside their values.
        """
        require_size(data, FD_PAYLOAD_SIZE, what="CAN FD request")
        position, velocity, current, mode, run, kp, kd, zero = packers(model).fd_command.unpack(data)
        return build(
            cls,
            data,
            position_deg=position,
            velocity_rpm=velocity,
            current_raw=int(current),
            mode=decode_enum("Mode Sel", int(mode), ControlMode, data),
            run=int(run),
            kp=int(kp),
            kd=int(kd),
            zero=int(zero),
            model=model,
        )
