"""The state the parts of the simulated MyActuator motor share.

:class:`~servobus.protocols.myactuator.sim.device.MyActuatorMotor` is one state machine told in
parts by concern: the output and the plant (:mod:`~servobus.protocols.myactuator.sim.drive`), the
error latch and 0xB3 protection (:mod:`~servobus.protocols.myactuator.sim.faults`), the frames it
takes (:mod:`~servobus.protocols.myactuator.sim.intake`) and the command handlers
(:mod:`~servobus.protocols.myactuator.sim.handlers`). They all work on one state, the motor's
attributes, declared here and set by the motor's ``__init__`` and power-up. The state stays on the
motor itself because its C twin (:mod:`~servobus.protocols.myactuator.sim.core`) reads and writes
it there by name, some of it through pulled attributes
(:func:`~servobus.protocols.myactuator.sim.core.attached_class`).
"""

from __future__ import annotations

from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator import ErrorFlags, Revision, StreamableCommand
from servobus.protocols.myactuator.sim.state import EncoderFrame, ErrorLatch, Settings, Stream
from servobus.sim.device import ListeningDevice
from servobus.sim.plant import Control

__all__ = ["MotorBase"]


class MotorBase(ListeningDevice):
    """The motor's state as its parts read and write it (see the module docstring)."""

    # configuration (constructor arguments)
    revision: Revision
    version_date: int
    model: str
    turnaround_s: float
    motion_scales: ma.MotionScales
    has_brake: bool
    rated_current_a: float
    rated_speed_dps: float
    pole_pairs: int
    # memory
    rom: Settings
    ram: Settings
    encoder: EncoderFrame
    errors: ErrorLatch
    # the output and what runs it (a C twin pulls and pushes these by name)
    control: Control
    run_mode: ma.RunMode
    brake_released: bool
    feedforward_pct: int | None
    streams: dict[StreamableCommand, Stream]
    unresponsive: bool
    comm_tripped: bool
    trip_echo: bool
    _next_trip_frame_s: float | None
    boot_s: float
    _last_heard_s: float
    next_report_s: float | None
    # memos
    _decoded: dict[tuple[int, bytes] | None, Command | tuple[Revision, ma.MotionScales]]
    _status1_key: tuple[float, float, bool, ErrorFlags] | None
    _status1_reply: Reply | None

    @property
    def motor_id(self) -> int:
        """The id the motor answers to now (RAM; a new ROM id acts after a restart)."""
        return self.ram.motor_id
