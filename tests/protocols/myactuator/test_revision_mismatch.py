"""A reply in the other revision's layout, decoded by a bound codec, names the mismatch (issue 24 item 4).

A V4.3 motor bound with the default revision (V4.4) answers ``read_single_turn_angle()`` with
``94 00 00 00 00 00 24 23``: V4.3's uint16 0..359.99° in DATA[6..7] (89.96°), which V4.4's int32 in
DATA[4..7] reads as 5,895,618.56°, outside its ±180°. The codec's ProtocolError says which revision it
decoded as and which one the bytes look like, with the motor and the command, so the Bus can fail the
request with it instead of a timeout.
"""

from __future__ import annotations

import dataclasses

import pytest

from servobus import Frame
from servobus.errors import ProtocolError
from servobus.protocols import get_family
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.sim.device import MyActuatorMotor

V43_FRAME = bytes.fromhex("94 00 00 00 00 00 24 23")
MOTOR_ID = 5
REPLY_ID = 0x240 + MOTOR_ID


def _reply(data: bytes) -> Frame:
    return Frame(arbitration_id=REPLY_ID, data=data, is_rx=True)


def test_v43_single_turn_reply_decoded_by_a_v44_bound_codec_names_both_revisions() -> None:
    codec = get_family("myactuator").bind(MOTOR_ID)
    assert codec.revision is ma.Revision.V4_4  # the default
    frame = _reply(V43_FRAME)
    assert codec.classify(frame)[1] == codec.reply_key(ma.ReadSingleTurnAngle())  # it would answer it
    with pytest.raises(ProtocolError) as caught:
        codec.decode(frame)
    error = caught.value
    assert type(error) is ProtocolError
    assert error.message == (
        "SingleTurnAngleReply: angle_deg=5895618.56 is outside [-180, 180]; "
        "looks like a V4.3 frame (revision mismatch: decoded as V4.4)"
    )
    assert (error.motor_id, error.command, error.raw) == (MOTOR_ID, 0x94, V43_FRAME)
    assert str(error).endswith(f"(motor {MOTOR_ID}, command 0x94, raw 94 00 00 00 00 00 24 23)")
    # Bound with the revision the bytes look like, they are a reply.
    v43 = get_family("myactuator").bind(MOTOR_ID, revision="V4_3")
    assert v43.decode(frame) == ma.CircleAngleReply(angle_deg=89.96)


def test_the_same_mismatch_on_the_rs485_link_names_the_motor() -> None:
    codec = get_family("myactuator").bind(MOTOR_ID, link="rs485")
    frame = Frame(arbitration_id=MOTOR_ID, data=V43_FRAME, is_serial=True, is_rx=True)
    with pytest.raises(ProtocolError, match=r"V4\.3 frame \(revision mismatch: decoded as V4\.4\)") as caught:
        codec.decode(frame)
    assert (caught.value.motor_id, caught.value.command) == (MOTOR_ID, 0x94)


def test_a_v44_frame_decoded_by_a_v43_bound_codec_names_both_revisions() -> None:
    # V4.4's int32 -90.00° (-9000 = FF FF DC D8) puts FF FF in DATA[6..7]: V4.3 reads 655.35°.
    data = bytes.fromhex("94 00 00 00 D8 DC FF FF")
    codec = get_family("myactuator").bind(MOTOR_ID, revision="V4_3")
    with pytest.raises(ProtocolError) as caught:
        codec.decode(_reply(data))
    assert caught.value.message.endswith("; looks like a V4.4 frame (revision mismatch: decoded as V4.3)")
    assert (caught.value.motor_id, caught.value.command) == (MOTOR_ID, 0x94)
    assert get_family("myactuator").bind(MOTOR_ID).decode(_reply(data)) == ma.SingleTurnAngleReply(
        angle_deg=-90.0
    )


def test_a_simulated_v43_motor_read_through_a_v44_bound_codec() -> None:
    # The whole exchange at the codec level: the V4.4 codec's request, the V4.3 device's reply.
    codec = get_family("myactuator").bind(MOTOR_ID)
    motor = MyActuatorMotor(MOTOR_ID, revision=ma.Revision.V4_3)
    motor.plant.position_deg = 89.96
    (emission,) = motor.receive(codec.encode(ma.ReadSingleTurnAngle()), 0.0)
    assert emission.frame.data == V43_FRAME  # the frame
    with pytest.raises(ProtocolError, match=r"V4\.3 frame \(revision mismatch: decoded as V4\.4\)"):
        codec.decode(dataclasses.replace(emission.frame, is_rx=True))


def test_an_out_of_range_value_no_revision_reads_is_not_called_a_mismatch() -> None:
    # 0x94 with a non-zero NULL byte: no revision reads it whole, so no revision is named.
    data = bytes.fromhex("94 00 00 00 FF FF FF 7F")
    with pytest.raises(ProtocolError) as caught:
        get_family("myactuator").bind(MOTOR_ID).decode(_reply(data))
    assert "revision mismatch" not in caught.value.message and "looks like" not in caught.value.message
