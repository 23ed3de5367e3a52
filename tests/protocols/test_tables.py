"""The declarations as tables (protocols/_tables.py): what a generator outside Python reads.

A table is checked against the class it describes: bytes written from the table alone (counts at
the field's limits, little-endian, at its offset) decode, through the class, to the values the table
says they mean.
"""

from __future__ import annotations

import json
import math

import pytest

from servobus.errors import ProtocolError
from servobus.protocols import FAMILIES, get_family
from servobus.protocols._layout import Layout
from servobus.protocols._tables import LayoutTable, family_tables, main


def _payload(table: LayoutTable, pick: str) -> tuple[bytes, dict[str, float]]:
    """Bytes built from ``table`` only, with each numeric field at its ``pick`` ("lo"/"hi") limit."""
    data = bytearray(table.size)
    if table.code is not None:
        data[0] = table.code
    for offset, byte in table.constants:
        data[offset] = byte
    expected: dict[str, float] = {}
    for field in table.fields:
        limit = field.lo if pick == "lo" else field.hi
        assert limit is not None
        count = math.trunc(limit / field.scale + (1e-9 if limit >= 0 else -1e-9))
        if field.special is not None and count == field.special:
            count += 1 if pick == "lo" else -1
        data[field.offset : field.offset + field.size] = count.to_bytes(
            field.size, "little", signed=field.signed
        )
        expected[field.name] = count * field.scale
    return bytes(data), expected


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_every_declared_command_has_a_table(name: str) -> None:
    family = get_family(name)
    tables = {t.name: t for t in family_tables(family)}
    for command in family.commands:
        if issubclass(command, Layout):
            assert tables[command.__name__].command
            assert tables[command.__name__].replies == tuple(r.__name__ for r in command.reply_types())


@pytest.mark.parametrize("pick", ["lo", "hi"])
def test_bytes_written_from_a_table_decode_to_what_it_says(pick: str) -> None:
    checked = []
    for name in sorted(FAMILIES):
        family = get_family(name)
        for table in family_tables(family):
            if not table.fields or any(f.kind != "int" for f in table.fields):
                continue  # other kinds are described by kind and width only
            cls = next(c for c in _classes(family) if c.__name__ == table.name)
            data, expected = _payload(table, pick)
            try:
                message = cls.decode(data)
            except (ProtocolError, TypeError):  # a cross-field rule, or a decoder that needs the model
                continue
            for field, value in expected.items():
                assert getattr(message, field) == pytest.approx(value, rel=1e-9, abs=1e-12), (
                    table.name,
                    field,
                )
            checked.append(f"{name}.{table.name}")
    assert len(checked) >= 20, checked


def _classes(family: object) -> list[type]:
    out: list[type] = []
    for command in family.commands:  # type: ignore[attr-defined]
        out += [command, *command.reply_types()]
    return out


def test_the_command_line_writes_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["myactuator"]) == 0
    tables = json.loads(capsys.readouterr().out)
    status = next(t for t in tables if t["name"] == "ReadStatus2")
    assert status["code"] == 0x9C and status["read"] and status["size"] == 8
