"""servobus.dbc: the DBC generated from MyActuator's field tables loads in cantools and decodes every
layout it holds to the values servobus decodes (the same raw code of every field); every layout of the
revision is either in it or named as left out."""

from __future__ import annotations

import math
import random
import struct
from typing import Any

import cantools
import pytest

from servobus.dbc import MUX, Layout, SignalSpec, build_database, dbc_text, layouts, signal_names
from servobus.errors import ProtocolError
from servobus.logs import message_values
from servobus.protocols import myactuator as ma
from servobus.protocols.myactuator.codec import REPLIES, REQUESTS

REVISIONS = ["V4_4", "V4_3"]


def _load(revision: str, ids: list[int]) -> Any:
    database, _ = build_database("myactuator", ids, revision)
    return cantools.database.load_string(dbc_text(database), "dbc")


def _raw(spec: SignalSpec, rng: random.Random) -> bytes:
    """Random bytes of one field, within the range its signal states (edges included)."""
    if spec.choices:
        return rng.choice(spec.choices)[0].to_bytes(spec.size, "little")
    if spec.is_float:
        return struct.pack("<f", rng.choice([0.0, -1.5, rng.uniform(-1e6, 1e6)]))
    bits = 8 * spec.size
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if spec.signed else (0, (1 << bits) - 1)
    if spec.minimum is not None and spec.maximum is not None:
        lo = max(lo, math.ceil(spec.minimum / spec.scale - 1e-9))
        hi = min(hi, math.floor(spec.maximum / spec.scale + 1e-9))
    code = rng.choice([lo, hi, 0 if lo <= 0 <= hi else lo, rng.randint(lo, hi)])
    return code.to_bytes(spec.size, "little", signed=spec.signed)


def _payloads(layout: Layout, rng: random.Random, count: int = 24) -> list[bytes]:
    out = []
    for _ in range(count):
        data = bytearray(8)
        data[0] = layout.code
        for spec in layout.signals:
            data[spec.offset : spec.offset + spec.size] = _raw(spec, rng)
        for offset, byte in layout.constants:
            data[offset] = byte
        out.append(bytes(data))
    return out


def _same(spec: SignalSpec, dbc_value: Any, value: Any) -> None:
    """The DBC's value and servobus' are the same raw code (choices: the same name)."""
    if spec.choices:
        assert str(dbc_value) == str(value), spec
        return
    if value is None or isinstance(value, bool):  # SpecialZero None is raw 0; flags byte 0/1
        value = int(value or 0)
    if spec.is_float:
        assert dbc_value == value, spec
        return
    assert round(dbc_value / spec.scale) == round(value / spec.scale), spec
    assert math.isclose(dbc_value, value, rel_tol=1e-12, abs_tol=1e-12), spec


def _compare(db: Any, ident: int, table: list[Layout], decode: Any, rng: random.Random) -> int:
    names = signal_names(table)
    checked = 0
    for layout in table:
        before = checked
        for data in _payloads(layout, rng):
            try:
                message = decode(ident, data)
            except ProtocolError:
                continue  # a combination servobus refuses (0 < acceleration < 100, say): not data
            values = message_values(message)
            decoded = db.decode_message(ident, data)
            assert str(decoded[MUX]) == layout.name
            for spec in layout.signals:
                value = values[spec.field] if spec.field in values else values[f"command.{spec.field}"]
                _same(spec, decoded[names[spec][0]], value)
            checked += 1
        assert checked - before >= 3, layout  # random samples of every layout are data
    return checked


@pytest.mark.parametrize("revision", REVISIONS)
def test_every_reply_layout_decodes_as_servobus_decodes_it(revision: str) -> None:
    db = _load(revision, [1, 7])
    _, replies, _ = layouts("myactuator", revision)
    rev = ma.Revision[revision]
    for ident in (0x241, 0x247):

        def decode(can_id: int, data: bytes) -> Any:
            return ma.decode_reply(can_id, data, revision=rev)

        assert _compare(db, ident, replies, decode, random.Random(ident)) > 10 * len(replies)


@pytest.mark.parametrize("revision", REVISIONS)
def test_every_request_layout_decodes_as_servobus_decodes_it(revision: str) -> None:
    db = _load(revision, [2])
    requests, _, _ = layouts("myactuator", revision)
    rev = ma.Revision[revision]

    def decode(can_id: int, data: bytes) -> Any:
        return ma.decode_request(can_id, data, revision=rev)

    for ident in (0x142, 0x280):
        assert _compare(db, ident, requests, decode, random.Random(ident)) > 5 * len(requests)


@pytest.mark.parametrize("revision", REVISIONS)
def test_every_layout_of_the_revision_is_in_the_dbc_or_left_out_with_why(revision: str) -> None:
    requests, replies, left_out = layouts("myactuator", revision)
    rev = ma.Revision[revision]
    for what, table, out in (("request", REQUESTS, requests), ("reply", REPLIES, replies)):
        codes = {code for code, candidates in table.items() if any(rev in c.revisions for c in candidates)}
        missing = codes - {layout.code for layout in out}
        named = {code for code in missing if any(r.startswith(f"{what} 0x{code:02X} ") for r in left_out)}
        assert missing == named
    # In V4.4: 0x20 (its value is signed by index) both ways and 0xB5's text; V4.3 adds 0x79.
    assert len(left_out) == (4 if revision == "V4_4" else 6)
    assert any("motion" in reason for reason in left_out)


def test_signals_carry_scale_range_and_unit_from_the_field_tables() -> None:
    db = _load("V4_4", [1])
    reply = db.get_message_by_name("myactuator_reply_1")
    speed = reply.get_signal_by_name("speed_dps")  # R2: int16 1 dps/LSB
    assert (speed.start, speed.length, speed.is_signed, speed.scale, speed.unit) == (32, 16, True, 1, "deg/s")
    current = reply.get_signal_by_name("current_a")
    assert (current.scale, current.unit, current.minimum, current.maximum) == (0.01, "A", -327.68, 327.67)
    angle = reply.get_signal_by_name("angle_deg_94")  # 0x94 V4.4: int32 0.01°, ±180°
    assert (angle.length, angle.scale, angle.minimum, angle.maximum) == (32, 0.01, -180, 180)
    assert reply.get_signal_by_name("value").is_float  # 0x30 PID float32
    assert db.get_message_by_frame_id(0x141).senders == ["host"]
    assert db.get_message_by_frame_id(0x280).name == "myactuator_broadcast"


@pytest.mark.parametrize("family", ["lk", "hollow"])
def test_families_without_field_tables_are_refused(family: str) -> None:
    with pytest.raises(ValueError, match=f"{family} has none"):
        layouts(family)
