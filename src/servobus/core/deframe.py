"""Incremental de-framers for the serial links, run by the C core.

Feed bytes as they arrive, in any chunking; get whole, CRC-checked frames back. Garbage is dropped
and counted, never raised: a serial reader must keep going. Counters:

* ``frames``: frames returned.
* ``discarded_bytes``: bytes dropped because they could not start a frame that checks.
* ``crc_errors``: frames that stood where a frame was expected and failed their check.
* ``pending``: bytes held for a frame not yet complete (bounded; see ``SB_DEFRAME_CAPACITY``).

A de-framer belongs to one thread: it holds a stream's state and scratch buffers and is not
thread-safe. Use one per reader (per port), never one shared by several threads.
"""

from __future__ import annotations

from typing import ClassVar, Literal

from servobus.core._lib import Buffer, ffi, lib, raise_status, readable_cbuffer, writable_cbuffer

__all__ = ["Deframer", "HollowTransparentDeframer", "ModbusRtuDeframer", "MyActuatorRs485Deframer"]

_CHUNK = 1 << 16  # output scratch sized for this much input per C call


class Deframer:
    """Base of the three de-framers; use a subclass.

    Not thread-safe: a de-framer belongs to one thread. It holds one stream's partial frame and
    reuses scratch buffers on every call, so give each reader (each port) its own, and never feed
    one from two threads. asyncio code on one loop is fine.
    """

    _KIND: ClassVar[int]
    _MIN_FRAME: ClassVar[int]

    __slots__ = ("_consumed", "_lens", "_max_frame", "_out", "_state")

    def __init__(self, option: int) -> None:
        if not hasattr(type(self), "_KIND"):
            raise TypeError("Deframer is the base class; use one of its subclasses")
        self._state = ffi.new("sb_deframer *")
        try:
            status = lib.sb_deframer_init(self._state, self._KIND, option)
        except (OverflowError, TypeError):
            raise TypeError(f"{type(self).__name__} option must be a small int, not {option!r}") from None
        if status:
            raise_status(status, type(self).__name__)
        self._max_frame = lib.sb_deframer_max_frame(self._state)
        # feed() needs one C call per input slice to return every frame it completes: the slice,
        # plus what feed_into may have left buffered (up to the capacity), plus the margin parse
        # stops at (room for one more maximum frame).
        out_cap = _CHUNK + lib.SB_DEFRAME_CAPACITY + self._max_frame
        self._out = ffi.new("uint8_t[]", out_cap)
        self._lens = ffi.new("uint16_t[]", out_cap // self._MIN_FRAME + 1)
        self._consumed = ffi.new("size_t *")

    def feed(self, data: Buffer) -> list[bytes]:
        """Take received bytes; return the whole frames they complete, in order.

        Never raises for bad bytes: they are dropped and counted.

        Raises:
            TypeError: ``data`` is not a contiguous bytes-like buffer.
        """
        src = readable_cbuffer(data)
        total = len(src)
        frames: list[bytes] = []
        consumed = self._consumed
        # Input goes in slices of at most _CHUNK bytes (at least one call, so an empty feed still
        # returns frames a full feed_into left behind). The scratch output holds _CHUNK bytes plus
        # more than the de-framer can have buffered, so one C call always takes a whole slice.
        offset = 0
        while True:
            size = min(_CHUNK, total - offset)
            n = lib.sb_deframer_feed(
                self._state,
                src + offset,
                size,
                consumed,
                self._out,
                len(self._out),
                self._lens,
                len(self._lens),
            )
            if n < 0:
                raise_status(n, type(self).__name__)
            if consumed[0] != size:  # pragma: no cover - guarded by the sizing above
                raise RuntimeError("servobus: de-framer scratch buffer too small")
            self._collect(n, frames)
            offset += size
            if offset >= total:
                return frames

    def idle(self) -> list[bytes]:
        """Tell the de-framer the line has gone quiet (Modbus RTU: 3.5 character times of silence).

        Frames still buffered are returned, and a candidate waiting for bytes that will not come
        is dropped as noise (counted), so a stray byte cannot hold back the frame behind it.
        """
        frames: list[bytes] = []
        n = lib.sb_deframer_idle(self._state, self._out, len(self._out), self._lens, len(self._lens))
        if n < 0:
            raise_status(n, type(self).__name__)
        self._collect(n, frames)
        return frames

    def _collect(self, n: int, frames: list[bytes]) -> None:
        if n:
            lens = ffi.unpack(self._lens, n)
            blob = ffi.buffer(self._out, sum(lens))[:]
            pos = 0
            for length in lens:
                frames.append(blob[pos : pos + length])
                pos += length

    def feed_into(self, data: Buffer, out: Buffer, lens: Buffer) -> tuple[int, int]:
        """Allocation-free form for tight loops and benchmarks.

        Frames go back to back into the writable ``out``; their lengths into ``lens`` (a writable
        uint16 buffer, e.g. ``array('H')``). Stops when ``out``/``lens`` cannot take another frame
        of :attr:`max_frame` bytes; complete frames left buffered come out of the next call
        (``feed_into`` with the rest, or ``feed(b"")``).

        Returns:
            (frames written, input bytes consumed). Call again with the unconsumed rest.

        Raises:
            ValueError: ``out`` is shorter than :attr:`max_frame` or ``lens`` is empty, which could
                never make progress.
            TypeError: ``data`` is not a contiguous buffer, ``lens`` is not a writable uint16
                buffer, or ``out`` is not writable.
        """
        try:
            lens_format = memoryview(lens).format
        except TypeError:
            lens_format = None
        if lens_format not in ("H", "<H", "=H"):
            raise TypeError("lens must be a writable uint16 buffer, e.g. array('H')")
        src = readable_cbuffer(data)
        dst = writable_cbuffer("uint8_t[]", out, "out")
        lens_c = writable_cbuffer("uint16_t[]", lens, "lens")
        if len(dst) < self._max_frame or len(lens_c) == 0:
            raise ValueError(f"out needs at least {self._max_frame} bytes and lens at least one slot")
        consumed = self._consumed
        n = lib.sb_deframer_feed(self._state, src, len(src), consumed, dst, len(dst), lens_c, len(lens_c))
        if n < 0:
            raise_status(n, type(self).__name__)
        return n, consumed[0]

    def clear(self) -> None:
        """Drop buffered partial bytes (after a port reopen, say); they count as discarded."""
        status = lib.sb_deframer_reset(self._state)
        if status:
            raise_status(status, type(self).__name__)

    @property
    def frames(self) -> int:
        return int(self._state.frames)

    @property
    def discarded_bytes(self) -> int:
        return int(self._state.discarded_bytes)

    @property
    def crc_errors(self) -> int:
        return int(self._state.crc_errors)

    @property
    def pending(self) -> int:
        return int(self._state.len)

    @property
    def max_frame(self) -> int:
        return int(self._max_frame)

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(frames={self.frames}, discarded_bytes={self.discarded_bytes}, "
            f"crc_errors={self.crc_errors}, pending={self.pending})"
        )


class MyActuatorRs485Deframer(Deframer):
    """MyActuator RS485: ``0x3E, ID, LEN, DATA[LEN], CRC16/MODBUS low byte first``.

    Args:
        max_data_len: largest LEN accepted (the standard protocol fixes it at 8; a larger LEN is
            treated as noise, which keeps resynchronisation quick).
    """

    _KIND = lib.SB_DEFRAME_MYACTUATOR_RS485
    _MIN_FRAME = 6
    __slots__ = ()

    def __init__(self, max_data_len: int = 8) -> None:
        if not 1 <= max_data_len <= 255:
            raise ValueError(f"max_data_len={max_data_len} is outside [1, 255]")
        super().__init__(max_data_len)


class HollowTransparentDeframer(Deframer):
    """Hollow RS485→CANFD converter, transparent mode: ``ID + 16 bytes + CRC32 LSB first``.

    The frame has no header, so the de-framer synchronises on the CRC.
    """

    _KIND = lib.SB_DEFRAME_HOLLOW_TRANSPARENT
    _MIN_FRAME = lib.SB_TRANSPARENT_FRAME
    __slots__ = ()

    def __init__(self) -> None:
        super().__init__(0)


_DIRECTIONS: dict[str, int] = {
    "requests": lib.SB_MODBUS_REQUESTS,
    "replies": lib.SB_MODBUS_REPLIES,
    "both": lib.SB_MODBUS_REQUESTS | lib.SB_MODBUS_REPLIES,
}


class ModbusRtuDeframer(Deframer):
    """Modbus RTU frames of functions 0x03 and 0x10 (and their exception replies), CRC16.

    Args:
        direction: ``"replies"`` on a host (the default), ``"requests"`` on a device or
            simulator, ``"both"`` for a bus monitor (the CRC tells the two 0x03 forms apart).
    """

    _KIND = lib.SB_DEFRAME_MODBUS_RTU
    _MIN_FRAME = 5
    __slots__ = ()

    def __init__(self, direction: Literal["requests", "replies", "both"] = "replies") -> None:
        try:
            option = _DIRECTIONS[direction]
        except KeyError:
            raise ValueError(f"direction={direction!r} is not one of {sorted(_DIRECTIONS)}") from None
        super().__init__(option)
