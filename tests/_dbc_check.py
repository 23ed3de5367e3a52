"""Comparing one CAN frame as cantools decodes it from a generated DBC with what servobus decodes.

:func:`check_frame` compares every field. Every signal cantools decodes is a field of servobus' message,
and every field servobus decodes (not None) is a signal or implied by the multiplexer values (LK's
``command`` of a shared reply layout, a parameter's name). Raw codes must be equal: cantools' raw value
(scaling off) is servobus' value mapped back through the signal's own factor and offset,
``round((value - offset) / factor)``, and an enum's choice name is servobus' member name. Scaled values
agree within 1e-9 relative (plus 1e-9 of one LSB, for values near zero): servobus computes ``code * span
/ codes + origin`` (C core) or ``code / counts_per_unit``, cantools ``raw * factor + offset`` with the
factor divided out beforehand, and servobus clamps a top motion code that lands one ulp past its range,
so the two differ in the last bits of a double and nowhere else. The exact raw comparison is what pins
each bit's place: the 40-bit CAN FD position's LSB is 2e-12 of its range, below any tolerance on the
scaled value. A field split in bit runs (hollow's extended-mode position) is compared run by run (raw)
and as the sum of its runs.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections import defaultdict
from typing import Any

from servobus.protocols import Message
from servobus.protocols.dbc import CONFIG_FIELDS, Layout, MessageSpec, SignalSpec
from servobus.tools.dbc import signal_table

__all__ = ["check_frame", "values_of"]


def values_of(message: Any) -> dict[str, Any]:
    """A message's values as the DBC's fields name them: enums by name, flags as int, tuples as ``x[i]``,
    an echoed command as ``command`` (its class) and ``command.x``, PID gains as ``value.kp``."""
    out: dict[str, Any] = {}
    for field in dataclasses.fields(message):
        if field.name not in CONFIG_FIELDS:
            _put(out, field.name, getattr(message, field.name))
    return out


def _put(out: dict[str, Any], name: str, value: Any) -> None:
    if isinstance(value, Message):
        out[name] = type(value).__name__
        out.update({f"{name}.{k}": v for k, v in values_of(value).items()})
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for field in dataclasses.fields(value):
            _put(out, f"{name}.{field.name}", getattr(value, field.name))
    elif isinstance(value, enum.Flag):
        out[name] = int(value.value)
    elif isinstance(value, enum.Enum):
        out[name] = value.name
    elif isinstance(value, tuple):
        for i, item in enumerate(value):
            _put(out, f"{name}[{i}]", item)
    else:
        out[name] = value


def _close(dbc_value: float, ours: float, spec: SignalSpec) -> bool:
    return math.isclose(dbc_value, ours, rel_tol=1e-9, abs_tol=1e-9 * spec.scale)


def same(spec: SignalSpec, raw: Any, named: Any, ours: Any, name: str) -> None:
    """One signal: cantools' raw and scaled/named values against servobus' value."""
    where = f"{name} ({spec.field})"
    if ours is None:
        assert spec.none_raw is not None and raw == spec.none_raw, f"{where}: servobus None, raw {raw}"
        return
    if spec.is_float:
        assert named == ours or (math.isnan(named) and math.isnan(ours)), where
        return
    if isinstance(ours, str):  # an enum member, by name
        assert dict(spec.choices).get(raw) == ours and str(named) == ours, f"{where}: {named} != {ours}"
        return
    if isinstance(ours, bool):
        assert raw == int(ours), where
        if spec.choices:
            assert str(named) == str(ours), where
        return
    assert raw == round((ours - spec.offset) / spec.scale), f"{where}: raw {raw} for {ours!r}"
    value = named if isinstance(named, int | float) else named.value
    if spec.choices and not isinstance(named, int | float):
        value = raw * spec.scale + spec.offset
    assert _close(value, ours, spec), f"{where}: {value!r} != {ours!r}"


def same_split(field: str, pieces: list[tuple[SignalSpec, int, float]], ours: float) -> None:
    """A field split in bit runs: each run's raw code is its bits of servobus' code; the values add up."""
    first = next(spec for spec, _, _ in pieces if spec.part == 0)
    code = round((ours - first.offset) / first.scale)
    for spec, raw, _ in pieces:
        assert spec.part is not None
        bits = (code >> spec.part) & ((1 << spec.length) - 1)
        if spec.signed and bits >> (spec.length - 1):
            bits -= 1 << spec.length
        assert raw == bits, f"{field} bits {spec.part}..: raw {raw}, servobus code {code}"
    assert _close(sum(value for _, _, value in pieces), ours, first), field


_TABLES: dict[int, tuple[MessageSpec, dict[str, Any]]] = {}


def _table(spec: MessageSpec) -> dict[str, Any]:
    """:func:`signal_table` of a message of a cached plan, computed once."""
    if id(spec) not in _TABLES:
        _TABLES[id(spec)] = (spec, signal_table(spec))
    return _TABLES[id(spec)][1]


def check_frame(spec: MessageSpec, db: Any, data: bytes, ours: Any) -> None:
    """cantools (from the DBC) and servobus (``ours``) decode ``data`` to the same values, every field."""
    table = _table(spec)
    message = db.get_message_by_name(spec.name)
    named = message.decode(data)
    raw = message.decode(data, decode_choices=False, scaling=False)
    selected: list[Layout] = [spec.root]
    for name, placed in table.items():
        if placed.layouts is not None and name in raw:
            chosen = [layout for layout in placed.layouts if layout.code == raw[name]]
            assert len(chosen) == 1, (name, raw[name])
            selected += chosen
    values = values_of(ours)
    classes = {layout.message for layout in selected if layout.message}
    assert classes == {type(ours).__name__}, (classes, ours)
    covered: set[str] = set()
    for layout in selected:
        for field, expected in layout.implies:
            assert values[field] == expected, (field, values[field], expected)
            covered.add(field)
        for offset, byte in layout.constants:
            assert data[offset] == byte
    parts: dict[str, list[tuple[SignalSpec, int, float]]] = defaultdict(list)
    for name, value in named.items():
        placed = table[name]
        if placed.layouts is not None:
            continue
        signal = placed.spec
        assert signal.field in values, f"signal {name}: servobus' {type(ours).__name__} has no {signal.field}"
        covered.add(signal.field)
        if signal.part is not None:
            parts[signal.field].append((signal, raw[name], value))
        else:
            same(signal, raw[name], value, values[signal.field], name)
    for field, pieces in parts.items():
        same_split(field, pieces, values[field])
    missing = {k for k, v in values.items() if v is not None} - covered
    assert not missing, f"{type(ours).__name__}: no signal for {sorted(missing)}"
