"""The command declarations as plain tables, for code generated outside Python (the C core).

Every message class whose payload is declared (:class:`~servobus.protocols._layout.Layout`: ``CODE``,
``SIZE``, ``CONSTANTS``, ``FIELDS``) is described by :func:`layout_table` as numbers and names only:
each field's offset, width, signedness, the scale from a count to its unit, and its limits. The
simulator's C hot path ([simcore]) is generated from these tables, so the byte layouts stay said once,
in the classes. ::

    python -m servobus.protocols._tables myactuator > myactuator.json

Fields whose bytes are not a plain integer (text, IEEE floats, a family's own kinds such as LK's
motor-type-dependent currents, which live in ``MODEL_FIELDS`` and are not listed) are described by
kind and width only; a generator that needs them falls back to the Python model for that message.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from servobus.protocols._family import Family
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._layout import (
    AsciiField,
    BoolField,
    EnumField,
    FlagsField,
    Float32Field,
    Layout,
    OpenEnumField,
    StepField,
)
from servobus.protocols._message import Command
from servobus.protocols._special import SpecialZero

__all__ = ["FieldTable", "LayoutTable", "family_tables", "layout_table"]


@dataclass(frozen=True, slots=True)
class FieldTable:
    """One field: ``value = count * scale`` for numbers, within ``[lo, hi]`` (in the field's unit).

    ``kind`` is ``"int"`` (a number), ``"enum"``, ``"flags"``, ``"bool"``, ``"float32"`` or
    ``"ascii"``; ``special`` is the raw count with a meaning of its own (protocols/_special.py), or None.
    """

    name: str
    offset: int
    size: int
    kind: str
    signed: bool = False
    scale: float = 1.0
    lo: float | None = None
    hi: float | None = None
    special: int | None = None


@dataclass(frozen=True, slots=True)
class LayoutTable:
    """One message class: its command byte, payload size, fixed bytes, fields, and what it declares."""

    name: str
    code: int | None
    size: int
    constants: tuple[tuple[int, int], ...]
    fields: tuple[FieldTable, ...]
    command: bool
    replies: tuple[str, ...] = ()
    read: bool = False


def _field(offset: int, spec: Any) -> FieldTable:
    special = None
    if isinstance(spec, SpecialZero):
        special, spec = spec.raw, spec.inner
    if isinstance(spec, ScaledField):
        lo, hi = spec.limits
        return FieldTable(
            spec.name, offset, spec.size, "int", spec.signed, 1 / spec.counts_per_unit, lo, hi, special
        )
    if isinstance(spec, IntField):
        lo_i, hi_i = spec.limits
        return FieldTable(spec.name, offset, spec.size, "int", spec.signed, 1.0, lo_i, hi_i, special)
    if isinstance(spec, StepField):
        lo_s, hi_s = spec.limits
        return FieldTable(spec.name, offset, spec.size, "int", False, float(spec.step), lo_s, hi_s, special)
    kinds: dict[type, str] = {
        EnumField: "enum",
        OpenEnumField: "enum",
        FlagsField: "flags",
        BoolField: "bool",
        Float32Field: "float32",
        AsciiField: "ascii",
    }
    # A kind of its own (a family's: LK's motor-type-dependent current, a big-endian float) is
    # named by its class: a generator that does not know it leaves the message to Python.
    kind = kinds.get(type(spec), type(spec).__name__)
    return FieldTable(spec.name, offset, spec.size, kind, special=special)


def layout_table(cls: type[Layout]) -> LayoutTable:
    """The table of one declared message class."""
    is_command = issubclass(cls, Command)
    replies = tuple(r.__name__ for r in cls.reply_types()) if issubclass(cls, Command) else ()
    return LayoutTable(
        name=cls.__name__,
        code=cls.CODE,
        size=cls.SIZE,
        constants=tuple(cls.CONSTANTS),
        fields=tuple(_field(offset, spec) for offset, spec in cls.FIELDS),
        command=is_command,
        replies=replies,
        read=is_command and bool(getattr(cls, "READ", False)),
    )


def family_tables(family: Family[Any]) -> list[LayoutTable]:
    """The tables of a family's declared commands and of the declared replies they name, in order."""
    classes: dict[type, None] = {}
    for command in family.commands:
        if issubclass(command, Layout):
            classes[command] = None
        for reply in command.reply_types():
            if issubclass(reply, Layout):
                classes[reply] = None
    return [layout_table(cls) for cls in classes]


def main(argv: Sequence[str] | None = None) -> int:
    from dataclasses import asdict

    from servobus.protocols import available_families, get_family

    parser = argparse.ArgumentParser(prog="python -m servobus.protocols._tables", description=__doc__)
    parser.add_argument("family", choices=sorted(available_families()))
    args = parser.parse_args(argv)
    tables = [asdict(t) for t in family_tables(get_family(args.family))]
    json.dump(tables, sys.stdout, indent=1)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
