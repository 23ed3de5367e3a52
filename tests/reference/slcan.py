"""SLCAN (LAWICEL) receive lines as a plain state machine: the oracle for csrc/slcan.c.

Written from the rules in csrc/servobus_core.h, not from the C: bytes go one at a time into a line;
CR ends it and it is classified, BEL ends it as the adapter's error, LF at a line start is skipped,
and a line that grows past the longest valid one is dropped up to its terminator.

Frames come out as tuples ``(id, extended, fd, brs, data, timestamp)``.
"""

from __future__ import annotations

__all__ = ["FD_LENGTHS", "KINDS", "RefFrame", "SlcanReference", "max_line"]

RefFrame = tuple[int, bool, bool, bool, bytes, int]

FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
# first byte -> (extended, fd, brs, remote)
KINDS = {
    "t": (False, False, False, False),
    "T": (True, False, False, False),
    "r": (False, False, False, True),
    "R": (True, False, False, True),
    "d": (False, True, False, False),
    "D": (True, True, False, False),
    "b": (False, True, True, False),
    "B": (True, True, True, False),
}
HEX = set("0123456789abcdefABCDEF")


def max_line(timestamps: bool) -> int:
    """D + 8 id digits + DLC + 128 data digits (+ 4 timestamp digits)."""
    return 1 + 8 + 1 + 128 + (4 if timestamps else 0)


def parse_line(line: str, timestamps: bool) -> RefFrame | str:
    """A line without its CR: a frame, or one of "ok", "ack", "remote", "bad"."""
    if line == "":
        return "ok"
    if line in ("z", "Z"):
        return "ack"
    if line[0] not in KINDS:
        return "bad"
    extended, fd, brs, remote = KINDS[line[0]]
    digits = 8 if extended else 3
    head = line[1 : 1 + digits + 1]
    if len(head) != digits + 1 or not set(head) <= HEX:
        return "bad"
    ident, dlc = int(head[:digits], 16), int(head[digits], 16)
    if ident > (0x1FFFFFFF if extended else 0x7FF):
        return "bad"
    if not fd and dlc > 8:
        return "bad"
    length = FD_LENGTHS[dlc] if fd else dlc
    body = line[2 + digits :]
    stamp = ""
    if timestamps:
        body, stamp = body[:-4], body[-4:]
        if len(stamp) != 4 or not set(stamp) <= HEX:
            return "bad"
    want = 0 if remote else 2 * length
    if len(body) != want or not set(body) <= HEX:
        return "bad"
    if remote:
        return "remote"
    return (ident, extended, fd, brs, bytes.fromhex(body), int(stamp, 16) if stamp else 0)


class SlcanReference:
    def __init__(self, *, timestamps: bool = False) -> None:
        self.timestamps = timestamps
        self.max_line = max_line(timestamps)
        self._line = bytearray()
        self._dropping = False
        self.frames = self.remote = self.acks = self.oks = self.bells = 0
        self.malformed = self.overlong = self.discarded_bytes = 0

    @property
    def pending(self) -> int:
        return len(self._line)

    def counters(self) -> tuple[int, ...]:
        return (
            self.frames,
            self.remote,
            self.acks,
            self.oks,
            self.bells,
            self.malformed,
            self.overlong,
            self.discarded_bytes,
            self.pending,
        )

    def clear(self) -> None:
        self.discarded_bytes += len(self._line)
        self._line.clear()
        self._dropping = False

    def feed(self, data: bytes) -> list[RefFrame]:
        out: list[RefFrame] = []
        for byte in data:
            if byte == 0x0D:
                if self._dropping:
                    self._dropping = False
                    self.discarded_bytes += 1
                    continue
                line = self._line.decode("latin-1")
                self._line.clear()
                result = parse_line(line, self.timestamps)
                if isinstance(result, tuple):
                    self.frames += 1
                    out.append(result)
                elif result == "ok":
                    self.oks += 1
                elif result == "ack":
                    self.acks += 1
                elif result == "remote":
                    self.remote += 1
                else:
                    self.malformed += 1
                    self.discarded_bytes += len(line) + 1
            elif byte == 0x07:
                self.bells += 1
                if self._line:
                    self.malformed += 1
                    self.discarded_bytes += len(self._line)
                    self._line.clear()
                self._dropping = False
            elif self._dropping:
                self.discarded_bytes += 1
            elif byte == 0x0A and not self._line:
                continue
            elif len(self._line) < self.max_line:
                self._line.append(byte)
            else:
                self.overlong += 1
                self.discarded_bytes += len(self._line) + 1
                self._line.clear()
                self._dropping = True
        return out
