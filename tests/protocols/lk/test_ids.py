"""LK identifiers and match keys (ids.py), and the V2.35 echo rule."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.frame import Frame
from servobus.protocols import lk
from servobus.protocols.lk import Revision, ids
from servobus.protocols.lk.codec import reply_frame, request_frame

from .._contract import can_payloads, standard_ids

V236 = Revision.V2_36
V235 = Revision.V2_35
motor_ids = st.integers(min_value=1, max_value=32)


def test_identifier_arithmetic() -> None:
    assert ids.request_id(1) == 0x141
    assert ids.request_id(32) == 0x160
    assert ids.reply_id(1, V236) == 0x181
    assert ids.reply_id(32, V236) == 0x1A0
    assert ids.reply_id(1, V235) == 0x141
    assert ids.MULTI_MOTOR_ID == 0x280
    assert ids.motor_id_from_reply_id(0x1A0, V236) == 32
    assert ids.motor_id_from_reply_id(0x141, V236) is None
    assert ids.motor_id_from_reply_id(0x141, V235) == 1
    assert ids.motor_id_from_reply_id(0x181, V235) is None
    assert ids.motor_id_from_request_id(0x160) == 32
    assert ids.motor_id_from_request_id(0x140) is None
    assert ids.motor_id_from_request_id(0x161) is None


@pytest.mark.parametrize("bad", [0, 33, -1, True, 1.0])
def test_motor_ids_outside_1_to_32_are_refused(bad: object) -> None:
    with pytest.raises(ValueError, match="motor_id"):
        ids.request_id(bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="motor_id"):
        ids.reply_id(bad, V236)  # type: ignore[arg-type]


@given(motor_ids, st.sampled_from(list(Revision)))
def test_reply_ids_invert(motor_id: int, revision: Revision) -> None:
    assert ids.motor_id_from_reply_id(ids.reply_id(motor_id, revision), revision) == motor_id
    assert ids.motor_id_from_request_id(ids.request_id(motor_id)) == motor_id


def test_match_keys_follow_design_md() -> None:
    # design.md "Matching": (0x180+ID, DATA[0]) on V2.36, (0x140+ID, DATA[0]) on V2.35.
    assert ids.match_key(5, 0xA1, V236) == (0x185, 0xA1)
    assert ids.match_key(5, 0xA1, V235) == (0x145, 0xA1)
    assert ids.request_keys(5, 0x9C, V236) == ((0x185, 0x9C),)
    # Spec A4: [003]'s 0x9B reply table says 0x9A; V2.35 accepts either for a 0x9B request.
    assert ids.request_keys(5, 0x9B, V235) == ((0x145, 0x9B), (0x145, 0x9A))
    assert ids.request_keys(5, 0x9B, V236) == ((0x185, 0x9B),)
    assert ids.multi_motor_reply_keys(V235) == tuple((0x140 + i, 0xA1) for i in (1, 2, 3, 4))
    with pytest.raises(ValueError, match="not available in V2_36"):
        ids.multi_motor_reply_keys(V236)
    with pytest.raises(ValueError, match=r"motor_id=5 is not one of 1\.\.4"):
        ids.multi_motor_reply_keys(V235, range(1, 6))


@given(motor_ids, st.integers(min_value=0, max_value=255), st.binary(min_size=7, max_size=7))
def test_v235_our_own_request_is_never_a_reply_but_the_motors_echo_is(
    motor_id: int, command: int, rest: bytes
) -> None:
    # The V2.35 echo problem (ids.py docstring): identical id and bytes, told apart by direction only.
    data = bytes([command]) + rest
    ours = Frame(arbitration_id=ids.request_id(motor_id), data=data, is_rx=False)
    echo = Frame(arbitration_id=ids.reply_id(motor_id, V235), data=data, is_rx=True)
    assert ours == echo  # Frame equality ignores is_rx: bytes alone cannot tell them apart
    assert ids.reply_key(ours, revision=V235) is None
    assert ids.reply_key(echo, revision=V235) == (0x140 + motor_id, command)


@given(motor_ids, can_payloads, st.booleans())
def test_v236_nothing_on_the_request_id_is_a_reply(motor_id: int, data: bytes, is_rx: bool) -> None:
    frame = Frame(arbitration_id=ids.request_id(motor_id), data=data, is_rx=is_rx)
    assert ids.reply_key(frame, revision=V236) is None
    reply = Frame(arbitration_id=ids.reply_id(motor_id, V236), data=data, is_rx=is_rx)
    assert ids.reply_key(reply, revision=V236) == ((0x180 + motor_id, data[0]) if data and is_rx else None)


@given(standard_ids, can_payloads, st.sampled_from(list(Revision)))
def test_reply_key_only_for_received_frames_on_reply_ids(
    can_id: int, data: bytes, revision: Revision
) -> None:
    key = ids.reply_key(Frame(arbitration_id=can_id, data=data), revision=revision)
    if key is None:
        assert not data or not ids.is_reply_id(can_id, revision)
    else:
        assert key == (can_id, data[0])
        assert ids.motor_id_from_reply_id(can_id, revision) in range(1, 33)


def test_reply_key_ignores_extended_and_fd_frames() -> None:
    data = bytes.fromhex("9C 00 00 00 00 00 00 00")
    assert ids.reply_key(Frame(arbitration_id=0x181, data=data, is_extended_id=True), revision=V236) is None
    assert ids.reply_key(Frame(arbitration_id=0x181, data=data, is_fd=True), revision=V236) is None
    assert ids.reply_key(Frame(arbitration_id=0x181, data=b""), revision=V236) is None
    assert ids.reply_key(Frame(arbitration_id=0x181, data=data), revision=V236) == (0x181, 0x9C)


def test_request_frame_and_reply_frame_use_the_revision_ids() -> None:
    frame = request_frame(lk.MotorStop(), motor_id=3, revision=V235)
    assert frame == Frame(arbitration_id=0x143, data=bytes.fromhex("81 00 00 00 00 00 00 00"))
    echo = reply_frame(lk.EchoReply(command=0x81), motor_id=3, revision=V235)
    assert echo == frame  # same id, same bytes: only is_rx separates them on the bus
    assert reply_frame(lk.EchoReply(command=0x81), motor_id=3, revision=V236).arbitration_id == 0x183
    multi = lk.MultiMotorTorque(motor_type=lk.MotorType.MG, currents_a=(0.0, 0.0, 0.0, 0.0))
    assert request_frame(multi, motor_id=None, revision=V235).arbitration_id == 0x280
    with pytest.raises(ValueError, match=r"addresses motors 1\.\.4 by position"):
        request_frame(multi, motor_id=1, revision=V235)
    with pytest.raises(ValueError, match="motor_id is required"):
        request_frame(lk.MotorStop(), motor_id=None)
    with pytest.raises(ValueError, match="Status1ReplyV235 does not exist in V2_36"):
        reply_frame(
            lk.Status1ReplyV235(command=0x9A, temperature_c=0, voltage_v=0, error_state=lk.ErrorStateV235(0)),
            motor_id=1,
        )
