"""Replies: normal (6 B), extended (8 B) and CAN FD (16 B) (hollow.md §4.5, §5.3, §7.3)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given

from servobus.errors import ProtocolError
from servobus.protocols.hollow import (
    DEFAULT_MODEL,
    ControlMode,
    ExtendedReply,
    FdReply,
    HollowModel,
    NormalReply,
)
from servobus.protocols.hollow.replies import EXTENDED_POSITION_LIMITS_DEG

from .._contract import assert_quantised
from ._strategies import MODELS, extended_replies, fd_replies, normal_replies

COUNT_DEG = 360.0 / (1 << 20)


@given(normal_replies())
def test_normal_reply_round_trip_is_quantisation(reply: NormalReply) -> None:
    frame = reply.encode()
    assert len(frame) == 6 and frame[0] == reply.motor_id
    decoded = NormalReply.decode(frame, model=reply.model)
    model = reply.model
    assert_quantised(
        decoded.position_deg, reply.position_deg, model.position_full_scale_deg / 0x8000, field="p"
    )
    assert_quantised(decoded.speed_rad_s, reply.speed_rad_s, model.speed_full_scale_rad_s / 0x800, field="v")
    assert_quantised(decoded.current_a, reply.current_a, model.current_full_scale_a / 0x800, field="t")
    assert decoded.motor_id == reply.motor_id
    assert decoded.encode() == frame


@given(extended_replies())
def test_extended_reply_round_trip_is_quantisation(reply: ExtendedReply) -> None:
    frame = reply.encode()
    assert len(frame) == 8 and frame[0] == reply.motor_id
    decoded = ExtendedReply.decode(frame, model=reply.model)
    model = reply.model
    assert_quantised(decoded.position_deg, reply.position_deg, COUNT_DEG, field="x")
    assert_quantised(decoded.speed_rad_s, reply.speed_rad_s, model.speed_full_scale_rad_s / 0x800, field="v")
    assert_quantised(decoded.current_a, reply.current_a, model.current_full_scale_a / 0x800, field="t")
    assert decoded.encode() == frame


@given(fd_replies())
def test_fd_reply_round_trip_is_quantisation(reply: FdReply) -> None:
    frame = reply.encode()
    assert len(frame) == 16 and frame[15] == reply.slave_id
    decoded = FdReply.decode(frame, model=reply.model)
    assert_quantised(decoded.position_deg, reply.position_deg, COUNT_DEG, field="position_deg")
    rpm_res = 1 / reply.model.fd_velocity_counts_per_rpm
    assert_quantised(decoded.velocity_rpm, reply.velocity_rpm, rpm_res, field="velocity_rpm")
    same = ("current_raw", "mode", "running", "reserved", "temperature_c", "slave_id")
    assert [getattr(decoded, f) for f in same] == [getattr(reply, f) for f in same]
    assert decoded.encode() == frame


def test_normal_reply_example_and_manual_decode() -> None:
    # §4.5 illustrative frame: motor 1 at +180 deg, at rest, 0 A.
    reply = NormalReply.decode(bytes.fromhex("01 C0 00 80 08 00"))
    assert reply == NormalReply(motor_id=1, position_deg=180.0, speed_rad_s=0.0, current_a=0.0)
    assert not reply.position_saturated


@pytest.mark.parametrize("frame", ["01 00 00 80 08 00", "01 FF FF 80 08 00"])
def test_normal_reply_saturation(frame: str) -> None:
    # A34: outside ±Pmax the position code sticks at 0x0000 / 0xFFFF.
    assert NormalReply.decode(bytes.fromhex(frame)).position_saturated


def test_extended_reply_examples() -> None:
    # §5.3 illustrative frames: +1/2 turn, and X = -1.
    half = ExtendedReply.decode(bytes.fromhex("01 00 00 80 08 00 00 08"))
    assert (half.motor_id, half.position_deg, half.position_counts) == (1, 180.0, 0x80000)
    minus_one = ExtendedReply.decode(bytes.fromhex("01 FF FF 80 08 00 FF FF"))
    assert minus_one.position_counts == -1 and minus_one.position_deg == -COUNT_DEG
    assert ExtendedReply(
        motor_id=1, position_deg=-COUNT_DEG, speed_rad_s=0, current_a=0
    ).encode() == bytes.fromhex("01 FF FF 80 08 00 FF FF")


def test_extended_reply_position_limits_are_2048_turns() -> None:
    lo, hi = EXTENDED_POSITION_LIMITS_DEG
    assert lo == -2048 * 360.0 and hi == 2048 * 360.0 - COUNT_DEG
    with pytest.raises(ValueError, match=r"position_deg=.* is outside \[-737280\.0, "):
        ExtendedReply(motor_id=1, position_deg=math.nextafter(hi, math.inf), speed_rad_s=0, current_a=0)


def test_fd_reply_temperature_is_int8() -> None:
    frame = bytearray(16)
    frame[14] = 0xE2  # -30 °C
    frame[15] = 7
    reply = FdReply.decode(bytes(frame))
    assert (reply.temperature_c, reply.slave_id) == (-30, 7)


@pytest.mark.parametrize(("byte", "value"), [(0x7E, 126), (0x7F, 127), (0x80, -128), (0x82, -126)])
def test_fd_reply_temperature_outside_the_manual_range_is_a_protocol_error(byte: int, value: int) -> None:
    # Manual §VII (spec §7.3, A39): "Temperature -125-125 degrees"; int8 holds 3 more each side.
    frame = bytearray(16)
    frame[14] = byte
    frame[15] = 7
    with pytest.raises(ProtocolError, match=rf"temperature_c={value} is outside \[-125, 125\]"):
        FdReply.decode(bytes(frame))
    for edge, degrees in ((0x7D, 125), (0x83, -125)):
        frame[14] = edge
        assert FdReply.decode(bytes(frame)).temperature_c == degrees


@pytest.mark.parametrize(
    ("index", "value", "message"),
    [
        (11, 3, "Mode: unknown value 3"),
        (12, 2, "running=2"),
        (15, 101, r"slave_id=101 is outside \[0, 100\]"),
    ],
)
def test_fd_reply_decode_refuses_unknown_bytes(index: int, value: int, message: str) -> None:
    frame = bytearray(16)
    frame[index] = value
    with pytest.raises(ProtocolError, match=message):
        FdReply.decode(bytes(frame))


def test_fd_reply_keeps_the_reserved_byte() -> None:
    frame = bytes(13) + b"\x5a\x00\x01"
    assert FdReply.decode(frame).reserved == 0x5A
    assert FdReply.decode(frame).encode() == frame


@pytest.mark.parametrize("cls", [NormalReply, ExtendedReply])
def test_classic_reply_motor_id_range(cls: type[NormalReply] | type[ExtendedReply]) -> None:
    size = 6 if cls is NormalReply else 8
    with pytest.raises(ProtocolError, match=r"motor_id=101 is outside \[0, 100\]"):
        cls.decode(bytes([101]) + bytes(size - 1))
    with pytest.raises(ProtocolError, match=f"expected {size} data bytes, got {size + 1}"):
        cls.decode(bytes(size + 1))
    with pytest.raises(ValueError, match=r"motor_id=-1 is outside \[0, 100\]"):
        cls(motor_id=-1, position_deg=0.0, speed_rad_s=0.0, current_a=0.0)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
@pytest.mark.parametrize("cls", [NormalReply, ExtendedReply])
def test_classic_reply_speed_and_current_just_outside(model: HollowModel, cls: type[NormalReply]) -> None:
    speed = model.speed_full_scale_rad_s
    current = model.current_full_scale_a
    where = rf" for model {model.name}$"
    with pytest.raises(ValueError, match=rf"^speed_rad_s=.* is outside \[-{speed!r}, {speed!r}\]{where}"):
        cls(
            motor_id=1,
            position_deg=0.0,
            speed_rad_s=math.nextafter(speed, math.inf),
            current_a=0.0,
            model=model,
        )
    with pytest.raises(ValueError, match=rf"^current_a=.* is outside \[-{current!r}, {current!r}\]{where}"):
        cls(
            motor_id=1,
            position_deg=0.0,
            speed_rad_s=0.0,
            current_a=math.nextafter(-current, -math.inf),
            model=model,
        )


def test_fd_reply_ranges() -> None:
    with pytest.raises(ValueError, match=r"temperature_c=126 is outside \[-125, 125\]"):
        FdReply(slave_id=1, temperature_c=126)
    with pytest.raises(ValueError, match=r"reserved=256 is outside \[0, 255\]"):
        FdReply(slave_id=1, reserved=256)
    assert FdReply(slave_id=1, mode=2).mode is ControlMode.POSITION  # type: ignore[arg-type]
    assert FdReply(slave_id=1).model is DEFAULT_MODEL


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.name)
def test_saturation_is_the_end_codes_for_every_model(model: HollowModel) -> None:
    full = model.position_full_scale_deg
    for position, saturated in ((-full, True), (full, True), (0.0, False), (full * 0.999, False)):
        reply = NormalReply(motor_id=1, position_deg=position, speed_rad_s=0.0, current_a=0.0, model=model)
        assert reply.position_saturated is saturated
        assert NormalReply.decode(reply.encode(), model=model).position_saturated is saturated
