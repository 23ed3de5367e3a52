"""The bound codecs' fast paths against the families' full decoders (protocols/_fast.py's rule).

A fast decoder may only ever return what the full decoder returns, and must leave every error to it:
so for random payloads of every hot DATA[0] (and random motion/MIT payloads), ``bound.decode`` and the
family's ``decode_reply`` either return equal replies or both raise ProtocolError. Random bytes hit the
range checks the manuals state (helper ranges, enum codes, encoder widths) far more often than the
simulator's frames do.
"""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus import Frame
from servobus.errors import ProtocolError
from servobus.protocols import get_family, lk
from servobus.protocols import hollow as ho
from servobus.protocols import myactuator as ma
from servobus.protocols.lk.ids import reply_id
from servobus.protocols.myactuator.bound import _FAST


def _outcome(decode: Any, frame: Frame) -> Any:
    """The decoded reply's repr (so 1, 1.0, True and an enum member all differ), or ProtocolError."""
    try:
        return repr(decode(frame))
    except ProtocolError:
        return ProtocolError


# Every DATA[0] with a fast decoder in either revision (and a few without, for contrast).
MA_HOT = sorted({*_FAST[ma.Revision.V4_3], *_FAST[ma.Revision.V4_4], 0x30, 0xB5})


@pytest.mark.parametrize("revision", list(ma.Revision), ids=lambda r: r.name)
@given(code=st.sampled_from(MA_HOT), rest=st.binary(min_size=0, max_size=8))
def test_myactuator_fast_decode_agrees_with_the_codec(revision: ma.Revision, code: int, rest: bytes) -> None:
    codec = get_family("myactuator").bind(2, revision=revision)
    frame = Frame(arbitration_id=0x242, data=(bytes([code]) + rest)[:8])
    expected = _outcome(lambda f: ma.decode_reply(f.arbitration_id, f.data, revision=revision), frame)
    assert _outcome(codec.decode, frame) == expected


@pytest.mark.parametrize("revision", list(ma.Revision), ids=lambda r: r.name)
@given(data=st.binary(min_size=0, max_size=8))
def test_myactuator_motion_fast_decode_agrees_with_the_codec(revision: ma.Revision, data: bytes) -> None:
    codec = get_family("myactuator").bind(2, revision=revision)
    frame = Frame(arbitration_id=0x502, data=data)
    expected = _outcome(lambda f: ma.decode_reply(f.arbitration_id, f.data, revision=revision), frame)
    assert _outcome(codec.decode, frame) == expected


@given(data=st.lists(st.binary(min_size=7, max_size=7).map(lambda d: b"\x02" + d), min_size=1, max_size=40))
def test_myactuator_motion_batch_decode_is_the_per_frame_decode(data: list[bytes]) -> None:
    codec = get_family("myactuator").bind(2)
    frames = [Frame(arbitration_id=0x502, data=d) for d in data]
    assert codec.decode_many(frames) == [codec.decode(f) for f in frames]


LK_MODELS = [
    lk.LkModel(),
    lk.LkModel(revision=lk.Revision.V2_35),
    lk.LkModel(motor_type=lk.MotorType.MS),
    lk.LkModel(motor_type=lk.MotorType.MF, encoder_bits=16),
    lk.LkModel(revision=lk.Revision.V2_35, motor_type=lk.MotorType.MH, encoder_bits=18),
]


@pytest.mark.parametrize("model", LK_MODELS, ids=repr)
@given(code=st.sampled_from([0x9C, *range(0xA0, 0xA9)]), rest=st.binary(min_size=0, max_size=8))
def test_lk_fast_decode_agrees_with_the_codec(model: lk.LkModel, code: int, rest: bytes) -> None:
    codec = get_family("lk").bind(2, model=model)
    ident = reply_id(2, model.revision)
    frame = Frame(arbitration_id=ident, data=(bytes([code]) + rest)[:8])
    expected = _outcome(lambda f: lk.decode_reply(f.arbitration_id, f.data, model=model), frame)
    assert _outcome(codec.decode, frame) == expected


HOLLOW_MODELS = [ho.DEFAULT_MODEL, *ho.MODELS.values()]
CLASSIC = st.one_of(st.binary(min_size=6, max_size=6), st.binary(min_size=8, max_size=8))


@pytest.mark.parametrize("model", HOLLOW_MODELS, ids=lambda m: m.name)
@given(data=CLASSIC, motor=st.integers(0, 120))
def test_hollow_classic_fast_decode_agrees_with_the_codec(model: Any, data: bytes, motor: int) -> None:
    codec = get_family("hollow").bind(5, model=model)
    frame = Frame(arbitration_id=100, data=bytes([motor]) + data[1:])
    expected = _outcome(lambda f: ho.decode_reply(f.arbitration_id, f.data, model=model), frame)
    assert _outcome(codec.decode, frame) == expected


@given(data=st.binary(min_size=16, max_size=16), slave=st.integers(0, 120), run=st.integers(0, 2))
def test_hollow_fd_fast_decode_agrees_with_the_codec(data: bytes, slave: int, run: int) -> None:
    codec = get_family("hollow").bind(5, link="canfd")
    payload = data[:12] + bytes([run]) + data[13:15] + bytes([slave])
    frame = Frame(arbitration_id=100, data=payload, is_fd=True)
    expected = _outcome(lambda f: ho.decode_reply(f.arbitration_id, f.data, is_fd=True), frame)
    assert _outcome(codec.decode, frame) == expected
