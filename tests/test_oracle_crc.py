"""The C CRCs (slice-by-8 tables) against the bitwise oracle in tests/reference/crc.py."""

from __future__ import annotations

import zlib
from array import array

import pytest
from hypothesis import given
from hypothesis import strategies as st

from reference import crc as ref
from reference.settings import oracle_settings
from servobus.core import crc16_modbus, crc32_ieee

# (bytes covered, CRC as sent on the wire: low byte first), from the specs' verified examples.
CRC16_VECTORS = [
    ("3E 01 08 9C 00 00 00 00 00 00 00", "F2 30"),  # myactuator-v4.md §1.2, 0x9C read
    ("3E 01 08 30 01 00 00 00 00 00 00", "E8 DD"),
    ("3E 01 08 9A 32 00 01 E5 01 04 00", "38 15"),
    ("3E 01 08 A2 00 00 00 10 27 00 00", "C4 63"),
    ("3E 01 08 A4 00 F4 01 A0 8C 00 00", "3B DD"),
    ("3E 01 08 92 00 00 00 A0 8C 00 00", "90 57"),
    ("3E CD 08 80 00 00 00 00 00 00 00", "36 6A"),
    ("3E 01 08 80 00 00 00 00 00 00 00", "F3 69"),
    ("01 10 00 00 00 10 20" + " 00" * 32, "83 BC"),  # hollow.md §9.5 [H14]
    ("01 10 00 00 00 10", "C1 C5"),  # [H15]
    ("01 03 00 00 00 10", "44 06"),  # [H16]
]
CRC32_VECTORS = [
    ("01" + " 00" * 16, "FE 3A 49 4E"),  # hollow.md §9.4 [H12]
    ("64 00 00 00 00 22" + " 00" * 9 + " 1E 01", "52 CB 4E 9E"),  # [H13]
    ("01 00 00 0A 59 71" + " 00" * 11, "67 10 8E AD"),  # [H19]
]


def _buffers(data: bytes, offset: int) -> list[object]:
    """The same bytes as bytes, bytearray, array('B') and an unaligned memoryview slice."""
    backing = bytearray(b"\xa5" * offset + data + b"\x5a")
    return [data, bytearray(data), array("B", data), memoryview(backing)[offset : offset + len(data)]]


@pytest.mark.parametrize(("covered", "sent"), CRC16_VECTORS)
def test_crc16_spec_vectors(covered: str, sent: str) -> None:
    """Oracle and C both give the CRC-16/MODBUS bytes the specs verified."""
    data = bytes.fromhex(covered)
    assert ref.crc16_modbus(data).to_bytes(2, "little") == bytes.fromhex(sent)
    assert crc16_modbus(data).to_bytes(2, "little") == bytes.fromhex(sent)


@pytest.mark.parametrize(("covered", "sent"), CRC32_VECTORS)
def test_crc32_spec_vectors(covered: str, sent: str) -> None:
    """Oracle and C both give the transparent-mode CRC-32 bytes the hollow spec verified."""
    data = bytes.fromhex(covered)
    assert ref.crc32_ieee(data).to_bytes(4, "little") == bytes.fromhex(sent)
    assert crc32_ieee(data).to_bytes(4, "little") == bytes.fromhex(sent)


def test_check_values_and_empty_input() -> None:
    """The catalogue check values, and an empty input returns the running CRC unchanged."""
    assert ref.crc16_modbus(b"123456789") == crc16_modbus(b"123456789") == 0x4B37
    assert ref.crc32_ieee(b"123456789") == crc32_ieee(b"123456789") == 0xCBF43926
    for init in (0, 1, 0x1234, 0xFFFF):
        assert crc16_modbus(b"", init) == init
    for init in (0, 1, 0xDEADBEEF, 0xFFFFFFFF):
        assert crc32_ieee(b"", init) == init


def test_non_buffer_raises_type_error() -> None:
    """A str is not bytes: both CRCs refuse it instead of hashing its encoding."""
    with pytest.raises(TypeError):
        crc16_modbus("123456789")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        crc32_ieee("123456789")  # type: ignore[arg-type]


@oracle_settings
@given(
    data=st.binary(max_size=300),
    init=st.one_of(st.just(0xFFFF), st.integers(0, 0xFFFF)),
    split=st.integers(0, 300),
    offset=st.integers(0, 7),
)
def test_crc16_matches_reference(data: bytes, init: int, split: int, offset: int) -> None:
    """C CRC-16/MODBUS equals the bitwise one for any bytes, init and buffer type, and chains."""
    expected = ref.crc16_modbus(data, init)
    for buf in _buffers(data, offset):
        assert crc16_modbus(buf, init) == expected  # type: ignore[arg-type]
    if init == 0xFFFF:
        assert crc16_modbus(data) == expected
    head, tail = data[:split], data[split:]
    assert crc16_modbus(tail, crc16_modbus(head, init)) == expected


@oracle_settings
@given(
    data=st.binary(max_size=300),
    init=st.one_of(st.just(0), st.integers(0, 0xFFFFFFFF)),
    split=st.integers(0, 300),
    offset=st.integers(0, 7),
)
def test_crc32_matches_reference(data: bytes, init: int, split: int, offset: int) -> None:
    """C CRC-32 equals the bitwise one (and zlib) for any bytes, init and buffer type, and chains."""
    expected = ref.crc32_ieee(data, init)
    assert expected == zlib.crc32(data, init)  # the oracle itself agrees with an independent CRC-32
    for buf in _buffers(data, offset):
        assert crc32_ieee(buf, init) == expected  # type: ignore[arg-type]
    if init == 0:
        assert crc32_ieee(data) == expected
    head, tail = data[:split], data[split:]
    assert crc32_ieee(tail, crc32_ieee(head, init)) == expected
