"""The state the parts of the simulated MyActuator motor share.

:class:`~servobus.protocols.myactuator.sim.device.MyActuatorMotor` is one state machine told in
parts by concern: the output and the plant (:mod:`~servobus.protocols.myactuator.sim.drive`), the
error latch and 0xB3 protection (:mod:`~servobus.protocols.myactuator.sim.faults`), the frames it
takes (:mod:`~servobus.protocols.myactuator.sim.intake`) and the command handlers
(:mod:`~servobus.protocols.myactuator.sim.handlers`). They all work on one state, the motor's
attributes, set here (``MotorBase.__init__``, from the configuration the motor checked) and by
power-up. The state stays on the
motor itself because its C twin (:mod:`~servobus.protocols.myactuator.sim.core`) reads and writes
it there by name, some of it through pulled attributes
(:func:`~servobus.protocols.myactuator.sim.core.attached_class`).
"""

from __future__ import annotations

from collections import Counter

from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator import ErrorFlags, Revision, StreamableCommand
from servobus.protocols.myactuator.sim.state import EncoderFrame, ErrorLatch, Settings, Stream
from servobus.sim.device import ListeningDevice
from servobus.sim.plant import Control, Off, Plant

__all__ = ["RUN_MODE_POWER_UP", "MotorBase"]

# [I] The manuals define three run modes and no other (§4.27: "has the following 3 states"), so 0x70
# always reports one: after 0x80 (or a fault or comm trip) the last loop's mode stays; at power-up,
# before any control command, the position loop (the manuals' only 0x70 example reads 0x03).
RUN_MODE_POWER_UP = ma.RunMode.POSITION_LOOP


class MotorBase(ListeningDevice):
    """The motor's state as its parts read and write it (see the module docstring)."""

    def __init__(
        self,
        *,
        name: str,
        plant: Plant,
        encoder: EncoderFrame,
        rom: Settings,
        revision: Revision,
        version_date: int,
        model: str,
        turnaround_s: float,
        motion_scales: ma.MotionScales,
        has_brake: bool,
        rated_current_a: float,
        rated_speed_dps: float,
        pole_pairs: int,
        trip_echo: bool,
        now_s: float,
    ) -> None:
        # configuration (constructor arguments)
        self._name = name
        self._plant = plant
        self.revision = revision
        self.version_date = version_date
        self.model = model
        self.turnaround_s = turnaround_s
        self.motion_scales = motion_scales
        self.has_brake = has_brake
        self.rated_current_a = rated_current_a
        self.rated_speed_dps = rated_speed_dps
        self.pole_pairs = pole_pairs
        self.trip_echo = trip_echo
        # memory
        self.encoder = encoder
        self.rom = rom
        self.ram = rom.copy()
        self.errors = ErrorLatch()
        self.unresponsive = False
        self._counters: Counter[str] = Counter()
        # the output and what runs it (a C twin pulls and pushes these by name); power-up sets them
        self.control: Control = Off()
        self.run_mode = RUN_MODE_POWER_UP
        self.brake_released = False
        self.feedforward_pct: int | None = None
        self.streams: dict[StreamableCommand, Stream] = {}
        self.comm_tripped = False
        self._next_trip_frame_s: float | None = None
        self.boot_s = now_s
        self._last_heard_s = now_s
        self.next_report_s: float | None = None
        # memos
        self._decoded: dict[tuple[int, bytes] | None, Command | tuple[Revision, ma.MotionScales]] = {}
        self._status1_key: tuple[float, float, bool, ErrorFlags] | None = None  # the last 0x9A's inputs
        self._status1_reply: Reply | None = None

    @property
    def motor_id(self) -> int:
        """The id the motor answers to now (RAM; a new ROM id acts after a restart)."""
        return self.ram.motor_id
