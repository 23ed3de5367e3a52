"""Bit-packed payloads as DBC signals: a C-core packer's frame (:func:`packed_signals`) and a
declared :class:`~servobus.protocols.bits.BitLayout` (:func:`bit_signals`).

A bit-packed field (MIT: a float in [lo, hi] onto an n-bit code, ``code = (x - lo) * (2**n - 1) /
(hi - lo)``, i.e. factor ``(hi - lo) / (2**n - 1)``, offset ``lo``) is a big-endian signal. A C-core
packer's bit positions are not copied from the C source: :func:`packed_signals` packs one bit of one
field at a time through the C core and reads where it lands, so the DBC places every bit where
``servobus._core`` does; a declaration states them (:func:`bit_signals`). A field whose bits are not
one big-endian run becomes one signal per run (``position_deg_b0``, ``position_deg_b16``), whose
values add up to the field's.

Layer: protocols (the family contract).
"""

from __future__ import annotations

import enum
import functools
import typing
from collections.abc import Iterable, Sequence
from typing import Any

from servobus.core import FieldScale, Packer
from servobus.protocols.bits import BitField, BitLayout
from servobus.protocols.dbc_layouts import SignalSpec, bool_choices, enum_choices, message_fields, unit_of

__all__ = ["bit_signals", "packed_signals"]


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
    return _code_signals(
        zip(fields, packer.scales, layout.bits, _bit_positions(layout, packer.stride), strict=True)
    )


def bit_signals(message: type[BitLayout], model: Any = None) -> tuple[SignalSpec, ...]:
    """The signals of a :class:`~servobus.protocols.bits.BitLayout` payload, from its declaration:
    each field's bits, and its scale for ``model`` (None: the class's default model). Constant bits
    (a payload's identity) are no signal. What :func:`packed_signals` gives a C-core packer's frame."""
    if model is None:
        model = message.default_model()
    hints = typing.get_type_hints(message)
    rows = []
    for spec in message.FIELDS:
        if not isinstance(spec, BitField):
            continue
        scale = spec.scale_for(model)
        width = spec.width
        bits = -width if spec.code_range(scale)[0] < 0 else width
        # (the code's bits, least significant first, as (byte, bit) of the payload)
        positions = tuple(
            ((o + w - 1 - j) // 8, 7 - (o + w - 1 - j) % 8)
            for o, w in reversed(spec.pieces)
            for j in range(w)
        )
        rows.append(((spec.name, hints.get(spec.name, spec.kind)), scale, bits, positions))
    return _code_signals(rows)


def _code_signals(
    rows: Iterable[tuple[tuple[str, Any], FieldScale, int, Sequence[tuple[int, int]]]],
) -> tuple[SignalSpec, ...]:
    """One signal per field (per bit run, for a field split over the frame) of ``rows``: a field's
    name and type, its scale, its width (negative: signed) and where each bit of its code lands."""
    signals: list[SignalSpec] = []
    for (name, kind), scale, bits, positions in rows:
        factor = scale.span / scale.codes
        cmin, cmax = _code_range(bits)
        choices: tuple[tuple[int, str], ...] = ()
        if kind is bool:
            choices = bool_choices()
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
                    unit=unit_of(name),
                    comment=comment,
                    part=None if whole else first,
                )
            )
    return tuple(signals)
