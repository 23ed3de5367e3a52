"""The SLCAN (LAWICEL) line de-framer, run by the C core (csrc/slcan.c).

Feed the bytes an SLCAN adapter sends, in any chunking; get whole, checked CAN and CAN FD
:class:`~servobus.frame.Frame` objects back. Everything else is counted, never raised: a serial
reader must keep going, and one bad line must not cost the frames behind it. Counters:

* ``frames``: data frames returned.
* ``remote``: remote (RTR) frames, counted and dropped (servobus carries no remote frames).
* ``acks``: ``z``/``Z`` transmit acknowledgements; ``oks``: empty lines (the adapter's OK);
  ``bells``: BEL bytes (the adapter's error reply).
* ``malformed``: lines dropped for their form: an unknown first byte, a bad hex digit, an
  identifier out of range (standard ids are 11-bit), a classic DLC above 8, or a number of data
  digits that disagrees with the DLC (never truncated or padded into a frame).
* ``overlong``: lines longer than the longest valid one, dropped up to their CR without being held.
* ``discarded_bytes``: bytes of malformed and over-long lines, their CR included.
* ``pending``: bytes of the current line held so far, never more than :attr:`max_line`.

Timestamps: adapters sent ``Z1`` end every frame line in 4 hex digits of milliseconds; give
``timestamps=True`` for such an adapter (the digits are checked and dropped). Without it, a line
with 4 extra digits is malformed, which is what keeps the DLC check exact.

A de-framer belongs to one thread (it reuses its scratch records); it is not thread-safe.
"""

from __future__ import annotations

import struct

from servobus.core._lib import Buffer, ffi, lib, raise_status, readable_cbuffer
from servobus.frame import Frame

__all__ = ["SlcanDeframer"]

_RECORDS = 1024  # frame records filled per C call (the loop calls again for more)
_RECORD = struct.Struct("<IBBH64s")  # sb_slcan_frame: id, flags, len, timestamp, data[64]
_EXTENDED = lib.SB_SLCAN_EXTENDED
_FD = lib.SB_SLCAN_FD
_BRS = lib.SB_SLCAN_BRS


class SlcanDeframer:
    """LAWICEL receive lines in, :class:`~servobus.frame.Frame` objects out (see the module doc).

    Not thread-safe: a de-framer belongs to one thread (one reader per port).

    Args:
        timestamps: every frame line carries the 4-digit timestamp suffix (the adapter got ``Z1``).
    """

    __slots__ = ("_consumed", "_out", "_state", "_view")

    def __init__(self, *, timestamps: bool = False) -> None:
        if _RECORD.size != ffi.sizeof("sb_slcan_frame"):  # pragma: no cover - a header/wrapper mismatch
            raise ImportError("servobus: sb_slcan_frame does not have the layout this wrapper reads")
        self._state = ffi.new("sb_slcan *")
        status = lib.sb_slcan_init(self._state, lib.SB_SLCAN_TIMESTAMPS if timestamps else 0)
        if status:  # pragma: no cover - the option is built here
            raise_status(status, "SlcanDeframer")
        self._out = ffi.new("sb_slcan_frame[]", _RECORDS)
        self._view = ffi.buffer(self._out)
        self._consumed = ffi.new("size_t *")

    def feed(self, data: Buffer, timestamp: float = 0.0) -> list[Frame]:
        """Take received bytes; return the data frames they complete, in order, stamped ``timestamp``.

        Never raises for bad bytes: they are dropped and counted.

        Raises:
            TypeError: ``data`` is not a contiguous bytes-like buffer.
        """
        src = readable_cbuffer(data)
        total = len(src)
        frames: list[Frame] = []
        state, out, consumed, view = self._state, self._out, self._consumed, self._view
        offset = 0
        while True:
            n = lib.sb_slcan_feed(state, src + offset, total - offset, consumed, out, _RECORDS)
            if n < 0:
                raise_status(n, "SlcanDeframer")
            if n:
                append = frames.append
                for ident, flags, length, _stamp, payload in _RECORD.iter_unpack(view[: n * _RECORD.size]):
                    append(
                        Frame(
                            arbitration_id=ident,
                            data=payload[:length],
                            is_extended_id=bool(flags & _EXTENDED),
                            is_fd=bool(flags & _FD),
                            bitrate_switch=bool(flags & _BRS),
                            timestamp=timestamp,
                        )
                    )
            offset += consumed[0]
            if offset >= total:
                return frames

    def clear(self) -> None:
        """Drop the line held so far (after a port reopen, say); its bytes count as discarded."""
        status = lib.sb_slcan_reset(self._state)
        if status:
            raise_status(status, "SlcanDeframer")

    @property
    def frames(self) -> int:
        return int(self._state.frames)

    @property
    def remote(self) -> int:
        return int(self._state.remote)

    @property
    def acks(self) -> int:
        return int(self._state.acks)

    @property
    def oks(self) -> int:
        return int(self._state.oks)

    @property
    def bells(self) -> int:
        return int(self._state.bells)

    @property
    def malformed(self) -> int:
        return int(self._state.malformed)

    @property
    def overlong(self) -> int:
        return int(self._state.overlong)

    @property
    def discarded_bytes(self) -> int:
        return int(self._state.discarded_bytes)

    @property
    def pending(self) -> int:
        return int(self._state.len)

    @property
    def max_line(self) -> int:
        """Longest line (before its CR) accepted: 138, or 142 with timestamps."""
        return int(lib.sb_slcan_max_line(self._state))

    def __repr__(self) -> str:
        return (
            f"SlcanDeframer(frames={self.frames}, malformed={self.malformed}, overlong={self.overlong}, "
            f"remote={self.remote}, acks={self.acks}, oks={self.oks}, bells={self.bells}, "
            f"pending={self.pending})"
        )
