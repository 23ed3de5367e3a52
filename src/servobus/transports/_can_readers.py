"""How a :class:`~servobus.transports.can.CanTransport` reads its python-can bus: three strategies
behind one small interface (private).

* :class:`FdReader`: the bus has a file descriptor (socketcan, python-can's slcan and other serial
  adapters): the loop watches it (:class:`~servobus.transports._watch.ReadWatch`) and reads one frame
  per wake-up, with no thread.
* :class:`ThreadReader`: no descriptor (virtual, most vendor drivers): one reader thread, as
  python-can's own ``Notifier`` has, hands frames over in batches through the runtime's
  ``call_soon_threadsafe`` (never blocks the thread).
* :class:`NotifierReader`: the application's ``can.Notifier`` reads the bus: a listener on it.

Each hands ``(message, time)`` pairs to its :class:`Sink`'s ``take`` (the transport's
:class:`~servobus.transports._can_intake.CanIntake`) with the connection's generation. Frames read on
the loop are stamped on the loop's clock already (``shift`` 0); those from a thread on
``time.monotonic``, shifted onto the loop's clock when they arrive there (trio's clock and a virtual
clock are not ``time.monotonic``). A read that fails with an OS error is a lost device (``lose``);
one python-can cannot parse is a bad frame (``count_bad``), and reading goes on.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Sequence
from typing import Protocol

import anyio
import can

from servobus.runtime import Runtime
from servobus.transports._owned import LinkTasks
from servobus.transports._watch import ReadWatch, loop_context

__all__ = ["FdReader", "NotifierReader", "Reader", "ThreadReader", "device_failed"]

_THREAD_POLL_S = 0.05  # how long a reader thread blocks in recv(): bounds how fast close() is
_THREAD_BATCH = 256  # frames a reader thread hands to the loop per wake-up, at most

#: python-can's slcan reader keeps bytes until a ``\r`` arrives; a peer that never sends one would grow
#: its buffer without end. No valid line is longer than this (CAN FD extended, with timestamp).
_SLCAN_MAX_LINE = 1 + 8 + 1 + 128 + 4 + 1

Batch = Sequence[tuple[can.Message, float]]


class Sink(Protocol):
    """What a reader hands its frames and failures to (the transport's intake)."""

    @property
    def name(self) -> str: ...

    def take(self, batch: Batch, generation: int, shift: float = 0.0) -> None: ...

    def count_bad(self, count: int, generation: int, discarded_bytes: int = 0) -> None: ...

    @property
    def lose(self) -> Callable[[BaseException, int], None]: ...


class Reader(Protocol):
    def start(self) -> None: ...

    async def close(self) -> None:
        """Stop reading; once it returns nothing more is handed over from this reader."""
        ...


def device_failed(exc: BaseException) -> bool:
    """Whether a receive error means the device is gone (an OS or serial error), not a bad frame.

    python-can's readers raise ValueError/IndexError for a line they cannot parse (slcan: ``t12\\r``)
    and wrap OS errors in CanOperationError; only the latter is a lost device.
    """
    cause: BaseException | None = exc
    while cause is not None:
        if isinstance(cause, OSError):
            return True
        if isinstance(cause, ValueError | IndexError | KeyError | TypeError):
            return False
        cause = cause.__cause__ or cause.__context__
    return True  # unknown: treat as lost, the reopen logic recovers a device that is still there


class FdReader:
    """One frame per readiness of the bus's descriptor, read on the loop."""

    def __init__(
        self, sink: Sink, bus: can.BusABC, fd: int, generation: int, runtime: Runtime, tasks: LinkTasks
    ) -> None:
        self._sink = sink
        self._bus = bus
        self._generation = generation
        self._time = runtime.time
        self._watch = ReadWatch(runtime, tasks, fd, self._on_readable, sink.name)
        self._slcan = _is_python_can_slcan(bus)  # (its line buffer is bounded here: see below)

    def start(self) -> None:
        self._watch.start()

    async def close(self) -> None:
        await self._watch.stop()

    def _on_readable(self) -> None:
        sink, bus = self._sink, self._bus
        try:
            message = bus.recv(0)
        except Exception as exc:
            if not device_failed(exc):  # a line python-can could not parse: one bad frame
                sink.count_bad(1, self._generation)
                return
            self._watch.cancel()  # a vanished device stays readable: stop watching it
            sink.lose(exc, self._generation)
            return
        finally:
            if self._slcan:
                _bound_line_buffer(bus, sink, self._generation)
        if message is not None:
            sink.take([(message, self._time())], self._generation)


def _is_python_can_slcan(bus: can.BusABC) -> bool:
    try:
        from can.interfaces.slcan import slcanBus
    except ImportError:  # (python-can without its slcan interface)
        return False
    return isinstance(bus, slcanBus)


def _bound_line_buffer(bus: can.BusABC, sink: Sink, generation: int) -> None:
    # python-can's slcan keeps its partial line in ``_buffer``; it has no public bound or reset
    buffer = getattr(bus, "_buffer", None)
    if isinstance(buffer, bytearray) and len(buffer) > _SLCAN_MAX_LINE:
        sink.count_bad(1, generation, len(buffer))
        buffer.clear()


class ThreadReader:
    """A reader thread: blocks in ``recv``, batches what is already there, hands it to the loop."""

    def __init__(self, sink: Sink, bus: can.BusABC, generation: int, runtime: Runtime) -> None:
        self._sink = sink
        self._bus = bus
        self._generation = generation
        self._call = runtime.call_soon_threadsafe
        self._time = runtime.time
        self._stop = threading.Event()
        self._thread = threading.Thread(  # its hand-overs run in a context naming the backend
            target=loop_context(runtime).run, args=(self._run,), name=f"{sink.name} reader", daemon=True
        )

    def start(self) -> None:
        self._thread.start()

    async def close(self) -> None:
        self._stop.set()
        with anyio.CancelScope(shield=True):  # it polls every 50 ms: a short, bounded wait
            await anyio.to_thread.run_sync(self._thread.join)

    def _run(self) -> None:
        bus, sink, generation, stop = self._bus, self._sink, self._generation, self._stop
        monotonic = time.monotonic
        bad = 0
        while not stop.is_set():
            batch: list[tuple[can.Message, float]] = []
            try:
                message = bus.recv(_THREAD_POLL_S)
                if message is None:
                    continue
                batch.append((message, monotonic()))
                # what came meanwhile goes in the same hand-over (python-can's public recv(0))
                while len(batch) < _THREAD_BATCH and (message := bus.recv(0)) is not None:
                    batch.append((message, monotonic()))
            except Exception as exc:
                if device_failed(exc):
                    if not stop.is_set():
                        with contextlib.suppress(RuntimeError):  # the loop is gone
                            self._call(sink.lose, exc, generation)
                    return
                bad += 1  # a frame python-can could not parse: counted, the reader goes on
            try:
                if bad:
                    self._call(sink.count_bad, bad, generation)
                    bad = 0
                if batch:
                    self._call(_take_from_thread, sink, batch, generation, self._time)
            except RuntimeError:  # the loop closed under us
                return


def _take_from_thread(sink: Sink, batch: Batch, generation: int, loop_time: Callable[[], float]) -> None:
    """On the loop: a thread's batch, its monotonic stamps shifted onto the loop's clock."""
    sink.take(batch, generation, loop_time() - time.monotonic())


class NotifierReader(can.Listener):
    """What a :class:`CanTransport` adds to an application's ``can.Notifier``: the frames the notifier
    reads go to the transport's loop in batches; a reader failure is a lost device."""

    def __init__(self, sink: Sink, notifier: can.Notifier, generation: int, runtime: Runtime) -> None:
        self._sink = sink
        self._notifier = notifier
        self._generation = generation
        self._runtime = runtime
        self._call = runtime.call_soon_threadsafe
        self._context = loop_context(runtime)  # a copy per hand-over: threads may overlap
        self._pending: list[tuple[can.Message, float]] = []
        self._lock = threading.Lock()

    def start(self) -> None:
        self._notifier.add_listener(self)

    async def close(self) -> None:
        with contextlib.suppress(ValueError):  # the application removed it already
            self._notifier.remove_listener(self)

    def on_message_received(self, msg: can.Message) -> None:
        with self._lock:
            self._pending.append((msg, time.monotonic()))
            if len(self._pending) > 1:
                return  # a hand-over is already on its way
        if self._runtime.is_current():  # a notifier running on our own loop
            self._flush()
            return
        with contextlib.suppress(RuntimeError):  # the loop is gone: nobody is left to take it
            self._call(self._context.copy().run, self._flush)

    def _flush(self) -> None:
        with self._lock:
            batch, self._pending = self._pending, []
        _take_from_thread(self._sink, batch, self._generation, self._runtime.time)

    def on_error(self, exc: Exception) -> None:
        """A read failed in the notifier: a lost device (or one bad frame) for the transport.

        Raises NotImplementedError, python-can's "not handled here", so whether the application's
        notifier stops or reads on stays its own listeners' decision, as without servobus.
        """
        sink, generation, call, run = self._sink, self._generation, self._call, self._context.copy().run
        with contextlib.suppress(RuntimeError):
            if device_failed(exc):
                call(run, sink.lose, exc, generation)
            else:  # a frame python-can could not parse
                call(run, sink.count_bad, 1, generation)
        raise NotImplementedError

    def stop(self) -> None:
        """python-can's ``Listener.stop`` (the notifier stopping): nothing to release here."""


def start_reader(
    sink: Sink,
    bus: can.BusABC,
    notifier: can.Notifier | None,
    generation: int,
    runtime: Runtime,
    tasks: LinkTasks,
) -> Reader:
    """The reader for ``bus``: the notifier's listener, the descriptor's watch, or a thread; started."""
    reader: FdReader | ThreadReader | NotifierReader
    if notifier is not None:
        reader = NotifierReader(sink, notifier, generation, runtime)
    else:
        fileno = -1
        with contextlib.suppress(NotImplementedError, can.CanError, OSError):
            fileno = bus.fileno()
        if fileno >= 0:
            reader = FdReader(sink, bus, fileno, generation, runtime, tasks)
        else:
            reader = ThreadReader(sink, bus, generation, runtime)
    reader.start()
    return reader
