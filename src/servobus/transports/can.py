"""CAN and CAN FD through python-can: any interface it supports, configured the way it is.

* **Configuration** is python-can's own, merged once: arguments first, then ``can.rc``, the
  environment (``CAN_INTERFACE``, ``CAN_CHANNEL``, ``CAN_BITRATE``, ``CAN_CONFIG``) and the config
  files (``~/.canrc``, ``~/can.conf``, ...), in python-can's order (``can.util.load_config``).
  ``config_context`` picks a section; ``ignore_config=True`` uses the arguments alone.
* **Runs on asyncio and on trio** (anyio, and the runtime's lane for thread hand-offs). Opening and
  shutting down a python-can bus happen in a worker thread (``anyio.to_thread``).
* **Receiving** runs inside the event loop: where the bus has a file descriptor (socketcan,
  slcan and other serial adapters) the loop watches it and reads one frame per readiness, with no
  thread. Buses without one (virtual, most vendor drivers) get a single reader thread, as
  python-can's own ``Notifier`` does, which hands frames over in batches (``_can_readers``); what
  they read becomes frames in :mod:`servobus.transports._can_intake`.
* **Sending** never blocks the loop: python-can's ``send`` is a blocking call on most
  interfaces, so the queued frames go to a worker thread, a batch at a time, in order, with an
  optional minimum gap between frames (``_can_sender``). python-can's ``virtual`` bus never blocks
  a send given ``timeout=0``: there ``send`` writes the frame at once when nothing is queued. A full
  adapter buffer (ENOBUFS, "transmit buffer full") is handled by policy: ``"wait"`` retries until
  ``enobufs_timeout_s`` (2 ms) and then drops, and while the buffer stays full later frames get
  one try each, so a full buffer never stalls a control loop; ``"drop"`` drops at once. A frame not
  sent is counted (``enobufs_dropped``) and reported ``"queue_full"``.
* **Bus-off** (a BUS_OFF error frame, or a send refused with ENETDOWN) is a state of the open bus,
  not a lost device: no close or reopen, events ``BusOff`` and then ``BusRestarted`` (a RESTARTED
  error frame, or a send that went through), and meanwhile sends fail at once (``BusOffError``,
  reported ``"bus_off"``; see :mod:`servobus.transports._busoff`).
* **Filters**: :meth:`CanTransport.set_receive_ids` installs exact-match filters for the reply
  identifiers in use; python-can puts them in the kernel or adapter where the interface can, and
  filters in software otherwise. They are re-applied after a reopen.
* **An application's bus**: ``CanTransport(bus)`` takes a ``can.BusABC`` that is open already
  (and ``notifier=``, the application's ``can.Notifier`` on it, when there is one; a bus with a
  running notifier is joined by itself). servobus then listens through that notifier instead of
  reading the bus, filters its reply identifiers in software, and never shuts the bus down.
* **Error frames** become :class:`~servobus.transports.events.ErrorFrame` events, each counted
  (``error_frames``; BUS_OFF and RESTARTED also move the bus-off state); remote frames are counted
  and dropped.

The conversions between :class:`~servobus.frame.Frame` and ``can.Message`` are
:meth:`Frame.from_message <servobus.frame.Frame.from_message>` and :func:`message_from_frame` (here,
at python-can's edge: servobus.frame never imports can).
"""

from __future__ import annotations

import contextlib
import functools
import threading
import time
from collections.abc import Iterable
from typing import Any, Literal

import anyio
import can

from servobus.errors import TransportError
from servobus.frame import Frame
from servobus.transports._can_intake import CanIntake, exact_filters, wanted_ids
from servobus.transports._can_readers import Reader, start_reader
from servobus.transports._can_sender import BlockingSender, SendReport, buffer_full, controller_off
from servobus.transports._watch import loop_context
from servobus.transports.base import BusOffError, Outgoing, Transport, logger

__all__ = ["CanTransport", "frame_from_message", "message_from_frame"]


def frame_from_message(message: can.Message, timestamp: float) -> Frame:
    """A received ``can.Message`` as a :class:`Frame` stamped ``timestamp``: :meth:`Frame.from_message`.

    Raises:
        ValueError: a remote or error frame, a DLC that disagrees with the data, or an id or length
            out of range.
    """
    return Frame.from_message(message, timestamp)


def message_from_frame(frame: Frame, **message: Any) -> can.Message:
    """A :class:`Frame` as a ``can.Message``: identifier, extended, FD,
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
        enobufs_timeout_s: with ``"wait"``, how long a frame that meets a full buffer may wait for
            room (the first of an episode: later ones are not waited for until one goes through).
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
        enobufs_timeout_s: float = 0.002,
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
        self._borrowed, self._notifier = _borrowed_bus(interface, notifier)
        if self._borrowed is not None:
            if channel is not None or options or config_context is not None:
                raise ValueError("an open can.BusABC takes no channel, configuration or python-can options")
            interface, ignore_config, reopen = None, True, False
            options = {"interface": _interface_name(self._borrowed)}
            fd = fd or getattr(self._borrowed, "protocol", None) in _FD_PROTOCOLS
        given = {"interface": interface, "channel": channel, "bitrate": bitrate, "data_bitrate": data_bitrate}
        self.config = _merged_config(given, options, fd=fd, ignore=ignore_config, context=config_context)
        self.fd = bool(self.config.get("fd", False))
        self.bitrate: int | None = self.config.get("bitrate")
        self.data_bitrate: int | None = self.config.get("data_bitrate")
        channel_name = self.config.get("channel") if self._borrowed is None else self._borrowed.channel_info
        super().__init__(
            name=f"can:{self.config['interface']}:{channel_name}",
            queue_size=queue_size,
            rx_buffer=rx_buffer,
            stale_after_s=stale_after_s,
            reopen=reopen,
            reopen_backoff_s=reopen_backoff_s,
        )
        self._load_known = self.bitrate is not None
        self._intake = intake = CanIntake(
            self.name,
            self._stats,
            self._load,
            generation=lambda: self._generation,
            deliver=self._deliver,
            error_frame=self._bus_off.error_frame,
            lose=self._lose,
        )
        intake.bitrate, intake.data_bitrate = self.bitrate, self.data_bitrate
        self._min_gap_s = min_gap_s
        self._sender = BlockingSender(
            min_gap_s=min_gap_s,
            enobufs=enobufs,
            enobufs_timeout_s=enobufs_timeout_s,
            send_timeout_s=send_timeout_s,
            stale_after_s=stale_after_s,
        )
        self._send_lane = anyio.CapacityLimiter(1)  # one batch in the worker at a time
        self._filters: list[can.typechecking.CanFilter] | None = None
        if receive_ids is not None:
            self._filters = exact_filters(receive_ids, extended=False)
        # An application's bus keeps its own filters: the identifiers are checked by the intake instead.
        intake.wanted = wanted_ids(self._filters) if self._borrowed is not None else None
        self._bus: can.BusABC | None = None
        self._reader: Reader | None = None

    # ----------------------------------------------------------------- public API

    def send(self, frame: Frame, handle: object = None) -> None:
        """Queue ``frame``; it is written in order by the writer thread. The send report names
        ``handle`` (the frame itself when None).

        Raises:
            ValueError: an FD frame on a bus opened without ``fd=True``, or a serial-link message.
            SendQueueFull: the queue is full.
            BusOffError: the CAN controller is bus-off.
            TransportError: the bus is not open (lost or closed).
        """
        if frame.is_serial:
            raise ValueError(f"{self.name}: {frame!r} is a serial-link message, not a CAN frame")
        if frame.is_fd and not self.fd:
            raise ValueError(f"{self.name}: CAN FD frame {frame!r} on a bus opened without fd=True")
        self._enqueue(frame, None, handle)

    def set_receive_ids(self, ids: Iterable[int] | None, *, extended: bool = False) -> None:
        """Receive only these identifiers (exact match); None receives everything again.

        The filters stay across reopens.
        """
        self._filters = None if ids is None else exact_filters(ids, extended=extended)
        self._intake.wanted = wanted_ids(self._filters) if self._borrowed is not None else None
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
        opening = _Opening(functools.partial(can.Bus, ignore_config=True, **self.config))
        try:
            bus = await anyio.to_thread.run_sync(opening.run, abandon_on_cancel=True)
        except anyio.get_cancelled_exc_class():  # closed while opening: the bus is shut down once it exists
            opening.abandon()
            raise
        except (can.CanError, OSError) as exc:
            raise TransportError(f"{self.name}: cannot open: {exc}") from exc
        if self._filters is not None:
            bus.set_filters(self._filters)
        self._attach(bus)

    def _attach(self, bus: can.BusABC) -> None:
        """Start sending to and receiving from the open ``bus``."""
        # python-can has no public "is it open"; its BusABC keeps the flag shutdown() sets here
        if self._borrowed is not None and getattr(bus, "_is_shutdown", False):
            raise TransportError(f"{self.name}: the application's bus is shut down")
        self._bus = bus
        self._sender.renew()
        # python-can's virtual bus hands a sent frame to its peers' queues and, with timeout=0, never
        # blocks; with no gap to keep, send() writes it at once (the worker still serves a queue).
        self._direct = self.config.get("interface") == "virtual" and not self._min_gap_s
        notifier = self._notifier
        if notifier is None and self._borrowed is not None:
            find = getattr(can.Notifier, "find_instances", None)  # python-can >= 4.5
            running = [n for n in (find(bus) if find else ()) if not n.stopped]
            notifier = running[0] if running else None
        assert self._runtime is not None  # set by open()
        self._reader = start_reader(self._intake, bus, notifier, self._generation, self._runtime, self._tasks)

    async def _disconnect(self) -> None:
        bus, self._bus = self._bus, None
        reader, self._reader = self._reader, None
        if reader is not None:
            await reader.close()
        self._direct = False
        self._sender.abort.set()
        if bus is not None and bus is not self._borrowed:
            try:
                with anyio.CancelScope(shield=True):  # a bus half shut down is worse than a slow close
                    await anyio.to_thread.run_sync(bus.shutdown)
            except Exception as exc:  # a vanished adapter cannot be told goodbye
                logger.debug("%s: shutdown of a failed bus raised %s", self.name, exc)

    # ----------------------------------------------------------------- sending

    async def _transmit(self, batch: list[Outgoing[Frame]]) -> None:
        assert self._bus is not None and self._runtime is not None
        frames = batch.copy()
        batch.clear()  # the writer thread accounts for these itself, even if this task is cancelled
        generation = self._generation
        call = self._runtime.call_soon_threadsafe
        await anyio.to_thread.run_sync(
            loop_context(self._runtime).run,  # its report's hand-over runs in a context naming the backend
            self._sender.send_batch,
            self._bus,
            frames,
            self._now() - time.monotonic(),
            lambda: generation == self._generation,
            lambda report: call(self._account, report, generation),
            message_from_frame,
            abandon_on_cancel=True,  # a loss or close need not wait for a blocked send
            limiter=self._send_lane,
        )

    def _account(self, report: SendReport, generation: int) -> None:
        stats = self._stats
        stats.frames_out += len(report.sent)
        stats.enobufs_waits += report.enobufs_waits
        if report.sent and self._bus_off.since is not None:  # a frame went through: the controller is back
            self._bus_off.came_back(report.sent[0][1])
        for reason, items, counter in (
            ("stale", report.stale, None),
            ("queue_full", report.enobufs_dropped, "enobufs_dropped"),
            ("purged", report.purged, None),
        ):
            self._dropped(reason, [o.handle for o in items], counter)
        if report.bus_off_cause is not None:
            if generation == self._generation:
                self._bus_off.went_off(report.bus_off_at, report.bus_off_cause)
            self._dropped("bus_off", [o.handle for o in report.bus_off], "bus_off_dropped")
        for outgoing, sent_at in report.sent:
            frame = outgoing.item
            stats.bytes_out += len(frame.data)
            if self._load_known:
                self._load.add(sent_at, self._intake.frame_time_s(frame))
            self._sent(outgoing.handle, sent_at)
        if report.error is not None:
            self._lose(report.error, generation)

    def _write_now(self, frame: Frame, handle: Any) -> bool:
        """Loop-native send for a bus whose ``send`` never blocks (python-can's ``virtual``, timeout 0)."""
        bus = self._bus
        if bus is None:
            return False
        try:
            bus.send(message_from_frame(frame), timeout=0)
        except can.CanError as exc:
            if buffer_full(exc):
                return False  # queue it: the writer thread applies the ENOBUFS policy
            if controller_off(exc):
                self._bus_off.went_off(self._now(), exc)
                self._stats.bus_off_dropped += 1
                raise BusOffError(f"{self.name}: the CAN controller is bus-off ({exc})") from exc
            self._lose(exc, self._generation)
            raise self._error() from exc
        now = self._now()
        if self._bus_off.since is not None:
            self._bus_off.came_back(now)
        stats = self._stats
        stats.frames_out += 1
        stats.bytes_out += len(frame.data)
        if self._load_known:
            self._load.add(now, self._intake.frame_time_s(frame))
        self._sent(handle, now)
        return True


class _Opening:
    """Opening a python-can bus in a worker thread that a close may abandon: the bus it opens after
    being abandoned is shut down there, never left open."""

    def __init__(self, open_bus: functools.partial[can.BusABC]) -> None:
        self._open_bus = open_bus
        self._lock = threading.Lock()
        self._abandoned = False
        self._bus: can.BusABC | None = None

    def run(self) -> can.BusABC:
        bus = self._open_bus()
        with self._lock:
            if not self._abandoned:
                self._bus = bus
                return bus
        bus.shutdown()
        raise TransportError("closed while opening")

    def abandon(self) -> None:
        with self._lock:
            self._abandoned = True
            bus, self._bus = self._bus, None
        if bus is not None:  # opened, but the await was cancelled before it returned
            with contextlib.suppress(Exception):
                bus.shutdown()


_FD_PROTOCOLS = tuple(
    getattr(can.CanProtocol, name) for name in ("CAN_FD", "CAN_FD_NON_ISO") if hasattr(can, "CanProtocol")
)


def _borrowed_bus(
    interface: str | can.BusABC | None, notifier: can.Notifier | None
) -> tuple[can.BusABC | None, can.Notifier | None]:
    """The application's open bus (and its notifier) when ``interface`` or ``notifier`` names one.

    Raises:
        ValueError: a notifier over several buses, or one without the bus it reads.
        TypeError: ``interface`` is neither a name nor a ``can.BusABC``.
    """
    if interface is None and notifier is not None:
        buses = notifier.bus if isinstance(notifier.bus, tuple | list) else (notifier.bus,)
        if len(buses) != 1:
            raise ValueError(f"the notifier reads {len(buses)} buses: give the one to use")
        interface = buses[0]
    if isinstance(interface, can.BusABC):
        return interface, notifier
    if interface is not None and not isinstance(interface, str):
        raise TypeError(f"interface must be a python-can interface name or a can.BusABC, not {interface!r}")
    if notifier is not None:
        raise ValueError("a notifier goes with the open can.BusABC it reads")
    return None, None


def _merged_config(
    given: dict[str, Any], options: dict[str, Any], *, fd: bool, ignore: bool, context: str | None
) -> dict[str, Any]:
    """The arguments, then python-can's own configuration (unless ``ignore``), in its order.

    Raises:
        ValueError: no interface given or configured.
    """
    config: dict[str, Any] = {key: value for key, value in given.items() if value is not None}
    config.update(options)
    if fd:
        config["fd"] = True
    if not ignore:
        try:
            config = dict(can.util.load_config(config=config, context=context))
        except can.CanInterfaceNotImplementedError as exc:
            raise ValueError(f"no usable CAN interface: {exc}") from exc
    if not config.get("interface"):
        raise ValueError("no CAN interface given and none in python-can's configuration")
    return config


def _interface_name(bus: can.BusABC) -> str:
    """python-can's name for the interface of an open bus ("virtual", "socketcan", ...)."""
    kind = type(bus)
    for name, (module, class_name) in can.interfaces.BACKENDS.items():
        if class_name == kind.__name__ and module == kind.__module__:
            return name
    return kind.__name__
