"""LK parameter messages (params.py): both addressing schemes, value layouts, opposite status bytes."""

from __future__ import annotations

import struct
from typing import Any

import pytest

from servobus.errors import ProtocolError
from servobus.protocols import lk
from servobus.protocols.lk import (
    BusType,
    CanBaud,
    ControlParam,
    ParamId,
    ParamResult,
    PidGains,
    Rs485Baud,
    SettingParam,
)
from servobus.protocols.lk.params import max_angle_from_halves, max_angle_halves

PID = PidGains(kp=100, ki=200, kd=2000)


@pytest.mark.parametrize(
    ("message", "fmt", "values"),
    [
        # Spec §13 rows, V2.36 0xC0/0xC1.
        (
            lk.WriteControlParam(param=ControlParam.SPEED_PID, value=PID),
            "<BBHHH",
            (0xC1, 0x0B, 100, 200, 2000),
        ),
        (lk.WriteControlParam(param=ControlParam.TORQUE_LIMIT, value=2000), "<BBxxhxx", (0xC1, 0x1E, 2000)),
        (
            lk.WriteControlParam(param=ControlParam.SPEED_LIMIT, value=600_000),
            "<BBxxi",
            (0xC1, 0x20, 600_000),
        ),
        (
            lk.WriteControlParam(param=ControlParam.ANGLE_LOWER_LIMIT, value=-(2**31)),
            "<BBxxi",
            (0xC1, 0x23, -(2**31)),
        ),
        (lk.WriteControlParam(param=ControlParam.SPEED_RAMP, value=1), "<BBxxi", (0xC1, 0x26, 1)),
        (lk.ReadControlParam(param=ControlParam.CURRENT_PID), "<BBxxxxxx", (0xC0, 0x0C)),
        # V2.36 setting parameters 0x40/0x42.
        (lk.WriteSetting(param=SettingParam.DRIVER_ID, value=32), "<BBBxBxxx", (0x42, 0x05, 0x0A, 32)),
        (
            lk.WriteSetting(param=SettingParam.CAN_BAUD, value=CanBaud.BAUD_1M),
            "<BBBxBxxx",
            (0x42, 0x05, 0x0D, 4),
        ),
        (lk.WriteSetting(param=SettingParam.MAX_POWER, value=850), "<BBBxhxx", (0x42, 0x05, 0xB0, 850)),
        (
            lk.WriteSetting(param=SettingParam.CURRENT_RAMP, value=30_000),
            "<BBBxhxx",
            (0x42, 0x05, 0xBA, 30_000),
        ),
        (
            lk.WriteSetting(param=SettingParam.MAX_ANGLE, value=2**31 - 1),
            "<BBBxi",
            (0x42, 0x05, 0xB4, 2**31 - 1),
        ),
        (lk.WriteSetting(param=SettingParam.POSITION_PID, value=PID), "<BBHHH", (0x42, 0xA0, 100, 200, 2000)),
        (lk.ReadSetting(param=SettingParam.SPEED_RAMP), "<BBBxxxxx", (0x40, 0x05, 0xBC)),
        (lk.ReadSetting(param=SettingParam.CURRENT_PID), "<BBBxxxxx", (0x40, 0xA8, 0x00)),  # A28
        (lk.SaveSettings(), "<BBBxxxxx", (0x44, 0x05, 0xFA)),
        # V2.35 ParamID.
        (lk.ReadParam(param=ParamId.ANGLE_PID), "<BBxxxxxx", (0x40, 0x96)),
        (lk.WriteParamRam(param=ParamId.SPEED_PID, value=PID), "<BBHHH", (0x42, 0x97, 100, 200, 2000)),
        (lk.WriteParamRom(param=ParamId.MAX_TORQUE_CURRENT, value=-5), "<BBhxxxx", (0x44, 0x99, -5)),
        (lk.WriteParamRam(param=ParamId.SPEED_RAMP, value=-(2**31)), "<BBixx", (0x42, 0x9E, -(2**31))),
        (lk.WriteParamRom(param=ParamId.MAX_ANGLE_LOW, value=0xFFFFFFFF), "<BBIxx", (0x44, 0x9B, 0xFFFFFFFF)),
    ],
    ids=lambda v: type(v).__name__ if isinstance(v, lk.LkCommand) else None,
)
def test_request_layouts_match_spec_struct_formats(message: Any, fmt: str, values: tuple[Any, ...]) -> None:
    data = struct.pack(fmt, *values)
    assert message.encode() == data
    assert type(message).decode(data) == message


@pytest.mark.parametrize(
    ("reply", "fmt", "values"),
    [
        (
            lk.ControlParamReply(command=0xC0, param=ControlParam.ANGLE_UPPER_LIMIT, value=-1),
            "<BBxxi",
            (0xC0, 0x22, -1),
        ),
        (
            lk.SettingReply(command=0x40, param=SettingParam.SPEED_PID, value=PID),
            "<BBHHH",
            (0x40, 0xA4, 100, 200, 2000),
        ),
        (
            lk.SettingReply(command=0x42, param=SettingParam.RS485_BAUD, value=Rs485Baud.BAUD_4000000),
            "<BBBxBxxx",
            (0x42, 0x05, 0x0C, 10),
        ),
        (lk.ParamReply(param=ParamId.MAX_SPEED, value=36_000), "<BBixx", (0x40, 0x9A, 36_000)),
        (lk.ParamReply(param=ParamId.CURRENT_PID, value=PID), "<BBHHH", (0x40, 0x98, 100, 200, 2000)),
    ],
    ids=lambda v: type(v).__name__ if isinstance(v, lk.LkReply) else None,
)
def test_reply_layouts_match_spec_struct_formats(reply: Any, fmt: str, values: tuple[Any, ...]) -> None:
    data = struct.pack(fmt, *values)
    assert reply.encode() == data
    assert type(reply).decode(data) == reply


def test_pid_group_reply_carries_kp_low_byte_where_the_request_had_zero() -> None:
    # Spec §4.27: for PID groups, the reply's DATA[2] is Kp's low byte (the request sends 0x00).
    reply = lk.SettingReply.decode(bytes.fromhex("40 A0 D0 07 00 00 05 00"))
    assert reply.param is SettingParam.POSITION_PID
    assert reply.value == PidGains(kp=2000, ki=0, kd=5)


@pytest.mark.parametrize(
    ("v236", "v235", "result"),
    [
        ("44 05 01 00 00 00 00 00", "44 9A 00 00 00 00 00 00", ParamResult.SUCCESS),
        ("44 05 00 00 00 00 00 00", "44 9A 01 00 00 00 00 00", ParamResult.FAILURE),
    ],
)
def test_opposite_success_bytes_decode_to_the_same_named_result(
    v236: str, v235: str, result: ParamResult
) -> None:
    # Spec §7.7: V2.36 0x44 reply 1 = OK; V2.35 0x42/0x44 reply 0 = OK.
    save = lk.SaveSettingsReply.decode(bytes.fromhex(v236))
    write = lk.ParamWriteReply.decode(bytes.fromhex(v235))
    assert save.result is result is write.result
    assert save.ok is write.ok is (result is ParamResult.SUCCESS)
    assert write.param is ParamId.MAX_SPEED
    assert save.encode() == bytes.fromhex(v236)
    assert write.encode() == bytes.fromhex(v235)
    ram = lk.ParamWriteReply.decode(bytes.fromhex("42" + v235[2:]))
    assert ram.command == 0x42 and ram.result is result


@pytest.mark.parametrize(
    ("cls", "data", "message"),
    [
        (lk.SaveSettingsReply, "44 05 02 00 00 00 00 00", "neither success nor failure"),
        (lk.SaveSettingsReply, "44 06 01 00 00 00 00 00", r"DATA\[1\] is not 0x05"),
        (lk.ParamWriteReply, "42 96 FF 00 00 00 00 00", "neither success nor failure"),
        (lk.ParamWriteReply, "42 95 00 00 00 00 00 00", r"DATA\[1\]=0x95 is not a ParamId"),
        (lk.SaveSettings, "44 05 FB 00 00 00 00 00", r"DATA\[2\] is not 0xFA"),
        (lk.ReadSetting, "40 05 0E 00 00 00 00 00", "05 0E is not a setting parameter"),
        (lk.ReadSetting, "40 A1 00 00 00 00 00 00", "A1 00 is not a setting parameter"),
        (lk.SettingReply, "40 05 0B 00 03 00 00 00", r"DATA\[4\]=0x03 is not a BusType"),
        (lk.SettingReply, "40 05 0A 00 21 00 00 00", r"driver_id=33 is outside \[0, 32\]"),
        (lk.ControlParamReply, "C0 0D 00 00 00 00 00 00", "is not a ControlParam"),
        (lk.ControlParamReply, "C1 0A D1 07 00 00 00 00", r"position_pid.kp=2001 is outside \[0, 2000\]"),
        (lk.WriteControlParam, "C1 20 00 00 C1 27 09 00", r"speed_limit=600001 is outside \[0, 600000\]"),
    ],
)
def test_parameter_decoders_raise_protocol_errors(cls: Any, data: str, message: str) -> None:
    with pytest.raises(ProtocolError, match=message):
        cls.decode(bytes.fromhex(data))


@pytest.mark.parametrize(
    ("factory", "message"),
    [
        (
            lambda: lk.WriteControlParam(param=ControlParam.TORQUE_LIMIT, value=2001),
            r"torque_limit=2001 is outside \[0, 2000\]",
        ),
        (
            lambda: lk.WriteControlParam(param=ControlParam.SPEED_LIMIT, value=-1),
            r"speed_limit=-1 is outside \[0, 600000\]",
        ),
        (lambda: lk.WriteControlParam(param=ControlParam.SPEED_PID, value=5), "speed_pid=5 is not PidGains"),
        (
            lambda: lk.WriteControlParam(param=ControlParam.SPEED_RAMP, value=PID),
            "speed_ramp=.* is not an integer",
        ),
        (lambda: lk.WriteControlParam(param=0x0A, value=PID), "param=10 is not one of ControlParam"),
        (
            lambda: lk.WriteSetting(param=SettingParam.DRIVER_ID, value=33),
            r"driver_id=33 is outside \[0, 32\]",
        ),
        (lambda: lk.WriteSetting(param=SettingParam.BUS_TYPE, value=2), "bus_type=2 is not one of BusType"),
        (lambda: lk.WriteSetting(param=SettingParam.MAX_SPEED, value=BusType.CAN), "not a plain integer"),
        (
            lambda: lk.WriteSetting(param=SettingParam.CURRENT_RAMP, value=30_001),
            r"current_ramp=30001 is outside \[0, 30000\]",
        ),
        (
            lambda: lk.WriteSetting(param=SettingParam.MAX_ANGLE, value=-1),
            r"max_angle=-1 is outside \[0, 2147483647\]",
        ),
        (
            lambda: lk.WriteSetting(param=SettingParam.CURRENT_PID, value=PidGains(kp=2001, ki=0, kd=0)),
            r"current_pid.kp=2001 is outside \[0, 2000\]",
        ),
        (
            lambda: lk.WriteParamRam(param=ParamId.MAX_ANGLE_LOW, value=-1),
            r"max_angle_low=-1 is outside \[0, 4294967295\]",
        ),
        (
            lambda: lk.WriteParamRom(param=ParamId.MAX_TORQUE_CURRENT, value=32768),
            r"max_torque_current=32768 is outside \[-32768, 32767\]",
        ),
        (lambda: PidGains(kp=0, ki=-1, kd=0), r"ki=-1 is outside \[0, 65535\]"),
        (
            lambda: lk.ControlParamReply(command=0xC2, param=ControlParam.SPEED_PID, value=PID),
            "command=0xC2 is not one of 0xC0, 0xC1",
        ),
    ],
)
def test_parameter_values_are_validated_naming_the_parameter_and_limit(factory: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        factory()


def test_max_angle_halves_round_trip() -> None:
    # Spec §6.3: maxAngle is 8 bytes split over 0x9B (bytes 0..3) and 0x9C (bytes 4..7).
    for value in (0, 1, -1, 2**40 + 5, -(2**63), 2**63 - 1):
        low, high = max_angle_halves(value)
        lk.WriteParamRam(param=ParamId.MAX_ANGLE_LOW, value=low)
        lk.WriteParamRam(param=ParamId.MAX_ANGLE_HIGH, value=high)
        assert max_angle_from_halves(low, high) == value
    assert (
        struct.pack("<q", -2)[:4]
        == lk.WriteParamRam(param=ParamId.MAX_ANGLE_LOW, value=max_angle_halves(-2)[0]).encode()[2:6]
    )
    with pytest.raises(ValueError, match="max_angle"):
        max_angle_halves(2**63)


def test_baud_enums_name_their_rates() -> None:
    assert Rs485Baud.BAUD_1000000.bps == 1_000_000
    assert Rs485Baud(9).bps == 2_000_000  # spec A8: OCR's "20000000" repaired
    assert CanBaud.BAUD_500K.bps == 500_000
    assert [b.bps for b in CanBaud] == [100_000, 125_000, 250_000, 500_000, 1_000_000]
