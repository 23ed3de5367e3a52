"""RS485 serial lines on the port's descriptor: Frames in and out, the framing chosen by the family.

One :class:`SerialTransport` is one port and one half-duplex line:

* **Frames on every link.** :meth:`SerialTransport.send` takes a serial
  :class:`~servobus.frame.Frame` (``is_serial``: the address byte as ``arbitration_id``, the
  message body as ``data``, as a family's bound codec encodes it on its ``"rs485"`` link) and
  writes ``framing.encode(frame)``; received bytes go through ``framing.deframer()`` and come out
  as Frames stamped with the event loop's clock. The **framing** is a plug-in the family supplies
  (``FAMILY.bind(id, link="rs485").framing``), not something the transport knows: any object with
  ``encode(frame) -> bytes`` and ``deframer()`` (:class:`~servobus.protocols._bound.Framing`) works.
  The rest comes from the family's declaration of the line (``Family.serial``, a
  :class:`~servobus.protocols.SerialLine`): the baud rates its manual allows, the default first,
  and the parity. ``mode=`` names a serial line by its name or an alias, found by asking the
  registered families (:func:`~servobus.protocols.available_families`; a plug-in family's lines
  too), so ``mode="myactuator"``, ``"hollow-transparent"`` and ``"modbus-rtu"`` keep working.
* **The de-framer's counters** (``discarded_bytes``, ``crc_errors``) are read from the family's
  de-framer where it has them as public ``int`` attributes, and kept over reconnections in
  :meth:`~SerialTransport.stats`; a de-framer without them counts 0.
* **The line's rules are declared**, read-only, for the orchestrator to schedule by:
  :attr:`~SerialTransport.rules` (the :class:`~servobus.transports.contract.LineRules` a Bus reads),
  :attr:`~SerialTransport.half_duplex` (True), :attr:`~SerialTransport.max_outstanding` (one
  request per port), :attr:`~SerialTransport.char_time_s`, :attr:`~SerialTransport.gap_s` (rest
  between two frames of ours) and :attr:`~SerialTransport.turnaround_s` (rest after the far end's
  last byte before we drive the line). The Bus will enforce them itself. Standalone (scripts,
  tests) the transport keeps doing it: a frame sent with ``reply_timeout_s`` holds the line until
  one whole frame comes back or the timeout passes, and the rests are kept between frames.
* **Backpressure and freshness** (``_fresh_writer.FreshWriter``). Every byte not yet written stays
  in our own queue; the port gets one frame at a time, and only when it can take it now: the OS
  output buffer holds at most ``high_water_bytes`` (``TIOCOUTQ``, polled no faster than every
  millisecond) and the write does not block (``EAGAIN``: wait for the descriptor to become writable,
  event-driven). A frame older than ``stale_after_s`` when it would be written is dropped (reported
  ``"stale"``), never written; one that cannot be written whole before it goes stale is abandoned
  and its head flushed from the OS buffer (``tcflush``); and when the OS reports bytes it has held,
  without taking more, for longer than ``stale_after_s`` (a stalled adapter), they are flushed too.
  For a motor a stale set-point is worse than none. What the OS cannot report stays out of reach: a
  pty's buffer (``TIOCOUTQ`` says 0) keeps the frames it took while they were fresh.
* **Receiving**: bytes go through the de-framer as they arrive; when no byte has come for
  ``idle_s`` the de-framer is told the line went idle, which drops a stray partial frame as noise
  (and ends a Modbus RTU frame). ``idle_s`` is not the wire's 3.5-character silence: USB adapters
  hand bytes over in bursts (an FTDI's default latency timer is 16 ms), so a host sees gaps inside
  frames that the wire never had. It defaults to 20 ms, or 3.5 characters where that is longer.
* **Loss**: a port that vanishes (EIO, ENODEV, EOF on a pty) fails every waiter at once and is
  reopened by path with backoff, as in :class:`~servobus.transports.base.Transport`.

**Why we write to the descriptor ourselves.** pyserial-asyncio-fast (0.16) has two write-path bugs
that a slow or stalled port triggers
(https://github.com/home-assistant-libs/pyserial-asyncio-fast/pull/36, "fix defered writes"; also
pyserial/pyserial-asyncio#77): a writer callback that stays registered and spins at 100 % CPU, and
pyserial's ``Serial.write``, which with ``write_timeout=0`` retries ``EAGAIN`` in a busy loop. So a
frame goes to the port's file descriptor with ``os.write`` (non-blocking), and a full port is waited
for with ``anyio.wait_writable``. Reading is the descriptor's too, on asyncio and on trio
(:mod:`servobus.transports._serialport`).

pyserial is imported when the first port opens, so CAN-only users never load it.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import anyio

from servobus.frame import Frame
from servobus.protocols import SerialLine, available_families, get_family
from servobus.protocols._bound import Framing, StreamDeframer
from servobus.timing import uart_time_s
from servobus.transports._fresh_writer import FreshWriter
from servobus.transports._serialport import SerialPort
from servobus.transports.base import Outgoing, Transport
from servobus.transports.stats import TransportStats

__all__ = ["SerialTransport", "find_serial_line", "serial_line_names"]

_IDLE_CHARS = 3.5  # Modbus RTU's inter-frame silence, in character times
_READ_SIZE = 16384  # bytes taken from the port per wake-up, at most
_USB_BURST_S = 0.02  # longer than the gaps USB adapters put inside frames (FTDI latency timer: 16 ms)
_HIGH_WATER_BYTES = 64  # about one frame of any built-in framing may wait in the OS buffer

#: a received Frame is fresh from the de-framer, held by nobody else: stamp it in place
_SET_TIMESTAMP: Callable[[Frame, float], None] = Frame.timestamp.__set__  # type: ignore[attr-defined,misc]


_PARITY_BITS = {"N": 0, "E": 1, "O": 1}


def _families_loaded_first() -> list[str]:
    """The registered families' names, those already imported first: a framing in hand means its
    family is loaded, so finding its serial line seldom imports another family."""
    names = available_families()
    loaded = [n for n, target in names.items() if target.partition(":")[0] in sys.modules]
    return loaded + [n for n in names if n not in loaded]


def find_serial_line(name: str) -> SerialLine | None:
    """The registered families' serial line named ``name`` (or with ``name`` among its aliases).

    Families are imported one at a time, the loaded ones first, until one declares it; a plug-in
    family that fails to load is passed over (with the registry's warning).
    """
    for family in _families_loaded_first():
        try:
            lines = get_family(family).serial
        except ValueError:
            continue
        for line in lines:
            if name == line.name or name in line.aliases:
                return line
    return None


def serial_line_names() -> list[str]:
    """Every serial line's name and aliases over the registered families (imports them all)."""
    names: list[str] = []
    for family in available_families():
        try:
            lines = get_family(family).serial
        except ValueError:
            continue
        for line in lines:
            names += [line.name, *line.aliases]
    return names


def _count(deframer: StreamDeframer, name: str) -> int:
    """A de-framer's counter (``discarded_bytes``, ``crc_errors``): an optional public attribute of
    the family's de-framer; 0 where it keeps none."""
    value = getattr(deframer, name, 0)
    return value if isinstance(value, int) else 0


def _line_settings(
    framing: Framing | None, mode: str | None, baud: int | None, parity: str | None
) -> tuple[SerialLine | None, Framing, int, str]:
    """The serial line, framing, baud rate and parity that ``SerialTransport``'s arguments name.

    Raises:
        ValueError: neither framing nor mode, an unknown mode or parity, a rate the line does not use.
    """
    line = None
    if mode is not None:
        line = find_serial_line(mode)
        if line is None:
            raise ValueError(f"mode={mode!r} is not one of {', '.join(serial_line_names())}")
    if framing is None:
        if line is None:
            raise ValueError("give framing= (the family's: FAMILY.bind(1, link='rs485').framing) or mode=")
        framing = line.framing()
    elif not isinstance(framing, Framing):
        raise ValueError(f"framing={framing!r} has no encode(frame) and deframer()")
    elif line is None:
        line = find_serial_line(framing.name)
    label = mode if mode is not None else framing.name
    bauds: tuple[int, ...] | None = line.bauds if line is not None else getattr(framing, "bauds", None)
    if baud is None:
        if not bauds:
            raise ValueError(f"baud= is needed: framing {framing.name!r} names no baud rates")
        baud = bauds[0]
    if bauds and baud not in bauds:
        raise ValueError(f"baud={baud} is not one of {label}'s rates {tuple(bauds)}")
    if parity is None:
        parity = line.parity if line is not None else "N"
    if baud <= 0:
        raise ValueError(f"baud={baud} must be positive")
    if parity not in _PARITY_BITS:
        raise ValueError(f"parity={parity!r} is not one of 'N', 'E', 'O'")
    return line, framing, baud, parity


class SerialTransport(Transport[Frame, Frame]):
    """One RS485 port: serial Frames out one transaction at a time, whole Frames in.

    Args:
        port: the serial device (``/dev/ttyUSB0``, a pty, or a pyserial URL with a file descriptor,
            such as ``socket://``).
        framing: how Frames look on the wire, from the family:
            ``FAMILY.bind(motor_id, link="rs485").framing``.
        mode: the name or an alias of a registered family's serial line (``Family.serial``):
            ``"myactuator"``, ``"hollow-transparent"``, ``"modbus-rtu"``, or a plug-in family's.
            It gives the framing, the baud rates and the parity; with ``framing`` too, only the
            rates and the parity.
        baud: the line's rate; one its serial line allows (default: the first). A framing that
            no family declares takes any rate (its ``bauds`` attribute, if it has one, lists the
            allowed ones) and then needs ``baud``.
        parity: ``"N"``, ``"E"`` or ``"O"`` (default: the serial line's, else ``"N"``; Modbus
            devices differ).
        gap_s: rest between two frames of ours on the line (default: 3.5 character times).
        turnaround_s: rest after the far end's last byte before we send (default: ``gap_s``).
        idle_s: silence after which buffered partial bytes are dropped (default: 20 ms, or 3.5
            character times where that is longer).
        high_water_bytes: the next frame is written only when the OS output buffer holds at most
            this many bytes (default 64, about one frame).
        exclusive: lock the port against other processes (pyserial's ``exclusive``).
        queue_size, rx_buffer, stale_after_s, reopen, reopen_backoff_s: see
            :class:`~servobus.transports.base.Transport`.
        **options: other pyserial arguments.

    Raises:
        ValueError: neither framing nor mode, unknown mode or parity, a baud rate the framing
            does not use, negative times.
    """

    batch_size = 1  # half-duplex: one transaction at a time

    def __init__(
        self,
        port: str,
        *,
        framing: Framing | None = None,
        mode: str | None = None,
        baud: int | None = None,
        parity: str | None = None,
        gap_s: float | None = None,
        turnaround_s: float | None = None,
        idle_s: float | None = None,
        high_water_bytes: int = _HIGH_WATER_BYTES,
        exclusive: bool = True,
        queue_size: int = 256,
        rx_buffer: int = 65536,
        stale_after_s: float | None = 0.5,
        reopen: bool = True,
        reopen_backoff_s: tuple[float, float] = (0.05, 2.0),
        **options: Any,
    ) -> None:
        self.mode: str | None = mode
        #: the family's serial line this transport runs (None: a framing no family declares)
        self.line: SerialLine | None
        self.line, self._framing, baud, parity = _line_settings(framing, mode, baud, parity)
        negative = any(t is not None and t < 0 for t in (gap_s, turnaround_s))
        if negative or (idle_s is not None and idle_s <= 0):
            raise ValueError(
                f"need gap_s, turnaround_s >= 0 and idle_s > 0 (gap_s={gap_s}, "
                f"turnaround_s={turnaround_s}, idle_s={idle_s})"
            )
        if high_water_bytes < 0:
            raise ValueError(f"high_water_bytes={high_water_bytes} must be >= 0")
        super().__init__(
            name=f"rs485:{port}",
            queue_size=queue_size,
            rx_buffer=rx_buffer,
            stale_after_s=stale_after_s,
            reopen=reopen,
            reopen_backoff_s=reopen_backoff_s,
        )
        self.port = port
        self.baud = baud
        self.parity = parity
        self.bits_per_char = 10 + _PARITY_BITS[parity]
        self._char_time_s = uart_time_s(1, baud, bits_per_byte=self.bits_per_char)
        silence_s = self._char_time_s * _IDLE_CHARS
        self._gap_s = silence_s if gap_s is None else gap_s
        self._turnaround_s = self._gap_s if turnaround_s is None else turnaround_s
        self.idle_s = max(silence_s, _USB_BURST_S) if idle_s is None else idle_s
        self._serial_options = {"exclusive": exclusive, **options}
        self._deframer: StreamDeframer = self._framing.deframer()
        self._old_counts = [0, 0]  # discarded bytes, CRC errors of the de-framers of past connections
        self._load_known = True
        self._port: SerialPort | None = None
        self._writer_line = FreshWriter(
            high_water_bytes=high_water_bytes,
            char_time_s=self._char_time_s,
            stale_after_s=stale_after_s,
            clock=self._now,
        )
        self._tx_quiet_at = 0.0  # loop time our last byte ends on the wire
        self._rx_quiet_at = 0.0  # loop time the far end's last byte came
        self._quiet: _QuietWatch | None = None
        self._reply: anyio.Event | None = None

    # ----------------------------------------------------------------- the line's rules

    @property
    def framing(self) -> Framing:
        """How Frames look on this line's wire (the family's plug-in)."""
        return self._framing

    @property
    def half_duplex(self) -> bool:
        """One direction at a time: a request and its reply never overlap on the line."""
        return True

    @property
    def max_outstanding(self) -> int:
        """Requests awaiting a reply at once on this port: one."""
        return 1

    @property
    def char_time_s(self) -> float:
        """One character on the wire: start, 8 data bits, parity if any, stop, at the baud rate."""
        return self._char_time_s

    @property
    def gap_s(self) -> float:
        """Rest between the end of one frame of ours and the start of the next (3.5 characters)."""
        return self._gap_s

    @property
    def turnaround_s(self) -> float:
        """Rest between the far end's last byte and our next frame (the line changes direction)."""
        return self._turnaround_s

    @property
    def high_water_bytes(self) -> int:
        """Bytes the OS output buffer may hold when the next frame is written."""
        return self._writer_line.high_water_bytes

    def wire_time_s(self, n_bytes: int) -> float:
        """Seconds ``n_bytes`` occupy this line."""
        return n_bytes * self._char_time_s

    # ----------------------------------------------------------------- public API

    def send(self, frame: Frame, handle: object = None, *, reply_timeout_s: float | None = None) -> None:
        """Queue one serial Frame (as the family's codec encoded it on its ``"rs485"`` link).

        Args:
            handle: what the send report names (the frame itself when None).
            reply_timeout_s: a reply is expected: keep the line for up to this long after the
                frame has left, until a whole frame comes back. None: no reply (broadcast).

        Raises:
            ValueError: not a serial Frame, one the framing refuses, or a negative timeout.
            SendQueueFull: the queue is full.
            TransportError: the port is not open (lost or closed).
        """
        if not isinstance(frame, Frame) or not frame.is_serial:
            raise ValueError(f"{frame!r} is not a serial Frame (is_serial=True): RS485 carries those")
        if reply_timeout_s is not None and reply_timeout_s < 0:
            raise ValueError(f"reply_timeout_s={reply_timeout_s} must be >= 0")
        self._framing.encode(frame)  # refuse now what the framing cannot put on the wire
        self._enqueue(frame, reply_timeout_s, handle)

    def stats(self) -> TransportStats:
        snapshot = super().stats()
        snapshot.discarded_bytes = self._old_counts[0] + _count(self._deframer, "discarded_bytes")
        snapshot.crc_errors = self._old_counts[1] + _count(self._deframer, "crc_errors")
        return snapshot

    # ----------------------------------------------------------------- connection

    async def _connect(self) -> None:
        # Bytes of a frame cut by the loss cannot be completed: a fresh de-framer, counts kept.
        self._old_counts[0] += _count(self._deframer, "discarded_bytes")
        self._old_counts[1] += _count(self._deframer, "crc_errors")
        self._deframer = self._framing.deframer()
        assert self._runtime is not None  # set by open()
        generation = self._generation  # (the lambdas look the methods up per call: tests wrap them)
        self._port = SerialPort.open(
            self.name,
            lambda data: self._on_bytes(data, generation),
            lambda cause: self._lose(cause, generation),
            self.port,
            self._runtime,
            self._tasks,
            read_size=_READ_SIZE,
            baudrate=self.baud,
            parity=self.parity,
            bytesize=8,
            stopbits=1,
            **self._serial_options,
        )
        self._quiet = _QuietWatch(self.idle_s, self._now, lambda: self._on_quiet(generation))
        self._tasks.start_soon(self._quiet.run, name=f"{self.name} idle")
        self._writer_line.reset()

    async def _disconnect(self) -> None:
        port, self._port = self._port, None
        quiet, self._quiet = self._quiet, None
        if quiet is not None:
            quiet.stop()
        if port is not None:
            await port.close()

    # ----------------------------------------------------------------- receiving

    def _on_bytes(self, data: bytes, generation: int) -> None:
        if generation != self._generation:
            return
        now = self._now()
        self._stats.bytes_in += len(data)
        self._load.add(now, uart_time_s(len(data), self.baud, bits_per_byte=self.bits_per_char))
        self._rx_quiet_at = now
        if self._quiet is not None:
            self._quiet.arm(now)
        self._take(self._deframer.feed(data), now)

    def _on_quiet(self, generation: int) -> bool:
        """No byte for ``idle_s``: the de-framer drops (or ends) the partial frame it holds.
        False (nothing done) when the connection that timed it is no longer the current one."""
        if generation != self._generation:
            return False
        self._take(self._deframer.idle(), self._now())
        return True

    def _take(self, frames: list[Frame], now: float) -> None:
        if not frames:
            return
        for frame in frames:
            _SET_TIMESTAMP(frame, now)
        self._stats.frames_in += len(frames)
        self._deliver(frames)
        if self._reply is not None:
            self._reply.set()

    # ----------------------------------------------------------------- sending

    async def _transmit(self, batch: list[Outgoing[Frame]]) -> None:
        stats = self._stats
        limit = self.stale_after_s
        generation = self._generation
        while batch:
            outgoing = batch[0]
            deadline = None if limit is None else outgoing.queued_at + limit
            rest = max(self._tx_quiet_at + self._gap_s, self._rx_quiet_at + self._turnaround_s) - self._now()
            if rest > 0:
                await anyio.sleep(rest)
            port = self._port
            if port is None or port.failed:  # failed while we rested: the base purges the rest
                return
            data = self._framing.encode(outgoing.item)
            try:
                now = await self._writer_line.write(port, data, deadline)
            except OSError as exc:  # the port failed under the write (EIO: unplugged)
                self._lose(exc, generation)
                return
            batch.pop(0)
            if now is None:
                self._dropped("stale", [outgoing.handle])
                continue
            reply = None if outgoing.hold_s is None else anyio.Event()
            self._reply = reply
            on_wire_s = self._char_time_s * len(data)
            self._tx_quiet_at = now + on_wire_s
            stats.frames_out += 1
            stats.bytes_out += len(data)
            self._load.add(now, on_wire_s)
            self._sent(outgoing.handle, now)
            if reply is not None and outgoing.hold_s is not None:
                try:
                    # no reply in time: the line is free again; matching the silence is the caller's job
                    with anyio.move_on_after(on_wire_s + outgoing.hold_s):
                        await reply.wait()
                finally:
                    self._reply = None


class _QuietWatch:
    """One connection's silence timer: ``idle_s`` after the last byte (on ``clock``), ``on_quiet()``;
    it ends when that returns False (the connection is no longer the current one).

    A task in the transport's task group that sleeps while bytes come and waits while none are
    expected, so a burst costs one flag, not a timer per read.
    """

    def __init__(self, idle_s: float, clock: Callable[[], float], on_quiet: Callable[[], bool]) -> None:
        self._idle_s = idle_s
        self._clock = clock
        self._on_quiet = on_quiet
        #: when the last byte came (the clock's time)
        self.last_rx = 0.0
        self._armed = False
        self._wake = anyio.Event()
        self._scope = anyio.CancelScope()

    def arm(self, now: float) -> None:
        """Bytes came at ``now``: time the silence after them (the silence restarts while timed)."""
        self.last_rx = now
        if not self._armed:
            self._armed = True
            self._wake.set()

    def stop(self) -> None:
        self._scope.cancel()

    async def run(self) -> None:
        clock, idle_s = self._clock, self._idle_s
        with self._scope:
            while True:
                await self._wake.wait()
                self._wake = anyio.Event()
                while (still := self.last_rx + idle_s - clock()) > 0:
                    await anyio.sleep(still)  # bytes came meanwhile: the silence starts over
                self._armed = False
                if not self._on_quiet():
                    return
