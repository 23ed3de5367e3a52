"""The transport base: one reader, one writer, a bounded send queue, waiters that fail together.

A concrete transport (CAN through python-can, RS485 through pyserial-asyncio-fast) supplies three
things: how to open its device (:meth:`Transport._connect`), how to let go of it
(:meth:`Transport._disconnect`), and how to put a batch of queued frames on the wire
(:meth:`Transport._transmit`). It hands received frames to :meth:`Transport._deliver` and reports a
failed device with :meth:`Transport._lose`. Everything else is here, once:

* **Sending never blocks the loop.** :meth:`Transport.send` appends to a bounded queue and
  returns; one writer task empties it in batches. A full queue raises :class:`SendQueueFull`;
  ``await drain()`` waits until everything queued has been written.
* **Receiving is pushed**: :meth:`Transport.set_consumer` makes the transport call one consumer
  (the Bus's intake) on the event loop with every batch of received frames. Without a consumer,
  frames wait in a bounded buffer read by :meth:`Transport.receive`, :meth:`Transport.receive_batch`
  or ``async for frame in transport``; when nobody reads, the oldest are dropped and counted, never
  memory without end.
* **Every send is accounted for**: :meth:`Transport.set_send_reporter` gets
  ``reporter(item, sent_at, None)`` when a frame left (``sent_at`` on the loop's clock), or
  ``reporter(item, None, reason)`` when it never will (``"stale"``, ``"purged"``, ``"enobufs_dropped"``).
* **No hop where none is needed**: a transport whose device never blocks (python-can's ``virtual``,
  the in-process simulator) writes a frame from :meth:`Transport.send` itself when nothing is queued
  ahead of it.
* **Loss.** When the device fails, every pending ``receive()`` and ``drain()`` raises
  :class:`~servobus.errors.TransportError` (chained to the cause) at once, the state goes to
  ``LOST``, the queued frames are purged (counted), and a background task reopens the device with
  exponential backoff. Frames queued before an outage are never replayed onto a bus whose motors
  may just have restarted; frames that waited longer than ``stale_after_s`` are dropped too.
* **Events** (state changes, error frames, bus-off, drops) go to listeners and :meth:`events`.

Received frames carry the time the transport read them on the event loop's clock (``loop.time()``,
which is ``time.monotonic()`` on a plain asyncio loop and the virtual clock under ``looptime``), so
they compare directly with ``loop.time()`` deadlines.
"""

from __future__ import annotations

import abc
import asyncio
import contextlib
import copy
import logging
import time
import warnings
from collections import deque
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import ClassVar, Generic, Self, TypeVar

from servobus.errors import TransportError
from servobus.transports.events import FramesDropped, StateChanged, TransportEvent, TransportState
from servobus.transports.stats import LoadMeter, TransportStats

__all__ = ["Consumer", "Outgoing", "SendQueueFull", "SendReporter", "Transport"]

logger = logging.getLogger("servobus.transports")

RxT = TypeVar("RxT")
TxT = TypeVar("TxT")

#: ``consumer(frames)``: a batch of received frames, called on the event loop.
Consumer = Callable[[list[RxT]], object]
#: ``reporter(item, sent_at, reason)``: ``sent_at`` when the item left, else ``reason`` it never will.
SendReporter = Callable[[TxT, float | None, str | None], object]


class SendQueueFull(TransportError, asyncio.QueueFull):
    """A non-blocking send found the queue full: back off, or ``await drain()`` first."""


@dataclass(slots=True)
class Outgoing(Generic[TxT]):
    """One queued frame: what to write, when it was queued, how long the line stays ours after it."""

    item: TxT
    queued_at: float
    hold_s: float | None = None


class Transport(abc.ABC, Generic[RxT, TxT]):
    """Frames out through a bounded queue, frames in through a bounded buffer, one device.

    Use it as an async context manager (``async with CanTransport(...) as bus:``) or call
    :meth:`open` and :meth:`close`.

    Args:
        name: a label for errors and logs.
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

    def __init__(
        self,
        *,
        name: str,
        queue_size: int = 256,
        rx_buffer: int = 65536,
        stale_after_s: float | None = 0.5,
        reopen: bool = True,
        reopen_backoff_s: tuple[float, float] = (0.05, 2.0),
    ) -> None:
        if queue_size < 1 or rx_buffer < 1:
            raise ValueError(f"queue_size={queue_size} and rx_buffer={rx_buffer} must be at least 1")
        if stale_after_s is not None and stale_after_s <= 0:
            raise ValueError(f"stale_after_s={stale_after_s} must be positive (or None)")
        first, longest = reopen_backoff_s
        if not 0 < first <= longest:
            raise ValueError(f"reopen_backoff_s={reopen_backoff_s} must be 0 < first <= longest")
        self.name = name
        self._queue_size = queue_size
        self._rx_capacity = rx_buffer
        self._stale_after_s = stale_after_s
        self._reopen = reopen
        self._backoff = (first, longest)
        self._state = TransportState.CLOSED
        self._stats = TransportStats()
        self._load = LoadMeter()
        self._load_known = False  # subclasses set it when they know the line's bit rate
        self._queue: deque[Outgoing[TxT]] = deque()
        self._rx: deque[RxT] = deque()
        self._rx_waiters: list[asyncio.Future[None]] = []
        self._idle_waiters: list[asyncio.Future[None]] = []
        self._open_waiters: list[asyncio.Future[None]] = []
        self._writer_wake: asyncio.Future[None] | None = None
        self._writer: asyncio.Task[None] | None = None
        self._recovery: asyncio.Task[None] | None = None
        self._transmitting = False
        self._listeners: list[Callable[[TransportEvent], object]] = []
        self._failure: tuple[str, BaseException | None] | None = ("not open", None)
        self._generation = 0  # bumped per connection: callbacks of an old one are ignored
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ever_opened = False
        self._consumer: Consumer[RxT] | None = None
        self._reporter: SendReporter[TxT] | None = None
        #: set by a subclass whose device never blocks a write: send() then writes at once when
        #: nothing is queued ahead (see :meth:`_write_now`)
        self._direct = False

    # ----------------------------------------------------------------- subclass interface

    @abc.abstractmethod
    async def _connect(self) -> None:
        """Open the device and start reading; tag callbacks with ``self._generation``.

        Raises:
            TransportError: the device cannot be opened (chained to the cause).
        """

    @abc.abstractmethod
    async def _disconnect(self) -> None:
        """Stop reading and release the device; must not raise for a device already gone."""

    @abc.abstractmethod
    async def _transmit(self, batch: list[Outgoing[TxT]]) -> None:
        """Write ``batch`` in order, count it, and call :meth:`_lose` if the device fails.

        Take each frame off the front of ``batch`` as it goes out (a writer thread that accounts
        for its frames itself may take them all at once). Whatever is still in ``batch`` when this
        returns, or when a loss or close cancels it, is counted as purged here in the base.
        """

    def _write_now(self, item: TxT) -> bool:
        """Write ``item`` from the caller's stack (only called while ``self._direct`` is True).

        Returns:
            True when written (counted and reported here by the subclass); False to queue it
            instead (the device cannot take it now).
        """
        raise NotImplementedError

    def _now(self) -> float:
        """The event loop's clock (time.monotonic() before the transport was first opened)."""
        loop = self._loop
        return loop.time() if loop is not None else time.monotonic()

    # ----------------------------------------------------------------- life cycle

    @property
    def state(self) -> TransportState:
        return self._state

    @property
    def stale_after_s(self) -> float | None:
        """How long a queued frame may wait before it is dropped as stale (None: no limit)."""
        return self._stale_after_s

    @property
    def is_open(self) -> bool:
        return self._state is TransportState.OPEN

    async def open(self) -> None:
        """Open the device.

        Raises:
            TransportError: it cannot be opened (the cause is chained); the state stays CLOSED.
            RuntimeError: the transport is not closed.
        """
        if self._state is not TransportState.CLOSED:
            raise RuntimeError(f"{self.name} is already {self._state.value}")
        self._loop = asyncio.get_running_loop()
        self._set_state(TransportState.OPENING)
        self._generation += 1
        try:
            await self._connect()
        except BaseException:
            self._set_state(TransportState.CLOSED)
            raise
        self._ever_opened = True
        self._connected()

    async def close(self) -> None:
        """Stop, drop whatever is still queued (counted as purged) and release the device.

        Pending receivers raise :class:`~servobus.errors.TransportError`; ``async for`` loops end.
        Closing twice is harmless.
        """
        if self._state is TransportState.CLOSED:
            return
        self._generation += 1
        self._failure = ("closed", None)
        self._state = TransportState.CLOSED  # announced last, after the drops it causes
        for task in (self._recovery, self._writer):
            if task is not None and task is not asyncio.current_task():
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
        self._recovery = self._writer = None
        self._purge("purged")
        self._fail_waiters(self._open_waiters)
        self._fail_waiters(self._rx_waiters)
        self._fail_waiters(self._idle_waiters)
        await self._disconnect()  # also when LOST: the recovery task may not have got to it
        self._set_state(TransportState.CLOSED)

    async def __aenter__(self) -> Self:
        await self.open()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()

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
        if self._state is TransportState.CLOSED:
            raise self._error()
        async with asyncio.timeout(timeout):
            await _park(self._open_waiters)

    def _connected(self) -> None:
        self._failure = None
        self._set_state(TransportState.OPEN)
        self._writer = asyncio.get_running_loop().create_task(
            self._write_loop(self._generation), name=f"{self.name} writer"
        )
        for waiter in self._open_waiters:
            _wake(waiter)

    def _lose(self, cause: BaseException, generation: int | None = None) -> None:
        """The device failed: fail every waiter at once, purge the queue, start reopening.

        Safe to call more than once and from stale callbacks (``generation`` of an older
        connection): only the first call for the current connection acts.
        """
        if self._state is not TransportState.OPEN or generation not in (None, self._generation):
            return
        logger.warning("%s: device lost: %s", self.name, cause)
        self._stats.losses += 1
        self._generation += 1
        self._failure = ("device lost", cause)
        self._set_state(TransportState.LOST, cause)
        if self._writer is not None and self._writer is not asyncio.current_task():
            self._writer.cancel()
        self._writer = None
        self._transmitting = False
        self._purge("purged")
        self._fail_waiters(self._rx_waiters)
        self._fail_waiters(self._idle_waiters)
        assert self._loop is not None
        self._recovery = self._loop.create_task(self._recover(), name=f"{self.name} recovery")

    async def _recover(self) -> None:
        with contextlib.suppress(Exception):
            await self._disconnect()
        if not self._reopen:
            return
        delay, longest = self._backoff
        while self._state is TransportState.LOST:
            await asyncio.sleep(delay)
            self._generation += 1
            try:
                await self._connect()
            except Exception as exc:  # the device is still away (or refuses): try again later
                log = logger.debug if isinstance(exc, TransportError) else logger.warning
                log("%s: reopen failed: %s", self.name, exc)
                delay = min(2 * delay, longest)
                continue
            if self._state is not TransportState.LOST:  # closed while we were opening
                await self._disconnect()
                return
            self._stats.reopens += 1
            logger.info("%s: reopened", self.name)
            self._recovery = None
            self._connected()

    def _set_state(self, state: TransportState, cause: BaseException | None = None) -> None:
        self._state = state
        self._emit(StateChanged(state, self._now(), cause))

    def _error(self) -> TransportError:
        """A fresh TransportError saying why the transport cannot serve now, chained to the cause."""
        what, cause = self._failure or (self._state.value, None)
        error = TransportError(f"{self.name}: {what}" + (f" ({cause})" if cause else ""))
        error.__cause__ = cause
        return error

    def _fail_waiters(self, waiters: list[asyncio.Future[None]]) -> None:
        for waiter in waiters:
            if not waiter.done():
                waiter.set_exception(self._error())
        waiters.clear()

    # ----------------------------------------------------------------- sending

    def _enqueue(self, item: TxT, hold_s: float | None = None) -> None:
        if self._state is not TransportState.OPEN:
            raise self._error()
        if self._direct and not self._queue and not self._transmitting and self._write_now(item):
            return
        if len(self._queue) >= self._queue_size:
            self._stats.queue_full += 1
            raise SendQueueFull(
                f"{self.name}: send queue full ({self._queue_size} frames); await drain() before sending more"
            )
        self._queue.append(Outgoing(item, self._now(), hold_s))
        if self._writer_wake is not None:
            _wake(self._writer_wake)

    @property
    def queue_room(self) -> int:
        """Frames :meth:`send` accepts now without raising :class:`SendQueueFull`."""
        return self._queue_size - len(self._queue)

    async def drain(self) -> None:
        """Wait until every queued frame has been written (or dropped by policy).

        Raises:
            TransportError: the device was lost or the transport closed meanwhile.
        """
        while self._queue or self._transmitting:
            if self._state is not TransportState.OPEN:
                raise self._error()
            await _park(self._idle_waiters)
        if self._state is not TransportState.OPEN:
            raise self._error()

    async def _write_loop(self, generation: int) -> None:
        loop = asyncio.get_running_loop()
        queue = self._queue
        while True:
            if not queue:
                for waiter in self._idle_waiters:
                    _wake(waiter)
                self._writer_wake = loop.create_future()
                await self._writer_wake
                self._writer_wake = None
                continue
            batch = [queue.popleft() for _ in range(min(self.batch_size, len(queue)))]
            batch = self._drop_stale(batch, self._now())
            if not batch:
                continue
            self._transmitting = True
            try:
                await self._transmit(batch)
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # a transmit bug must not leave the queue stuck forever
                self._lose(exc, generation)
                return
            finally:
                self._transmitting = False
                self._dropped("purged", [o.item for o in batch])  # not written: lost, closed or failed
            if generation != self._generation:  # _transmit lost the device
                return

    def _drop_stale(self, batch: list[Outgoing[TxT]], now: float) -> list[Outgoing[TxT]]:
        limit = self._stale_after_s
        if limit is None or now - batch[0].queued_at <= limit:  # the oldest is first
            return batch
        fresh = [item for item in batch if now - item.queued_at <= limit]
        self._dropped("stale", [o.item for o in batch if now - o.queued_at > limit])
        return fresh

    def _purge(self, reason: str) -> None:
        if self._queue:
            self._dropped(reason, [o.item for o in self._queue])
            self._queue.clear()

    def _dropped(self, reason: str, items: Sequence[TxT] | int) -> None:
        """Count frames that will never be sent, and report each one that is known."""
        count = items if isinstance(items, int) else len(items)
        if count:
            setattr(self._stats, reason, getattr(self._stats, reason) + count)
            self._emit(FramesDropped(reason, count, self._now()))
            reporter = self._reporter
            if reporter is not None and not isinstance(items, int):
                for item in items:
                    self._call(reporter, item, None, reason)

    def _sent(self, item: TxT, sent_at: float) -> None:
        """Report that ``item`` left at ``sent_at`` (a subclass calls it; counting is its own)."""
        if self._reporter is not None:
            self._call(self._reporter, item, sent_at, None)

    def set_send_reporter(self, reporter: SendReporter[TxT] | None) -> None:
        """Call ``reporter(item, sent_at, None)`` for every frame that left, and
        ``reporter(item, None, reason)`` for every one dropped after :meth:`send` accepted it.

        Called on the event loop; its exceptions are logged, never raised into the transport.
        """
        self._reporter = reporter

    def _call(self, callback: Callable[..., object], *args: object) -> None:
        try:
            callback(*args)
        except Exception:
            logger.exception("%s: callback %r failed", self.name, callback)

    # ----------------------------------------------------------------- receiving

    def set_consumer(self, consumer: Consumer[RxT] | None) -> None:
        """Push delivery: call ``consumer(frames)`` on the event loop with every received batch.

        With a consumer, nothing is buffered for :meth:`receive`; frames already buffered are handed
        to it at once. Its exceptions are logged, never raised into the reader. None goes back to
        buffering.
        """
        self._consumer = consumer
        if consumer is not None and self._rx:
            frames = list(self._rx)
            self._rx.clear()
            self._call(consumer, frames)

    def _deliver(self, frames: Sequence[RxT]) -> None:
        """Hand received frames to the consumer, or to readers (call in the loop thread)."""
        consumer = self._consumer
        if consumer is not None:
            try:
                consumer(frames if isinstance(frames, list) else list(frames))
            except Exception:
                logger.exception("%s: consumer %r failed", self.name, consumer)
            return
        rx = self._rx
        rx.extend(frames)
        if (overflow := len(rx) - self._rx_capacity) > 0:
            for _ in range(overflow):
                rx.popleft()
            self._dropped("rx_overflow", overflow)
        for waiter in self._rx_waiters:
            _wake(waiter)

    async def receive(self) -> RxT:
        """The next received frame (frames received before a loss or close come first).

        Raises:
            TransportError: the device is lost or the transport closed, and nothing is buffered.
        """
        while True:
            if self._rx:
                return self._rx.popleft()
            await self._wait_rx()

    async def receive_batch(self, max_frames: int | None = None) -> list[RxT]:
        """Every buffered frame (at most ``max_frames``), waiting for at least one."""
        while not self._rx:
            await self._wait_rx()
        rx = self._rx
        if max_frames is None or max_frames >= len(rx):
            frames = list(rx)
            rx.clear()
            return frames
        return [rx.popleft() for _ in range(max_frames)]

    async def _wait_rx(self) -> None:
        if self._state is not TransportState.OPEN:
            raise self._error()
        await _park(self._rx_waiters)

    async def __aiter__(self) -> AsyncIterator[RxT]:
        """Received frames until the transport is closed; a loss raises TransportError."""
        while True:
            try:
                yield await self.receive()
            except TransportError:
                if self._state is TransportState.CLOSED:
                    return
                raise

    # ----------------------------------------------------------------- events and counters

    def add_listener(self, listener: Callable[[TransportEvent], object]) -> None:
        """Call ``listener(event)`` in the loop for every event; its exceptions are logged, not raised."""
        self._listeners.append(listener)

    def remove_listener(self, listener: Callable[[TransportEvent], object]) -> None:
        self._listeners.remove(listener)

    async def events(self, maxsize: int = 1000) -> AsyncIterator[TransportEvent]:
        """Events as an async stream, ending after the transport closes (oldest dropped when full)."""
        pending: deque[TransportEvent] = deque(maxlen=maxsize)
        ready = asyncio.Event()

        def collect(event: TransportEvent) -> None:
            pending.append(event)
            ready.set()

        self.add_listener(collect)
        try:
            while True:
                await ready.wait()
                ready.clear()
                while pending:
                    event = pending.popleft()
                    yield event
                    if isinstance(event, StateChanged) and event.state is TransportState.CLOSED:
                        return
        finally:
            self.remove_listener(collect)

    def _emit(self, event: TransportEvent) -> None:
        for listener in list(self._listeners):
            try:
                listener(event)
            except Exception:
                logger.exception("%s: event listener %r failed", self.name, listener)

    def stats(self) -> TransportStats:
        """A snapshot of the counters, with the current state, queue depth and bus load."""
        snapshot = copy.copy(self._stats)
        snapshot.state = self._state
        snapshot.queue_depth = len(self._queue)
        snapshot.bus_load_pct = self._load.percent(self._now()) if self._load_known else None
        return snapshot

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name} {self._state.value}>"


def _wake(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


async def _park(waiters: list[asyncio.Future[None]]) -> None:
    """Wait on a new future in ``waiters`` until it is woken (or failed), then leave the list."""
    waiter = asyncio.get_running_loop().create_future()
    waiters.append(waiter)
    try:
        await waiter
    finally:
        with contextlib.suppress(ValueError):  # already cleared by _fail_waiters
            waiters.remove(waiter)
