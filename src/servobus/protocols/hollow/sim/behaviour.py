"""What the simulated hollow motor does on each request: its RAM state changed, nothing sent.

The dispatch is :data:`BEHAVIOUR`, filled by the behaviours themselves (``@_does``: no second list
of the commands); :class:`~servobus.protocols.hollow.sim.device.HollowMotor` looks a decoded
request up there and then answers with its status, whatever the request was (A37). Each behaviour
works on the motor's state (``enabled``, ``can_mode``, ``ctrl_mode``, ``setpoint``,
``zero_offset_deg``, ``pi_multipliers``), which lives in C while a C network runs the motor
(:mod:`~servobus.protocols.hollow.sim.core`), so the behaviours read and write it only through those
names.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol, TypeVar

from servobus.protocols.hollow import (
    CanMode,
    CanModeSwitch,
    ControlMode,
    FdCommand,
    HollowCommand,
    HollowModel,
    IncrementalSetpoint,
    PiGain,
    PiMultiplier,
    SelectMode,
    Setpoint,
    SetZero,
    Start,
    Stop,
)
from servobus.protocols.hollow.sim.core import HeldSetpoint
from servobus.sim.plant import Plant

__all__ = ["BEHAVIOUR", "HeldSetpoint", "HollowMotor", "apply", "implemented"]


class HollowMotor(Protocol):
    """What the behaviours read and change of the simulated hollow motor (the model's HollowMotor
    is one): typed here, so the model imports its behaviours and nothing here imports the model."""

    model: HollowModel
    enabled: bool
    can_mode: CanMode
    ctrl_mode: ControlMode
    setpoint: HeldSetpoint | None
    zero_offset_deg: float
    pi_multipliers: dict[PiGain, float]
    fd_current_a_per_count: float

    @property
    def plant(self) -> Plant: ...
    @property
    def position_deg(self) -> float: ...
    def tally(self, kind: str, n: int = 1) -> None: ...


DPS_PER_RAD_S = 180.0 / math.pi
DPS_PER_RPM = 6.0

#: what the motor does on each request class
BEHAVIOUR: dict[type[HollowCommand[Any]], Callable[[HollowMotor, Any], None]] = {}
C = TypeVar("C", bound=HollowCommand[Any])


def _does(cls: type[C]) -> Callable[[Callable[[HollowMotor, C], None]], Callable[[HollowMotor, C], None]]:
    """Register the decorated function as what the motor does on a ``cls`` request."""

    def register(behaviour: Callable[[HollowMotor, C], None]) -> Callable[[HollowMotor, C], None]:
        BEHAVIOUR[cls] = behaviour
        return behaviour

    return register


def implemented() -> frozenset[type[HollowCommand[Any]]]:
    """The request classes the simulated motor has a behaviour for."""
    return frozenset(BEHAVIOUR)


def apply(motor: HollowMotor, command: HollowCommand[Any]) -> None:
    """Do what ``command`` asks of ``motor``.

    Raises:
        NotImplementedError: a request class without behaviour here (a gap of the model, not noise).
    """
    behaviour = BEHAVIOUR.get(type(command))
    if behaviour is None:
        raise NotImplementedError(f"the simulated hollow motor does not implement {type(command).__name__}")
    behaviour(motor, command)


@_does(Start)
def _start(motor: HollowMotor, command: Start) -> None:
    motor.enabled = True
    if motor.can_mode is CanMode.EXTENDED and motor.ctrl_mode is ControlMode.POSITION:
        # §5.2 [M]: FC in extended position mode locks at the present position.
        held, model = motor.setpoint, motor.model
        motor.setpoint = HeldSetpoint(
            target_deg=motor.position_deg,
            speed_dps=held.speed_dps if held else model.speed_full_scale_rad_s * DPS_PER_RAD_S,
            current_a=held.current_a if held else model.current_full_scale_a,
            kp=held.kp if held else 0,
            kd=held.kd if held else 0,
        )
    elif motor.setpoint is None:
        motor.tally("start_without_setpoint")


@_does(Stop)
def _stop(motor: HollowMotor, command: Stop) -> None:
    motor.enabled = False


@_does(SelectMode)
def _select_mode(motor: HollowMotor, command: SelectMode) -> None:
    motor.ctrl_mode = command.mode  # temporary, not persisted (§4.1)


@_does(SetZero)
def _set_zero_command(motor: HollowMotor, command: SetZero) -> None:
    _set_zero(motor)


def _set_zero(motor: HollowMotor) -> None:
    # §4.1 / A33: only while not enabled; not persisted. The multi-turn count is cleared with it.
    if motor.enabled:
        motor.tally("zero_refused")
        return
    motor.zero_offset_deg = motor.plant.position_deg


def _held(command: Setpoint | IncrementalSetpoint, target_deg: float) -> HeldSetpoint:
    """What the motor holds after a set-point frame aiming at ``target_deg``."""
    return HeldSetpoint(
        target_deg=target_deg,
        speed_dps=command.speed_rad_s * DPS_PER_RAD_S,
        current_a=command.current_a,
        kp=command.kp,
        kd=command.kd,
    )


@_does(Setpoint)
def _setpoint(motor: HollowMotor, command: Setpoint) -> None:
    motor.setpoint = _held(command, command.position_deg)


@_does(IncrementalSetpoint)
def _incremental_setpoint(motor: HollowMotor, command: IncrementalSetpoint) -> None:
    # §5.2 / A11: each frame moves the target once; the first one starts from where the motor is.
    base = motor.setpoint.target_deg if motor.setpoint is not None else motor.position_deg
    motor.setpoint = _held(command, base + command.step_deg)


@_does(CanModeSwitch)
def _can_mode_switch(motor: HollowMotor, command: CanModeSwitch) -> None:
    motor.can_mode = command.mode  # until power-off (§5.1)


@_does(PiMultiplier)
def _pi_multiplier(motor: HollowMotor, command: PiMultiplier) -> None:
    # §6: stored and reported by the simulator; the plant's loops have no gain knob.
    motor.pi_multipliers[command.gain] = command.multiplier


@_does(FdCommand)
def _apply_fd(motor: HollowMotor, command: FdCommand) -> None:
    # §7.2 / §13: Mode Sel, Run Cmd, Kp, Kd, then Zero, which acts only if the motor is not
    # running once this frame's Run Cmd is applied ("only while not enabled").
    motor.ctrl_mode = command.mode
    motor.enabled = command.run
    motor.setpoint = HeldSetpoint(
        target_deg=command.position_deg,
        speed_dps=command.velocity_rpm * DPS_PER_RPM,
        current_a=command.current_raw * motor.fd_current_a_per_count,
        kp=command.kp,
        kd=command.kd,
    )
    if command.zero:
        _set_zero(motor)
