"""The settings ``servobus config`` reads and writes, one table per family, units in the key names.

Each :class:`Setting` says how to parse a value from the command line, which command reads it (and
which field of the reply holds it), which command writes it, and whether the write reaches the
motor's ROM (then the CLI asks first). The command classes check the ranges (ValueError naming the
field and its limits, before anything is sent); the revision checks are the bound codec's.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import click

from servobus.protocols import Command, Reply

__all__ = ["SETTINGS", "Setting", "setting"]


@dataclass(frozen=True, slots=True)
class Setting:
    """One setting of one family.

    Attributes:
        key: its name on the command line (units in it where it has one).
        help: what it is, in a line.
        parse: the command line's text -> the value the write takes (ValueError for bad text).
        read: the command that reads it (None: the motor cannot report it).
        field: the reply's field that holds the value read.
        write: (value, to_rom) -> the command that writes it (None: read-only).
        rom: True: every write reaches ROM; False: RAM only; None: RAM, or ROM with ``--rom``.
    """

    key: str
    help: str
    parse: Callable[[str], Any]
    read: Callable[[], Command] | None = None
    field: str = "value"
    write: Callable[[Any, bool], Command] | None = None
    rom: bool | None = False

    def value_of(self, reply: Reply | None) -> Any:
        """The value in the reply to :attr:`read`."""
        return getattr(reply, self.field, None)


def _float(text: str) -> float:
    return float(text)


def _float_or_none(text: str) -> float | None:
    return None if text.lower() in ("none", "off") else float(text)


def _int_or_none(text: str) -> int | None:
    return None if text.lower() in ("none", "off") else _int(text)


def _bool(text: str) -> bool:
    lowered = text.lower()
    if lowered in ("on", "1", "true", "yes"):
        return True
    if lowered in ("off", "0", "false", "no"):
        return False
    raise ValueError(f"{text!r} is not on or off")


def _int(text: str) -> int:
    """A whole number: decimal, ``0x``/``0o``/``0b``, or a float that is one (``1e3``, ``200.0``: the
    range check then names the limits, where int() would say "invalid literal")."""
    try:
        return int(text, 0)
    except ValueError:
        pass
    try:
        number = float(text)
    except ValueError:
        raise ValueError("not a number") from None
    if not number.is_integer():
        raise ValueError("not a whole number")
    return int(number)


# ---- MyActuator ----


def _myactuator() -> list[Setting]:
    from servobus.protocols import myactuator as ma

    out = []
    for index in ma.PidIndex:

        def write_pid(value: float, rom: bool, index: ma.PidIndex = index) -> Command:
            return (ma.WritePidRom if rom else ma.WritePidRam)(index=index, value=value)

        out.append(
            Setting(
                key=f"pid.{index.name.lower()}",
                help=f"PID parameter {index.name} (float32; RAM, or ROM with --rom)",
                parse=_float,
                read=functools.partial(ma.ReadPid, index=index),
                write=write_pid,
                rom=None,
            )
        )
    for accel in ma.AccelIndex:
        out.append(
            Setting(
                key=f"{accel.name.lower()}_dps_s",
                help=f"{accel.name.lower().replace('_', ' ')}, 100..60000 dps/s or 'none' (no planning)",
                parse=_float_or_none,
                read=functools.partial(ma.ReadAcceleration, index=accel),
                field="acceleration_dps_s",
                write=_write_acceleration(accel),
                rom=True,
            )
        )
    f = ma.FunctionControl
    out += [
        Setting(
            key="comm_timeout_ms",
            help="communication-interruption protection (0xB3): output off after this silence; "
            "'off' disables it",
            parse=_int_or_none,
            write=lambda value, rom: ma.SetCommTimeout(timeout_ms=value),
            rom=True,
        ),
        Setting(
            key="can_id_filter",
            help="CAN-id filter on/off (0x20 index 2; off lets 0x280 broadcasts in)",
            parse=_bool,
            write=lambda value, rom: f.can_id_filter(value),
            rom=True,
        ),
        Setting(
            key="error_reporting",
            help="send 0x9A every 100 ms while an error is present, on/off (0x20 index 3)",
            parse=_bool,
            write=lambda value, rom: f.error_reporting(value),
            rom=True,
        ),
        Setting(
            key="limit.max_positive_angle_raw",
            help="maximum positive angle, raw int32 (0x20 index 6; no unit stated, likely 0.01 deg)",
            parse=_int,
            write=lambda value, rom: f.max_positive_angle(value),
            rom=True,
        ),
        Setting(
            key="limit.max_negative_angle_raw",
            help="maximum negative angle, raw int32 (0x20 index 7; as index 6)",
            parse=_int,
            write=lambda value, rom: f.max_negative_angle(value),
            rom=True,
        ),
    ]
    return out


def _write_acceleration(index: Any) -> Callable[[Any, bool], Command]:
    from servobus.protocols import myactuator as ma

    def write(value: Any, rom: bool) -> Command:
        return ma.WriteAcceleration(index=index, acceleration_dps_s=value)

    return write


# ---- LK ----


def _write_control(param: Any) -> Callable[[Any, bool], Command]:
    from servobus.protocols import lk

    def write(value: Any, rom: bool) -> Command:
        return lk.WriteControlParam(param=param, value=value)

    return write


def _pid_gains(text: str) -> Any:
    from servobus.protocols.lk import PidGains

    parts = text.split(",")
    if len(parts) != 3:
        raise ValueError(f"{text!r}: give kp,ki,kd (three integers)")
    kp, ki, kd = (int(p, 0) for p in parts)
    return PidGains(kp=kp, ki=ki, kd=kd)


def _lk() -> list[Setting]:
    from servobus.protocols import lk

    out = []
    raw = {
        lk.ControlParam.TORQUE_LIMIT: (
            "torque_limit_counts",
            "torque-current limit, iq counts (MS 0..850, else 0..2000)",
        ),
        lk.ControlParam.SPEED_LIMIT: ("speed_limit_raw", "speed limit, raw (0.01 dps likely)"),
        lk.ControlParam.ANGLE_UPPER_LIMIT: (
            "limit.angle_upper_raw",
            "upper angle limit, raw (0.01 deg likely)",
        ),
        lk.ControlParam.ANGLE_LOWER_LIMIT: (
            "limit.angle_lower_raw",
            "lower angle limit, raw (0.01 deg likely)",
        ),
        lk.ControlParam.SPEED_RAMP: ("speed_ramp_raw", "speed ramp, raw (0.01 dps/s likely)"),
    }
    for param in lk.ControlParam:
        if param.name.endswith("_PID"):
            key = f"pid.{param.name.removesuffix('_PID').lower()}"
            text = f"{param.name.removesuffix('_PID').lower()} loop PID gains kp,ki,kd (V2.36, RAM)"
            parse: Callable[[str], Any] = _pid_gains
        else:
            key, text = raw[param]
            text += " (V2.36, RAM)"
            parse = _int
        out.append(
            Setting(
                key=key,
                help=text,
                parse=parse,
                read=functools.partial(lk.ReadControlParam, param=param),
                write=_write_control(param),
            )
        )
    out.append(
        Setting(
            key="acceleration_dps2",
            help="acceleration limit, dps/s (V2.35, RAM)",
            parse=_float,
            read=lk.ReadAcceleration,
            field="acceleration_dps2",
            write=lambda value, rom: lk.WriteAcceleration(acceleration_dps2=value),
        )
    )
    return out


SETTINGS: dict[str, Callable[[], list[Setting]]] = {"myactuator": _myactuator, "lk": _lk, "hollow": list}


def settings(family: str) -> dict[str, Setting]:
    """The family's settings by key."""
    return {s.key: s for s in SETTINGS.get(family, list)()}


def setting(family: str, key: str) -> Setting:
    """The setting ``key`` of ``family``.

    Raises:
        click.BadParameter: no such key for the family (exit 2), naming the keys there are.
    """
    known = settings(family)
    if not known:
        raise click.UsageError(f"{family} motors have no settings the CLI can read or write")
    found = known.get(key)
    if found is None:
        raise click.BadParameter(
            f"{family} motors have no setting {key!r} (servobus config list --family {family})",
            param_hint="KEY",
        )
    return found
