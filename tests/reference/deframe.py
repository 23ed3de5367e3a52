"""Stream de-framers as plain state machines over a growing buffer: the oracle for csrc/deframe.c.

Frames (from the specs):

* MyActuator RS485 (myactuator-v4.md §1.2): ``3E, ID, LEN, DATA[LEN], CRC16/MODBUS lo, hi`` over every
  byte before the CRC. LEN is 8 in the standard protocol; 1..max_data_len is accepted.
* Hollow converter, transparent mode (hollow.md §9.4): ``ID, 16 bytes, CRC32 (zlib) of those 17 bytes``,
  least significant byte first. 21 bytes, no header, no length.
* Modbus RTU (hollow.md §9.5, with the Modbus application protocol's length rules): functions 0x03 and
  0x10 and their exception replies 0x83 / 0x90, CRC16/MODBUS low byte first.

Counting rules (csrc/servobus_core.h, csrc/deframe.c):

* At each position a frame is tried with the bytes available. "Need more" keeps the rest buffered.
* A byte that cannot start a frame (bad header), or a complete candidate whose check fails, is dropped
  one byte at a time and counted in ``discarded_bytes`` (the first byte of a bad candidate may be noise
  in front of a real frame, so the hunt resumes at the very next byte).
* A failed check counts once in ``crc_errors`` only if it stood where a frame was expected: at the
  stream start (after construction or clear()) or right after a good frame.
* idle() (the line went quiet): a candidate still waiting for bytes is treated like a bad header.
"""

from __future__ import annotations

import enum
from typing import Literal

from .crc import BytesLike, crc16_modbus, crc32_ieee

__all__ = [
    "ModbusRtuDeframer",
    "MyActuatorRs485Deframer",
    "Parse",
    "ReferenceDeframer",
    "TransparentDeframer",
    "crc16_ok",
    "modbus_frame_lengths",
]


class Parse(enum.Enum):
    FRAME = "frame"
    NEED_MORE = "need more"
    BAD_HEADER = "bad header"
    BAD_CRC = "bad crc"


def crc16_ok(frame: bytes) -> bool:
    """CRC16/MODBUS of all but the last two bytes, sent low byte first, equals the last two bytes."""
    return crc16_modbus(frame[:-2]).to_bytes(2, "little") == frame[-2:]


class ReferenceDeframer:
    """Shared feed loop: subclasses say how to parse a window that starts at a candidate position."""

    max_frame: int  # longest frame the subclass can return

    def __init__(self) -> None:
        self._buf = bytearray()
        self._synced = True
        self.frames = 0
        self.discarded_bytes = 0
        self.crc_errors = 0

    @property
    def pending(self) -> int:
        return len(self._buf)

    def parse(self, window: bytes) -> tuple[Parse, int]:
        """Classify ``window`` (the next at most max_frame bytes); the int is the frame length."""
        raise NotImplementedError

    def feed(self, data: BytesLike) -> list[bytes]:
        """Append ``data``; return the frames that are now complete, in order."""
        self._buf += bytes(data)
        return self._drain(line_idle=False)

    def idle(self) -> list[bytes]:
        """The line went quiet: frames still buffered come out, and a candidate that needs more bytes
        is noise (its first byte is dropped and counted, and the hunt goes on)."""
        return self._drain(line_idle=True)

    def _drain(self, *, line_idle: bool) -> list[bytes]:
        stream = bytes(self._buf)
        frames: list[bytes] = []
        pos = 0
        while pos < len(stream):
            window = stream[pos : pos + self.max_frame]
            result, length = self.parse(window)
            if result is Parse.NEED_MORE:
                if not line_idle:
                    break
                result = Parse.BAD_HEADER
            if result is Parse.FRAME:
                frames.append(window[:length])
                self.frames += 1
                self._synced = True
                pos += length
                continue
            if result is Parse.BAD_CRC and self._synced:
                self.crc_errors += 1
            self._synced = False
            self.discarded_bytes += 1
            pos += 1
        del self._buf[:pos]
        return frames

    def clear(self) -> None:
        """Drop the buffered bytes (counted as discarded); the next byte is again a frame start."""
        self.discarded_bytes += len(self._buf)
        self._buf.clear()
        self._synced = True

    def counters(self) -> tuple[int, int, int, int]:
        return (self.frames, self.discarded_bytes, self.crc_errors, self.pending)


class MyActuatorRs485Deframer(ReferenceDeframer):
    HEADER = 0x3E

    def __init__(self, max_data_len: int = 8) -> None:
        if not 1 <= max_data_len <= 255:
            raise ValueError("max_data_len must be 1..255")
        super().__init__()
        self.max_data_len = max_data_len
        self.max_frame = max_data_len + 5

    def parse(self, window: bytes) -> tuple[Parse, int]:
        if window[0] != self.HEADER:
            return Parse.BAD_HEADER, 0
        if len(window) < 3:
            return Parse.NEED_MORE, 0
        data_len = window[2]
        if not 1 <= data_len <= self.max_data_len:
            return Parse.BAD_HEADER, 0
        length = 3 + data_len + 2
        if len(window) < length:
            return Parse.NEED_MORE, 0
        return (Parse.FRAME if crc16_ok(window[:length]) else Parse.BAD_CRC), length


class TransparentDeframer(ReferenceDeframer):
    FRAME = 21

    def __init__(self) -> None:
        super().__init__()
        self.max_frame = self.FRAME

    def parse(self, window: bytes) -> tuple[Parse, int]:
        if len(window) < self.FRAME:
            return Parse.NEED_MORE, 0
        good = crc32_ieee(window[:17]).to_bytes(4, "little") == window[17:21]
        return (Parse.FRAME if good else Parse.BAD_CRC), self.FRAME


Direction = Literal["requests", "replies", "both"]

_NEED_HEADER = -1  # a length that the header decides, but not all of the header is here yet
_INVALID = 0  # the header rules this frame kind out


def modbus_frame_lengths(window: bytes, direction: Direction) -> list[int] | None:
    """Lengths the frame starting at ``window`` may have (``_NEED_HEADER`` where the header is still
    incomplete), or None when its function code is not one this de-framer takes.

    Frame kinds (Modbus application protocol; hollow.md §9.5 only uses 16-register transfers):

    * 0x03 request: addr fn start(2) quantity(2) crc(2) = 8 bytes.
    * 0x03 reply: addr fn bytecount data crc(2) = 5 + bytecount; bytecount = 2 x quantity, 1..125
      registers, so even and 2..250.
    * 0x10 request: addr fn start(2) quantity(2) bytecount data crc(2) = 9 + bytecount; quantity 1..123
      and bytecount = 2 x quantity.
    * 0x10 reply: addr fn start(2) quantity(2) crc(2) = 8 bytes.
    * 0x83 / 0x90 exception reply: addr fn exception-code crc(2) = 5 bytes.
    """
    requests = direction in ("requests", "both")
    replies = direction in ("replies", "both")
    fn = window[1]
    lengths: list[int] = []
    if fn == 0x03:
        if requests:
            lengths.append(8)
        if replies:
            if len(window) < 3:
                lengths.append(_NEED_HEADER)
            else:
                count = window[2]
                lengths.append(5 + count if 2 <= count <= 250 and count % 2 == 0 else _INVALID)
    elif fn == 0x10:
        if replies:
            lengths.append(8)
        if requests:
            if len(window) < 7:
                lengths.append(_NEED_HEADER)
            else:
                quantity = int.from_bytes(window[4:6], "big")
                count = window[6]
                lengths.append(9 + count if 1 <= quantity <= 123 and count == 2 * quantity else _INVALID)
    elif fn in (0x83, 0x90):
        if replies:
            lengths.append(5)
    else:
        return None
    return lengths


class ModbusRtuDeframer(ReferenceDeframer):
    """Modbus RTU has no common length field: each candidate length is tried, shortest first, and the
    CRC decides. While a candidate is not yet complete (or its length not yet known) the de-framer
    waits, unless a shorter candidate already checked."""

    def __init__(self, direction: Direction = "replies") -> None:
        if direction not in ("requests", "replies", "both"):
            raise ValueError(f"bad direction {direction!r}")
        super().__init__()
        self.direction: Direction = direction
        self.max_frame = 255  # 5 + 250 (0x03 reply) = 9 + 246 (0x10 request)

    def parse(self, window: bytes) -> tuple[Parse, int]:
        if len(window) < 2:
            return Parse.NEED_MORE, 0
        lengths = modbus_frame_lengths(window, self.direction)
        if not lengths:  # unknown function, or none of its kinds in this direction
            return Parse.BAD_HEADER, 0
        known = sorted(n for n in lengths if n > 0)
        checked = False
        for n in known:
            if len(window) < n:
                return Parse.NEED_MORE, 0  # the longer ones cannot be complete either
            checked = True
            if crc16_ok(window[:n]):
                return Parse.FRAME, n
        if _NEED_HEADER in lengths:
            return Parse.NEED_MORE, 0
        return (Parse.BAD_CRC if checked else Parse.BAD_HEADER), 0
