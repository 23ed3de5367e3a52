"""The MyActuator fast codec's compiled encoders (scaled and stepped fields rounded in their own code)
and the R2 status decoder (its steps written out) give exactly what the full codec gives."""

from __future__ import annotations

import random
import struct
from typing import Any

import pytest

import servobus.protocols.myactuator  # noqa: F401 - every message class defined
from servobus.errors import ProtocolError
from servobus.protocols._fields import IntField, ScaledField
from servobus.protocols._layout import EnumField, StepField
from servobus.protocols._special import SpecialZero
from servobus.protocols.myactuator._fast import Slow, compile_fixed, compile_fixed_encoder
from servobus.protocols.myactuator._layout import Fixed, MyActuatorCommand
from servobus.protocols.myactuator.replies import StatusReply


def _classes(base: type) -> list[type]:
    found: dict[type, None] = {}
    todo = [base]
    while todo:
        for cls in todo.pop().__subclasses__():
            if cls not in found:
                found[cls] = None
                todo.append(cls)
    return list(found)


def _rounded_classes() -> list[type]:
    """The compiled-encoder classes with a field rounded in the encoder's own code."""
    out = []
    for cls in _classes(MyActuatorCommand):
        kinds = {type(spec) for _, spec in getattr(cls, "FIELDS", ())}
        if kinds & {ScaledField, StepField} and compile_fixed_encoder(cls) is not None:
            out.append(cls)
    return out


_SKIP = object()


def _value(spec: Any, rng: random.Random) -> Any:
    if type(spec) is SpecialZero:
        return None if rng.random() < 0.2 else _value(spec.inner, rng)
    if type(spec) is ScaledField:
        lo, hi = spec.limits
        cpu = spec.counts_per_unit
        # ties (x.5 counts) and both signs, where rounding differs most
        code = rng.randint(int(lo * cpu), int(hi * cpu))
        return min(max((code + rng.choice((0.5, -0.5, 0.25, 0.0))) / cpu, lo), hi)
    if type(spec) is StepField:
        return rng.randint(0, 50) * spec.step + rng.choice((0, spec.step // 2))
    if type(spec) is IntField:
        lo, hi = spec.limits
        return rng.randint(int(lo), int(hi))
    if type(spec) is EnumField:
        return rng.choice(list(spec.enum))
    return _SKIP


ROUNDED = _rounded_classes()
FLOATS = [spec.name for _, spec in StatusReply.FIELDS if type(spec) is ScaledField]


def test_some_classes_are_rounded_in_the_compiled_encoder() -> None:
    assert ROUNDED  # (the parity below checks something)


@pytest.mark.parametrize("cls", ROUNDED, ids=lambda cls: cls.__name__)
def test_compiled_encoder_gives_the_full_encoders_bytes(cls: type) -> None:
    fast = compile_fixed_encoder(cls)
    assert fast is not None
    rng = random.Random(cls.__name__)
    checked = 0
    for _ in range(400):
        values = {}
        for _, spec in cls.FIELDS:
            value = _value(spec, rng)
            if value is _SKIP:
                break
            values[spec.name] = value
        else:
            try:
                message = cls(**values)
            except (ValueError, TypeError, ProtocolError):
                continue
            assert fast(message) == Fixed.encode(message), values
            checked += 1
    assert checked > 50


def test_the_r2_status_decoder_gives_the_full_decoders_reply() -> None:
    fast = compile_fixed(StatusReply)
    assert fast is not None and fast.__name__ == "decode_r2"
    rng = random.Random(2)
    decoded = 0
    for _ in range(2000):
        data = bytes([rng.choice((0x9C, 0xA1, 0xA2, 0xA4, 0xFF))]) + rng.randbytes(7)
        try:
            full = StatusReply.decode(data)
        except (ValueError, ProtocolError):
            with pytest.raises(Slow):
                fast(data)
            continue
        try:
            got = fast(data)
        except Slow:
            continue
        assert got == full
        assert [struct.pack("<d", float(getattr(got, f))) for f in FLOATS] == [
            struct.pack("<d", float(getattr(full, f))) for f in FLOATS
        ]
        decoded += 1
    assert decoded > 500
