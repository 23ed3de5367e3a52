"""Wire time of CAN, CAN FD and UART frames (servobus.timing)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from servobus.frame import Frame
from servobus.timing import (
    CLASSIC_8_BYTE_STANDARD_BITS,
    can_crc15,
    classic_frame_bits,
    fd_frame_bits,
    frame_time_s,
    nominal_frame_time_s,
    uart_time_s,
)


def _bits_of(text: bytes) -> list[int]:
    return [(byte >> (7 - i)) & 1 for byte in text for i in range(8)]


def test_crc15_check_value() -> None:
    # CRC-15/CAN catalogue check value ("123456789" -> 0x059E).
    assert can_crc15(_bits_of(b"123456789")) == 0x059E


def test_unstuffable_frame_costs_the_unstuffed_minimum() -> None:
    # 0x55 data never forms a run of five; some id and CRC among these need no stuff bit at all.
    frames = [Frame(arbitration_id=i, data=b"\x55" * 8) for i in range(0x7FF)]
    assert min(classic_frame_bits(f) for f in frames) == 111


def test_all_zero_frame_is_heavily_stuffed() -> None:
    # Hand count: SOF, id, RTR, IDE, r0 are 15 zeros (3 stuff bits); DLC 1000 and 64 data zeros
    # leave 67 zeros after the 1 (13 stuff bits). This frame's CRC needs none: 111 + 16.
    assert classic_frame_bits(Frame(arbitration_id=0, data=bytes(8))) == 127


@given(st.integers(0, 0x7FF), st.binary(min_size=8, max_size=8))
def test_eight_byte_standard_frames_stay_in_the_bit_count_bound(ident: int, data: bytes) -> None:
    lo, hi = CLASSIC_8_BYTE_STANDARD_BITS
    assert lo <= classic_frame_bits(Frame(arbitration_id=ident, data=data)) <= hi


@given(st.integers(0, 0x1FFFFFFF), st.binary(min_size=0, max_size=8))
def test_extended_frames_cost_twenty_more_unstuffed_bits(ident: int, data: bytes) -> None:
    bits = classic_frame_bits(Frame(arbitration_id=ident, data=data, is_extended_id=True))
    unstuffed = 131 - 8 * (8 - len(data))
    assert unstuffed <= bits <= unstuffed + (unstuffed - 13 - 1) // 4


def test_frame_time_at_one_megabit() -> None:
    frame = Frame(arbitration_id=0x141, data=bytes.fromhex("9C00000000000000"))
    assert frame_time_s(frame) == classic_frame_bits(frame) / 1e6
    assert frame_time_s(frame, 500_000) == 2 * frame_time_s(frame)


def test_fd_frame_with_bit_rate_switch_splits_its_phases() -> None:
    frame = Frame(arbitration_id=0x01, data=bytes(16), is_fd=True, bitrate_switch=True)
    nominal, data = fd_frame_bits(frame)
    # 16 data bytes, stuff count + CRC-17 with 6 fixed stuff bits, ESI + DLC at the data rate.
    assert data >= 1 + 4 + 128 + 4 + 17 + 6
    assert nominal >= 1 + 11 + 1 + 1 + 1 + 1 + 1 + 13
    slow = Frame(arbitration_id=0x01, data=bytes(16), is_fd=True)
    assert fd_frame_bits(slow) == (nominal + data, 0)
    assert frame_time_s(frame, 1e6, 5e6) == pytest.approx(nominal / 1e6 + data / 5e6)
    assert frame_time_s(frame, 1e6, 5e6) < frame_time_s(slow, 1e6, 5e6)


def test_fd_crc21_above_sixteen_bytes() -> None:
    short = fd_frame_bits(Frame(arbitration_id=1, data=b"\x55" * 16, is_fd=True))[0]
    longer = fd_frame_bits(Frame(arbitration_id=1, data=b"\x55" * 20, is_fd=True))[0]
    # 4 more data bytes (32 bits), CRC-21 instead of 17 (+4) and one more fixed stuff bit.
    assert longer - short == 32 + 4 + 1


def test_wrong_kind_and_bad_rates_raise() -> None:
    with pytest.raises(ValueError, match="needs a classic frame"):
        classic_frame_bits(Frame(arbitration_id=1, data=bytes(16), is_fd=True))
    with pytest.raises(ValueError, match="needs a CAN FD frame"):
        fd_frame_bits(Frame(arbitration_id=1))
    with pytest.raises(ValueError, match="bit rates must be positive"):
        frame_time_s(Frame(arbitration_id=1), 0)


def test_uart_time() -> None:
    assert uart_time_s(13, 1_000_000) == pytest.approx(130e-6)
    assert uart_time_s(8, 19200) == pytest.approx(80 / 19200)
    with pytest.raises(ValueError):
        uart_time_s(1, 0)


@pytest.mark.parametrize("is_extended_id", [False, True])
@pytest.mark.parametrize("is_fd", [False, True])
@given(data=st.binary(max_size=64))
def test_nominal_frame_time_is_the_exact_time_without_its_stuff_bits(
    is_extended_id: bool, is_fd: bool, data: bytes
) -> None:
    sizes = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64) if is_fd else tuple(range(9))
    data = data[: max(s for s in sizes if s <= len(data))]
    frame = Frame(arbitration_id=0x123, data=data, is_extended_id=is_extended_id, is_fd=is_fd)
    exact = frame_time_s(frame, 1.0)
    nominal = nominal_frame_time_s(frame, 1.0)
    # Stuff bits are the only difference: never negative, at most one per four bits after the first.
    assert nominal <= exact <= nominal + (nominal - 13) / 4 + 1


def test_nominal_frame_time_of_an_eight_byte_standard_frame_is_the_unstuffed_111_bits() -> None:
    frame = Frame(arbitration_id=0x141, data=bytes(8))
    assert nominal_frame_time_s(frame, 1_000_000) == CLASSIC_8_BYTE_STANDARD_BITS[0] / 1_000_000


def test_nominal_frame_time_of_a_switched_fd_frame_splits_its_phases() -> None:
    frame = Frame(arbitration_id=0x1, data=bytes(16), is_fd=True, bitrate_switch=True)
    nominal_bits, data_bits = fd_frame_bits(frame)
    slow = nominal_frame_time_s(frame, 1.0, 1e9)
    assert slow <= nominal_bits <= slow * 1.25
    assert nominal_frame_time_s(frame, 1.0, 1.0) <= nominal_bits + data_bits
