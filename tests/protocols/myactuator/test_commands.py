"""MyActuator requests (commands.py, commands_control.py): round trips, limits, per-command rules."""

from __future__ import annotations

import dataclasses
import re
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.protocols import Command
from servobus.protocols import myactuator as ma
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._special import SpecialZero
from servobus.protocols.myactuator._layout import (
    AsciiField,
    BoolField,
    EnumField,
    Fixed,
    Float32Field,
    StepField,
)
from servobus.protocols.myactuator.codec import REQUESTS

from ._strategies import assert_round_trip, message_classes, message_strategy, minimal_value

STANDARD_COMMANDS: list[type] = [
    c for c in message_classes() if issubclass(c, Command) and issubclass(c, ma.MyActuatorCommand)
]
OTHER_COMMANDS = [c for c in message_classes() if issubclass(c, Command) and c not in STANDARD_COMMANDS]


def test_the_command_lists_hold_every_exported_command() -> None:
    # The exported commands are exactly those the codec's request table decodes, each once.
    assert len(set(STANDARD_COMMANDS)) == len(STANDARD_COMMANDS)
    assert set(STANDARD_COMMANDS) == {layout.message for layouts in REQUESTS.values() for layout in layouts}
    assert set(OTHER_COMMANDS) == {ma.MotionCommand, ma.Rs485MotionCommand}


def decoder_for(message: Any) -> Any:
    if isinstance(message, ma.MotionCommand | ma.MotionReply):
        return lambda data: type(message).decode(data, message.scales)
    if isinstance(message, ma.Echo):
        return lambda data: ma.Echo.decode(data, type(message.command))
    return type(message).decode


@pytest.mark.parametrize("cls", STANDARD_COMMANDS + OTHER_COMMANDS, ids=lambda c: c.__name__)
@given(data=st.data())
def test_every_command_round_trips_to_its_quantised_self(cls: type, data: st.DataObject) -> None:
    command = data.draw(message_strategy(cls))
    assert_round_trip(command, decoder_for(command))


def minimal(cls: Any) -> dict[str, Any]:
    """Valid constructor arguments, the low end of every field."""
    if cls is ma.FunctionControl:
        return {"index": ma.FunctionIndex.CAN_ID_FILTER, "value": 0}
    return {name: minimal_value(spec) for name, spec in cls.field_specs().items()}


def _outside(spec: Any) -> list[tuple[Any, str]]:
    """Values just outside a field's range, each with a pattern its ValueError must match."""
    if isinstance(spec, SpecialZero):
        return _outside(spec.inner)
    if isinstance(spec, ScaledField):
        lo, hi = spec.limits
        step = spec.resolution
        return [(lo - step, re.escape(f"[{lo!r}, {hi!r}]")), (hi + step, re.escape(f"[{lo!r}, {hi!r}]"))]
    if isinstance(spec, IntField | StepField):
        lo, hi = spec.limits
        return [(lo - 1, re.escape(f"[{lo!r}, {hi!r}]")), (hi + 1, re.escape(f"[{lo!r}, {hi!r}]"))]
    if isinstance(spec, Float32Field):
        lo, hi = spec.limits
        return [(hi * 2, re.escape(f"{hi!r}]")), (float("nan"), "outside"), (float("inf"), "outside")]
    if isinstance(spec, EnumField):
        return [(0xEE, "is not one of"), (True, "is not one of"), (1.0, "is not one of")]
    if isinstance(spec, BoolField):
        return [(1, "is not a bool")]
    if isinstance(spec, AsciiField):
        return [("x" * (spec.size + 1), f"longer than {spec.size}"), ("é", "not printable ASCII")]
    return []


def _limit_cases(classes: list[Any]) -> list[Any]:
    cases = []
    for cls in classes:
        for name, spec in cls.field_specs().items():
            for value, pattern in _outside(spec):
                cases.append(pytest.param(cls, name, value, pattern, id=f"{cls.__name__}-{name}-{value!r}"))
    return cases


@pytest.mark.parametrize(
    ("cls", "name", "value", "pattern"), _limit_cases([*STANDARD_COMMANDS, ma.Rs485MotionCommand])
)
def test_values_outside_a_field_raise_value_error_naming_field_and_limit(
    cls: type, name: str, value: Any, pattern: str
) -> None:
    kwargs = minimal(cls)
    cls(**kwargs).encode()  # the base case is valid
    kwargs[name] = value
    with pytest.raises(ValueError, match=re.escape(name) + ".*" + pattern):
        cls(**kwargs)


@pytest.mark.parametrize("cls", STANDARD_COMMANDS, ids=lambda c: c.__name__)
def test_payload_is_eight_bytes_with_the_command_byte_first(cls: Any) -> None:
    data = cls(**minimal(cls)).encode()
    assert len(data) == 8 and data[0] == cls.CODE
    with pytest.raises(ProtocolError, match="expected 8 data bytes"):
        cls.decode(data[:7])
    with pytest.raises(ProtocolError, match=f"DATA\\[0\\] is not 0x{cls.CODE:02X}"):
        cls.decode(bytes([cls.CODE ^ 0x01]) + data[1:])


def test_non_numbers_are_refused_before_any_byte_exists() -> None:
    with pytest.raises(ValueError, match="current_a='1' is not a number"):
        ma.TorqueControl(current_a="1")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"max_torque_pct=1\.5 is not an integer"):
        ma.SpeedControl(speed_dps=1.0, max_torque_pct=1.5)  # type: ignore[arg-type]


def test_commands_are_frozen_and_slotted() -> None:
    command = ma.TorqueControl(current_a=1.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        command.current_a = 2.0  # type: ignore[misc]
    assert not hasattr(command, "__dict__")


def test_plain_ints_become_enum_members() -> None:
    command = ma.ReadPid(index=1)  # type: ignore[arg-type]
    assert command.index is ma.PidIndex.CURRENT_KP
    assert repr(command) == "ReadPid(index=<PidIndex.CURRENT_KP: 1>)"


def test_undefined_pid_indexes_do_not_exist() -> None:
    # §4.1: 0x03 and 0x06 are not defined.
    for index in (0x03, 0x06):
        with pytest.raises(ValueError, match=r"index=(3|6) is not one of"):
            ma.ReadPid(index=index)  # type: ignore[arg-type]
        with pytest.raises(ProtocolError, match="is not one of PidIndex"):
            ma.ReadPid.decode(bytes([0x30, index]) + bytes(6))


def test_nulls_are_ignored_on_decode() -> None:
    # One rule for the family (_layout.py): NULL bytes do not carry meaning, so they do not reject a frame.
    assert ma.MotorShutdown.decode(bytes.fromhex("80 FF FF FF FF FF FF FF")) == ma.MotorShutdown()
    assert ma.ReadPid.decode(bytes.fromhex("30 01 AA BB 00 00 00 00")) == ma.ReadPid(
        index=ma.PidIndex.CURRENT_KP
    )


# ---- 0x20 ----


@pytest.mark.parametrize(
    ("command", "data"),
    [
        (ma.FunctionControl.clear_multi_turn(), "20 01 00 00 00 00 00 00"),
        (ma.FunctionControl.can_id_filter(True), "20 02 00 00 01 00 00 00"),
        (ma.FunctionControl.can_id_filter(False), "20 02 00 00 00 00 00 00"),
        (ma.FunctionControl.error_reporting(True), "20 03 00 00 01 00 00 00"),
        (ma.FunctionControl.save_multi_turn(True), "20 04 00 00 01 00 00 00"),
        (ma.FunctionControl.set_can_id(32), "20 05 00 00 20 00 00 00"),
        (ma.FunctionControl.max_positive_angle(36000), "20 06 00 00 A0 8C 00 00"),
        (ma.FunctionControl.max_negative_angle(-36000), "20 07 00 00 60 73 FF FF"),
        (ma.FunctionControl.error_auto_recovery(True), "20 08 00 00 01 00 00 00"),
    ],
    ids=lambda x: x.index.name if isinstance(x, ma.FunctionControl) else "",
)
def test_function_control_covers_every_index(command: ma.FunctionControl, data: str) -> None:
    assert command.encode() == bytes.fromhex(data)
    assert ma.FunctionControl.decode(bytes.fromhex(data)) == command
    assert command.meaning == ma.FUNCTION_VALUES[command.index].meaning


def test_every_function_index_has_a_value_rule_and_a_builder() -> None:
    assert [int(i) for i in ma.FunctionIndex] == list(range(1, 9))
    assert set(ma.FUNCTION_VALUES) == set(ma.FunctionIndex)
    builders = {name for name in vars(ma.FunctionControl) if not name.startswith("_")}
    for index in ma.FunctionIndex:
        assert index.name.lower() in builders


@pytest.mark.parametrize(
    ("index", "value", "pattern"),
    [
        (ma.FunctionIndex.CLEAR_MULTI_TURN, 1, r"value \(index CLEAR_MULTI_TURN\)=1 is outside \[0, 0\]"),
        (ma.FunctionIndex.CAN_ID_FILTER, 2, r"\[0, 1\]"),
        (ma.FunctionIndex.SET_CAN_ID, 0, r"\[1, 32\]"),
        (ma.FunctionIndex.SET_CAN_ID, 33, r"\[1, 32\]"),
        (ma.FunctionIndex.MAX_POSITIVE_ANGLE, 1 << 31, r"=2147483648 is outside \[-2147483648, 2147483647\]"),
        (ma.FunctionIndex.CAN_ID_FILTER, True, r"value=True is not an integer"),
        (ma.FunctionIndex.ERROR_AUTO_RECOVERY, -1, r"\[0, 1\]"),
    ],
)
def test_function_control_values_are_checked_per_index(
    index: ma.FunctionIndex, value: int, pattern: str
) -> None:
    with pytest.raises(ValueError, match=pattern):
        ma.FunctionControl(index=index, value=value)


def test_function_control_decode_refuses_values_its_index_does_not_take() -> None:
    with pytest.raises(ProtocolError, match=r"value \(index SET_CAN_ID\)=0"):
        ma.FunctionControl.decode(bytes.fromhex("20 05 00 00 00 00 00 00"))
    with pytest.raises(ProtocolError, match="is not one of FunctionIndex"):
        ma.FunctionControl.decode(bytes.fromhex("20 09 00 00 00 00 00 00"))


# ---- 0x43 ----


def test_acceleration_is_none_or_100_to_60000() -> None:
    # §9 item 19: the range is 100..60000 and 0 has a documented meaning (no planning), asked for
    # with None only (issue 19); the numbers 0..99 are refused.
    assert ma.WriteAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION, acceleration_dps_s=None).encode() == (
        bytes.fromhex("43 02 00 00 00 00 00 00")
    )
    assert ma.WriteAcceleration.decode(bytes.fromhex("43 02 00 00 00 00 00 00")).acceleration_dps_s is None
    with pytest.raises(ValueError, match=r"acceleration_dps_s=0 encodes to raw 0, which means no planning"):
        ma.WriteAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION, acceleration_dps_s=0)
    with pytest.raises(ValueError, match=r"acceleration_dps_s=0.4 rounds .* acceleration_dps_s=None"):
        ma.WriteAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION, acceleration_dps_s=0.4)
    ma.WriteAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION, acceleration_dps_s=100)
    ma.WriteAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION, acceleration_dps_s=99.5)  # rounds to 100
    with pytest.raises(ValueError, match=r"acceleration_dps_s=50 is outside \[100, 60000\]"):
        ma.WriteAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION, acceleration_dps_s=50)
    with pytest.raises(ValueError, match=r"acceleration_dps_s=60001 is outside \[0, 60000\]"):
        ma.WriteAcceleration(index=ma.AccelIndex.SPEED_ACCELERATION, acceleration_dps_s=60001)
    with pytest.raises(ProtocolError, match="acceleration_dps_s=50"):
        ma.WriteAcceleration.decode(bytes.fromhex("43 00 00 00 32 00 00 00"))


# ---- control ----


def test_single_turn_angle_passes_360_through_unchanged() -> None:
    # §9 item 10: the examples send 36000 (A0 8C); it is not reduced modulo 360.
    command = ma.SingleTurnPositionControl(
        angle_deg=360, max_speed_dps=500, direction=ma.SpinDirection.CLOCKWISE
    )
    assert command.encode() == bytes.fromhex("A6 00 F4 01 A0 8C 00 00")
    with pytest.raises(ValueError, match=r"angle_deg=360.01 is outside \[0.0, 360.0\]"):
        ma.SingleTurnPositionControl(
            angle_deg=360.01, max_speed_dps=None, direction=ma.SpinDirection.CLOCKWISE
        )


def test_speed_control_torque_limit_defaults_off() -> None:
    assert ma.SpeedControl(speed_dps=-100).encode() == bytes.fromhex("A2 00 00 00 F0 D8 FF FF")
    assert ma.SpeedControl(speed_dps=100, max_torque_pct=60).encode()[1] == 60


def test_feedforward_percentages_are_signed_bytes() -> None:
    sf = ma.PositionSpeedFeedforward(angle_deg=0, max_speed_dps=None, feedforward_speed_pct=-128)
    assert sf.encode() == bytes.fromhex("72 80 00 00 00 00 00 00")
    tf = ma.PositionTorqueFeedforward(angle_deg=0, max_speed_dps=None, feedforward_torque_pct=127)
    assert tf.encode() == bytes.fromhex("73 7F 00 00 00 00 00 00")


@given(st.floats(min_value=-21474836.48, max_value=21474836.47))
def test_position_angle_quantises_to_a_hundredth_of_a_degree(angle: float) -> None:
    command = ma.AbsolutePositionControl(angle_deg=angle, max_speed_dps=None)
    decoded = ma.AbsolutePositionControl.decode(command.encode())
    assert abs(decoded.angle_deg - angle) <= 0.005 + 1e-9 * max(1.0, abs(angle))


# ---- 0x79, 0xB4..0xB6 ----


def test_can_id_setting_forms() -> None:
    assert ma.SetCanId(motor_id=2).encode() == bytes.fromhex("79 00 00 00 00 00 00 02")
    assert ma.ReadCanId().encode() == bytes.fromhex("79 00 01 00 00 00 00 00")
    with pytest.raises(ProtocolError, match=r"DATA\[2\] is not 0x00"):
        ma.SetCanId.decode(bytes.fromhex("79 00 01 00 00 00 00 02"))
    with pytest.raises(ValueError, match=r"motor_id=33 is outside \[1, 32\]"):
        ma.SetCanId(motor_id=33)


def test_baud_rate_index_is_raw_with_the_v43_meaning_attached() -> None:
    # §4.34: [002]'s mapping; indexes 3 and 4 are unverified, so no meaning is given.
    assert ma.SetBaudRate(baud_index=1).setting == ma.BaudRateSetting(rs485_bps=500_000, can_bps=1_000_000)
    assert ma.SetBaudRate(baud_index=2).setting == ma.BaudRateSetting(rs485_bps=1_000_000, can_bps=None)
    assert ma.SetBaudRate(baud_index=3).setting is None


def test_model_read_forms() -> None:
    assert ma.ReadModel().encode() == bytes.fromhex("B5 00 00 00 00 00 00 00")
    assert ma.ReadModelPart(part=3).encode() == bytes.fromhex("B5 01 03 00 00 00 00 00")
    with pytest.raises(ProtocolError, match=r"DATA\[1\] is not 0x01"):
        ma.ReadModelPart.decode(bytes.fromhex("B5 00 01 00 00 00 00 00"))


def test_active_reply_interval_is_in_10_ms_steps_and_never_streams_0x9e() -> None:
    command = ma.ActiveReply(command=ma.StreamableCommand.STATUS_1, enabled=True, interval_ms=104)
    assert command.encode() == bytes.fromhex("B6 9A 01 0A 00 00 00 00")
    assert command.interval_code == 10
    assert ma.ActiveReply.decode(command.encode()).interval_ms == 100
    with pytest.raises(ValueError, match="command=158 is not one of"):
        ma.ActiveReply(command=0x9E, enabled=True)  # type: ignore[arg-type]
    with pytest.raises(ProtocolError, match="enabled=2 is not 0 or 1"):
        ma.ActiveReply.decode(bytes.fromhex("B6 60 02 01 00 00 00 00"))


def test_active_reply_interval_0_is_only_for_disabling() -> None:
    # §4.36: interval 0 is undefined for a stream; 3 ms rounds to it on the 10 ms field (issue 19).
    with pytest.raises(
        ValueError, match=r"interval_ms=3 rounds .* step of 10 ms\) to raw 0, which is not defined"
    ):
        ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=True, interval_ms=3)
    with pytest.raises(ValueError, match=r"interval_ms=None sends interval 0"):
        ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=True)
    off = ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=False)
    assert off.encode() == bytes.fromhex("B6 9C 00 00 00 00 00 00")
    assert ma.ActiveReply.decode(off.encode()) == off
    assert (
        ma.ActiveReply(command=ma.StreamableCommand.STATUS_2, enabled=True, interval_ms=5).interval_code == 1
    )
    with pytest.raises(ProtocolError, match="interval_ms=None sends interval 0"):
        ma.ActiveReply.decode(bytes.fromhex("B6 9C 01 00 00 00 00 00"))


def test_the_base_layout_writes_constants_before_fields() -> None:
    assert issubclass(ma.ReadModelPart, Fixed)
    assert ma.ReadModelPart.CONSTANTS == ((1, 0x01),)
