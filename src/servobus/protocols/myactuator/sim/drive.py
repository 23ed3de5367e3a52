"""The simulated MyActuator motor's output: the control it runs, its run mode, the brake, the plant.

A closed-loop command (``@loop`` in :mod:`~servobus.protocols.myactuator.sim.handlers`) gives a
plant control and a run mode; :meth:`Drive.control_command` runs it unless an error flag is set and
answers with the status either way. A locked brake holds the shaft whatever the command; the slew is
the acceleration (RAM) of the loop that runs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator.sim.base import MotorBase
from servobus.protocols.myactuator.sim.state import (
    Readings,
    motion_reply,
    single_turn_status_reply,
    status_reply,
)
from servobus.sim.plant import Brake, Control, Off
from servobus.sim.plant import SpeedControl as PlantSpeedControl

__all__ = ["Drive", "Loop"]

#: a closed loop: ``loop(motor, command)`` gives the plant control and the run mode
Loop = Callable[[Any, Any], "tuple[Control, ma.RunMode]"]


class Drive(MotorBase):
    """The output part of :class:`~servobus.protocols.myactuator.sim.device.MyActuatorMotor`."""

    @property
    def enabled(self) -> bool:
        """The output is on (a control command is running): V4.4 refuses ROM saves then."""
        return not isinstance(self.control, Off)

    @property
    def angle_deg(self) -> float:
        """Output angle from the zero (what 0x92 reports)."""
        return self.encoder.angle_deg(self.plant.motor_position_deg)

    def readings(self) -> Readings:
        """The measurements a reply would carry now."""
        plant, rotor = self.plant, self.plant.motor_position_deg
        return Readings(
            temperature_c=plant.temperature_c,
            current_a=plant.current_a,
            speed_dps=plant.speed_dps,
            angle_deg=self.encoder.angle_deg(rotor),
            voltage_v=plant.voltage_v,
            rotor_deg=rotor,
            position_counts=self.encoder.position_counts(rotor),
            counts_per_turn=self.encoder.counts_per_turn,
        )

    def control_command(self, command: Command, loop: Loop, *, releases_brake: bool) -> Reply:
        if self.errors.flags:
            self._counters["refused_fault"] += 1
        else:
            # Every control command but 0xA1 releases the brake: the manuals name only 0xA1 as unable [I].
            self.brake_released = self.brake_released or releases_brake
            self.set_control(*loop(self, command))
        readings = self.readings()
        reply = type(command).REPLY
        if reply is ma.MotionReply:
            return motion_reply(self.motor_id, readings, self.plant.torque_nm, self.motion_scales)
        if reply is ma.SingleTurnStatusReply:
            return single_turn_status_reply(readings)
        assert reply is ma.StatusReply and command.CODE is not None, command
        return status_reply(ma.StatusCommand(command.CODE), readings)

    def set_control(self, control: Control, run_mode: ma.RunMode) -> None:
        self.control = control
        self.run_mode = run_mode
        self.apply_plant()

    def apply_plant(self) -> None:
        accel = self.ram.acceleration_dps_s
        if isinstance(self.control, PlantSpeedControl):
            slew = accel[ma.AccelIndex.SPEED_ACCELERATION]
        else:
            slew = accel[ma.AccelIndex.POSITION_ACCELERATION]
        self.plant.acceleration_dps2 = slew if slew > 0 else math.inf  # 0: limited by the current only
        locked = self.has_brake and not self.brake_released
        self.plant.set_control(Brake() if locked else self.control)

    def current_limit_a(self, pct: int | None) -> float | None:
        if pct is None:  # maxTorque 0: force-limit mode off (§4.20)
            return None
        limit = pct / 100.0 * self.rated_current_a
        return limit if 0 < limit < self.plant.params.max_current_a else None

    def target_deg(self, angle_deg: float) -> float:
        return self.encoder.output_deg_for(angle_deg)
