"""LK replies (replies.py): round trips, exact layouts per spec §13, named state bytes, range errors."""

from __future__ import annotations

import struct
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.protocols import lk
from servobus.protocols.lk import ErrorState, ErrorStateV235, LkModel, MotorState, MotorType, Revision
from servobus.protocols.lk.codec import REPLY_LAYOUTS

from ._strategies import REPLIES, check_round_trip

V236 = LkModel(revision=Revision.V2_36)
V235 = LkModel(revision=Revision.V2_35)


def test_every_reply_class_has_a_round_trip_strategy() -> None:
    assert set(REPLIES) == {cls for cls, _ in REPLY_LAYOUTS}


@pytest.mark.parametrize("cls", sorted(REPLIES, key=lambda c: c.__name__), ids=lambda c: c.__name__)
@given(data=st.data())
def test_reply_round_trip_is_quantisation(cls: type, data: st.DataObject) -> None:
    case = REPLIES[cls]
    check_round_trip(data.draw(case.strategy), case)


def test_status1_v236_decodes_named_state_and_flags() -> None:
    # Spec §13 `<BbhhBB`: 25 °C, 24.00 V, -1.50 A, motor OFF, low voltage + stall.
    data = struct.pack("<BbhhBB", 0x9A, 25, 2400, -150, 0x10, 0x41)
    reply = lk.Status1Reply.decode(data)
    assert reply == lk.Status1Reply(
        command=0x9A,
        temperature_c=25,
        voltage_v=24.0,
        current_a=-1.5,
        motor_state=MotorState.OFF,
        error_state=ErrorState.LOW_VOLTAGE | ErrorState.MOTOR_STALL,
    )
    assert reply.encode() == data
    assert lk.Status1Reply.decode(b"\x9b" + data[1:]).command == 0x9B


def test_status1_v235_decodes_its_own_layout() -> None:
    # Spec §13 `<BbxHxxB`: -5 °C, 48.3 V (0.1 V/LSB), over-temperature plus an undocumented bit 6.
    data = struct.pack("<BbxHxxB", 0x9A, -5, 483, 0x48)
    reply = lk.Status1ReplyV235.decode(data)
    assert reply.temperature_c == -5
    assert reply.voltage_v == 48.3
    assert ErrorStateV235.OVER_TEMPERATURE in reply.error_state
    assert ErrorStateV235.LOW_VOLTAGE not in reply.error_state
    assert int(reply.error_state) == 0x48  # the unknown bit is kept, not dropped
    assert reply.encode() == data


def test_unknown_motor_state_is_a_protocol_error() -> None:
    with pytest.raises(ProtocolError, match=r"DATA\[6\]=0x01 is not a MotorState"):
        lk.Status1Reply.decode(struct.pack("<BbhhBB", 0x9A, 0, 0, 0, 0x01, 0))


@pytest.mark.parametrize(
    ("motor_type", "expected"),
    [
        (MotorType.MF, {"current_a": -100 * 33 / 4096}),
        (MotorType.MG, {"current_a": -100 * 66 / 4096}),
        (MotorType.MS, {"power_counts": -100}),
        (MotorType.MH, {"iq_counts": -100}),
    ],
)
def test_status2_reads_iq_per_motor_type(motor_type: MotorType, expected: dict[str, Any]) -> None:
    # Spec §8.2; layout `<BbhhH`.
    data = struct.pack("<BbhhH", 0xA1, 40, -100, -720, 16383)
    reply = lk.Status2Reply.decode(data, model=LkModel(motor_type=motor_type))
    fields = {"current_a": None, "power_counts": None, "iq_counts": None, **expected}
    assert reply == lk.Status2Reply(
        command=0xA1,
        motor_type=motor_type,
        encoder_bits=14,
        temperature_c=40,
        speed_dps=-720.0,
        encoder_counts=16383,
        **fields,
    )
    assert reply.encoder_deg == pytest.approx(16383 * 360 / 16384)
    assert reply.encode() == data


def test_status2_rejects_counts_beyond_the_declared_encoder_width() -> None:
    data = struct.pack("<BbhhH", 0x9C, 0, 0, 0, 40000)
    with pytest.raises(ProtocolError, match=r"encoder_counts=40000 is outside \[0, 16383\]"):
        lk.Status2Reply.decode(data)
    wide = lk.Status2Reply.decode(data, model=LkModel(encoder_bits=16))
    assert wide.encoder_deg == pytest.approx(40000 * 360 / 65536)
    # 18-bit: the uint16 field holds 0..65535; the angle assumes the top 16 bits (inferred).
    assert lk.Status2Reply.decode(data, model=LkModel(encoder_bits=18)).encoder_deg == wide.encoder_deg


def test_status2_accepts_iq_beyond_the_nominal_range() -> None:
    # The nominal iq range is ±2048; a reply carries whatever the int16 holds.
    data = struct.pack("<BbhhH", 0x9C, 0, -32768, 32767, 0)
    reply = lk.Status2Reply.decode(data, model=LkModel(motor_type=MotorType.MG))
    assert reply.current_a == -32768 * 66 / 4096
    assert reply.speed_dps == 32767
    assert reply.encode() == data


def test_status3_phase_currents_per_revision_and_motor_type() -> None:
    v236 = struct.pack("<Bbhhh", 0x9D, 30, 4096, -4096, 0)
    mg = lk.Status3Reply.decode(v236, model=LkModel(motor_type=MotorType.MG))
    assert mg.temperature_c == 30
    assert mg.currents_a == (66.0, -66.0, 0.0)
    mf = lk.Status3Reply.decode(v236, model=LkModel(motor_type=MotorType.MF))
    assert mf.currents_a == (33.0, -33.0, 0.0)
    ms = lk.Status3Reply.decode(v236, model=LkModel(motor_type=MotorType.MS))
    assert ms.currents_a is None
    assert ms.currents_counts == (4096, -4096, 0)
    # V2.35 `<Bxhhh`: DATA[1] NULL, 1/64 A/LSB for every motor.
    v235 = struct.pack("<Bxhhh", 0x9D, 64, -32, 1)
    assert lk.Status3ReplyV235.decode(v235).currents_a == (1.0, -0.5, 1 / 64)


def test_single_turn_angle_layouts_differ_per_revision() -> None:
    # Spec §4.25 D9: not wire-compatible.
    assert lk.SingleTurnAngleReply.decode(struct.pack("<BxxxI", 0x94, 72000)).angle_deg == 720.0
    assert lk.SingleTurnAngleReplyV235.decode(struct.pack("<BxxxxxH", 0x94, 35999)).angle_deg == 359.99
    assert lk.SingleTurnAngleReplyV235(angle_deg=1).encode() == bytes.fromhex("94 00 00 00 00 00 64 00")
    assert lk.SingleTurnAngleReply(angle_deg=1).encode() == bytes.fromhex("94 00 00 00 64 00 00 00")


@pytest.mark.parametrize(
    ("data", "angle"),
    [
        ("92 01 00 00 00 00 00 00", 0.01),
        ("92 FF FF FF FF FF FF FF", -0.01),  # 56-bit two's complement (spec A7)
        ("92 00 00 00 00 00 00 80", -(2**55) / 100),
    ],
)
def test_multi_turn_angle_is_56_bit_signed(data: str, angle: float) -> None:
    raw = bytes.fromhex(data)
    if abs(angle) > 2**53 / 100:
        with pytest.raises(ProtocolError, match="angle_deg"):
            lk.MultiTurnAngleReply.decode(raw)
        return
    reply = lk.MultiTurnAngleReply.decode(raw)
    assert reply.angle_deg == angle
    assert reply.encode() == raw


def test_encoder_and_offset_replies() -> None:
    data = struct.pack("<BxHHH", 0x90, 100, 300, 200)
    assert lk.EncoderReply.decode(data) == lk.EncoderReply(
        encoder_bits=14, encoder_counts=100, raw_counts=300, offset_counts=200
    )
    offset = struct.pack("<BxxxxxH", 0x19, 1234)
    assert lk.EncoderOffsetReply.decode(offset).offset_counts == 1234
    assert lk.EncoderOffsetReply.decode(b"\x91" + offset[1:]).command == 0x91


def test_calibration_reply_names_its_bits() -> None:
    # Spec §13 `<BIHB`, §7.5.
    data = struct.pack("<BIHB", 0x18, 123456, 998, 0x11)
    reply = lk.CalibrationReply.decode(data)
    assert reply.align_value == 123456
    assert reply.align_ratio == 998
    assert reply.succeeded
    assert reply.phase_inverted
    failed = lk.CalibrationReply.decode(struct.pack("<BIHB", 0x18, 0, 0, 0x00))
    assert not failed.succeeded
    assert not failed.phase_inverted


def test_brake_reply_names_the_state() -> None:
    assert lk.BrakeReply.decode(bytes.fromhex("8C 01 00 00 00 00 00 00")).state is lk.BrakeState.RELEASED
    assert lk.BrakeReply.decode(bytes.fromhex("8C 00 00 00 00 00 00 00")).state is lk.BrakeState.ENGAGED
    with pytest.raises(ProtocolError, match="BrakeState"):
        lk.BrakeReply.decode(bytes.fromhex("8C 10 00 00 00 00 00 00"))


def test_acceleration_reply_is_the_0x34_echo() -> None:
    data = struct.pack("<Bxxxi", 0x34, 5000)
    assert lk.AccelerationReply.decode(data).acceleration_dps2 == 5000
    assert lk.WriteAcceleration(acceleration_dps2=5000).encode() == data


def test_replies_ignore_null_bytes() -> None:
    # Spec §0: NULL bytes in replies are not relied on.
    assert lk.EchoReply.decode(bytes.fromhex("95 12 34 56 78 9A BC DE")) == lk.EchoReply(command=0x95)
    v235 = lk.Status1ReplyV235.decode(bytes.fromhex("9A 19 FF E3 01 FF FF 00"))
    assert v235.voltage_v == 48.3


@pytest.mark.parametrize(
    ("factory", "message"),
    [
        (lambda: lk.EchoReply(command=0x9C), "command=0x9C is not one of 0x80, 0x81, 0x88, 0x95"),
        (
            lambda: lk.Status1Reply(
                command=0x9A,
                temperature_c=128,
                voltage_v=0,
                current_a=0,
                motor_state=MotorState.ON,
                error_state=ErrorState(0),
            ),
            r"temperature_c=128 is outside \[-128, 127\]",
        ),
        (
            lambda: lk.Status1ReplyV235(
                command=0x9A, temperature_c=0, voltage_v=-0.1, error_state=ErrorStateV235(0)
            ),
            r"voltage_v=-0.1 is outside \[0.0, 6553.5\]",
        ),
        (
            lambda: lk.Status2Reply(
                command=0xA1,
                motor_type=MotorType.MS,
                encoder_bits=14,
                temperature_c=0,
                speed_dps=0,
                encoder_counts=0,
                current_a=1.0,
            ),
            "current_a=1.0 given for motor_type=MS, which uses power_counts",
        ),
        (
            lambda: lk.Status2Reply(
                command=0xA1,
                motor_type=MotorType.MF,
                encoder_bits=14,
                temperature_c=0,
                speed_dps=32767.6,
                encoder_counts=0,
                current_a=1.0,
            ),
            r"speed_dps=32767.6 is outside \[-32768.0, 32767.0\]",
        ),
        (lambda: lk.Status3ReplyV235(currents_a=(0.0, 512.0, 0.0)), "phase B: currents_a=512.0 is outside"),
        (
            lambda: lk.CalibrationReply(align_value=2**32, align_ratio=0, align_state=lk.AlignState(0)),
            "align_value",
        ),
        (
            lambda: lk.CalibrationReply(align_value=0, align_ratio=0, align_state=lk.AlignState(256)),
            "align_state",
        ),
        (lambda: lk.AccelerationReply(command=0x34, acceleration_dps2=2.0**31), "acceleration_dps2"),
        (
            lambda: lk.SingleTurnAngleReplyV235(angle_deg=655.36),
            r"angle_deg=655.36 is outside \[0.0, 655.35\]",
        ),
    ],
)
def test_reply_fields_are_validated(factory: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        factory()


# ---- decoded values outside the manuals' ranges (issue 13) ----


@pytest.mark.parametrize(
    ("revision", "motor_type", "command", "counts", "message"),
    [
        # [003] §4.14 / §5: iq "Range:-2048~2048" in the 0x9C and 0xA1..0xA8 replies.
        (
            Revision.V2_35,
            MotorType.MG,
            0x9C,
            2049,
            r"current_a=33\.01611328125 \(2049 counts\) is outside \[-2048",
        ),
        (
            Revision.V2_35,
            MotorType.MF,
            0xA4,
            -2049,
            r"current_a=.* \(-2049 counts\) is outside \[-2048, 2048\]",
        ),
        (Revision.V2_35, MotorType.MH, 0xA1, 4000, r"iq_counts=4000 .* outside \[-2048, 2048\]"),
    ],
)
def test_status2_torque_field_outside_the_stated_range_is_a_protocol_error(
    revision: Revision, motor_type: MotorType, command: int, counts: int, message: str
) -> None:
    model = LkModel(revision=revision, motor_type=motor_type)
    data = struct.pack("<BbhhH", command, 30, counts, 0, 0)
    with pytest.raises(ProtocolError, match=message):
        lk.Status2Reply.decode(data, model=model)
    limit = lk.replies.torque_range(revision, motor_type, command)
    assert limit is not None
    edge = struct.pack("<BbhhH", command, 30, limit[1] if counts > 0 else limit[0], 0, 0)
    assert lk.Status2Reply.decode(edge, model=model).encode() == edge


def test_status2_v236_iq_has_no_stated_range() -> None:
    # [001] gives only the resolution of a reported iq (MF/MG/MH): the int16 range decodes.
    assert lk.replies.torque_range(Revision.V2_36, MotorType.MG, 0x9C) is None
