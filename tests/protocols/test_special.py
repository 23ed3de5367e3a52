"""The special-value audit (issue 19), checked from its own rows.

For every numeric special field of every family: no ordinary number (anywhere in the field's range, and
just around the special raw value) encodes to the special raw value, and the explicit request does. The
other rows (flags, frame patterns, addresses) are checked one by one. ``docs/special-values.md`` must be
the rendering of the rows.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.protocols import hollow as ho
from servobus.protocols import lk
from servobus.protocols import myactuator as ma
from servobus.protocols._special import SpecialValue, all_special_values, render_markdown
from servobus.protocols.hollow.commands import is_special_command
from servobus.protocols.lk.model import MotorType

ROWS = all_special_values()
NUMERIC = [row for row in ROWS if row.spec is not None]
DOC = Path(__file__).resolve().parents[2] / "docs" / "special-values.md"

#: Valid values of every other field of each class with a numeric special field.
BASE: dict[type, dict[str, Any]] = {
    ma.SpeedControl: {"speed_dps": 10.0},
    ma.AbsolutePositionControl: {"angle_deg": 10.0, "max_speed_dps": 100.0},
    ma.SingleTurnPositionControl: {
        "angle_deg": 10.0,
        "max_speed_dps": 100.0,
        "direction": ma.SpinDirection(0),
    },
    ma.IncrementalPositionControl: {"angle_deg": 10.0, "max_speed_dps": 100.0},
    ma.ForcePositionControl: {"angle_deg": 10.0, "max_speed_dps": 100.0, "max_torque_pct": 50},
    ma.PositionSpeedFeedforward: {"angle_deg": 10.0, "max_speed_dps": 100.0, "feedforward_speed_pct": 0},
    ma.PositionTorqueFeedforward: {"angle_deg": 10.0, "max_speed_dps": 100.0, "feedforward_torque_pct": 0},
    ma.WriteAcceleration: {"index": ma.AccelIndex(0)},
    ma.SetCommTimeout: {},
    ma.ActiveReply: {"command": ma.StreamableCommand.STATUS_2, "enabled": True},
    lk.MultiTurnPositionSpeed: {"angle_deg": 10.0},
    lk.SingleTurnPositionSpeed: {"angle_deg": 10.0, "direction": lk.SpinDirection(0)},
    lk.SingleTurnPositionSpeedV235: {"angle_deg": 10.0, "direction": lk.SpinDirection(0)},
    lk.IncrementalPositionSpeed: {"increment_deg": 10.0},
}


def _raw_at(row: SpecialValue, data: bytes) -> int:
    assert row.spec is not None and row.offset is not None
    return int.from_bytes(data[row.offset : row.offset + row.spec.size], "little", signed=row.spec.signed)


def _numbers(row: SpecialValue) -> st.SearchStrategy[Any]:
    """Numbers over the field's range, and just around the special raw value."""
    spec = row.spec
    assert spec is not None
    lo, hi = spec.limits
    special = spec.raw * spec.resolution
    if spec.inner.__class__.__name__ == "IntField":
        return st.one_of(st.integers(int(lo), int(hi)), st.integers(spec.raw - 2, spec.raw + 2))
    near = st.floats(special - 2 * spec.resolution, special + 2 * spec.resolution, allow_nan=False)
    return st.one_of(st.floats(lo, hi, allow_nan=False), near, st.integers(int(lo), int(hi)))


def test_the_doc_is_the_rendering_of_the_rows() -> None:
    assert DOC.read_text(encoding="utf-8") == render_markdown(), (
        "docs/special-values.md is stale: regenerate it with render_markdown()"
    )


def test_every_family_has_rows_and_each_numeric_row_has_a_base() -> None:
    assert {row.family for row in ROWS} == {"myactuator", "lk", "hollow"}
    assert {row.cls for row in NUMERIC} <= set(BASE)


@pytest.mark.parametrize("row", NUMERIC, ids=lambda r: f"{r.family}-{r.command}-{r.field}")
@given(data=st.data())
def test_no_ordinary_number_encodes_to_the_special_value(row: SpecialValue, data: st.DataObject) -> None:
    value = data.draw(_numbers(row))
    try:
        command = row.cls(**{**BASE[row.cls], row.field: value})
    except ValueError as exc:
        text = str(exc)
        assert row.field in text
        spec = row.spec
        assert spec is not None
        if spec.limits[0] <= value <= spec.limits[1] and spec.code_of(value) == spec.raw:
            assert repr(value) in text and spec.meaning in text  # names the value and what it meant
        return
    assert _raw_at(row, command.encode()) != row.spec.raw  # type: ignore[union-attr]


@pytest.mark.parametrize("row", NUMERIC, ids=lambda r: f"{r.family}-{r.command}-{r.field}")
def test_the_explicit_request_encodes_to_the_special_value(row: SpecialValue) -> None:
    spec = row.spec
    assert spec is not None
    kwargs = dict(BASE[row.cls])
    if row.cls is ma.ActiveReply:
        kwargs["enabled"] = False  # interval 0 is only for disabling a stream
    if not spec.explicit:
        with pytest.raises(ValueError, match="cannot be sent"):
            row.cls(**{**kwargs, row.field: None})
        data = bytearray(row.cls(**{**kwargs, row.field: spec.raw + 1}).encode())
        data[row.offset : row.offset + spec.size] = spec.raw.to_bytes(spec.size, "little")  # type: ignore[misc]
        with pytest.raises(ProtocolError):
            row.cls.decode(bytes(data))  # type: ignore[attr-defined]
        return
    command = row.cls(**{**kwargs, row.field: None})
    data = command.encode()
    assert _raw_at(row, data) == spec.raw
    assert getattr(row.cls.decode(data), row.field) is None  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match=f"{row.field}=None"):  # the message says how to ask
        row.cls(**{**kwargs, row.field: spec.raw if spec.resolution == 1 else spec.raw * spec.resolution})


def test_the_issue_cases_raise_with_the_explanation() -> None:
    with pytest.raises(
        ValueError, match=r"max_speed_dps=0.4 rounds .* raw 0, which means no speed limit.*max_speed_dps=None"
    ):
        ma.AbsolutePositionControl(angle_deg=10, max_speed_dps=0.4)
    with pytest.raises(ValueError, match=r"max_speed_dps=0 encodes to raw 0, which means no speed limit"):
        ma.AbsolutePositionControl(angle_deg=10, max_speed_dps=0)
    with pytest.raises(ValueError, match=r"interval_ms=3 rounds .* 10 ms\) to raw 0"):
        ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=True, interval_ms=3)
    assert ma.AbsolutePositionControl(angle_deg=10, max_speed_dps=0.5).encode()[2:4] == b"\x01\x00"
    assert ma.SetCommTimeout.protection_off().encode() == bytes.fromhex("B3 00 00 00 00 00 00 00")


def test_function_control_flags_are_named() -> None:
    for row in (r for r in ROWS if r.cls is ma.FunctionControl):
        builder = getattr(ma.FunctionControl, row.request.split(".")[1].split("(")[0])
        data = builder(False).encode()
        assert data[4:8] == b"\x00" * 4 and builder(True).encode()[4] == 1
        with pytest.raises(ValueError):
            ma.FunctionControl(index=data[1], value=2)


@given(st.floats(-16.5, 16.5), st.integers(-2048, 2048))
def test_lk_torque_limit_never_encodes_to_zero(amps: float, counts: int) -> None:
    for kwargs in (
        {"motor_type": MotorType.MF, "current_limit_a": amps},
        {"motor_type": MotorType.MH, "iq_limit_counts": counts},
    ):
        try:
            command = lk.SpeedControl(speed_dps=1.0, **kwargs)  # type: ignore[arg-type]
        except ValueError as exc:
            assert "not defined by the manuals" in str(exc)
            continue
        assert command.encode()[2:4] != b"\x00\x00"


@given(
    st.floats(-360.0, 360.0),
    st.floats(-200.0, 200.0),
    st.integers(4000, 4095),
    st.integers(4000, 4095),
    st.floats(-4.0, 4.0),
)
def test_hollow_setpoints_never_read_as_special_commands(
    p: float, v: float, kp: int, kd: int, i: float
) -> None:
    for cls, name in ((ho.Setpoint, "position_deg"), (ho.IncrementalSetpoint, "step_deg")):
        for position in (p, 360.0 * 32767 / 32768, 360.0):
            for speed in (v, 200.0):
                try:
                    command = cls(**{name: position}, speed_rad_s=speed, kp=kp, kd=kd, current_a=i)  # type: ignore[arg-type]
                except ValueError:
                    continue
                assert not is_special_command(command.encode())
    assert is_special_command(ho.Start().encode()) and is_special_command(ho.SetZero().encode())


def test_hollow_rows() -> None:
    assert ho.FdCommand(zero=True).encode()[15] == 1 and ho.FdCommand().encode()[15] == 0
    for cls in (ho.ModbusWrite, ho.ModbusRead):
        kwargs = {"command": ho.FdCommand()} if cls is ho.ModbusWrite else {}
        with pytest.raises(ValueError, match="broadcast"):
            cls(slave_id=0, **kwargs)
