"""RS485 serial lines through pyserial-asyncio-fast, cut into frames by the C de-framers.

One :class:`SerialTransport` is one port and one half-duplex line:

* **Modes** pick the framing, the de-framer and the baud rates the manuals allow:
  ``"myactuator"`` (``0x3E`` frames, CRC-16/MODBUS; 115200, 500 k, 1 M, 1.5 M, 2.5 Mbaud),
  ``"hollow-transparent"`` (ID + 16 bytes + CRC32; 1 Mbaud) and ``"modbus-rtu"`` (19200 baud).
* **Half-duplex**: one transaction at a time per port. A frame sent with ``reply_timeout_s`` keeps
  the line until one whole frame has come back or the timeout passes; only then does the next
  queued frame go. Between frames the line rests for ``gap_s`` (default 3.5 character times, the
  Modbus RTU silence), counted from the end of the last byte either side sent.
* **Framing**: received bytes go through the de-framer as they arrive; whole, CRC-checked frames
  come out as :class:`SerialFrame`, found by header, length and CRC. When no byte has come for
  ``idle_s`` the de-framer is told the line went idle, which drops a stray partial frame as noise.
  ``idle_s`` is not the wire's 3.5-character silence: USB adapters hand bytes over in bursts (an
  FTDI's default latency timer is 16 ms), so a host sees gaps inside frames that the wire never
  had. It defaults to 20 ms, or 3.5 characters where that is longer.
* **Loss**: a port that vanishes (EIO, ENODEV, EOF on a pty) fails every waiter at once and is
  reopened by path with backoff, as in :class:`~servobus.transports.base.Transport`.

pyserial-asyncio-fast is imported when the first port opens, so CAN-only users never load it.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from servobus.core import (
    Deframer,
    HollowTransparentDeframer,
    ModbusRtuDeframer,
    MyActuatorRs485Deframer,
)
from servobus.errors import TransportError
from servobus.timing import uart_time_s
from servobus.transports.base import Outgoing, Transport
from servobus.transports.stats import TransportStats

__all__ = ["SerialFrame", "SerialMode", "SerialTransport"]

_IDLE_CHARS = 3.5  # Modbus RTU's inter-frame silence, in character times
_READ_SIZE = 16384  # bytes taken from the port per wake-up, at most
_USB_BURST_S = 0.02  # longer than the gaps USB adapters put inside frames (FTDI latency timer: 16 ms)


class SerialMode(enum.Enum):
    """The framing on the line."""

    MYACTUATOR = "myactuator"
    HOLLOW_TRANSPARENT = "hollow-transparent"
    MODBUS_RTU = "modbus-rtu"


@dataclass(frozen=True, slots=True)
class _ModeSpec:
    deframer: Callable[[], Deframer]
    bauds: tuple[int, ...]  # the first is the default


_MODES: dict[SerialMode, _ModeSpec] = {
    SerialMode.MYACTUATOR: _ModeSpec(
        MyActuatorRs485Deframer, (115_200, 500_000, 1_000_000, 1_500_000, 2_500_000)
    ),
    SerialMode.HOLLOW_TRANSPARENT: _ModeSpec(HollowTransparentDeframer, (1_000_000,)),
    SerialMode.MODBUS_RTU: _ModeSpec(ModbusRtuDeframer, (19_200,)),
}

_PARITY_BITS = {"N": 0, "E": 1, "O": 1}


@dataclass(frozen=True, slots=True)
class SerialFrame:
    """One whole serial frame as it was on the wire (header, payload and CRC; the CRC checked).

    ``timestamp`` is ``time.monotonic()`` when its last byte was read; equality ignores it.
    """

    data: bytes
    timestamp: float = field(default=0.0, compare=False)

    def __repr__(self) -> str:
        return f"SerialFrame([{self.data.hex(' ').upper()}])"


class SerialTransport(Transport[SerialFrame, bytes]):
    """One RS485 port: frames out one transaction at a time, whole frames in.

    Args:
        port: the serial device (``/dev/ttyUSB0``, a pty, or any pyserial URL).
        mode: ``"myactuator"``, ``"hollow-transparent"`` or ``"modbus-rtu"``.
        baud: the line's rate; one the mode's manual allows (default: the mode's first).
        parity: ``"N"``, ``"E"`` or ``"O"`` (Modbus devices differ; the others use none).
        gap_s: rest between frames on the line (default: 3.5 character times).
        idle_s: silence after which buffered partial bytes are dropped (default: 20 ms, or 3.5
            character times where that is longer).
        exclusive: lock the port against other processes (pyserial's ``exclusive``).
        queue_size, rx_buffer, stale_after_s, reopen, reopen_backoff_s: see
            :class:`~servobus.transports.base.Transport`.
        **options: other pyserial arguments.

    Raises:
        ValueError: unknown mode or parity, or a baud rate the mode does not use.
    """

    batch_size = 1  # half-duplex: one transaction at a time

    def __init__(
        self,
        port: str,
        *,
        mode: SerialMode | str,
        baud: int | None = None,
        parity: str = "N",
        gap_s: float | None = None,
        idle_s: float | None = None,
        exclusive: bool = True,
        queue_size: int = 256,
        rx_buffer: int = 65536,
        stale_after_s: float | None = 0.5,
        reopen: bool = True,
        reopen_backoff_s: tuple[float, float] = (0.05, 2.0),
        **options: Any,
    ) -> None:
        try:
            self.mode = SerialMode(mode)
        except ValueError:
            known = ", ".join(m.value for m in SerialMode)
            raise ValueError(f"mode={mode!r} is not one of {known}") from None
        spec = _MODES[self.mode]
        self.baud = spec.bauds[0] if baud is None else baud
        if self.baud not in spec.bauds:
            raise ValueError(f"baud={self.baud} is not one of {self.mode.value}'s rates {spec.bauds}")
        if parity not in _PARITY_BITS:
            raise ValueError(f"parity={parity!r} is not one of 'N', 'E', 'O'")
        if (gap_s is not None and gap_s < 0) or (idle_s is not None and idle_s <= 0):
            raise ValueError(f"need gap_s >= 0 and idle_s > 0 (gap_s={gap_s}, idle_s={idle_s})")
        super().__init__(
            name=f"rs485:{port}",
            queue_size=queue_size,
            rx_buffer=rx_buffer,
            stale_after_s=stale_after_s,
            reopen=reopen,
            reopen_backoff_s=reopen_backoff_s,
        )
        self.port = port
        self.parity = parity
        self.bits_per_char = 10 + _PARITY_BITS[parity]
        silence_s = uart_time_s(1, self.baud, bits_per_byte=self.bits_per_char) * _IDLE_CHARS
        self.gap_s = silence_s if gap_s is None else gap_s
        self.idle_s = max(silence_s, _USB_BURST_S) if idle_s is None else idle_s
        self._serial_options = {"exclusive": exclusive, **options}
        self._deframer = spec.deframer()
        self._load_known = True
        self._line: asyncio.Transport | None = None
        self._protocol: _LineProtocol | None = None
        self._line_quiet_at = 0.0  # monotonic time the line's last byte ends (either side)
        self._last_rx = 0.0
        self._idle_timer: asyncio.TimerHandle | None = None
        self._reply: asyncio.Future[None] | None = None

    # ----------------------------------------------------------------- public API

    def send(self, frame: bytes, *, reply_timeout_s: float | None = None) -> None:
        """Queue one whole frame (as the codec encoded it, CRC included).

        Args:
            reply_timeout_s: a reply is expected: keep the line for up to this long after the
                frame has left, until a whole frame comes back. None: no reply (broadcast).

        Raises:
            ValueError: empty frame or negative timeout.
            SendQueueFull: the queue is full.
            TransportError: the port is not open (lost or closed).
        """
        if not frame:
            raise ValueError("cannot send an empty serial frame")
        if reply_timeout_s is not None and reply_timeout_s < 0:
            raise ValueError(f"reply_timeout_s={reply_timeout_s} must be >= 0")
        self._enqueue(bytes(frame), reply_timeout_s)

    def stats(self) -> TransportStats:
        snapshot = super().stats()
        snapshot.discarded_bytes = self._deframer.discarded_bytes
        snapshot.crc_errors = self._deframer.crc_errors
        return snapshot

    # ----------------------------------------------------------------- connection

    async def _connect(self) -> None:
        import serial
        import serial_asyncio_fast

        loop = asyncio.get_running_loop()
        protocol = _LineProtocol(self, self._generation)
        try:
            line, _ = await serial_asyncio_fast.create_serial_connection(
                loop,
                lambda: protocol,
                self.port,
                baudrate=self.baud,
                parity=self.parity,
                bytesize=8,
                stopbits=1,
                **self._serial_options,
            )
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"{self.name}: cannot open: {exc}") from exc
        # pyserial-asyncio-fast reads at most 1 KiB per wake-up (its own TODO says so); a larger read
        # takes a burst in one call, which is what the de-framer is built for.
        if hasattr(line, "_max_read_size"):
            line._max_read_size = _READ_SIZE
        self._deframer.clear()  # bytes of a frame cut by the loss cannot be completed
        self._line, self._protocol = line, protocol

    async def _disconnect(self) -> None:
        line, protocol = self._line, self._protocol
        self._line = self._protocol = None
        if self._idle_timer is not None:
            self._idle_timer.cancel()
            self._idle_timer = None
        if line is not None and protocol is not None:
            if not line.is_closing():  # a failed line is already closing (closing twice breaks it)
                line.abort()  # queued bytes belong to a line that is going away
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(asyncio.shield(protocol.closed), 1.0)

    # ----------------------------------------------------------------- receiving

    def _on_bytes(self, data: bytes, generation: int) -> None:
        if generation != self._generation:
            return
        now = time.monotonic()
        self._stats.bytes_in += len(data)
        self._load.add(now, uart_time_s(len(data), self.baud, bits_per_byte=self.bits_per_char))
        self._last_rx = now
        self._line_quiet_at = max(self._line_quiet_at, now)
        self._take(self._deframer.feed(data), now)
        if self._deframer.pending and self._idle_timer is None:
            self._idle_timer = asyncio.get_running_loop().call_later(self.idle_s, self._on_quiet, generation)

    def _on_quiet(self, generation: int) -> None:
        self._idle_timer = None
        if generation != self._generation:
            return
        still = self._last_rx + self.idle_s - time.monotonic()
        if still > 0:  # bytes came meanwhile: the silence starts over
            self._idle_timer = asyncio.get_running_loop().call_later(still, self._on_quiet, generation)
            return
        self._take(self._deframer.idle(), time.monotonic())

    def _take(self, frames: list[bytes], now: float) -> None:
        if not frames:
            return
        self._stats.frames_in += len(frames)
        self._deliver([SerialFrame(frame, now) for frame in frames])
        if self._reply is not None and not self._reply.done():
            self._reply.set_result(None)

    # ----------------------------------------------------------------- sending

    async def _transmit(self, batch: list[Outgoing[bytes]]) -> None:
        stats = self._stats
        while batch:
            if (rest := self._line_quiet_at + self.gap_s - time.monotonic()) > 0:
                await asyncio.sleep(rest)
            line = self._line
            if line is None or line.is_closing():  # failed while we rested: the base purges the rest
                return
            outgoing = batch.pop(0)
            data = outgoing.item
            reply = None if outgoing.hold_s is None else asyncio.get_running_loop().create_future()
            self._reply = reply
            line.write(data)
            on_wire_s = uart_time_s(len(data), self.baud, bits_per_byte=self.bits_per_char)
            now = time.monotonic()
            self._line_quiet_at = now + on_wire_s
            stats.frames_out += 1
            stats.bytes_out += len(data)
            self._load.add(now, on_wire_s)
            if reply is not None and outgoing.hold_s is not None:
                try:
                    await asyncio.wait_for(reply, on_wire_s + outgoing.hold_s)
                except TimeoutError:
                    pass  # no reply: the line is free again; matching the silence is the caller's job
                finally:
                    self._reply = None


class _LineProtocol(asyncio.Protocol):
    """pyserial-asyncio-fast's callbacks, forwarded to the transport of one connection."""

    def __init__(self, owner: SerialTransport, generation: int) -> None:
        self._owner = owner
        self._generation = generation
        self.closed: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def data_received(self, data: bytes) -> None:
        self._owner._on_bytes(data, self._generation)

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.closed.done():
            self.closed.set_result(None)
        if exc is None:
            exc = ConnectionError("the port closed")
        self._owner._lose(exc, self._generation)
