"""SLCAN (LAWICEL) USB-CAN adapters, natively: the port's descriptor on the loop, the C core cuts lines.

:class:`SlcanTransport` speaks to an SLCAN adapter (CANable, CANUSB, the hollow manual's USB-CANFD
adapter, the simulator's pty) without python-can, on the event loop (asyncio or trio), with no thread:

* **Receiving**: the bytes the adapter sends go through :class:`~servobus.core.SlcanDeframer` as
  they arrive (up to 64 KiB per wake-up). A malformed line (``t12``, bad hex, an 11-bit id above
  0x7FF, a DLC that disagrees with its data) is counted in ``stats().bad_frames`` and dropped; the
  frames around it still arrive and the transport stays OPEN. A line longer than the longest valid
  one is dropped without being held, so a peer sending bytes without end costs a fixed 142-byte
  buffer. Remote frames are counted in ``ignored`` and dropped. Adapter replies (OK, BEL, ``z``/``Z``
  acknowledgements) are counted in :meth:`SlcanTransport.line_counters`.
* **Opening**: ``C`` (close whatever was open), ``S0``..``S8`` for the nominal bit rate, ``Y1``/``Y2``/
  ``Y4``/``Y5`` for a CAN FD data rate, then ``O`` (``L`` for listen-only), each answered before the
  next goes. A BEL to ``S``, ``Y`` or ``O``, or no answer within ``open_timeout_s``, fails the open
  with :class:`~servobus.errors.TransportError`. ``bitrate=None`` leaves the adapter's rate alone.
* **Sending**: frames become ``t``/``T`` lines (``d``/``D``/``b``/``B`` for CAN FD) written straight to
  the port's file descriptor, a batch per write, never more than the kernel takes at once: lines
  the kernel did not take stay in our queue, where ``stale_after_s`` still applies (only a line
  cut in the middle is finished before anything else). pyserial's own write path is not used: with
  ``write_timeout=0`` it retries EAGAIN in a busy loop.
* **A stalled adapter is backpressure, not loss**: when the port takes nothing (EAGAIN) or the
  driver's output queue (``out_waiting``) is above ``write_high_water`` bytes, the writer waits;
  ``send`` keeps queueing until the queue is full (:class:`~servobus.transports.base.SendQueueFull`),
  and a frame that waited longer than ``stale_after_s`` is dropped (counted and reported), never
  written late. Bytes already in the kernel's buffer are beyond recall: on a real tty the high-water
  mark bounds them; a pty reports no output queue.
* **Loss**: a port that vanishes (EIO, EOF on a pty, an unplugged adapter) fails every waiter at
  once and the port is reopened by path with backoff, as in
  :class:`~servobus.transports.base.Transport`.

pyserial is imported when the first port opens (see :mod:`servobus.transports._serialport`).
"""

from __future__ import annotations

import binascii
import contextlib
from typing import Any

import anyio

from servobus.core import SlcanDeframer
from servobus.errors import TransportError
from servobus.frame import Frame
from servobus.timing import format_duration, nominal_frame_time_s
from servobus.transports._serialport import SerialPort
from servobus.transports.base import Outgoing, Transport
from servobus.transports.stats import TransportStats

__all__ = ["DATA_BITRATES", "NOMINAL_BITRATES", "SlcanTransport", "encode_line"]

#: LAWICEL's ``Sn`` table (S7 is 800 kbit/s there).
NOMINAL_BITRATES: dict[int, int] = {
    10_000: 0,
    20_000: 1,
    50_000: 2,
    100_000: 3,
    125_000: 4,
    250_000: 5,
    500_000: 6,
    800_000: 7,
    1_000_000: 8,
}
#: ``Yn`` of CANable-2.0-type CAN FD firmware.
DATA_BITRATES: dict[int, int] = {1_000_000: 1, 2_000_000: 2, 4_000_000: 4, 5_000_000: 5}

_READ_SIZE = 65536  # bytes taken from the port per wake-up, at most
_STALL_POLL_S = 0.001  # how often a writer held by the driver's output queue looks again
_FD_DLC = {n: code for code, n in enumerate((0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64))}
_FD_KINDS = {(False, False): b"d", (True, False): b"D", (False, True): b"b", (True, True): b"B"}
_HEX = binascii.hexlify


def encode_line(frame: Frame) -> bytes:
    """The LAWICEL line (CR included) that transmits ``frame``: ``t``/``T``, or ``d``/``D``/``b``/``B``."""
    data = frame.data
    if frame.is_fd:
        kind = _FD_KINDS[frame.is_extended_id, frame.bitrate_switch]
        dlc = _FD_DLC[len(data)]
    else:
        kind = b"T" if frame.is_extended_id else b"t"
        dlc = len(data)
    form = b"%s%08X%X" if frame.is_extended_id else b"%s%03X%X"
    return form % (kind, frame.arbitration_id, dlc) + _HEX(data).upper() + b"\r"


class SlcanTransport(Transport[Frame, Frame]):
    """One SLCAN adapter on a serial port (USB CDC, a pty): CAN and CAN FD frames in and out.

    Args:
        port: the serial device (``/dev/ttyACM0``, a pty, or any pyserial URL with a file descriptor).
        bitrate: nominal bit rate, one of :data:`NOMINAL_BITRATES` (``S0``..``S8``); None leaves the
            adapter's configured rate as it is (and the bus load unknown).
        data_bitrate: CAN FD data rate, one of :data:`DATA_BITRATES` (``Y1``..``Y5``); implies ``fd``.
        fd: accept CAN FD frames for sending (received FD frames always arrive).
        listen_only: open with ``L``: frames are received, none can be sent.
        timestamps: the adapter appends 4-digit timestamps to its lines (it was configured with
            ``Z1`` elsewhere); servobus does not send ``Z``.
        tty_baudrate: the serial line's own rate (USB CDC adapters ignore it).
        write_high_water: bytes the driver's output queue may hold before the writer waits.
        min_gap_s: least time between the starts of two written frames (0: batches back to back);
            for adapters that overflow when fed faster than their bus.
        open_timeout_s: how long each open command may wait for the adapter's answer.
        exclusive: lock the port against other processes (pyserial's ``exclusive``).
        queue_size, rx_buffer, stale_after_s, reopen, reopen_backoff_s: see
            :class:`~servobus.transports.base.Transport`.
        **options: other pyserial arguments.

    Raises:
        ValueError: a bit rate the adapter has no command for, or an option out of range.
    """

    def __init__(
        self,
        port: str,
        *,
        bitrate: int | None = 1_000_000,
        data_bitrate: int | None = None,
        fd: bool = False,
        listen_only: bool = False,
        timestamps: bool = False,
        tty_baudrate: int = 115_200,
        write_high_water: int = 4096,
        min_gap_s: float = 0.0,
        open_timeout_s: float = 1.0,
        exclusive: bool = True,
        queue_size: int = 256,
        rx_buffer: int = 65536,
        stale_after_s: float | None = 0.5,
        reopen: bool = True,
        reopen_backoff_s: tuple[float, float] = (0.05, 2.0),
        **options: Any,
    ) -> None:
        if bitrate is not None and bitrate not in NOMINAL_BITRATES:
            raise ValueError(f"bitrate={bitrate} is not an SLCAN rate (one of {sorted(NOMINAL_BITRATES)})")
        if data_bitrate is not None and data_bitrate not in DATA_BITRATES:
            raise ValueError(
                f"data_bitrate={data_bitrate} is not an SLCAN CAN FD rate (one of {sorted(DATA_BITRATES)})"
            )
        if write_high_water < 0 or min_gap_s < 0 or open_timeout_s <= 0:
            raise ValueError(
                f"need write_high_water >= 0, min_gap_s >= 0 and open_timeout_s > 0 (write_high_water="
                f"{write_high_water}, min_gap_s={min_gap_s}, open_timeout_s={open_timeout_s})"
            )
        super().__init__(
            name=f"slcan:{port}",
            queue_size=queue_size,
            rx_buffer=rx_buffer,
            stale_after_s=stale_after_s,
            reopen=reopen,
            reopen_backoff_s=reopen_backoff_s,
        )
        self.port = port
        self.bitrate = bitrate
        self.data_bitrate = data_bitrate
        self.fd = fd or data_bitrate is not None
        self.listen_only = listen_only
        self.tty_baudrate = tty_baudrate
        self.write_high_water = write_high_water
        self.min_gap_s = min_gap_s
        self.open_timeout_s = open_timeout_s
        self._last_start = -float("inf")  # loop time the last frame was written (for min_gap_s)
        self._serial_options = {"exclusive": exclusive, **options}
        self._deframer = SlcanDeframer(timestamps=timestamps)
        self._load_known = bitrate is not None
        self._port: SerialPort | None = None
        self._tail = b""  # the unwritten rest of a line the kernel took only part of
        self._answer: anyio.Event | None = None  # an open command waiting for OK or BEL

    # ----------------------------------------------------------------- public API

    def send(self, frame: Frame, handle: object = None) -> None:
        """Queue ``frame``; the writer puts it on the port in order. The send report names ``handle``
        (the frame itself when None).

        Raises:
            ValueError: a serial-link message, a CAN FD frame without ``fd=True``, or any frame on a
                listen-only adapter.
            SendQueueFull: the queue is full.
            TransportError: the adapter is not open (lost or closed).
        """
        if frame.is_serial:
            raise ValueError(f"{self.name}: {frame!r} is a serial-link message, not a CAN frame")
        if frame.is_fd and not self.fd:
            raise ValueError(f"{self.name}: CAN FD frame {frame!r} on an adapter opened without fd=True")
        if self.listen_only:
            raise ValueError(f"{self.name}: the adapter is open listen-only; it sends nothing")
        self._enqueue(frame, None, handle)

    def line_counters(self) -> dict[str, int]:
        """The line de-framer's counters since creation: frames, remote, acks (``z``/``Z``), oks (empty
        lines), bells (BEL: the adapter refused a command or frame), malformed, overlong,
        discarded_bytes, pending (bytes of the line held now)."""
        d = self._deframer
        return {
            "frames": d.frames,
            "remote": d.remote,
            "acks": d.acks,
            "oks": d.oks,
            "bells": d.bells,
            "malformed": d.malformed,
            "overlong": d.overlong,
            "discarded_bytes": d.discarded_bytes,
            "pending": d.pending,
        }

    def stats(self) -> TransportStats:
        snapshot = super().stats()
        d = self._deframer
        snapshot.bad_frames += d.malformed + d.overlong
        snapshot.ignored += d.remote
        snapshot.discarded_bytes = d.discarded_bytes
        return snapshot

    # ----------------------------------------------------------------- connection

    async def _connect(self) -> None:
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
            baudrate=self.tty_baudrate,
            **self._serial_options,
        )
        self._deframer.clear()  # a line cut by the loss cannot be completed
        self._tail = b""
        try:
            await self._open_channel()
        except BaseException:
            with anyio.CancelScope(shield=True):
                await self._disconnect()
            raise

    async def _open_channel(self) -> None:
        await self._command(b"C", must_succeed=False)  # BEL when nothing was open: fine
        if self.bitrate is not None:
            await self._command(b"S%d" % NOMINAL_BITRATES[self.bitrate])
        if self.data_bitrate is not None:
            await self._command(b"Y%d" % DATA_BITRATES[self.data_bitrate])
        await self._command(b"L" if self.listen_only else b"O")

    async def _command(self, command: bytes, *, must_succeed: bool = True) -> None:
        """Write one configuration command and wait for its answer (CR: done, BEL: refused)."""
        assert self._port is not None
        deframer = self._deframer
        answered = deframer.oks + deframer.bells
        bells = deframer.bells
        try:
            try:
                written = self._port.write(command + b"\r")
            except OSError as exc:
                raise TransportError(f"{self.name}: cannot write {command.decode()!r}: {exc}") from exc
            if written != len(command) + 1:
                raise TransportError(f"{self.name}: the adapter did not take {command.decode()!r}")
            with anyio.fail_after(self.open_timeout_s):
                while deframer.oks + deframer.bells == answered:
                    self._answer = anyio.Event()
                    await self._answer.wait()
        except TimeoutError:
            raise TransportError(
                f"{self.name}: no answer to {command.decode()!r} within "
                f"{format_duration(self.open_timeout_s)}: is it an SLCAN adapter?"
            ) from None
        finally:
            self._answer = None
        if must_succeed and deframer.bells != bells:
            raise TransportError(f"{self.name}: the adapter refused {command.decode()!r} (BEL)")

    async def _disconnect(self) -> None:
        port, self._port = self._port, None
        self._tail = b""
        if port is None:
            return
        if not port.failed:
            with contextlib.suppress(OSError):
                port.write(b"C\r")  # take the adapter off the bus; best effort
        await port.close()

    # ----------------------------------------------------------------- receiving

    def _on_bytes(self, data: bytes, generation: int) -> None:
        if generation != self._generation:
            return
        now = self._now()
        frames = self._deframer.feed(data, now)
        if self._answer is not None:
            self._answer.set()
        if not frames:
            return
        stats = self._stats
        stats.frames_in += len(frames)
        stats.bytes_in += sum(len(frame.data) for frame in frames)
        if self._load_known:
            self._load.add(now, sum(self._frame_time_s(frame) for frame in frames))
        self._deliver(frames)

    def _frame_time_s(self, frame: Frame) -> float:
        assert self.bitrate is not None
        return nominal_frame_time_s(frame, self.bitrate, self.data_bitrate)

    # ----------------------------------------------------------------- sending

    async def _transmit(self, batch: list[Outgoing[Frame]]) -> None:
        generation = self._generation
        stats = self._stats
        limit = self.stale_after_s
        gap = self.min_gap_s
        while batch:
            port = self._port
            if port is None or port.failed or not await self._wait_for_room(port):
                return  # the line went away: the base counts the rest as purged
            now = self._now()
            if gap and (rest := self._last_start + gap - now) > 0:
                await anyio.sleep(rest)
                continue  # look at room and freshness again after the rest
            if limit is not None and now - batch[0].queued_at > limit:
                stale = [o for o in batch if now - o.queued_at > limit]
                batch[:] = [o for o in batch if now - o.queued_at <= limit]
                self._dropped("stale", [o.handle for o in stale])
                if not batch:
                    return
            lines = [encode_line(o.item) for o in (batch[:1] if gap else batch)]
            data = b"".join(lines)
            try:
                written = port.write(data)
            except BlockingIOError:
                written = 0
            except OSError as exc:
                self._lose(exc, generation)
                return
            # Frames whose line went out whole, or at least started (its rest is finished first).
            sent = end = 0
            while sent < len(lines) and end < written:
                end += len(lines[sent])
                sent += 1
            if end > written:
                self._tail = data[written:end]
            if sent:
                self._last_start = now
            for outgoing in batch[:sent]:
                frame = outgoing.item
                stats.frames_out += 1
                stats.bytes_out += len(frame.data)
                if self._load_known:
                    self._load.add(now, self._frame_time_s(frame))
                self._sent(outgoing.handle, now)
            del batch[:sent]
        port = self._port
        if self._tail and port is not None:
            await self._wait_for_room(port)  # a cut line is finished before the writer rests

    async def _wait_for_room(self, port: SerialPort) -> bool:
        """Finish a cut line, then wait until the driver's output queue is below the high-water mark;
        False when the port failed meanwhile."""
        while not port.failed:
            if self._tail:
                try:
                    self._tail = self._tail[port.write(self._tail) :]
                except BlockingIOError:
                    await port.wait_writable()
                except OSError as exc:
                    self._lose(exc, self._generation)
                    return False
                continue
            try:
                queued = port.out_waiting()
            except OSError:  # a failing port: the reader reports it
                queued = 0
            if queued > self.write_high_water:
                await anyio.sleep(_STALL_POLL_S)
                continue
            return True
        return False
