"""CRC-16/MODBUS and CRC-32/ISO-HDLC over any bytes-like object, computed by the C core."""

from __future__ import annotations

from servobus.core._lib import Buffer, as_cbuffer, lib, raise_status

__all__ = ["crc16_modbus", "crc32_ieee"]

_crc16 = lib.sb_crc16_modbus
_crc32 = lib.sb_crc32_ieee


def _bad_start(crc: object, bits: int) -> Exception:
    # Reached only after cffi refused the start value: say what was wrong in servobus' terms.
    if isinstance(crc, int):
        return ValueError(f"crc={crc} is outside the {bits}-bit range [0, {(1 << bits) - 1:#x}]")
    return TypeError(f"crc must be an int, not {type(crc).__name__}")


def crc16_modbus(data: Buffer, crc: int = 0xFFFF) -> int:
    """CRC-16/MODBUS (reflected poly 0xA001, init 0xFFFF, no final xor).

    Used by MyActuator RS485 frames and Modbus RTU, both of which send the result low byte first.

    Args:
        data: the bytes to check.
        crc: 0xFFFF to start; a previous result to continue over more data.

    Returns:
        The 16-bit CRC.

    Raises:
        TypeError: data is not a contiguous buffer, or crc is not an int.
        ValueError: crc is outside 0..0xFFFF.
    """
    buf = data if type(data) is bytes else as_cbuffer(data)  # bytes, the hot case: no wrapping
    try:
        result: int = _crc16(buf, len(buf), crc)
    except (OverflowError, TypeError):
        raise _bad_start(crc, 16) from None
    if result < 0:  # the core's status for a NULL buffer; a Python buffer never is one
        raise_status(result, "crc16_modbus")
    return result


def crc32_ieee(data: Buffer, crc: int = 0) -> int:
    """CRC-32/ISO-HDLC, the zlib/IEEE 802.3 CRC (``zlib.crc32`` semantics, chaining included).

    The hollow converter's transparent frames send it least-significant byte first.

    Args:
        data: the bytes to check.
        crc: 0 to start; a previous result to continue over more data.

    Returns:
        The 32-bit CRC.

    Raises:
        TypeError: data is not a contiguous buffer, or crc is not an int.
        ValueError: crc is outside 0..0xFFFFFFFF.
    """
    buf = data if type(data) is bytes else as_cbuffer(data)
    try:
        result: int = _crc32(buf, len(buf), crc)
    except (OverflowError, TypeError):
        raise _bad_start(crc, 32) from None
    if result < 0:
        raise_status(result, "crc32_ieee")
    return result
