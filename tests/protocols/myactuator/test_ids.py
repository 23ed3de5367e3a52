"""Arbitration ids and match keys (ids.py), against design.md's "Matching" table."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.frame import Frame
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.ids import (
    BROADCAST_ID,
    ID_SETTING_ID,
    RS485_BROADCAST_ID,
    broadcast_reply_keys,
    check_motor_id,
    classify_id,
    motion_reply_id,
    motion_request_id,
    motor_id_from_reply_id,
    reply_id,
    reply_key,
    request_id,
    request_key,
    rs485_reply_key,
    rs485_request_key,
)

from .._contract import can_payloads, standard_ids

motor_ids = st.integers(1, 32)


def test_identifier_arithmetic() -> None:
    assert (request_id(1), reply_id(1)) == (0x141, 0x241)
    assert (request_id(32), reply_id(32)) == (0x160, 0x260)
    assert (motion_request_id(1), motion_reply_id(32)) == (0x401, 0x520)
    assert (BROADCAST_ID, ID_SETTING_ID, RS485_BROADCAST_ID) == (0x280, 0x300, 0xCD)
    assert motor_id_from_reply_id(0x244) == 4
    assert motor_id_from_reply_id(0x501) == 1


@pytest.mark.parametrize("bad", [0, 33, -1, True, 1.0])
def test_motor_ids_are_1_to_32(bad: object) -> None:
    for function in (request_id, reply_id, motion_request_id, motion_reply_id, check_motor_id):
        with pytest.raises(ValueError, match=r"motor_id=.* is outside \[1, 32\]"):
            function(bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("can_id", [0x141, 0x280, 0x300, 0x240, 0x261, 0x401])
def test_motor_id_from_reply_id_refuses_other_identifiers(can_id: int) -> None:
    with pytest.raises(ValueError, match="is not a MyActuator reply identifier"):
        motor_id_from_reply_id(can_id)


def test_classify_every_identifier() -> None:
    kinds = {can_id: classify_id(can_id) for can_id in range(0x800)}
    owned = {can_id: k for can_id, k in kinds.items() if k is not None}
    assert len(owned) == 4 * 32 + 2  # the ranges never overlap (ID <= 32)
    assert owned[0x280] == (ma.IdKind.BROADCAST, None)
    assert owned[0x300] == (ma.IdKind.ID_SETTING, None)
    assert owned[0x160] == (ma.IdKind.REQUEST, 32)
    assert owned[0x520] == (ma.IdKind.MOTION_REPLY, 32)


@given(motor_ids, st.binary(min_size=1, max_size=8))
def test_a_reply_carries_its_requests_key(motor_id: int, data: bytes) -> None:
    key = request_key(request_id(motor_id), data)
    assert key == (0x240 + motor_id, data[0])
    assert reply_key(Frame(arbitration_id=reply_id(motor_id), data=data)) == key
    # A different command byte, or another motor, is a different key.
    other = bytes([data[0] ^ 0xFF]) + data[1:]
    assert reply_key(Frame(arbitration_id=reply_id(motor_id), data=other)) != key
    other_motor = motor_id % 32 + 1
    assert reply_key(Frame(arbitration_id=reply_id(other_motor), data=data)) != key


@given(motor_ids, can_payloads)
def test_motion_replies_are_keyed_by_identifier(motor_id: int, data: bytes) -> None:
    key = request_key(motion_request_id(motor_id), data)
    assert key == 0x500 + motor_id
    assert reply_key(Frame(arbitration_id=motion_reply_id(motor_id), data=data)) == key


def test_id_setting_reply_is_never_our_own_frame() -> None:
    data = bytes.fromhex("79 00 01 00 00 00 42 02")
    assert request_key(0x300, bytes.fromhex("79 00 01 00 00 00 00 00")) == (0x300, 0x79)
    assert reply_key(Frame(arbitration_id=0x300, data=data)) == (0x300, 0x79)
    assert reply_key(Frame(arbitration_id=0x300, data=data, is_rx=False)) is None
    assert reply_key(Frame(arbitration_id=0x300, data=bytes.fromhex("80 00"))) is None


def test_broadcast_collects_one_key_per_motor() -> None:
    assert request_key(0x280, b"\x80" + bytes(7)) is None
    assert broadcast_reply_keys(b"\x60" + bytes(7), [1, 2, 3, 4]) == {
        m: (0x240 + m, 0x60) for m in (1, 2, 3, 4)
    }
    with pytest.raises(ValueError, match="needs DATA"):
        broadcast_reply_keys(b"", [1])


def expected_reply_key(can_id: int, data: bytes) -> object:
    """The module docstring's "Matching" table, written out: which received frames are replies."""
    if 0x241 <= can_id <= 0x260 and data:
        return (can_id, data[0])
    if 0x501 <= can_id <= 0x520:
        return can_id
    if can_id == 0x300 and data[:1] == b"\x79":
        return (0x300, 0x79)
    return None


# Reply identifiers are 65 of the 2048: drawn on purpose (0x300 on its own, where DATA[0] decides), or
# almost every example would be a non-reply.
reply_ids = st.sampled_from([*range(0x241, 0x261), *range(0x501, 0x521)])
id_setting_payloads = st.binary(max_size=7).map(lambda rest: b"\x79" + rest)


@given(st.one_of(standard_ids, reply_ids, st.just(0x300)), st.one_of(can_payloads, id_setting_payloads))
def test_reply_key_is_exactly_the_matching_table(can_id: int, data: bytes) -> None:
    """Replies get their key, every other frame None; both kinds are drawn in every run."""
    assert reply_key(Frame(arbitration_id=can_id, data=data)) == expected_reply_key(can_id, data)


def test_reply_key_ignores_extended_and_fd_frames() -> None:
    assert reply_key(Frame(arbitration_id=0x241, data=b"\x9c", is_extended_id=True)) is None
    assert reply_key(Frame(arbitration_id=0x241, data=b"\x9c" + bytes(7), is_fd=True)) is None
    assert reply_key(Frame(arbitration_id=0x241, data=b"")) is None


def test_rs485_keys() -> None:
    assert rs485_request_key(3, b"\x9c") == (3, 0x9C) == rs485_reply_key(3, b"\x9c")
    # 0xCD: each motor answers with its own id; 0x79 answers keep 0xCD (§4.38).
    assert rs485_request_key(0xCD, b"\x80") is None
    assert rs485_request_key(0xCD, b"\x79") == (0xCD, 0x79) == rs485_reply_key(0xCD, b"\x79")
    assert rs485_reply_key(0xCD, b"\x80") is None
    assert rs485_reply_key(33, b"\x80") is None
    assert rs485_request_key(1, b"") is None
