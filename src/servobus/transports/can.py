"""CAN and CAN FD through python-can: any interface it supports, configured the way it is.

* **Configuration** is python-can's own, merged once: arguments first, then ``can.rc``, the
  environment (``CAN_INTERFACE``, ``CAN_CHANNEL``, ``CAN_BITRATE``, ``CAN_CONFIG``) and the config
  files (``~/.canrc``, ``~/can.conf``, ...), in python-can's order (``can.util.load_config``).
  ``config_context`` picks a section; ``ignore_config=True`` uses the arguments alone.
* **Receiving** runs inside the event loop: where the bus has a file descriptor (socketcan,
  slcan and other serial adapters) the loop watches it (``add_reader``) and reads one frame per
  readiness, with no thread. Buses without one (virtual, most vendor drivers) get a single reader
  thread, as python-can's own ``Notifier`` does, which hands frames over in batches.
* **Sending** never blocks the loop: python-can's ``send`` is a blocking call on most
  interfaces, so the queued frames go to one writer thread per transport, in order, with an
  optional minimum gap between frames. A full adapter buffer (ENOBUFS, "transmit buffer full")
  is handled by policy: ``"wait"`` retries until ``enobufs_timeout_s`` and then drops, ``"drop"``
  drops at once; both are counted.
* **Filters**: :meth:`CanTransport.set_receive_ids` installs exact-match filters for the reply
  identifiers in use; python-can puts them in the kernel or adapter where the interface can, and
  filters in software otherwise. They are re-applied after a reopen.
* **An application's bus**: ``CanTransport(bus)`` takes a ``can.BusABC`` that is open already
  (and ``notifier=``, the application's ``can.Notifier`` on it, when there is one; a bus with a
  running notifier is joined by itself). servobus then listens through that notifier instead of
  reading the bus, filters its reply identifiers in software, and never shuts the bus down.
* **Error frames** become :class:`~servobus.transports.events.ErrorFrame` events (and
  :class:`~servobus.transports.events.BusOff` for bus-off); remote frames are counted and dropped.

The conversions between :class:`~servobus.frame.Frame` and ``can.Message`` are
:meth:`Frame.from_message <servobus.frame.Frame.from_message>` and :func:`message_from_frame` (which
:meth:`Frame.to_message <servobus.frame.Frame.to_message>` calls: servobus.frame never imports can).
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import functools
import queue
import threading
import time
from collections.abc import Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor
from copy import deepcopy
from dataclasses import dataclass, field
from typing import Any, Literal

import can

from servobus.errors import TransportError
from servobus.frame import Frame
from servobus.timing import nominal_frame_time_s
from servobus.transports.base import Outgoing, Transport, logger
from servobus.transports.events import BusOff, CanErrorClass, ErrorFrame

__all__ = ["CanMessage", "CanTransport", "frame_from_message", "message_from_frame"]

_THREAD_POLL_S = 0.05  # how long a reader thread blocks in recv(): bounds how fast close() is
_THREAD_BATCH = 256  # frames a reader thread hands to the loop per wake-up, at most
_ENOBUFS_RETRY_S = 0.0005


def frame_from_message(message: can.Message, timestamp: float) -> Frame:
    """A received ``can.Message`` as a :class:`Frame` stamped ``timestamp``: :meth:`Frame.from_message`.

    Raises:
        ValueError: a remote or error frame, a DLC that disagrees with the data, or an id or length
            out of range.
    """
    return Frame.from_message(message, timestamp)


def message_from_frame(frame: Frame, **message: Any) -> can.Message:
    """A :class:`Frame` as a ``can.Message`` (:meth:`Frame.to_message`): identifier, extended, FD,
    BRS, ESI, data, ``is_rx`` and timestamp; ``message`` adds other ``can.Message`` arguments.

    Raises:
        ValueError: a serial-link message, which has no CAN form.
    """
    if frame.is_serial:
        raise ValueError(f"{frame!r} is a serial-link message, not a CAN frame")
    return can.Message(
        timestamp=frame.timestamp,
        arbitration_id=frame.arbitration_id,
        data=frame.data,
        is_extended_id=frame.is_extended_id,
        is_fd=frame.is_fd,
        bitrate_switch=frame.bitrate_switch,
        error_state_indicator=frame.error_state_indicator,
        is_rx=frame.is_rx,
        check=False,  # a Frame is valid already
        **message,
    )


#: python-can's ``Message``, under a name :mod:`servobus.frame` can annotate with (it never imports can).
CanMessage = can.Message


class _NotifierListener(can.Listener):
    """What a :class:`CanTransport` adds to an application's ``can.Notifier``: the frames the
    notifier reads go to the transport's loop in batches; a reader failure is a lost device."""

    def __init__(self, transport: CanTransport, loop: asyncio.AbstractEventLoop, generation: int) -> None:
        self._transport = transport
        self._loop = loop
        self._generation = generation
        self._pending: list[tuple[can.Message, float]] = []
        self._lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        with self._lock:
            self._pending.append((msg, time.monotonic()))  # the loop's clock on a plain asyncio loop
            if len(self._pending) > 1:
                return  # a hand-over is already on its way
        if asyncio._get_running_loop() is self._loop:  # a notifier running on our own loop
            self._flush()
            return
        with contextlib.suppress(RuntimeError):  # the loop is gone: nobody is left to take it
            self._loop.call_soon_threadsafe(self._flush)

    def _flush(self) -> None:
        with self._lock:
            batch, self._pending = self._pending, []
        self._transport._take(batch, self._generation)

    def on_error(self, exc: Exception) -> None:
        """A read failed in the notifier: a lost device (or one bad frame) for the transport.

        Raises NotImplementedError, python-can's "not handled here", so whether the application's
        notifier stops or reads on stays its own listeners' decision, as without servobus.
        """
        transport, generation = self._transport, self._generation
        with contextlib.suppress(RuntimeError):
            if _device_failed(exc):
                self._loop.call_soon_threadsafe(transport._lose, exc, generation)
            else:  # a frame python-can could not parse
                self._loop.call_soon_threadsafe(transport._count_bad, 1, generation)
        raise NotImplementedError

    def stop(self) -> None:
        pass


@dataclass(slots=True)
class _SendReport:
    """What the writer thread did with one batch (times on time.monotonic, the loop's clock)."""

    sent: list[tuple[Frame, float]] = field(default_factory=list)
    stale: list[Frame] = field(default_factory=list)
    purged: list[Frame] = field(default_factory=list)
    enobufs_waits: int = 0
    enobufs_dropped: list[Frame] = field(default_factory=list)
    error: BaseException | None = None


class CanTransport(Transport[Frame, Frame]):
    """A CAN or CAN FD bus through python-can.

    Args:
        interface, channel: python-can's; None takes them from python-can's configuration. Or
            ``interface`` is a ``can.BusABC`` the application opened already: servobus sends and
            receives through it, never changes its filters (``receive_ids`` filter in software)
            and never shuts it down (closing the transport leaves it open; a lost one is not
            reopened behind the application's back).
        notifier: the application's ``can.Notifier`` on that bus: servobus adds itself to it as a
            listener instead of reading the bus itself (a bus has one reader). Without it, a bus
            that already has a notifier (``can.Notifier.find_instances``) is joined the same way.
        bitrate, data_bitrate: python-can's (nominal and CAN FD data rate). Also used for the
            bus-load estimate; without a bit rate from arguments or configuration the load is
            unknown (None).
        fd: open the bus for CAN FD (python-can's ``fd``); FD frames are refused without it.
        config_context, ignore_config: python-can's configuration section, or none at all.
        min_gap_s: least time between the starts of two sent frames (0: back to back).
        enobufs: what to do when the adapter's send buffer is full: ``"wait"`` or ``"drop"``.
        enobufs_timeout_s: with ``"wait"``, how long one frame may wait for buffer room.
        send_timeout_s: the timeout given to python-can's ``send``.
        receive_ids: reply identifiers to filter for (see :meth:`set_receive_ids`).
        queue_size, rx_buffer, stale_after_s, reopen, reopen_backoff_s: see
            :class:`~servobus.transports.base.Transport`.
        **options: any other python-can argument (``sleep_after_open``, ``receive_own_messages``,
            ``tty_baudrate``, ...).

    Raises:
        ValueError: no interface given or configured, or an option out of range.
    """

    def __init__(
        self,
        interface: str | can.BusABC | None = None,
        channel: Any = None,
        *,
        notifier: can.Notifier | None = None,
        bitrate: int | None = None,
        data_bitrate: int | None = None,
        fd: bool = False,
        config_context: str | None = None,
        ignore_config: bool = False,
        min_gap_s: float = 0.0,
        enobufs: Literal["wait", "drop"] = "wait",
        enobufs_timeout_s: float = 0.1,
        send_timeout_s: float | None = 0.05,
        receive_ids: Iterable[int] | None = None,
        queue_size: int = 256,
        rx_buffer: int = 65536,
        stale_after_s: float | None = 0.5,
        reopen: bool = True,
        reopen_backoff_s: tuple[float, float] = (0.05, 2.0),
        **options: Any,
    ) -> None:
        if enobufs not in ("wait", "drop"):
            raise ValueError(f"enobufs={enobufs!r} must be 'wait' or 'drop'")
        if min_gap_s < 0 or enobufs_timeout_s < 0:
            raise ValueError(f"min_gap_s={min_gap_s} and enobufs_timeout_s={enobufs_timeout_s} must be >= 0")
        if interface is None and notifier is not None:
            buses = notifier.bus if isinstance(notifier.bus, tuple | list) else (notifier.bus,)
            if len(buses) != 1:
                raise ValueError(f"the notifier reads {len(buses)} buses: give the one to use")
            interface = buses[0]
        self._borrowed: can.BusABC | None = None
        self._notifier = notifier
        if isinstance(interface, can.BusABC):
            if channel is not None or options or config_context is not None:
                raise ValueError("an open can.BusABC takes no channel, configuration or python-can options")
            self._borrowed = interface
            interface = None
            ignore_config = True
            options = {"interface": _interface_name(self._borrowed)}
            fd = fd or getattr(self._borrowed, "protocol", None) in _FD_PROTOCOLS
            reopen = False
        elif interface is not None and not isinstance(interface, str):
            raise TypeError(
                f"interface must be a python-can interface name or a can.BusABC, not {interface!r}"
            )
        elif notifier is not None:
            raise ValueError("a notifier goes with the open can.BusABC it reads")
        given = {"interface": interface, "channel": channel, "bitrate": bitrate, "data_bitrate": data_bitrate}
        config: dict[str, Any] = {key: value for key, value in given.items() if value is not None}
        config.update(options)
        if fd:
            config["fd"] = True
        if not ignore_config:
            try:
                config = dict(can.util.load_config(config=config, context=config_context))
            except can.CanInterfaceNotImplementedError as exc:
                raise ValueError(f"no usable CAN interface: {exc}") from exc
        if not config.get("interface"):
            raise ValueError("no CAN interface given and none in python-can's configuration")
        self.config = config
        self.fd = bool(config.get("fd", False))
        self.bitrate: int | None = config.get("bitrate")
        self.data_bitrate: int | None = config.get("data_bitrate")
        channel_name = config.get("channel") if self._borrowed is None else self._borrowed.channel_info
        super().__init__(
            name=f"can:{config['interface']}:{channel_name}",
            queue_size=queue_size,
            rx_buffer=rx_buffer,
            stale_after_s=stale_after_s,
            reopen=reopen,
            reopen_backoff_s=reopen_backoff_s,
        )
        self._load_known = self.bitrate is not None
        self._min_gap_s = min_gap_s
        self._enobufs = enobufs
        self._enobufs_timeout_s = enobufs_timeout_s
        self._send_timeout_s = send_timeout_s
        self._filters: list[can.typechecking.CanFilter] | None = None
        if receive_ids is not None:
            self._filters = _exact_filters(receive_ids, extended=False)
        # An application's bus keeps its own filters: the identifiers are checked here instead.
        self._wanted = _wanted(self._filters) if self._borrowed is not None else None
        self._bus: can.BusABC | None = None
        self._listener: _NotifierListener | None = None
        self._listening: can.Notifier | None = None
        self._reader_fd: int | None = None
        self._reader_thread: threading.Thread | None = None
        self._reader_stop = threading.Event()
        self._executor: ThreadPoolExecutor | None = None
        self._send_abort = threading.Event()
        self._last_send = 0.0  # perf_counter of the last frame's start (writer thread only)

    # ----------------------------------------------------------------- public API

    def send(self, frame: Frame) -> None:
        """Queue ``frame``; it is written in order by the writer thread.

        Raises:
            ValueError: an FD frame on a bus opened without ``fd=True``, or a serial-link message.
            SendQueueFull: the queue is full.
            TransportError: the bus is not open (lost or closed).
        """
        if frame.is_serial:
            raise ValueError(f"{self.name}: {frame!r} is a serial-link message, not a CAN frame")
        if frame.is_fd and not self.fd:
            raise ValueError(f"{self.name}: CAN FD frame {frame!r} on a bus opened without fd=True")
        self._enqueue(frame)

    def set_receive_ids(self, ids: Iterable[int] | None, *, extended: bool = False) -> None:
        """Receive only these identifiers (exact match); None receives everything again.

        The filters stay across reopens.
        """
        self._filters = None if ids is None else _exact_filters(ids, extended=extended)
        self._wanted = _wanted(self._filters) if self._borrowed is not None else None
        if self._bus is not None and self._borrowed is None:
            self._bus.set_filters(self._filters)

    @property
    def bus(self) -> can.BusABC | None:
        """The python-can bus while open (for interface-specific calls; do not recv() from it)."""
        return self._bus

    # ----------------------------------------------------------------- connection

    async def _connect(self) -> None:
        if self._borrowed is not None:
            self._attach(self._borrowed)
            return
        opening = asyncio.get_running_loop().run_in_executor(
            None, functools.partial(can.Bus, ignore_config=True, **self.config)
        )
        try:
            bus = await asyncio.shield(opening)
        except asyncio.CancelledError:  # closed while opening: shut the bus down when it exists
            opening.add_done_callback(_shutdown_when_opened)
            raise
        except (can.CanError, OSError) as exc:
            raise TransportError(f"{self.name}: cannot open: {exc}") from exc
        if self._filters is not None:
            bus.set_filters(self._filters)
        self._attach(bus)

    def _attach(self, bus: can.BusABC) -> None:
        """Start sending to and receiving from the open ``bus``."""
        if self._borrowed is not None and getattr(bus, "_is_shutdown", False):
            raise TransportError(f"{self.name}: the application's bus is shut down")
        self._bus = bus
        self._send_abort = threading.Event()
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"{self.name} writer")
        loop = asyncio.get_running_loop()
        generation = self._generation
        # python-can's virtual bus hands a sent frame to its peers' queues and never blocks; with no
        # gap to keep, send() writes it at once (the writer thread still serves a queue, if any).
        self._direct = self.config.get("interface") == "virtual" and not self._min_gap_s
        notifier = self._notifier
        if notifier is None and self._borrowed is not None:
            find = getattr(can.Notifier, "find_instances", None)  # python-can >= 4.5
            running = [n for n in (find(bus) if find else ()) if not n.stopped]
            notifier = running[0] if running else None
        if notifier is not None:  # the application's notifier reads the bus: listen to it
            self._listener = _NotifierListener(self, loop, generation)
            notifier.add_listener(self._listener)
            self._listening = notifier
            return
        fileno = -1
        with contextlib.suppress(NotImplementedError, can.CanError, OSError):
            fileno = bus.fileno()
        if fileno >= 0:
            loop.add_reader(fileno, self._on_readable, bus, generation)
            self._reader_fd = fileno
        else:
            self._reader_stop = threading.Event()
            self._reader_thread = threading.Thread(
                target=self._read_thread,
                args=(bus, loop, generation, self._reader_stop),
                name=f"{self.name} reader",
                daemon=True,
            )
            self._reader_thread.start()

    async def _disconnect(self) -> None:
        bus, self._bus = self._bus, None
        if self._listening is not None:
            with contextlib.suppress(ValueError):  # the application removed it already
                self._listening.remove_listener(self._listener)  # type: ignore[arg-type]
            self._listening = self._listener = None
        if self._reader_fd is not None:
            with contextlib.suppress(Exception):
                asyncio.get_running_loop().remove_reader(self._reader_fd)
            self._reader_fd = None
        if self._reader_thread is not None:
            self._reader_stop.set()
            await asyncio.to_thread(self._reader_thread.join)
            self._reader_thread = None
        self._direct = False
        self._send_abort.set()
        executor, self._executor = self._executor, None
        if executor is not None:
            executor.shutdown(wait=False, cancel_futures=True)
        if bus is not None and bus is not self._borrowed:
            try:
                await asyncio.to_thread(bus.shutdown)
            except Exception as exc:  # a vanished adapter cannot be told goodbye
                logger.debug("%s: shutdown of a failed bus raised %s", self.name, exc)

    # ----------------------------------------------------------------- receiving

    def _on_readable(self, bus: can.BusABC, generation: int) -> None:
        try:
            message = bus.recv(0)
        except Exception as exc:
            if not _device_failed(exc):  # a line python-can could not parse: one bad frame
                self._stats.bad_frames += 1
                return
            if self._reader_fd is not None:  # a vanished device stays readable: stop watching it
                asyncio.get_running_loop().remove_reader(self._reader_fd)
                self._reader_fd = None
            self._lose(exc, generation)
            return
        finally:
            _bound_line_buffer(bus, self._stats)
        if message is not None:
            self._take([(message, self._now())], generation)

    def _read_thread(
        self, bus: can.BusABC, loop: asyncio.AbstractEventLoop, generation: int, stop: threading.Event
    ) -> None:
        monotonic = time.monotonic  # the loop's clock on a plain asyncio loop
        more = _virtual_more if type(bus).__name__ == "VirtualBus" and hasattr(bus, "queue") else _recv_now
        bad = 0
        while not stop.is_set():
            batch: list[tuple[can.Message, float]] = []
            try:
                message = bus.recv(_THREAD_POLL_S)
                if message is None:
                    continue
                batch.append((message, monotonic()))
                while len(batch) < _THREAD_BATCH and (message := more(bus)) is not None:
                    batch.append((message, monotonic()))
            except Exception as exc:
                if _device_failed(exc):
                    if not stop.is_set():
                        with contextlib.suppress(RuntimeError):
                            loop.call_soon_threadsafe(self._lose, exc, generation)
                    return
                bad += 1  # a frame python-can could not parse: counted, the reader goes on
            try:
                if bad:
                    loop.call_soon_threadsafe(self._count_bad, bad, generation)
                    bad = 0
                if batch:
                    loop.call_soon_threadsafe(self._take, batch, generation)
            except RuntimeError:  # the loop closed under us
                return

    def _count_bad(self, count: int, generation: int) -> None:
        if generation == self._generation:
            self._stats.bad_frames += count

    def _take(self, batch: Sequence[tuple[can.Message, float]], generation: int) -> None:
        if generation != self._generation:
            return
        frames: list[Frame] = []
        stats = self._stats
        for message, timestamp in batch:
            if message.is_error_frame:
                self._on_error_frame(message, timestamp)
                continue
            if message.is_remote_frame:
                stats.ignored += 1
                continue
            if (
                self._wanted is not None
                and (message.arbitration_id, message.is_extended_id) not in self._wanted
            ):
                continue  # another identifier on the application's bus
            try:
                frame = frame_from_message(message, timestamp)
            except ValueError:
                stats.bad_frames += 1
                continue
            frames.append(frame)
            stats.bytes_in += len(frame.data)
            if self._load_known:
                self._load.add(timestamp, self._frame_time_s(frame))
        if frames:
            stats.frames_in += len(frames)
            self._deliver(frames)

    def _on_error_frame(self, message: can.Message, timestamp: float) -> None:
        classes = CanErrorClass(message.arbitration_id & 0x3FF)
        self._stats.error_frames += 1
        self._emit(ErrorFrame(timestamp, classes, bytes(message.data)))
        if CanErrorClass.BUS_OFF in classes:
            self._stats.bus_off += 1
            self._emit(BusOff(timestamp))

    def _frame_time_s(self, frame: Frame) -> float:
        assert self.bitrate is not None
        return nominal_frame_time_s(frame, self.bitrate, self.data_bitrate)

    # ----------------------------------------------------------------- sending

    async def _transmit(self, batch: list[Outgoing[Frame]]) -> None:
        assert self._bus is not None and self._executor is not None
        frames = batch.copy()
        batch.clear()  # the writer thread accounts for these itself, even if this task is cancelled
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(
            self._executor, self._send_blocking, self._bus, frames, loop, self._generation
        )

    def _send_blocking(
        self,
        bus: can.BusABC,
        batch: list[Outgoing[Frame]],
        loop: asyncio.AbstractEventLoop,
        generation: int,
    ) -> None:
        """Writer thread: send ``batch`` in order, honouring the gap and the ENOBUFS policy.

        The report goes back to the loop by itself, so frames are counted even when the task
        that awaited this batch was cancelled by a loss. A loss also stops the batch: the frames
        not yet sent are purged, never written after the device comes back.
        """
        report = _SendReport()
        clock = time.perf_counter
        stale_after_s = self._stale_after_s
        for index, outgoing in enumerate(batch):
            if generation != self._generation:
                report.purged = [o.item for o in batch[index:]]
                break
            if stale_after_s is not None and time.monotonic() - outgoing.queued_at > stale_after_s:
                report.stale.append(outgoing.item)  # waited out an ENOBUFS stretch or a long gap
                continue
            if self._min_gap_s and (wait := self._last_send + self._min_gap_s - clock()) > 0:
                self._send_abort.wait(wait)  # a sleep that a loss or close cuts short
                if generation != self._generation:
                    report.purged = [o.item for o in batch[index:]]
                    break
            sent = self._send_one(bus, message_from_frame(outgoing.item), report)
            if sent is None:
                report.purged = [o.item for o in batch[index + 1 :]]
                break
            if sent:
                report.sent.append((outgoing.item, time.monotonic()))
            else:
                report.enobufs_dropped.append(outgoing.item)
        with contextlib.suppress(RuntimeError):  # the loop is gone: nobody is left to count
            loop.call_soon_threadsafe(self._account, report, generation)

    def _send_one(self, bus: can.BusABC, message: can.Message, report: _SendReport) -> bool | None:
        """Send with the ENOBUFS policy: True sent, False dropped by the policy, None when the bus
        failed (``report.error`` says how).

        A full adapter buffer (ENOBUFS) and a stalled adapter (a serial write timeout, as python-can's
        slcan reports it) are both backpressure: wait and retry, or drop, by the policy.
        """
        give_up = time.perf_counter() + self._enobufs_timeout_s
        while True:
            try:
                bus.send(message, timeout=self._send_timeout_s)
            except can.CanError as exc:
                if not _buffer_full(exc):
                    report.error = exc
                    return None
                if self._enobufs == "drop" or time.perf_counter() >= give_up:
                    return False
                report.enobufs_waits += 1
                time.sleep(_ENOBUFS_RETRY_S)
            except Exception as exc:
                report.error = exc
                return None
            else:
                self._last_send = time.perf_counter()
                return True

    def _account(self, report: _SendReport, generation: int) -> None:
        stats = self._stats
        stats.frames_out += len(report.sent)
        stats.enobufs_waits += report.enobufs_waits
        for reason, items in (
            ("stale", report.stale),
            ("enobufs_dropped", report.enobufs_dropped),
            ("purged", report.purged),
        ):
            self._dropped(reason, items)
        for frame, sent_at in report.sent:
            stats.bytes_out += len(frame.data)
            if self._load_known:
                self._load.add(sent_at, self._frame_time_s(frame))
            self._sent(frame, sent_at)
        if report.error is not None:
            self._lose(report.error, generation)

    def _write_now(self, frame: Frame) -> bool:
        """Loop-native send for a bus whose ``send`` never blocks (python-can's ``virtual``)."""
        bus = self._bus
        if bus is None:
            return False
        try:
            _virtual_send(bus, message_from_frame(frame))
        except can.CanError as exc:
            if _buffer_full(exc):
                return False  # queue it: the writer thread applies the ENOBUFS policy
            self._lose(exc, self._generation)
            raise self._error() from exc
        now = self._now()
        stats = self._stats
        stats.frames_out += 1
        stats.bytes_out += len(frame.data)
        if self._load_known:
            self._load.add(now, self._frame_time_s(frame))
        self._sent(frame, now)
        return True


_FD_PROTOCOLS = tuple(
    getattr(can.CanProtocol, name) for name in ("CAN_FD", "CAN_FD_NON_ISO") if hasattr(can, "CanProtocol")
)


def _interface_name(bus: can.BusABC) -> str:
    """python-can's name for the interface of an open bus ("virtual", "socketcan", ...)."""
    kind = type(bus)
    for name, (module, class_name) in can.interfaces.BACKENDS.items():
        if class_name == kind.__name__ and module == kind.__module__:
            return name
    return kind.__name__


def _wanted(filters: list[can.typechecking.CanFilter] | None) -> frozenset[tuple[int, bool]] | None:
    if filters is None:
        return None
    return frozenset((f["can_id"], bool(f.get("extended"))) for f in filters)


def _shutdown_when_opened(opening: asyncio.Future[can.BusABC]) -> None:
    if not opening.cancelled() and opening.exception() is None:
        with contextlib.suppress(Exception):
            opening.result().shutdown()


def _recv_now(bus: can.BusABC) -> can.Message | None:
    """The next frame already received, if any (what a reader thread batches after a wake-up)."""
    return bus.recv(0)


def _virtual_more(bus: Any) -> can.Message | None:
    """:func:`_recv_now` for python-can's virtual bus: its queue's ``get_nowait``, with the software
    filters ``recv`` applies. ``recv(0)`` costs a timed wait and a raised Empty even when nothing is
    there, which a sequential request/reply pays on every reply."""
    while True:
        try:
            message = bus.queue.get_nowait()
        except queue.Empty:
            return None
        if bus._matches_filters(message):
            return message  # type: ignore[no-any-return]


def _virtual_send(bus: Any, message: can.Message) -> None:
    """python-can's ``VirtualBus.send``, less one copy: the message was built for this send only.

    ``VirtualBus.send`` deep-copies the message once per listening bus (80% of its cost), so that no
    two receivers share an object. The message here is ours alone, so the first listener gets it as
    it is and any further one a copy, exactly as python-can would hand them out. Any other bus, or a
    python-can whose virtual bus looks different, goes through its own ``send``.
    """
    channel = getattr(bus, "channel", None)
    own = getattr(bus, "queue", None)
    if type(bus).__name__ != "VirtualBus" or not isinstance(channel, list) or own is None:
        bus.send(message)
        return
    bus._check_if_open()
    timestamp = message.timestamp if bus.preserve_timestamps else time.time()
    listeners = [q for q in channel if q is not own or bus.receive_own_messages]
    all_sent = True
    for index, listener in enumerate(listeners):
        copy = message if index == 0 else deepcopy(message)
        copy.timestamp = timestamp
        copy.channel = bus.channel_id
        copy.is_rx = listener is not own
        try:
            listener.put_nowait(copy)  # never blocks the loop (a bounded rx_queue_size can be full)
        except queue.Full:
            all_sent = False
    if not all_sent:
        raise can.CanOperationError("Could not send message to one or more recipients")


def _device_failed(exc: BaseException) -> bool:
    """Whether a receive error means the device is gone (an OS or serial error), not a bad frame.

    python-can's readers raise ValueError/IndexError for a line they cannot parse (slcan: ``t12\r``)
    and wrap OS errors in CanOperationError; only the latter is a lost device.
    """
    while exc is not None:
        if isinstance(exc, OSError):
            return True
        if isinstance(exc, ValueError | IndexError | KeyError | TypeError):
            return False
        exc = exc.__cause__ or exc.__context__  # type: ignore[assignment]
    return True  # unknown: treat as lost, the reopen logic recovers a device that is still there


#: python-can's slcan reader keeps bytes until a ``\r`` arrives; a peer that never sends one would grow
#: its buffer without end. No valid line is longer than this (CAN FD extended, with timestamp).
_SLCAN_MAX_LINE = 1 + 8 + 1 + 128 + 4 + 1


def _bound_line_buffer(bus: can.BusABC, stats: Any) -> None:
    buffer = getattr(bus, "_buffer", None)
    if isinstance(buffer, bytearray) and len(buffer) > _SLCAN_MAX_LINE:
        stats.bad_frames += 1
        stats.discarded_bytes += len(buffer)
        buffer.clear()


def _buffer_full(exc: can.CanError) -> bool:
    """python-can's ways of saying "the adapter's send buffer is full, try again"."""
    if isinstance(exc, can.CanTimeoutError):
        return True
    code = getattr(exc, "error_code", None)
    if code in (errno.ENOBUFS, errno.EAGAIN):
        return True
    cause = exc.__cause__
    if isinstance(cause, OSError) and cause.errno in (errno.ENOBUFS, errno.EAGAIN):
        return True
    if type(cause).__name__ == "SerialTimeoutException":  # pyserial: a stalled adapter, not a lost one
        return True
    text = str(exc).lower()
    return "buffer full" in text or "write timeout" in text


def _exact_filters(ids: Iterable[int], *, extended: bool) -> list[can.typechecking.CanFilter]:
    mask = 0x1FFFFFFF if extended else 0x7FF
    filters: list[can.typechecking.CanFilter] = []
    for can_id in sorted(set(ids)):
        if not 0 <= can_id <= mask:
            raise ValueError(f"receive id 0x{can_id:X} is outside 0..0x{mask:X}")
        filters.append({"can_id": can_id, "can_mask": mask, "extended": extended})
    return filters
