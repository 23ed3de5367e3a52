"""Hypothesis strategies for a family's messages, built from each class's declared field limits.

A message class that declares its payload (``FIELDS``: ``(offset, field)`` pairs, or bare fields)
gets a strategy drawing every declared field of a kind :func:`field_strategy` knows within the
field's own limits, on the field's resolution (a scaled value is a whole number of counts, so it
decodes to itself), and leaving every other dataclass field at its default. A class with a required
field that no such declaration covers (a motor model, a parameter chosen by name, a field kind the
rules do not know) has no derived strategy: the family passes one (``strategies={Cls: ...}``).
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping
from typing import Any, Literal

from hypothesis import assume
from hypothesis import strategies as st

from servobus.protocols import Family, Message
from servobus.protocols.authoring import (
    AsciiField,
    BitField,
    BitLayout,
    BoolField,
    Float32Field,
    IntField,
    ScaledField,
    StepField,
)

__all__ = ["Strategies", "field_strategy", "message_classes", "message_strategy", "strategies_of"]

#: message class -> the strategy drawing its instances (None: none, see :func:`strategies_of`)
Strategies = Mapping[type[Message], st.SearchStrategy[Any] | None]


def message_classes(family: Family[Any]) -> tuple[type[Message], ...]:
    """The family's command classes, then every reply class they declare, each once, in order."""
    out: dict[type[Message], None] = dict.fromkeys(family.commands)
    for cls in family.commands:
        out.update(dict.fromkeys(cls.reply_types()))
    return tuple(out)


def _floats(lo: float, hi: float, *, width: Literal[16, 32, 64] = 64) -> st.SearchStrategy[float]:
    return st.floats(min_value=lo, max_value=hi, allow_nan=False, allow_infinity=False, width=width)


def _scaled(spec: ScaledField) -> st.SearchStrategy[float]:
    """Whole numbers of counts within the limits: the value a decoder gives back unchanged."""
    lo, hi = spec.limits
    code_lo = math.ceil(lo * spec.counts_per_unit - 1e-9)
    code_hi = math.floor(hi * spec.counts_per_unit + 1e-9)
    values = st.integers(code_lo, code_hi).map(spec.from_code)
    return values.filter(lambda v: lo <= v <= hi)


def _flags(flags: type[enum.IntFlag]) -> st.SearchStrategy[enum.IntFlag]:
    members = [m for m in flags if m.value]
    if not members:
        return st.just(flags(0))
    return st.sets(st.sampled_from(members)).map(lambda chosen: flags(sum(int(m) for m in chosen)))


def _ascii(size: int) -> st.SearchStrategy[str]:
    printable = st.characters(min_codepoint=0x20, max_codepoint=0x7E)
    return st.text(printable, max_size=size).filter(lambda s: s == s.rstrip(" "))


def field_strategy(spec: Any, model: Any = None) -> st.SearchStrategy[Any] | None:
    """Values ``spec`` (one declared field) accepts and decodes to themselves; None: a field kind
    these rules do not know (the family gives the class's strategy itself).

    Known kinds: a bit field (:class:`~servobus.protocols.bits.BitField`: the values of its codes
    within its limits, with ``model``'s scale), :class:`ScaledField` (counts within its limits),
    :class:`IntField`, :class:`StepField`, :class:`BoolField`, :class:`Float32Field` (binary32
    values), :class:`AsciiField`, any field with an ``enum`` or ``members`` enum (its members) or
    ``flags`` (unions of its flags), and a ``SpecialZero``-like field with an ``inner`` field (the
    inner field's values).
    """
    if isinstance(spec, BitField):
        return _bits(spec, model)
    if isinstance(spec, ScaledField):
        return _scaled(spec)
    if isinstance(spec, StepField):
        return st.integers(0, spec.limits[1] // spec.step).map(lambda n: n * spec.step)
    if isinstance(spec, IntField):
        return st.integers(*spec.limits)
    if isinstance(spec, BoolField):
        return st.booleans()
    if isinstance(spec, Float32Field):
        return _floats(*spec.limits, width=32)
    if isinstance(spec, AsciiField):
        return _ascii(spec.size)
    for attribute in ("enum", "members"):
        kind = getattr(spec, attribute, None)
        if isinstance(kind, type) and issubclass(kind, enum.Enum):
            return st.sampled_from(list(kind))
    flags = getattr(spec, "flags", None)
    if isinstance(flags, type) and issubclass(flags, enum.IntFlag):
        return _flags(flags)
    inner = getattr(spec, "inner", None)
    if inner is not None:
        return field_strategy(inner)
    return None  # (limits alone do not say which values decode to themselves: a scaled bit field's don't)


def _bits(spec: BitField, model: Any) -> st.SearchStrategy[Any]:
    """The values of ``spec``'s codes that its limits hold: each encodes to its code and decodes
    back to itself (an enum's members, a flag's two values)."""
    if spec.kind is bool:
        return st.booleans()
    if isinstance(spec.kind, type) and issubclass(spec.kind, enum.Enum):
        return st.sampled_from(list(spec.kind))
    scale = spec.scale_for(model)
    lo, hi = spec.code_range(scale)
    low, high = max(lo, spec.code(scale.lo, scale)), min(hi, spec.code(scale.hi, scale))
    value = spec.value
    return (
        st.integers(low, high)
        .map(lambda code: value(code, scale, b""))
        .filter(lambda v: scale.lo <= v <= scale.hi)
    )


def _declared(cls: type[Message]) -> list[Any]:
    """The named field objects ``cls`` declares (``FIELDS`` of ``(offset, field)`` pairs or of bare
    fields); an entry without a name is a constant of the layout, not a value."""
    out = []
    for entry in getattr(cls, "FIELDS", ()):
        spec = entry[1] if isinstance(entry, tuple) and len(entry) == 2 else entry
        if isinstance(getattr(spec, "name", None), str):
            out.append(spec)
    return out


@st.composite
def _built(draw: st.DrawFn, cls: type[Message], fields: dict[str, st.SearchStrategy[Any]]) -> Message:
    values = {name: draw(strategy) for name, strategy in fields.items()}
    try:
        return cls(**values)
    except ValueError:  # values each field accepts that the class refuses together
        assume(False)
        raise  # (unreachable: assume(False) rejects the example)


def message_strategy(cls: type[Message]) -> st.SearchStrategy[Message] | None:
    """Instances of ``cls`` drawn from its declared field limits (a field they do not describe kept at
    its default); None where a required field is not described (undeclared, or a field kind
    :func:`field_strategy` does not know).

    Values a class refuses as a whole (two fields that exclude each other) are rejected, not failed.
    """
    if not dataclasses.is_dataclass(cls):
        return None
    declared = _declared(cls)
    by_name = {spec.name: spec for spec in declared}
    model = cls.default_model() if issubclass(cls, BitLayout) else None
    fields: dict[str, st.SearchStrategy[Any]] = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        spec = by_name.get(f.name)
        strategy = None if spec is None else field_strategy(spec, model)
        if strategy is not None:
            fields[f.name] = strategy
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            return None  # required, and no declaration says what it holds (or not in known terms)
    return _built(cls, fields)


def strategies_of(family: Family[Any], given: Strategies | None = None) -> dict[type[Message], Any]:
    """Every message class of ``family`` with its strategy: ``given`` first, else derived from the
    declarations; classes with neither are left out (see :func:`message_strategy`), and so are those
    ``given`` maps to None (a class whose instances cannot be drawn without context the contract
    does not have: name it in ``unbuilt_ok`` too)."""
    out: dict[type[Message], Any] = {}
    for cls in message_classes(family):
        strategy = given[cls] if given is not None and cls in given else message_strategy(cls)
        if strategy is not None:
            out[cls] = strategy
    return out
