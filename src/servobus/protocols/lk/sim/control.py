"""How a simulated LK motor turns a control command (0xA0..0xA8, 0x280) into a plant control.

The LK protocol speaks motor-shaft degrees and dps (see :mod:`~servobus.protocols.lk.sim.state`); the
plant speaks output-shaft ones, so angles and speeds are divided by ``gear_ratio`` here.

=============  ===========================================================================
0xA0 power     ``CurrentControl``: power x (max current / 1000) on MS, iq counts elsewhere
               (V2.35 "torque open loop", A20); not limited by Max Power (spec §4.9)
0xA1, 0x280    ``CurrentControl`` at iqControl; not limited by Max Torque Current (§4.10, §5)
0xA2           ``SpeedControl``: V2.36 speed within Max Speed, current within the frame's
               iqControl (0 means no torque: the §4.11 hazard, taken literally); V2.35 current
               within Max Torque Current (§4.11)
0xA3 / 0xA4    ``PositionControl`` to the multi-turn target clamped to the angle limits, at
               Max Speed / the frame's maxSpeed (§4.12, §4.13)
0xA5 / 0xA6    ``PositionControl`` to the single-turn target, reached turning the way
               spinDirection says: clockwise = increasing angle (§4.24, §4.25: both angles
               increase clockwise); the period is 360° x ratio on V2.36 (0x94's range), 360° on
               V2.35; at Max Speed / the frame's maxSpeed (§4.14, §4.15)
0xA7 / 0xA8    ``PositionControl`` to the held position target (else the present position) plus
               the increment; 0xA7 at Max Speed on V2.36, unlimited on V2.35 (§4.16, D17);
               0xA8 at the frame's maxSpeed (§4.17)
=============  ===========================================================================

Every speed and position mode is current-limited by Max Torque Current (MS: Max Power). A
maxSpeed of 0 means "do not move" (the plant would read 0 as "no limit"). PID gains do not shape
the response: the plant's loops have fixed bandwidths.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from servobus.protocols import lk
from servobus.protocols.lk import LkCommand, Revision, SpinDirection
from servobus.protocols.lk.sim.state import Limits, single_turn_period_deg
from servobus.sim.plant import Control, CurrentControl, PositionControl, SpeedControl

__all__ = ["CONTROL_COMMANDS", "MotionContext", "plant_control"]

_NO_SPEED_DPS = 1e-9
_C = TypeVar("_C", bound=Callable[..., Control])


@dataclass(frozen=True, slots=True, kw_only=True)
class MotionContext:
    """What the mapping needs to know about the motor when the command arrives.

    Attributes:
        revision: the protocol revision.
        gear_ratio: motor turns per output turn.
        amps_per_count: plant amperes per iq (MS: power) count.
        limits: the limits in effect (motor-shaft units).
        multi_turn_deg: the present multi-turn angle (motor degrees from the zero).
        origin_deg: the motor-shaft angle at which the multi-turn angle is 0.
        position_deg: the plant's present output position.
        held_target_deg: the output target of the running position command, if one is running.
    """

    revision: Revision
    gear_ratio: float
    amps_per_count: float
    limits: Limits
    multi_turn_deg: float
    origin_deg: float
    position_deg: float
    held_target_deg: float | None


#: How each set-point command class maps to a plant control (the module's table), registered by class.
_CONTROLS: dict[type, Callable[[Any, MotionContext], Control]] = {}


def _controls(*classes: type[LkCommand]) -> Callable[[_C], _C]:
    def register(mapping: _C) -> _C:
        _CONTROLS.update(dict.fromkeys(classes, mapping))
        return mapping

    return register


def plant_control(command: LkCommand, ctx: MotionContext) -> Control:
    """The plant control that ``command`` asks for (see the module's table).

    Raises:
        TypeError: ``command`` is not a control command (0x280 is: the device picks its own set-point).
    """
    mapping = _CONTROLS.get(type(command))
    if mapping is None:
        raise TypeError(f"{type(command).__name__} is not a control command")
    return mapping(command, ctx)


@_controls(lk.OpenLoopControl)
def _open_loop(command: lk.OpenLoopControl, ctx: MotionContext) -> Control:
    return CurrentControl(current_a=command.power_counts * ctx.amps_per_count)


@_controls(lk.TorqueControl)
def _torque(command: lk.TorqueControl, ctx: MotionContext) -> Control:
    return CurrentControl(current_a=_amps(command.current_a, command.iq_counts, ctx.amps_per_count))


@_controls(lk.SpeedControl)
def _speed(command: lk.SpeedControl, ctx: MotionContext) -> Control:
    limits = ctx.limits
    speed = max(-limits.speed_dps, min(limits.speed_dps, command.speed_dps))
    limit = abs(_amps(command.current_limit_a, command.iq_limit_counts, ctx.amps_per_count))
    return SpeedControl(speed_dps=speed / ctx.gear_ratio, max_current_a=limit)


@_controls(lk.SpeedControlV235)
def _speed_v235(command: lk.SpeedControlV235, ctx: MotionContext) -> Control:
    return SpeedControl(
        speed_dps=command.speed_dps / ctx.gear_ratio,
        max_current_a=ctx.limits.torque_counts * ctx.amps_per_count,
    )


@_controls(lk.MultiTurnPosition)
def _multi_turn_position(command: lk.MultiTurnPosition, ctx: MotionContext) -> Control:
    return _position(_multi_turn(command.angle_deg, ctx), ctx.limits.speed_dps, ctx)


@_controls(lk.MultiTurnPositionSpeed)
def _multi_turn_position_speed(command: lk.MultiTurnPositionSpeed, ctx: MotionContext) -> Control:
    target = _multi_turn(command.angle_deg, ctx)
    return _position(target, _speed_limit(command.max_speed_dps, ctx.limits), ctx)


@_controls(lk.SingleTurnPosition, lk.SingleTurnPositionV235)
def _single_turn_position(command: lk.SingleTurnPosition, ctx: MotionContext) -> Control:
    return _position(_single_turn(command.angle_deg, command.direction, ctx), ctx.limits.speed_dps, ctx)


@_controls(lk.SingleTurnPositionSpeed, lk.SingleTurnPositionSpeedV235)
def _single_turn_position_speed(command: lk.SingleTurnPositionSpeed, ctx: MotionContext) -> Control:
    target = _single_turn(command.angle_deg, command.direction, ctx)
    return _position(target, _speed_limit(command.max_speed_dps, ctx.limits), ctx)


@_controls(lk.IncrementalPosition)
def _incremental(command: lk.IncrementalPosition, ctx: MotionContext) -> Control:
    # D17: 0xA7 runs at Max Speed on V2.36 and unlimited on V2.35.
    speed = ctx.limits.speed_dps if ctx.revision is Revision.V2_36 else math.inf
    return _position(_increment(command.increment_deg, ctx), speed, ctx)


@_controls(lk.IncrementalPositionSpeed)
def _incremental_speed(command: lk.IncrementalPositionSpeed, ctx: MotionContext) -> Control:
    speed = _speed_limit(command.max_speed_dps, ctx.limits)
    return _position(_increment(command.increment_deg, ctx), speed, ctx)


#: The set-point commands the device maps to plant controls (0x280 picks its own set-point).
CONTROL_COMMANDS: tuple[type[LkCommand], ...] = tuple(_CONTROLS)


def _position(target_deg: float, speed_dps: float, ctx: MotionContext) -> Control:
    """A position control to the output target at the motor-shaft speed limit (inf: none)."""
    ratio = ctx.gear_ratio
    max_speed = max(speed_dps / ratio, _NO_SPEED_DPS) if math.isfinite(speed_dps) else None
    return PositionControl(
        position_deg=target_deg,
        max_speed_dps=max_speed,
        max_current_a=ctx.limits.torque_counts * ctx.amps_per_count,
    )


def _increment(increment_deg: float, ctx: MotionContext) -> float:
    """The output target of an increment. Increments add to the running target, so a host streaming
    them does not accumulate the tracking error; the first one starts from where the shaft is."""
    base = ctx.position_deg if ctx.held_target_deg is None else ctx.held_target_deg
    return base + increment_deg / ctx.gear_ratio


def _speed_limit(max_speed_dps: float | None, limits: Limits) -> float:
    """A command's speed limit; maxSpeed 0 (None) is not defined by the manuals: the Max Speed setting [I]."""
    return limits.speed_dps if max_speed_dps is None else max_speed_dps


def _amps(current_a: float | None, counts: int | None, amps_per_count: float) -> float:
    """A command's torque current in A: given in A (MF/MG) or as counts (MH, MS)."""
    return current_a if current_a is not None else (counts or 0) * amps_per_count


def _multi_turn(angle_deg: float, ctx: MotionContext) -> float:
    lo, hi = ctx.limits.angle_deg
    return (min(max(angle_deg, lo), hi) + ctx.origin_deg) / ctx.gear_ratio


def _single_turn(angle_deg: float, direction: SpinDirection, ctx: MotionContext) -> float:
    period = single_turn_period_deg(ctx.revision, ctx.gear_ratio)
    here = ctx.multi_turn_deg
    delta = (angle_deg - here) % period
    if direction is SpinDirection.COUNTER_CLOCKWISE and delta:
        delta -= period
    return (here + delta + ctx.origin_deg) / ctx.gear_ratio
