"""The audit of the hollow series' encoder fields: every raw value that is not its number (issue 19).

One :class:`~servobus.protocols._special.SpecialValue` per command field, with the section of hollow.md.
The hollow protocol has no numeric "0 = off" field: its special meanings are frame patterns, addresses
and flags, each requested by a class, builder or bool of its own.
"""

from __future__ import annotations

from servobus.protocols._special import SpecialValue
from servobus.protocols.hollow import commands as cmd
from servobus.protocols.hollow import commands_fd as fd
from servobus.protocols.hollow import rs485

__all__ = ["SPECIAL_VALUES"]

_SPECIAL_FRAME = "FF x7 + F9..FE"
_SPECIAL_MEANING = (
    "a special command (start, stop, mode, zero), not a setpoint; a setpoint whose codes would read so has "
    "its position code lowered from 0xFFFF to 0xFFFE (one 1/32768-turn count, the documented rounding)"
)

SPECIAL_VALUES: tuple[SpecialValue, ...] = (
    SpecialValue(
        "hollow",
        cmd.Setpoint,
        "whole frame",
        _SPECIAL_FRAME,
        _SPECIAL_MEANING,
        "§4.1",
        "Start(), Stop(), SelectMode(mode=...), SetZero()",
    ),
    SpecialValue(
        "hollow",
        cmd.IncrementalSetpoint,
        "whole frame",
        _SPECIAL_FRAME,
        _SPECIAL_MEANING,
        "§4.1, §5.2",
        "Start(), Stop(), SelectMode(mode=...), SetZero()",
    ),
    SpecialValue(
        "hollow",
        fd.FdCommand,
        "zero",
        "D15 = 1",
        "re-zero on every frame while set (only while stopped; not persisted)",
        "§7.2",
        "zero=True (a bool)",
        offset=15,
    ),
    SpecialValue(
        "hollow",
        rs485.ModbusWrite,
        "slave_id",
        "0",
        "Modbus broadcast: every motor takes it, none answers",
        "§9.5",
        "cannot be sent (refused); decoding refuses it too",
        offset=0,
    ),
    SpecialValue(
        "hollow",
        rs485.ModbusRead,
        "slave_id",
        "0",
        "Modbus broadcast: every motor takes it, none answers",
        "§9.5",
        "cannot be sent (refused); decoding refuses it too",
        offset=0,
    ),
)
