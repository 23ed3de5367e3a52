"""Bitwise CRC-16/MODBUS and CRC-32/ISO-HDLC (no tables), the oracle for csrc/crc.c.

Both are reflected CRCs, so each input byte is xored into the low end of the register and the register
shifts right one bit at a time, xoring the reflected polynomial when a 1 falls out.
"""

from __future__ import annotations

from typing import TypeAlias

__all__ = ["BytesLike", "crc16_modbus", "crc32_ieee"]

BytesLike: TypeAlias = bytes | bytearray | memoryview

CRC16_POLY_REFLECTED = 0xA001  # 0x8005 bit-reversed (myactuator-v4.md §1.2, hollow.md §9.5)
CRC32_POLY_REFLECTED = 0xEDB88320  # 0x04C11DB7 bit-reversed (hollow.md §9.4)


def crc16_modbus(data: BytesLike, crc: int = 0xFFFF) -> int:
    """CRC-16/MODBUS: init ``crc`` (0xFFFF to start, a previous result to continue), no final xor."""
    for byte in bytes(data):
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ CRC16_POLY_REFLECTED if crc & 1 else crc >> 1
    return crc


def crc32_ieee(data: BytesLike, crc: int = 0) -> int:
    """CRC-32/ISO-HDLC with zlib's chaining: ``crc32_ieee(b, crc32_ieee(a)) == crc32_ieee(a + b)``.

    The register starts at ``~crc`` and the result is ``~register``, so 0 starts a fresh CRC
    (init 0xFFFFFFFF, xorout 0xFFFFFFFF) and a previous result resumes exactly where it stopped.
    """
    reg = crc ^ 0xFFFFFFFF
    for byte in bytes(data):
        reg ^= byte
        for _ in range(8):
            reg = (reg >> 1) ^ CRC32_POLY_REFLECTED if reg & 1 else reg >> 1
    return reg ^ 0xFFFFFFFF
