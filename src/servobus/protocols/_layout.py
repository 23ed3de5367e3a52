"""Fixed payload layouts stated once (private): fields at offsets, and the classes derived from them.

A payload of ``SIZE`` bytes (8 on classic CAN), DATA[0] the command byte, fields little-endian at fixed
offsets, every other byte NULL. A message class states its layout once as ``FIELDS``, ``(offset, field)``
pairs whose field names are the dataclass attribute names, and :class:`Layout` derives validation,
``encode`` and ``decode`` from it; the fast paths, the DBC and the simulator read the same ``FIELDS``.

Decoding choices (one rule for every family that uses it): NULL bytes are ignored on decode; a wrong
length, a wrong command byte or constant, or a field value the class does not accept (unknown enum
value, non-ASCII text, NaN float) raises ProtocolError with the raw bytes. On construction every field
is checked (ValueError naming field, value and limits) and enum/flag fields are stored as their types.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from enum import IntEnum, IntFlag
from typing import Any, ClassVar, Protocol, Self, TypeVar

from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField, check_range, round_half_away
from servobus.protocols._message import Message, require_length
from servobus.protocols._message import construct as _construct

__all__ = [
    "FLOAT32_MAX",
    "AsciiField",
    "BoolField",
    "EnumField",
    "FieldCodec",
    "FlagsField",
    "Float32BEField",
    "Float32Field",
    "Layout",
    "LayoutMismatch",
    "OpenEnumField",
    "StepField",
    "check_fields",
    "check_payload",
    "construct",
]

FLOAT32_MAX = struct.unpack("<f", b"\xff\xff\x7f\x7f")[0]

E = TypeVar("E", bound=IntEnum)
M = TypeVar("M", bound=Message)


class FieldCodec(Protocol):
    """What :class:`Fixed` needs of a field: ScaledField and IntField already fit."""

    @property
    def name(self) -> str: ...

    @property
    def size(self) -> int: ...

    def check(self, value: Any, /) -> None: ...

    def encode(self, value: Any, /) -> bytes: ...

    def decode(self, data: bytes, offset: int = 0, /) -> Any: ...


@dataclass(frozen=True, slots=True)
class EnumField:
    """An IntEnum carried as an unsigned integer; unknown codes do not decode."""

    name: str
    size: int
    enum: type[IntEnum]
    _codes: frozenset[int] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_codes", frozenset(int(member) for member in self.enum))

    def check(self, value: Any) -> None:
        if isinstance(value, bool) or not isinstance(value, int) or value not in self._codes:
            choices = ", ".join(repr(member) for member in self.enum)
            raise ValueError(f"{self.name}={value!r} is not one of {choices}")

    def normalise(self, value: Any) -> IntEnum:
        return self.enum(value)

    def encode(self, value: Any) -> bytes:
        self.check(value)
        return int(value).to_bytes(self.size, "little")

    def decode(self, data: bytes, offset: int = 0) -> IntEnum:
        code = int.from_bytes(data[offset : offset + self.size], "little")
        try:
            return self.enum(code)
        except ValueError:
            raise ValueError(f"{self.name}=0x{code:02X} is not one of {self.enum.__name__}") from None


@dataclass(frozen=True, slots=True)
class OpenEnumField:
    """An IntEnum whose undefined codes are kept as plain ints (0x70 run mode, §9 item 27)."""

    name: str
    size: int
    enum: type[IntEnum]

    def check(self, value: Any) -> None:
        IntField(self.name, self.size).check(int(value) if isinstance(value, IntEnum) else value)

    def normalise(self, value: Any) -> IntEnum | int:
        try:
            return self.enum(value)
        except ValueError:
            return int(value)

    def encode(self, value: Any) -> bytes:
        self.check(value)
        return int(value).to_bytes(self.size, "little")

    def decode(self, data: bytes, offset: int = 0) -> IntEnum | int:
        code = int.from_bytes(data[offset : offset + self.size], "little")
        try:
            return self.enum(code)
        except ValueError:
            return code


@dataclass(frozen=True, slots=True)
class FlagsField:
    """An IntFlag that keeps undefined bits (0x9A error state)."""

    name: str
    size: int
    flags: type[IntFlag]

    def check(self, value: Any) -> None:
        IntField(self.name, self.size).check(int(value) if isinstance(value, IntFlag) else value)

    def normalise(self, value: Any) -> IntFlag:
        return self.flags(value)

    def encode(self, value: Any) -> bytes:
        self.check(value)
        return int(value).to_bytes(self.size, "little")

    def decode(self, data: bytes, offset: int = 0) -> IntFlag:
        return self.flags(int.from_bytes(data[offset : offset + self.size], "little"))


@dataclass(frozen=True, slots=True)
class StepField:
    """An unsigned count of ``step`` units (0xB6 interval: 10 ms/LSB). Decodes to an exact int."""

    name: str
    size: int
    step: int

    @property
    def limits(self) -> tuple[int, int]:
        return (0, ((1 << (8 * self.size)) - 1) * self.step)

    @property
    def resolution(self) -> int:
        return self.step

    def check(self, value: Any) -> None:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{self.name}={value!r} is not a number")
        check_range(self.name, value, *self.limits)

    def encode(self, value: Any) -> bytes:
        self.check(value)
        return round_half_away(value / self.step).to_bytes(self.size, "little")

    def decode(self, data: bytes, offset: int = 0) -> int:
        return int.from_bytes(data[offset : offset + self.size], "little") * self.step


@dataclass(frozen=True, slots=True)
class BoolField:
    """A flag byte: 1 is True, 0 is False; anything else does not decode."""

    name: str
    size: int = 1

    def check(self, value: Any) -> None:
        if not isinstance(value, bool):
            raise ValueError(f"{self.name}={value!r} is not a bool")

    def encode(self, value: Any) -> bytes:
        self.check(value)
        return int(value).to_bytes(self.size, "little")

    def decode(self, data: bytes, offset: int = 0) -> bool:
        code = int.from_bytes(data[offset : offset + self.size], "little")
        if code not in (0, 1):
            raise ValueError(f"{self.name}={code} is not 0 or 1")
        return code == 1


@dataclass(frozen=True, slots=True)
class Float32Field:
    """An IEEE-754 binary32, little-endian (§0). Accepts finite values a float32 holds; encoding rounds
    to the nearest float32, which is this field's "resolution". NaN and infinities do not decode."""

    name: str
    size: int = 4

    @property
    def limits(self) -> tuple[float, float]:
        return (-FLOAT32_MAX, FLOAT32_MAX)

    def check(self, value: Any) -> None:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{self.name}={value!r} is not a number")
        if not -FLOAT32_MAX <= value <= FLOAT32_MAX:
            raise ValueError(f"{self.name}={value!r} is outside [{-FLOAT32_MAX!r}, {FLOAT32_MAX!r}]")

    def encode(self, value: Any) -> bytes:
        self.check(value)
        return struct.pack("<f", value)

    def decode(self, data: bytes, offset: int = 0) -> float:
        value: float = struct.unpack_from("<f", data, offset)[0]
        if not math.isfinite(value):
            raise ValueError(f"{self.name}={value!r} is not finite")
        return value


@dataclass(frozen=True, slots=True)
class Float32BEField:
    """An IEEE-754 binary32, big-endian (hollow.md §6, §9.3: the PI multipliers), within
    [``lo``, FLOAT32_MAX]; NaN and infinities do not decode."""

    name: str
    lo: float = -FLOAT32_MAX
    size: int = 4

    @property
    def limits(self) -> tuple[float, float]:
        return (self.lo, FLOAT32_MAX)

    def check(self, value: Any) -> None:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{self.name}={value!r} is not a number")
        check_range(self.name, value, self.lo, FLOAT32_MAX)

    def encode(self, value: Any) -> bytes:
        self.check(value)
        return struct.pack(">f", value)

    def decode(self, data: bytes, offset: int = 0) -> float:
        value: float = struct.unpack_from(">f", data, offset)[0]
        if not math.isfinite(value):
            raise ValueError(f"{self.name}={value!r} is not finite")
        return value


@dataclass(frozen=True, slots=True)
class AsciiField:
    """Up to ``size`` printable ASCII characters, NUL-padded on encode.

    Padding of short names is not specified (§4.35): decoding strips trailing NULs and spaces, so a
    value may not end in a space (it would not survive the round trip).
    """

    name: str
    size: int
    _allowed: frozenset[int] = field(default=frozenset(range(0x20, 0x7F)), repr=False, compare=False)

    def check(self, value: Any) -> None:
        if not isinstance(value, str):
            raise ValueError(f"{self.name}={value!r} is not a str")
        if len(value) > self.size:
            raise ValueError(f"{self.name}={value!r} is longer than {self.size} characters")
        if any(ord(c) not in self._allowed for c in value) or value != value.rstrip(" "):
            raise ValueError(f"{self.name}={value!r} is not printable ASCII without trailing spaces")

    def encode(self, value: Any) -> bytes:
        self.check(value)
        return str(value).encode("ascii").ljust(self.size, b"\x00")

    def decode(self, data: bytes, offset: int = 0) -> str:
        raw = data[offset : offset + self.size].rstrip(b"\x00 ")
        if any(b not in self._allowed for b in raw):
            raise ValueError(f"{self.name}={raw!r} is not printable ASCII")
        return raw.decode("ascii")


class LayoutMismatch(ProtocolError):
    """The bytes are not this layout at all (command byte or a layout constant differs), as opposed to
    being this layout with a bad value. Lets a decoder that tries several layouts of one command byte
    report the error of the layout that matched."""


def construct(cls: type[M], data: bytes, values: dict[str, Any], *, what: str | None = None) -> M:
    """``cls(**values)`` from decoded bytes; a refused value is a ProtocolError naming DATA[0]."""
    return _construct(cls, data, values, what=what, command=data[0] if data else None)


class Layout(Message):
    """A payload of ``SIZE`` bytes: ``CODE`` in DATA[0], ``FIELDS`` at their offsets, NULL elsewhere.

    ``CONSTANTS`` are ``(offset, byte)`` pairs a layout fixes (a read/write flag, a version flag):
    written on encode, required on decode, which is how two layouts sharing a command byte are told
    apart. A class whose DATA[0] varies leaves ``CODE`` None and declares a field at offset 0.
    """

    __slots__ = ()
    SIZE: ClassVar[int] = 8
    FIELDS: ClassVar[tuple[tuple[int, FieldCodec], ...]] = ()
    CONSTANTS: ClassVar[tuple[tuple[int, int], ...]] = ()

    def __post_init__(self) -> None:
        check_fields(self, self.FIELDS)

    def encode(self) -> bytes:
        buf = bytearray(self.SIZE)
        if self.CODE is not None:
            buf[0] = self.CODE
        for offset, byte in self.CONSTANTS:
            buf[offset] = byte
        for offset, spec in self.FIELDS:
            buf[offset : offset + spec.size] = spec.encode(getattr(self, spec.name))
        return bytes(buf)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        """Decode the payload bytes.

        Raises:
            ProtocolError: wrong length, wrong command byte or constant, or a value the class does not
                accept.
        """
        check_payload(data, cls.CODE, what=cls.__name__, size=cls.SIZE)
        for offset, byte in cls.CONSTANTS:
            if data[offset] != byte:
                raise LayoutMismatch(
                    f"{cls.__name__}: DATA[{offset}] is not 0x{byte:02X}", raw=data, command=data[0]
                )
        try:
            values = {spec.name: spec.decode(data, offset) for offset, spec in cls.FIELDS}
        except ValueError as exc:
            raise ProtocolError(f"{cls.__name__}: {exc}", raw=data, command=data[0]) from None
        return construct(cls, data, values)

    @classmethod
    def field_specs(cls) -> dict[str, FieldCodec]:
        """The field codecs by attribute name (tests build their strategies from this)."""
        return {spec.name: spec for _, spec in cls.FIELDS}


def check_fields(message: object, specs: tuple[tuple[int, FieldCodec], ...]) -> None:
    """Validate each field of ``message``; store enum and flag fields as their types (a plain int of a
    defined code becomes the enum member, so the object is typed and prints names)."""
    for _, spec in specs:
        value = getattr(message, spec.name)
        spec.check(value)
        normalise = getattr(spec, "normalise", None)
        if normalise is not None:
            object.__setattr__(message, spec.name, normalise(value))


def check_payload(data: bytes, code: int | None, *, what: str, size: int = 8) -> None:
    """Raise ProtocolError unless ``data`` is ``size`` bytes whose DATA[0] is ``code`` (if given)."""
    require_length(data, size, what=what, command=data[0] if data else None)
    if code is not None and data[0] != code:
        raise LayoutMismatch(f"{what}: DATA[0] is not 0x{code:02X}", raw=data, command=data[0])
