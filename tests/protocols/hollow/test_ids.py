"""Ids and match keys (hollow.md §3, §7.1, §9; design.md "Matching": hollow rows)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.frame import Frame
from servobus.protocols.hollow import FdReply, NormalReply, TransparentReply
from servobus.protocols.hollow.codec import reply_frame, request_frame
from servobus.protocols.hollow.ids import (
    DEFAULT_HOST_ID,
    check_host_id,
    check_modbus_slave_id,
    check_motor_id,
    modbus_reply_key,
    modbus_request_key,
    motor_id_from_reply,
    reply_id,
    reply_key,
    request_id,
    request_key,
    transparent_reply_key,
    transparent_request_key,
)
from servobus.protocols.hollow.rs485 import ModbusRead, ModbusReadReply, ModbusWriteAck

from .._contract import standard_ids


def test_request_goes_to_the_motor_id_and_the_reply_to_the_host_id() -> None:
    assert request_id(0) == 0 and request_id(100) == 100
    assert reply_id() == DEFAULT_HOST_ID == 0x064
    assert reply_id(0x123) == 0x123


@pytest.mark.parametrize(
    ("check", "value", "message"),
    [
        (check_motor_id, 101, r"motor_id=101 is outside \[0, 100\]"),
        (check_motor_id, -1, r"motor_id=-1 is outside \[0, 100\]"),
        (check_motor_id, 1.0, "motor_id=1.0 is not an integer"),
        (check_motor_id, True, "motor_id=True is not an integer"),
        (check_host_id, 0x800, r"host_id=2048 is outside \[0, 2047\]"),
        (check_modbus_slave_id, 0, r"slave_id=0 is outside \[1, 100\]"),
        (check_modbus_slave_id, 101, r"slave_id=101 is outside \[1, 100\]"),
    ],
)
def test_id_ranges(check: object, value: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        check(value)  # type: ignore[operator]


def test_request_id_and_reply_id_validate() -> None:
    with pytest.raises(ValueError, match="motor_id=101"):
        request_id(101)
    with pytest.raises(ValueError, match="host_id=-1"):
        reply_id(-1)
    with pytest.raises(ValueError, match="motor_id=200"):
        request_key(200)


@given(st.integers(0, 100), standard_ids)
def test_a_classic_reply_matches_its_request(motor_id: int, host_id: int) -> None:
    reply = NormalReply(motor_id=motor_id, position_deg=0.0, speed_rad_s=0.0, current_a=0.0)
    frame = reply_frame(host_id, reply)
    assert reply_key(frame, host_id=host_id) == request_key(motor_id, host_id=host_id) == (host_id, motor_id)


@given(st.integers(0, 100))
def test_an_fd_reply_is_keyed_by_its_slave_id(motor_id: int) -> None:
    frame = reply_frame(DEFAULT_HOST_ID, FdReply(slave_id=motor_id))
    assert frame.is_fd and frame.bitrate_switch
    assert reply_key(frame) == request_key(motor_id)
    assert motor_id_from_reply(frame.data, is_fd=True) == motor_id


def test_frames_that_are_not_our_replies_have_no_key() -> None:
    reply = bytes([5, 0x80, 0x00, 0x80, 0x08, 0x00])
    assert reply_key(Frame(arbitration_id=100, data=reply)) == (100, 5)
    assert reply_key(Frame(arbitration_id=101, data=reply)) is None  # other host
    assert reply_key(Frame(arbitration_id=100, data=reply, is_extended_id=True)) is None
    assert reply_key(Frame(arbitration_id=100, data=reply[:5])) is None  # no reply layout
    assert reply_key(Frame(arbitration_id=100, data=bytes(12), is_fd=True)) is None
    # Our own request looped back (motor id 100 = host id) is never a reply.
    assert reply_key(Frame(arbitration_id=100, data=bytes(8), is_rx=False)) is None


def test_motor_id_from_reply_payloads() -> None:
    assert motor_id_from_reply(bytes([7]) + bytes(5)) == 7
    assert motor_id_from_reply(bytes([7]) + bytes(7)) == 7
    assert motor_id_from_reply(bytes(15) + b"\x09", is_fd=True) == 9
    assert motor_id_from_reply(bytes(7)) is None
    assert motor_id_from_reply(bytes(8), is_fd=True) is None


def test_request_frames_carry_the_id_kind_of_their_command() -> None:
    from servobus.protocols.hollow import CanMode, CanModeSwitch, FdCommand, Start

    assert request_frame(3, Start()) == Frame(arbitration_id=3, data=b"\xff" * 7 + b"\xfc")
    switch = request_frame(3, CanModeSwitch(mode=CanMode.EXTENDED))
    assert switch.is_extended_id and switch.arbitration_id == 3 and not switch.is_fd
    fd = request_frame(3, FdCommand())
    assert fd.is_fd and fd.bitrate_switch and not fd.is_extended_id and len(fd.data) == 16
    with pytest.raises(ValueError, match="motor_id=101"):
        request_frame(101, Start())


def test_transparent_keys_are_the_slave_id() -> None:
    frame = TransparentReply(reply=FdReply(slave_id=42)).encode()
    assert transparent_reply_key(frame) == transparent_request_key(42) == 42
    assert transparent_reply_key(frame[:20]) is None
    with pytest.raises(ValueError, match="motor_id=101"):
        transparent_request_key(101)


def test_modbus_keys_are_the_slave_address() -> None:
    assert modbus_request_key(9) == 9
    assert modbus_reply_key(ModbusWriteAck(slave_id=9).encode()) == 9
    assert modbus_reply_key(ModbusReadReply(slave_id=9, reply=FdReply(slave_id=9)).encode()) == 9
    assert modbus_reply_key(ModbusRead(slave_id=9).encode()) == 9
    assert modbus_reply_key(b"") is None
