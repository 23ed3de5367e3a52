"""The audit of LK's encoder fields: every raw value that is not its number (issue 19).

One :class:`~servobus.protocols._special.SpecialValue` per command field, with the section of lk-v2.md.
The LK manuals define no "0 = off" style value; what they leave undefined is maxSpeed 0 (sent only when
asked for with None) and the V2.36 0xA2 torque limit 0 (never sent). Parameter writes (0x42, 0xC1, 0x34)
carry raw values within stated ranges and no special ones.
"""

from __future__ import annotations

from servobus.protocols._special import SpecialValue
from servobus.protocols.lk import commands_control as ctl

__all__ = ["SPECIAL_VALUES"]


def _max_speed(cls: type, section: str) -> SpecialValue:
    return SpecialValue.of("lk", cls, ctl.MAX_SPEED, offset=2, section=section)


SPECIAL_VALUES: tuple[SpecialValue, ...] = (
    SpecialValue(
        "lk",
        ctl.SpeedControl,
        "current_limit_a / iq_limit_counts",
        "0",
        "torque limit 0 is not defined by the manuals (a V2.35 0xA2 frame read as V2.36 carries it)",
        "§4.11",
        "cannot be sent (refused); decoding refuses it too",
        offset=2,
    ),
    _max_speed(ctl.MultiTurnPositionSpeed, "§4.13"),
    _max_speed(ctl.SingleTurnPositionSpeed, "§4.15"),
    _max_speed(ctl.SingleTurnPositionSpeedV235, "§4.15"),
    _max_speed(ctl.IncrementalPositionSpeed, "§4.17"),
)
