"""A DBC of a family's CAN frames, derived from its classes' declarations (cantools: ``servobus[dbc]``).

A DBC signal is a bit range with a byte order, a sign, ``value = raw * factor + offset``, a range and a
unit. The exporter never names a family: it asks the :class:`~servobus.protocols.Family` (built-in or
registered by entry point) and derives every signal from what the codec already states.

**From the declarations.** A message class with a fixed layout (``protocols/_layout.py``: ``CODE`` in
DATA[0], ``FIELDS`` of ``(offset, field)`` pairs, ``CONSTANTS``, ``SIZE``) gives one DBC layout:
each field is a little-endian signal whose factor, range and unit come from the field object
(:func:`signal_spec`: a ``ScaledField`` of 100 counts per ampere is factor 0.01, unit ``A`` from the name
``current_a``), an enum field's members are its choices. :func:`fields_layout` makes that layout; a class
decoded by a rule of its own or holding text is left out with the reason. A C-core field is bit-packed
(MIT: a float in [lo, hi] onto an n-bit code, ``code = (x - lo) * (2**n - 1) / (hi - lo)``, i.e. factor
``(hi - lo) / (2**n - 1)``, offset ``lo``). Its bit positions are not copied from the C source:
:func:`packed_signals` packs one bit of one field at a time through the C core and reads where it lands,
so the DBC places every bit where ``servobus._core`` does. A field whose bits are not one big-endian run
becomes one signal per run (``position_deg_b0``, ``position_deg_b16``), whose values add up to the
field's.

**From the family** (what declarations cannot say): which identifiers carry which frames per motor,
which byte multiplexes them, comments, bit-packed layouts, options (a motor model, a CAN mode). A family
states it in its ``dbc`` part (``Family.part("dbc")``, a :class:`DbcFamily`), whose ``describe`` builds
the messages with the helpers here. A family without a ``dbc`` part gets :func:`derived`: per motor,
the identifiers its bound codec lists (``request_ids``, ``reply_ids``), the commands of the revision
multiplexed on DATA[0] by their ``CODE``, their replies (``reply_types()``) likewise.

Messages are multiplexed on DATA[0] (the signal ``code``) where the family keys its frames by it;
parameter frames whose value layout depends on a parameter byte are multiplexed again on that byte
(extended multiplexing, ``SG_MUL_VAL_``). A multiplexer value's name is unique (``Status2Reply_A0``):
cantools reads a decoded name back by the name.

**Signal names are servobus' field names** (what ``decode`` and ``servobus.logs`` call them), with two
rules the DBC format forces, and :func:`signal_table` applies:

* a DBC name is an identifier: an item of a tuple value or a field of a field is spelled with ``_``
  (:func:`dbc_name`: ``currents_a[0]`` -> ``currents_a_0``, ``value.kp`` -> ``value_kp``,
  ``command.speed_dps`` -> ``command_speed_dps``); a field split in bit runs is one signal per run
  (``position_deg_b0``, ``position_deg_b16``, see above).
* a DBC name is unique in its message, and one signal has one multiplexer, bit range, conversion,
  choices, range and comment. A field described alike under several values of one multiplexer is one
  signal, shared by them (``angle_deg`` of the 0x9C status reply and of the control replies). Where
  layouts under one identifier describe a field differently (an int16 1° ``angle_deg`` in those
  replies, an int32 0.01° one in 0x92's; 0xA9's ``max_torque_pct``, whose raw 0 is not 0xA2's "no
  limit") or under different multiplexers (LK's ``value`` of 0xC1's parameters and of 0x42's
  settings), only one signal can have the name: the one with the fewest multiplexer levels above it,
  then the one the most multiplexer values carry (the first of a tie), keeps it; each other gets the
  multiplexer values of its first layout as a suffix (``angle_deg_92``, ``value_C1_1E``: 0xC1's value
  of parameter 0x1E). Neither extended multiplexing nor a message per multiplexer value avoids it: a
  DBC has one message per identifier, and a signal's multiplexer values select its children under
  every value of the multiplexer above it (cantools builds one subtree per value of the multiplexer
  itself), so a byte that is a multiplexer in one layout (0xC1's ``param``) and a plain value in
  another (0xC0's) must be two signals.

The multiplexer on DATA[0], ``code``, is not a field: its value names the layout (the message class).
A servobus field a multiplexer value stands for (the ``command`` byte of a reply layout several
DATA[0] values share, a parameter's name) has no signal of its own: the multiplexer value selecting the
layout gives it (the layout's ``implies``).

What a DBC cannot say is left out, and :func:`plan` names it with the reason (text fields, layouts
decoded by rules of their own, two layouts under one identifier and DATA[0], what the family's part
adds).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import re
import typing
from collections import OrderedDict
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, TypeAlias

from servobus.core import FieldScale, Packer
from servobus.protocols import Command, Family, available_families, get_family
from servobus.protocols._bound import EXTENDED
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._layout import (
    BoolField,
    EnumField,
    FlagsField,
    Float32Field,
    OpenEnumField,
    StepField,
)
from servobus.protocols._layout import (
    Layout as FixedLayout,
)
from servobus.protocols._special import SpecialZero

__all__ = [
    "CONFIG_FIELDS",
    "DIRECTIONS",
    "MUX",
    "DbcFamily",
    "DbcOption",
    "DbcQuery",
    "Described",
    "EnumByte",
    "FlagsByte",
    "Keyed",
    "Layout",
    "MessageSpec",
    "Mux",
    "Placed",
    "Plan",
    "ResultByte",
    "SignalSpec",
    "build_database",
    "database",
    "dbc_name",
    "dbc_part",
    "dbc_text",
    "derived",
    "enum_choices",
    "fields_layout",
    "keyed_layouts",
    "le_signal",
    "muxed",
    "option_owners",
    "packed_signals",
    "plan",
    "reply_keys",
    "request_keys",
    "signal_spec",
    "signal_table",
]

ByteOrder: TypeAlias = Literal["little_endian", "big_endian"]

#: The multiplexer signal on DATA[0].
MUX = "code"
DIRECTIONS = ("request", "reply")
_PLURAL = {"request": "requests", "reply": "replies"}
#: Fields a message carries to be self-contained, not values of its frame.
CONFIG_FIELDS = frozenset({"model", "scales", "motor_type", "encoder_bits"})

#: Unit of a field, from its name's suffix (longest suffix first).
UNITS = (
    ("_dps_s", "deg/s^2"),
    ("_dps2", "deg/s^2"),
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


# ---- what a DBC is made of ---------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SignalSpec:
    """One value of a frame as a DBC signal.

    Attributes:
        field: servobus' name of the value: the message's field (``speed_dps``), an item of a tuple
            field (``currents_a[0]``), a field of a field (``value.kp`` of PID gains,
            ``command.speed_dps`` of an echoed command).
        start, length, byte_order: the bits, in cantools' numbering (a big-endian signal starts at
            its most significant bit).
        signed, scale, offset, is_float: ``value = raw * scale + offset`` (or the IEEE float).
        choices: names of raw values (enums, booleans, multiplexer values).
        minimum, maximum, unit, comment: as the DBC states them.
        part: for a field split into several bit runs, the bit of the field's code this run starts
            at; the field's value is the sum of its parts' values. None for a whole field.
        none_raw: the raw value servobus reads as None (``max_speed_dps=None`` is raw 0), if any.
    """

    field: str
    start: int
    length: int
    byte_order: ByteOrder = "little_endian"
    signed: bool = False
    scale: float = 1.0
    offset: float = 0.0
    is_float: bool = False
    choices: tuple[tuple[int, str], ...] = ()
    minimum: float | None = None
    maximum: float | None = None
    unit: str = ""
    comment: str = ""
    part: int | None = None
    none_raw: int | None = None

    @property
    def base_name(self) -> str:
        """The DBC identifier this signal is named after (before any suffix that keeps it unique)."""
        name = dbc_name(self.field)
        return name if self.part is None else f"{name}_b{self.part}"


def dbc_name(field: str) -> str:
    """servobus' name of a value as a DBC identifier: each run of characters a DBC name cannot hold
    becomes ``_`` (``currents_a[0]`` -> ``currents_a_0``, ``value.kp`` -> ``value_kp``); a plain field
    name (``angle_deg``) is itself."""
    return re.sub(r"[^0-9A-Za-z_]+", "_", field).strip("_")


@dataclass(frozen=True, slots=True)
class Layout:
    """What one multiplexer value (DATA[0], or a parameter byte under it) selects.

    Attributes:
        code: the multiplexer value (None for a message's root, which is always present).
        name: the multiplexer value's name in the DBC (a message class, ``Echo_X``, a parameter).
        signals: the signals present under it.
        constants: ``(offset, byte)`` pairs the layout fixes (0xB5's DATA[1] = 0x01): not signals.
        mux: a nested multiplexer under this value, or None.
        message: the servobus class the frame decodes to, where this level names one.
        implies: ``(field, value)`` pairs the selecting multiplexer values mean (LK's ``command``
            byte of a shared reply layout, a parameter's name, a PI frame's gain).
    """

    code: int | None
    name: str
    signals: tuple[SignalSpec, ...] = ()
    constants: tuple[tuple[int, int], ...] = ()
    mux: Mux | None = None
    message: str | None = None
    implies: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True, slots=True)
class Mux:
    """A multiplexer signal and the layouts its values select."""

    signal: SignalSpec
    layouts: tuple[Layout, ...]


@dataclass(frozen=True, slots=True)
class MessageSpec:
    """One DBC message: an identifier, its length and frame kind, and the layout tree of its signals."""

    frame_id: int
    name: str
    length: int
    kind: str  # "request" or "reply"
    root: Layout
    senders: tuple[str, ...]
    comment: str = ""
    extended: bool = False
    fd: bool = False
    motor_id: int | None = None


@dataclass(frozen=True, slots=True)
class Plan:
    """Everything a DBC of one family holds, and what it leaves out (each with the reason)."""

    family: str
    revision: enum.Enum
    messages: tuple[MessageSpec, ...]
    left_out: tuple[str, ...]
    nodes: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Placed:
    """A signal of a built message: its spec, the multiplexer it hangs on and the values selecting it;
    for a multiplexer, the layouts its values select."""

    name: str
    spec: SignalSpec
    mux_signal: str | None
    mux_ids: tuple[int, ...]
    layouts: tuple[Layout, ...] | None = None


def _unit(name: str) -> str:
    name = re.sub(r"\[\d+\]$", "", name)  # an item of a tuple value: currents_a[0]
    return next((unit for suffix, unit in UNITS if name.endswith(suffix)), "")


def le_signal(field: str, offset: int, size: int, **kwargs: Any) -> SignalSpec:
    """A little-endian signal of ``size`` bytes at DATA[offset], its unit from the field's name
    (``kwargs``: the other :class:`SignalSpec` attributes)."""
    return SignalSpec(field, 8 * offset, 8 * size, unit=_unit(field), **kwargs)


def _bool_choices() -> tuple[tuple[int, str], ...]:
    return ((0, "False"), (1, "True"))


def enum_choices(enum_cls: type[enum.Enum]) -> tuple[tuple[int, str], ...]:
    """An enum's members as DBC choices: ``(value, name)``."""
    return tuple((int(member.value), member.name) for member in enum_cls)


# ---- field objects -> signals ------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class EnumByte:
    """An IntEnum carried as an unsigned integer of ``size`` bytes, for a class without ``FIELDS``."""

    name: str
    enum: type[enum.IntEnum]
    size: int = 1


@dataclass(frozen=True, slots=True)
class FlagsByte:
    """An IntFlag byte (servobus gives it as an int; the DBC comment names the bits)."""

    name: str
    flags: type[enum.IntFlag]


@dataclass(frozen=True, slots=True)
class ResultByte:
    """A status byte whose values map to named results (a family's write/save result polarities)."""

    name: str
    table: Mapping[int, enum.Enum]


def signal_spec(offset: int, field: Any, name: str | None = None) -> SignalSpec | None:
    """The little-endian signal of a field object at DATA[offset] (``name`` renames it), or None if a DBC
    signal cannot carry it (text)."""
    comment = ""
    none_raw = None
    if isinstance(field, SpecialZero):
        comment = f"raw {field.raw} {field.meaning}"
        none_raw = field.raw if field.explicit else None
        field = field.inner
    name = name or field.name
    if isinstance(field, EnumByte):
        return le_signal(name, offset, field.size, choices=enum_choices(field.enum))
    if isinstance(field, FlagsByte):
        flags = ", ".join(f"{m.name}=0x{int(m):X}" for m in field.flags if m.name and int(m))
        return le_signal(name, offset, 1, minimum=0, maximum=255, comment=f"flags: {flags}")
    if isinstance(field, ResultByte):
        return le_signal(
            name, offset, 1, choices=tuple((raw, r.name) for raw, r in sorted(field.table.items()))
        )
    common: dict[str, Any] = {"comment": comment, "none_raw": none_raw}
    if isinstance(field, ScaledField):
        lo, hi = field.limits
        return le_signal(
            name,
            offset,
            field.size,
            signed=field.signed,
            scale=1.0 / field.counts_per_unit,
            minimum=lo,
            maximum=hi,
            **common,
        )
    if isinstance(field, IntField | StepField):
        lo, hi = field.limits
        scale = float(field.step) if isinstance(field, StepField) else 1.0
        signed = isinstance(field, IntField) and field.signed
        return le_signal(
            name, offset, field.size, signed=signed, scale=scale, minimum=lo, maximum=hi, **common
        )
    if isinstance(field, EnumField | OpenEnumField):
        return le_signal(name, offset, field.size, choices=tuple((int(m), m.name) for m in field.enum))
    if isinstance(field, FlagsField):
        flags = ", ".join(f"{m.name}=0x{int(m):X}" for m in field.flags if m.name and int(m))
        return le_signal(name, offset, field.size, comment=f"flags: {flags}")
    if isinstance(field, BoolField):
        return le_signal(name, offset, field.size, choices=_bool_choices(), minimum=0, maximum=1)
    if isinstance(field, Float32Field):
        return le_signal(name, offset, field.size, signed=True, is_float=True)
    return None  # AsciiField: text


# ---- C-core layouts: bit positions found by packing through the C core --------------------------


def _code_range(bits: int) -> tuple[int, int]:
    width = abs(bits)
    return (-(1 << (width - 1)), (1 << (width - 1)) - 1) if bits < 0 else (0, (1 << width) - 1)


@functools.cache
def _bit_positions(layout: Any, stride: int) -> tuple[tuple[tuple[int, int], ...], ...]:
    """For each field of a C-core layout, the ``(byte, bit)`` each bit of its code lands on, LSB first.

    Found by packing codes with one bit set (the sign bit of a signed field is its most negative code)
    through the C core with identity scales, and reading which frame bit it set.
    """
    scales = [FieldScale.integer(f"probe_{k}", *_code_range(bits)) for k, bits in enumerate(layout.bits)]
    probe = Packer(layout, scales, stride=stride)
    fields = []
    for k, bits in enumerate(layout.bits):
        width = abs(bits)
        positions = []
        for b in range(width):
            row = [0.0] * len(layout.bits)
            row[k] = float(-(1 << b) if bits < 0 and b == width - 1 else 1 << b)
            frame = probe.pack(row)
            ones = [(i, j) for i, byte in enumerate(frame) for j in range(8) if byte >> j & 1]
            if len(ones) != 1 or probe.unpack(frame) != tuple(row):
                raise AssertionError(f"{layout.name} field {k} bit {b} packs to {frame.hex()}")
            positions.append(ones[0])
        fields.append(tuple(positions))
    return tuple(fields)


def _runs(positions: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """``(first field bit, length)`` of each big-endian run: bit b+1 sits just above bit b (in Motorola
    order: the next more significant bit of the byte, or bit 0 of the byte before)."""

    def order(pos: tuple[int, int]) -> int:
        return 8 * pos[0] + 7 - pos[1]

    runs = []
    first = 0
    for b in range(1, len(positions) + 1):
        if b == len(positions) or order(positions[b]) != order(positions[b - 1]) - 1:
            runs.append((first, b - first))
            first = b
    return runs


def message_fields(message: type) -> list[tuple[str, Any]]:
    """A message class's value fields (its dataclass fields without configuration) and their types."""
    hints = typing.get_type_hints(message)
    return [(f.name, hints[f.name]) for f in dataclasses.fields(message) if f.name not in CONFIG_FIELDS]


def _packed_fields(message: type) -> list[tuple[str, Any]]:
    """The fields a packer carries for ``message``, with their types: its declared ``FIELDS`` (named
    field objects in the packer's order), else its value fields (:func:`message_fields`)."""
    declared = getattr(message, "FIELDS", ())
    if declared and all(isinstance(getattr(f, "name", None), str) for f in declared):
        hints = typing.get_type_hints(message)
        return [(f.name, hints.get(f.name)) for f in declared]
    return message_fields(message)


def packed_signals(packer: Packer, message: type) -> tuple[SignalSpec, ...]:
    """The signals of a C-core packer's frame, named after ``message``'s fields in the packer's order
    (its declared ``FIELDS``, or its dataclass fields but :data:`CONFIG_FIELDS`).

    Factor and offset come from each field's :class:`~servobus.core.FieldScale` (``span / codes`` and
    ``origin``), the range from its limits and code range, choices from the message field's type (an
    IntEnum, or bool), the bit positions from :func:`_bit_positions`.

    Raises:
        ValueError: the message's fields do not match the layout's.
    """
    layout = packer.layout
    fields = _packed_fields(message)
    if len(fields) != len(layout.fields):
        raise ValueError(f"{message.__name__} has {len(fields)} fields, {layout.name} {len(layout.fields)}")
    signals: list[SignalSpec] = []
    for (name, kind), scale, bits, positions in zip(
        fields, packer.scales, layout.bits, _bit_positions(layout, packer.stride), strict=True
    ):
        factor = scale.span / scale.codes
        cmin, cmax = _code_range(bits)
        choices: tuple[tuple[int, str], ...] = ()
        if kind is bool:
            choices = _bool_choices()
        elif isinstance(kind, type) and issubclass(kind, enum.IntEnum):
            choices = enum_choices(kind)
        runs = _runs(positions)
        for first, length in runs:
            msb = positions[first + length - 1]
            whole = len(runs) == 1
            signed = bits < 0 and first + length == abs(bits)
            lo, hi = _code_range(-length if signed else length)
            part_scale = factor * (1 << first)
            origin = scale.origin if first == 0 else 0.0
            comment = ""
            if not whole:
                comment = (
                    f"bits {first}..{first + length - 1} of the {abs(bits)}-bit {name} code: {name} is the "
                    "sum of its parts"
                )
            signals.append(
                SignalSpec(
                    name,
                    8 * msb[0] + msb[1],
                    length,
                    "big_endian",
                    signed=signed,
                    scale=part_scale,
                    offset=origin,
                    choices=choices,
                    minimum=max(scale.lo, cmin * factor + origin) if whole else lo * part_scale + origin,
                    maximum=min(scale.hi, cmax * factor + origin) if whole else hi * part_scale + origin,
                    unit=_unit(name),
                    comment=comment,
                    part=None if whole else first,
                )
            )
    return tuple(signals)


# ---- declared layouts -> DBC layouts ------------------------------------------------------------


def fields_layout(
    cls: type,
    code: int | None,
    what: str,
    left_out: list[str],
    *,
    name: str | None = None,
    prefix: str = "",
    implies: Iterable[tuple[str, Any]] = (),
    message: str | None = None,
) -> Layout | None:
    """The DBC layout of a fixed-layout class (``FIELDS``, ``CONSTANTS``) under the DATA[0] value
    ``code`` (None: a frame without a command byte), or None with the reason added to ``left_out``: a
    class decoded by a rule of its own (not its field table), or one with a text field.

    A field at offset 0 is the multiplexer's byte: the value ``code`` implies it (an R2 status reply's
    ``command``). Args: ``name``, the multiplexer value's name (default the class's); ``prefix``,
    before each field name (``command.`` for an echoed command); ``implies``, more fields the value
    stands for; ``message``, the class the frame decodes to (default ``name``).
    """
    name = name or cls.__name__
    where = f"{what} 0x{code:02X} ({name})" if code is not None else f"{what} {name}"
    decode = getattr(getattr(cls, "decode", None), "__func__", None)
    if decode is not FixedLayout.decode.__func__:  # type: ignore[attr-defined]
        left_out.append(f"{where}: decoded by a rule of its own, not its field table")
        return None
    signals: list[SignalSpec] = []
    implied = list(implies)
    for offset, field in getattr(cls, "FIELDS", ()):
        if offset == 0 and code is not None:
            implied.append((prefix + field.name, _scalar(field.decode(bytes([code]), 0))))
            continue
        spec = signal_spec(offset, field, prefix + field.name)
        if spec is None:
            left_out.append(f"{where}: field {field.name!r} is ASCII text, not a number")
            return None
        signals.append(spec)
    constants = tuple(getattr(cls, "CONSTANTS", ()))
    return Layout(code, name, tuple(signals), constants, message=message or name, implies=tuple(implied))


def _scalar(value: Any) -> Any:
    """A decoded value as :func:`servobus.logs.message_values` gives it (enums by name, flags as int)."""
    if isinstance(value, enum.Flag):
        return int(value.value)
    if isinstance(value, enum.Enum):
        return value.name
    return value


def muxed(layouts: tuple[Layout, ...]) -> Layout:
    """A root whose DATA[0] (the signal ``code``) multiplexes ``layouts``.

    A layout name several values share (LK's ``Status2Reply`` of 0x9C and 0xA0..0xA8) gets the value as
    a suffix (``Status2Reply_A0``): cantools turns a decoded multiplexer name back into its value by the
    name, so a shared name would select the first value's signals for all of them.
    """
    counts: dict[str, int] = {}
    for layout in layouts:
        counts[layout.name] = counts.get(layout.name, 0) + 1
    named = tuple(
        dataclasses.replace(layout, name=f"{layout.name}_{layout.code:02X}")
        if counts[layout.name] > 1
        else layout
        for layout in layouts
    )
    return Layout(None, "", mux=Mux(SignalSpec(MUX, 0, 8), named))


@dataclass(frozen=True, slots=True)
class Keyed:
    """One class a DATA[0] value selects, as the family's codec reads it.

    Attributes:
        code: the DATA[0] value.
        cls: the class whose ``FIELDS`` lay the frame out (for an echo: the command echoed).
        name: the multiplexer value's name (``Echo_SetCanId`` for an echo).
        echo: the frame is the command's own bytes echoed back: its fields are ``command.<field>``,
            and the value implies ``command`` (the class's name).
    """

    code: int
    cls: type
    name: str
    echo: bool = False


def _in(cls: type, revision: enum.Enum) -> bool:
    """Whether ``cls`` exists in ``revision``: its declared ``REVISIONS``, or every revision."""
    return revision in getattr(cls, "REVISIONS", (revision,))


def request_keys(commands: Iterable[type[Command]], revision: enum.Enum) -> list[Keyed]:
    """The commands of ``revision`` that have a ``CODE``, each under it."""
    return [Keyed(c.CODE, c, c.__name__) for c in commands if c.CODE is not None and _in(c, revision)]


def reply_keys(
    commands: Iterable[type[Command]], revision: enum.Enum, *, echo: type | None = None
) -> list[Keyed]:
    """The replies of ``revision``'s commands (``reply_types()``), each under its DATA[0], once: its own
    ``CODE``; a reply without one is a layout several commands share, under each command's byte; the
    class ``echo`` (a family's "the request's bytes echoed") is the command itself, echoed."""
    out: list[Keyed] = []
    for command in commands:
        code = command.CODE
        if code is None or not _in(command, revision):
            continue
        for reply in command.reply_types():
            if echo is not None and reply is echo:
                key = Keyed(code, command, f"Echo_{command.__name__}", echo=True)
            elif not _in(reply, revision):
                continue
            else:
                key = Keyed(code if reply.CODE is None else reply.CODE, reply, reply.__name__)
            if key not in out:
                out.append(key)
    return out


def keyed_layouts(keys: Iterable[Keyed], what: str, left_out: list[str]) -> tuple[Layout, ...]:
    """The layouts of ``keys`` by DATA[0] (:func:`fields_layout`); a DATA[0] several classes share is
    left out (told apart by another byte), as is a class :func:`fields_layout` cannot describe."""
    by_code: dict[int, list[Keyed]] = {}
    for key in keys:
        by_code.setdefault(key.code, []).append(key)
    out: list[Layout] = []
    for code, here in sorted(by_code.items()):
        if len(here) > 1:
            names = ", ".join(k.name for k in here)
            left_out.append(
                f"{what} 0x{code:02X} ({names}): {len(here)} layouts under one DATA[0], told apart by "
                "another byte"
            )
            continue
        key = here[0]
        if key.echo:
            layout = fields_layout(
                key.cls,
                code,
                what,
                left_out,
                name=key.name,
                prefix="command.",
                implies=(("command", key.cls.__name__),),
                message="Echo",
            )
        else:
            layout = fields_layout(key.cls, code, what, left_out, name=key.name)
        if layout is not None:
            out.append(layout)
    return tuple(out)


# ---- what a family tells the exporter -----------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class DbcOption:
    """An option of a family's DBC: ``plan(family, ids, name=value)``, on the command line ``--option
    name=value`` (or a flag of its own, ``--model``).

    Attributes:
        name: the keyword (``can_mode``), an identifier.
        help: one line for the user: what it sets and its default.
        parse: the value from command-line text (``int``; default: the text itself).
    """

    name: str
    help: str
    parse: Callable[[str], Any] = str


@dataclass(frozen=True, slots=True, kw_only=True)
class DbcQuery:
    """What a DBC is asked for, as a family's :attr:`DbcFamily.describe` gets it.

    Attributes:
        family: the family.
        ids: the motors' ids (each once, in the order given).
        revision: the revision asked for (a member of ``family.revisions``), or None: the family's
            choice (its default, or what an option implies).
        options: the family's options that were given, by name (never None values).
        direction: ``"request"`` or ``"reply"`` when only those messages are wanted (the exporter
            drops the others; a family may use it to choose what shares an identifier), or None.
    """

    family: Family
    ids: tuple[int, ...]
    revision: enum.Enum | None
    options: Mapping[str, Any]
    direction: str | None


@dataclass(frozen=True, slots=True, kw_only=True)
class Described:
    """A family's answer: the revision described, every message (both directions), what is left out."""

    revision: enum.Enum
    messages: tuple[MessageSpec, ...]
    left_out: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True, kw_only=True)
class DbcFamily:
    """A family's DBC part (``Family.parts["dbc"]``, ``protocols/<family>/dbc.py`` ``DBC``): what its
    classes' declarations do not say.

    Attributes:
        summary: what its DBC holds, in a few lines (``servobus dbc --help`` shows it).
        options: the options its ``describe`` takes (validated by name before it is called).
        describe: the messages of a :class:`DbcQuery`: identifiers per motor, layouts (from the
            declarations with :func:`fields_layout` and :func:`muxed`, bit-packed ones with
            :func:`packed_signals`), comments. Raises ValueError naming a bad id or option value.
            Default :func:`derived`.
    """

    summary: str = ""
    options: tuple[DbcOption, ...] = ()
    describe: Callable[[DbcQuery], Described] = dataclasses.field(default_factory=lambda: derived)

    def option(self, name: str) -> DbcOption | None:
        """The option called ``name``, or None."""
        return next((o for o in self.options if o.name == name), None)


def dbc_part(family: Family) -> DbcFamily:
    """The family's DBC part, or the default (:func:`derived`, no options) if it has none.

    Raises:
        TypeError: the family's ``dbc`` part is not a :class:`DbcFamily`.
    """
    if "dbc" not in family.parts:
        return DbcFamily()
    part = family.part("dbc")
    if not isinstance(part, DbcFamily):
        raise TypeError(f"the {family.name} family's dbc part is {type(part).__name__}, not a DbcFamily")
    return part


def derived(query: DbcQuery) -> Described:
    """The DBC of a family from its declarations alone (a family without a ``dbc`` part).

    Per motor, the bound codec's identifiers (``Family.bind(motor_id, revision=...)``): a request
    message on each of its ``request_ids``, the family's commands of the revision (``REVISIONS``, if
    declared) multiplexed on DATA[0] by ``CODE``; a reply message on each of its ``reply_ids``, the
    commands' ``reply_types()`` likewise. A direction of one class whose ``CODE`` is None is that
    class's layout, unmultiplexed. An identifier several motors share (one reply id for all) is one
    message; an identifier in both lists carries the replies unless ``direction="request"``. A message
    is as long as its longest ``SIZE`` (CAN FD beyond 8 bytes); an identifier in ``EXTENDED`` is
    29-bit.

    Raises:
        ValueError: a motor id outside ``family.motor_ids``, or one its ``bind`` refuses.
    """
    family = query.family
    rev = query.revision if query.revision is not None else family.default_revision
    left_out: list[str] = []
    commands = [c for c in family.commands if _in(c, rev)]
    replies = list(dict.fromkeys(r for c in commands for r in c.reply_types() if _in(r, rev)))
    roots = {
        "request": _derived_root(commands, request_keys(commands, rev), "request", left_out),
        "reply": _derived_root(replies, reply_keys(commands, rev), "reply", left_out),
    }
    sizes = {
        "request": max((getattr(c, "SIZE", 8) for c in commands), default=8),
        "reply": max((getattr(r, "SIZE", 8) for r in replies), default=8),
    }
    carried: dict[tuple[str, int], list[int]] = {}
    shared_any = False
    for motor_id in query.ids:
        if motor_id not in family.motor_ids:
            first, last = family.motor_ids[0], family.motor_ids[-1]
            raise ValueError(f"motor_id={motor_id} is outside {family.name}'s ids {first}..{last}")
        codec = family.bind(motor_id, revision=rev)
        shared = codec.request_ids & codec.reply_ids
        shared_any = shared_any or bool(shared)
        for kind, idents in (("request", codec.request_ids), ("reply", codec.reply_ids)):
            for ident in sorted(idents):
                # An identifier both ways carries the replies, unless the requests are asked for.
                if ident in shared and (kind == "request") != (query.direction == "request"):
                    continue
                carried.setdefault((kind, ident), []).append(motor_id)
    if shared_any and query.direction != "request":
        left_out.append(
            "requests on the identifiers replies come on: a DBC has one message per identifier, so those "
            "describe the replies; direction 'request' gives the requests' DBC"
        )
    names = {
        key: f"{family.name}_{key[0]}" + (f"_{m[0]}" if len(m) == 1 else "") for key, m in carried.items()
    }
    messages = []
    for (kind, ident), motors in carried.items():
        root = roots[kind]
        if root is None:
            continue
        frame_id = ident & ~EXTENDED
        name = names[(kind, ident)]
        if list(names.values()).count(name) > 1:  # a motor with several identifiers one way
            name += f"_{frame_id:X}"
        senders = ("host",) if kind == "request" else tuple(f"motor_{m}" for m in motors)
        whose = f"motor {motors[0]}" if len(motors) == 1 else "motors " + ", ".join(map(str, motors))
        multiplexed = ", multiplexed on DATA[0]" if root.mux is not None else ""
        messages.append(
            MessageSpec(
                frame_id,
                name,
                sizes[kind],
                kind,
                root,
                senders,
                f"{family.name} {rev.name} {_PLURAL[kind]} of {whose}{multiplexed}",
                extended=bool(ident & EXTENDED),
                fd=sizes[kind] > 8,
                motor_id=motors[0] if len(motors) == 1 else None,
            )
        )
    return Described(revision=rev, messages=tuple(messages), left_out=tuple(left_out))


def _derived_root(
    classes: Sequence[type], keys: list[Keyed], what: str, left_out: list[str]
) -> Layout | None:
    """One direction's layout tree: ``keys`` multiplexed on DATA[0]; a lone class without a ``CODE``,
    as it is; None (and why, in ``left_out``) when nothing is describable."""
    if len(classes) == 1 and getattr(classes[0], "CODE", None) is None:
        layout = fields_layout(classes[0], None, what, left_out)
        return None if layout is None else dataclasses.replace(layout, name="")
    keyed = {key.cls for key in keys}
    for cls in classes:
        if cls not in keyed and getattr(cls, "CODE", None) is None:
            left_out.append(f"{what} {cls.__name__}: no CODE (DATA[0]) to be told apart by")
    layouts = keyed_layouts(keys, what, left_out)
    return muxed(layouts) if layouts else None


# ---- plans and databases ------------------------------------------------------------------------


def option_owners(option: str) -> list[str]:
    """The families (built-in and plug-in) whose DBC takes ``option``; a family whose part does not
    load is skipped (an error message is being built)."""
    owners = []
    for name in available_families():
        try:
            part = dbc_part(get_family(name))
        except (ImportError, LookupError, TypeError, ValueError):
            continue
        if part.option(option) is not None:
            owners.append(name)
    return owners


def plan(
    family: str | Family,
    ids: Iterable[int],
    revision: str | enum.Enum | None = None,
    *,
    direction: str | None = None,
    **options: Any,
) -> Plan:
    """What the DBC of ``family``'s motors ``ids`` holds, and what it leaves out.

    Args:
        family: a registered family's name (``myactuator``, ``lk``, ``hollow``, a plug-in's), or the
            Family.
        ids: the motors' ids.
        revision: the protocol revision (default: the family's choice).
        direction: ``request`` or ``reply`` for only those messages (default both).
        options: the family's DBC options (its ``DbcFamily.options``); None is "not given". The
            built-in ones: ``model`` (LK: an ``LkModel`` or a motor type MS, MF, MH, MG; hollow: a
            ``HollowModel`` or a name of ``hollow.MODELS``), ``encoder_bits`` (LK), ``can_mode`` and
            ``host_id`` (hollow), ``max_torque_nm`` (MyActuator V4.4's motion torque range).

    Raises:
        ValueError: an unknown family, revision, direction or option, an option of another family, a
            bad option value, or a motor id the family does not accept.
    """
    if isinstance(family, str):
        known = available_families()
        if family not in known:
            raise ValueError(f"no family {family!r} (known: {', '.join(known)})")
        family = get_family(family)
    if direction is not None and direction not in DIRECTIONS:
        raise ValueError(f"direction={direction!r} is not one of {', '.join(DIRECTIONS)}")
    part = dbc_part(family)
    given = {name: value for name, value in options.items() if value is not None}
    for name in given:
        if part.option(name) is None:
            owners = " and ".join(option_owners(name)) or "no family"
            raise ValueError(f"{name} is an option of {owners}, not of {family.name}")
    query = DbcQuery(
        family=family,
        ids=tuple(dict.fromkeys(ids)),
        revision=family.revision(revision) if revision is not None else None,
        options=given,
        direction=direction,
    )
    described = part.describe(query)
    messages = [m for m in described.messages if direction is None or m.kind == direction]
    nodes = ("host", *(f"motor_{i}" for i in query.ids))
    return Plan(family.name, described.revision, tuple(messages), tuple(described.left_out), nodes)


def signal_table(message: MessageSpec) -> dict[str, Placed]:
    """Every DBC signal of ``message`` by name.

    A signal with one shape (spec) under one multiplexer is one DBC signal, shared by the multiplexer
    values that carry it; a multiplexer is shared by the values whose nested layouts are the same. A
    name is the field's (``speed_dps``, ``currents_a_0``: :func:`dbc_name`). Where several signals have
    one field name (described differently, or under different multiplexers), the one with the fewest
    multiplexer levels above it, then the most multiplexer values, keeps the name (``angle_deg``: int16
    1° in the status replies); each other gets the multiplexer values of its first layout as a suffix
    (``angle_deg_92``: int32 0.01° under 0x92; ``value_C1_1E``: 0xC1's value of parameter 0x1E).
    """
    groups: list[_Group] = []
    by_spec: dict[tuple[int | None, SignalSpec], int] = {}
    muxes: dict[int | None, list[int]] = {}

    def visit(layout: Layout, parent: int | None, path: tuple[int, ...]) -> None:
        for spec in layout.signals:
            k = by_spec.get((parent, spec))
            if k is None:
                k = by_spec[(parent, spec)] = len(groups)
                groups.append(_Group(spec, path, parent))
            if layout.code is not None:
                groups[k].ids.append(layout.code)
        mux = layout.mux
        if mux is None:
            return
        siblings = muxes.setdefault(parent, [])
        k = next((i for i in siblings if groups[i].mux is mux or groups[i].mux == mux), None)
        new = k is None
        if k is None:
            k = len(groups)
            groups.append(_Group(mux.signal, path, parent, mux))
            siblings.append(k)
        if layout.code is not None:
            groups[k].ids.append(layout.code)
        if new:
            for sub in mux.layouts:
                assert sub.code is not None
                visit(sub, k, (*path, sub.code))

    visit(message.root, None, ())
    # The field's own name goes to one signal per name (see _rank; the first of a tie); any other shape
    # of that field is suffixed.
    owner: dict[str, int] = {}
    for k, group in enumerate(groups):
        base = group.spec.base_name
        best = owner.get(base)
        if best is None or _rank(group) > _rank(groups[best]):
            owner[base] = k
    names: list[str] = [""] * len(groups)
    taken = set(owner)
    for base, k in owner.items():
        names[k] = base
    for k, group in enumerate(groups):
        if names[k]:
            continue
        name = group.spec.base_name + "".join(f"_{c:02X}" for c in group.path)
        unique, n = name, 2
        while unique in taken:
            unique, n = f"{name}_{n}", n + 1
        names[k] = unique
        taken.add(unique)
    return {
        name: Placed(
            name,
            group.spec,
            None if group.parent is None else names[group.parent],
            tuple(group.ids),
            None if group.mux is None else group.mux.layouts,
        )
        for name, group in zip(names, groups, strict=True)
    }


def _rank(group: _Group) -> tuple[int, int]:
    """Which of the signals sharing a field name keeps it: the fewest multiplexer levels above it (a
    root signal first), then the most multiplexer values selecting it."""
    return (-len(group.path), len(group.ids))


@dataclass(slots=True)
class _Group:
    """One DBC signal while :func:`signal_table` collects them: its spec, the multiplexer values of its
    first layout, the group it hangs on, the values selecting it (and the multiplexer it is)."""

    spec: SignalSpec
    path: tuple[int, ...]
    parent: int | None
    mux: Mux | None = None
    ids: list[int] = dataclasses.field(default_factory=list)


def database(p: Plan) -> Any:
    """The cantools Database of a :class:`Plan`.

    Raises:
        ImportError: cantools is not installed (``pip install 'servobus[dbc]'``).
    """
    from cantools.database.can import Database, Message, Node

    messages = [
        Message(
            m.frame_id,
            m.name,
            m.length,
            [_signal(placed) for placed in signal_table(m).values()],
            comment=m.comment or None,
            senders=list(m.senders),
            is_extended_frame=m.extended,
            is_fd=m.fd,
        )
        for m in p.messages
    ]
    specifics = _fd_specifics() if any(m.fd for m in p.messages) else None
    return Database(messages=messages, nodes=[Node(n) for n in p.nodes], dbc_specifics=specifics)


def _fd_specifics() -> Any:
    """DBC attributes that make cantools write (and read back) CAN FD messages: BusType "CAN FD"."""
    from cantools.database.can.formats.dbc import DbcSpecifics
    from cantools.database.can.formats.dbc.dbc_attribute import DbcAttribute
    from cantools.database.can.formats.dbc.dbc_attribute_definition import DbcAttributeDefinition

    bus_type = DbcAttributeDefinition("BusType", default_value="", type_name="STRING")
    return DbcSpecifics(
        attributes=OrderedDict(BusType=DbcAttribute("CAN FD", bus_type)),
        attribute_definitions=OrderedDict(BusType=bus_type),
    )


def _signal(placed: Placed) -> Any:
    from cantools.database.can import Signal
    from cantools.database.conversion import BaseConversion
    from cantools.database.namedsignalvalue import NamedSignalValue

    spec = placed.spec
    choices: OrderedDict[int, str | NamedSignalValue] | None = None
    if placed.layouts is not None:
        choices = OrderedDict(
            (layout.code, layout.name) for layout in placed.layouts if layout.code is not None
        )
    elif spec.choices:
        choices = OrderedDict(spec.choices)
    conversion = BaseConversion.factory(
        scale=spec.scale, offset=spec.offset, choices=choices, is_float=spec.is_float
    )
    return Signal(
        placed.name,
        spec.start,
        spec.length,
        byte_order=spec.byte_order,
        is_signed=spec.signed,
        conversion=conversion,
        minimum=spec.minimum,
        maximum=spec.maximum,
        unit=spec.unit or None,
        comment=spec.comment or None,
        is_multiplexer=placed.layouts is not None,
        multiplexer_ids=list(placed.mux_ids) if placed.mux_signal is not None else None,
        multiplexer_signal=placed.mux_signal,
    )


def build_database(
    family: str, ids: Iterable[int], revision: str | enum.Enum | None = None, **options: Any
) -> tuple[Any, list[str]]:
    """A cantools Database of ``family``'s frames for the motors ``ids``, and what it leaves out.

    ``options`` are :func:`plan`'s.

    Raises:
        ValueError: as :func:`plan`.
        ImportError: cantools is not installed (``pip install 'servobus[dbc]'``).
    """
    p = plan(family, ids, revision, **options)
    return database(p), list(p.left_out)


def dbc_text(db: Any) -> str:
    """The database as DBC text."""
    text: str = db.as_dbc_string()
    return text
