"""LK-TECH's part of the command line (V2.36 / V2.35): what each CLI command sends, the settings
``servobus config`` reads and writes, and the status reads.

Imported only when the CLI is asked for this family (``FAMILY.part("cli")``); the contract is
:mod:`servobus.protocols.cli`'s.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from servobus.protocols import BoundCodec, Command, lk
from servobus.protocols import cli as plugin
from servobus.protocols.lk.commands_control import TORQUE_LIMIT

__all__ = ["CLI"]


def _speed(codec: BoundCodec, v: plugin.Values) -> Command:
    """0xA2 with ``--max-current-a``, or the motor type's full scale (MF/MG: 2048 counts in A; MH/MS,
    which have no ampere scale: 2048 raw counts)."""
    limit = v.get("max_current_a")
    if codec.revision is lk.Revision.V2_35:
        if limit is not None:
            raise ValueError("LK V2.35's speed command carries no current limit: drop --max-current-a")
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


def _torque(codec: BoundCodec, v: plugin.Values) -> Command:
    return lk.TorqueControl(motor_type=codec.model.motor_type, current_a=v["current_a"])


def _brake(codec: BoundCodec, v: plugin.Values) -> Command:
    return lk.BrakeControl(action=lk.BrakeAction.ENGAGE if v["lock"] else lk.BrakeAction.RELEASE)


OPS: dict[str, plugin.Op] = {
    "move": plugin.move(
        plugin.build(lk.MultiTurnPositionSpeed),
        plugin.build(lk.IncrementalPositionSpeed, increment_deg="angle_deg"),
        angle=lk.ReadMultiTurnAngle,
        reads=(lk.ReadStatus2,),
        angle_in_reply=False,  # the set-points' replies carry the encoder, not the angle
    ),
    "speed": plugin.setpoint(_speed, current_limit=True),
    "torque": plugin.setpoint(_torque),
    "brake": plugin.once(_brake),
    "zero": plugin.once(
        plugin.build(lk.SetZeroRom), rom=True, note="the new zero takes effect after a power cycle"
    ),
    "clear-errors": plugin.once(plugin.build(lk.ClearErrors)),
}

WHY_NOT = {
    "mit": "the LK protocol has no motion (MIT) mode",
    "set-id": "the id is set with the vendor's tool (V2.36 setting 05 0A is not in the CLI)",
    "reset": "the LK protocol has no reset request",
}


def _pid_gains(text: str) -> lk.PidGains:
    parts = text.split(",")
    if len(parts) != 3:
        raise ValueError(f"{text!r}: give kp,ki,kd (three integers)")
    kp, ki, kd = (int(p, 0) for p in parts)
    return lk.PidGains(kp=kp, ki=ki, kd=kd)


#: the V2.36 control parameters that hold one number: key and what it is
_RAW: dict[lk.ControlParam, tuple[str, str]] = {
    lk.ControlParam.TORQUE_LIMIT: (
        "torque_limit_counts",
        "torque-current limit, iq counts (MS 0..850, else 0..2000)",
    ),
    lk.ControlParam.SPEED_LIMIT: ("speed_limit_raw", "speed limit, raw (0.01 dps likely)"),
    lk.ControlParam.ANGLE_UPPER_LIMIT: ("limit.angle_upper_raw", "upper angle limit, raw (0.01 deg likely)"),
    lk.ControlParam.ANGLE_LOWER_LIMIT: ("limit.angle_lower_raw", "lower angle limit, raw (0.01 deg likely)"),
    lk.ControlParam.SPEED_RAMP: ("speed_ramp_raw", "speed ramp, raw (0.01 dps/s likely)"),
}


def _settings() -> list[plugin.Setting]:
    out = []
    for param in lk.ControlParam:
        loop = param.name.removesuffix("_PID").lower()
        if param.name.endswith("_PID"):
            key, text = f"pid.{loop}", f"{loop} loop PID gains kp,ki,kd"
            parse: Callable[[str], Any] = _pid_gains
        else:
            key, text = _RAW[param]
            parse = plugin.parse_int
        out.append(
            plugin.setting_of(
                key,
                f"{text} (V2.36, RAM)",
                read=lk.ReadControlParam,
                write=lk.WriteControlParam,
                keys={"param": param},
                parse=parse,
            )
        )
    out.append(
        plugin.setting_of(
            "acceleration_dps2",
            "acceleration limit, dps/s (V2.35, RAM)",
            read=lk.ReadAcceleration,
            write=lk.WriteAcceleration,
        )
    )
    return out


CLI = plugin.CliFamily(
    ops=OPS,
    why_not=WHY_NOT,
    status=(lk.ReadStatus1, lk.ReadStatus2, lk.ReadMultiTurnAngle),
    settings=_settings(),
)
