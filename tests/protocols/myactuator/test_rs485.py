"""RS485 standard frames (rs485.py): framing, CRC, broadcast, the stream de-framer, any bytes."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.core import crc16_modbus
from servobus.errors import ProtocolError
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.rs485 import (
    decode_rs485,
    decode_rs485_reply,
    decode_rs485_request,
    encode_rs485,
    rs485_deframer,
)

from .._contract import decodes_or_protocol_error

ABSOLUTE = ma.AbsolutePositionControl(angle_deg=360, max_speed_dps=500)

# §1.2's table: frames from the manuals with their CRC-16/MODBUS.
SPEC_FRAMES = [
    (1, ma.ReadStatus2(), "3E 01 08 9C 00 00 00 00 00 00 00 F2 30"),
    (1, ma.ReadPid(index=ma.PidIndex.CURRENT_KP), "3E 01 08 30 01 00 00 00 00 00 00 E8 DD"),
    (1, ma.SpeedControl(speed_dps=100), "3E 01 08 A2 00 00 00 10 27 00 00 C4 63"),
    (
        1,
        ma.AbsolutePositionControl(angle_deg=360, max_speed_dps=500),
        "3E 01 08 A4 00 F4 01 A0 8C 00 00 3B DD",
    ),
    (0xCD, ma.MotorShutdown(), "3E CD 08 80 00 00 00 00 00 00 00 36 6A"),
]
SPEC_REPLIES = [
    (
        ma.Status1Reply(
            temperature_c=50,
            mos_temperature_c=0,
            brake_released=True,
            voltage_v=48.5,
            errors=ma.ErrorFlags(4),
        ),
        "3E 01 08 9A 32 00 01 E5 01 04 00 38 15",
    ),
    (ma.MultiTurnAngleReply(angle_deg=360), "3E 01 08 92 00 00 00 A0 8C 00 00 90 57"),
    (ma.Echo(command=ma.MotorShutdown()), "3E 01 08 80 00 00 00 00 00 00 00 F3 69"),
]


@pytest.mark.parametrize(("motor_id", "command", "frame"), SPEC_FRAMES)
def test_requests_frame_as_in_the_spec(motor_id: int, command: ma.MyActuatorCommand, frame: str) -> None:
    assert encode_rs485(motor_id, command) == bytes.fromhex(frame)
    assert encode_rs485(motor_id, command.encode()) == bytes.fromhex(frame)
    assert decode_rs485_request(bytes.fromhex(frame)) == (motor_id, command)


@pytest.mark.parametrize(("reply", "frame"), SPEC_REPLIES)
def test_replies_frame_as_in_the_spec(reply: ma.MyActuatorReply, frame: str) -> None:
    assert encode_rs485(1, reply) == bytes.fromhex(frame)
    assert decode_rs485_reply(bytes.fromhex(frame)) == (1, reply)


def test_frame_checks() -> None:
    good = bytes.fromhex("3E 01 08 9C 00 00 00 00 00 00 00 F2 30")
    assert decode_rs485(good) == (1, bytes.fromhex("9C 00 00 00 00 00 00 00"))
    cases = {
        good[:-1]: "expected 13 bytes, got 12",
        b"\x3f" + good[1:]: "header 0x3F is not 0x3E",
        good[:2] + b"\x07" + good[3:]: "length byte 7 is not 8",
        good[:-1] + b"\x31": "CRC F2 31 should be F2 30",
    }
    for frame, message in cases.items():
        with pytest.raises(ProtocolError, match=message):
            decode_rs485(frame)
    body = bytes.fromhex("3E 21 08 9C 00 00 00 00 00 00 00")
    with pytest.raises(ProtocolError, match=r"id byte 0x21 is neither 1\.\.32 nor 0xCD"):
        decode_rs485(body + crc16_modbus(body).to_bytes(2, "little"))


def test_what_has_no_rs485_standard_frame() -> None:
    with pytest.raises(ValueError, match="0xB6 active reply is CAN only"):
        encode_rs485(
            1, ma.ActiveReply(command=ma.StreamableCommand.ENCODER_POSITION, enabled=True, interval_ms=10)
        )
    motion = ma.MotionCommand(position_rad=0, velocity_rad_s=0, kp=0, kd=0, torque_ff_nm=0)
    with pytest.raises(ValueError, match="no RS485 standard frame"):
        encode_rs485(1, motion)
    with pytest.raises(ValueError, match="0x79 is sent with ID byte 0xCD, not 1"):
        encode_rs485(1, ma.SetCanId(motor_id=2))
    with pytest.raises(ValueError, match=r"motor_id=33 is outside \[1, 32\] and is not the broadcast 0xCD"):
        encode_rs485(33, ma.MotorStop())
    with pytest.raises(ValueError, match="payload has 7 bytes"):
        encode_rs485(1, bytes(7))
    with pytest.raises(ValueError, match=r"exists only in V4\.3"):
        encode_rs485(0xCD, ma.ReadCanId(), revision=ma.Revision.V4_4)
    active = bytes.fromhex("B6 60 01 01 00 00 00 00")
    with pytest.raises(ProtocolError, match="0xB6 active reply is CAN only"):
        decode_rs485_request(encode_rs485(1, active))


def test_id_byte_rules_of_0x79_and_broadcast() -> None:
    write = encode_rs485(0xCD, ma.SetCanId(motor_id=2))
    assert write == bytes.fromhex("3E CD 08 79 00 00 00 00 00 00 02 78 85")
    assert decode_rs485_request(write, revision=ma.Revision.V4_3) == (0xCD, ma.SetCanId(motor_id=2))
    assert decode_rs485_reply(write, revision=ma.Revision.V4_3) == (
        0xCD,
        ma.Echo(command=ma.SetCanId(motor_id=2)),
    )
    with pytest.raises(ProtocolError, match="0x79 is sent on 0x300"):
        decode_rs485_request(encode_rs485(1, write[3:11]), revision=ma.Revision.V4_3)
    # A broadcast of any other command is fine as a request; a reply always names its motor.
    shutdown = encode_rs485(0xCD, ma.MotorShutdown())
    assert decode_rs485_request(shutdown) == (0xCD, ma.MotorShutdown())
    with pytest.raises(ProtocolError, match="carry the motor's own id"):
        decode_rs485_reply(shutdown)


def test_a_stream_of_frames_fed_byte_by_byte_comes_back_whole() -> None:
    frames = [encode_rs485(motor_id, command) for motor_id, command, _ in SPEC_FRAMES]
    frames += [encode_rs485(3, reply) for reply, _ in SPEC_REPLIES]
    stream = b"".join(frames)
    deframer = rs485_deframer()
    out = [frame for byte in stream for frame in deframer.feed(bytes([byte]))]
    assert out == frames
    assert (deframer.discarded_bytes, deframer.crc_errors, deframer.pending) == (0, 0, 0)
    # With noise between frames, and fed whole: the frames still come back, the noise is counted.
    noisy = rs485_deframer()
    assert noisy.feed(b"\x00\x3e\x01" + frames[0] + b"\xff" + frames[1]) == frames[:2]
    assert noisy.discarded_bytes > 0
    assert [decode_rs485(frame)[1] for frame in out[:3]] == [c.encode() for _, c, _ in SPEC_FRAMES[:3]]


id_bytes = st.one_of(st.integers(0, 255), st.sampled_from([1, 32, 0xCD]))


@given(st.binary(max_size=20))
def test_decoders_take_any_bytes(frame: bytes) -> None:
    for decode in (decode_rs485_request, decode_rs485_reply):
        decodes_or_protocol_error(lambda f: decode(f)[1], frame)  # noqa: B023
    with contextlib.suppress(ProtocolError):
        decode_rs485(frame)


@given(id_bytes, st.binary(min_size=8, max_size=8), st.sampled_from(list(ma.Revision)))
def test_decoders_take_any_payload_in_a_valid_frame(
    motor_id: int, data: bytes, revision: ma.Revision
) -> None:
    body = bytes((0x3E, motor_id, 8)) + data
    frame = body + crc16_modbus(body).to_bytes(2, "little")
    for decode in (decode_rs485_request, decode_rs485_reply):
        decodes_or_protocol_error(lambda f: decode(f, revision=revision)[1], frame)  # noqa: B023
