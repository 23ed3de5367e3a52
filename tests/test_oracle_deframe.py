"""The C stream de-framers (csrc/deframe.c) against tests/reference/deframe.py.

Streams are built from valid frames (CRCs from the bitwise reference), random garbage and corrupted
frames (bit flips, dropped, inserted and swapped bytes, truncation). Hypothesis draws the de-framer
configuration, the chunking and a seed; the stream comes from the seed, and a failing case prints it.
"""

from __future__ import annotations

import random
from array import array
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest
from hypothesis import given, note
from hypothesis import strategies as st

from reference import deframe as ref
from reference.crc import crc16_modbus, crc32_ieee
from reference.settings import oracle_settings
from servobus.core import HollowTransparentDeframer, ModbusRtuDeframer, MyActuatorRs485Deframer
from servobus.core.deframe import Deframer

# Bytes that start or steer a frame: RS485 header and standard LEN, Modbus functions, fill bytes.
INTERESTING = [0x3E, 0x08, 0x03, 0x10, 0x83, 0x90, 0x00, 0xFF, 0x01, 0x20, 0x64]

# ---- frame builders ----


def with_crc16(body: bytes) -> bytes:
    """``body`` with its CRC16/MODBUS appended low byte first (RS485 and Modbus RTU)."""
    return body + crc16_modbus(body).to_bytes(2, "little")


def rs485_frame(rng: random.Random, max_data_len: int) -> bytes:
    """3E, ID, LEN, DATA[LEN], CRC16 (myactuator-v4.md §1.2); LEN 8 as standard, or any accepted LEN."""
    n = rng.choice([min(8, max_data_len), max_data_len, rng.randint(1, max_data_len)])
    motor_id = rng.choice([1, 2, 32, 0xCD, rng.getrandbits(8)])
    return with_crc16(bytes([0x3E, motor_id, n]) + _payload(rng, n))


def transparent_frame(rng: random.Random) -> bytes:
    """ID + 16 CAN FD bytes + CRC32 of those 17 bytes, LSB first (hollow.md §9.4)."""
    body = bytes([rng.choice([1, 0x64, rng.getrandbits(8)])]) + _payload(rng, 16)
    return body + crc32_ieee(body).to_bytes(4, "little")


def modbus_frame(rng: random.Random, direction: ref.Direction) -> bytes:
    """A 0x03/0x10 request or reply or an exception reply that ``direction`` takes and that no shorter
    candidate length also checks (such a frame is ambiguous on the wire whatever parses it)."""
    kinds = []
    if direction in ("requests", "both"):
        kinds += ["read request", "write request"]
    if direction in ("replies", "both"):
        kinds += ["read reply", "write reply", "exception"]
    parser = ref.ModbusRtuDeframer(direction)
    while True:
        kind = rng.choice(kinds)
        addr = rng.choice([1, 2, 0, 247, rng.getrandbits(8)])
        quantity = rng.choice([16, 1, 2, rng.randint(1, 123)])  # hollow.md §9.5 uses 16 registers
        start = rng.choice([0, rng.getrandbits(16)]).to_bytes(2, "big")
        if kind == "read request":
            body = (
                bytes([addr, 0x03])
                + start
                + rng.choice([quantity, 125, rng.getrandbits(16)]).to_bytes(2, "big")
            )
        elif kind == "write request":
            body = bytes([addr, 0x10]) + start + quantity.to_bytes(2, "big") + bytes([2 * quantity])
            body += _payload(rng, 2 * quantity)
        elif kind == "read reply":
            count = 2 * rng.choice([quantity, 125])
            body = bytes([addr, 0x03, count]) + _payload(rng, count)
        elif kind == "write reply":
            body = bytes([addr, 0x10]) + start + quantity.to_bytes(2, "big")
        else:
            body = bytes([addr, rng.choice([0x83, 0x90]), rng.choice([1, 2, 3, 4, rng.getrandbits(8)])])
        frame = with_crc16(body)
        if parser.parse(frame) == (ref.Parse.FRAME, len(frame)):
            return frame


def _payload(rng: random.Random, n: int) -> bytes:
    """Data bytes: random, zero, or rich in bytes that look like headers."""
    style = rng.randrange(3)
    if style == 0:
        return rng.randbytes(n)
    if style == 1:
        return bytes(n)
    return bytes(rng.choice(INTERESTING) if rng.random() < 0.5 else rng.getrandbits(8) for _ in range(n))


def garbage(rng: random.Random) -> bytes:
    """A run of noise, often of bytes that look like the start of a frame."""
    n = rng.choice([1, 1, 2, 3, rng.randint(1, 40)])
    return bytes(rng.choice(INTERESTING) if rng.random() < 0.5 else rng.getrandbits(8) for _ in range(n))


def corrupt(rng: random.Random, frame: bytes) -> bytes:
    """A damaged copy of ``frame``: one flipped bit, a dropped, inserted or duplicated byte, two bytes
    swapped, or a truncation."""
    b = bytearray(frame)
    i = rng.randrange(len(b))
    how = rng.randrange(6)
    if how == 0:
        b[i] ^= 1 << rng.randrange(8)
    elif how == 1:
        del b[i]
    elif how == 2:
        b.insert(i, rng.getrandbits(8))
    elif how == 3:
        b.insert(i, b[i])
    elif how == 4:
        j = rng.randrange(len(b))
        b[i], b[j] = b[j], b[i]
    else:
        del b[rng.randint(1, len(b) - 1) :]
    return bytes(b)


def build_stream(
    rng: random.Random, make_frame: Callable[[random.Random], bytes], *, clean: bool
) -> tuple[bytes, list[bytes]]:
    """A byte stream and the valid frames placed in it, in order. Garbage or damaged frames may
    happen to contain a valid frame too, so the list is exact only for clean streams."""
    parts: list[bytes] = []
    frames: list[bytes] = []
    for _ in range(rng.choice([0, 1, 2, 3, 4, 6, 10])):
        pick = 0 if clean else rng.randrange(10)
        if pick < 5:
            frame = make_frame(rng)
            parts.append(frame)
            frames.append(frame)
        elif pick < 7:
            parts.append(garbage(rng))
        else:
            parts.append(corrupt(rng, make_frame(rng)))
    return b"".join(parts), frames


def chunks(rng: random.Random, data: bytes, style: str) -> Iterator[bytes]:
    """``data`` whole, one byte at a time, or cut at random places (empty chunks included)."""
    if style == "whole":
        yield data
    elif style == "bytes":
        for i in range(len(data)):
            yield data[i : i + 1]
    else:
        pos = 0
        while pos < len(data):
            size = rng.choice([0, 1, 2, 3, 5, 8, 13, 21, rng.randint(1, 300)])
            yield data[pos : pos + size]
            pos += size


# ---- configurations ----


@dataclass(frozen=True)
class Config:
    """One de-framer configuration: the C de-framer, its oracle, and a maker of valid frames."""

    name: str
    make_dut: Callable[[], Deframer]
    make_ref: Callable[[], ref.ReferenceDeframer]
    make_frame: Callable[[random.Random], bytes]


def rs485_config(rng: random.Random) -> Config:
    """Mostly the standard LEN 8, sometimes a smaller or larger max_data_len (1..255)."""
    n = rng.choice([8, 8, 8, 1, 2, 12, 64, 255, rng.randint(1, 255)])
    return Config(
        f"MyActuatorRs485Deframer({n})",
        lambda: MyActuatorRs485Deframer(n),
        lambda: ref.MyActuatorRs485Deframer(n),
        lambda r: rs485_frame(r, n),
    )


def transparent_config(rng: random.Random) -> Config:
    """The transparent de-framer has no options."""
    return Config(
        "HollowTransparentDeframer()", HollowTransparentDeframer, ref.TransparentDeframer, transparent_frame
    )


def modbus_config(rng: random.Random) -> Config:
    """Host side (replies), device side (requests) or bus monitor (both)."""
    direction: ref.Direction = rng.choice(["replies", "requests", "both"])
    return Config(
        f"ModbusRtuDeframer({direction!r})",
        lambda: ModbusRtuDeframer(direction),
        lambda: ref.ModbusRtuDeframer(direction),
        lambda r: modbus_frame(r, direction),
    )


CONFIGS: dict[str, Callable[[random.Random], Config]] = {
    "rs485": rs485_config,
    "transparent": transparent_config,
    "modbus": modbus_config,
}


def counters(d: Deframer | ref.ReferenceDeframer) -> tuple[int, int, int, int]:
    """(frames, discarded_bytes, crc_errors, pending)."""
    return (d.frames, d.discarded_bytes, d.crc_errors, d.pending)


def drain_feed_into(d: Deframer, data: bytes, out_frames: int, max_lens: int) -> list[bytes]:
    """Feed ``data`` through feed_into with room for ``out_frames`` maximum-size frames and ``max_lens``
    lengths per call, calling again with the rest until all is consumed and nothing more comes out
    (a full output can leave whole frames buffered, so an empty call may still return frames)."""
    out = bytearray(out_frames * d.max_frame)
    lens = array("H", [0] * max_lens)
    frames: list[bytes] = []
    pos = 0
    for _ in range(2 * len(data) + 2):
        n, consumed = d.feed_into(memoryview(data)[pos:], out, lens)
        offset = 0
        for length in lens[:n]:
            frames.append(bytes(out[offset : offset + length]))
            offset += length
        pos += consumed
        if pos == len(data) and n == 0:
            return frames
    raise AssertionError("feed_into made no progress")


# ---- three feeds (h11 style) and hand-checked counting ----

SPEC_FRAMES: dict[str, tuple[Callable[[], Deframer], bytes]] = {
    "rs485": (MyActuatorRs485Deframer, bytes.fromhex("3E01089C00000000000000F230")),  # myactuator §1.2
    "transparent": (HollowTransparentDeframer, bytes.fromhex("01" + "00" * 16 + "FE3A494E")),  # [H12]
    "modbus-write-response": (ModbusRtuDeframer, bytes.fromhex("011000000010C1C5")),  # [H15]
    "modbus-read-request": (
        lambda: ModbusRtuDeframer("requests"),
        bytes.fromhex("0103000000104406"),
    ),  # [H16]
    "modbus-write-request": (  # [H14], 41 bytes
        lambda: ModbusRtuDeframer("both"),
        bytes.fromhex("01100000001020" + "00" * 32 + "83BC"),
    ),
}


@pytest.mark.parametrize("case", SPEC_FRAMES, ids=list(SPEC_FRAMES))
def test_three_feeds(case: str) -> None:
    """A spec frame fed whole; one byte at a time (nothing until the last byte, all of it pending);
    and with the start of the next frame behind it (those bytes stay pending, then complete)."""
    make, frame = SPEC_FRAMES[case]
    d = make()
    assert d.feed(frame) == [frame]
    assert counters(d) == (1, 0, 0, 0)

    d = make()
    for i, byte in enumerate(frame[:-1]):
        assert d.feed(bytes([byte])) == []
        assert d.pending == i + 1
    assert d.feed(frame[-1:]) == [frame]
    assert counters(d) == (1, 0, 0, 0)

    d = make()
    for cut in range(1, len(frame)):
        assert d.feed(frame + frame[:cut]) == [frame]
        assert d.pending == cut
        assert d.feed(frame[cut:]) == [frame]
    assert counters(d) == (2 * (len(frame) - 1), 0, 0, 0)


def test_rs485_counting_rules() -> None:
    """Garbage counts per byte; a bad CRC counts once where a frame was expected, not while hunting;
    a bad LEN is a bad header; clear() counts the pending bytes and re-synchronises."""
    good = bytes.fromhex("3E01089C00000000000000F230")
    bad = good[:-1] + b"\x31"
    d = MyActuatorRs485Deframer()
    assert d.feed(b"\x00\x01" + good) == [good]
    assert counters(d) == (1, 2, 0, 0)  # leading garbage is not a CRC error
    assert d.feed(bad + bad + good) == [good]
    assert counters(d) == (2, 28, 1, 0)  # the second bad frame was met while hunting: no count
    assert d.feed(bad + good[:5]) == []
    assert counters(d) == (2, 41, 2, 5)
    d.clear()
    assert counters(d) == (2, 46, 2, 0)
    assert d.feed(bad) == []
    assert counters(d) == (2, 59, 3, 0)  # after clear() a frame is expected again
    assert d.feed(bytes.fromhex("3E01003E0109")) == []  # LEN 0 and LEN 9 > 8: headers, not CRCs
    assert counters(d) == (2, 65, 3, 0)
    assert d.feed(b"\x3e") == [] and d.pending == 1  # one 3E could still start a frame


def test_transparent_resynchronises_on_the_crc() -> None:
    """No header: after noise the de-framer hunts byte by byte until 21 bytes check again."""
    frame = SPEC_FRAMES["transparent"][1]
    d = HollowTransparentDeframer()
    assert d.feed(b"\x00\x00\x00" + frame + frame[:20]) == [frame]
    assert counters(d) == (1, 3, 1, 20)  # the first 21 bytes stood at the stream start: one CRC error
    assert d.feed(frame[20:]) == [frame]
    assert counters(d) == (2, 3, 1, 0)


def test_modbus_candidates_and_directions() -> None:
    """Both directions: a 0x03 reply is tried as an 8-byte request first, then waited for; an exception
    reply is noise to a device-side (requests) de-framer; a lone byte is always pending."""
    reply = with_crc16(bytes.fromhex("010320") + bytes(range(32)))  # 37 bytes, hollow.md §9.5 read response
    assert not ref.crc16_ok(reply[:8])  # precondition: not also a valid 8-byte request
    d = ModbusRtuDeframer("both")
    assert d.feed(reply[:10]) == []
    assert d.pending == 10  # the 8-byte request failed its CRC, the 37-byte reply may still come
    assert d.feed(reply[10:]) == [reply]
    assert counters(d) == (1, 0, 0, 0)
    exception = with_crc16(bytes.fromhex("018302"))
    d = ModbusRtuDeframer("requests")
    assert d.feed(exception) == []
    assert counters(d) == (0, 4, 0, 1)
    d = ModbusRtuDeframer("replies")
    assert d.feed(exception + exception[:1]) == [exception]
    assert counters(d) == (1, 0, 0, 1)


def test_constructor_arguments() -> None:
    """Out-of-range options are refused; max_frame is the largest frame of the configuration."""
    for bad in (0, 256, -1):
        with pytest.raises(ValueError):
            MyActuatorRs485Deframer(bad)
    with pytest.raises(ValueError):
        ModbusRtuDeframer("sideways")  # type: ignore[arg-type]
    assert MyActuatorRs485Deframer().max_frame == 13
    assert MyActuatorRs485Deframer(255).max_frame == 260
    assert HollowTransparentDeframer().max_frame == 21
    assert ModbusRtuDeframer().max_frame == 255


# ---- against the oracle ----


@pytest.mark.parametrize("kind", CONFIGS, ids=list(CONFIGS))
@oracle_settings
@given(
    seed=st.integers(0, 2**64 - 1),
    chunking=st.sampled_from(["whole", "bytes", "random", "random"]),
    clean=st.sampled_from([False, False, True]),
    clear=st.sampled_from([False, False, False, True]),
    idle=st.sampled_from([False, False, True]),
)
def test_deframer_matches_reference(
    kind: str, seed: int, chunking: str, clean: bool, clear: bool, idle: bool
) -> None:
    """Chunk by chunk, the C de-framer returns the oracle's frames and has its counters; pending stays
    below one maximum frame; every byte ends in a frame, the discard count or pending. With ``idle``,
    the line goes quiet after random chunks and both sides flush alike. Without clear() or idle():
    the same bytes fed all at once, or through feed_into with a small output, give the same frames and
    counters; and a clean stream gives back exactly the frames put in."""
    rng = random.Random(seed)
    config = CONFIGS[kind](rng)
    data, placed = build_stream(rng, config.make_frame, clean=clean)
    pieces = list(chunks(rng, data, chunking))
    clear_at = rng.randrange(len(pieces)) if clear and pieces else -1
    note(f"{config.name}\nstream={data.hex()}\nchunk sizes={[len(p) for p in pieces]} clear_at={clear_at}")

    dut, oracle = config.make_dut(), config.make_ref()
    out: list[bytes] = []
    for k, piece in enumerate(pieces):
        if k == clear_at:
            dut.clear()
            oracle.clear()
        got = dut.feed(piece)
        assert got == oracle.feed(piece)
        assert counters(dut) == counters(oracle)
        assert dut.pending <= dut.max_frame - 1
        out += got
        if idle and rng.random() < 0.3:
            flushed = dut.idle()
            assert flushed == oracle.idle()
            assert counters(dut) == counters(oracle)
            assert dut.pending == 0
            out += flushed
    assert dut.frames == len(out)
    assert sum(map(len, out)) + dut.discarded_bytes + dut.pending == len(data)
    if clear_at >= 0 or idle:
        return

    whole = config.make_dut()
    assert whole.feed(data) == out
    assert counters(whole) == counters(dut)
    small = config.make_dut()
    assert drain_feed_into(small, data, rng.choice([1, 2, 5]), rng.choice([1, 2, 64])) == out
    assert counters(small) == counters(dut)
    if clean:
        assert out == placed
        assert counters(dut) == (len(placed), 0, 0, 0)


@pytest.mark.parametrize("kind", CONFIGS, ids=list(CONFIGS))
def test_large_input(kind: str) -> None:
    """Over 64 KiB in one feed (the wrapper's slice size; frames straddle the slice edges) and in
    three uneven feeds: same frames and counters as the oracle."""
    rng = random.Random(64 << 10)
    config = CONFIGS[kind](rng)
    parts: list[bytes] = []
    while sum(map(len, parts)) < 80_000:
        parts.append(build_stream(rng, config.make_frame, clean=False)[0])
    data = b"".join(parts)
    oracle = config.make_ref()
    expected = oracle.feed(data)
    assert len(expected) > 1000
    whole = config.make_dut()
    assert whole.feed(data) == expected
    assert counters(whole) == counters(oracle)
    pieces = config.make_dut()
    got = (
        pieces.feed(data[:65_535])
        + pieces.feed(memoryview(data)[65_535:65_540])
        + pieces.feed(bytearray(data[65_540:]))
    )
    assert got == expected
    assert counters(pieces) == counters(oracle)
