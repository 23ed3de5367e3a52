"""How long a frame occupies the wire: CAN, CAN FD and UART, bit-exact where the standard is.

Sans-IO arithmetic for the simulator's bus model, the transports' bus-load estimate and for
benchmarks that state which bus they assume. Classic CAN times are exact: the frame's real bit
stream is followed (including its CRC-15) and stuff bits are counted where ISO 11898-1 inserts them,
so an 8-byte standard frame costs between 111 and 135 bit times (design.md, "Environment facts")
depending on its bytes.

CAN FD (ISO variant) is exact for dynamic stuffing up to the end of the data field; the stuff
count and CRC field use fixed stuff bits, counted by rule, so no CRC is needed. Bits from the BRS
sample point to the CRC delimiter run at the data bit rate when bit-rate switching is on.

The counting runs in the C core (csrc/sim_timing.c: one pass over the bits, nothing built), since
the simulator times every frame; tests/reference/timing.py keeps the bit-list version it is checked
against.
"""

from __future__ import annotations

import math

from servobus.core._lib import ffi, lib
from servobus.frame import Frame

__all__ = [
    "CLASSIC_8_BYTE_STANDARD_BITS",
    "INTERFRAME_BITS",
    "can_crc15",
    "classic_frame_bits",
    "fd_frame_bits",
    "format_duration",
    "frame_time_s",
    "nominal_frame_time_s",
    "uart_time_s",
]

INTERFRAME_BITS = 3  # intermission: the bus is idle for 3 recessive bits between frames
# An 8-byte standard data frame: 111 bits unstuffed (incl. intermission), 24 stuff bits at most.
CLASSIC_8_BYTE_STANDARD_BITS = (111, 135)

_FLAG_EXT = lib.SB_FRAME_EXT
_FLAG_FD = lib.SB_FRAME_FD
_FLAG_BRS = lib.SB_FRAME_BRS
_frame_bits = lib.sb_can_frame_bits
_frame_time = lib.sb_can_frame_time


def can_crc15(bits: list[int]) -> int:
    """CRC-15/CAN (polynomial 0x4599) of a bit sequence, as the transmitter computes it."""
    crc = 0
    for bit in bits:
        feedback = bit ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if feedback:
            crc ^= 0x4599
    return crc


def _flags(frame: Frame) -> int:
    return (
        (_FLAG_EXT if frame.is_extended_id else 0)
        | (_FLAG_FD if frame.is_fd else 0)
        | (_FLAG_BRS if frame.bitrate_switch else 0)
    )


def _no_wire_time(frame: Frame) -> ValueError:
    # Frame's own checks leave only a serial message too long for a CAN frame to get here.
    return ValueError(f"{frame!r} cannot be a CAN data frame: it has no CAN wire time")


def _counted(frame: Frame) -> tuple[int, int]:
    out = ffi.new("int[2]")
    data = frame.data
    if _frame_bits(frame.arbitration_id, _flags(frame), data, len(data), out, out + 1) != 0:
        raise _no_wire_time(frame)
    return out[0], out[1]


def classic_frame_bits(frame: Frame) -> int:
    """Bit times a classic CAN data frame occupies, stuff bits and intermission included.

    Raises:
        ValueError: ``frame`` is a CAN FD frame.
    """
    if frame.is_fd:
        raise ValueError("classic_frame_bits() needs a classic frame; use fd_frame_bits()")
    return _counted(frame)[0]


def fd_frame_bits(frame: Frame) -> tuple[int, int]:
    """(nominal-rate bits, data-rate bits) of a CAN FD data frame, intermission included.

    Without bit-rate switching every bit is at the nominal rate and the second number is 0.

    Raises:
        ValueError: ``frame`` is not a CAN FD frame.
    """
    if not frame.is_fd:
        raise ValueError("fd_frame_bits() needs a CAN FD frame; use classic_frame_bits()")
    return _counted(frame)


def frame_time_s(frame: Frame, bitrate: float = 1_000_000, data_bitrate: float | None = None) -> float:
    """Seconds ``frame`` occupies a CAN bus at ``bitrate`` (FD data phase at ``data_bitrate``).

    Raises:
        ValueError: a bit rate is not positive.
    """
    if bitrate <= 0 or (data_bitrate is not None and data_bitrate <= 0):
        raise ValueError(f"bit rates must be positive (bitrate={bitrate}, data_bitrate={data_bitrate})")
    data = frame.data
    flags = 0
    if frame.is_extended_id:
        flags = _FLAG_EXT
    if frame.is_fd:
        flags |= _FLAG_FD | (_FLAG_BRS if frame.bitrate_switch else 0)
    seconds: float = _frame_time(frame.arbitration_id, flags, data, len(data), bitrate, data_bitrate or 0.0)
    if seconds < 0:  # the core's status: a NaN rate (C refuses it) or a frame no CAN bus carries
        if bitrate != bitrate or data_bitrate != data_bitrate:
            raise ValueError(f"bit rates must be positive (bitrate={bitrate}, data_bitrate={data_bitrate})")
        raise _no_wire_time(frame)
    return seconds


def nominal_frame_time_s(frame: Frame, bitrate: float, data_bitrate: float | None = None) -> float:
    """Seconds ``frame`` takes on the wire without stuff bits: a cheap lower bound of :func:`frame_time_s`.

    Pure arithmetic on the frame's format and length (no bit stream is built), so a transport can
    afford it for every frame it counts; stuff bits add at most about a fifth on top.
    """
    n = len(frame.data)
    trailer = 1 + 2 + 7 + INTERFRAME_BITS  # CRC delimiter, ACK slot + delimiter, EOF, intermission
    if not frame.is_fd:
        # SOF, identifier (+ SRR, IDE, 18 more bits), RTR, IDE/r1, r0, DLC, data, CRC-15.
        head = 39 if frame.is_extended_id else 19
        return (head + 8 * n + 15 + trailer) / bitrate
    crc_bits = 17 if n <= 16 else 21
    crc_field = 4 + crc_bits + 1 + (4 + crc_bits) // 4
    # Nominal phase up to BRS: SOF, identifier (extended: SRR, IDE, 18 bits), RRS, IDE, FDF, res, BRS.
    nominal = (36 if frame.is_extended_id else 17) + trailer
    data_phase = 1 + 4 + 8 * n + crc_field  # ESI, DLC, data, stuff count + CRC with fixed stuff bits
    if not frame.bitrate_switch:
        return (nominal + data_phase) / bitrate
    return nominal / bitrate + data_phase / (data_bitrate or bitrate)


def uart_time_s(n_bytes: int, baud: float, *, bits_per_byte: int = 10) -> float:
    """Seconds ``n_bytes`` take on a UART line (8N1: start + 8 data + stop = 10 bits per byte).

    Raises:
        ValueError: ``baud`` is not positive or ``n_bytes`` is negative.
    """
    if baud <= 0 or n_bytes < 0:
        raise ValueError(f"need baud > 0 and n_bytes >= 0 (baud={baud}, n_bytes={n_bytes})")
    return n_bytes * bits_per_byte / baud


#: (seconds per unit, unit, most decimals): below a second a tenth of the unit is the finest shown
_UNITS = ((1.0, "s", 2), (1e-3, "ms", 1), (1e-6, "µs", 1))


def format_duration(seconds: float) -> str:
    """A duration as a person reads it: ``0.00677841`` -> ``"6.8 ms"``, ``1.25`` -> ``"1.25 s"``,
    ``8.5e-05`` -> ``"85 µs"``; at most 3 significant digits (fewer below a second: a tenth of a ms
    or µs is the finest), trailing zeros dropped. Every duration a message prints goes through this.
    """
    if not math.isfinite(seconds):
        return f"{seconds} s"
    magnitude = float(f"{abs(seconds):.3g}")  # rounded first, so 0.99996 s is "1 s", not "1000 ms"
    if magnitude == 0:
        return "0 s"
    scale, unit, most = next((u for u in _UNITS if magnitude >= u[0]), _UNITS[-1])
    value = round(magnitude / scale, 9)  # (0.00105 / 1e-3 is 1.0499999...)
    decimals = min(most, max(0, 2 - math.floor(math.log10(value))))
    text = f"{value:.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return f"{'-' if seconds < 0 else ''}{text} {unit}"
