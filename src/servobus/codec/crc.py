"""CRC-16/MODBUS and CRC-32/ISO-HDLC over any bytes-like object, computed by the C core."""

from __future__ import annotations

from servobus.codec._lib import Buffer, as_cbuffer, lib

__all__ = ["crc16_modbus", "crc32_ieee"]

_crc16 = lib.sb_crc16_modbus
_crc32 = lib.sb_crc32_ieee


def crc16_modbus(data: Buffer, crc: int = 0xFFFF) -> int:
    """CRC-16/MODBUS (reflected poly 0xA001, init 0xFFFF, no final xor).

    Used by MyActuator RS485 frames and Modbus RTU, both of which send the result low byte first.

    Args:
        data: the bytes to check.
        crc: 0xFFFF to start; a previous result to continue over more data.

    Returns:
        The 16-bit CRC.

    Raises:
        TypeError: data is not a contiguous buffer.
    """
    if type(data) is bytes:  # the hot case: no wrapper work at all
        return _crc16(data, len(data), crc)  # type: ignore[no-any-return]
    buf = as_cbuffer(data)
    return _crc16(buf, len(buf), crc)  # type: ignore[no-any-return]


def crc32_ieee(data: Buffer, crc: int = 0) -> int:
    """CRC-32/ISO-HDLC, the zlib/IEEE 802.3 CRC (``zlib.crc32`` semantics, chaining included).

    The hollow converter's transparent frames send it least-significant byte first.

    Args:
        data: the bytes to check.
        crc: 0 to start; a previous result to continue over more data.

    Returns:
        The 32-bit CRC.

    Raises:
        TypeError: data is not a contiguous buffer.
    """
    if type(data) is bytes:
        return _crc32(data, len(data), crc)  # type: ignore[no-any-return]
    buf = as_cbuffer(data)
    return _crc32(buf, len(buf), crc)  # type: ignore[no-any-return]
