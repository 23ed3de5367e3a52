"""MyActuator decoder tables keyed by DATA[0], revision availability, and the CAN entry points.

* :func:`decode_request` / :func:`decode_reply`: ``(can_id, data, *, revision)`` to the typed object; the
  identifier picks the table (0x140+ID and 0x280: standard requests; 0x300: 0x79; 0x400+ID: motion;
  0x240+ID: replies; 0x500+ID: motion replies).
* :func:`check_available` / :func:`encode_request`: refuse a command the revision does not have
  ("0x79 CAN-ID setting exists only in V4.3 (revision V4_4 given)") before any byte is sent.
* :func:`arbitration_id` / :func:`request_frame`: where a command goes on CAN.

Tables: :data:`REQUESTS` and :data:`REPLIES` map each command byte to its candidate layouts, each with the
revisions it exists in; decoding keeps the candidates of the revision asked for and takes the first that
decodes. So a command byte whose layout changed (0x94, 0xB5) decodes by revision, and one that does not
exist in the revision (0x72 on V4.3, 0x79 on V4.4) raises ProtocolError saying so.
:data:`NO_REPLY` lists the requests that get no reply, with the manual's reason.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import IntEnum
from types import ModuleType
from typing import Any, cast

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.protocols._family import command_classes
from servobus.protocols._message import Command, Reply
from servobus.protocols.myactuator import commands as cmd
from servobus.protocols.myactuator import commands_control as ctl
from servobus.protocols.myactuator import motion, rs485_motion
from servobus.protocols.myactuator import replies as rep
from servobus.protocols.myactuator._layout import LayoutMismatch, MyActuatorCommand, MyActuatorMessage
from servobus.protocols.myactuator.enums import STATUS_COMMAND_REVISIONS, StatusCommand, StreamableCommand
from servobus.protocols.myactuator.ids import (
    BROADCAST_ID,
    ID_SETTING_CODE,
    ID_SETTING_ID,
    IdKind,
    classify_id,
    motion_request_id,
    request_id,
)
from servobus.protocols.myactuator.motion import MOTION_SCALES, MotionCommand, MotionReply, MotionScales
from servobus.protocols.myactuator.revision import Revision, revision_names

__all__ = [
    "COMMANDS",
    "ECHO_COMMANDS",
    "NO_REPLY",
    "REPLIES",
    "REQUESTS",
    "STATUS_COMMAND_REVISIONS",
    "Candidate",
    "arbitration_id",
    "check_available",
    "decode_reply",
    "decode_request",
    "encode_request",
    "expects_reply",
    "request_frame",
]

DEFAULT_REVISION = Revision.V4_4


@dataclass(frozen=True, slots=True)
class Candidate:
    """One candidate reading of a command byte: its decoder, message class and revisions."""

    message: type[MyActuatorMessage]
    decode: Callable[[bytes], MyActuatorMessage]
    revisions: frozenset[Revision]

    def reason(self, revision: Revision, code: int) -> str:
        names = revision_names(self.revisions)
        return f"0x{code:02X} {self.message.TITLE} exists only in {names} (revision {revision.name} given)"


def _layout(message: Any) -> tuple[int, Candidate]:
    return message.CODE, Candidate(message, message.decode, message.REVISIONS)


def _echo(command: type[MyActuatorCommand]) -> tuple[int, Candidate]:
    def decode(data: bytes) -> MyActuatorMessage:
        return rep.Echo.decode(data, command)

    assert command.CODE is not None
    return command.CODE, Candidate(command, decode, command.REVISIONS)


def _declared(*modules: ModuleType) -> tuple[type[Command], ...]:
    """The command classes defined in ``modules``, in the order they are written there."""
    return command_classes(
        value
        for module in modules
        for value in vars(module).values()
        if getattr(value, "__module__", None) == module.__name__
    )


#: Every MyActuator command class. Each declares its facts once (reply type, READ, SLOW, ECHO,
#: STREAMABLE, NO_REPLY, NOTED, REVISIONS); the tables below and the bound codec's rules follow.
COMMANDS: tuple[type[Command], ...] = _declared(cmd, ctl, motion, rs485_motion)
#: The standard 8-byte requests (the ones with a command byte).
_REQUEST_CLASSES: tuple[type[MyActuatorCommand], ...] = tuple(
    c for c in COMMANDS if issubclass(c, MyActuatorCommand)
)


def _table(layouts: list[tuple[int, Candidate]]) -> dict[int, tuple[Candidate, ...]]:
    table: dict[int, tuple[Candidate, ...]] = {}
    for code, layout in layouts:
        if layout not in table.get(code, ()):  # two commands answered by one layout list it once
            table[code] = (*table.get(code, ()), layout)
    return table


#: Request layouts by DATA[0] (standard 8-byte commands; motion mode has no command byte).
REQUESTS: Mapping[int, tuple[Candidate, ...]] = _table([_layout(c) for c in _REQUEST_CLASSES])

#: Commands answered by an echo of their own data (§0); their replies decode to ``Echo(command=...)``.
ECHO_COMMANDS: tuple[type[MyActuatorCommand], ...] = tuple(
    c for c in _REQUEST_CLASSES if rep.Echo in c.reply_types()
)


def _reply_layout(command: type[MyActuatorCommand], reply: type[Reply]) -> tuple[int, Candidate]:
    if reply is rep.Echo:
        return _echo(command)
    if reply.CODE is None:  # a layout shared by several commands (R2): DATA[0] is the command's byte
        assert command.CODE is not None
        return command.CODE, Candidate(reply, reply.decode, command.REVISIONS)  # type: ignore[arg-type, attr-defined]
    if reply.CODE != command.CODE:
        raise TypeError(
            f"{command.__name__} (0x{command.CODE:02X}) is declared to be answered by {reply.__name__}, "
            f"whose DATA[0] is 0x{reply.CODE:02X}"
        )
    return _layout(reply)


#: Reply layouts by DATA[0]: each command's declared reply types.
REPLIES: Mapping[int, tuple[Candidate, ...]] = _table(
    [_reply_layout(c, reply) for c in _REQUEST_CLASSES for reply in c.reply_types()]
    + [_layout(event) for event in rep.EVENTS]  # (frames the motor sends of itself, answering nothing)
)

#: Requests without a reply to wait for, and why (the command table's "none"/"random").
NO_REPLY: Mapping[int, str] = {
    c.CODE: c.NO_REPLY for c in _REQUEST_CLASSES if c.NO_REPLY is not None and c.CODE is not None
}


def _check_enum(enum: type[IntEnum], codes: set[int], declaration: str) -> None:
    # The enums stay classes with members, so a user's mypy knows them; they must list what is declared.
    if codes != {int(m) for m in enum}:
        raise TypeError(
            f"{enum.__name__} must list exactly the commands declared {declaration}: "
            f"{', '.join(f'0x{c:02X}' for c in sorted(codes))}"
        )


_STATUS_CODES = {
    c.CODE: c.REVISIONS for c in _REQUEST_CLASSES if rep.StatusReply in c.reply_types() and c.CODE is not None
}
_check_enum(StatusCommand, set(_STATUS_CODES), "MyActuatorCommand[StatusReply]")
_check_enum(StreamableCommand, {c.CODE for c in _REQUEST_CLASSES if c.STREAMABLE and c.CODE}, "STREAMABLE")

if {StatusCommand(code): revisions for code, revisions in _STATUS_CODES.items()} != STATUS_COMMAND_REVISIONS:
    raise TypeError("enums.STATUS_COMMAND_REVISIONS must be the status commands' declared REVISIONS")


def expects_reply(command: MyActuatorMessage) -> bool:
    """Whether a reply to ``command`` should be awaited (False for 0x76, 0xB4, 0xB6)."""
    return command.code not in NO_REPLY


# ---- availability ----


def check_available(command: MyActuatorMessage, revision: Revision) -> None:
    """Raise unless ``command`` exists in ``revision``.

    Raises:
        ValueError: e.g. "0x79 CAN-ID setting exists only in V4.3 (revision V4_4 given)".
    """
    if not isinstance(revision, Revision):
        raise ValueError(f"revision={revision!r} is not a Revision (V4_3, V4_4)")
    reason = command.unavailable_reason(revision)
    if reason is not None:
        raise ValueError(reason)


def encode_request(command: MyActuatorMessage, *, revision: Revision = DEFAULT_REVISION) -> bytes:
    """The 8 data bytes of ``command``, after checking that ``revision`` has it.

    Raises:
        ValueError: the command does not exist in ``revision`` (see :func:`check_available`).
    """
    check_available(command, revision)
    return command.encode()


def arbitration_id(
    command: MyActuatorMessage, motor_id: int | None = None, *, broadcast: bool = False
) -> int:
    """The CAN identifier ``command`` is sent on.

    0x79 (``SetCanId``/``ReadCanId``) always goes to 0x300 and needs no motor id; motion commands go to
    0x400 + ID; anything else to 0x140 + ID, or to 0x280 with ``broadcast=True``.

    Raises:
        ValueError: motor id missing or outside 1..32; a motion or 0x79 command with ``broadcast``.
    """
    if isinstance(command, cmd.SetCanId | cmd.ReadCanId):
        if broadcast:
            raise ValueError("0x79 goes to 0x300 (every motor takes it); it has no 0x280 form")
        return ID_SETTING_ID
    if broadcast:
        if isinstance(command, MotionCommand):
            raise ValueError("motion mode has no broadcast form")
        return BROADCAST_ID
    if motor_id is None:
        raise ValueError("motor_id is required unless broadcast=True")
    return motion_request_id(motor_id) if isinstance(command, MotionCommand) else request_id(motor_id)


def request_frame(
    command: MyActuatorMessage,
    motor_id: int | None = None,
    *,
    revision: Revision = DEFAULT_REVISION,
    broadcast: bool = False,
) -> Frame:
    """The CAN frame that sends ``command`` (revision checked, identifier per :func:`arbitration_id`).

    Raises:
        ValueError: as :func:`encode_request` and :func:`arbitration_id`.
    """
    data = encode_request(command, revision=revision)
    return Frame(
        arbitration_id=arbitration_id(command, motor_id, broadcast=broadcast), data=data, is_rx=False
    )


# ---- decoding ----


def _decode_in(
    table: Mapping[int, tuple[Candidate, ...]], data: bytes, revision: Revision, *, what: str
) -> MyActuatorMessage:
    if not data:
        raise ProtocolError(f"empty {what}")
    layouts = table.get(data[0])
    if layouts is None:
        if table is REPLIES and data[0] in NO_REPLY:
            raise ProtocolError(
                f"0x{data[0]:02X} has no reply: {NO_REPLY[data[0]]}", raw=data, command=data[0]
            )
        raise ProtocolError(f"unknown {what} command byte", raw=data, command=data[0])
    candidates = [layout for layout in layouts if revision in layout.revisions]
    if not candidates:
        raise ProtocolError(layouts[0].reason(revision, data[0]), raw=data, command=data[0])
    errors: list[ProtocolError] = []
    for layout in candidates:
        try:
            message = layout.decode(data)
        except ProtocolError as exc:
            errors.append(exc)
            continue
        reason = message.unavailable_reason(revision)
        if reason is not None:
            raise ProtocolError(reason, raw=data, command=data[0])
        return message
    # Report the layout the bytes matched (a bad value), not one they were never meant to be.
    error = next((e for e in errors if not isinstance(e, LayoutMismatch)), errors[0])
    if not isinstance(error, LayoutMismatch):
        # A value outside this revision's range may be another revision's frame read with the wrong
        # layout (a V4.3 0x94 uint16 in DATA[6..7] reads as a V4.4 int32 of 655.36° and up): say so,
        # naming both revisions, so a motor bound with the wrong one is told apart from bad bytes.
        other = _other_revision_reading(layouts, data, revision)
        if other is not None:
            raise ProtocolError(
                f"{error.message}; looks like a {other} frame "
                f"(revision mismatch: decoded as {revision_names(frozenset({revision}))})",
                raw=data,
                command=data[0],
            )
    raise error


def _other_revision_reading(layouts: tuple[Candidate, ...], data: bytes, revision: Revision) -> str | None:
    """The revisions of the first layout outside ``revision`` that reads ``data`` whole, or None.

    "Whole": the layout decodes the bytes and encodes its reading back to the same bytes, so no
    non-zero byte was skipped as NULL (V4.3's 0x94 layout would read any V4.4 frame with DATA[6..7] = 0
    as 0°, which is no reading of it).
    """
    for layout in layouts:
        if revision in layout.revisions:
            continue
        try:
            if layout.decode(data).encode() != data:
                continue
        except ProtocolError:
            continue
        return revision_names(layout.revisions)
    return None


def _check_revision(revision: Revision) -> None:
    # A wrong revision argument is the caller's bug, not bad bytes: ValueError, as for commands.
    if not isinstance(revision, Revision):
        raise ValueError(f"revision={revision!r} is not a Revision (V4_3, V4_4)")


def _motion_scales(revision: Revision, motion_scales: MotionScales | None) -> MotionScales:
    return motion_scales if motion_scales is not None else MOTION_SCALES[revision]


def decode_standard_request(
    data: bytes, revision: Revision, *, id_setting_allowed: bool = False, id_setting_only: bool = False
) -> Command:
    """Decode a standard 8-byte request.

    0x79 travels only on CAN 0x300 (where nothing else does) or with RS485 ID byte 0xCD (which also
    carries broadcasts of every other command): callers say which by the two flags.

    Raises:
        ProtocolError: as :func:`decode_request`.
    """
    if data:
        is_id_setting = data[0] == ID_SETTING_CODE
        if is_id_setting and not (id_setting_allowed or id_setting_only):
            raise ProtocolError("0x79 is sent on 0x300 (RS485: ID byte 0xCD) only", raw=data, command=data[0])
        if id_setting_only and not is_id_setting:
            raise ProtocolError("only 0x79 is sent on 0x300", raw=data, command=data[0])
    return cast(Command, _decode_in(REQUESTS, data, revision, what="request"))


def decode_request(
    can_id: int,
    data: bytes,
    *,
    revision: Revision = DEFAULT_REVISION,
    motion_scales: MotionScales | None = None,
) -> Command:
    """Decode a host->motor CAN frame (device side: the simulator; the CLI's log decoder).

    Args:
        can_id: 0x141..0x160, 0x280 (same data as single-motor), 0x300 (0x79), or 0x401..0x420 (motion).
        data: the 8 data bytes.
        revision: protocol revision of the motor.
        motion_scales: motion-mode ranges (default: the revision's, see ``MotionScales.for_revision``).

    Returns:
        The typed command (``MotionCommand`` for 0x400+ID).

    Raises:
        ProtocolError: not a request identifier of this family, wrong length, unknown command byte, a
            value the layout does not accept, or a command that does not exist in ``revision``. When the
            identifier names a motor, the error's ``motor_id`` is set.
        ValueError: ``revision`` is not a :class:`Revision`.
    """
    _check_revision(revision)
    found = classify_id(can_id)
    kind, motor_id = found if found else (None, None)
    try:
        return _decode_request(kind, can_id, data, revision, motion_scales)
    except ProtocolError as exc:
        raise exc.with_context(motor_id=motor_id) from None


def _decode_request(
    kind: IdKind | None, can_id: int, data: bytes, revision: Revision, motion_scales: MotionScales | None
) -> Command:
    if kind in (IdKind.REQUEST, IdKind.BROADCAST):
        return decode_standard_request(data, revision)
    if kind is IdKind.ID_SETTING:
        return decode_standard_request(data, revision, id_setting_only=True)
    if kind is IdKind.MOTION_REQUEST:
        return MotionCommand.decode(data, _motion_scales(revision, motion_scales))
    raise ProtocolError(f"0x{can_id:X} is not a MyActuator request identifier", raw=data)


def decode_standard_reply(data: bytes, revision: Revision) -> Reply:
    """Decode a standard 8-byte reply (CAN 0x240+ID or 0x300, or an RS485 frame's DATA).

    Raises:
        ProtocolError: as :func:`decode_reply`.
    """
    return cast(Reply, _decode_in(REPLIES, data, revision, what="reply"))


def decode_reply(
    can_id: int,
    data: bytes,
    *,
    revision: Revision = DEFAULT_REVISION,
    motion_scales: MotionScales | None = None,
) -> Reply:
    """Decode a motor->host CAN frame.

    Args:
        can_id: 0x241..0x260 (replies, active 0xB6 frames, 0x9A error reports), 0x300 (0x79 replies as
            the manual prints them), or 0x501..0x520 (motion replies).
        data: the 8 data bytes.
        revision: protocol revision of the motor.
        motion_scales: motion-mode ranges (default: the revision's).

    Returns:
        The typed reply: a reply class, or ``Echo(command=...)`` for commands answered by an echo.

    Raises:
        ProtocolError: not a reply identifier of this family, wrong length, unknown command byte, a
            value the layout does not accept, a reply that does not exist in ``revision``, or a motion
            reply whose DATA[0] is not the identifier's motor id. The error's ``motor_id`` is set from
            the identifier.
        ValueError: ``revision`` is not a :class:`Revision`.
    """
    _check_revision(revision)
    found = classify_id(can_id)
    kind, motor_id = found if found else (None, None)
    try:
        return _decode_reply(kind, motor_id, can_id, data, revision, motion_scales)
    except ProtocolError as exc:
        raise exc.with_context(motor_id=motor_id) from None


def _decode_reply(
    kind: IdKind | None,
    motor_id: int | None,
    can_id: int,
    data: bytes,
    revision: Revision,
    motion_scales: MotionScales | None,
) -> Reply:
    if kind is IdKind.REPLY:
        return decode_standard_reply(data, revision)
    if kind is IdKind.ID_SETTING:
        if data and data[0] != ID_SETTING_CODE:
            raise ProtocolError("only 0x79 replies arrive on 0x300", raw=data, command=data[0])
        return decode_standard_reply(data, revision)
    if kind is IdKind.MOTION_REPLY:
        reply = MotionReply.decode(data, _motion_scales(revision, motion_scales))
        if reply.motor_id != motor_id:
            raise ProtocolError(
                f"motion reply on 0x{can_id:X} names motor {reply.motor_id}", raw=data, motor_id=motor_id
            )
        return reply
    raise ProtocolError(f"0x{can_id:X} is not a MyActuator reply identifier", raw=data)
