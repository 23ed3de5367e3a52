"""MyActuator replies (replies.py, enums.py): round trips, limits, layouts that differ, flags, faults."""

from __future__ import annotations

import re
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.protocols import Reply
from servobus.protocols import myactuator as ma

from ._strategies import assert_round_trip, message_classes, message_strategy
from .test_commands import _limit_cases, decoder_for, minimal

STANDARD_REPLIES: list[type] = [c for c in message_classes() if issubclass(c, ma.MyActuatorReply)]
OTHER_REPLIES = [c for c in message_classes() if issubclass(c, Reply) and c not in STANDARD_REPLIES]


def test_the_reply_lists_hold_every_exported_reply() -> None:
    assert len(STANDARD_REPLIES) == 21  # 20 answers and the 0xF1 event (CommunicationTimeoutTripped)
    assert set(OTHER_REPLIES) == {ma.Echo, ma.MotionReply, ma.Rs485MotionReply}


@pytest.mark.parametrize("cls", STANDARD_REPLIES + OTHER_REPLIES, ids=lambda c: c.__name__)
@given(data=st.data())
def test_every_reply_round_trips_to_its_quantised_self(cls: type, data: st.DataObject) -> None:
    reply = data.draw(message_strategy(cls))
    assert_round_trip(reply, decoder_for(reply))


@pytest.mark.parametrize(
    ("cls", "name", "value", "pattern"), _limit_cases([*STANDARD_REPLIES, ma.Rs485MotionReply])
)
def test_values_outside_a_field_raise_value_error_naming_field_and_limit(
    cls: type, name: str, value: Any, pattern: str
) -> None:
    kwargs = minimal(cls)
    cls(**kwargs).encode()
    kwargs[name] = value
    with pytest.raises(ValueError, match=re.escape(name) + ".*" + pattern):
        cls(**kwargs)


# ---- echo ----


def test_echo_holds_the_command_and_repeats_its_bytes() -> None:
    command = ma.WritePidRam(index=ma.PidIndex.CURRENT_KP, value=1.5)
    echo = ma.Echo(command=command)
    assert echo.encode() == command.encode() == bytes.fromhex("31 01 00 00 00 00 C0 3F")
    assert echo.code == 0x31
    assert ma.Echo.decode(echo.encode(), ma.WritePidRam) == echo
    with pytest.raises(ValueError, match="is not a MyActuator command"):
        ma.Echo(command=ma.MotorShutdown.decode)  # type: ignore[type-var]


# ---- R2 and friends ----


def test_status_reply_carries_the_command_it_answers() -> None:
    reply = ma.StatusReply.decode(bytes.fromhex("A1 32 9C FF 0C FE D3 FF"))
    assert reply == ma.StatusReply(
        command=ma.StatusCommand.TORQUE_CONTROL,
        temperature_c=50,
        current_a=-1.0,
        speed_dps=-500,
        angle_deg=-45,
    )
    assert reply.code == 0xA1
    with pytest.raises(ProtocolError, match="is not one of StatusCommand"):
        ma.StatusReply.decode(bytes.fromhex("9B 32 9C FF 0C FE D3 FF"))


def test_status1_decodes_flags_and_keeps_unknown_bits() -> None:
    reply = ma.Status1Reply.decode(bytes.fromhex("9A 32 00 01 E5 01 16 80"))
    assert (
        reply.errors
        == ma.ErrorFlags.STALL | ma.ErrorFlags.LOW_VOLTAGE | ma.ErrorFlags.PHASE_OVERCURRENT | 0x8000
    )
    assert reply.errors.names() == ["STALL", "LOW_VOLTAGE", "PHASE_OVERCURRENT"]
    assert reply.errors.unknown_bits == 0x8000
    assert reply.errors.known == ma.ErrorFlags(0x0016)
    assert reply.encode() == bytes.fromhex("9A 32 00 01 E5 01 16 80")
    with pytest.raises(ProtocolError, match="brake_released=2 is not 0 or 1"):
        ma.Status1Reply.decode(bytes.fromhex("9A 32 00 02 E5 01 00 00"))


@pytest.mark.parametrize("code", [0x00, 0x04, 0x07, 0xFF])
def test_run_mode_outside_the_three_manual_modes_is_a_protocol_error(code: int) -> None:
    # [002] §2.25.3 / [000] §2.26.3: the run mode "has the following 3 states" (0x01..0x03); the manual
    # overrides the spec's pass-through (§9 item 27).
    assert ma.RunModeReply.decode(bytes.fromhex("70 00 00 00 00 00 00 03")).mode is ma.RunMode.POSITION_LOOP
    data = bytes([0x70, 0, 0, 0, 0, 0, 0, code])
    with pytest.raises(ProtocolError, match=f"mode=0x{code:02X} is not one of RunMode"):
        ma.RunModeReply.decode(data)
    with pytest.raises(ProtocolError, match=f"mode=0x{code:02X}"):
        ma.decode_reply(0x241, data)
    with pytest.raises(ValueError, match=f"mode={code}"):
        ma.RunModeReply(mode=code)  # type: ignore[arg-type]


def test_pid_reply_refuses_non_finite_floats() -> None:
    with pytest.raises(ProtocolError, match="value=nan is not finite"):
        ma.PidReply.decode(bytes.fromhex("30 01 00 00 00 00 C0 7F"))


# ---- 0x79 read reply: §9 item 15's ordered rule ----


@pytest.mark.parametrize(
    ("tail", "motor_id", "layout"),
    [
        ("00 02", 2, ma.CanIdLayout.DATA7),  # RS485 example
        ("00 20", 32, ma.CanIdLayout.DATA7),  # rule 1 first: as LE this would be 0x2000
        ("00 05", 5, ma.CanIdLayout.DATA7),  # 0x0500 must not become 0x0500 - 0x240
        ("42 02", 2, ma.CanIdLayout.REPLY_IDENTIFIER),  # CAN example: 0x0242
        ("60 02", 32, ma.CanIdLayout.REPLY_IDENTIFIER),
        ("07 00", 7, ma.CanIdLayout.BARE),
    ],
)
def test_can_id_read_reply_rules(tail: str, motor_id: int, layout: ma.CanIdLayout) -> None:
    data = bytes.fromhex("79 00 01 00 00 00 " + tail)
    reply = ma.CanIdReply.decode(data)
    assert (reply.motor_id, reply.layout) == (motor_id, layout)
    assert reply.encode() == data


@pytest.mark.parametrize("tail", ["00 00", "00 21", "40 02", "61 02", "21 00", "FF FF"])
def test_can_id_read_reply_outside_every_rule_is_a_protocol_error(tail: str) -> None:
    with pytest.raises(ProtocolError, match="fit none of"):
        ma.CanIdReply.decode(bytes.fromhex("79 00 01 00 00 00 " + tail))


# ---- 0x94 and 0xB5: one class per layout ----


@pytest.mark.parametrize(
    ("data", "revision"),
    [
        ("94 00 00 00 4C 1D 00 00", ma.Revision.V4_4),  # [000] example, 75°
        ("94 00 00 00 B4 E2 FF FF", ma.Revision.V4_4),  # -75°
        ("94 00 00 00 00 00 10 27", ma.Revision.V4_3),  # [002] example, 100°
        ("94 00 00 00 00 00 00 00", None),  # 0° in both
        ("94 00 00 00 01 00 01 00", None),  # neither producer's range
        ("92 00 00 00 4C 1D 00 00", None),
    ],
)
def test_single_turn_layout_guess(data: str, revision: ma.Revision | None) -> None:
    assert ma.guess_single_turn_revision(bytes.fromhex(data)) is revision


def test_the_two_single_turn_layouts() -> None:
    assert ma.SingleTurnAngleReply.decode(bytes.fromhex("94 00 00 00 B4 E2 FF FF")).angle_deg == -75.0
    assert ma.CircleAngleReply.decode(bytes.fromhex("94 00 00 00 00 00 10 27")).angle_deg == 100.0


def test_model_replies() -> None:
    assert ma.ModelReply.decode(bytes.fromhex("B5 58 38 53 32 56 31 30")).model == "X8S2V10"
    assert ma.ModelReply(model="X8").encode() == bytes.fromhex("B5 58 38 00 00 00 00 00")
    assert ma.ModelReply.decode(bytes.fromhex("B5 58 38 20 20 00 00 00")).model == "X8"
    with pytest.raises(ProtocolError, match="not printable ASCII"):
        ma.ModelReply.decode(bytes.fromhex("B5 58 00 38 00 00 00 00"))
    with pytest.raises(ProtocolError, match="not printable ASCII"):
        ma.ModelReply.decode(bytes.fromhex("B5 01 01 58 38 53 32 56"))  # a V4.4 reply is not a V4.3 one
    with pytest.raises(ValueError, match="trailing spaces"):
        ma.ModelReply(model="X8 ")
    parts = [
        ma.ModelPartReply(part=2, text="10"),
        ma.ModelPartReply.decode(bytes.fromhex("B5 01 01 58 38 53 32 56")),
    ]
    assert ma.join_model(parts) == "X8S2V10"
    with pytest.raises(ValueError, match="part 2 given twice"):
        ma.join_model([*parts, parts[0]])


def test_version_date_reply_chooses_a_revision() -> None:
    reply = ma.VersionDateReply.decode(bytes.fromhex("B2 00 00 00 2E 89 34 01"))
    assert reply.version_date == 20220206
    assert reply.revision() is ma.Revision.V4_3
    assert reply.revision(cutoff=20220101) is ma.Revision.V4_4


# ---- enums and the fault table ----


def test_every_named_error_flag_is_described() -> None:
    named = [f for f in ma.ErrorFlags if f]
    assert set(ma.ERROR_FLAG_INFO) == set(named)
    assert [int(f) for f in named] == [0x2, 0x4, 0x8, 0x10, 0x40, 0x80, 0x100, 0x800, 0x1000, 0x2000, 0x4000]


def test_fault_table_matches_the_manual() -> None:
    # §7: ten faults; component over-temperature and encoder data error are not in it.
    assert len(ma.FAULTS) == 10
    levels = {f.name: f.level for f in ma.FAULTS}
    assert levels["stall error"] is ma.IndicatorLevel.LEVEL_1
    assert levels["under-voltage"] is ma.IndicatorLevel.LEVEL_2
    flags = {f.flag for f in ma.FAULTS}
    assert ma.ErrorFlags.COMPONENT_OVER_TEMPERATURE not in flags
    assert ma.ErrorFlags.ENCODER_DATA_ERROR not in flags
    assert next(f for f in ma.FAULTS if f.flag is None).name == "hardware over-current"


# ---- decoded values outside the manuals' ranges (issue 13) ----


def test_v4_3_single_turn_frame_read_as_v4_4_is_out_of_range_and_named() -> None:
    # [002] §2.13's example (uint16 100.00° in DATA[6..7]) read with V4.4's int32 layout is 65536.00°,
    # outside [000] §2.12's -180..+180°; V4.3's layout reads every byte of it.
    data = bytes.fromhex("94 00 00 00 00 00 10 27")
    message = r"angle_deg=6553600\.0 is outside \[-180, 180\]; looks like a V4\.3 frame"
    with pytest.raises(ProtocolError, match=message):
        ma.decode_reply(0x241, data, revision=ma.Revision.V4_4)
    with pytest.raises(ProtocolError, match=r"angle_deg=6553600\.0"):
        ma.SingleTurnAngleReply.decode(data)
    assert ma.decode_reply(0x241, data, revision=ma.Revision.V4_3) == ma.CircleAngleReply(angle_deg=100.0)


def test_v4_4_negative_single_turn_frame_read_as_v4_3_is_out_of_range_and_named() -> None:
    data = ma.SingleTurnAngleReply(angle_deg=-75.0).encode()  # B4 E2 FF FF: DATA[6..7] = 0xFFFF
    message = r"angle_deg=655\.35 is outside \[0, 359\.99\]; looks like a V4\.4 frame"
    with pytest.raises(ProtocolError, match=message):
        ma.decode_reply(0x241, data, revision=ma.Revision.V4_3)


@pytest.mark.parametrize(
    ("data", "revision", "message"),
    [
        # 180.01°: V4.3 would read 0° only by skipping DATA[4..5], so no other revision is named.
        ("94 00 00 00 51 46 00 00", ma.Revision.V4_4, r"angle_deg=180\.01 is outside \[-180, 180\] \("),
        ("94 00 00 00 AF B9 FF FF", ma.Revision.V4_4, r"angle_deg=-180\.01 is outside \[-180, 180\] \("),
        # 360.00°: [002] §2.13 "0~35999"; as a V4.4 int32 it is far out of range too.
        ("94 00 00 00 00 00 A0 8C", ma.Revision.V4_3, r"angle_deg=360\.0 is outside \[0, 359\.99\] \("),
    ],
)
def test_single_turn_angle_outside_the_revision_range(data: str, revision: ma.Revision, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        ma.decode_reply(0x241, bytes.fromhex(data), revision=revision)


def test_single_turn_angle_range_ends_decode() -> None:
    v44 = ma.Revision.V4_4
    assert ma.decode_reply(0x241, ma.SingleTurnAngleReply(angle_deg=180.0).encode(), revision=v44)
    assert ma.decode_reply(0x241, ma.SingleTurnAngleReply(angle_deg=-180.0).encode(), revision=v44)
    last = ma.decode_reply(0x241, bytes.fromhex("94 00 00 00 00 00 9F 8C"), revision=ma.Revision.V4_3)
    assert last == ma.CircleAngleReply(angle_deg=359.99)


def test_mos_temperature_is_unsigned() -> None:
    # [002] §2.14.3 / [000] §2.13.3 print DATA[2] = (uint8_t)(motorMOStemperature).
    reply = ma.decode_reply(0x241, bytes.fromhex("9A 32 C8 01 E5 01 04 00"))
    assert isinstance(reply, ma.Status1Reply) and reply.mos_temperature_c == 200
    with pytest.raises(ValueError, match="mos_temperature_c=-1"):
        ma.Status1Reply(temperature_c=50, mos_temperature_c=-1, brake_released=True, voltage_v=48.5)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (50, r"acceleration_dps_s=50\.0 is outside \[100, 60000\]"),
        (60001, r"acceleration_dps_s=60001\.0 is outside"),
    ],
)
def test_acceleration_reply_outside_0_or_100_to_60000(value: int, message: str) -> None:
    # [000]/[002] 0x42: Accel 100..60000 dps/s (0 has a documented meaning, spec §9 item 19).
    data = bytes([0x42, 0, 0, 0]) + value.to_bytes(4, "little")
    with pytest.raises(ProtocolError, match=message):
        ma.decode_reply(0x241, data)
    assert ma.decode_reply(0x241, bytes.fromhex("42 00 00 00 00 00 00 00")) == ma.AccelerationReply(
        index=ma.AccelIndex.POSITION_ACCELERATION, acceleration_dps_s=0.0
    )
