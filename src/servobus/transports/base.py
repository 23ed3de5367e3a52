"""The one link base: one device, a bounded send queue and its writer, a receive side, loss and reopen.

Every link is a :class:`Transport`: the device transports (CAN, SLCAN, RS485), the in-process
simulator, and the test and bench links with no device (they override ``send`` and report by
themselves). Who owns what: the transport owns its life (state, connection generation, open and
close, loss and reopen) and the hot path of a send (``_enqueue``); its base
:class:`~servobus.transports._send_side.SendSide` owns the counters, the send queue
(:mod:`~servobus.transports._sending`), the send reports and the bus-off gate
(:mod:`~servobus.transports._busoff`); its base :class:`~servobus.transports._inbox.ReceiveSide`
owns the received frames (:class:`~servobus.transports._inbox.Inbox`); the events are
:class:`~servobus.transports._listeners.EventSource`'s; the reopening is a task of
:class:`~servobus.transports._recovery.Recovery`. Each part is handed what it needs of the others
at construction (a clock, a callable), and none reaches into another's state.

Everything here runs on anyio, on asyncio or on trio: the loop's hot-path operations come from
:func:`servobus.runtime.current` (taken by :meth:`Transport.open`), background tasks live in a task
group the transport owns (entered by ``open()``, left by ``close()`` in the same task: nothing
outlives ``close()``, and an unexpected error of those tasks is raised by it, not lost).

* **Sending never blocks the loop.** :meth:`Transport.send` appends to a bounded queue and
  returns; one writer task empties it in batches. A full queue raises :class:`SendQueueFull` (a
  :class:`~servobus.errors.TransportError`); ``await drain()`` waits until everything queued has
  been written. A transport whose device never blocks (python-can's ``virtual``, the in-process
  simulator) writes a frame from ``send()`` itself when nothing is queued ahead of it.
* **Every send is accounted for, by its handle**: ``send(frame, handle)`` (the FrameLink contract,
  :mod:`servobus.transports.contract`); the reporter set by :meth:`Transport.set_send_reporter`
  gets ``reporter(handle, sent_at, None)`` when the frame left (``sent_at`` on the loop's clock) or
  ``reporter(handle, None, reason)`` when it never will (``"stale"``, ``"purged"``,
  ``"queue_full"``: the adapter's buffer was full, ``"bus_off"``). With no handle, the frame is
  the handle.
* **Receiving is pushed** to one consumer (:meth:`Transport.set_consumer`), or buffered (bounded,
  the oldest dropped and counted) for :meth:`Transport.receive`, ``receive_batch`` and ``async for``.
* **Loss.** When the device fails, every pending ``receive()`` and ``drain()`` raises
  :class:`~servobus.errors.TransportError` (chained to the cause) at once, the state goes to
  ``LOST``, the queued frames are purged, and a recovery task reopens the device with exponential
  backoff. Frames queued before an outage are never replayed; frames older than ``stale_after_s``
  when their turn comes are dropped.
* **Bus-off** is a state of the open link (:mod:`servobus.transports._busoff`), not a loss: events
  :class:`~servobus.transports.events.BusOff` and ``BusRestarted``, and meanwhile sends fail at once
  with :class:`BusOffError` (reason ``"bus_off"``).
* **Events** (state changes, error frames, bus-off, drops) go to listeners and :meth:`events`.
  Received frames carry the loop's clock (``anyio.current_time()``).

**The subclass interface** (what a concrete transport writes, and what it may call):

* ``async _connect()`` (default: nothing to open): open the device (tag callbacks with
  ``self._generation``); start its reader tasks in ``self._tasks`` (the transport's task group, there
  from ``_connect`` on, on a first open and on every reopen; ``_connect`` always runs in a task:
  ``open()``'s or the recovery task's, and anyio starts no task from a bare loop callback); raise
  TransportError when it cannot.
* ``async _disconnect()`` (default: nothing to release): release the device; never raises for a
  device already gone. It runs after the task group's tasks have ended on ``close()``, and in the
  recovery task after a loss (the reader tasks of the lost connection must then stop by themselves:
  check the generation).
* ``async _transmit(batch)``: write a list of :class:`Outgoing` in order, taking each off the front
  as it goes; report each with ``self._sent(outgoing.handle, sent_at)``; call ``_lose`` on failure.
  What is still in ``batch`` when it returns or is cancelled is reported purged by the base.
  (Only a link that queues, through ``_enqueue``, writes one.)
* ``_write_now(item, handle) -> bool`` (only while ``self._direct``): write from ``send()``'s
  stack; True when written (counted and reported with ``_sent(handle, now)`` by the subclass).
* ``send(frame, handle=None, ...)``: a subclass's public send calls
  ``self._enqueue(item, hold_s, handle)``, or writes and reports by itself (``self._handle(frame,
  handle)`` is the handle a report carries; ``_sent(handle, at, frame)`` counts the frame too).
* It calls (on the loop, from a task or a loop callback): ``_deliver(frames)``, ``_lose(cause,
  generation)`` (a loss wakes the recovery task, which runs from open to close), ``_sent(handle,
  sent_at)``, ``_dropped(reason, handles_or_count)``, ``_set_state``, ``_emit(event)``, ``_now()``,
  ``_error()``, and the bus-off state ``self._bus_off`` (``error_frame``, ``went_off``,
  ``came_back``); it counts into ``self._stats`` and ``self._load``; ``self._runtime`` (the
  :class:`~servobus.runtime.Runtime`: ``time``, ``call_soon``, ``call_soon_threadsafe``,
  ``waiter``) replaces the asyncio loop; ``self._tasks`` is where its tasks start.
* It declares its line: attributes or properties ``half_duplex``, ``bitrate``, ``gap_s``,
  ``turnaround_s``, ``exact_times`` (and ``stale_after_s`` from the constructor) make
  :attr:`Transport.rules`; or it sets them whole (``self.rules = LineRules(...)``).
"""

from __future__ import annotations

import copy
import logging
import time
import warnings
from collections.abc import Callable
from functools import partial
from types import TracebackType
from typing import Any, ClassVar, Generic, Self, TypeVar

import anyio

from servobus import runtime as _runtime
from servobus.errors import TransportError
from servobus.transports._inbox import Inbox, ReceiveSide
from servobus.transports._owned import LinkTasks, OwnedTaskGroup, owned_exit
from servobus.transports._recovery import Recovery
from servobus.transports._send_side import SendSide
from servobus.transports._sending import (
    BusOffError,
    Outgoing,
    SendQueueFull,
    SendReporter,
)
from servobus.transports._waiters import WaiterList
from servobus.transports.contract import LineRules
from servobus.transports.events import StateChanged, TransportState
from servobus.transports.stats import LoadMeter, TransportStats

__all__ = ["BusOffError", "Consumer", "Outgoing", "SendQueueFull", "SendReporter", "Transport"]

logger = logging.getLogger("servobus.transports")

RxT = TypeVar("RxT")
TxT = TypeVar("TxT")

#: ``consumer(frames)``: a batch of received frames, called on the event loop.
Consumer = Callable[[list[RxT]], object]


def declared_rules(link: object, stale_after_s: float | None) -> LineRules:
    """The rules a link declares with attributes or properties ``half_duplex``, ``bitrate``,
    ``gap_s``, ``turnaround_s`` and ``exact_times`` (those it lacks take LineRules' defaults)."""
    return LineRules(
        half_duplex=bool(getattr(link, "half_duplex", False)),
        bitrate=getattr(link, "bitrate", None),
        gap_s=float(getattr(link, "gap_s", 0.0) or 0.0),
        turnaround_s=float(getattr(link, "turnaround_s", 0.0) or 0.0),
        stale_after_s=stale_after_s,
        exact_times=bool(getattr(link, "exact_times", False)),
    )


class Transport(ReceiveSide[RxT], SendSide[TxT], Generic[RxT, TxT]):
    """Frames out through a bounded queue, frames in through a consumer or a buffer, one device.

    The one base of every link: the device transports, the in-process simulator, and the test and
    bench links that override :meth:`send` and report by themselves (``_sent``, ``_dropped``,
    ``_deliver``); a link with no device to open keeps the no-op ``_connect``/``_disconnect``.

    Use it as an async context manager (``async with CanTransport(...) as bus:``), or call
    :meth:`open` and :meth:`close` from the same task.

    Args:
        name: a label for errors and logs (default: the class's ``name``).
        queue_size: frames the send queue holds before :meth:`send` raises :class:`SendQueueFull`.
        rx_buffer: received frames held for the reader before the oldest are dropped.
        stale_after_s: a queued frame older than this when its turn comes is dropped, not sent
            (None: never).
        reopen: reopen the device by itself after a loss.
        reopen_backoff_s: (first, longest) delay between reopen attempts; it doubles each time.
    """

    #: frames the writer hands to :meth:`_transmit` at once (a half-duplex line takes one at a time,
    #: so each frame's age is checked when its own transaction starts)
    batch_size: ClassVar[int] = 64
    #: while bus-off, one frame this often still goes to the adapter (the others fail at once)
    bus_off_probe_s: ClassVar[float] = 0.02
    name: str = "link"
    #: the rules when declared whole (``self.rules = ...``); else they come from attributes
    _rules: LineRules | None = None

    def __init__(
        self,
        *,
        name: str | None = None,
        queue_size: int = 256,
        rx_buffer: int = 65536,
        stale_after_s: float | None = 0.5,
        reopen: bool = True,
        reopen_backoff_s: tuple[float, float] = (0.05, 2.0),
    ) -> None:
        # (A SimTransport's instance keeps under 30 attributes, CPython's shared-key limit: at 30 its
        # send path measured 15% slower. test_one_base.py holds it there.)
        name = self.name if name is None else name
        self._state = TransportState.CLOSED
        self._runtime: _runtime.Runtime | None = None
        SendSide.__init__(  # the counters, the queue, the send reports, bus-off, the events
            self,
            name,
            self._now,
            self._serving,
            queue_size=queue_size,
            stale_after_s=stale_after_s,
            batch_size=self.batch_size,
            probe_s=self.bus_off_probe_s,
            transmit=self._transmit,
            lose=self._lose,
        )
        closed = lambda: self._state is TransportState.CLOSED  # noqa: E731 (an "async for" ends then)
        ReceiveSide.__init__(
            self, Inbox(name, rx_buffer, partial(self._dropped, "rx_overflow"), self._serving, closed)
        )
        self._recovery = Recovery(
            name, reopen, reopen_backoff_s, self._stats, self._disconnect, self._reconnect, self._connected
        )
        self._load = LoadMeter()
        self._load_known = False  # subclasses set it when they know the line's bit rate
        self._open_waiters = WaiterList()
        self._owned = OwnedTaskGroup(name)
        self._failure: tuple[str, BaseException | None] | None = ("not open", None)
        self._generation = 0  # bumped per connection: callbacks of an old one are ignored
        self._ever_opened = False
        self._direct = False  # a subclass whose device never blocks a write sets it: see _write_now

    # ------------------------------------- subclass interface (each hook: see the module docstring)

    async def _connect(self) -> None:
        """Open the device and start reading; raise TransportError when it cannot."""

    async def _disconnect(self) -> None:
        """Release the device; never raises for a device already gone."""

    async def _transmit(self, batch: list[Outgoing[TxT]]) -> None:
        """Write ``batch`` (only a link that queues, through :meth:`_enqueue`, writes one)."""
        raise NotImplementedError

    def _write_now(self, item: TxT, handle: Any) -> bool:
        """Write ``item`` now (only while ``self._direct``): True when written, False to queue it."""
        raise NotImplementedError

    def _now(self) -> float:
        """The loop's clock (time.monotonic() before the transport was first opened, or once the
        trio run it was opened in has ended: trio's clock exists only inside its run)."""
        lane = self._runtime
        if lane is None:
            return time.monotonic()
        try:
            return lane.time()
        except RuntimeError:
            return time.monotonic()

    @property
    def _tasks(self) -> LinkTasks:
        """The transport's task group (from :meth:`_connect` on, until :meth:`close`)."""
        return self._owned.open_tasks()

    # ----------------------------------------------------------------- life cycle

    @property
    def state(self) -> TransportState:
        return self._state

    @property
    def rules(self) -> LineRules:
        """The line's rules (the FrameLink contract), from what the subclass declares.

        A subclass declares ``half_duplex``, ``bitrate``, ``gap_s`` and ``turnaround_s`` as
        attributes or properties (those it lacks take LineRules' defaults); ``stale_after_s`` is the
        constructor's. Or it sets the rules whole (``self.rules = LineRules(...)``).
        """
        return self._rules or declared_rules(self, self.stale_after_s)

    @rules.setter
    def rules(self, rules: LineRules) -> None:
        self._rules = rules

    @property
    def is_open(self) -> bool:
        return self._state is TransportState.OPEN

    async def open(self) -> None:
        """Open the device, and enter the transport's task group in the calling task.

        Raises:
            TransportError: it cannot be opened (the cause is chained); the state stays CLOSED.
            RuntimeError: the transport is not closed.
        """
        if self._state is not TransportState.CLOSED:
            raise RuntimeError(f"{self.name} is already {self._state.value}")
        self._runtime = lane = _runtime.current()
        tasks = await self._owned.enter()
        tasks.start_soon(self._recovery.watch, lane, name=f"{self.name} recovery")
        self._set_state(TransportState.OPENING)
        self._generation += 1
        try:
            await self._connect()
        except BaseException:
            self._generation += 1
            try:
                await self._owned.leave()  # (no shield around it: the group must be the innermost)
            finally:
                self._set_state(TransportState.CLOSED)
            raise
        self._ever_opened = True
        self._connected()

    async def close(self) -> None:
        """Stop, drop whatever is still queued (reported purged) and release the device.

        Call it from the task that opened the transport (not inside a cancel scope entered after
        ``open()``). Pending receivers raise :class:`~servobus.errors.TransportError`; ``async for``
        loops end. Closing twice is harmless.

        Raises:
            RuntimeError: called from another task than the one that opened the transport.
            BaseExceptionGroup: a task of the transport failed (after the transport is closed).
        """
        await self._close(None, None, None)

    async def _close(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool:
        if self._state is TransportState.CLOSED:
            return False
        self._owned.check_owner("close()")
        self._generation += 1
        self._failure = ("closed", None)
        self._state = TransportState.CLOSED  # announced last, after the drops it causes
        self._sending.stop()
        try:
            return await self._owned.leave(exc_type, exc, tb)
        finally:
            with anyio.CancelScope(shield=True):
                self._sending.fail(self._error)
                self._open_waiters.fail_all(self._error)
                self._inbox.readers.fail_all(self._error)
                await self._disconnect()  # also when LOST: the recovery task may not have got to it
                self._set_state(TransportState.CLOSED)

    async def __aenter__(self) -> Self:
        await self.open()
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool:
        return await self._close(*owned_exit(exc_type, exc, tb))

    def __del__(self) -> None:
        if getattr(self, "_ever_opened", False) and self._state is not TransportState.CLOSED:
            warnings.warn(f"{self.name} was never closed", ResourceWarning, stacklevel=1)

    async def wait_open(self, timeout: float | None = None) -> None:
        """Wait until the transport is OPEN (after a loss: until it has reopened).

        Raises:
            TimeoutError: not open within ``timeout`` seconds.
            TransportError: the transport was closed.
        """
        if self._state is TransportState.OPEN:
            return
        if self._state is TransportState.CLOSED or self._runtime is None:
            raise self._error()
        with anyio.fail_after(timeout):
            await self._open_waiters.park(self._runtime)

    def _connected(self) -> None:
        self._failure = None
        self._bus_off.forget()
        self._set_state(TransportState.OPEN)
        assert self._runtime is not None  # (set by open())
        self._sending.start(self._tasks, self._runtime, self._generation)
        self._open_waiters.wake_all()

    async def _reconnect(self) -> bool:
        """The recovery task's attempt to reopen the device (raises while it is away): whether the
        transport still waits for it (False: closed meanwhile, and close() releases it)."""
        if self._state is not TransportState.LOST:
            return False
        self._generation += 1
        await self._connect()
        return self._state is TransportState.LOST

    def _lose(self, cause: BaseException, generation: int | None = None) -> None:
        """The device failed: fail every waiter at once, purge the queue, start reopening.

        Safe to call more than once and from stale callbacks (``generation`` of an older
        connection): only the first call for the current connection acts. Call it on the loop.
        """
        if self._state is TransportState.OPEN and generation in (None, self._generation):
            self._recovery.lost(cause)  # (first: counted and logged before anyone hears of it)
            self._generation += 1
            self._failure = ("device lost", cause)
            self._set_state(TransportState.LOST, cause)
            self._sending.fail(self._error)
            self._inbox.readers.fail_all(self._error)

    def _set_state(self, state: TransportState, cause: BaseException | None = None) -> None:
        self._state = state
        self._emit(StateChanged(state, self._now(), cause))

    def _serving(self) -> _runtime.Runtime:
        """The loop, while the transport is open (what its waiters park on).

        Raises:
            TransportError: it is not open, and why.
        """
        if self._state is not TransportState.OPEN or self._runtime is None:
            raise self._error()
        return self._runtime

    def _error(self) -> TransportError:
        """A fresh TransportError saying why the transport cannot serve now, chained to the cause."""
        what, cause = self._failure or (self._state.value, None)
        error = TransportError(f"{self.name}: {what}" + (f" ({cause})" if cause else ""))
        error.__cause__ = cause
        return error

    # ----------------------------------------------------------------- sending

    def _enqueue(self, item: TxT, hold_s: float | None = None, handle: Any = None) -> None:
        """Accept ``item`` for sending (its send report will carry ``handle``, or ``item``).

        Raises:
            TransportError: the transport is not open.
            SendQueueFull: the queue is full.
            BusOffError: the CAN controller is bus-off (and this frame is not its probe).
        """
        if self._state is not TransportState.OPEN:
            raise self._error()
        if self._bus_off.since is not None:
            self._bus_off.gate(self._now())
        if handle is None:
            handle = item
        sending = self._sending
        if self._direct and not self._queue and not sending.transmitting and self._write_now(item, handle):
            return
        sending.put(Outgoing(item, self._now(), hold_s, handle))

    # ----------------------------------------------------------------- counters

    def stats(self) -> TransportStats:
        """A snapshot of the counters, with the current state, queue depth and bus load."""
        snapshot = copy.copy(self._stats)
        snapshot.state = self._state
        snapshot.queue_depth = len(self._queue)
        snapshot.bus_load_pct = self._load.percent(self._now()) if self._load_known else None
        return snapshot

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name} {self._state.value}>"
