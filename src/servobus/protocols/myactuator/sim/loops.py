"""The simulated MyActuator motor's closed loops (§4.19-§4.26, §5), stop, shutdown and the brake.

Each closed-loop command gives the plant control and run mode it asks for (the table in
:mod:`~servobus.protocols.myactuator.sim.device`'s docstring); the motor runs it unless an error
flag is set and answers with its status either way
(:meth:`~servobus.protocols.myactuator.sim.drive.Drive.control_command`).
"""

from __future__ import annotations

import math
from typing import Any

from servobus.protocols import myactuator as ma
from servobus.protocols._message import Command
from servobus.protocols.myactuator import MotionCommand
from servobus.protocols.myactuator.sim.handlers import HandledMotor, handles, loop
from servobus.sim.plant import Control, CurrentControl, Impedance, Off, PositionControl
from servobus.sim.plant import SpeedControl as PlantSpeedControl

__all__: list[str] = []  # the handlers register themselves (handlers.py)

# In motion mode the MIT law ends in a q-axis current reference, so the drive runs its current loop.
_RUN_MODE_MOTION = ma.RunMode.CURRENT_LOOP


@loop(ma.TorqueControl, releases_brake=False)
def _torque(motor: HandledMotor, command: ma.TorqueControl) -> tuple[Control, ma.RunMode]:
    # §4.19: 0xA1 cannot release the brake; a locked brake keeps the shaft held.
    if motor.has_brake and not motor.brake_released:
        motor.tally("brake_locked")
    return CurrentControl(current_a=command.current_a), ma.RunMode.CURRENT_LOOP


@loop(MotionCommand)
def _impedance(motor: HandledMotor, command: MotionCommand) -> tuple[Control, ma.RunMode]:
    p_des_deg = motor.target_deg(math.degrees(command.position_rad))
    control = Impedance(
        position_rad=math.radians(p_des_deg),
        velocity_rad_s=command.velocity_rad_s,
        kp=command.kp,
        kd=command.kd,
        torque_ff_nm=command.torque_ff_nm,
    )
    return control, _RUN_MODE_MOTION


@loop(ma.SpeedControl)
def _speed(motor: HandledMotor, command: ma.SpeedControl) -> tuple[Control, ma.RunMode]:
    limit = motor.current_limit_a(command.max_torque_pct)
    return PlantSpeedControl(speed_dps=command.speed_dps, max_current_a=limit), ma.RunMode.SPEED_LOOP


@loop(
    ma.AbsolutePositionControl,
    ma.ForcePositionControl,
    ma.PositionSpeedFeedforward,
    ma.PositionTorqueFeedforward,
)
def _absolute(motor: HandledMotor, command: Any) -> tuple[Control, ma.RunMode]:
    limit = None
    if isinstance(command, ma.ForcePositionControl):
        limit = motor.current_limit_a(command.max_torque_pct)
    if isinstance(command, ma.PositionSpeedFeedforward):
        motor.feedforward_pct = command.feedforward_speed_pct
    elif isinstance(command, ma.PositionTorqueFeedforward):
        motor.feedforward_pct = command.feedforward_torque_pct
    return _position(motor.target_deg(command.angle_deg), command.max_speed_dps, limit)


@loop(ma.IncrementalPositionControl)
def _incremental(motor: HandledMotor, command: ma.IncrementalPositionControl) -> tuple[Control, ma.RunMode]:
    return _position(motor.plant.position_deg + command.angle_deg, command.max_speed_dps)


@loop(ma.SingleTurnPositionControl)
def _single_turn(motor: HandledMotor, command: ma.SingleTurnPositionControl) -> tuple[Control, ma.RunMode]:
    here = motor.angle_deg % 360.0
    wanted = command.angle_deg % 360.0
    if command.direction is ma.SpinDirection.CLOCKWISE:
        delta = (wanted - here) % 360.0
    else:
        delta = -((here - wanted) % 360.0)
    return _position(motor.plant.position_deg + delta, command.max_speed_dps)


def _position(
    target_deg: float, max_speed_dps: float | None, limit_a: float | None = None
) -> tuple[Control, ma.RunMode]:
    # max_speed_dps None (maxSpeed 0): no limit (§4.21).
    control = PositionControl(position_deg=target_deg, max_speed_dps=max_speed_dps, max_current_a=limit_a)
    return control, ma.RunMode.POSITION_LOOP


@handles(ma.MotorShutdown)
def _on_shutdown(motor: HandledMotor, _command: Command, _now_s: float, _rs485: bool) -> None:
    motor.set_control(Off(), motor.run_mode)


@handles(ma.MotorStop)
def _on_stop(motor: HandledMotor, _command: Command, _now_s: float, _rs485: bool) -> None:
    if motor.enabled and not motor.errors.flags:  # hold where it is; the loop stays (§4.18)
        motor.set_control(PositionControl(position_deg=motor.plant.position_deg), motor.run_mode)


@handles(ma.BrakeRelease, ma.BrakeLock)
def _on_brake(motor: HandledMotor, command: Command, _now_s: float, _rs485: bool) -> None:
    motor.brake_released = isinstance(command, ma.BrakeRelease)
    motor.apply_plant()
