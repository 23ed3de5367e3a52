"""How long a frame occupies the wire: CAN, CAN FD and UART, bit-exact where the standard is.

Sans-IO arithmetic for the simulator's bus model, the transports' bus-load estimate and for
benchmarks that state which bus they assume. Classic CAN times are exact: the frame's real bit
stream is built (including its CRC-15) and stuff bits are counted where ISO 11898-1 inserts them,
so an 8-byte standard frame costs between 111 and 135 bit times (design.md, "Environment facts")
depending on its bytes.

CAN FD (ISO variant) is exact for dynamic stuffing up to the end of the data field; the stuff
count and CRC field use fixed stuff bits, counted by rule, so no CRC is needed. Bits from the BRS
sample point to the CRC delimiter run at the data bit rate when bit-rate switching is on.
"""

from __future__ import annotations

from servobus.frame import Frame

__all__ = [
    "CLASSIC_8_BYTE_STANDARD_BITS",
    "INTERFRAME_BITS",
    "can_crc15",
    "classic_frame_bits",
    "fd_frame_bits",
    "frame_time_s",
    "nominal_frame_time_s",
    "uart_time_s",
]

INTERFRAME_BITS = 3  # intermission: the bus is idle for 3 recessive bits between frames
# An 8-byte standard data frame: 111 bits unstuffed (incl. intermission), 24 stuff bits at most.
CLASSIC_8_BYTE_STANDARD_BITS = (111, 135)

_FD_DLC_BYTES = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


def _bits(value: int, width: int) -> list[int]:
    return [(value >> (width - 1 - i)) & 1 for i in range(width)]


def _data_bits(data: bytes) -> list[int]:
    return [bit for byte in data for bit in _bits(byte, 8)]


def can_crc15(bits: list[int]) -> int:
    """CRC-15/CAN (polynomial 0x4599) of a bit sequence, as the transmitter computes it."""
    crc = 0
    for bit in bits:
        feedback = bit ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if feedback:
            crc ^= 0x4599
    return crc


def _stuff_bit_count(bits: list[int]) -> int:
    """Stuff bits a transmitter inserts: one after every run of five equal bits (stuff bits included)."""
    count = 0
    run_bit, run_length = -1, 0
    for bit in bits:
        if bit == run_bit:
            run_length += 1
        else:
            run_bit, run_length = bit, 1
        if run_length == 5:
            count += 1
            run_bit, run_length = 1 - bit, 1  # the complementary stuff bit starts the next run
    return count


def _arbitration_and_control(frame: Frame, dlc: int) -> list[int]:
    """SOF .. DLC of a data frame (classic or FD), in transmission order."""
    ident = frame.arbitration_id
    if frame.is_extended_id:
        # SOF, base id, SRR (recessive), IDE (recessive), id extension, then RTR/RRS.
        head = [0, *_bits(ident >> 18, 11), 1, 1, *_bits(ident & 0x3FFFF, 18), 0]
    else:
        head = [0, *_bits(ident, 11), 0, 0]  # SOF, id, RTR/RRS, IDE
    if frame.is_fd:
        # FDF (recessive), res, BRS, ESI (error-active), DLC
        return [*head, 1, 0, int(frame.bitrate_switch), 0, *_bits(dlc, 4)]
    # classic: r1 (extended frames only), r0, DLC
    return [*head, *([0] if frame.is_extended_id else []), 0, *_bits(dlc, 4)]


def classic_frame_bits(frame: Frame) -> int:
    """Bit times a classic CAN data frame occupies, stuff bits and intermission included.

    Raises:
        ValueError: ``frame`` is a CAN FD frame.
    """
    if frame.is_fd:
        raise ValueError("classic_frame_bits() needs a classic frame; use fd_frame_bits()")
    stuffed = _arbitration_and_control(frame, len(frame.data)) + _data_bits(frame.data)
    stuffed += _bits(can_crc15(stuffed), 15)
    # CRC delimiter, ACK slot, ACK delimiter, EOF (7), intermission: fixed form, never stuffed.
    return len(stuffed) + _stuff_bit_count(stuffed) + 1 + 2 + 7 + INTERFRAME_BITS


def fd_frame_bits(frame: Frame) -> tuple[int, int]:
    """(nominal-rate bits, data-rate bits) of a CAN FD data frame, intermission included.

    Without bit-rate switching every bit is at the nominal rate and the second number is 0.

    Raises:
        ValueError: ``frame`` is not a CAN FD frame.
    """
    if not frame.is_fd:
        raise ValueError("fd_frame_bits() needs a CAN FD frame; use classic_frame_bits()")
    dlc = _FD_DLC_BYTES.index(len(frame.data))
    head = _arbitration_and_control(frame, dlc)
    body = _data_bits(frame.data)
    dynamic = head + body
    stuff = _stuff_bit_count(dynamic)
    crc_bits = 17 if len(frame.data) <= 16 else 21
    # Stuff count (4 bits) + CRC, with a fixed stuff bit before the stuff count and after every
    # fourth bit of the two (ISO 11898-1:2015, 10.5).
    crc_field = 4 + crc_bits + 1 + (4 + crc_bits) // 4
    trailer = 1 + 2 + 7 + INTERFRAME_BITS  # CRC delimiter, ACK slot + delimiter, EOF, intermission
    # Phases: the nominal rate runs up to and including BRS; the data rate from ESI to the CRC.
    brs_index = len(head) - 6  # head ends with BRS, ESI, DLC(4)
    nominal_head = brs_index + 1
    stuffed_in_nominal = _stuff_bit_count(dynamic[:nominal_head])
    data_phase = len(dynamic) - nominal_head + (stuff - stuffed_in_nominal) + crc_field
    nominal = nominal_head + stuffed_in_nominal + trailer
    if not frame.bitrate_switch:
        return nominal + data_phase, 0
    return nominal, data_phase


def frame_time_s(frame: Frame, bitrate: float = 1_000_000, data_bitrate: float | None = None) -> float:
    """Seconds ``frame`` occupies a CAN bus at ``bitrate`` (FD data phase at ``data_bitrate``).

    Raises:
        ValueError: a bit rate is not positive.
    """
    if bitrate <= 0 or (data_bitrate is not None and data_bitrate <= 0):
        raise ValueError(f"bit rates must be positive (bitrate={bitrate}, data_bitrate={data_bitrate})")
    if not frame.is_fd:
        return classic_frame_bits(frame) / bitrate
    nominal_bits, data_bits = fd_frame_bits(frame)
    return nominal_bits / bitrate + data_bits / (data_bitrate or bitrate)


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
