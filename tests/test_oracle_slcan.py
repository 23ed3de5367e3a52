"""The C SLCAN line de-framer (csrc/slcan.c) against tests/reference/slcan.py, plus its contract.

Streams mix valid frame lines of every kind (with and without timestamps), adapter replies (OK,
BEL, z/Z), garbage, damaged frame lines (a changed, dropped or inserted character, a DLC that
disagrees with the data) and over-long lines. Hypothesis draws a seed, the chunking (whole, byte
by byte, random cuts) and the options; the stream comes from the seed, and a failing case prints it.
.ci/sanitize runs this file under ASan+UBSan.
"""

from __future__ import annotations

import random
from collections.abc import Iterator

import pytest
from hypothesis import given, note
from hypothesis import strategies as st

from reference.settings import oracle_settings
from reference.slcan import FD_LENGTHS, RefFrame, SlcanReference
from servobus.core import SlcanDeframer
from servobus.core._lib import ffi, lib
from servobus.frame import Frame
from servobus.sim.slcan import parse_frame

# ---- stream builders ----


def frame_line(rng: random.Random, timestamps: bool) -> bytes:
    """A valid line of any kind, CR included; hex in upper or lower case."""
    kind = rng.choice("tttTTrRdDbB")
    extended = kind in "TRDB"
    top = 0x1FFFFFFF if extended else 0x7FF
    ident = rng.choice([0, 1, 0x141, top, rng.randint(0, top)])
    if kind in "dDbB":
        dlc = rng.randrange(16)
        length = FD_LENGTHS[dlc]
    else:
        dlc = rng.randint(0, 8)
        length = dlc
    data = b"" if kind in "rR" else rng.randbytes(length)
    text = f"{kind}{ident:0{8 if extended else 3}X}{dlc:X}{data.hex().upper()}"
    if timestamps:
        text += f"{rng.randrange(0x10000):04X}"
    if rng.random() < 0.2:
        text = text[0] + text[1:].lower()
    return text.encode() + b"\r"


def reply(rng: random.Random) -> bytes:
    return rng.choice([b"\r", b"\a", b"z\r", b"Z\r", b"\n\r", b"V1013\r", b"F00\r"])


def garbage(rng: random.Random) -> bytes:
    alphabet = b"tTrRdDbBzZ0123456789ABCDEFabcdefxX\r\a\n \x00\xff"
    n = rng.choice([1, 2, 3, rng.randint(1, 60)])
    return bytes(rng.choice(alphabet) if rng.random() < 0.8 else rng.getrandbits(8) for _ in range(n))


def damaged(rng: random.Random, line: bytes) -> bytes:
    """A frame line with one character changed, dropped, inserted or duplicated, or its DLC off by one."""
    b = bytearray(line[:-1])
    i = rng.randrange(len(b))
    how = rng.randrange(5)
    if how == 0:
        b[i] = rng.choice(b"0123456789ABCDEFGgxX \x00\r")
    elif how == 1:
        del b[i]
    elif how == 2:
        b.insert(i, rng.choice(b"0Ff9"))
    elif how == 3:
        b.insert(i, b[i])
    else:
        digits = 8 if b[:1] in (b"T", b"R", b"D", b"B") else 3
        if len(b) > digits + 1:
            b[1 + digits] = rng.choice(b"0123456789ABCDEF")
    return bytes(b) + b"\r"


def overlong(rng: random.Random) -> bytes:
    """More characters than any valid line, usually ended by a CR (or BEL), sometimes not."""
    n = rng.choice([139, 140, 142, 143, 300, rng.randint(139, 3000)])
    body = bytes(rng.choice(b"t0123456789ABCDEF") for _ in range(n))
    return body + rng.choice([b"\r", b"\r", b"\a", b""])


def build_stream(rng: random.Random, timestamps: bool, clean: bool) -> tuple[bytes, list[bytes]]:
    parts: list[bytes] = []
    valid: list[bytes] = []
    for _ in range(rng.choice([0, 1, 2, 5, 10, 30])):
        pick = 0 if clean else rng.randrange(12)
        if pick < 5:
            line = frame_line(rng, timestamps)
            parts.append(line)
            valid.append(line)
        elif pick < 7:
            parts.append(reply(rng))
        elif pick < 8:
            parts.append(garbage(rng))
        elif pick < 11:
            parts.append(damaged(rng, frame_line(rng, timestamps)))
        else:
            parts.append(overlong(rng))
    return b"".join(parts), valid


def chunks(rng: random.Random, data: bytes, style: str) -> Iterator[bytes]:
    if style == "whole":
        yield data
    elif style == "bytes":
        for i in range(len(data)):
            yield data[i : i + 1]
    else:
        pos = 0
        while pos < len(data):
            size = rng.choice([0, 1, 2, 3, 5, 8, 21, 64, rng.randint(1, 500)])
            yield data[pos : pos + size]
            pos += size


def as_ref(frame: Frame) -> RefFrame:
    return (frame.arbitration_id, frame.is_extended_id, frame.is_fd, frame.bitrate_switch, frame.data, 0)


def counters(d: SlcanDeframer) -> tuple[int, ...]:
    return (
        d.frames,
        d.remote,
        d.acks,
        d.oks,
        d.bells,
        d.malformed,
        d.overlong,
        d.discarded_bytes,
        d.pending,
    )


def strip_stamp(frames: list[RefFrame]) -> list[RefFrame]:
    return [(*f[:5], 0) for f in frames]


# ---- against the oracle ----


@oracle_settings
@given(
    seed=st.integers(0, 2**64 - 1),
    chunking=st.sampled_from(["whole", "bytes", "random", "random"]),
    clean=st.sampled_from([False, False, True]),
    timestamps=st.booleans(),
    clear=st.sampled_from([False, False, False, True]),
)
def test_slcan_matches_reference(
    seed: int, chunking: str, clean: bool, timestamps: bool, clear: bool
) -> None:
    """Chunk by chunk, the C de-framer returns the oracle's frames and has its counters; pending never
    exceeds the longest line; fed whole, the same stream gives the same result; a clean stream gives
    back exactly the frames put in (remote frames counted, not returned)."""
    rng = random.Random(seed)
    data, valid = build_stream(rng, timestamps, clean)
    pieces = list(chunks(rng, data, chunking))
    clear_at = rng.randrange(len(pieces)) if clear and pieces else -1
    note(f"timestamps={timestamps}\nstream={data!r}")
    note(f"chunk sizes={[len(p) for p in pieces]} clear_at={clear_at}")

    dut, oracle = SlcanDeframer(timestamps=timestamps), SlcanReference(timestamps=timestamps)
    out: list[Frame] = []
    for k, piece in enumerate(pieces):
        if k == clear_at:
            dut.clear()
            oracle.clear()
        got = dut.feed(piece, timestamp=float(k))
        assert [as_ref(f) for f in got] == strip_stamp(oracle.feed(piece))
        assert all(f.timestamp == float(k) for f in got)
        assert counters(dut) == oracle.counters()
        assert dut.pending <= dut.max_line
        out += got
    if clear_at >= 0:
        return
    whole = SlcanDeframer(timestamps=timestamps)
    assert whole.feed(data) == out
    assert counters(whole) == counters(dut)
    if clean:  # cross-checked with the simulator's own parser (servobus.sim.slcan.parse_frame)
        parsed = [parse_frame(line[: len(line) - 1 - 4 * timestamps].decode()) for line in valid]
        assert out == [frame for frame, _ in parsed if frame is not None]
        assert dut.remote == sum(remote for _, remote in parsed)
        assert (dut.malformed, dut.overlong, dut.discarded_bytes, dut.pending) == (0, 0, 0, 0)


def test_large_input_straddles_the_record_batches() -> None:
    """Far more frames than one C call's records, in one feed and in uneven pieces."""
    rng = random.Random(7)
    data = b"".join(frame_line(rng, False) if rng.random() < 0.9 else garbage(rng) for _ in range(20_000))
    oracle = SlcanReference()
    expected = oracle.feed(data)
    assert len(expected) > 10_000  # garbage without a CR takes the line after it along
    whole = SlcanDeframer()
    assert [as_ref(f) for f in whole.feed(data)] == expected
    assert counters(whole) == oracle.counters()
    pieces = SlcanDeframer()
    got = pieces.feed(data[:70_001]) + pieces.feed(memoryview(data)[70_001:70_005])
    got += pieces.feed(bytearray(data[70_005:]))
    assert [as_ref(f) for f in got] == expected


# ---- hand-checked lines ----


def test_frame_kinds_and_flags() -> None:
    d = SlcanDeframer()
    frames = d.feed(
        b"t1412AABB\rT1FFFFFFF0\rd7FFA" + b"11" * 16 + b"\rB000000019" + b"22" * 12 + b"\rt0000\r"
    )
    assert frames == [
        Frame(arbitration_id=0x141, data=b"\xaa\xbb"),
        Frame(arbitration_id=0x1FFFFFFF, data=b"", is_extended_id=True),
        Frame(arbitration_id=0x7FF, data=b"\x11" * 16, is_fd=True),
        Frame(arbitration_id=1, data=b"\x22" * 12, is_extended_id=True, is_fd=True, bitrate_switch=True),
        Frame(arbitration_id=0, data=b""),
    ]
    assert counters(d) == (5, 0, 0, 0, 0, 0, 0, 0, 0)


@pytest.mark.parametrize(
    "line",
    [
        b"t12\r",  # the example: too short for an id and DLC
        b"t1232AABBCC\r",  # DLC 2, three bytes of data: python-can delivers a 1-byte frame
        b"t1233AABB\r",  # DLC 3, two bytes
        b"t1232AAB\r",  # an odd number of digits
        b"t8000\r",  # an 11-bit id above 0x7FF
        b"T200000000\r",  # a 29-bit id above 0x1FFFFFFF
        b"t1239" + b"00" * 9 + b"\r",  # a classic DLC above 8
        b"t12G0\r",  # not hex
        b"t1232AAGG\r",
        b"t1232AABB0000\r",  # a timestamp suffix the de-framer was not told about
        b"d123912\r",  # FD DLC 9 is 12 bytes
        b"x\r",
        b"zz\r",
    ],
)
def test_malformed_line_is_counted_and_dropped_and_the_next_line_still_parses(line: bytes) -> None:
    d = SlcanDeframer()
    good = b"t1411FF\r"
    assert d.feed(line + good) == [Frame(arbitration_id=0x141, data=b"\xff")]
    assert (d.frames, d.malformed, d.discarded_bytes, d.pending) == (1, 1, len(line), 0)


def test_replies_and_remote_frames_are_counted() -> None:
    d = SlcanDeframer()
    assert d.feed(b"\r\az\rZ\rr1230\rR000001238\r\n\r") == []
    assert (d.oks, d.bells, d.acks, d.remote, d.malformed) == (2, 1, 2, 2, 0)


def test_bel_cuts_an_unfinished_line() -> None:
    d = SlcanDeframer()
    assert d.feed(b"t14\at1410\r") == [Frame(arbitration_id=0x141)]
    assert (d.bells, d.malformed, d.discarded_bytes) == (1, 1, 3)


def test_timestamps_option() -> None:
    d = SlcanDeframer(timestamps=True)
    assert d.max_line == 142
    assert d.feed(b"t1411FFEA5F\rt1411FF\rr1410abcd\r") == [Frame(arbitration_id=0x141, data=b"\xff")]
    assert (d.frames, d.malformed, d.remote) == (1, 1, 1)
    assert SlcanDeframer().max_line == 138


def test_one_mebibyte_without_cr_holds_one_line_at_most() -> None:
    """The issue's unbounded line buffer: 1 MiB with no CR is one over-long line, never held."""
    d = SlcanDeframer()
    blob = b"t" + b"A" * (1 << 20)
    for i in range(0, len(blob), 4096):
        assert d.feed(blob[i : i + 4096]) == []
        assert d.pending <= d.max_line
    assert (d.overlong, d.malformed, d.pending) == (1, 0, 0)
    assert d.feed(b"\rt1410\r") == [Frame(arbitration_id=0x141)]
    assert d.discarded_bytes == len(blob) + 1


def test_longest_valid_line_fits_and_one_more_character_does_not() -> None:
    longest = b"D1FFFFFFFF" + b"AB" * 64
    assert len(longest) == 138
    d = SlcanDeframer()
    assert len(d.feed(longest + b"\r")) == 1
    assert d.feed(longest + b"A\r") == []
    assert (d.overlong, d.discarded_bytes) == (1, 140)


def test_clear_counts_the_held_line() -> None:
    d = SlcanDeframer()
    assert d.feed(b"t14") == [] and d.pending == 3
    d.clear()
    assert (d.pending, d.discarded_bytes) == (0, 3)
    assert d.feed(b"1410\r") == []  # no longer a frame: "1410" is an unknown line
    assert d.malformed == 1


# ---- the C contract: statuses, never undefined behaviour ----


def test_c_refuses_bad_arguments() -> None:
    state = ffi.new("sb_slcan *")
    out, consumed, null = ffi.new("sb_slcan_frame[]", 2), ffi.new("size_t *"), ffi.NULL
    assert lib.sb_slcan_init(null, 0) == lib.SB_E_ARG
    assert lib.sb_slcan_init(state, 2) == lib.SB_E_ARG
    assert lib.sb_slcan_feed(state, b"t1410\r", 6, consumed, out, 2) == lib.SB_E_ARG  # refused state
    assert lib.sb_slcan_reset(state) == lib.SB_E_ARG and lib.sb_slcan_max_line(state) == 0
    assert lib.sb_slcan_init(state, 0) == lib.SB_OK
    feed = lib.sb_slcan_feed
    assert feed(state, null, 5, consumed, out, 2) == lib.SB_E_ARG
    assert feed(state, b"t", 1, null, out, 2) == lib.SB_E_ARG
    assert feed(state, b"t", 1, consumed, null, 2) == lib.SB_E_ARG
    assert feed(state, b"t", 1, consumed, out, 0) == lib.SB_E_ARG
    assert feed(null, b"t", 1, consumed, out, 2) == lib.SB_E_ARG
    assert consumed[0] == 0 and state.len == 0
    assert feed(state, null, 0, consumed, out, 2) == 0
    assert lib.sb_slcan_reset(null) == lib.SB_E_ARG and lib.sb_slcan_max_line(null) == 0


def test_c_stops_when_its_output_is_full() -> None:
    state = ffi.new("sb_slcan *")
    assert lib.sb_slcan_init(state, 0) == lib.SB_OK
    out, consumed = ffi.new("sb_slcan_frame[]", 1), ffi.new("size_t *")
    data = b"t1410\rt1420\r"
    assert lib.sb_slcan_feed(state, data, len(data), consumed, out, 1) == 1
    assert consumed[0] == 6 and out[0].id == 0x141
    assert lib.sb_slcan_feed(state, data[6:], 6, consumed, out, 1) == 1
    assert consumed[0] == 6 and out[0].id == 0x142


@pytest.mark.parametrize(("field", "value"), [("option", 2), ("option", -1), ("dropping", 2), ("len", 139)])
def test_c_refuses_a_state_written_from_outside(field: str, value: int) -> None:
    d = SlcanDeframer()
    setattr(d._state, field, value)
    with pytest.raises(ValueError, match=r"^SlcanDeframer: bad argument"):
        d.feed(b"t1410\r")
    with pytest.raises(ValueError, match=r"^SlcanDeframer: bad argument"):
        d.clear()


def test_feed_argument_types() -> None:
    d = SlcanDeframer()
    for bad in ("t1410\r", 5, None, memoryview(bytes(8))[::2]):
        with pytest.raises(TypeError):
            d.feed(bad)  # type: ignore[arg-type]
