"""The 0xA0 (open loop) reply: DATA[2..3] is power, the raw int16, on every motor type (issue 24 item 4).

Spec §4.9: "DATA[2..3] = output power" in the reply of both revisions ([003]'s table mislabels the bytes
"Torque current", A20); A24: the manuals give that power three ranges (-1000..1000, -850..850) and no
unit, so the raw int16 is kept. A V2.35 motor answered ``A0 EC C2 FB 29 FE 34 3A`` (power -1086), which
the decoder refused with its ±850 range check, so the request timed out.
"""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus import Frame
from servobus.protocols import get_family, lk
from servobus.protocols.lk import LkModel, MotorType, Revision
from servobus.protocols.lk.bound import LkCodec
from servobus.protocols.lk.ids import reply_id

FIELD_FRAME = bytes.fromhex("A0 EC C2 FB 29 FE 34 3A")
MOTOR_ID = 3


def _bound(model: LkModel) -> LkCodec:
    return get_family("lk").bind(MOTOR_ID, model=model)  # type: ignore[return-value]


def _frame(data: bytes, revision: Revision) -> Frame:
    return Frame(arbitration_id=reply_id(MOTOR_ID, revision), data=data)


@pytest.mark.parametrize("motor_type", list(MotorType), ids=lambda t: t.name)
def test_v235_open_loop_reply_beyond_850_decodes_as_raw_power(motor_type: MotorType) -> None:
    model = LkModel(revision=Revision.V2_35, motor_type=motor_type)
    expected = lk.Status2Reply(
        command=0xA0,
        motor_type=motor_type,
        encoder_bits=14,
        temperature_c=-20,  # 0xEC
        speed_dps=-471.0,  # 0xFE29
        encoder_counts=14900,  # 0x3A34
        power_counts=-1086,  # 0xFBC2: beyond [003]'s stated -850..850
    )
    by_class = lk.Status2Reply.decode(FIELD_FRAME, model=model)
    by_table = lk.decode_reply(reply_id(MOTOR_ID, Revision.V2_35), FIELD_FRAME, model=model)
    by_bound = _bound(model).decode(_frame(FIELD_FRAME, Revision.V2_35))
    assert by_class == by_table == by_bound == expected
    assert by_bound.current_a is None and by_bound.iq_counts is None  # never read as a current
    assert expected.encode() == FIELD_FRAME


def test_v236_ms_open_loop_reply_has_no_range_check_either() -> None:
    # [001]: 0xA0 is MS only, its reply is status 2 with MS power ("-1000~1000" in 0x9C's text). The
    # same bytes were refused there by the ±1000 check; spec A24 keeps the raw int16 on both revisions.
    model = LkModel(revision=Revision.V2_36, motor_type=MotorType.MS)
    for code in (0xA0, 0x9C):
        data = bytes([code]) + FIELD_FRAME[1:]
        reply = _bound(model).decode(_frame(data, Revision.V2_36))
        assert isinstance(reply, lk.Status2Reply) and reply.power_counts == -1086
        assert reply == lk.decode_reply(reply_id(MOTOR_ID, Revision.V2_36), data, model=model)
    assert lk.replies.torque_range(Revision.V2_36, MotorType.MS, 0x9C) is None


@pytest.mark.parametrize("revision", list(Revision), ids=lambda r: r.name)
@pytest.mark.parametrize("motor_type", list(MotorType), ids=lambda t: t.name)
@given(
    power=st.integers(-0x8000, 0x7FFF),
    temperature=st.integers(-128, 127),
    speed=st.integers(-0x8000, 0x7FFF),
    encoder=st.integers(0, 16383),
)
def test_open_loop_reply_round_trips_the_full_int16_power(
    revision: Revision, motor_type: MotorType, power: int, temperature: int, speed: int, encoder: int
) -> None:
    model = LkModel(revision=revision, motor_type=motor_type)
    data = struct.pack("<BbhhH", 0xA0, temperature, power, speed, encoder)
    reply = _bound(model).decode(_frame(data, revision))  # the fast path where it applies
    assert isinstance(reply, lk.Status2Reply)
    assert reply.power_counts == power and reply.current_a is None and reply.iq_counts is None
    assert reply == lk.Status2Reply.decode(data, model=model)  # the full decoder agrees
    assert reply.encode() == data
    built = lk.Status2Reply(
        command=0xA0,
        motor_type=motor_type,
        encoder_bits=14,
        temperature_c=temperature,
        speed_dps=speed,
        encoder_counts=encoder,
        power_counts=power,
    )
    assert built.encode() == data and built == reply


def test_open_loop_reply_refuses_a_current() -> None:
    with pytest.raises(ValueError, match=r"0xA0 reply \(DATA\[2\.\.3\] is power.*uses power_counts"):
        lk.Status2Reply(
            command=0xA0,
            motor_type=MotorType.MG,
            encoder_bits=14,
            temperature_c=0,
            speed_dps=0,
            encoder_counts=0,
            current_a=1.0,
        )


def test_other_v235_replies_keep_the_stated_iq_range() -> None:
    # Only the power field lost its range: [003]'s iq "Range:-2048~2048" still holds for 0xA1..0xA8.
    model = LkModel(revision=Revision.V2_35)
    assert lk.replies.torque_range(Revision.V2_35, MotorType.MG, 0xA1) == (-2048, 2048)
    assert lk.replies.torque_range(Revision.V2_35, MotorType.MG, 0xA0) is None
    reply = _bound(model).decode(_frame(bytes([0xA1]) + FIELD_FRAME[1:], Revision.V2_35))
    assert isinstance(reply, lk.Status2Reply) and reply.current_a == pytest.approx(-1086 * 66 / 4096)
