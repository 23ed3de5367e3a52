"""The CAN FD request of the hollow series (hollow.md §7.2): one 16-byte frame carries everything.

There are no special commands in CAN FD mode: start/stop, mode, gains and zeroing are fields of every
frame. The same 16 bytes travel inside the RS-485 converter's transparent frames and Modbus RTU write
registers (§9.4, §9.5), so :mod:`servobus.protocols.hollow.rs485` wraps this class.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from servobus.protocols._fields import round_half_away
from servobus.protocols.bits import Code, Flag
from servobus.protocols.hollow._packed import Packed, fd_position_limits_deg, fd_velocity_limits_rpm
from servobus.protocols.hollow.commands import ControlMode, HollowCommand
from servobus.protocols.hollow.model import COUNTS_PER_TURN, DEFAULT_MODEL, HollowModel
from servobus.protocols.hollow.replies import FD_PAYLOAD_SIZE, FdReply, fd_motion_fields

__all__ = [
    "FD_GAIN_MAX",
    "FD_PAYLOAD_SIZE",
    "FdCommand",
    "fd_position_limits_deg",
    "fd_velocity_limits_rpm",
]

FD_GAIN_MAX = 0xFF  # §7.2: Kp, Kd 0..255


#: the fields a running motor does not act on in each mode, and a stopped one (FdCommand.inactive)
_UNUSED = {
    ControlMode.TORQUE: frozenset({"position_deg", "velocity_rpm"}),
    ControlMode.VELOCITY: frozenset({"position_deg"}),
}
_UNUSED_STOPPED = frozenset({"position_deg", "velocity_rpm", "current_raw"})


@dataclass(frozen=True, slots=True, kw_only=True)
class FdCommand(Packed, HollowCommand[FdReply]):
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

    It travels on CAN FD and, through the converter, in transparent mode and as a Modbus write (the
    bound codec sends it as :class:`~servobus.protocols.hollow.rs485.ModbusWrite`, whose
    acknowledgement answers it there).
    """

    FD: ClassVar[bool] = True
    LINKS: ClassVar[tuple[str, ...]] = ("canfd", "rs485", "modbus")
    PACKER: ClassVar[str] = "fd_command"
    SIZE: ClassVar[int] = FD_PAYLOAD_SIZE
    WHAT: ClassVar[str] = "CAN FD request"
    FIELDS = (
        *fd_motion_fields("Mode Sel"),
        Flag("run", (96, 8)),
        Code("kp", (104, 8), 0, FD_GAIN_MAX),
        Code("kd", (112, 8), 0, FD_GAIN_MAX),
        Flag("zero", (120, 8)),
    )
    position_deg: float = 0.0
    velocity_rpm: float = 0.0
    current_raw: int = 0
    mode: ControlMode = ControlMode.TORQUE
    run: bool = False
    kp: int = 0
    kd: int = 0
    zero: bool = False
    model: HollowModel = field(default=DEFAULT_MODEL, repr=False)

    def inactive(self) -> frozenset[str]:
        """What its mode leaves unused: all of it when not running (the stop frame), the position
        and speed in torque mode, the position in velocity mode (Command.inactive)."""
        if not self.run:
            return _UNUSED_STOPPED
        return _UNUSED.get(self.mode, frozenset())

    @property
    def position_counts(self) -> int:
        """Pos as the counts the frame carries."""
        return round_half_away(self.position_deg * COUNTS_PER_TURN / 360.0)

    @property
    def electrical_hz(self) -> float:
        """Vel as the manual's electrical frequency (§7.4)."""
        return self.velocity_rpm * self.model.pole_pairs / 60.0
