"""The base classes of every typed command and reply, and the DATA[0] decoder-table lookup.

A family's commands and replies are frozen, slotted, keyword-only dataclasses deriving from
:class:`Command` or :class:`Reply`. Both directions encode and decode, because the simulator speaks
the same codecs from the device side: the host encodes commands and decodes replies, a simulated
motor decodes commands and encodes replies.

Contract of every ``decode`` (h11's reader contract, narrowed to whole payloads): given the payload
bytes of one frame, return the typed object or raise :class:`~servobus.errors.ProtocolError` with the
raw bytes. Never any other exception: a decoder checks lengths and enum values itself.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from types import NoneType, UnionType
from typing import Any, ClassVar, Generic, Union, get_args, get_origin

if sys.version_info >= (3, 13):
    from typing import TypeVar
else:  # a default for the reply type: a bare ``Command`` is ``Command[Any]``
    from typing_extensions import TypeVar

from servobus.errors import ProtocolError

__all__ = ["Command", "Message", "Reply", "construct", "decode_by_code", "require_length"]

M = TypeVar("M", bound="Message")
R = TypeVar("R", covariant=True, default=Any)
"""A command's reply type: ``Command[StatusReply]`` (``Command[None]``: no reply comes)."""


class Message:
    """A command or reply: a frozen dataclass with its command byte and its payload encoding.

    Subclasses set ``CODE`` (the DATA[0] byte, or ``None`` for frames without a command byte) and
    implement :meth:`encode`. Validation of physical ranges happens in ``__post_init__``, so an
    object that exists always encodes.
    """

    __slots__ = ()
    CODE: ClassVar[int | None] = None

    def encode(self) -> bytes:
        """The payload bytes of this message (CAN data field / RS485 DATA[0..n])."""
        raise NotImplementedError(type(self).__name__)


class Command(Message, Generic[R]):
    """A host -> motor message, generic in the reply it gets: ``class ReadStatus2(Command[StatusReply])``.

    A command class says everything about itself once, and the codec tables, the bound codec's
    rules, the simulator's dispatch, the typed motor methods, the CLI and the DBC are derived from it
    (design.md: "each command is said once"). Besides ``CODE``, its fields and the reply type in its
    base, it declares:

    ``READ``
        It changes nothing on the motor: an automatic retry may resend it, and a motor that was
        only read is not stopped when the Bus is left.
    ``SLOW``
        It writes ROM/flash or moves the brake: its reply may take the codec's longer time.
    ``ECHO``
        Its reply echoes the value it wrote, so the match key holds those bytes (a stray echo of
        another value never answers it).
    ``STREAMABLE``
        The motor can stream its reply (MyActuator 0xB6).
    ``NO_REPLY``
        Why no reply comes (``"the program restarts"``), or None when one does. A class declared
        ``Command[None]`` must say why.
    ``NOTED``
        It changes how the motor talks (streams, error reports): the bound codec is told when it
        was sent (``BoundCodec.note_sent``).
    ``NEVER_ECHOED``
        Its real reply is never its own bytes (it carries measurements: temperature, current), so a
        reply that is those bytes is the motor echoing it without executing it (MyActuator after
        its 0xB3 trip): the request fails with ``MotorNotExecuted`` (``BoundCodec.may_echo``).

    ``POSITION``
        How a position field of it is meant, for host-side limits (:mod:`servobus.limits`):
        ``"absolute"`` (the default), ``"relative"`` (an increment from where the motor is) or
        ``"single_turn"`` (an angle within the turn the motor is in); :meth:`inactive` says which
        fields its motor ignores as it is set.

    ``REPLY`` is not written by hand: it is the type argument of the command's base, read when the
    class is made (a union for a command answered by one of several layouts; None for no reply).
    """

    __slots__ = ()
    REPLY: ClassVar[Any]  # = Reply, below: a command whose base gives no reply type
    READ: ClassVar[bool] = False
    SLOW: ClassVar[bool] = False
    ECHO: ClassVar[bool] = False
    STREAMABLE: ClassVar[bool] = False
    NO_REPLY: ClassVar[str | None] = None
    NOTED: ClassVar[bool] = False
    NEVER_ECHOED: ClassVar[bool] = False
    POSITION: ClassVar[str] = "absolute"

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        # ``dataclass(slots=True)`` makes the class a second time from this one's __dict__, which
        # holds __orig_bases__ and the REPLY found the first time.
        for base in cls.__dict__.get("__orig_bases__", ()):
            origin = get_origin(base)
            if isinstance(origin, type) and issubclass(origin, Command):
                (reply,) = get_args(base)
                if not isinstance(reply, TypeVar):
                    cls.REPLY = None if reply is None or reply is NoneType else reply
        if (
            cls.REPLY is None
            and cls.NO_REPLY is None
            and cls.__dict__.get("__dataclass_fields__") is not None
        ):
            raise TypeError(f"{cls.__name__} is declared without a reply: say why in NO_REPLY")

    def inactive(self) -> frozenset[str]:
        """The fields the motor does not act on as this command is set (a position with kp = 0, a
        mode that ignores it): host-side limits (:mod:`servobus.limits`) leave them alone."""
        return frozenset()

    @classmethod
    def reply_types(cls) -> tuple[type[Reply], ...]:
        """The reply classes that may answer this command (empty when none comes)."""
        reply = cls.REPLY
        if reply is None:
            return ()
        if get_origin(reply) in (Union, UnionType):
            return tuple(t for t in get_args(reply) if t is not NoneType)
        return (reply,)


class Reply(Message):
    """A motor -> host message.

    ``FAULTS`` names the field that holds the motor's error flags in replies that carry them (the Bus
    keeps ``motor.fault`` from it); None in every other reply.

    ``FAULT_CODE`` names the field that holds the motor's error *code* where the family reports one
    code rather than flags (an ``enum.IntEnum`` field, or an int): the Bus keeps ``motor.fault`` from
    it (a :class:`~servobus.errors.MotorFault` with ``code``), except for the codes in
    ``NO_FAULT_CODES``, which are states and no fault (default: 0; Damiao: 0 disabled, 1 enabled).
    A reply declares one of ``FAULTS`` and ``FAULT_CODE``, not both; None in every other reply.

    ``EVENT`` names a frame the motor sends of itself to tell that something happened to it (not an
    answer, not a measurement: MyActuator's 0xF1 communication trip): the Bus counts it under that
    name, shows it in ``motor.fault`` until the motor executes a command again, and tells the
    status listeners ``EVENT_REASON``. None in every other reply.

    ``SINGLE_TURN`` says its angle is within one turn, not where the motor is (MyActuator 0x94,
    LK 0x94): host-side limits (:mod:`servobus.limits`) never take it for the motor's position.
    """

    __slots__ = ()
    FAULTS: ClassVar[str | None] = None
    FAULT_CODE: ClassVar[str | None] = None
    NO_FAULT_CODES: ClassVar[frozenset[int]] = frozenset({0})
    EVENT: ClassVar[str | None] = None
    EVENT_REASON: ClassVar[str] = ""
    SINGLE_TURN: ClassVar[bool] = False


Command.REPLY = Reply


def require_length(data: bytes, length: int, *, what: str, command: int | None = None) -> None:
    """Raise ProtocolError unless ``data`` is exactly ``length`` bytes long."""
    if len(data) != length:
        raise ProtocolError(
            f"{what}: expected {length} data bytes, got {len(data)}",
            raw=data,
            command=command if command is not None else (data[0] if data else None),
        )


def decode_by_code(table: Mapping[int, Callable[[bytes], M]], data: bytes, *, what: str) -> M:
    """Decode ``data`` with the decoder that ``table`` keys by its DATA[0].

    Raises:
        ProtocolError: ``data`` is empty or its DATA[0] has no decoder (or the decoder rejects it).
    """
    if not data:
        raise ProtocolError(f"empty {what}")
    decoder = table.get(data[0])
    if decoder is None:
        raise ProtocolError(f"unknown {what} command byte", raw=data, command=data[0])
    return decoder(data)


def construct(
    cls: type[M], data: bytes, fields: dict[str, Any], *, what: str | None = None, command: int | None = None
) -> M:
    """``cls(**fields)`` for values decoded from ``data``; a value its validation refuses is bad bytes.

    A decoded value the typed message rejects (a count above the encoder's width, a reserved enum
    value) means the bytes do not decode, so the ValueError surfaces as ProtocolError with them.

    Raises:
        ProtocolError: the constructor refused a value (its message kept, the raw bytes attached).
    """
    try:
        return cls(**fields)
    except ValueError as exc:
        raise ProtocolError(f"{what or cls.__name__}: {exc}", raw=data, command=command) from None
