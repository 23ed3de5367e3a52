"""Bit-packed payloads declared once: fields at bit offsets and widths, scales from the motor's model.

The byte-aligned declarations (:class:`~servobus.protocols.authoring.Layout`) assume a command byte
in DATA[0] and whole-byte fields. MIT-style frames are neither: a set-point packs position, speed,
gains and torque into 16/12/12/12/12 bits, a feedback frame shares a byte between an error code and
the motor id, a special command is the constant ``FF x 7`` followed by a code, and the scales (P_MAX,
V_MAX, T_MAX) depend on the motor model. A :class:`BitLayout` class states such a payload once::

    @dataclass(frozen=True, slots=True, kw_only=True)
    class MitControl(BitLayout, Command[Feedback]):
        SIZE = 8
        FIELDS = (
            Linear("position_rad", (0, 16), lambda m: (-m.p_max, m.p_max)),
            Linear("velocity_rad_s", (16, 12), lambda m: (-m.v_max, m.v_max)),
            Linear("kp", (28, 12), (0.0, 500.0)),
            Linear("kd", (40, 12), (0.0, 5.0)),
            Linear("torque_nm", (52, 12), lambda m: (-m.t_max, m.t_max)),
        )
        position_rad: float
        ...
        model: DmModel = DM4310

and gets, from that alone: every field checked on construction (``ValueError`` naming the field, its
limits and, where the limits come from the model, the model: nothing out of range is ever built, so
what exists encodes), ``encode()``, ``decode(data, *, model=...)`` (``ProtocolError`` for a wrong
length, a constant that differs, or a value outside its field's range) and :meth:`BitLayout.matches`
(whether bytes are this payload: its size and constants), which a codec uses to tell frames apart
that have no command byte (:func:`claimant`).

**Bits** are numbered from the most significant bit of the payload's first byte (bit 0) on: a field
at ``(offset, width)`` holds bits ``offset .. offset + width - 1``, most significant first, the
big-endian order of MIT frames. A field split over the payload gives its pieces most significant
first, ``((48, 16), (8, 16))``; :func:`le` gives the pieces of a little-endian whole-byte field.

**Scales** are the C core's (:class:`~servobus.core.FieldScale`): ``code = round((x - origin) *
codes / span)``, ties away from zero, and ``x = code * span / codes + origin``. A field's scale is
a FieldScale or a function of the message's model (its ``model`` attribute, or the ``model`` given to
``decode``) returning one. A field is signed (two's complement) when its scale's ``lo`` lies below
its ``origin``. The kinds of field: :func:`Linear` (the MIT map of [lo, hi] onto every code),
:func:`OffsetBinary` (±full scale, zero at the middle code), :func:`Signed` (two's complement, so
many codes per unit), :func:`Code` (an integer), :func:`Choice` (an IntEnum), :func:`Flag` (0/1 as a
bool), and :class:`Const` (bits that must hold a value: a payload's identity).

A built-in family may keep a faster packer for a layout (hollow's C-core packers); the declaration
stays the reference it is tested against (``tests/protocols/test_bits.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import MISSING, dataclass
from enum import IntEnum
from functools import lru_cache
from typing import Any, ClassVar, Self, TypeAlias

from servobus.core import FieldScale
from servobus.errors import ProtocolError
from servobus.protocols._fields import check_flag, to_enum
from servobus.protocols._message import Message, construct

__all__ = [
    "BitField",
    "BitLayout",
    "Bits",
    "Choice",
    "Code",
    "Const",
    "Flag",
    "Linear",
    "OffsetBinary",
    "Scale",
    "Signed",
    "claimant",
    "field_names",
    "le",
]

Bits: TypeAlias = tuple[int, int] | tuple[tuple[int, int], ...]
"""Where a field's bits sit: ``(offset, width)``, or its pieces ``((offset, width), ...)``, most
significant first."""
Scale: TypeAlias = FieldScale | Callable[[Any], FieldScale]
"""A field's scale, or a function of the message's model returning it."""
Limits: TypeAlias = tuple[float, float] | Callable[[Any], tuple[float, float]]
Pieces: TypeAlias = tuple[tuple[int, int], ...]


def le(byte: int, size: int) -> Pieces:
    """The pieces of a little-endian field of ``size`` whole bytes from byte ``byte`` on (most
    significant byte, the last, first)."""
    return tuple((8 * (byte + i), 8) for i in reversed(range(size)))


def _pieces(bits: Bits) -> Pieces:
    if len(bits) == 2 and all(isinstance(b, int) for b in bits):
        return ((bits[0], bits[1]),)  # type: ignore[return-value]
    return tuple((int(o), int(w)) for o, w in bits)  # type: ignore[misc]


def _model_name(model: Any) -> str:
    return str(getattr(model, "name", model))


@dataclass(frozen=True, slots=True)
class BitField:
    """One field of a :class:`BitLayout`: its attribute ``name``, its ``pieces`` (bit offset and
    width, most significant first), its ``scale`` and the ``kind`` of value it holds (``float``,
    ``int``, ``bool`` or an IntEnum class). ``label`` names it in decoding errors (the manual's name).
    Build one with :func:`Linear`, :func:`OffsetBinary`, :func:`Signed`, :func:`Code`,
    :func:`Choice` or :func:`Flag`."""

    name: str
    pieces: Pieces
    scale: Scale
    kind: type = float
    label: str = ""

    def __post_init__(self) -> None:
        if isinstance(self.scale, FieldScale):  # (a model's scale is checked when first made)
            _fits(self.scale, self.width, "a bit field")

    @property
    def width(self) -> int:
        """The field's width in bits."""
        return sum(w for _, w in self.pieces)

    @property
    def model_dependent(self) -> bool:
        """Whether the scale is a function of the model."""
        return not isinstance(self.scale, FieldScale)

    def scale_for(self, model: Any) -> FieldScale:
        """The field's scale for ``model``."""
        return self.scale if isinstance(self.scale, FieldScale) else self.scale(model)

    def check(self, value: Any, model: Any) -> Any:
        """``value`` as stored (an enum member, a bool), or ValueError naming the field and its
        limits (and the model, where they come from it)."""
        kind, name = self.kind, self.name
        if kind is bool:
            return check_flag(name, value)
        if isinstance(kind, type) and issubclass(kind, IntEnum):
            return to_enum(name, value, kind)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"{name}={value!r} is not {'an integer' if kind is int else 'a number'}")
        if kind is int and not isinstance(value, int):
            raise ValueError(f"{name}={value!r} is not an integer")
        scale = self.scale_for(model)
        if not scale.lo <= value <= scale.hi:
            where = f" for model {_model_name(model)}" if self.model_dependent else ""
            raise ValueError(f"{name}={value!r} is outside [{scale.lo!r}, {scale.hi!r}]{where}")
        return value

    def code(self, value: Any, scale: FieldScale) -> int:
        """The code of a checked ``value``, as the C core computes it (clamped to the field's codes):
        ``round((x - origin) * codes / span)``, ties away from zero; an integer one code per unit
        exactly, however wide."""
        if self.kind is not float and _whole_units(scale):
            code = int(value) - int(scale.origin)
        else:
            y = abs((float(value) - scale.origin) * scale.codes / scale.span)
            whole = math.floor(y)
            code = int(math.copysign(whole + (y - whole >= 0.5), (float(value) - scale.origin)))
        lo, hi = self.code_range(scale)
        return lo if code <= lo else hi if code >= hi else code

    def code_range(self, scale: FieldScale) -> tuple[int, int]:
        """The lowest and highest code of the field (signed when the scale's lo is below its origin)."""
        width = self.width
        if scale.lo < scale.origin:
            return -(1 << (width - 1)), (1 << (width - 1)) - 1
        return 0, (1 << width) - 1

    def value(self, code: int, scale: FieldScale, data: bytes) -> Any:
        """The constructor's argument for a received ``code`` (ProtocolError: an unknown enum code)."""
        kind = self.kind
        if kind is float:
            x = code * scale.span / scale.codes + scale.origin
            # (a code within the field's range is data; a last-ulp excess is the arithmetic's)
            lo, hi = self.code_range(scale)
            return scale.lo if x < scale.lo and code == lo else scale.hi if x > scale.hi and code == hi else x
        if _whole_units(scale):
            code += int(scale.origin)  # (exact, however wide)
        else:  # (an integer with a step)
            code = round(code * scale.span / scale.codes + scale.origin)
        if isinstance(kind, type) and issubclass(kind, IntEnum):
            try:
                return kind(code)
            except ValueError:
                raise ProtocolError(f"{self.label or self.name}: unknown value {code}", raw=data) from None
        return code  # (int, and bool's 0/1: the constructor's check takes them)


def _limits(limits: Limits) -> Callable[[Any], tuple[float, float]]:
    return limits if callable(limits) else (lambda model: limits)


def Linear(name: str, bits: Bits, limits: Limits) -> BitField:
    """A real number in ``limits`` (``(lo, hi)``, or a function of the model) mapped onto every code
    of the field, lo to 0 and hi to the last: the MIT map (``FieldScale.linear``)."""
    pieces = _pieces(bits)
    width = sum(w for _, w in pieces)
    if callable(limits):
        get = _limits(limits)
        return BitField(name, pieces, _cached(lambda m: FieldScale.linear(name, *get(m), width), width))
    return BitField(name, pieces, FieldScale.linear(name, limits[0], limits[1], width))


def OffsetBinary(name: str, bits: Bits, full_scale: float | Callable[[Any], float]) -> BitField:
    """A real number within ±``full_scale`` (or a function of the model): the middle code is zero
    and ``2**width`` codes span ±full scale, +full scale saturating on the last code (hollow's
    classic frames, ``FieldScale.offset_binary``)."""
    pieces = _pieces(bits)
    width = sum(w for _, w in pieces)
    if callable(full_scale):
        get = full_scale
        return BitField(name, pieces, _cached(lambda m: FieldScale.offset_binary(name, get(m), width), width))
    return BitField(name, pieces, FieldScale.offset_binary(name, full_scale, width))


def Signed(
    name: str, bits: Bits, per_unit: float | Callable[[Any], float] = 1.0, *, span: float = 1.0
) -> BitField:
    """A real number in two's complement: ``per_unit`` codes (or a function of the model) are
    ``span`` units, every code accepted (``FieldScale.twos_complement``)."""
    pieces = _pieces(bits)
    width = sum(w for _, w in pieces)
    if callable(per_unit):
        get = per_unit
        return BitField(
            name,
            pieces,
            _cached(lambda m: FieldScale.twos_complement(name, width, codes=get(m), span=span), width),
        )
    return BitField(name, pieces, FieldScale.twos_complement(name, width, codes=per_unit, span=span))


def Code(name: str, bits: Bits, lo: int | None = None, hi: int | None = None) -> BitField:
    """An integer within ``lo .. hi`` (default: every code of the field, unsigned; a negative ``lo``
    makes it two's complement)."""
    pieces = _pieces(bits)
    width = sum(w for _, w in pieces)
    lo = 0 if lo is None else lo
    hi = ((1 << (width - 1 if lo < 0 else width)) - 1) if hi is None else hi
    return BitField(name, pieces, FieldScale.integer(name, lo, hi), int)


def Choice(name: str, bits: Bits, enum: type[IntEnum], label: str = "") -> BitField:
    """An IntEnum member carried as its value; a code no member has does not decode (``label``, the
    manual's name for the field, names it in that error)."""
    pieces = _pieces(bits)
    values = [int(m) for m in enum]
    return BitField(name, pieces, FieldScale.integer(name, min(values), max(values)), enum, label)


def Flag(name: str, bits: Bits) -> BitField:
    """A bool carried as 0 or 1; any other code does not decode."""
    return BitField(name, _pieces(bits), FieldScale.integer(name, 0, 1), bool)


@dataclass(frozen=True, slots=True)
class Const:
    """Bits that always hold ``value``: what makes bytes this payload (``FF x 7`` of a special
    command, its code). Written by ``encode``; bytes where they differ are not this payload."""

    bits: Bits
    value: int

    def __post_init__(self) -> None:
        width = sum(w for _, w in self.pieces)
        if (
            isinstance(self.value, bool)
            or not isinstance(self.value, int)
            or not 0 <= self.value < 1 << width
        ):
            raise ValueError(f"Const value {self.value!r} does not fit its {width} bits")

    @property
    def pieces(self) -> Pieces:
        """The constant's pieces (bit offset and width, most significant first)."""
        return _pieces(self.bits)


def _whole_units(scale: FieldScale) -> bool:
    """One code per unit from a whole origin: an integer's codes are its values, shifted."""
    return scale.codes == scale.span and float(scale.origin).is_integer()


def _fits(scale: FieldScale, width: int, where: str) -> FieldScale:
    """``scale`` if its range maps within a ``width``-bit field (signed when its lo is below its
    origin), else ValueError: good values would be clamped silently (``FieldScale.check_fits``)."""
    scale.check_fits(-width if scale.lo < scale.origin else width, where)
    return scale


def _cached(make: Callable[[Any], FieldScale], width: int) -> Callable[[Any], FieldScale]:
    """``make`` once per model (models are hashable; a control loop never rebuilds a scale), each
    model's scale checked to fit the field when first made."""
    return lru_cache(maxsize=64)(lambda model: _fits(make(model), width, f"model {_model_name(model)}"))


# ---- the layout ----


def _place(pieces: Pieces, code: int, total: int) -> int:
    """``code``'s bits placed in a ``total``-bit big-endian word, pieces most significant first."""
    word, left = 0, sum(w for _, w in pieces)
    for offset, width in pieces:
        left -= width
        word |= ((code >> left) & ((1 << width) - 1)) << (total - offset - width)
    return word


def _take(pieces: Pieces, word: int, total: int) -> int:
    code = 0
    for offset, width in pieces:
        code = (code << width) | ((word >> (total - offset - width)) & ((1 << width) - 1))
    return code


class BitLayout(Message):
    """A payload of ``SIZE`` bytes whose ``FIELDS`` (:class:`BitField`, :class:`Const`) are at bit
    offsets; a ``model`` attribute, if the class has one, gives the scales that depend on it.

    Mix it into a frozen, slotted dataclass with one attribute per named field (and ``model``).
    ``WHAT`` names the payload in errors (default: the class name). Bits no field covers are 0.

    Raises (on class creation):
        TypeError: fields that overlap, leave the payload, or name no attribute.
    """

    __slots__ = ()
    SIZE: ClassVar[int]
    FIELDS: ClassVar[tuple[BitField | Const, ...]]
    WHAT: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "FIELDS" in cls.__dict__:
            _check_declaration(cls)

    def __post_init__(self) -> None:
        model = getattr(self, "model", None)
        for spec in self.FIELDS:
            if isinstance(spec, BitField):
                value = getattr(self, spec.name)
                checked = spec.check(value, model)
                if checked is not value:
                    object.__setattr__(self, spec.name, checked)

    def encode(self) -> bytes:
        """The payload: every field's code at its bits, constants written, other bits 0."""
        model = getattr(self, "model", None)
        total = 8 * self.SIZE
        word = 0
        for spec in self.FIELDS:
            if isinstance(spec, Const):
                word |= _place(spec.pieces, spec.value, total)
            else:
                word |= _place(spec.pieces, spec.code(getattr(self, spec.name), spec.scale_for(model)), total)
        return word.to_bytes(self.SIZE, "big")

    @classmethod
    def default_model(cls) -> Any:
        """The model a payload is decoded with when none is given: the ``model`` attribute's default."""
        found = getattr(cls, "__dataclass_fields__", {}).get("model")
        return None if found is None or found.default is MISSING else found.default

    @classmethod
    def matches(cls, data: bytes) -> bool:
        """Whether ``data`` is this payload's size with every constant in place (no field decoded)."""
        if len(data) != cls.SIZE:
            return False
        word, total = int.from_bytes(data, "big"), 8 * cls.SIZE
        return all(_take(c.pieces, word, total) == c.value for c in cls.FIELDS if isinstance(c, Const))

    @classmethod
    def decode(cls, data: bytes, *, model: Any = None) -> Self:
        """Decode ``SIZE`` bytes with ``model``'s scales (None: :meth:`default_model`).

        Raises:
            ProtocolError: a wrong length, a constant that differs, an unknown enum code, or a
                value the class refuses (outside its field's range), with the raw bytes.
        """
        what = cls.WHAT or cls.__name__
        if len(data) != cls.SIZE:
            raise ProtocolError(f"{what}: expected {cls.SIZE} data bytes, got {len(data)}", raw=data)
        if not cls.matches(data):
            raise ProtocolError(f"{what}: the bytes are not this payload (a constant differs)", raw=data)
        if model is None:
            model = cls.default_model()
        word, total = int.from_bytes(data, "big"), 8 * cls.SIZE
        values: dict[str, Any] = {}
        for spec in cls.FIELDS:
            if isinstance(spec, BitField):
                scale = spec.scale_for(model)
                code = _take(spec.pieces, word, total)
                lo, _ = spec.code_range(scale)
                if lo < 0 and code >= 1 << (spec.width - 1):
                    code -= 1 << spec.width
                values[spec.name] = spec.value(code, scale, bytes(data))
        if "model" in getattr(cls, "__dataclass_fields__", {}):
            values["model"] = model
        return construct(cls, bytes(data), values)


def _check_declaration(cls: type[BitLayout]) -> None:
    total = 8 * cls.SIZE
    used = 0
    names: set[str] = set()
    for spec in cls.FIELDS:
        for offset, width in spec.pieces:
            if width < 1 or offset < 0 or offset + width > total:
                raise TypeError(f"{cls.__name__}: bits ({offset}, {width}) leave the {cls.SIZE}-byte payload")
            mask = ((1 << width) - 1) << (total - offset - width)
            if used & mask:
                raise TypeError(f"{cls.__name__}: bits ({offset}, {width}) overlap another field's")
            used |= mask
        if isinstance(spec, BitField):
            names.add(spec.name)
    annotated = {n for klass in cls.__mro__ for n in getattr(klass, "__annotations__", {})}
    if missing := sorted(names - annotated):
        raise TypeError(f"{cls.__name__}: fields {missing} name no attribute of the class")
    ruled = [s.name for s in cls.FIELDS if isinstance(s, BitField) and s.model_dependent]
    if ruled and "model" not in annotated:
        raise TypeError(f"{cls.__name__}: fields {ruled} take their ranges from a model; it has no `model`")


def claimant(classes: Iterable[type[BitLayout]], data: bytes) -> type[BitLayout] | None:
    """The first of ``classes`` whose size and constants ``data`` has (:meth:`BitLayout.matches`):
    how a codec tells apart payloads without a command byte (put those with constants first)."""
    for cls in classes:
        if cls.matches(data):
            return cls
    return None


def field_names(cls: type[BitLayout]) -> Sequence[str]:
    """The named fields of ``cls``, in declaration order."""
    return [spec.name for spec in cls.FIELDS if isinstance(spec, BitField)]
