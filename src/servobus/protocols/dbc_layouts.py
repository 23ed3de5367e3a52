"""The messages a DBC is made of, and how a family's declarations become them (the DBC contract's
building blocks: a family's ``dbc`` part describes its messages with these; the exporter,
:mod:`servobus.tools.dbc`, places and writes them).

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
field's. Bit-packed payloads (:func:`packed_signals`, :func:`bit_signals`) are
:mod:`servobus.protocols.dbc_packed`'s.

A :class:`MessageSpec` is one identifier's message: a tree of :class:`Layout` s, multiplexed by a
:class:`Mux` on DATA[0] (the signal :data:`MUX`) or on a parameter byte under it.

Layer: protocols (the family contract); imports the C core and the protocols' generic modules only.
"""

from __future__ import annotations

import dataclasses
import enum
import re
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal, TypeAlias

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
from servobus.protocols._message import Command
from servobus.protocols._special import SpecialZero

__all__ = [
    "CONFIG_FIELDS",
    "DIRECTIONS",
    "MUX",
    "UNITS",
    "EnumByte",
    "FlagsByte",
    "Keyed",
    "Layout",
    "MessageSpec",
    "Mux",
    "ResultByte",
    "SignalSpec",
    "dbc_name",
    "enum_choices",
    "fields_layout",
    "in_revision",
    "keyed_layouts",
    "le_signal",
    "message_fields",
    "muxed",
    "reply_keys",
    "request_keys",
    "signal_spec",
]

ByteOrder: TypeAlias = Literal["little_endian", "big_endian"]

MUX = "code"
"""The multiplexer signal on DATA[0]."""
DIRECTIONS = ("request", "reply")
"""A :class:`MessageSpec`'s ``kind``: a frame the host sends, or one a motor sends."""
CONFIG_FIELDS = frozenset({"model", "scales", "motor_type", "encoder_bits"})
"""Fields a message carries to be self-contained, not values of its frame (no signal)."""

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


def unit_of(name: str) -> str:
    name = re.sub(r"\[\d+\]$", "", name)  # an item of a tuple value: currents_a[0]
    return next((unit for suffix, unit in UNITS if name.endswith(suffix)), "")


def le_signal(field: str, offset: int, size: int, **kwargs: Any) -> SignalSpec:
    """A little-endian signal of ``size`` bytes at DATA[offset], its unit from the field's name
    (``kwargs``: the other :class:`SignalSpec` attributes)."""
    return SignalSpec(field, 8 * offset, 8 * size, unit=unit_of(field), **kwargs)


def bool_choices() -> tuple[tuple[int, str], ...]:
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
        return le_signal(name, offset, field.size, choices=bool_choices(), minimum=0, maximum=1)
    if isinstance(field, Float32Field):
        return le_signal(name, offset, field.size, signed=True, is_float=True)
    return None  # AsciiField: text


# ---- message fields ----------------------------------------------------------------------------


def message_fields(message: type) -> list[tuple[str, Any]]:
    """A message class's value fields (its dataclass fields without configuration) and their types."""
    hints = typing.get_type_hints(message)
    return [(f.name, hints[f.name]) for f in dataclasses.fields(message) if f.name not in CONFIG_FIELDS]


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
    """A value as :func:`servobus.tools.logs.message_values` gives it (enums by name, flags as ints)."""
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


def in_revision(cls: type, revision: enum.Enum) -> bool:
    """Whether ``cls`` exists in ``revision``: its declared ``REVISIONS``, or every revision."""
    return revision in getattr(cls, "REVISIONS", (revision,))


def request_keys(commands: Iterable[type[Command]], revision: enum.Enum) -> list[Keyed]:
    """The commands of ``revision`` that have a ``CODE``, each under it."""
    return [Keyed(c.CODE, c, c.__name__) for c in commands if c.CODE is not None and in_revision(c, revision)]


def reply_keys(
    commands: Iterable[type[Command]], revision: enum.Enum, *, echo: type | None = None
) -> list[Keyed]:
    """The replies of ``revision``'s commands (``reply_types()``), each under its DATA[0], once: its own
    ``CODE``; a reply without one is a layout several commands share, under each command's byte; the
    class ``echo`` (a family's "the request's bytes echoed") is the command itself, echoed."""
    out: list[Keyed] = []
    for command in commands:
        code = command.CODE
        if code is None or not in_revision(command, revision):
            continue
        for reply in command.reply_types():
            if echo is not None and reply is echo:
                key = Keyed(code, command, f"Echo_{command.__name__}", echo=True)
            elif not in_revision(reply, revision):
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
