"""MyActuator's part of the command line (V4.3 / V4.4): what each CLI command sends, the settings
``servobus config`` reads and writes, the status reads, and what ``scan`` asks a motor.

Imported only when the CLI is asked for this family (``FAMILY.part("cli")``); the contract is
:mod:`servobus.cli.plugin`'s.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from servobus.cli.plugin import (
    CliFamily,
    Op,
    Query,
    Setting,
    Values,
    build,
    move,
    once,
    parse_bool,
    parse_int,
    setpoint,
    setting_of,
)
from servobus.protocols import BoundCodec, Command, Reply
from servobus.protocols.myactuator import (
    AbsolutePositionControl,
    AccelIndex,
    BrakeLock,
    BrakeRelease,
    FunctionControl,
    IncrementalPositionControl,
    ModelPartReply,
    MotionCommand,
    PidIndex,
    ReadAcceleration,
    ReadModel,
    ReadModelPart,
    ReadMultiTurnAngle,
    ReadPid,
    ReadRunMode,
    ReadStatus1,
    ReadStatus2,
    ReadVersionDate,
    Revision,
    SetCommTimeout,
    SpeedControl,
    SystemReset,
    TorqueControl,
    WriteAcceleration,
    WriteCurrentPositionAsZero,
    WritePidRam,
    WritePidRom,
    join_model,
    revision_from_version_date,
)

__all__ = ["CLI"]


def _mit(codec: BoundCodec, v: Values) -> Command:
    return MotionCommand(
        position_rad=v["position_rad"],
        velocity_rad_s=v["velocity_rad_s"],
        kp=v["kp"],
        kd=v["kd"],
        torque_ff_nm=v["torque_ff_nm"],
        scales=codec.model,  # the revision's ranges
    )


def _brake(codec: BoundCodec, v: Values) -> Command:
    return BrakeLock() if v["lock"] else BrakeRelease()


_RESET_NOTE = "takes effect after a reset (servobus reset)"

OPS: dict[str, Op] = {
    "move": move(
        build(AbsolutePositionControl),
        build(IncrementalPositionControl),
        angle=ReadMultiTurnAngle,
        reads=(ReadStatus2,),
    ),
    "speed": setpoint(build(SpeedControl)),
    "torque": setpoint(build(TorqueControl)),
    "mit": setpoint(_mit),
    "brake": once(_brake),
    "zero": once(build(WriteCurrentPositionAsZero), rom=True, note=f"the new zero {_RESET_NOTE}"),
    "set-id": once(
        lambda codec, v: FunctionControl.set_can_id(v["new_id"]), rom=True, note=f"the new id {_RESET_NOTE}"
    ),
    "reset": once(build(SystemReset)),
}

WHY_NOT = {
    "clear-errors": "V4.3/V4.4 define no clear-errors request; an error clears when its cause is gone "
    "(V4.4: 0x20 index 8 auto-recovery), or try servobus reset",
}


def _settings() -> list[Setting]:
    out = [
        setting_of(
            f"pid.{index.name.lower()}",
            f"PID parameter {index.name} (float32; RAM, or ROM with --rom)",
            read=ReadPid,
            write=WritePidRam,
            rom_write=WritePidRom,
            keys={"index": index},
        )
        for index in PidIndex
    ]
    out += [
        setting_of(
            f"{accel.name.lower()}_dps_s",
            f"{accel.name.lower().replace('_', ' ')}, 100..60000 dps/s or 'none' (no planning)",
            read=ReadAcceleration,
            write=WriteAcceleration,
            keys={"index": accel},
            rom=True,
        )
        for accel in AccelIndex
    ]
    out.append(
        setting_of(
            "comm_timeout_ms",
            "communication-interruption protection (0xB3): output off after this silence; 'off' disables it",
            write=SetCommTimeout,
            rom=True,
        )
    )
    # 0x20 function control: one command for several settings, each index its own meaning
    f = FunctionControl
    functions: tuple[tuple[str, str, Any, Any], ...] = (
        (
            "can_id_filter",
            "CAN-id filter on/off (0x20 index 2; off lets 0x280 broadcasts in)",
            parse_bool,
            f.can_id_filter,
        ),
        (
            "error_reporting",
            "send 0x9A every 100 ms while an error is present, on/off (0x20 index 3)",
            parse_bool,
            f.error_reporting,
        ),
        (
            "limit.max_positive_angle_raw",
            "maximum positive angle, raw int32 (0x20 index 6; no unit stated, likely 0.01 deg)",
            parse_int,
            f.max_positive_angle,
        ),
        (
            "limit.max_negative_angle_raw",
            "maximum negative angle, raw int32 (0x20 index 7; as index 6)",
            parse_int,
            f.max_negative_angle,
        ),
    )
    for key, text, parse, make in functions:
        out.append(Setting(key=key, help=text, parse=parse, write=_function(make), rom=True))
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
    return {"firmware": str(version), "revision": revision_from_version_date(version).name}


def _describe_reads(codec: BoundCodec) -> Sequence[Command]:
    """Model (0xB5, in the motor's revision's form) and operating mode (0x70)."""
    if codec.revision is Revision.V4_4:
        return (*(ReadModelPart(part=part) for part in (1, 2, 3)), ReadRunMode())
    return (ReadModel(), ReadRunMode())


def _describe_columns(codec: BoundCodec, replies: Sequence[Reply | None]) -> dict[str, Any]:
    *model, mode = replies
    out: dict[str, Any] = {}
    if codec.revision is Revision.V4_4:
        out["model"] = join_model(p for p in model if isinstance(p, ModelPartReply))
    else:
        out["model"] = getattr(model[0], "model", None)
    run_mode = getattr(mode, "mode", None)
    if run_mode is not None:
        out["state"] = run_mode
    return out


CLI = CliFamily(
    ops=OPS,
    why_not=WHY_NOT,
    status=(ReadStatus1, ReadStatus2),
    settings=_settings(),
    identify=Query(reads=lambda codec: (ReadVersionDate(),), columns=_identify_columns),
    describe=Query(reads=_describe_reads, columns=_describe_columns),
)
