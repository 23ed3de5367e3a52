"""LK-TECH's part of the command line (V2.36 / V2.35): what each CLI command sends, the settings
``servobus config`` reads and writes, and the status reads.

Imported only when the CLI is asked for this family (``FAMILY.part("cli")``); the contract is
:mod:`servobus.cli.plugin`'s.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from servobus.cli.plugin import (
    CliFamily,
    Op,
    Setting,
    Values,
    build,
    move,
    once,
    parse_int,
    setpoint,
    setting_of,
)
from servobus.protocols import BoundCodec, Command
from servobus.protocols.lk import (
    BrakeAction,
    BrakeControl,
    ClearErrors,
    ControlParam,
    IncrementalPositionSpeed,
    MultiTurnPositionSpeed,
    PidGains,
    ReadAcceleration,
    ReadControlParam,
    ReadMultiTurnAngle,
    ReadStatus1,
    ReadStatus2,
    Revision,
    SetZeroRom,
    SpeedControl,
    SpeedControlV235,
    TorqueControl,
    WriteAcceleration,
    WriteControlParam,
)
from servobus.protocols.lk.commands_control import TORQUE_LIMIT

__all__ = ["CLI"]


def _speed(codec: BoundCodec, v: Values) -> Command:
    """0xA2 with ``--max-current-a``, or the motor type's full scale (MF/MG: 2048 counts in A; MH/MS,
    which have no ampere scale: 2048 raw counts)."""
    limit = v.get("max_current_a")
    if codec.revision is Revision.V2_35:
        if limit is not None:
            raise ValueError("LK V2.35's speed command carries no current limit: drop --max-current-a")
        return SpeedControlV235(speed_dps=v["speed_dps"])
    motor_type = codec.model.motor_type
    amps = TORQUE_LIMIT.field(motor_type)
    if limit is None and amps is None:
        return SpeedControl(
            speed_dps=v["speed_dps"], motor_type=motor_type, iq_limit_counts=TORQUE_LIMIT.max_counts
        )
    full = amps.hi if amps is not None else None
    return SpeedControl(
        speed_dps=v["speed_dps"], motor_type=motor_type, current_limit_a=full if limit is None else limit
    )


def _torque(codec: BoundCodec, v: Values) -> Command:
    return TorqueControl(motor_type=codec.model.motor_type, current_a=v["current_a"])


def _brake(codec: BoundCodec, v: Values) -> Command:
    return BrakeControl(action=BrakeAction.ENGAGE if v["lock"] else BrakeAction.RELEASE)


OPS: dict[str, Op] = {
    "move": move(
        build(MultiTurnPositionSpeed),
        build(IncrementalPositionSpeed, increment_deg="angle_deg"),
        angle=ReadMultiTurnAngle,
        reads=(ReadStatus2,),
        angle_in_reply=False,  # the set-points' replies carry the encoder, not the angle
    ),
    "speed": setpoint(_speed, current_limit=True),
    "torque": setpoint(_torque),
    "brake": once(_brake),
    "zero": once(build(SetZeroRom), rom=True, note="the new zero takes effect after a power cycle"),
    "clear-errors": once(build(ClearErrors)),
}

WHY_NOT = {
    "mit": "the LK protocol has no motion (MIT) mode",
    "set-id": "the id is set with the vendor's tool (V2.36 setting 05 0A is not in the CLI)",
    "reset": "the LK protocol has no reset request",
}


def _pid_gains(text: str) -> PidGains:
    parts = text.split(",")
    if len(parts) != 3:
        raise ValueError(f"{text!r}: give kp,ki,kd (three integers)")
    kp, ki, kd = (int(p, 0) for p in parts)
    return PidGains(kp=kp, ki=ki, kd=kd)


#: the V2.36 control parameters that hold one number: key and what it is
_RAW: dict[ControlParam, tuple[str, str]] = {
    ControlParam.TORQUE_LIMIT: (
        "torque_limit_counts",
        "torque-current limit, iq counts (MS 0..850, else 0..2000)",
    ),
    ControlParam.SPEED_LIMIT: ("speed_limit_raw", "speed limit, raw (0.01 dps likely)"),
    ControlParam.ANGLE_UPPER_LIMIT: ("limit.angle_upper_raw", "upper angle limit, raw (0.01 deg likely)"),
    ControlParam.ANGLE_LOWER_LIMIT: ("limit.angle_lower_raw", "lower angle limit, raw (0.01 deg likely)"),
    ControlParam.SPEED_RAMP: ("speed_ramp_raw", "speed ramp, raw (0.01 dps/s likely)"),
}


def _settings() -> list[Setting]:
    out = []
    for param in ControlParam:
        loop = param.name.removesuffix("_PID").lower()
        if param.name.endswith("_PID"):
            key, text = f"pid.{loop}", f"{loop} loop PID gains kp,ki,kd"
            parse: Callable[[str], Any] = _pid_gains
        else:
            key, text = _RAW[param]
            parse = parse_int
        out.append(
            setting_of(
                key,
                f"{text} (V2.36, RAM)",
                read=ReadControlParam,
                write=WriteControlParam,
                keys={"param": param},
                parse=parse,
            )
        )
    out.append(
        setting_of(
            "acceleration_dps2",
            "acceleration limit, dps/s (V2.35, RAM)",
            read=ReadAcceleration,
            write=WriteAcceleration,
        )
    )
    return out


CLI = CliFamily(
    ops=OPS,
    why_not=WHY_NOT,
    status=(ReadStatus1, ReadStatus2, ReadMultiTurnAngle),
    settings=_settings(),
)
