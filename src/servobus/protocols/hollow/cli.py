"""The hollow series' part of the command line: set-points on classic CAN (the CLI drives the normal
mode, §4), ``stop``/``off`` on every link, and why the rest is not there.

Imported only when the CLI is asked for this family (``FAMILY.part("cli")``); the contract is
:mod:`servobus.protocols.cli`'s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from servobus.protocols import BoundCodec, Command
from servobus.protocols.cli import CliFamily, Op, Values
from servobus.protocols.hollow import ControlMode, SelectMode, Setpoint, SetZero, Start, Stop

__all__ = ["CLI"]


def _classic(codec: BoundCodec, what: str) -> None:
    if codec.link != "can":
        raise ValueError(
            f"hollow motors on {codec.link}: the CLI sends {what} on classic CAN only (drop --fd/--port)"
        )


def _setpoint(mode: ControlMode) -> Op:
    """SelectMode, a first set-point, Start; then the set-point again at the rate (§4.1-§4.4)."""

    def setpoint(codec: BoundCodec, v: Values) -> Command:
        _classic(codec, "set-points")
        model = codec.model
        full_speed = model.speed_full_scale_rad_s
        limit = v.get("max_current_a")  # move and speed: --max-current-a, or I_fs
        full_current = model.current_full_scale_a if limit is None else limit
        if mode is ControlMode.POSITION:
            speed = math.radians(v["max_speed_dps"]) if v["max_speed_dps"] is not None else full_speed
            return Setpoint(
                position_deg=v["angle_deg"],
                speed_rad_s=speed,
                kp=2048,
                kd=0,
                current_a=full_current,
                model=model,
            )
        if mode is ControlMode.VELOCITY:
            return Setpoint(
                position_deg=0.0,
                speed_rad_s=math.radians(v["speed_dps"]),
                kp=0,
                kd=0,
                current_a=full_current,
                model=model,
            )
        return Setpoint(position_deg=0.0, speed_rad_s=0.0, kp=0, kd=0, current_a=v["current_a"], model=model)

    def first(codec: BoundCodec, v: Values) -> Sequence[Command]:
        point = setpoint(codec, v)  # checked (and refused) before the mode changes
        return (SelectMode(mode=mode), point, Start())

    return Op(
        first=first,
        repeat=lambda codec, v: (setpoint(codec, v),),
        current_limit=mode is not ControlMode.TORQUE,
        speed_limit=mode is ControlMode.POSITION,  # (V is the position mode's maximum speed)
    )


def _absolute_only(op: Op) -> Op:
    def first(codec: BoundCodec, v: Values) -> Sequence[Command]:
        if v["relative"]:
            raise ValueError("hollow motors: --relative needs their extended CAN mode; give the angle")
        return op.first(codec, v)

    return Op(first=first, repeat=op.repeat, current_limit=op.current_limit, speed_limit=op.speed_limit)


def _zero(codec: BoundCodec, v: Values) -> Sequence[Command]:
    _classic(codec, "the zero command")
    return (Stop(), SetZero())  # only while not enabled (§4.1)


CLI = CliFamily(
    ops={
        "move": _absolute_only(_setpoint(ControlMode.POSITION)),
        "speed": _setpoint(ControlMode.VELOCITY),
        "torque": _setpoint(ControlMode.TORQUE),
        "zero": Op(first=_zero, note="the zero holds until power-off (the hollow zero is not saved)"),
    },
    why_not={
        "status": "the protocol has no read-only request; each set-point's reply carries the state",
        "mit": "their position set-point (servobus move) is the hollow position-speed-current loop",
        "brake": "the hollow protocol has no brake command",
        "clear-errors": "the hollow protocol has no error state",
        "set-id": "the hollow id is set through the converter's configuration frames",
        "reset": "the hollow protocol has no reset request",
    },
    status=(),
)
