"""A DBC of a family's CAN frames, generated from the codecs' own definitions (cantools: ``servobus[dbc]``).

A DBC signal is a bit range with a byte order, a sign, ``value = raw * factor + offset``, a range and a
unit. Each family's frames are described from what its codec already states, never retyped:

* **MyActuator** (0x140/0x240 + ID, 0x280): the ``FIELDS`` tables of ``(offset, field)`` pairs
  (``protocols/myactuator/_layout.py``) that the decoder tables ``REQUESTS``/``REPLIES`` list per DATA[0]
  and revision; factor, range and unit come from the field object (``ScaledField`` 0.01 A/LSB: factor
  0.01, unit ``A``). **Motion mode** (0x400/0x500 + ID): the C core's ``MIT_COMMAND``/``MIT_REPLY``
  packers with the revision's :class:`~servobus.protocols.myactuator.MotionScales` (``--max-torque``
  for V4.4's model-specific torque range).
* **hollow**: the C core's packers of the motor model (``hollow.model.packers``): ``HOLLOW_SETPOINT``
  and ``MIT_REPLY`` (normal mode), ``HOLLOW_SETPOINT`` and ``HOLLOW_EXT_REPLY`` (extended mode),
  ``HOLLOW_FD_COMMAND``/``HOLLOW_FD_REPLY`` (CAN FD, 16 bytes). The extended-id frames (CAN mode switch,
  PI multiplier) are laid out in their classes' code; :func:`hollow_config` states them here.
* **LK** (V2.36 and V2.35): the field objects of ``protocols/lk`` (``SPEED``, ``TEMPERATURE``, the
  ``IqSlot`` of the motor type, the parameter ``*_LAYOUTS``) at the offsets their classes write in
  ``encode``/``decode``. Those offsets are in code, not tables, so :func:`lk_fields` states them once;
  ``tests/test_dbc_export.py`` decodes frames of every LK class both ways and compares every field.

A C-core field is bit-packed (MIT: a float in [lo, hi] onto an n-bit code, ``code = (x - lo) *
(2**n - 1) / (hi - lo)``, i.e. factor ``(hi - lo) / (2**n - 1)``, offset ``lo``). Its bit positions are
not copied from the C source: :func:`packed_signals` packs one bit of one field at a time through the
C core and reads where it lands, so the DBC places every bit where ``servobus._core`` does. A field
whose bits are not one big-endian run (hollow's extended-mode position: DATA[1..2] low half, DATA[6..7]
high half) becomes one signal per run, ``position_deg_b0`` and ``position_deg_b16``, whose values add
up to the field's.

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

What a DBC cannot say is left out, and :func:`plan` names it with the reason: text fields, layouts
decoded by rules of their own, two layouts under one identifier and DATA[0] (or, LK V2.35, requests and
replies on one identifier), hollow's special commands (a 7-byte pattern, not a multiplexer value) and
the frames of its other CAN modes.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import re
import typing
from collections import OrderedDict
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, TypeAlias

from servobus.core import FieldScale, Packer
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._special import SpecialZero

__all__ = [
    "DIRECTIONS",
    "FAMILIES",
    "HOLLOW_CAN_MODES",
    "MUX",
    "OPTIONS",
    "Layout",
    "MessageSpec",
    "Mux",
    "Placed",
    "Plan",
    "SignalSpec",
    "build_database",
    "database",
    "dbc_name",
    "dbc_text",
    "hollow_config",
    "lk_fields",
    "packed_signals",
    "plan",
    "signal_spec",
    "signal_table",
]

ByteOrder: TypeAlias = Literal["little_endian", "big_endian"]

#: The multiplexer signal on DATA[0].
MUX = "code"
FAMILIES = ("myactuator", "lk", "hollow")
DIRECTIONS = ("request", "reply")
HOLLOW_CAN_MODES = ("normal", "extended", "fd")
#: The options of :func:`plan` each family takes.
OPTIONS: Mapping[str, frozenset[str]] = {
    "myactuator": frozenset({"max_torque_nm"}),
    "lk": frozenset({"model", "encoder_bits"}),
    "hollow": frozenset({"model", "can_mode", "host_id"}),
}
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


def _le(field: str, offset: int, size: int, **kwargs: Any) -> SignalSpec:
    """A little-endian signal of ``size`` bytes at DATA[offset]."""
    return SignalSpec(field, 8 * offset, 8 * size, unit=_unit(field), **kwargs)


def _bool_choices() -> tuple[tuple[int, str], ...]:
    return ((0, "False"), (1, "True"))


def _enum_choices(enum_cls: type[enum.Enum]) -> tuple[tuple[int, str], ...]:
    return tuple((int(member.value), member.name) for member in enum_cls)


# ---- field objects -> signals ------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class EnumByte:
    """An IntEnum carried as an unsigned integer of ``size`` bytes (LK's state and selector bytes)."""

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
    """A status byte whose values map to named results (LK's opposite write/save polarities)."""

    name: str
    table: Mapping[int, enum.Enum]


def signal_spec(offset: int, field: Any, name: str | None = None) -> SignalSpec | None:
    """The little-endian signal of a field object at DATA[offset] (``name`` renames it), or None if a DBC
    signal cannot carry it (text)."""
    from servobus.protocols.myactuator import _layout as lay

    comment = ""
    none_raw = None
    if isinstance(field, SpecialZero):
        comment = f"raw {field.raw} {field.meaning}"
        none_raw = field.raw if field.explicit else None
        field = field.inner
    name = name or field.name
    if isinstance(field, EnumByte):
        return _le(name, offset, field.size, choices=_enum_choices(field.enum))
    if isinstance(field, FlagsByte):
        flags = ", ".join(f"{m.name}=0x{int(m):X}" for m in field.flags if m.name and int(m))
        return _le(name, offset, 1, minimum=0, maximum=255, comment=f"flags: {flags}")
    if isinstance(field, ResultByte):
        return _le(name, offset, 1, choices=tuple((raw, r.name) for raw, r in sorted(field.table.items())))
    common: dict[str, Any] = {"comment": comment, "none_raw": none_raw}
    if isinstance(field, ScaledField):
        lo, hi = field.limits
        return _le(
            name,
            offset,
            field.size,
            signed=field.signed,
            scale=1.0 / field.counts_per_unit,
            minimum=lo,
            maximum=hi,
            **common,
        )
    if isinstance(field, IntField | lay.StepField):
        lo, hi = field.limits
        scale = float(field.step) if isinstance(field, lay.StepField) else 1.0
        signed = isinstance(field, IntField) and field.signed
        return _le(name, offset, field.size, signed=signed, scale=scale, minimum=lo, maximum=hi, **common)
    if isinstance(field, lay.EnumField | lay.OpenEnumField):
        return _le(name, offset, field.size, choices=tuple((int(m), m.name) for m in field.enum))
    if isinstance(field, lay.FlagsField):
        flags = ", ".join(f"{m.name}=0x{int(m):X}" for m in field.flags if m.name and int(m))
        return _le(name, offset, field.size, comment=f"flags: {flags}")
    if isinstance(field, lay.BoolField):
        return _le(name, offset, field.size, choices=_bool_choices(), minimum=0, maximum=1)
    if isinstance(field, lay.Float32Field):
        return _le(name, offset, field.size, signed=True, is_float=True)
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


def packed_signals(packer: Packer, message: type) -> tuple[SignalSpec, ...]:
    """The signals of a C-core packer's frame, named after ``message``'s fields (in layout order).

    Factor and offset come from each field's :class:`~servobus.core.FieldScale` (``span / codes`` and
    ``origin``), the range from its limits and code range, choices from the message field's type (an
    IntEnum, or bool), the bit positions from :func:`_bit_positions`.

    Raises:
        ValueError: the message's fields do not match the layout's.
    """
    layout = packer.layout
    fields = message_fields(message)
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
            choices = _enum_choices(kind)
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


# ---- MyActuator ---------------------------------------------------------------------------------


def _myactuator(
    ids: Sequence[int], revision: Any, max_torque_nm: float | None, direction: str | None
) -> Plan:
    from servobus.protocols.myactuator import FAMILY, MotionCommand, MotionReply, MotionScales
    from servobus.protocols.myactuator.codec import REPLIES, REQUESTS
    from servobus.protocols.myactuator.ids import (
        BROADCAST_ID,
        motion_reply_id,
        motion_request_id,
        reply_id,
        request_id,
    )
    from servobus.protocols.myactuator.motion import command_packer, reply_packer

    rev = FAMILY.revision(revision) if revision is not None else FAMILY.default_revision
    scales = MotionScales.for_revision(typing.cast(Any, rev), max_torque_nm=max_torque_nm)
    left_out: list[str] = []
    requests = _myactuator_table(REQUESTS, rev, "request", left_out)
    replies = _myactuator_table(REPLIES, rev, "reply", left_out)
    command = Layout(None, "", packed_signals(command_packer(scales), MotionCommand), message="MotionCommand")
    reply = Layout(None, "", packed_signals(reply_packer(scales), MotionReply), message="MotionReply")
    ranges = (
        f"p ±{scales.p_max_rad} rad, v ±{scales.v_max_rad_s} rad/s, kp 0..{scales.kp_max}, "
        f"kd 0..{scales.kd_max}, t ±{scales.t_max_nm} Nm"
    )
    messages = []
    for motor_id in ids:
        motor = f"motor_{motor_id}"
        # DATA[0] of a motion reply is the motor's id, the one of its identifier (checked on decode).
        own = tuple(
            dataclasses.replace(s, minimum=motor_id, maximum=motor_id) if s.field == "motor_id" else s
            for s in reply.signals
        )
        for ident, name, kind, root, sender, comment in (
            (request_id(motor_id), "request", "request", _muxed(requests), "host", "requests"),
            (reply_id(motor_id), "reply", "reply", _muxed(replies), motor, "replies"),
            (motion_request_id(motor_id), "motion_command", "request", command, "host", "motion commands"),
            (
                motion_reply_id(motor_id),
                "motion_reply",
                "reply",
                dataclasses.replace(reply, signals=own),
                motor,
                "motion replies",
            ),
        ):
            text = f"MyActuator {rev.name} {comment} of motor {motor_id}"
            text += f" ({ranges})" if name.startswith("motion") else ", multiplexed on DATA[0]"
            messages.append(
                MessageSpec(
                    ident, f"myactuator_{name}_{motor_id}", 8, kind, root, (sender,), text, motor_id=motor_id
                )
            )
    messages.append(
        MessageSpec(
            BROADCAST_ID,
            "myactuator_broadcast",
            8,
            "request",
            _muxed(requests),
            ("host",),
            f"MyActuator {rev.name} multi-motor requests (every motor replies on 0x240 + ID)",
        )
    )
    return _finish("myactuator", rev, messages, left_out, ids, direction)


def _myactuator_table(
    table: Mapping[int, Iterable[Any]], revision: enum.Enum, what: str, left_out: list[str]
) -> tuple[Layout, ...]:
    from servobus.protocols.myactuator._layout import Fixed

    out: list[Layout] = []
    for code, candidates in sorted(table.items()):
        here = [c for c in candidates if revision in c.revisions]
        if not here:
            continue
        names = [_myactuator_name(c, what) for c in here]
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
        echo = name.startswith("Echo_")
        prefix = "command." if echo else ""
        signals: list[SignalSpec] = []
        implies: list[tuple[str, Any]] = [("command", cls.__name__)] if echo else []
        for offset, field in cls.FIELDS:
            if offset == 0:  # DATA[0] is the multiplexer (the R2 status reply's ``command``)
                implies.append((prefix + field.name, _scalar(field.decode(bytes([code]), 0))))
                continue
            spec = signal_spec(offset, field, prefix + field.name)
            if spec is None:
                left_out.append(
                    f"{what} 0x{code:02X} ({name}): field {field.name!r} is ASCII text, not a number"
                )
                break
            signals.append(spec)
        else:
            message = "Echo" if echo else cls.__name__
            out.append(
                Layout(
                    code, name, tuple(signals), tuple(cls.CONSTANTS), message=message, implies=tuple(implies)
                )
            )
    return tuple(out)


def _myactuator_name(candidate: Any, what: str) -> str:
    cls = candidate.message
    is_echo = what == "reply" and getattr(candidate.decode, "__func__", None) is None
    return f"Echo_{cls.__name__}" if is_echo else str(cls.__name__)


def _scalar(value: Any) -> Any:
    """A decoded value as :func:`servobus.logs.message_values` gives it (enums by name, flags as int)."""
    if isinstance(value, enum.Flag):
        return int(value.value)
    if isinstance(value, enum.Enum):
        return value.name
    return value


def _muxed(layouts: tuple[Layout, ...]) -> Layout:
    """A root whose DATA[0] multiplexes ``layouts``.

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


# ---- LK -----------------------------------------------------------------------------------------


def _iq(slot: Any, motor_type: Any, limits: tuple[int, int] | None = None) -> Any:
    """The field an LK ``IqSlot`` is for ``motor_type``: amperes (MF, MG) or raw counts under the slot's
    name for the type, within ``limits`` (default: the slot's); None if the type does not carry it."""
    lo, hi = limits if limits is not None else slot.limits
    amps = slot.field(motor_type, (lo, hi))
    if amps is not None:
        return amps
    name = slot.counts_names.get(motor_type)
    return None if name is None else IntField(name, size=2, signed=True, lo=lo, hi=hi)


def _items(field: Any, count: int) -> list[Any]:
    """``field`` as the items of a tuple value: ``currents_a[0]``, ``currents_a[1]``..."""
    return [dataclasses.replace(field, name=f"{field.name}[{i}]") for i in range(count)]


def _param_layouts(params: type[enum.IntEnum], layouts: Mapping[Any, Any] | None) -> tuple[Layout, ...]:
    """One layout per parameter of ``params`` (the value signals of its ``ValueLayout``)."""
    return tuple(
        Layout(int(p), p.name, _value_signals(layouts[p]) if layouts else (), implies=(("param", p.name),))
        for p in params
    )


def _value_signals(layout: Any) -> tuple[SignalSpec, ...]:
    """The signals of an LK parameter ``ValueLayout`` (``params.py``): PID gains, an integer, a choice."""
    from servobus.protocols.lk import params as lkp

    if isinstance(layout, lkp._Pid):
        return tuple(
            _le(f"value.{gain}", offset, 2, minimum=0, maximum=layout.hi)
            for gain, offset in (("kp", 2), ("ki", 4), ("kd", 6))
        )
    if isinstance(layout, lkp._Int):
        field = IntField("value", size=layout.size, signed=layout.signed, lo=layout.lo, hi=layout.hi)
        spec = signal_spec(layout.offset, field)
    elif isinstance(layout, lkp._Choice):
        spec = signal_spec(layout.offset, EnumByte("value", layout.enum_cls))
    else:  # pragma: no cover - a new ValueLayout kind: describe it here
        raise TypeError(f"no signal for the LK parameter layout {layout!r}")
    assert spec is not None
    return (spec,)


def _setting_mux(with_values: bool) -> Mux:
    """V2.36 setting parameters: DATA[1] is a group (0x05: single values, addressed by DATA[2]; 0xA0,
    0xA4, 0xA8: PID groups, values from DATA[2]) (spec §6.2, ``params.decode_setting_address``)."""
    from servobus.protocols.lk.params import SETTING_LAYOUTS, SettingParam

    singles = [p for p in SettingParam if p >> 8 == 0x05]
    single_layouts = tuple(
        Layout(
            p & 0xFF,
            p.name,
            _value_signals(SETTING_LAYOUTS[p]) if with_values else (),
            implies=(("param", p.name),),
        )
        for p in singles
    )
    groups = [
        Layout(
            0x05,
            "SINGLE_VALUE",
            mux=Mux(_le("param", 2, 1, choices=_choices(single_layouts)), single_layouts),
        )
    ]
    for p in SettingParam:
        if p >> 8 != 0x05:
            signals = _value_signals(SETTING_LAYOUTS[p]) if with_values else ()
            groups.append(Layout(p >> 8, p.name, signals, implies=(("param", p.name),)))
    layouts = tuple(groups)
    return Mux(_le("param_group", 1, 1, choices=_choices(layouts)), layouts)


def _param_mux(params: type[enum.IntEnum], layouts: Mapping[Any, Any] | None) -> Mux:
    """A parameter byte at DATA[1] multiplexing each parameter's value layout."""
    subs = _param_layouts(params, layouts)
    return Mux(_le("param", 1, 1, choices=_choices(subs)), subs)


def _choices(layouts: Iterable[Layout]) -> tuple[tuple[int, str], ...]:
    return tuple((layout.code, layout.name) for layout in layouts if layout.code is not None)


def lk_fields(cls: type, code: int | None, model: Any) -> tuple[tuple[Any, ...], Mux | None, str | None]:
    """Where an LK message class puts its fields, for ``model``: ``(offset, field object)`` pairs, a
    parameter multiplexer under DATA[0] (or None), and why the class cannot be described (or None).

    The offsets are those the classes' ``encode``/``decode`` write (spec §4, §6, §8); the field objects
    are the LK modules' own, so scales and ranges are the codec's.
    """
    from servobus.protocols.lk import commands as cmd
    from servobus.protocols.lk import commands_control as ctl
    from servobus.protocols.lk import params as lkp
    from servobus.protocols.lk import params_v235 as p235
    from servobus.protocols.lk import params_v236 as p236
    from servobus.protocols.lk import replies as rep
    from servobus.protocols.lk import replies_position as rpos
    from servobus.protocols.lk import states
    from servobus.protocols.lk.model import encoder_max_count

    motor_type = model.motor_type

    def encoder(name: str) -> IntField:
        return IntField(name, size=2, hi=encoder_max_count(model.encoder_bits))

    def iq(slot: Any, limits: tuple[int, int] | None = None) -> Any:
        field = _iq(slot, motor_type, limits)
        return (
            _NotCarried(f"{slot.amps_name}: {motor_type.name} motors do not carry it")
            if field is None
            else field
        )

    def items(field: Any, count: int) -> list[Any]:
        return [field] * count if isinstance(field, _NotCarried) else _items(field, count)

    direction = EnumByte("direction", states.SpinDirection)
    # The status-2 shape's DATA[2..3] depends on the command byte too: what it is (0xA0's power on every
    # motor type, ``replies.status2_slot``) and its range (``replies.torque_range``).
    status2_iq = rep.torque_range(model.revision, motor_type, code) if code is not None else None
    status2_slot = rep.status2_slot(code) if code is not None else rep.REPLY_IQ
    table: dict[type, tuple[Any, ...] | Mux] = {
        rep.Status2Reply: (
            (1, rep.TEMPERATURE),
            (2, iq(status2_slot, status2_iq)),
            (4, rep.REPLY_SPEED),
            (6, encoder("encoder_counts")),
        ),
        cmd.BrakeControl: ((1, EnumByte("action", states.BrakeAction)),),
        cmd.WriteEncoderOffset: ((cmd.ENCODER_OFFSET_AT, encoder("offset_counts")),),
        cmd.WriteAcceleration: ((4, cmd.ACCELERATION),),
        ctl.OpenLoopControl: ((4, ctl.POWER),),
        ctl.TorqueControl: ((4, iq(ctl.TORQUE)),),
        ctl.SpeedControl: ((2, iq(ctl.TORQUE_LIMIT)), (4, ctl.SPEED)),
        ctl.SpeedControlV235: ((4, ctl.SPEED),),
        ctl.MultiTurnPosition: ((4, ctl.ANGLE),),
        ctl.MultiTurnPositionSpeed: ((2, ctl.MAX_SPEED), (4, ctl.ANGLE)),
        ctl.SingleTurnPosition: ((1, direction), (4, ctl.SINGLE_TURN)),
        ctl.SingleTurnPositionV235: ((1, direction), (4, ctl.SINGLE_TURN_V235)),
        ctl.SingleTurnPositionSpeed: ((1, direction), (2, ctl.MAX_SPEED), (4, ctl.SINGLE_TURN)),
        ctl.SingleTurnPositionSpeedV235: ((1, direction), (2, ctl.MAX_SPEED), (4, ctl.SINGLE_TURN_V235)),
        ctl.IncrementalPosition: ((4, ctl.INCREMENT),),
        ctl.IncrementalPositionSpeed: ((2, ctl.MAX_SPEED), (4, ctl.INCREMENT)),
        ctl.MultiMotorTorque: tuple(zip((0, 2, 4, 6), items(iq(ctl.MULTI_TORQUE), 4), strict=True)),
        p236.ReadControlParam: ((1, EnumByte("param", lkp.ControlParam)),),
        p236.WriteControlParam: _param_mux(lkp.ControlParam, lkp.CONTROL_LAYOUTS),
        p236.ControlParamReply: _param_mux(lkp.ControlParam, lkp.CONTROL_LAYOUTS),
        p236.ReadSetting: _setting_mux(with_values=False),
        p236.WriteSetting: _setting_mux(with_values=True),
        p236.SettingReply: _setting_mux(with_values=True),
        p236.SaveSettingsReply: ((2, ResultByte("result", lkp.SAVE_RESULT)),),
        p235.ReadParam: ((1, EnumByte("param", lkp.ParamId)),),
        p235.WriteParamRam: _param_mux(lkp.ParamId, lkp.PARAM_LAYOUTS),
        p235.WriteParamRom: _param_mux(lkp.ParamId, lkp.PARAM_LAYOUTS),
        p235.ParamReply: _param_mux(lkp.ParamId, lkp.PARAM_LAYOUTS),
        p235.ParamWriteReply: (
            (1, EnumByte("param", lkp.ParamId)),
            (2, ResultByte("result", lkp.WRITE_RESULT_V235)),
        ),
        rep.Status1Reply: (
            (1, rep.TEMPERATURE),
            (2, rep.VOLTAGE),
            (4, rep.BUS_CURRENT),
            (6, EnumByte("motor_state", states.MotorState)),
            (7, FlagsByte("error_state", states.ErrorState)),
        ),
        rep.Status1ReplyV235: (
            (1, rep.TEMPERATURE),
            (3, rep.VOLTAGE_V235),
            (7, FlagsByte("error_state", states.ErrorStateV235)),
        ),
        rep.Status3Reply: ((1, rep.TEMPERATURE), *zip((2, 4, 6), items(iq(rep.PHASE), 3), strict=True)),
        rep.Status3ReplyV235: tuple(zip((2, 4, 6), _items(rep.PHASE_V235, 3), strict=True)),
        rep.BrakeReply: ((1, EnumByte("state", states.BrakeState)),),
        rpos.EncoderReply: (
            (2, encoder("encoder_counts")),
            (4, encoder("raw_counts")),
            (6, encoder("offset_counts")),
        ),
        rpos.CalibrationReply: (
            (1, rpos.ALIGN_VALUE),
            (5, rpos.ALIGN_RATIO),
            (7, FlagsByte("align_state", states.AlignState)),
        ),
        rpos.EncoderOffsetReply: ((6, encoder("offset_counts")),),
        rpos.MultiTurnAngleReply: ((1, rpos.MULTI_TURN),),
        rpos.SingleTurnAngleReply: ((4, rpos.CIRCLE),),
        rpos.SingleTurnAngleReplyV235: ((6, rpos.CIRCLE_V235),),
        rpos.AccelerationReply: ((4, rpos.ACCELERATION),),
    }
    entry = table.get(cls, ())
    if isinstance(entry, Mux):
        return (), entry, None
    missing = next((f for _, f in entry if isinstance(f, _NotCarried)), None)
    if missing is not None:
        return (), None, missing.why
    return entry, None, None


@dataclass(frozen=True, slots=True)
class _NotCarried:
    """A field the motor type does not carry (MS has no torque loop): the class is left out."""

    why: str


#: Fixed bytes of LK layouts (spec §4.29): 0x44 ``05 FA`` (request) and ``05 flag`` (reply).
LK_CONSTANTS: Mapping[str, tuple[tuple[int, int], ...]] = {
    "SaveSettings": ((1, 0x05), (2, 0xFA)),
    "SaveSettingsReply": ((1, 0x05),),
}


def _lk_layout(cls: type, code: int, model: Any, what: str, left_out: list[str]) -> Layout | None:
    fields, mux, why = lk_fields(cls, code, model)
    name = cls.__name__
    if why is not None:
        left_out.append(f"{what} 0x{code:02X} ({name}): {why}")
        return None
    signals = []
    for offset, field in fields:
        spec = signal_spec(offset, field)
        assert spec is not None  # LK has no text fields
        signals.append(spec)
    implies = (("command", code),) if "command" in {f.name for f in dataclasses.fields(cls)} else ()
    return Layout(code, name, tuple(signals), LK_CONSTANTS.get(name, ()), mux, message=name, implies=implies)


def _lk(
    ids: Sequence[int], revision: Any, model: Any, encoder_bits: int | None, direction: str | None
) -> Plan:
    from servobus.protocols.lk import FAMILY
    from servobus.protocols.lk import commands_control as ctl
    from servobus.protocols.lk.codec import REPLY_CLASSES, REQUESTS, resolve_model
    from servobus.protocols.lk.ids import MULTI_MOTOR_ID, reply_id, request_id
    from servobus.protocols.lk.model import LkModel, MotorType, Revision

    rev = FAMILY.revision(revision) if revision is not None else None
    if isinstance(model, str):
        try:
            motor_type = MotorType[model.upper()]
        except KeyError:
            raise ValueError(f"lk has no motor type {model!r} (known: MS, MF, MH, MG)") from None
        model = LkModel(
            revision=rev or Revision.V2_36, motor_type=motor_type, encoder_bits=encoder_bits or 14
        )
    elif model is None:
        model = LkModel(revision=rev or Revision.V2_36, encoder_bits=encoder_bits or 14)
    elif encoder_bits is not None and encoder_bits != model.encoder_bits:
        raise ValueError(f"encoder_bits={encoder_bits} contradicts model.encoder_bits={model.encoder_bits}")
    model = resolve_model(rev, model)
    rev = model.revision
    left_out: list[str] = []
    requests = tuple(
        layout
        for code, cls in sorted(REQUESTS[rev].items())
        if (layout := _lk_layout(cls, code, model, "request", left_out)) is not None
    )
    replies = tuple(
        layout
        for code, cls in sorted(REPLY_CLASSES[rev].items())
        if (layout := _lk_layout(cls, code, model, "reply", left_out)) is not None
    )
    what = f"LK {rev.name} ({model.motor_type.name}, {model.encoder_bits}-bit encoder)"
    # V2.35 replies come on the request's identifier (spec §1.1): one DBC holds one of the two.
    shared = rev is Revision.V2_35 and direction is None
    if shared:
        left_out.append(
            "requests on 0x140+ID: V2.35 motors reply on the request's identifier and a DBC has one message "
            "per identifier, so 0x140+ID describes the replies (a request frame there decodes as a reply); "
            "--direction request gives the requests' DBC"
        )
    messages = []
    for motor_id in ids:
        motor = f"motor_{motor_id}"
        if not shared:
            messages.append(
                MessageSpec(
                    request_id(motor_id),
                    f"lk_request_{motor_id}",
                    8,
                    "request",
                    _muxed(requests),
                    ("host",),
                    f"{what} requests to motor {motor_id}, multiplexed on DATA[0]",
                    motor_id=motor_id,
                )
            )
        messages.append(
            MessageSpec(
                reply_id(motor_id, rev),
                f"lk_reply_{motor_id}",
                8,
                "reply",
                _muxed(replies),
                (motor,),
                f"{what} replies of motor {motor_id}, multiplexed on DATA[0]",
                motor_id=motor_id,
            )
        )
    if rev in ctl.MultiMotorTorque.REVISIONS:
        fields, _, why = lk_fields(ctl.MultiMotorTorque, None, model)
        if why is not None:
            left_out.append(f"request id 0x280 (MultiMotorTorque): {why}")
        else:
            signals = tuple(s for offset, f in fields if (s := signal_spec(offset, f)) is not None)
            messages.append(
                MessageSpec(
                    MULTI_MOTOR_ID,
                    "lk_multi_motor",
                    8,
                    "request",
                    Layout(None, "", signals, message="MultiMotorTorque"),
                    ("host",),
                    f"{what} torque set-points of motors 1..4 (layout inferred, spec §5); each replies "
                    "on 0x140+ID with a 0xA1 status-2 reply",
                )
            )
    return _finish("lk", rev, messages, left_out, ids, direction)


# ---- hollow -------------------------------------------------------------------------------------


@functools.cache
def hollow_config() -> Mux:
    """The hollow extended-id frames (§5.1, §6), laid out in ``CanModeSwitch``/``PiMultiplier`` code:
    DATA[1] tells them apart (0: the mode switch, whose D0 bit 1 is the mode; 1..4: the PI gain whose
    multiplier is a big-endian float32 at DATA[2..5]), as ``commands.decode_extended_request`` does."""
    from servobus.protocols.hollow import CanMode, PiGain

    mode = SignalSpec("mode", 1, 1, choices=_enum_choices(CanMode))  # D0 bit 1 (§5.1, A4)
    multiplier = SignalSpec("multiplier", 8 * 2 + 7, 32, "big_endian", signed=True, is_float=True, minimum=0)
    layouts = [Layout(0, "CanModeSwitch", (mode,), message="CanModeSwitch")]
    layouts += [
        Layout(
            int(g),
            f"PiMultiplier_{g.name}",
            (multiplier,),
            message="PiMultiplier",
            implies=(("gain", g.name),),
        )
        for g in PiGain
    ]
    return Mux(SignalSpec("gain", 8, 8), tuple(layouts))


def _hollow(
    ids: Sequence[int],
    revision: Any,
    model: Any,
    can_mode: str | None,
    host_id: int | None,
    direction: str | None,
) -> Plan:
    from servobus.protocols import hollow as ho
    from servobus.protocols.hollow.ids import check_host_id, check_motor_id
    from servobus.protocols.hollow.model import packers

    rev = ho.FAMILY.revision(revision) if revision is not None else ho.FAMILY.default_revision
    if model is None:
        model = ho.DEFAULT_MODEL
    elif isinstance(model, str):
        if model not in ho.MODELS:
            raise ValueError(f"hollow has no model {model!r} (known: {', '.join(ho.MODELS)})")
        model = ho.MODELS[model]
    mode = can_mode or "normal"
    if mode not in HOLLOW_CAN_MODES:
        raise ValueError(f"can_mode={mode!r} is not one of {', '.join(HOLLOW_CAN_MODES)}")
    host = check_host_id(ho.DEFAULT_HOST_ID if host_id is None else host_id)
    for motor_id in ids:
        check_motor_id(motor_id)
    if host in ids:
        raise ValueError(f"motor id {host} is the host id the replies go to: give another --host-id")
    p = packers(model)
    left_out = [
        "RS-485 converter frames (transparent, Modbus RTU, configuration): serial frames, not CAN",
    ]
    if mode == "fd":
        request = ("fd_command", 16, packed_signals(p.fd_command, ho.FdCommand), "FdCommand")
        reply = ("fd_reply", 16, packed_signals(p.fd_reply, ho.FdReply), "FdReply")
    else:
        left_out.append(
            "special commands FF x7 + F9..FE (Start, Stop, SelectMode, SetZero): told apart from a setpoint "
            "by a 7-byte pattern, not a multiplexer value; the DBC reads them as setpoints"
        )
        if mode == "normal":
            request = ("setpoint", 8, packed_signals(p.setpoint, ho.Setpoint), "Setpoint")
            reply = ("reply", 6, packed_signals(p.normal_reply, ho.NormalReply), "NormalReply")
        else:
            request = (
                "increment",
                8,
                packed_signals(p.setpoint, ho.IncrementalSetpoint),
                "IncrementalSetpoint",
            )
            reply = ("ext_reply", 8, packed_signals(p.extended_reply, ho.ExtendedReply), "ExtendedReply")
            left_out.append(
                "ExtendedReply position_deg as one signal: its 32-bit code is split (low half DATA[1..2], "
                "high half DATA[6..7]), so it is two signals whose values add up to it (position_deg_b0 + "
                "position_deg_b16)"
            )
    others = [m for m in HOLLOW_CAN_MODES if m != mode]
    left_out.append(
        f"the {' and '.join(others)} frames: they use the same identifiers (the motor id for requests, the "
        "host id for replies) and a DBC has one message per identifier; --can-mode gives their DBC"
    )
    what = f"hollow {rev.name} ({model.name} model"
    if mode != "fd":
        what += f": ±{model.position_full_scale_deg} deg, ±{model.speed_full_scale_rad_s} rad/s, "
        what += f"±{model.current_full_scale_a} A)"
    else:
        what += f", {model.pole_pairs} pole pairs)"
    fd = mode == "fd"
    messages = []
    config = Layout(None, "", mux=hollow_config())
    for motor_id in ids:
        name, length, signals, message = request
        messages.append(
            MessageSpec(
                motor_id,
                f"hollow_{name}_{motor_id}",
                length,
                "request",
                Layout(None, "", signals, message=message),
                ("host",),
                f"{what} {mode}-mode {message} to motor {motor_id}",
                fd=fd,
                motor_id=motor_id,
            )
        )
        messages.append(
            MessageSpec(
                motor_id,
                f"hollow_config_{motor_id}",
                8,
                "request",
                config,
                ("host",),
                f"hollow CAN mode switch and PI multiplier frames to motor {motor_id} (extended id), "
                "multiplexed on DATA[1]",
                extended=True,
                motor_id=motor_id,
            )
        )
    name, length, signals, message = reply
    messages.append(
        MessageSpec(
            host,
            f"hollow_{name}",
            length,
            "reply",
            Layout(None, "", signals, message=message),
            tuple(f"motor_{i}" for i in ids),
            f"{what} {mode}-mode replies of every motor, on the host id (the motor id is in the frame)",
            fd=fd,
        )
    )
    return _finish("hollow", rev, messages, left_out, ids, direction)


# ---- plans and databases ------------------------------------------------------------------------


def _finish(
    family: str,
    revision: enum.Enum,
    messages: list[MessageSpec],
    left_out: list[str],
    ids: Sequence[int],
    direction: str | None,
) -> Plan:
    if direction is not None:
        messages = [m for m in messages if m.kind == direction]
    nodes = ("host", *(f"motor_{i}" for i in ids))
    return Plan(family, revision, tuple(messages), tuple(left_out), nodes)


def plan(
    family: str,
    ids: Iterable[int],
    revision: str | enum.Enum | None = None,
    *,
    model: Any = None,
    encoder_bits: int | None = None,
    can_mode: str | None = None,
    host_id: int | None = None,
    max_torque_nm: float | None = None,
    direction: str | None = None,
) -> Plan:
    """What the DBC of ``family``'s motors ``ids`` holds, and what it leaves out.

    Args:
        family: ``myactuator``, ``lk`` or ``hollow``.
        ids: the motors' ids.
        revision: the protocol revision (default: the family's).
        model: LK: an ``LkModel`` or a motor type name (MS, MF, MH, MG; default MG); hollow: a
            ``HollowModel`` or a name of ``hollow.MODELS`` (default ``default``).
        encoder_bits: LK: the encoder width (14, 15, 16, 18; default 14).
        can_mode: hollow: ``normal`` (default), ``extended`` or ``fd``: which frames share the ids.
        host_id: hollow: the identifier replies go to (default 100).
        max_torque_nm: MyActuator V4.4: the motor's max torque, the motion-mode torque range.
        direction: ``request`` or ``reply`` for only those messages (default both; LK V2.35: replies).

    Raises:
        ValueError: an unknown family, revision, model or option, an option of another family, or a
            motor id the family does not accept.
    """
    if family not in FAMILIES:
        raise ValueError(f"no family {family!r} (known: {', '.join(FAMILIES)})")
    if direction is not None and direction not in DIRECTIONS:
        raise ValueError(f"direction={direction!r} is not one of {', '.join(DIRECTIONS)}")
    given = {
        "model": model,
        "encoder_bits": encoder_bits,
        "can_mode": can_mode,
        "host_id": host_id,
        "max_torque_nm": max_torque_nm,
    }
    for option, value in given.items():
        if value is not None and option not in OPTIONS[family]:
            owners = " and ".join(f for f in FAMILIES if option in OPTIONS[f])
            raise ValueError(f"{option} is an option of {owners}, not of {family}")
    ids = list(dict.fromkeys(ids))
    if family == "myactuator":
        return _myactuator(ids, revision, max_torque_nm, direction)
    if family == "lk":
        return _lk(ids, revision, model, encoder_bits, direction)
    return _hollow(ids, revision, model, can_mode, host_id, direction)


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
