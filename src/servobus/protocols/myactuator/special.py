"""The audit of MyActuator's encoder fields: every raw value that is not its number (issue 19).

One :class:`~servobus.protocols._special.SpecialValue` per command field, with the section of
myactuator-v4.md. Numeric fields carry their :class:`~servobus.protocols._special.SpecialZero`, whose
meaning and request these rows repeat; the 0x20 flags are named by builders. Fields not listed have no
special or undefined raw value in the manuals (out-of-range values are refused by their limits).
"""

from __future__ import annotations

from servobus.protocols._special import SpecialValue, SpecialZero
from servobus.protocols.myactuator import commands as cmd
from servobus.protocols.myactuator import commands_control as ctl

__all__ = ["SPECIAL_VALUES"]


def _row(cls: type, name: str, section: str) -> SpecialValue:
    offset, spec = next((o, s) for o, s in cls.FIELDS if s.name == name)  # type: ignore[attr-defined]
    assert isinstance(spec, SpecialZero)
    return SpecialValue.of("myactuator", cls, spec, offset=offset, section=section)


def _flag(builder: str, meaning: str) -> SpecialValue:
    return SpecialValue(
        "myactuator",
        cmd.FunctionControl,
        "value",
        "0",
        meaning,
        "§4.37",
        f"FunctionControl.{builder}(False)",
        offset=4,
    )


SPECIAL_VALUES: tuple[SpecialValue, ...] = (
    _row(ctl.SpeedControl, "max_torque_pct", "§4.20"),
    _row(ctl.AbsolutePositionControl, "max_speed_dps", "§4.21"),
    _row(ctl.SingleTurnPositionControl, "max_speed_dps", "§4.22 (as §4.21)"),
    _row(ctl.IncrementalPositionControl, "max_speed_dps", "§4.23 (as §4.21)"),
    _row(ctl.ForcePositionControl, "max_speed_dps", "§4.24 (as §4.21)"),
    _row(ctl.ForcePositionControl, "max_torque_pct", "§4.24"),
    _row(ctl.PositionSpeedFeedforward, "max_speed_dps", "§4.25 (as §4.21)"),
    _row(ctl.PositionTorqueFeedforward, "max_speed_dps", "§4.26 (as §4.21)"),
    _row(cmd.WriteAcceleration, "acceleration_dps_s", "§4.5, §4.21"),
    _row(cmd.SetCommTimeout, "timeout_ms", "§4.33"),
    _row(cmd.ActiveReply, "interval_ms", "§4.36"),
    _flag("can_id_filter", "index 2: CAN-ID filter off (needed for 0x280 broadcasts)"),
    _flag("error_reporting", "index 3: no 0x9A frames on errors"),
    _flag("save_multi_turn", "index 4: multi-turn value not saved: single-turn mode after restart"),
    _flag("error_auto_recovery", "index 8 (V4.4): voltage and over-speed errors do not clear by themselves"),
)
