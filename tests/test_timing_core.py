"""CAN / CAN FD frame timing in the C core (csrc/sim_timing.c) against tests/reference/timing.py.

The reference builds each frame's bit stream as lists (CRC-15 bit by bit, stuff bits counted over the
list): the C count must equal it for every frame, and ``servobus.timing`` (which calls C) must return
the reference's floats exactly. C checks its own arguments (SB_E_ARG); a fuzz target feeds it any
identifier, flags, length and bytes. .ci/sanitize runs this file under ASan + UBSan.
"""

from __future__ import annotations

import math
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from reference import timing as ref
from reference.settings import oracle_settings
from servobus import timing
from servobus.core._lib import ffi, lib
from servobus.frame import Frame

CSRC = Path(__file__).resolve().parents[1] / "csrc"
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
EXT, FD, BRS = lib.SB_FRAME_EXT, lib.SB_FRAME_FD, lib.SB_FRAME_BRS


def _c_bits(ident: int, flags: int, data: bytes, length: int | None = None) -> tuple[int, int, int]:
    """(status, nominal bits, data bits) straight from C."""
    out = ffi.new("int[2]", [-1, -1])
    status = lib.sb_can_frame_bits(ident, flags, data, len(data) if length is None else length, out, out + 1)
    return status, out[0], out[1]


def _flags(frame: Frame) -> int:
    return (
        (EXT if frame.is_extended_id else 0)
        | (FD if frame.is_fd else 0)
        | (BRS if frame.bitrate_switch else 0)
    )


# Identifiers with long runs of equal bits (stuffing inside the identifier) as well as any.
def _idents(extended: bool) -> st.SearchStrategy[int]:
    top = 0x1FFFFFFF if extended else 0x7FF
    return st.one_of(st.integers(0, top), st.sampled_from([0, top, top & 0x555, top & 0x3E0, top >> 1]))


# Bytes with long runs (0x00, 0xFF, 0x0F, 0xF0) as well as any.
_data_bytes = st.one_of(
    st.binary(min_size=64, max_size=64),
    st.lists(st.sampled_from([0x00, 0xFF, 0x0F, 0xF0, 0x55, 0x1F, 0xE0]), min_size=64, max_size=64).map(
        bytes
    ),
)


@st.composite
def frames(draw: st.DrawFn) -> Frame:
    extended = draw(st.booleans())
    is_fd = draw(st.booleans())
    length = draw(st.sampled_from(FD_LENGTHS) if is_fd else st.integers(0, 8))
    return Frame(
        arbitration_id=draw(_idents(extended)),
        data=draw(_data_bytes)[:length],
        is_extended_id=extended,
        is_fd=is_fd,
        bitrate_switch=is_fd and draw(st.booleans()),
    )


# ---- 1. C against the reference ----


@oracle_settings
@given(frames())
def test_c_counts_match_the_reference(frame: Frame) -> None:
    status, nominal, data = _c_bits(frame.arbitration_id, _flags(frame), frame.data)
    assert status == lib.SB_OK
    if frame.is_fd:
        assert (nominal, data) == ref.fd_frame_bits(frame)
        assert timing.fd_frame_bits(frame) == ref.fd_frame_bits(frame)
    else:
        assert (nominal, data) == (ref.classic_frame_bits(frame), 0)
        assert timing.classic_frame_bits(frame) == ref.classic_frame_bits(frame)


_rates = st.one_of(
    st.sampled_from([125_000, 250_000, 500_000, 1_000_000, 1e6, 2e6, 5e6, 8e6, math.inf]),
    st.floats(min_value=1e-3, max_value=1e9),
)


@oracle_settings
@given(frames(), _rates, st.none() | _rates)
def test_frame_time_is_the_reference_float_exactly(
    frame: Frame, bitrate: float, data_bitrate: float | None
) -> None:
    expected = ref.frame_time_s(frame, bitrate, data_bitrate)
    got = timing.frame_time_s(frame, bitrate, data_bitrate)
    assert struct.pack("<d", got) == struct.pack("<d", expected)
    c = lib.sb_can_frame_time(
        frame.arbitration_id, _flags(frame), frame.data, len(frame.data), bitrate, data_bitrate or 0.0
    )
    assert struct.pack("<d", c) == struct.pack("<d", expected)


@pytest.mark.parametrize("length", FD_LENGTHS)
@pytest.mark.parametrize("brs", [False, True])
@pytest.mark.parametrize("extended", [False, True])
@pytest.mark.parametrize("fill", [0x00, 0xFF, 0x55, 0xF0])
def test_every_fd_length_matches_the_reference(length: int, brs: bool, extended: bool, fill: int) -> None:
    for ident in (0, 0x7FF, 0x123, 0x1FFFFFFF if extended else 0x400):
        frame = Frame(
            arbitration_id=ident,
            data=bytes([fill]) * length,
            is_extended_id=extended,
            is_fd=True,
            bitrate_switch=brs,
        )
        assert timing.fd_frame_bits(frame) == ref.fd_frame_bits(frame)


def test_known_counts() -> None:
    # Hand-counted in tests/test_timing.py: an all-zero 8-byte standard frame is 111 + 16 bits.
    assert _c_bits(0, 0, bytes(8)) == (lib.SB_OK, 127, 0)
    # 0x55 data and this id never form a run of five: the unstuffed 111 bits (search as in test_timing.py).
    lo, hi = timing.CLASSIC_8_BYTE_STANDARD_BITS
    assert min(_c_bits(i, 0, b"\x55" * 8)[1] for i in range(0x800)) == lo
    assert max(_c_bits(i, 0, bytes(8))[1] for i in range(0x800)) <= hi
    # A zero-length frame: SOF, id, RTR, IDE, r0, DLC (19) + CRC-15 + trailer (13), and at least the
    # stuff bit that RTR, IDE, r0 and DLC 0000 (seven zeros) need.
    assert min(_c_bits(i, 0, b"")[1] for i in range(0x800)) == 19 + 15 + 13 + 1


@given(st.integers(0, 0x7FF), st.binary(min_size=8, max_size=8))
def test_eight_byte_standard_frames_stay_in_bounds_in_c(ident: int, data: bytes) -> None:
    lo, hi = timing.CLASSIC_8_BYTE_STANDARD_BITS
    status, bits, data_bits = _c_bits(ident, 0, data)
    assert status == lib.SB_OK and lo <= bits <= hi and data_bits == 0


def test_infinite_bitrate_takes_no_time_and_a_missing_data_rate_is_the_nominal_one() -> None:
    frame = Frame(arbitration_id=5, data=bytes(16), is_fd=True, bitrate_switch=True)
    assert timing.frame_time_s(frame, math.inf) == 0.0
    assert lib.sb_can_frame_time(5, FD | BRS, bytes(16), 16, math.inf, math.inf) == 0.0
    nominal, data = timing.fd_frame_bits(frame)
    for no_rate in (0.0, -1.0, -math.inf):
        assert lib.sb_can_frame_time(5, FD | BRS, bytes(16), 16, 1e6, no_rate) == nominal / 1e6 + data / 1e6


def test_byte_tables_are_generated() -> None:
    """csrc/sim_timing_tables.h is exactly what csrc/gen_timing_tables.py prints (no hand edits)."""
    generated = subprocess.run(
        [sys.executable, str(CSRC / "gen_timing_tables.py")], check=True, capture_output=True, text=True
    ).stdout
    assert (CSRC / "sim_timing_tables.h").read_text() == generated


@pytest.mark.parametrize("state", range(8))
def test_every_byte_from_every_run_state_matches_the_reference(state: int) -> None:
    """The stuffing table's every entry through C: a standard frame whose identifier ends in the run
    state (bit, length) before each data byte value, compared with the reference."""
    run_bit, run_length = state >> 2, (state & 3) + 1
    # The first data byte ends in `run_length` bits of `run_bit` after alternating bits (runs of one),
    # so the second byte starts in exactly that run state.
    lead = 0
    for position in range(7, -1, -1):
        alternate = (position - run_length) % 2 == 0
        bit = run_bit if position < run_length else (1 - run_bit if alternate else run_bit)
        lead |= bit << position
    for byte in range(256):
        frame = Frame(arbitration_id=0x2A5, data=bytes([lead, byte]))
        assert _c_bits(0x2A5, 0, frame.data)[1] == ref.classic_frame_bits(frame)


# ---- 2. argument checks ----

BAD_ARGUMENTS = {
    "classic 9 bytes": (0x1, 0, 9),
    "FD 9 bytes": (0x1, FD, 9),
    "FD 10 bytes": (0x1, FD, 10),
    "FD 65 bytes": (0x1, FD, 65),
    "FD 63 bytes": (0x1, FD | BRS, 63),
    "standard id 0x800": (0x800, 0, 8),
    "standard FD id 0x800": (0x800, FD, 8),
    "extended id 0x20000000": (0x20000000, EXT, 8),
    "extended id all ones": (0xFFFFFFFF, EXT | FD, 8),
    "BRS without FD": (0x1, BRS, 8),
    "BRS extended without FD": (0x1, BRS | EXT, 8),
    "unknown flag 8": (0x1, 8, 8),
    "unknown high flag": (0x1, FD | 0x100, 8),
    "negative flags": (0x1, -1, 8),
}


@pytest.mark.parametrize(("ident", "flags", "length"), BAD_ARGUMENTS.values(), ids=BAD_ARGUMENTS.keys())
def test_c_refuses_bad_frames(ident: int, flags: int, length: int) -> None:
    data = bytes(length)
    out = ffi.new("int[2]", [-7, -7])
    assert lib.sb_can_frame_bits(ident, flags, data, length, out, out + 1) == lib.SB_E_ARG
    assert list(out) == [-7, -7]  # nothing written on refusal
    assert lib.sb_can_frame_time(ident, flags, data, length, 1e6, 0.0) == lib.SB_E_ARG


def test_c_refuses_null_pointers_and_bad_rates() -> None:
    out = ffi.new("int[2]")
    assert lib.sb_can_frame_bits(1, 0, ffi.NULL, 1, out, out + 1) == lib.SB_E_ARG
    assert lib.sb_can_frame_bits(1, 0, ffi.NULL, 0, out, out + 1) == lib.SB_OK  # no data: no bytes read
    assert lib.sb_can_frame_bits(1, 0, b"", 0, ffi.NULL, out) == lib.SB_E_ARG
    assert lib.sb_can_frame_bits(1, 0, b"", 0, out, ffi.NULL) == lib.SB_E_ARG
    for rate in (0.0, -1.0, math.nan, -math.inf):
        assert lib.sb_can_frame_time(1, 0, b"", 0, rate, 0.0) == lib.SB_E_ARG
    assert lib.sb_can_frame_time(1, FD, b"", 0, 1e6, math.nan) == lib.SB_E_ARG
    assert lib.sb_can_frame_time(1, 0, ffi.NULL, 3, 1e6, 0.0) == lib.SB_E_ARG


def test_python_errors_are_the_same_as_before() -> None:
    classic = Frame(arbitration_id=1, data=bytes(8))
    fd = Frame(arbitration_id=1, data=bytes(16), is_fd=True)
    for module in (timing, ref):
        with pytest.raises(
            ValueError, match=r"^classic_frame_bits\(\) needs a classic frame; use fd_frame_bits\(\)$"
        ):
            module.classic_frame_bits(fd)
        with pytest.raises(
            ValueError, match=r"^fd_frame_bits\(\) needs a CAN FD frame; use classic_frame_bits\(\)$"
        ):
            module.fd_frame_bits(classic)
        for bitrate, data_bitrate in ((0, None), (-1.0, None), (1e6, 0), (1e6, -5.0)):
            with pytest.raises(ValueError, match=r"^bit rates must be positive \(bitrate="):
                module.frame_time_s(fd, bitrate, data_bitrate)
    with pytest.raises(ValueError, match="bit rates must be positive"):
        timing.frame_time_s(classic, math.nan)


def test_a_serial_message_longer_than_a_can_frame_has_no_wire_time() -> None:
    message = Frame(arbitration_id=1, data=bytes(20), is_serial=True)
    with pytest.raises(ValueError, match="no CAN wire time"):
        timing.frame_time_s(message)
    with pytest.raises(ValueError, match="no CAN wire time"):
        timing.classic_frame_bits(message)
    short = Frame(arbitration_id=1, data=bytes(8), is_serial=True)  # counted as a classic frame, as before
    assert timing.classic_frame_bits(short) == ref.classic_frame_bits(short)


# ---- 3. fuzz: any identifier, flags, length and bytes ----

# Bits a data frame can take at most: the unstuffed frame plus one stuff bit per four after the first.
_MAX_BITS = 67 + 8 * 64 + 26 + 13 + (67 + 8 * 64) // 4 + 1


def fuzz_frame_bits(data: bytes) -> None:
    """The first 9 bytes choose the identifier, flags and claimed length; the rest is the payload.
    SB_E_ARG exactly when the arguments are bad, otherwise counts within the frame's bounds."""
    head = data[:9].ljust(9, b"\0")
    ident, flags_raw = struct.unpack_from("<IH", head)
    ident = ident if head[8] & 0x80 else ident & (0x1FFFFFFF if head[8] & 0x40 else 0x7FF)
    flags = flags_raw if head[8] & 0x20 else flags_raw & 7
    payload = data[9:]
    length = min(head[6] % 80, len(payload)) if head[8] & 0x10 else head[6] % 80
    buf = ffi.new(
        "uint8_t[]", payload[:length].ljust(length, b"\xa5")
    )  # exactly `length` bytes: ASan sees past them
    out = ffi.new("int[2]", [-7, -7])
    status = lib.sb_can_frame_bits(ident, flags, buf if length else ffi.NULL, length, out, out + 1)
    fd = bool(flags & FD)
    valid = (
        flags & ~7 == 0
        and (fd or not flags & BRS)
        and ident <= (0x1FFFFFFF if flags & EXT else 0x7FF)
        and (length in FD_LENGTHS if fd else length <= 8)
    )
    if not valid:
        assert status == lib.SB_E_ARG and list(out) == [-7, -7]
        return
    assert status == lib.SB_OK
    nominal, data_bits = out[0], out[1]
    if not (flags & BRS):
        assert data_bits == 0
    assert 19 + 15 + 13 <= nominal + data_bits <= _MAX_BITS
    frame = Frame(
        arbitration_id=ident,
        data=bytes(ffi.buffer(buf, length)),
        is_extended_id=bool(flags & EXT),
        is_fd=fd,
        bitrate_switch=bool(flags & BRS),
    )
    expected = ref.fd_frame_bits(frame) if fd else (ref.classic_frame_bits(frame), 0)
    assert (nominal, data_bits) == expected


@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.binary(max_size=80))
def test_fuzz_frame_bits(data: bytes) -> None:
    fuzz_frame_bits(data)


def test_fuzz_frame_bits_edges() -> None:
    # No payload with a claimed length, and the largest claimed length with and without FD.
    for tail in (b"", bytes(70)):
        for code in range(0x100):
            fuzz_frame_bits(struct.pack("<IHB", 0x7FF, 0x7, 64) + bytes([0, code]) + tail)
            fuzz_frame_bits(struct.pack("<IHB", 0xFFFFFFFF, 0x3, 48) + bytes([0, code]) + tail)
