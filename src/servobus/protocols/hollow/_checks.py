"""Validation helpers of the hollow messages: one wording for every ValueError and ProtocolError.

Commands and replies check their fields in ``__post_init__`` with these (ValueError naming the field,
the value and the limits, before any byte exists); decoders build objects through :func:`build`, so a
received value that the constructor refuses becomes a ProtocolError carrying the raw bytes.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Any, TypeVar

from servobus.errors import ProtocolError
from servobus.protocols._fields import check_flag, check_range, to_enum
from servobus.protocols._message import Message, construct

__all__ = [
    "build",
    "check_flag",
    "check_int",
    "check_real",
    "decode_enum",
    "require_size",
    "to_enum",
]

E = TypeVar("E", bound=IntEnum)
M = TypeVar("M", bound=Message)


def check_real(name: str, value: object, lo: float, hi: float) -> None:
    """Raise ValueError unless ``value`` is a real number (not bool) within [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{name}={value!r} is not a number")
    check_range(name, value, lo, hi)


def check_int(name: str, value: object, lo: int, hi: int) -> None:
    """Raise ValueError unless ``value`` is an int (not bool) within [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name}={value!r} is not an integer")
    check_range(name, value, lo, hi)


def decode_enum(name: str, value: int, enum: type[E], data: bytes, *, motor_id: int | None = None) -> E:
    """A received byte as a member of ``enum``.

    Raises:
        ProtocolError: the byte is no member's value (reserved or unknown), with the raw bytes.
    """
    try:
        return enum(value)
    except ValueError:
        raise ProtocolError(f"{name}: unknown value {value}", raw=data, motor_id=motor_id) from None


def require_size(data: bytes, size: int, *, what: str) -> None:
    """Raise ProtocolError unless ``data`` is exactly ``size`` bytes long.

    Unlike the shared ``require_length`` it names no command byte: hollow frames have none.
    """
    if len(data) != size:
        raise ProtocolError(f"{what}: expected {size} data bytes, got {len(data)}", raw=data)


def build(cls: type[M], data: bytes, **fields: Any) -> M:
    """``cls(**fields)`` from received bytes; a refused value is a ProtocolError (see ``construct``).

    Hollow frames have no command byte, so the error names none.
    """
    return construct(cls, data, fields)
