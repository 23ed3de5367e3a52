"""The toy family's codec: decode tables derived from the message classes, and one motor's bound codec.

Identifiers (11-bit, classic CAN, none used by a built-in family):

==========  ===========  ==============================================================
identifier  direction    carries
==========  ===========  ==============================================================
0x600 + ID  host->motor  a request to motor ID (1..31)
0x600       host->all    the same request to every motor (each answers as to its own)
0x680 + ID  motor->host  motor ID's reply; DATA[0] tells which reply it is
==========  ===========  ==============================================================

A reply is matched to its request by its identifier and DATA[0] (the reply class's ``CODE``); the echo
of a written value (``ECHO``) is matched by its bytes too, so a late echo of another value never
answers the next write.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from typing import Any

from servobus.errors import ProtocolError
from servobus.frame import Frame, classic_request
from servobus.protocols import Broadcast, Command, FrameKind, Reply, check_bus
from servobus.protocols.authoring import (
    CodecBase,
    Message,
    command_classes,
    decode_by_code,
    echo_key,
    frame_key,
    motor_ids_of,
)
from servobus_toy import messages
from servobus_toy.messages import Revision, Stop, ToyCommand, ToyReply

__all__ = [
    "BROADCAST_ID",
    "COMMANDS",
    "LINKS",
    "MOTOR_IDS",
    "ToyCodec",
    "bind",
    "broadcast",
    "decode_reply",
    "decode_request",
    "reply_id",
    "request_id",
]

LINKS = ("can",)
MOTOR_IDS = range(1, 32)
BROADCAST_ID = 0x600
_REPLY_BASE = 0x680
#: How long a reply may take: the drive answers within a millisecond, a flash write (``SLOW``) within
#: 100 ms; both with room for a loaded bus.
TIMEOUT_S = 0.02
SLOW_TIMEOUT_S = 0.2


#: Every command class, in declaration order; the tables below are derived from their declarations.
COMMANDS: tuple[type[ToyCommand[Any]], ...] = command_classes(vars(messages).values())  # type: ignore[assignment]


def _code(cls: type[Message]) -> int:
    """``cls.CODE``: every toy message has one (TypeError for a class declared without)."""
    if cls.CODE is None:
        raise TypeError(f"{cls.__name__} declares no CODE")
    return cls.CODE


def _reply_class(cls: type[Reply]) -> type[ToyReply]:
    if not issubclass(cls, ToyReply):
        raise TypeError(f"{cls.__name__} is not a toy reply")
    return cls


_REQUESTS: dict[int, Callable[[bytes], ToyCommand[Any]]] = {_code(cls): cls.decode for cls in COMMANDS}
_REPLIES: dict[int, Callable[[bytes], ToyReply]] = {
    _code(reply): _reply_class(reply).decode for cls in COMMANDS for reply in cls.reply_types()
}
#: command class -> DATA[0] of its reply (None: no reply comes)
_REPLY_CODES: dict[type[Command], int | None] = {
    cls: _code(reply) if (reply := cls.REPLY) is not None else None for cls in COMMANDS
}
_ECHOES = frozenset(cls.CODE for cls in COMMANDS if cls.ECHO)


def request_id(motor_id: int) -> int:
    """Motor ``motor_id``'s request identifier.

    Raises:
        ValueError: ``motor_id`` outside 1..31.
    """
    if isinstance(motor_id, bool) or not isinstance(motor_id, int) or motor_id not in MOTOR_IDS:
        raise ValueError(f"toy motor_id={motor_id!r} is outside 1..31")
    return BROADCAST_ID + motor_id


def reply_id(motor_id: int) -> int:
    """Motor ``motor_id``'s reply identifier (ValueError outside 1..31)."""
    return _REPLY_BASE + request_id(motor_id) - BROADCAST_ID


def _revision(revision: Revision | str | None) -> Revision:
    """``revision``, its name (``"V1"``) resolved, or the default; ValueError for another."""
    if isinstance(revision, Revision):
        return revision
    if revision is None:
        return Revision.V1
    from servobus_toy import FAMILY  # (the package imports this module first)

    found: Revision = FAMILY.revision(revision)
    return found


def decode_request(can_id: int, data: bytes, *, revision: Revision | str | None = None) -> ToyCommand[Any]:
    """The command in a request frame's ``data`` (``can_id``: 0x600..0x61F).

    Raises:
        ProtocolError: not a toy request identifier, or bytes that do not decode.
    """
    _revision(revision)
    if not BROADCAST_ID <= can_id <= BROADCAST_ID + MOTOR_IDS.stop - 1:
        raise ProtocolError(f"0x{can_id:03X} is no toy request identifier", raw=data)
    return decode_by_code(_REQUESTS, data, what="toy request")


def decode_reply(can_id: int, data: bytes, *, revision: Revision | str | None = None) -> ToyReply:
    """The reply in a reply frame's ``data`` (``can_id``: 0x681..0x69F).

    Raises:
        ProtocolError: not a toy reply identifier, or bytes that do not decode.
    """
    _revision(revision)
    if not _REPLY_BASE + 1 <= can_id <= _REPLY_BASE + MOTOR_IDS.stop - 1:
        raise ProtocolError(f"0x{can_id:03X} is no toy reply identifier", raw=data)
    return decode_by_code(_REPLIES, data, what="toy reply")


class ToyCodec(CodecBase):
    """One toy motor on CAN (the :class:`~servobus.protocols.BoundCodec` contract)."""

    family = "toy"
    SAFE_COMMANDS = {"stop": lambda codec: Stop()}  # noqa: RUF012 - a class table, not per instance
    __slots__ = ("_reply_id", "_request_id")

    def __init__(self, motor_id: int, revision: Revision) -> None:
        self._request_id = request_id(motor_id)
        self._reply_id = reply_id(motor_id)
        self.motor_id = motor_id
        self.revision = revision
        self.model = None
        self.link = "can"
        self.framing = None
        self.request_ids = frozenset({self._request_id})
        self.reply_ids = frozenset({self._reply_id})
        self.shared_ids = frozenset({BROADCAST_ID})

    def encode(self, command: Command) -> Frame:
        """The frame that sends ``command`` to this motor.

        Raises:
            ValueError: not a toy command.
        """
        if not isinstance(command, ToyCommand):
            raise ValueError(f"{command!r} is not a toy command")
        return classic_request(self._request_id, command.encode())

    def reply_key(self, command: Command) -> Hashable | None:
        """The key the reply to ``command`` carries; None for a command that gets no reply.

        Raises:
            ValueError: not a toy command.
        """
        try:
            code = _REPLY_CODES[type(command)]
        except KeyError:
            raise ValueError(f"{command!r} is not a toy command") from None
        if code is None:
            return None
        key = frame_key(self._reply_id, code)
        return echo_key(key, command.encode()) if command.ECHO else key

    def classify(self, frame: Frame) -> tuple[FrameKind, Hashable | None]:
        """REPLY for a frame on this motor's reply identifier (keyed by DATA[0]), NOT_OURS otherwise."""
        if (
            frame.arbitration_id != self._reply_id
            or not frame.is_rx
            or frame.is_extended_id
            or frame.is_fd
            or frame.is_serial
        ):
            return FrameKind.NOT_OURS, None
        data = frame.data
        if not data:
            return FrameKind.REPLY, None
        key = frame_key(self._reply_id, data[0])
        return FrameKind.REPLY, echo_key(key, data) if data[0] in _ECHOES else key

    def decode(self, frame: Frame) -> Reply:
        """The typed reply in ``frame``.

        Raises:
            ProtocolError: bytes that do not decode, or a frame that is not this motor's.
        """
        if frame.arbitration_id != self._reply_id:
            raise ProtocolError(
                f"{frame!r} is not a frame of this motor", raw=frame.data, motor_id=self.motor_id
            )
        return decode_by_code(_REPLIES, frame.data, what="toy reply")

    def timeout_s(self, command: Command) -> float:
        """How long the reply to ``command`` may take (a ``SLOW`` one: a flash write)."""
        return SLOW_TIMEOUT_S if command.SLOW else TIMEOUT_S

    def retry_safe(self, command: Command) -> bool:
        """True for reads (``READ``): only they may be resent, and a motor only read is not stopped."""
        return command.READ


def bind(
    motor_id: int, *, revision: Revision | str | None = None, model: None = None, link: str = "can"
) -> ToyCodec:
    """Toy motor ``motor_id``'s codec.

    Raises:
        ValueError: an id outside 1..31, an unknown revision, a model (toy motors have none) or a link
            other than ``"can"``.
    """
    if link not in LINKS:
        raise ValueError(f"toy has no link {link!r} (links: {', '.join(LINKS)})")
    if model is not None:
        raise ValueError(f"toy motors have no models (model={model!r} given)")
    return ToyCodec(motor_id, _revision(revision))


def broadcast(command: Command, motors: Sequence[ToyCodec]) -> Broadcast:
    """``command`` once on 0x600; every motor of ``motors`` answers it as its own.

    Raises:
        ValueError: no motors, a repeated id, motors that are not toy motors, or a command that is not
            a toy command.
    """
    if not motors:
        raise ValueError("a broadcast needs at least one motor")
    motor_ids_of(motors)
    check_bus(motors)
    if not all(isinstance(m, ToyCodec) for m in motors):
        raise ValueError("a toy broadcast goes to toy motors")
    frame = motors[0].encode(command)
    replies = {m.motor_id: key for m in motors if (key := m.reply_key(command)) is not None}
    return Broadcast(classic_request(BROADCAST_ID, frame.data), replies)
