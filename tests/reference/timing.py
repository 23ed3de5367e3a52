"""CAN and CAN FD bit counts built from the real bit stream in Python: the oracle for csrc/sim_timing.c.

These are servobus.timing's bodies from before the C core counted frames (the frame's bits as lists,
CRC-15 bit by bit, stuff bits counted over the list), kept verbatim so that C is checked against
the code whose numbers the simulator's timing tests were written for.
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
