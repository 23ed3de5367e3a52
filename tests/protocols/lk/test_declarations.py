"""Each LK command class's declared facts agree with what the codec, the bound codec and the simulated
motor do: READ is what retries, SLOW is what waits longer, NO_REPLY is what has no reply key, the
reply type is what the codec decodes from the simulator's answer, in every revision the class has."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from servobus.protocols.lk import LkCommand, LkModel, MotorType, Revision
from servobus.protocols.lk.bound import DEFAULT_TIMEOUT_S, LkCodec, broadcast
from servobus.protocols.lk.codec import COMMAND_CLASSES, REPLY_CLASSES, REQUESTS, decode_reply, request_frame
from servobus.protocols.lk.sim import LkMotor

from ._strategies import COMMANDS

CASES = [(cls, revision) for cls in COMMAND_CLASSES for revision in Revision if revision in cls.REVISIONS]


def _model(command: LkCommand, revision: Revision) -> LkModel:
    """The model a motor that can run ``command`` has: the command's own motor type and encoder
    width where it carries them, else a motor type the manual allows it on."""
    allowed = type(command).MOTOR_TYPES.get(revision)
    default = MotorType.MG
    if allowed is not None and default not in allowed:
        default = min(allowed, key=lambda t: t.name)
    return LkModel(
        revision=revision,
        motor_type=getattr(command, "motor_type", default),
        encoder_bits=getattr(command, "encoder_bits", 14),
    )


def _ids(case: Any) -> str:
    cls, revision = case
    return f"{cls.__name__}-{revision.name}"


@pytest.mark.parametrize("case", CASES, ids=_ids)
@settings(max_examples=5, deadline=None)
@given(data=st.data())
def test_bound_codec_follows_the_declarations(case: tuple[type[LkCommand], Revision], data: Any) -> None:
    cls, revision = case
    command = data.draw(COMMANDS[cls].strategy)
    model = _model(command, revision)
    codec = LkCodec(1, model)
    assert codec.retry_safe(command) is cls.READ
    assert (codec.timeout_s(command) > DEFAULT_TIMEOUT_S) is cls.SLOW
    if cls.CODE is None:  # the 0x280 frame: a broadcast whose replies come from motors 1..4
        assert cls.NO_REPLY is None
        with pytest.raises(ValueError, match=r"use FAMILY\.broadcast"):
            codec.reply_key(command)
        assert broadcast(command, [LkCodec(m, model) for m in (1, 2)]).replies
        return
    assert (codec.reply_key(command) is None) is (cls.NO_REPLY is not None)


@pytest.mark.parametrize("case", CASES, ids=_ids)
@settings(max_examples=3, deadline=None)
@given(data=st.data())
def test_the_simulated_motor_answers_with_a_declared_reply(
    case: tuple[type[LkCommand], Revision], data: Any
) -> None:
    cls, revision = case
    command = data.draw(COMMANDS[cls].strategy)
    model = _model(command, revision)
    motor = LkMotor(1, model=model)
    frame = request_frame(command, motor_id=None if cls.CODE is None else 1, model=model)
    emissions = motor.receive(frame, 0.0)
    assert len(emissions) == 1, f"{cls.__name__}: {motor.counters}"
    sent = dataclasses.replace(emissions[0].frame, is_rx=True)
    reply = decode_reply(sent.arbitration_id, sent.data, model=model)
    assert isinstance(reply, cls.reply_types())
    if cls.CODE is not None:  # the reply carries the key the bound codec waits for
        codec = LkCodec(1, model)
        assert codec.classify(sent)[1] == codec.reply_key(command)


@pytest.mark.parametrize("case", CASES, ids=_ids)
def test_the_codec_tables_come_from_the_declarations(case: tuple[type[LkCommand], Revision]) -> None:
    cls, revision = case
    if cls.CODE is None:
        assert REPLY_CLASSES[revision][0xA1] in cls.reply_types()  # spec §5: 0xA1 status-2 replies
        return
    assert REQUESTS[revision][cls.CODE] is cls
    reply = REPLY_CLASSES[revision][cls.CODE]
    assert reply in cls.reply_types() and revision in reply.REVISIONS
    assert cls.CODE in reply.answers() or reply.CODE == cls.CODE
