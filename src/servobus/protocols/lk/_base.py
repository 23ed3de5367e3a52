"""What every LK message shares: declared 8-byte layouts, revision availability, model-dependent fields.

Every LK frame is a classic CAN frame with DLC 8 and DATA[0] = command byte (spec §0, §1.1), except
the 0x280 multi-motor frame, which has no command byte (spec §5). A message class states its layout
once (``CODE``, ``FIELDS`` at offsets, ``CONSTANTS``; :mod:`servobus.protocols._layout`), and
:class:`LkMessage` derives checks, ``encode`` and ``decode(data, *, model=...)`` from it. Decoders are
strict about length, command byte and constants and lenient about NULL bytes: the manuals tell the
master to send 0x00 but spec §0 says a decoder should not rely on them, so NULL bytes are ignored on
decode (requests and replies alike) and written as 0x00 on encode.

What a plain field cannot state, because it depends on the motor (:class:`LkModel`), is a field kind
here that sees the whole message (or, decoding, the model): :class:`IqField` (the int16 whose name
and scale depend on the motor type, spec §8.2), :class:`EncoderCountField` (counts within the encoder
width), :class:`CommandField` (DATA[0] of a reply layout several commands share: the command bytes
are those of the commands that declare it as their reply). ``MODEL`` names the message attributes a
decoder takes from the model (``motor_type``, ``encoder_bits``).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Generic, Self

from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._layout import FieldCodec, Layout, LayoutMismatch
from servobus.protocols._message import Command, R, Reply, require_length
from servobus.protocols.lk.model import (
    DEFAULT_MODEL,
    LkModel,
    MotorType,
    Revision,
    check_encoder_bits,
    check_member,
    encoder_max_count,
    iq_field,
)

__all__ = [
    "BOTH",
    "FRAME_LENGTH",
    "V2_35_ONLY",
    "V2_36_ONLY",
    "CommandField",
    "EncoderCountField",
    "FlagByteField",
    "IqField",
    "IqSlot",
    "LkCommand",
    "LkMessage",
    "LkReply",
    "MemberField",
    "MessageField",
    "TupleField",
    "check_command",
    "check_encoder_count",
]

FRAME_LENGTH = 8
BOTH: frozenset[Revision] = frozenset(Revision)
V2_36_ONLY: frozenset[Revision] = frozenset({Revision.V2_36})
V2_35_ONLY: frozenset[Revision] = frozenset({Revision.V2_35})

# The command bytes each reply class answers, filled as the command classes are made (see LkCommand).
_ANSWERS: dict[type, set[int]] = {}
_ALL_FIELDS: dict[type, tuple[tuple[int, Any], ...]] = {}
# How the model attributes a message may carry are checked.
_MODEL_CHECKS: Mapping[str, Callable[[Any], None]] = {
    "motor_type": lambda value: check_member("motor_type", value, MotorType),
    "encoder_bits": check_encoder_bits,
}


class MessageField:
    """A field whose check, bytes or attribute names depend on the rest of the message or the model.

    ``names`` are the attributes it fills (one wire value may be one of several attributes, by motor
    type). :class:`LkMessage` calls :meth:`check_message` when a message is made, :meth:`encode_message`
    to encode it and :meth:`decode_values` to decode (``owner`` is the class being decoded).
    """

    __slots__ = ()
    size: int

    @property
    def names(self) -> tuple[str, ...]:
        raise NotImplementedError

    def check_message(self, message: Any) -> None:
        raise NotImplementedError

    def encode_message(self, message: Any) -> bytes:
        raise NotImplementedError

    def decode_values(self, owner: type, data: bytes, offset: int, model: LkModel) -> dict[str, Any]:
        raise NotImplementedError


class LkMessage(Layout):
    """An LK payload declared as a layout; ``REVISIONS`` lists the revisions whose manual has it.

    A class per layout (spec §3, §9 D12): a layout that differs between revisions is two classes.
    """

    __slots__ = ()
    REVISIONS: ClassVar[frozenset[Revision]] = BOTH
    MODEL: ClassVar[tuple[str, ...]] = ()
    #: The fields that depend on the message or the model (:class:`MessageField`), by offset as FIELDS.
    MODEL_FIELDS: ClassVar[tuple[tuple[int, MessageField], ...]] = ()
    #: False for the 0x280 frame, whose DATA[0] is not a command byte (errors then name none).
    HAS_CODE: ClassVar[bool] = True

    @classmethod
    def all_fields(cls) -> tuple[tuple[int, FieldCodec | MessageField], ...]:
        """FIELDS and MODEL_FIELDS together, by offset: the whole layout."""
        found = _ALL_FIELDS.get(cls)
        if found is None:
            found = _ALL_FIELDS[cls] = tuple(sorted((*cls.FIELDS, *cls.MODEL_FIELDS), key=lambda f: f[0]))
        return found

    def __post_init__(self) -> None:
        for name in self.MODEL:
            _MODEL_CHECKS[name](getattr(self, name))
        for _, spec in self.all_fields():
            if isinstance(spec, MessageField):
                spec.check_message(self)
                continue
            value = getattr(self, spec.name)
            spec.check(value)
            normalise = getattr(spec, "normalise", None)
            if normalise is not None:
                object.__setattr__(self, spec.name, normalise(value))

    def encode(self) -> bytes:
        buf = bytearray(FRAME_LENGTH)
        if self.CODE is not None:
            buf[0] = self.CODE
        for offset, byte in self.CONSTANTS:
            buf[offset] = byte
        for offset, spec in self.all_fields():
            if isinstance(spec, MessageField):
                buf[offset : offset + spec.size] = spec.encode_message(self)
            else:
                buf[offset : offset + spec.size] = spec.encode(getattr(self, spec.name))
        return bytes(buf)

    @classmethod
    def decode(cls, data: bytes, *, model: LkModel = DEFAULT_MODEL) -> Self:
        """Decode a payload; ``model`` supplies motor type and encoder width.

        Raises:
            ProtocolError: wrong length, wrong command byte or constant, or a value the layout does not
                allow.
        """
        code = data[0] if data and cls.HAS_CODE else None
        require_length(data, FRAME_LENGTH, what=cls.__name__, command=code)
        if cls.CODE is not None and data[0] != cls.CODE:
            raise LayoutMismatch(
                f"{cls.__name__}: command byte is not 0x{cls.CODE:02X}", raw=data, command=code
            )
        for offset, byte in cls.CONSTANTS:
            if data[offset] != byte:
                raise LayoutMismatch(
                    f"{cls.__name__}: DATA[{offset}] is not 0x{byte:02X}", raw=data, command=code
                )
        cls.check_bytes(data, model)
        values: dict[str, Any] = {name: getattr(model, name) for name in cls.MODEL}
        try:
            for offset, spec in cls.all_fields():
                if isinstance(spec, MessageField):
                    values.update(spec.decode_values(cls, data, offset, model))
                else:
                    values[spec.name] = spec.decode(data, offset)
        except ValueError as exc:
            raise ProtocolError(f"{cls.__name__}: {exc}", raw=data, command=code) from None
        try:
            return cls(**values)
        except ValueError as exc:
            raise ProtocolError(f"{cls.__name__}: {exc}", raw=data, command=code) from None

    @classmethod
    def check_bytes(cls, data: bytes, model: LkModel) -> None:
        """A decode-time check the layout cannot state (none by default; status 2's stated iq range)."""


class LkReply(LkMessage, Reply):
    """A motor -> host LK message."""

    __slots__ = ()

    @classmethod
    def answers(cls) -> frozenset[int]:
        """The command bytes of the commands this reply layout answers (from their declarations)."""
        return frozenset(_ANSWERS.get(cls, ()))


class LkCommand(LkMessage, Command[R], Generic[R]):
    """A host -> motor LK message, generic in its reply: ``class ReadStatus2(LkCommand[Status2Reply])``.

    Besides what :class:`~servobus.protocols._message.Command` declares (READ, SLOW, ECHO, ...),
    ``MOTOR_TYPES`` maps a revision to the motor types the manual allows the command on, where it
    restricts them ([001]: 0xA0 MS only, 0xA1 MF/MH/MG only);
    :func:`servobus.protocols.lk.codec.check_available` enforces it and ``REVISIONS``.
    ``TIMEOUT_S`` overrides the bound codec's timeout where even ``SLOW`` is too short (0x18).
    ``REPLY_ALIASES`` maps a revision to another DATA[0] its reply may carry (V2.35 0x9B: 0x9A, A4).
    ``INFERRED`` says why the layout is the spec's inference where no manual prints it.
    """

    __slots__ = ()
    MOTOR_TYPES: ClassVar[Mapping[Revision, frozenset[MotorType]]] = {}
    TIMEOUT_S: ClassVar[float | None] = None
    REPLY_ALIASES: ClassVar[Mapping[Revision, int]] = {}
    INFERRED: ClassVar[str | None] = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.CODE is not None and "CODE" in cls.__dict__:
            for reply in cls.reply_types():
                _ANSWERS.setdefault(reply, set()).add(cls.CODE)


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
class MemberField:
    """A uint8 naming a member of ``enum``: only members are accepted (a bare int is not), and a byte
    the manual does not list does not decode."""

    name: str
    members: type[enum.IntEnum]
    size: int = 1

    def check(self, value: Any) -> None:
        check_member(self.name, value, self.members)

    def encode(self, value: Any) -> bytes:
        return int(value).to_bytes(self.size, "little")

    def decode(self, data: bytes, offset: int = 0) -> enum.IntEnum:
        try:
            return self.members(data[offset])
        except ValueError:
            raise ValueError(
                f"DATA[{offset}]=0x{data[offset]:02X} is not a {self.members.__name__}"
            ) from None


@dataclass(frozen=True, slots=True)
class FlagByteField:
    """A uint8 of flags (an IntFlag that keeps undefined bits); the message holds the flag type."""

    name: str
    flags: type[enum.IntFlag]
    size: int = 1

    def check(self, value: Any) -> None:
        check_member(self.name, value, self.flags)
        IntField(self.name, self.size).check(int(value))

    def encode(self, value: Any) -> bytes:
        return int(value).to_bytes(self.size, "little")

    def decode(self, data: bytes, offset: int = 0) -> enum.IntFlag:
        return self.flags(data[offset])


def _check_tuple(name: str, value: Any, count: int) -> None:
    if value is not None and (not isinstance(value, tuple) or len(value) != count):
        raise ValueError(f"{name}={value!r} is not a tuple of {count} values")


@dataclass(frozen=True, slots=True)
class TupleField:
    """``len(labels)`` values of one field kind side by side (V2.35 phase currents iA, iB, iC)."""

    item: ScaledField
    label: str
    labels: tuple[str, ...]

    @property
    def name(self) -> str:
        return self.item.name

    @property
    def size(self) -> int:
        return self.item.size * len(self.labels)

    def check(self, value: Any) -> None:
        _check_tuple(self.name, value, len(self.labels))
        for label, item in zip(self.labels, value, strict=True):
            try:
                self.item.check(item)
            except ValueError as exc:
                raise ValueError(f"{self.label} {label}: {exc}") from None

    def encode(self, value: Any) -> bytes:
        return b"".join(self.item.encode(v) for v in value)

    def decode(self, data: bytes, offset: int = 0) -> tuple[float, ...]:
        step = self.item.size
        return tuple(self.item.decode(data, offset + i * step) for i in range(len(self.labels)))


@dataclass(frozen=True, slots=True)
class CommandField(MessageField):
    """DATA[0] of a reply layout several commands share, held as ``command``: one of the command bytes
    whose commands declare this reply (:meth:`LkReply.answers`)."""

    size: int = 1

    @property
    def names(self) -> tuple[str, ...]:
        return ("command",)

    def check_message(self, message: Any) -> None:
        check_command(message.command, type(message).answers())

    def encode_message(self, message: Any) -> bytes:
        return bytes([message.command])

    def decode_values(self, owner: type, data: bytes, offset: int, model: LkModel) -> dict[str, Any]:
        codes = owner.answers()  # type: ignore[attr-defined]
        if data[offset] not in codes:
            expected = " or ".join(f"0x{c:02X}" for c in sorted(codes))
            raise ValueError(f"command byte is not {expected}")
        return {"command": data[offset]}


@dataclass(frozen=True, slots=True)
class EncoderCountField(MessageField):
    """A uint16 encoder count, within the message's ``encoder_bits`` (a wrong width shows at once)."""

    name: str
    size: int = 2

    @property
    def names(self) -> tuple[str, ...]:
        return (self.name,)

    def check_message(self, message: Any) -> None:
        check_encoder_count(self.name, getattr(message, self.name), message.encoder_bits)

    def encode_message(self, message: Any) -> bytes:
        return int(getattr(message, self.name)).to_bytes(2, "little")

    def decode_values(self, owner: type, data: bytes, offset: int, model: LkModel) -> dict[str, Any]:
        return {self.name: int.from_bytes(data[offset : offset + 2], "little")}


@dataclass(frozen=True, slots=True)
class IqSlot:
    """One int16 torque field and how it is given per motor type (spec §8.2).

    MF and MG give it in amperes (``amps_name``); the motor types in ``counts_names`` give it as raw
    counts under a name of their own (MH ``iq_counts``: scale unknown; MS ``power_counts``: power,
    unitless); any other motor type is refused. Exactly the one field that belongs to the motor
    type is set, the others are None, so each value has one representation. A slot with
    ``in_amps=False`` is never a current (the 0xA0 reply's power, spec §4.9): every motor type
    gives it as raw counts. ``note`` prefixes its errors (what the slot is, where it is unexpected).
    """

    amps_name: str
    counts_names: Mapping[MotorType, str]
    max_counts: int
    min_counts: int | None = None  # default: -max_counts
    in_amps: bool = True
    note: str = ""

    @property
    def limits(self) -> tuple[int, int]:
        """The int16 count range."""
        return (-self.max_counts if self.min_counts is None else self.min_counts, self.max_counts)

    @property
    def names(self) -> tuple[str, ...]:
        """Every attribute name the slot may fill."""
        return tuple(dict.fromkeys((self.amps_name, *self.counts_names.values())))

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
        try:
            return self._to_counts(motor_type, values)
        except ValueError as exc:
            if self.note:
                raise ValueError(f"{self.note}: {exc}") from None
            raise

    def _to_counts(self, motor_type: MotorType, values: Mapping[str, float | int | None]) -> int:
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
        values: dict[str, float | int | None] = dict.fromkeys(self.names)
        amps = self.field(motor_type)
        if amps is not None:
            values[self.amps_name] = amps.from_code(counts)
        elif motor_type in self.counts_names:
            values[self.counts_names[motor_type]] = counts
        return values

    def _allowed(self) -> list[MotorType]:
        return [t for t in MotorType if self.field(t) is not None or t in self.counts_names]


@dataclass(frozen=True, slots=True)
class IqField(MessageField):
    """The int16 torque value(s) of an :class:`IqSlot` at 2-byte steps, read per the message's
    ``motor_type``: one value, or a tuple per ``labels`` (phases A..C, motors 1..4).

    ``by_command`` gives the slot of the reply to particular command bytes (0xA0's power); ``zero``,
    if given, refuses a value that encodes to 0 counts and says why ("iqControl 0, which ...").
    """

    slot: IqSlot
    label: str = ""
    labels: tuple[str, ...] = ()
    by_command: Mapping[int, IqSlot] = field(default_factory=dict)
    zero: str = ""

    @property
    def size(self) -> int:  # type: ignore[override]
        return 2 * max(1, len(self.labels))

    @property
    def names(self) -> tuple[str, ...]:
        return self.slot.names

    def slot_of(self, command: int | None) -> IqSlot:
        """The slot of a message with DATA[0] ``command``."""
        return self.by_command.get(command, self.slot) if command is not None else self.slot

    def counts(self, message: Any) -> list[int]:
        """The int16 count(s) a valid message sends (ValueError naming field, item and limits)."""
        slot = self.slot_of(getattr(message, "command", message.CODE))
        names = self.names
        if not self.labels:
            values = {n: getattr(message, n) for n in names}
            count = slot.to_counts(message.motor_type, values)
            if count == 0 and self.zero:
                name, given = next((n, v) for n, v in values.items() if v is not None)
                raise ValueError(f"{name}={given!r} encodes to {self.zero}")
            return [count]
        for name in names:
            _check_tuple(name, getattr(message, name), len(self.labels))
        counts = []
        for i, label in enumerate(self.labels):
            values = {n: (getattr(message, n) or (None,) * len(self.labels))[i] for n in names}
            try:
                counts.append(slot.to_counts(message.motor_type, values))
            except ValueError as exc:
                raise ValueError(f"{self.label} {label}: {exc}") from None
        return counts

    def check_message(self, message: Any) -> None:
        self.counts(message)

    def encode_message(self, message: Any) -> bytes:
        return b"".join(c.to_bytes(2, "little", signed=True) for c in self.counts(message))

    def decode_values(self, owner: type, data: bytes, offset: int, model: LkModel) -> dict[str, Any]:
        code = data[0] if getattr(owner, "HAS_CODE", True) else None
        slot = self.slot_of(code)
        if not self.labels:
            return slot.from_counts(model.motor_type, _i16(data, offset))
        items = [
            slot.from_counts(model.motor_type, _i16(data, offset + 2 * i)) for i in range(len(self.labels))
        ]
        tuples = {name: tuple(item[name] for item in items) for name in self.names}
        return {name: None if None in value else value for name, value in tuples.items()}


def _i16(data: bytes, offset: int) -> int:
    return int.from_bytes(data[offset : offset + 2], "little", signed=True)
