"""MyActuator's part of the command line (V4.3 / V4.4): what each CLI command sends, the settings
``servobus config`` reads and writes, the status reads, and what ``scan`` asks a motor.

Imported only when the CLI is asked for this family (``FAMILY.part("cli")``); the contract is
:mod:`servobus.protocols.cli`'s.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from servobus.protocols import BoundCodec, Command, Reply
from servobus.protocols import cli as plugin
from servobus.protocols import myactuator as ma

__all__ = ["CLI"]


def _mit(codec: BoundCodec, v: plugin.Values) -> Command:
    return ma.MotionCommand(
        position_rad=v["position_rad"],
        velocity_rad_s=v["velocity_rad_s"],
        kp=v["kp"],
        kd=v["kd"],
        torque_ff_nm=v["torque_ff_nm"],
        scales=codec.model,  # the revision's ranges
    )


def _brake(codec: BoundCodec, v: plugin.Values) -> Command:
    return ma.BrakeLock() if v["lock"] else ma.BrakeRelease()


_RESET_NOTE = "takes effect after a reset (servobus reset)"

OPS: dict[str, plugin.Op] = {
    "move": plugin.move(
        plugin.build(ma.AbsolutePositionControl),
        plugin.build(ma.IncrementalPositionControl),
        angle=ma.ReadMultiTurnAngle,
        reads=(ma.ReadStatus2,),
    ),
    "speed": plugin.setpoint(plugin.build(ma.SpeedControl)),
    "torque": plugin.setpoint(plugin.build(ma.TorqueControl)),
    "mit": plugin.setpoint(_mit),
    "brake": plugin.once(_brake),
    "zero": plugin.once(
        plugin.build(ma.WriteCurrentPositionAsZero), rom=True, note=f"the new zero {_RESET_NOTE}"
    ),
    "set-id": plugin.once(
        lambda codec, v: ma.FunctionControl.set_can_id(v["new_id"]),
        rom=True,
        note=f"the new id {_RESET_NOTE}",
    ),
    "reset": plugin.once(plugin.build(ma.SystemReset)),
}

WHY_NOT = {
    "clear-errors": "V4.3/V4.4 define no clear-errors request; an error clears when its cause is gone "
    "(V4.4: 0x20 index 8 auto-recovery), or try servobus reset",
}


def _acceleration(text: str) -> float | None:
    """dps/s, or ``none``/``off``/``0`` for no planning: the motor reports that as 0, so a value read
    (``config dump``) is written back as it was; other numbers below 100 are refused by the write."""
    value = plugin.parse_float_or_none(text)
    return None if value == 0 else value


def _settings() -> list[plugin.Setting]:
    out = [
        plugin.setting_of(
            f"pid.{index.name.lower()}",
            f"PID parameter {index.name} (float32; RAM, or ROM with --rom)",
            read=ma.ReadPid,
            write=ma.WritePidRam,
            rom_write=ma.WritePidRom,
            keys={"index": index},
        )
        for index in ma.PidIndex
    ]
    out += [
        plugin.setting_of(
            f"{accel.name.lower()}_dps_s",
            f"{accel.name.lower().replace('_', ' ')}, 100..60000 dps/s or 'none' (no planning, reads 0)",
            read=ma.ReadAcceleration,
            write=ma.WriteAcceleration,
            keys={"index": accel},
            parse=_acceleration,
            rom=True,
        )
        for accel in ma.AccelIndex
    ]
    out.append(
        plugin.setting_of(
            "comm_timeout_ms",
            "communication-interruption protection (0xB3): output off after this silence; 'off' disables it",
            write=ma.SetCommTimeout,
            rom=True,
        )
    )
    # 0x20 function control: one command for several settings, each index its own meaning
    f = ma.FunctionControl
    functions: tuple[tuple[str, str, Any, Any], ...] = (
        (
            "can_id_filter",
            "CAN-id filter on/off (0x20 index 2; off lets 0x280 broadcasts in)",
            plugin.parse_bool,
            f.can_id_filter,
        ),
        (
            "error_reporting",
            "send 0x9A every 100 ms while an error is present, on/off (0x20 index 3)",
            plugin.parse_bool,
            f.error_reporting,
        ),
        (
            "limit.max_positive_angle_raw",
            "maximum positive angle, raw int32 (0x20 index 6; no unit stated, likely 0.01 deg)",
            plugin.parse_int,
            f.max_positive_angle,
        ),
        (
            "limit.max_negative_angle_raw",
            "maximum negative angle, raw int32 (0x20 index 7; as index 6)",
            plugin.parse_int,
            f.max_negative_angle,
        ),
    )
    for key, text, parse, make in functions:
        out.append(plugin.Setting(key=key, help=text, parse=parse, write=_function(make), rom=True))
    return out


def _function(make: Any) -> Any:
    def write(value: Any, rom: bool) -> Command:
        command: Command = make(value)
        return command

    return write


def _identify_columns(codec: BoundCodec, replies: Sequence[Reply | None]) -> dict[str, Any]:
    """Firmware date and the revision it implies (0xB2 reads the same in V4.3 and V4.4)."""
    version = getattr(replies[0], "version_date", None)
    if not version:
        return {}
    return {"firmware": str(version), "revision": ma.revision_from_version_date(version).name}


def _describe_reads(codec: BoundCodec) -> Sequence[Command]:
    """Model (0xB5, in the motor's revision's form) and operating mode (0x70)."""
    if codec.revision is ma.Revision.V4_4:
        return (*(ma.ReadModelPart(part=part) for part in (1, 2, 3)), ma.ReadRunMode())
    return (ma.ReadModel(), ma.ReadRunMode())


def _describe_columns(codec: BoundCodec, replies: Sequence[Reply | None]) -> dict[str, Any]:
    *model, mode = replies
    out: dict[str, Any] = {}
    if codec.revision is ma.Revision.V4_4:
        out["model"] = ma.join_model(p for p in model if isinstance(p, ma.ModelPartReply))
    else:
        out["model"] = getattr(model[0], "model", None)
    run_mode = getattr(mode, "mode", None)
    if run_mode is not None:
        out["state"] = run_mode
    return out


CLI = plugin.CliFamily(
    ops=OPS,
    why_not=WHY_NOT,
    status=(ma.ReadStatus1, ma.ReadStatus2),
    settings=_settings(),
    identify=plugin.Query(reads=lambda codec: (ma.ReadVersionDate(),), columns=_identify_columns),
    describe=plugin.Query(reads=_describe_reads, columns=_describe_columns),
)
