"""Each MyActuator command's declared facts agree with what the codec, the bound codec and the simulator do.

A command class states its reply type, READ, SLOW, ECHO, STREAMABLE, NO_REPLY and NOTED once; every
table is derived from them. These tests hold each declaration against the behaviour, per class and
revision, for any valid instance: a declaration that says one thing while a codec or the simulated
motor does another fails here.
"""

from __future__ import annotations

import copy
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servobus.frame import Frame
from servobus.protocols import Command
from servobus.protocols import myactuator as ma
from servobus.protocols._bound import KIND_REPLY, KIND_STREAM
from servobus.protocols.myactuator import codec
from servobus.protocols.myactuator.bound import DEFAULT_TIMEOUT_S, SLOW_TIMEOUT_S, MyActuatorCodec
from servobus.protocols.myactuator.codec import request_frame
from servobus.protocols.myactuator.sim.device import MyActuatorMotor

from ._strategies import _motion_command, message_strategy

MOTOR_ID = 3
#: The RS485 motion frame (FE EE) goes on no bound link and is not simulated (myactuator-v4.md §6).
UNBOUND = (ma.Rs485MotionCommand,)
CASES = [
    pytest.param(cls, revision, id=f"{cls.__name__}-{revision.name}")
    for cls in codec.COMMANDS
    for revision in ma.Revision
    if revision in cls.REVISIONS  # type: ignore[attr-defined]
]
BOUND_CASES = [case for case in CASES if case.values[0] not in UNBOUND]
FEW = settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def instances(cls: type[Command], revision: ma.Revision) -> st.SearchStrategy[Any]:
    """Valid instances of ``cls`` that ``revision`` has (motion commands with the revision's scales)."""
    if cls is ma.MotionCommand:
        return _motion_command(ma.MOTION_SCALES[revision])
    return message_strategy(cls).filter(lambda c: c.unavailable_reason(revision) is None)


def bound(revision: ma.Revision) -> MyActuatorCodec:
    return ma.FAMILY.bind(MOTOR_ID, revision=revision)  # type: ignore[return-value]


def state(motor: MyActuatorMotor) -> tuple[Any, ...]:
    """What a command can change on the simulated motor (copied)."""
    return copy.deepcopy(
        (motor.rom, motor.ram, motor.control, motor.run_mode, motor.brake_released, motor.streams)
    )


def test_the_family_offers_every_declared_command() -> None:
    assert set(ma.FAMILY.commands) == set(codec.COMMANDS)
    assert {c for c in codec.COMMANDS if issubclass(c, ma.MyActuatorCommand)} == {
        layout.message for layouts in codec.REQUESTS.values() for layout in layouts
    }


def test_the_tables_are_the_declarations() -> None:
    standard = [c for c in codec.COMMANDS if issubclass(c, ma.MyActuatorCommand)]
    assert {c.CODE: c.NO_REPLY for c in standard if c.NO_REPLY} == dict(codec.NO_REPLY)
    assert set(codec.ECHO_COMMANDS) == {c for c in standard if c.REPLY is ma.Echo}
    assert {int(m) for m in ma.StreamableCommand} == {c.CODE for c in standard if c.STREAMABLE}
    assert {int(m) for m in ma.StatusCommand} == {c.CODE for c in standard if c.REPLY is ma.StatusReply}
    for cls in standard:
        assert cls.CODE is not None
        for reply in cls.reply_types():
            candidates = [layout.message for layout in codec.REPLIES[cls.CODE]]
            assert (cls if reply is ma.Echo else reply) in candidates, (cls, reply)


@pytest.mark.parametrize(("cls", "revision"), CASES)
def test_the_declarations_agree_with_each_other(cls: type[Command], revision: ma.Revision) -> None:
    assert (cls.NO_REPLY is None) is (cls.REPLY is not None), "a reply type, or why none comes"
    assert not cls.STREAMABLE or (cls.READ and cls.NO_REPLY is None)
    assert not (cls.ECHO and cls.REPLY is not ma.Echo), "a value echo is answered by an Echo"
    assert not (cls.READ and cls.SLOW), "a read writes nothing that takes long"


@pytest.mark.parametrize(("cls", "revision"), BOUND_CASES)
@FEW
@given(data=st.data())
def test_the_bound_codec_follows_the_declaration(
    cls: type[Command], revision: ma.Revision, data: Any
) -> None:
    codec_ = bound(revision)
    command = data.draw(instances(cls, revision))
    assert codec_.retry_safe(command) is cls.READ
    assert codec_.timeout_s(command) == (SLOW_TIMEOUT_S if cls.SLOW else DEFAULT_TIMEOUT_S["can"])
    key = codec_.reply_key(command)
    assert (key is None) is (cls.NO_REPLY is not None)
    other = data.draw(instances(cls, revision))
    if key is not None and other.encode() != command.encode():
        # A value echo is keyed by the bytes it wrote; any other reply by the command alone.
        assert (codec_.reply_key(other) != key) is cls.ECHO


@pytest.mark.parametrize(("cls", "revision"), BOUND_CASES)
@FEW
@given(data=st.data())
def test_the_simulator_answers_with_a_declared_reply(
    cls: type[Command], revision: ma.Revision, data: Any
) -> None:
    command = data.draw(instances(cls, revision))
    motor = MyActuatorMotor(MOTOR_ID, revision=revision)
    codec_ = bound(revision)
    before = state(motor)
    emissions = motor.receive(request_frame(command, MOTOR_ID, revision=revision), 0.0)
    if cls.READ:  # what makes a retry safe, and leaving the Bus without a stop
        assert state(motor) == before, "a declared read changed the motor"
    if cls.NO_REPLY is not None:
        assert emissions == []
        return
    (emission,) = emissions
    frame = emission.frame
    kind, key = codec_.classify(frame)
    assert (kind, key) == (KIND_REPLY, codec_.reply_key(command))
    reply = codec_.decode(frame)
    assert isinstance(reply, cls.reply_types()), reply
    if isinstance(reply, ma.Echo):
        assert reply.command.encode() == command.encode()  # the same bytes (float32 fields round)


@pytest.mark.parametrize("streamed", [c for c in codec.COMMANDS if c.STREAMABLE], ids=lambda c: c.__name__)
def test_a_stream_carries_the_declared_reply(streamed: type[Command]) -> None:
    assert streamed.CODE is not None
    motor = MyActuatorMotor(MOTOR_ID)
    codec_ = bound(ma.Revision.V4_4)
    enable = ma.ActiveReply(command=ma.StreamableCommand(streamed.CODE), enabled=True, interval_ms=10)
    assert motor.receive(request_frame(enable, MOTOR_ID), 0.0) == []
    codec_.note_sent(enable)
    emissions = motor.poll(0.0105)
    assert len(emissions) == 1
    frame: Frame = emissions[0].frame
    assert codec_.classify(frame)[0] is KIND_STREAM
    assert isinstance(codec_.decode(frame), streamed.reply_types())


def test_the_rs485_motion_frame_is_refused_by_a_bound_codec() -> None:
    command = ma.Rs485MotionCommand(
        motor_id=1, position_rad=0.0, velocity_rad_s=0.0, kp=0.0, kd=0.0, torque_ff_nm=0.0
    )
    with pytest.raises(ValueError, match="FE EE"):
        bound(ma.Revision.V4_4).encode(command)
    with pytest.raises(ValueError, match="FE EE"):
        bound(ma.Revision.V4_4).reply_key(command)
