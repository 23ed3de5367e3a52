"""The LK bound codec's fast decoders (status 2, and those derived from the declared reply layouts)
give what the full decoder gives, reply or ProtocolError, for every reply byte of each revision."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import get_family, lk
from servobus.protocols.lk._base import LkMessage
from servobus.protocols.lk.bound import _fast_encoders
from servobus.protocols.lk.codec import REPLY_CLASSES
from servobus.protocols.lk.ids import reply_id

from ._strategies import COMMANDS

MODELS = [
    lk.LkModel(),
    lk.LkModel(revision=lk.Revision.V2_35),
    lk.LkModel(motor_type=lk.MotorType.MS, encoder_bits=16),
    lk.LkModel(revision=lk.Revision.V2_35, motor_type=lk.MotorType.MH, encoder_bits=18),
]
# Rest bytes: random, or mostly NULL (the values a motor sends), so both outcomes are exercised.
REST = st.one_of(
    st.binary(min_size=7, max_size=7), st.binary(min_size=0, max_size=3).map(lambda b: b.ljust(7, b"\0"))
)


def _outcome(decode: Any, frame: Frame) -> object:
    try:
        return decode(frame)
    except ProtocolError as exc:
        return ("ProtocolError", str(exc))


def test_every_fixed_layout_reply_has_a_fast_decoder() -> None:
    codec = get_family("lk").bind(2)
    derived = {code for code, cls in REPLY_CLASSES[lk.Revision.V2_36].items() if code in codec._fast}
    assert {0x9A, 0x9C, 0x90, 0x92, 0x94} <= derived  # status 1/2, encoder, multi- and single-turn


@pytest.mark.parametrize("model", MODELS, ids=repr)
@given(data=st.data(), rest=REST)
def test_fast_decode_agrees_with_the_full_decoder(
    model: lk.LkModel, data: st.DataObject, rest: bytes
) -> None:
    code = data.draw(st.sampled_from(sorted(REPLY_CLASSES[model.revision])))
    codec = get_family("lk").bind(2, model=model)
    frame = Frame(arbitration_id=reply_id(2, model.revision), data=bytes([code]) + rest, is_rx=True)
    expected = _outcome(lambda f: lk.decode_reply(f.arbitration_id, f.data, model=model), frame)
    got = _outcome(codec.decode, frame)
    assert got == expected
    assert type(got) is type(expected)


@pytest.mark.parametrize("cls", sorted(COMMANDS, key=lambda c: c.__name__), ids=lambda c: c.__name__)
@given(data=st.data())
def test_fast_encode_is_the_declared_encode(cls: type[lk.LkCommand], data: st.DataObject) -> None:
    command = data.draw(COMMANDS[cls].strategy)
    model = lk.LkModel(
        revision=min(cls.REVISIONS, key=lambda r: r.name),
        motor_type=getattr(command, "motor_type", lk.MotorType.MG),
        encoder_bits=getattr(command, "encoder_bits", 14),
    )
    fast = _fast_encoders(model).get(cls)
    if fast is None:
        assert cls.CODE is None or cls.CONSTANTS or cls.encode is not LkMessage.encode or cls.MODEL_FIELDS
        return
    assert fast(command) == command.encode()
