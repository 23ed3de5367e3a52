"""RS485 motion-mode frames (rs485_motion.py): the layout as far as the spec reconstructs it."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.core import crc32_ieee
from servobus.errors import ProtocolError
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator import rs485_motion
from servobus.protocols.myactuator.codec import check_available
from servobus.protocols.myactuator.rs485_motion import crc32_iso_hdlc_le

from .._contract import decodes_or_protocol_error

COMMAND = ma.Rs485MotionCommand(
    motor_id=1, position_rad=1.5, velocity_rad_s=-2.0, kp=10.0, kd=0.5, torque_ff_nm=0.25
)


def test_request_layout() -> None:
    frame = COMMAND.encode()
    assert len(frame) == 28
    assert frame[:4] == bytes.fromhex("FE EE 01 0A")
    # §6: t_ff, v_des, p_des, kp, kd as little-endian float32 in bytes 5..24 (1-based).
    assert struct.unpack("<5f", frame[4:24]) == (0.25, -2.0, 1.5, 10.0, 0.5)
    assert frame[24:] == crc32_ieee(frame[:24]).to_bytes(4, "little")
    assert ma.Rs485MotionCommand.decode(frame) == COMMAND


def test_reply_layout() -> None:
    body = bytes.fromhex("FE EE 02 0A E2 16 00 7F") + struct.pack("<3f", 1.0, -3.0, 0.5)
    frame = body + crc32_ieee(body).to_bytes(4, "little")
    reply = ma.Rs485MotionReply.decode(frame)
    assert reply == ma.Rs485MotionReply(
        motor_id=2,
        mode=ma.Rs485MotionMode.SERVO,
        temperature_c=-30,
        errors=ma.ErrorFlags(0x0016),
        torque_nm=1.0,
        speed_rad_s=-3.0,
        position_rad=0.5,
    )
    # The reserved byte (0x7F here) is ignored, so it re-encodes as 0.
    assert reply.encode()[7] == 0 and reply.encode()[:7] == frame[:7]


def test_the_crc_rule_is_pluggable() -> None:
    frame = COMMAND.encode()
    broken = frame[:-1] + bytes([frame[-1] ^ 1])
    with pytest.raises(ProtocolError, match="the CRC rule is unverified"):
        ma.Rs485MotionCommand.decode(broken)
    assert ma.Rs485MotionCommand.decode(broken, crc=None) == COMMAND

    def big_endian(body: bytes) -> bytes:
        return crc32_ieee(body).to_bytes(4, "big")

    other = COMMAND.encode(crc=big_endian)
    assert other[:24] == frame[:24] and other[24:] == frame[24:][::-1]
    assert ma.Rs485MotionCommand.decode(other, crc=big_endian) == COMMAND
    assert crc32_iso_hdlc_le(b"123456789") == (0xCBF43926).to_bytes(4, "little")


def test_frame_checks() -> None:
    frame = COMMAND.encode()
    with pytest.raises(ProtocolError, match="expected 28 bytes, got 24"):
        ma.Rs485MotionCommand.decode(frame[:24])
    with pytest.raises(ProtocolError, match="header FE EF is not FE EE"):
        ma.Rs485MotionCommand.decode(b"\xfe\xef" + frame[2:], crc=None)
    with pytest.raises(ProtocolError, match="mode=0x05 is not one of Rs485MotionMode"):
        ma.Rs485MotionCommand.decode(frame[:3] + b"\x05" + frame[4:], crc=None)
    with pytest.raises(ProtocolError, match="is not finite"):
        ma.Rs485MotionCommand.decode(frame[:4] + struct.pack("<f", float("nan")) + frame[8:], crc=None)


def test_ids_and_revision() -> None:
    broadcast = ma.Rs485MotionCommand(
        motor_id=0xBB, position_rad=0, velocity_rad_s=0, kp=0, kd=0, torque_ff_nm=0
    )
    assert broadcast.encode()[2] == 0xBB
    with pytest.raises(ValueError, match="not the broadcast 0xBB"):
        ma.Rs485MotionCommand(motor_id=0x33, position_rad=0, velocity_rad_s=0, kp=0, kd=0, torque_ff_nm=0)
    with pytest.raises(ValueError, match=r"RS485 motion mode command exists only in V4\.4"):
        check_available(COMMAND, ma.Revision.V4_3)
    check_available(COMMAND, ma.Revision.V4_4)


def test_values_are_float32() -> None:
    command = ma.Rs485MotionCommand(
        motor_id=1, position_rad=0.1, velocity_rad_s=0, kp=0, kd=0, torque_ff_nm=0
    )
    assert ma.Rs485MotionCommand.decode(command.encode()).position_rad == rs485_motion.float32(0.1) != 0.1
    with pytest.raises(ValueError, match="kp=1e\\+39 is outside"):
        ma.Rs485MotionCommand(motor_id=1, position_rad=0, velocity_rad_s=0, kp=1e39, kd=0, torque_ff_nm=0)


@given(st.binary(max_size=32), st.booleans())
def test_decoders_take_any_bytes(data: bytes, with_crc: bool) -> None:
    for cls, size in ((ma.Rs485MotionCommand, 28), (ma.Rs485MotionReply, 24)):
        frame = data
        if with_crc:
            body = (b"\xfe\xee" + data)[: size - 4].ljust(size - 4, b"\x00")
            frame = body + crc32_ieee(body).to_bytes(4, "little")
        decodes_or_protocol_error(cls.decode, frame)
