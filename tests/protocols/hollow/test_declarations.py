"""Each hollow command's declaration agrees with what the codec, the bound codec and the simulator do.

For every command class of the family (the Motor's commands and the frames sent outside a link):

* the bound codec on each declared link: ``retry_safe`` is ``READ``, the timeout is the slow one iff
  ``SLOW``, ``reply_key`` is None iff ``NO_REPLY``; a link not declared refuses the command;
* the simulated motor (classic CAN, CAN FD, or CAN FD behind the RS-485 converter) takes the frame the
  codec sends as this very class and answers with a frame the codec decodes to one of the declared
  reply types (of the message on the wire: on Modbus an FdCommand goes out as a ModbusWrite);
* whole serial frames (transparent and Modbus requests) get an answer of their declared reply type
  from the converter too.

The instances are built from the declarations (each field at both ends of its declared range), so a
new command class is tested without an entry here.
"""

from __future__ import annotations

import dataclasses
import enum
import typing
from typing import Any

import pytest

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols import hollow as ho
from servobus.protocols._family import command_classes
from servobus.protocols._message import Command
from servobus.protocols.hollow import bound
from servobus.protocols.hollow._packed import OnLinks, Packed
from servobus.protocols.hollow.codec import decode_request_frame
from servobus.protocols.hollow.commands import request_classes
from servobus.protocols.hollow.sim.converter import ConverterMode, HollowConverter
from servobus.protocols.hollow.sim.device import HollowMotor, implemented

MOTOR_ID = 1
ALL_COMMANDS = command_classes(vars(ho).values())
SENT_ON_LINKS = [(cls, link) for cls in ALL_COMMANDS for link in cls.LINKS]  # type: ignore[attr-defined]
# The converter's mode behind each serial link of the bound codec.
CONVERTER_MODES = {"rs485": ConverterMode.TRANSPARENT, "modbus": ConverterMode.MODBUS}


def _field_value(spec: Any, end: int) -> Any:
    """A value of ``spec`` near its low (end 0) or high (end 1) limit, for the default model."""
    scale = spec.scale_for(ho.DEFAULT_MODEL)
    if spec.kind is float:
        return (scale.lo, scale.hi)[end] * 0.5
    if spec.kind is int:
        return (int(scale.lo), int(scale.hi))[end]
    if spec.kind is bool:
        return bool(end)
    return list(spec.kind)[-end]


def examples(cls: type[Command[Any]]) -> list[Command[Any]]:
    """Valid instances of ``cls`` built from its declaration: packed fields at both ends of their
    declared limits, enums at their first and last member, ids 1 and 100, multipliers 0 and 2."""
    hints = typing.get_type_hints(cls)
    out = []
    for end in (0, 1):
        values: dict[str, Any] = {}
        if issubclass(cls, Packed):
            values = {spec.name: _field_value(spec, end) for spec in cls.FIELDS}
        for field in dataclasses.fields(cls):
            kind = hints[field.name]
            if field.name in values or field.name == "model" or field.name == "header":
                continue
            if isinstance(kind, type) and issubclass(kind, enum.IntEnum):
                values[field.name] = list(kind)[-end]
            elif kind is int:
                values[field.name] = (MOTOR_ID, 100)[end] if field.name.endswith("_id") else (0, 255)[end]
            elif kind is float:
                values[field.name] = (0.0, 2.0)[end]
            elif dataclasses.is_dataclass(kind) and isinstance(kind, type):
                values[field.name] = examples(kind)[end]  # type: ignore[arg-type]
        out.append(cls(**values))
    return out


def _at_motor(command: Command[Any]) -> Command[Any]:
    """``command`` addressed to MOTOR_ID (a serial frame names its motor or slave)."""
    address = {name: MOTOR_ID for name in ("slave_id", "motor_id") if hasattr(command, name)}
    return dataclasses.replace(command, **address) if address else command  # type: ignore[type-var]


def test_every_command_of_the_family_is_declared_and_simulated() -> None:
    # The Motor's commands are the ones a link carries; the others are whole frames sent directly.
    assert set(ho.FAMILY.commands) == {cls for cls in ALL_COMMANDS if cls.LINKS}  # type: ignore[attr-defined]
    assert all(issubclass(cls, OnLinks) for cls in ALL_COMMANDS)
    # Every CAN request has a behaviour in the simulated motor (its dispatch is registered per class).
    assert set(request_classes()) <= implemented()
    assert set(request_classes()) == {cls for cls in ALL_COMMANDS if issubclass(cls, ho.HollowCommand)}
    for cls in ALL_COMMANDS:
        assert (cls.NO_REPLY is None) == bool(cls.reply_types()), cls


@pytest.mark.parametrize(("cls", "link"), SENT_ON_LINKS, ids=lambda v: getattr(v, "__name__", v))
def test_the_bound_codec_follows_the_declaration(cls: type[Command[Any]], link: str) -> None:
    codec = ho.FAMILY.bind(MOTOR_ID, link=link)
    for command in map(_at_motor, examples(cls)):
        assert codec.retry_safe(command) is cls.READ
        assert (codec.timeout_s(command) > bound.DEFAULT_TIMEOUT_S[link]) is cls.SLOW
        assert (codec.reply_key(command) is None) is (cls.NO_REPLY is not None)


@pytest.mark.parametrize("cls", ALL_COMMANDS, ids=lambda c: c.__name__)
def test_a_link_not_declared_refuses_the_command(cls: type[Command[Any]]) -> None:
    command = _at_motor(examples(cls)[0])
    for link in set(bound.LINKS) - set(cls.LINKS):  # type: ignore[attr-defined]
        codec = ho.FAMILY.bind(MOTOR_ID, link=link)
        with pytest.raises(ValueError, match=f"not on link='{link}'"):
            codec.encode(command)


def _exchange(codec: Any, frame: Frame, link: str, cls: type[Command[Any]]) -> list[Frame]:
    """What comes back for ``frame`` from a simulated motor on ``link``, as the codec receives it."""
    if link in CONVERTER_MODES:
        motor = HollowMotor(MOTOR_ID, fd_enabled=True)
        converter = HollowConverter([motor], mode=CONVERTER_MODES[link])
        emissions = converter.receive_bytes(codec.framing.encode(frame), 0.0)
        deframer = codec.framing.deframer()
        return [f for e in emissions for f in deframer.feed(e.data)]
    motor = HollowMotor(MOTOR_ID, fd_enabled=link == "canfd")
    motor.can_mode = getattr(cls, "CAN_MODE", ho.CanMode.NORMAL)  # the mode its bytes are read in
    # The motor decodes the frame as this class (the classes' claims tell the frames apart).
    assert type(decode_request_frame(frame, can_mode=motor.can_mode)) is cls
    return [dataclasses.replace(e.frame, is_rx=True) for e in motor.receive(frame, 0.0)]


@pytest.mark.parametrize(("cls", "link"), SENT_ON_LINKS, ids=lambda v: getattr(v, "__name__", v))
def test_the_simulated_motor_answers_with_a_declared_reply(cls: type[Command[Any]], link: str) -> None:
    codec = ho.FAMILY.bind(MOTOR_ID, link=link)
    for command in map(_at_motor, examples(cls)):
        frames = _exchange(codec, codec.encode(command), link, cls)
        expected = type(codec.wire(command)).reply_types()  # type: ignore[attr-defined]
        if cls.NO_REPLY is not None:
            assert frames == []
            continue
        assert len(frames) == 1, command
        assert codec.classify(frames[0])[1] == codec.reply_key(command)
        reply = codec.decode(frames[0])
        assert isinstance(reply, expected), (command, reply)


def _decode_as(types: tuple[type[Any], ...], data: bytes) -> Any:
    for reply_type in types:
        try:
            return reply_type.decode(data)
        except ProtocolError:
            continue
    raise AssertionError(f"{data.hex(' ')} decodes as none of {types}")


SERIAL_FRAMES = [
    (ho.TransparentRequest, ConverterMode.TRANSPARENT),
    (ho.ModbusWrite, ConverterMode.MODBUS),
    (ho.ModbusRead, ConverterMode.MODBUS),
]


@pytest.mark.parametrize(("cls", "mode"), SERIAL_FRAMES, ids=lambda v: getattr(v, "__name__", v))
def test_the_converter_answers_a_whole_serial_frame_with_a_declared_reply(
    cls: type[Command[Any]], mode: ConverterMode
) -> None:
    for command in map(_at_motor, examples(cls)):
        converter = HollowConverter([HollowMotor(MOTOR_ID, fd_enabled=True)], mode=mode)
        (emission,) = converter.receive_bytes(command.encode(), 0.0)
        assert isinstance(_decode_as(cls.reply_types(), emission.data), cls.reply_types())


def test_the_serial_frames_tested_are_all_that_travel_on_no_link() -> None:
    unlinked = {cls for cls in ALL_COMMANDS if not cls.LINKS}  # type: ignore[attr-defined]
    assert unlinked - {cls for cls, _ in SERIAL_FRAMES} == {
        cls for cls in unlinked if cls.NO_REPLY is not None
    }
