"""What every LK message shares: base classes with revision availability, 8-byte payload helpers.

Every LK frame is a classic CAN frame with DLC 8 and DATA[0] = command byte (spec §0, §1.1), except
the 0x280 multi-motor frame, which has no command byte (spec §5). Decoders here are strict about
length and command byte and lenient about NULL bytes: the manuals tell the master to send 0x00 but
spec §0 says a decoder should not rely on them, so NULL bytes are ignored on decode (requests and
replies alike) and written as 0x00 on encode. Fixed non-NULL bytes (0x44's ``05 FA``) are checked.
"""

from __future__ import annotations

import enum
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Self, TypeVar

from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._message import Command, Message, Reply, construct, require_length
from servobus.protocols.lk.model import (
    DEFAULT_MODEL,
    LkModel,
    MotorType,
    Revision,
    check_encoder_bits,
    encoder_max_count,
    iq_field,
)

__all__ = [
    "BOTH",
    "FRAME_LENGTH",
    "V2_35_ONLY",
    "V2_36_ONLY",
    "IqSlot",
    "LkCommand",
    "LkReply",
    "build",
    "check_command",
    "check_encoder_count",
    "enum_byte",
    "expect",
    "payload",
]

FRAME_LENGTH = 8
BOTH: frozenset[Revision] = frozenset(Revision)
V2_36_ONLY: frozenset[Revision] = frozenset({Revision.V2_36})
V2_35_ONLY: frozenset[Revision] = frozenset({Revision.V2_35})

M = TypeVar("M", bound=Message)
E = TypeVar("E", bound=enum.IntEnum)


class LkCommand(Command):
    """A host -> motor LK message.

    ``REVISIONS`` lists the revisions whose manual has this request layout (spec §3, §9 D12); a class
    per layout, so a layout that differs between revisions is two classes. ``MOTOR_TYPES`` maps a
    revision to the motor types the manual allows the command on, where it restricts them ([001]:
    0xA0 MS only, 0xA1 MF/MH/MG only); :func:`servobus.protocols.lk.codec.check_available` enforces both.
    """

    __slots__ = ()
    REVISIONS: ClassVar[frozenset[Revision]] = BOTH
    MOTOR_TYPES: ClassVar[Mapping[Revision, frozenset[MotorType]]] = {}

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        """Decode a request payload (device side). ``model`` supplies motor type and encoder width.

        Raises:
            ProtocolError: wrong length, wrong command byte, or a value the layout does not allow.
        """
        raise NotImplementedError(cls.__name__)


class LkReply(Reply):
    """A motor -> host LK message; ``REVISIONS`` as for :class:`LkCommand`."""

    __slots__ = ()
    REVISIONS: ClassVar[frozenset[Revision]] = BOTH

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        """Decode a reply payload. ``model`` supplies motor type and encoder width.

        Raises:
            ProtocolError: wrong length, wrong command byte, or a value the layout does not allow.
        """
        raise NotImplementedError(cls.__name__)


def payload(code: int, *chunks: tuple[int, bytes]) -> bytes:
    """An 8-byte payload: ``code`` at DATA[0], each (offset, bytes) chunk in place, 0x00 elsewhere."""
    buf = bytearray(FRAME_LENGTH)
    buf[0] = code
    for offset, chunk in chunks:
        buf[offset : offset + len(chunk)] = chunk
    return bytes(buf)


def expect(data: bytes, codes: int | Collection[int], what: str) -> int:
    """Check an 8-byte payload whose DATA[0] is ``codes`` (or one of them); return DATA[0].

    Raises:
        ProtocolError: the length is not 8 or DATA[0] is not an expected command byte.
    """
    require_length(data, FRAME_LENGTH, what=what)
    allowed = (codes,) if isinstance(codes, int) else codes
    if data[0] not in allowed:
        expected = " or ".join(f"0x{c:02X}" for c in sorted(allowed))
        raise ProtocolError(f"{what}: command byte is not {expected}", raw=data, command=data[0])
    return data[0]


def build(cls: type[M], data: bytes, **fields: Any) -> M:
    """``cls(**fields)`` from decoded bytes; a refused value is a ProtocolError (see ``construct``)."""
    return construct(cls, data, fields, command=data[0] if data else None)


def enum_byte(enum_cls: type[E], data: bytes, offset: int, *, what: str) -> E:
    """DATA[offset] as a member of ``enum_cls``.

    Raises:
        ProtocolError: the byte is not a value the manual lists.
    """
    try:
        return enum_cls(data[offset])
    except ValueError:
        raise ProtocolError(
            f"{what}: DATA[{offset}]=0x{data[offset]:02X} is not a {enum_cls.__name__}",
            raw=data,
            command=data[0],
        ) from None


def check_command(value: int, codes: Collection[int]) -> None:
    """Raise ValueError unless ``value`` is one of the command bytes ``codes`` (a shared reply layout)."""
    if isinstance(value, bool) or not isinstance(value, int) or value not in codes:
        shown = f"0x{value:02X}" if isinstance(value, int) and 0 <= value <= 0xFF else repr(value)
        raise ValueError(f"command={shown} is not one of {', '.join(f'0x{c:02X}' for c in sorted(codes))}")


def check_encoder_count(name: str, value: int, encoder_bits: int) -> None:
    """Raise ValueError unless ``value`` is a count that fits ``encoder_bits`` (uint16 on the wire)."""
    check_encoder_bits(encoder_bits)
    IntField(name, size=2, signed=False, hi=encoder_max_count(encoder_bits)).check(value)


@dataclass(frozen=True, slots=True)
class IqSlot:
    """One int16 torque field and how it is given per motor type (spec §8.2).

    MF and MG give it in amperes (``amps_name``); the motor types in ``counts_names`` give it as raw
    counts under a name of their own (MH ``iq_counts``: scale unknown; MS ``power_counts``: power,
    unitless); any other motor type is refused. Exactly the one field that belongs to the motor
    type is set, the others are None, so each value has one representation. A slot with
    ``in_amps=False`` is never a current (the 0xA0 reply's power, spec §4.9): every motor type
    gives it as raw counts.
    """

    amps_name: str
    counts_names: Mapping[MotorType, str]
    max_counts: int
    min_counts: int | None = None  # default: -max_counts
    in_amps: bool = True

    @property
    def limits(self) -> tuple[int, int]:
        """The int16 count range."""
        return (-self.max_counts if self.min_counts is None else self.min_counts, self.max_counts)

    def field(self, motor_type: MotorType, limits: tuple[int, int] | None = None) -> ScaledField | None:
        """The field in amperes for ``motor_type`` within ``limits`` (counts; default: the slot's), or
        None if it has no ampere scale."""
        if not self.in_amps:
            return None
        return iq_field(self.amps_name, motor_type, *(limits if limits is not None else self.limits))

    def to_counts(self, motor_type: MotorType, values: Mapping[str, float | int | None]) -> int:
        """Validate ``values`` (field name -> value) for ``motor_type`` and return the int16 count.

        Raises:
            ValueError: the wrong field is set for the motor type, or the value is out of range.
        """
        amps = self.field(motor_type)
        wanted = self.amps_name if amps is not None else self.counts_names.get(motor_type)
        if wanted is None:
            raise ValueError(
                f"{self.amps_name}: motor_type={motor_type.name} does not carry this value "
                f"(allowed: {', '.join(t.name for t in self._allowed())})"
            )
        for name, value in values.items():
            if name != wanted and value is not None:
                raise ValueError(
                    f"{name}={value!r} given for motor_type={motor_type.name}, which uses {wanted}"
                )
        value = values.get(wanted)
        if value is None:
            raise ValueError(f"{wanted} is required for motor_type={motor_type.name}")
        if amps is not None:
            return amps.to_code(value)
        counts = IntField(wanted, size=2, signed=True, lo=self.limits[0], hi=self.limits[1])
        counts.check(value)  # type: ignore[arg-type]
        return int(value)

    def from_counts(self, motor_type: MotorType, counts: int) -> dict[str, float | int | None]:
        """The field values (all names, None where not used) that ``counts`` means for ``motor_type``."""
        values: dict[str, float | int | None] = dict.fromkeys((self.amps_name, *self.counts_names.values()))
        amps = self.field(motor_type)
        if amps is not None:
            values[self.amps_name] = amps.from_code(counts)
        elif motor_type in self.counts_names:
            values[self.counts_names[motor_type]] = counts
        return values

    def _allowed(self) -> list[MotorType]:
        return [t for t in MotorType if self.field(t) is not None or t in self.counts_names]
