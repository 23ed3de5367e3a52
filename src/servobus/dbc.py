"""A DBC of a family's frames, generated from the codec's own field tables (cantools: ``servobus[dbc]``).

Only a family whose layouts are data can be exported: MyActuator states every 8-byte payload as a
``FIELDS`` table of ``(offset, field)`` pairs (``protocols/myactuator/_layout.py``), and the decoder
tables ``REQUESTS``/``REPLIES`` list the layouts of each DATA[0] per revision. Each layout becomes one
value of a multiplexer on DATA[0] (the signal ``code``), each field a little-endian signal whose factor,
range and unit come from the field object (``ScaledField`` 0.01 A/LSB is factor 0.01, unit ``A``):

* ``myactuator_request_<id>`` (0x140 + ID) and ``myactuator_broadcast`` (0x280): the requests;
* ``myactuator_reply_<id>`` (0x240 + ID): the replies, echoes included (an echo carries its command's
  fields).

What a DBC multiplexed on DATA[0] cannot say is left out, and :func:`layouts` names it with the reason:
a layout decoded by rules of its own instead of its table (0x20's value, signed or not by index; the
0x79 read reply's three id forms), text fields (0xB5 model names: DBC signals are numbers), two
layouts under one DATA[0] told apart by another byte (0x79 set/read, V4.3), and the motion (MIT) frames
on 0x400/0x500 + ID, whose 12- and 16-bit fields are bit-packed by the C core: their bit positions
are not in a Python table this module could generate from.

LK and hollow are refused: LK's layouts are written out in each class's ``encode``/``decode``, and the
hollow frames are bit-packed by the C core, so neither has a table to generate from.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Any

from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._special import SpecialZero

__all__ = [
    "MUX",
    "Layout",
    "SignalSpec",
    "build_database",
    "dbc_text",
    "layouts",
    "signal_names",
    "signal_spec",
]

#: The multiplexer signal: DATA[0].
MUX = "code"

#: Unit of a field, from its name's suffix (longest suffix first).
UNITS = (
    ("_dps_s", "deg/s^2"),
    ("_rad_s", "rad/s"),
    ("_counts", "counts"),
    ("_deg", "deg"),
    ("_dps", "deg/s"),
    ("_rad", "rad"),
    ("_rpm", "rpm"),
    ("_pct", "%"),
    ("_ms", "ms"),
    ("_nm", "Nm"),
    ("_a", "A"),
    ("_v", "V"),
    ("_c", "degC"),
)


@dataclass(frozen=True, slots=True)
class SignalSpec:
    """One field as a DBC signal: little-endian bytes at ``offset``, ``raw * scale`` in ``unit``."""

    field: str
    offset: int
    size: int
    signed: bool = False
    scale: float = 1.0
    is_float: bool = False
    choices: tuple[tuple[int, str], ...] = ()
    minimum: float | None = None
    maximum: float | None = None
    unit: str = ""
    comment: str = ""


@dataclass(frozen=True, slots=True)
class Layout:
    """One DATA[0] value: the message class it decodes to, its signals, and the ``(offset, byte)``
    constants the layout fixes (0xB5's DATA[1] = 0x01: written by every sender, not a signal)."""

    code: int
    name: str
    signals: tuple[SignalSpec, ...]
    constants: tuple[tuple[int, int], ...] = ()


def _unit(name: str) -> str:
    return next((unit for suffix, unit in UNITS if name.endswith(suffix)), "")


def signal_spec(offset: int, field: Any) -> SignalSpec | None:
    """The signal of a field object at ``offset``, or None if a DBC signal cannot carry it (text)."""
    from servobus.protocols.myactuator import _layout as lay

    comment = ""
    if isinstance(field, SpecialZero):
        comment = f"raw {field.raw} {field.meaning}"
        field = field.inner
    name = field.name
    common: dict[str, Any] = {"field": name, "offset": offset, "size": field.size, "unit": _unit(name)}
    if isinstance(field, ScaledField):
        lo, hi = field.limits
        return SignalSpec(
            **common,
            signed=field.signed,
            scale=1.0 / field.counts_per_unit,
            minimum=lo,
            maximum=hi,
            comment=comment,
        )
    if isinstance(field, IntField | lay.StepField):
        lo, hi = field.limits
        scale = float(field.step) if isinstance(field, lay.StepField) else 1.0
        signed = isinstance(field, IntField) and field.signed
        return SignalSpec(**common, signed=signed, scale=scale, minimum=lo, maximum=hi, comment=comment)
    if isinstance(field, lay.EnumField | lay.OpenEnumField):
        return SignalSpec(**common, choices=tuple((int(m), m.name) for m in field.enum))
    if isinstance(field, lay.FlagsField):
        flags = ", ".join(f"{m.name}=0x{int(m):X}" for m in field.flags if m.name and int(m))
        return SignalSpec(**common, comment=f"flags: {flags}")
    if isinstance(field, lay.BoolField):
        return SignalSpec(**common, choices=((0, "False"), (1, "True")), minimum=0, maximum=1)
    if isinstance(field, lay.Float32Field):
        return SignalSpec(**common, signed=True, is_float=True)
    return None  # AsciiField: text


def layouts(family: str, revision: str | Enum | None = None) -> tuple[list[Layout], list[Layout], list[str]]:
    """The request and reply layouts of ``family`` in ``revision`` (default: the family's), and what was
    left out of them, each with the reason.

    Raises:
        ValueError: a family without field tables (LK, hollow) or an unknown revision.
    """
    if family != "myactuator":
        why = {
            "lk": "its layouts are written out in each message class's code, not in field tables",
            "hollow": "its frames are bit-packed by the C core; no field table gives their bit positions",
        }.get(family, "it has no field tables")
        raise ValueError(
            f"a DBC is generated from field tables, and {family} has none: {why} (myactuator has)"
        )
    from servobus.protocols.myactuator import FAMILY
    from servobus.protocols.myactuator.codec import REPLIES, REQUESTS

    rev = FAMILY.revision(revision) if revision is not None else FAMILY.default_revision
    left_out: list[str] = [
        "0x400+ID/0x500+ID motion (MIT) frames: 12- and 16-bit fields bit-packed by the C core, whose bit "
        "positions are in no Python field table to generate signals from",
    ]
    requests = _table(REQUESTS, rev, "request", left_out)
    replies = _table(REPLIES, rev, "reply", left_out)
    return requests, replies, left_out


def _table(
    table: Mapping[int, Iterable[Any]], revision: Enum, what: str, left_out: list[str]
) -> list[Layout]:
    from servobus.protocols.myactuator._layout import Fixed

    out: list[Layout] = []
    for code, candidates in sorted(table.items()):
        here = [c for c in candidates if revision in c.revisions]
        if not here:
            continue
        names = [_name(c, what) for c in here]
        if len(here) > 1:
            left_out.append(
                f"{what} 0x{code:02X} ({', '.join(names)}): {len(here)} layouts under one DATA[0], told "
                "apart by another byte"
            )
            continue
        cls, name = here[0].message, names[0]
        if getattr(cls.decode, "__func__", None) is not Fixed.decode.__func__:  # type: ignore[attr-defined]
            left_out.append(
                f"{what} 0x{code:02X} ({name}): decoded by a rule of its own, not its field table"
            )
            continue
        signals: list[SignalSpec] = []
        for offset, field in cls.FIELDS:
            if offset == 0:
                continue  # DATA[0] is the multiplexer (the R2 status reply's ``command``)
            spec = signal_spec(offset, field)
            if spec is None:
                left_out.append(
                    f"{what} 0x{code:02X} ({name}): field {field.name!r} is ASCII text, not a number"
                )
                break
            signals.append(spec)
        else:
            out.append(Layout(code, name, tuple(signals), tuple(cls.CONSTANTS)))
    return out


def _name(candidate: Any, what: str) -> str:
    cls = candidate.message
    is_echo = what == "reply" and getattr(candidate.decode, "__func__", None) is None
    return f"Echo_{cls.__name__}" if is_echo else str(cls.__name__)


def build_database(
    family: str, ids: Iterable[int], revision: str | Enum | None = None
) -> tuple[Any, list[str]]:
    """A cantools Database of ``family``'s frames for the motors ``ids``, and what it leaves out.

    Raises:
        ValueError: as :func:`layouts`, or a motor id the family does not accept.
        ImportError: cantools is not installed (``pip install 'servobus[dbc]'``).
    """
    from cantools.database.can import Database, Message, Node

    from servobus.protocols.myactuator import FAMILY
    from servobus.protocols.myactuator.ids import BROADCAST_ID, reply_id, request_id

    requests, replies, left_out = layouts(family, revision)
    rev = FAMILY.revision(revision) if revision is not None else FAMILY.default_revision
    ids = list(dict.fromkeys(ids))
    messages = []
    for motor_id in ids:
        for ident, what, layout, sender in (
            (request_id(motor_id), "request", requests, "host"),
            (reply_id(motor_id), "reply", replies, f"motor_{motor_id}"),
        ):
            comment = f"MyActuator {rev.name} {what}s of motor {motor_id}, multiplexed on DATA[0]"
            messages.append(
                Message(
                    ident,
                    f"myactuator_{what}_{motor_id}",
                    8,
                    _signals(layout),
                    comment=comment,
                    senders=[sender],
                )
            )
    comment = f"MyActuator {rev.name} multi-motor requests (every motor replies on 0x240 + ID)"
    messages.append(
        Message(
            BROADCAST_ID, "myactuator_broadcast", 8, _signals(requests), comment=comment, senders=["host"]
        )
    )
    nodes = [Node("host"), *(Node(f"motor_{i}") for i in ids)]
    return Database(messages=messages, nodes=nodes), left_out


def _signals(table: list[Layout]) -> list[Any]:
    from cantools.database.can import Signal
    from cantools.database.conversion import BaseConversion
    from cantools.database.namedsignalvalue import NamedSignalValue

    choices: OrderedDict[int, str | NamedSignalValue] = OrderedDict((t.code, t.name) for t in table)
    mux = Signal(MUX, 0, 8, is_multiplexer=True, conversion=BaseConversion.factory(choices=choices))
    names = signal_names(table)
    signals = [mux]
    for spec, (name, codes) in names.items():
        conversion = BaseConversion.factory(
            scale=spec.scale,
            choices=OrderedDict(spec.choices) or None,
            is_float=spec.is_float,
        )
        signals.append(
            Signal(
                name,
                8 * spec.offset,
                8 * spec.size,
                is_signed=spec.signed,
                conversion=conversion,
                minimum=spec.minimum,
                maximum=spec.maximum,
                unit=spec.unit or None,
                comment=spec.comment or None,
                multiplexer_ids=codes,
                multiplexer_signal=MUX,
            )
        )
    return signals


def signal_names(table: list[Layout]) -> dict[SignalSpec, tuple[str, list[int]]]:
    """Each distinct signal of a multiplexed message: its name and the DATA[0] codes that carry it.

    A field with one shape in every layout that has it is one signal under the field's name, shared
    by those codes; a name with several shapes gets the first code of each as a suffix
    (``angle_deg_92``: int32 0.01° in 0x92, ``angle_deg_72``: int16 1° in the status replies).
    """
    groups: dict[SignalSpec, list[int]] = {}
    for layout in table:
        for spec in layout.signals:
            groups.setdefault(spec, []).append(layout.code)
    shapes: dict[str, int] = {}
    for spec in groups:
        shapes[spec.field] = shapes.get(spec.field, 0) + 1
    return {
        spec: (
            spec.field if shapes[spec.field] == 1 and spec.field != MUX else f"{spec.field}_{codes[0]:02X}",
            codes,
        )
        for spec, codes in groups.items()
    }


def dbc_text(database: Any) -> str:
    """The database as DBC text."""
    text: str = database.as_dbc_string()
    return text
