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

from collections.abc import Callable, Mapping
from typing import Any, ClassVar, TypeVar

from servobus.errors import ProtocolError

__all__ = ["Command", "Message", "Reply", "construct", "decode_by_code", "require_length"]

M = TypeVar("M", bound="Message")


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


class Command(Message):
    """A host -> motor message."""

    __slots__ = ()


class Reply(Message):
    """A motor -> host message.

    ``FAULTS`` names the field that holds the motor's error flags in replies that carry them (the Bus
    keeps ``motor.fault`` from it); None in every other reply.
    """

    __slots__ = ()
    FAULTS: ClassVar[str | None] = None


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
