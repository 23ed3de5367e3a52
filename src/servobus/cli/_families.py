"""Which command class each CLI command sends, one small table per family.

A command the CLI offers maps to an :class:`Op`: the commands to send once, in order (``first``), and
for set-points the ones to resend at the command's rate (``repeat``): the set-point again where
resending it changes nothing (an absolute target, a speed, a current), and the reads that show where
the motor is where the set-point's reply does not say (LK's angle) or where the set-point must not
be resent (an increment, which every resend would add again). Every builder takes the motor's
bound codec (revision, model, link) and the command line's values in the units their option names
carry; the command classes check ranges and raise ValueError naming field and limit, before
anything is sent. A command a family has no entry for is refused in one line (exit 2) by
:func:`op`, with the reason where there is one (:data:`WHY_NOT`).
"""

from __future__ import annotations

import functools
import importlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import click

from servobus.protocols import Command

__all__ = ["TABLES", "Op", "op", "status_reads"]

Values = Mapping[str, Any]
Build = Callable[[Any, Values], Sequence[Command]]
Repeat = Callable[[Any, Values], Sequence[Command]]


@dataclass(frozen=True, slots=True)
class Op:
    """What one CLI command sends to one motor.

    Attributes:
        first: the commands sent once, in order (the reply to the last one is shown).
        repeat: for set-points, the commands sent again at the command's rate, in order (None:
            one-shot); their replies together are the motor's status. Only commands that may be
            repeated: an absolute set-point, a read; never an increment.
        rom: it writes the motor's ROM or changes its id: ask first (``--yes`` skips).
        note: said after it succeeded (what else the user must do).
        current_limit: its set-point carries a current limit (``--max-current-a``; without it, the
            motor's full scale); a command without one refuses the option.
    """

    first: Build
    repeat: Repeat | None = None
    rom: bool = False
    note: str = ""
    current_limit: bool = False


def _once(make: Callable[[Any, Values], Command], **options: Any) -> Op:
    return Op(first=lambda codec, v: (make(codec, v),), **options)


def _setpoint(make: Callable[[Any, Values], Command], *, current_limit: bool = False) -> Op:
    return Op(
        first=lambda codec, v: (make(codec, v),),
        repeat=lambda codec, v: (make(codec, v),),
        current_limit=current_limit,
    )


def _move(absolute: Callable[[Any, Values], Command], relative: Callable[[Any, Values], Command]) -> Op:
    """An absolute move resends its target; a relative one reads the angle, sends the increment once,
    then only reads (the reply to ``first[0]`` is the angle it started from)."""

    def first(codec: Any, v: Values) -> Sequence[Command]:
        if v["relative"]:
            return (_angle_read(codec), relative(codec, v))
        return (absolute(codec, v),)

    def repeat(codec: Any, v: Values) -> Sequence[Command]:
        if v["relative"]:
            return (_angle_read(codec), *_reads(codec.family, ("ReadStatus2",)))
        return (absolute(codec, v), *_angle_reads(codec))

    return Op(first=first, repeat=repeat)


def _angle_read(codec: Any) -> Command:
    """The multi-turn angle read (MyActuator 0x92, LK 0x92: degrees, the position set-points' scale)."""
    return _reads(codec.family, ("ReadMultiTurnAngle",))[0]


def _angle_reads(codec: Any) -> Sequence[Command]:
    """What an absolute move adds to its set-point to know the angle: nothing where the set-point's
    reply carries it (MyActuator), the angle read where it does not (LK)."""
    return (_angle_read(codec),) if codec.family == "lk" else ()


def _build(family: str, name: str, **fields: str) -> Callable[[Any, Values], Command]:
    """A builder of ``servobus.protocols.<family>.<name>``: each ``field="key"`` takes the command
    line's value ``key`` (imported when it runs: the CLI loads no family it does not use)."""

    def make(codec: Any, v: Values) -> Command:
        cls: Callable[..., Command] = getattr(importlib.import_module(f"servobus.protocols.{family}"), name)
        return cls(**{field: v[key] for field, key in fields.items()})

    return make


_ma = functools.partial(_build, "myactuator")
_lk = functools.partial(_build, "lk")


def _safe(kind: str) -> Op:
    return _once(lambda codec, v: codec.safe_command(kind))


# ---- MyActuator (V4.3 / V4.4) ----


def _ma_mit(codec: Any, v: Values) -> Command:
    from servobus.protocols.myactuator import MotionCommand

    return MotionCommand(
        position_rad=v["position_rad"],
        velocity_rad_s=v["velocity_rad_s"],
        kp=v["kp"],
        kd=v["kd"],
        torque_ff_nm=v["torque_ff_nm"],
        scales=codec.model,  # the revision's ranges
    )


def _ma_set_id(codec: Any, v: Values) -> Command:
    from servobus.protocols.myactuator import FunctionControl

    return FunctionControl.set_can_id(v["new_id"])


MYACTUATOR: dict[str, Op] = {
    "status": Op(first=lambda codec, v: _reads("myactuator", ("ReadStatus1", "ReadStatus2"))),
    "move": _move(
        _ma("AbsolutePositionControl", angle_deg="angle_deg", max_speed_dps="max_speed_dps"),
        _ma("IncrementalPositionControl", angle_deg="angle_deg", max_speed_dps="max_speed_dps"),
    ),
    "speed": _setpoint(_ma("SpeedControl", speed_dps="speed_dps")),
    "torque": _setpoint(_ma("TorqueControl", current_a="current_a")),
    "mit": _setpoint(_ma_mit),
    "stop": _safe("stop"),
    "off": _safe("shutdown"),
    "brake": _once(lambda codec, v: _ma("BrakeLock" if v["lock"] else "BrakeRelease")(codec, v)),
    "zero": _once(
        _ma("WriteCurrentPositionAsZero"),
        rom=True,
        note="the new zero takes effect after a reset (servobus reset)",
    ),
    "set-id": _once(_ma_set_id, rom=True, note="the new id takes effect after a reset (servobus reset)"),
    "reset": _once(_ma("SystemReset")),
}


# ---- LK-TECH (V2.36 / V2.35) ----


def _lk_v235(codec: Any) -> bool:
    return str(codec.revision.name) == "V2_35"


def _lk_speed(codec: Any, v: Values) -> Command:
    """0xA2 with ``--max-current-a``, or the motor type's full scale (MF/MG: 2048 counts in A; MH/MS,
    which have no ampere scale: 2048 raw counts)."""
    from servobus.protocols import lk
    from servobus.protocols.lk.commands_control import TORQUE_LIMIT

    limit = v.get("max_current_a")
    if _lk_v235(codec):
        if limit is not None:
            raise click.UsageError("LK V2.35's speed command carries no current limit: drop --max-current-a")
        return lk.SpeedControlV235(speed_dps=v["speed_dps"])
    motor_type = codec.model.motor_type
    amps = TORQUE_LIMIT.field(motor_type)
    if limit is None and amps is None:
        return lk.SpeedControl(
            speed_dps=v["speed_dps"], motor_type=motor_type, iq_limit_counts=TORQUE_LIMIT.max_counts
        )
    full = amps.hi if amps is not None else None
    return lk.SpeedControl(
        speed_dps=v["speed_dps"], motor_type=motor_type, current_limit_a=full if limit is None else limit
    )


def _lk_torque(codec: Any, v: Values) -> Command:
    from servobus.protocols import lk

    return lk.TorqueControl(motor_type=codec.model.motor_type, current_a=v["current_a"])


def _lk_brake(codec: Any, v: Values) -> Command:
    from servobus.protocols import lk

    return lk.BrakeControl(action=lk.BrakeAction.ENGAGE if v["lock"] else lk.BrakeAction.RELEASE)


LK: dict[str, Op] = {
    "status": Op(first=lambda codec, v: _reads("lk", ("ReadStatus1", "ReadStatus2", "ReadMultiTurnAngle"))),
    "move": _move(
        _lk("MultiTurnPositionSpeed", angle_deg="angle_deg", max_speed_dps="max_speed_dps"),
        _lk("IncrementalPositionSpeed", increment_deg="angle_deg", max_speed_dps="max_speed_dps"),
    ),
    "speed": _setpoint(_lk_speed, current_limit=True),
    "torque": _setpoint(_lk_torque),
    "stop": _safe("stop"),
    "off": _safe("shutdown"),
    "brake": _once(_lk_brake),
    "zero": _once(_lk("SetZeroRom"), rom=True, note="the new zero takes effect after a power cycle"),
    "clear-errors": _once(_lk("ClearErrors")),
}


# ---- hollow series (classic CAN set-points; stop on every link) ----


def _classic(codec: Any, what: str) -> None:
    if codec.link != "can":
        raise click.UsageError(
            f"hollow motors on {codec.link}: the CLI sends {what} on classic CAN only (drop --fd/--port)"
        )


def _ho_setpoint(mode: str) -> Op:
    """SelectMode, a first set-point, Start; then the set-point again at the rate (§4.1-§4.4)."""

    def setpoint(codec: Any, v: Values) -> Command:
        from servobus.protocols import hollow as ho

        _classic(codec, "set-points")
        model = codec.model
        full_speed = model.speed_full_scale_rad_s
        limit = v.get("max_current_a")  # move and speed: --max-current-a, or I_fs
        full_current = model.current_full_scale_a if limit is None else limit
        if mode == "POSITION":
            speed = math.radians(v["max_speed_dps"]) if v["max_speed_dps"] is not None else full_speed
            return ho.Setpoint(
                position_deg=v["angle_deg"],
                speed_rad_s=speed,
                kp=2048,
                kd=0,
                current_a=full_current,
                model=model,
            )
        if mode == "VELOCITY":
            return ho.Setpoint(
                position_deg=0.0,
                speed_rad_s=math.radians(v["speed_dps"]),
                kp=0,
                kd=0,
                current_a=full_current,
                model=model,
            )
        return ho.Setpoint(
            position_deg=0.0, speed_rad_s=0.0, kp=0, kd=0, current_a=v["current_a"], model=model
        )

    def first(codec: Any, v: Values) -> Sequence[Command]:
        from servobus.protocols import hollow as ho

        point = setpoint(codec, v)  # checked (and refused) before the mode changes
        return (ho.SelectMode(mode=ho.ControlMode[mode]), point, ho.Start())

    return Op(first=first, repeat=lambda codec, v: (setpoint(codec, v),), current_limit=mode != "TORQUE")


def _ho_move_absolute(op: Op) -> Op:
    def first(codec: Any, v: Values) -> Sequence[Command]:
        if v["relative"]:
            raise click.UsageError("hollow motors: --relative needs their extended CAN mode; give the angle")
        return op.first(codec, v)

    return Op(first=first, repeat=op.repeat, current_limit=op.current_limit)


def _ho_zero(codec: Any, v: Values) -> Sequence[Command]:
    from servobus.protocols import hollow as ho

    _classic(codec, "the zero command")
    return (ho.Stop(), ho.SetZero())  # only while not enabled (§4.1)


HOLLOW: dict[str, Op] = {
    "move": _ho_move_absolute(_ho_setpoint("POSITION")),
    "speed": _ho_setpoint("VELOCITY"),
    "torque": _ho_setpoint("TORQUE"),
    "stop": _safe("stop"),
    "off": _safe("shutdown"),
    "zero": Op(first=_ho_zero, note="the zero holds until power-off (the hollow zero is not saved)"),
}

TABLES: dict[str, dict[str, Op]] = {"myactuator": MYACTUATOR, "lk": LK, "hollow": HOLLOW}

#: why a family has no entry, where the manuals say
WHY_NOT: dict[tuple[str, str], str] = {
    ("myactuator", "clear-errors"): (
        "V4.3/V4.4 define no clear-errors request; an error clears when its cause is gone "
        "(V4.4: 0x20 index 8 auto-recovery), or try servobus reset"
    ),
    ("lk", "mit"): "the LK protocol has no motion (MIT) mode",
    ("lk", "set-id"): "the id is set with the vendor's tool (V2.36 setting 05 0A is not in the CLI)",
    ("lk", "reset"): "the LK protocol has no reset request",
    ("hollow", "status"): "the protocol has no read-only request; each set-point's reply carries the state",
    ("hollow", "mit"): "their position set-point (servobus move) is the hollow position-speed-current loop",
    ("hollow", "brake"): "the hollow protocol has no brake command",
    ("hollow", "clear-errors"): "the hollow protocol has no error state",
    ("hollow", "set-id"): "the hollow id is set through the converter's configuration frames",
    ("hollow", "reset"): "the hollow protocol has no reset request",
}


def op(family: str, command: str) -> Op:
    """The table entry of ``command`` for ``family``.

    Raises:
        click.UsageError: the family has no such command (exit 2), with the reason where known.
    """
    entry = TABLES.get(family, {}).get(command)
    if entry is None:
        why = WHY_NOT.get((family, command))
        raise click.UsageError(f"{family} motors have no {command} command" + (f": {why}" if why else ""))
    return entry


def status_reads(family: str) -> Op:
    """The reads ``status``, ``monitor`` and ``scan`` send (refused where the family has none)."""
    return op(family, "status")


def _reads(family: str, names: Sequence[str]) -> Sequence[Command]:
    module = importlib.import_module(f"servobus.protocols.{family}")
    return tuple(getattr(module, name)() for name in names)
