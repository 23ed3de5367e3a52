"""The Bus: one physical bus, its motors, and every request's life on it (asyncio, anyio-friendly).

``async with Bus(transport) as bus`` takes a transport (CAN through python-can, the native SLCAN
link, an RS485 line, or the in-process simulator), and then:

* ``bus.motor("myactuator", 3)`` binds a motor through its family's codec (``Family.bind``); motors
  that cannot share the bus are refused with both named.
* ``await motor.request(command)``, or ``await motor.read_status2()`` / ``motor.speed_control(...)``
  for every command of the family: the typed reply, or :class:`~servobus.errors.MotorTimeout`
  naming motor, command and timeout.
* ``await bus.cycle([(motor, command), ...])``: one control tick, every request in flight at once,
  one result per item in order (a reply, or the exception as a value), so one silent motor never
  costs the others their replies; and a tick never waits on a motor that is not answering (an
  offline motor's slot is MotorOffline at once, and the motor is probed aside until it answers).
* Timeouts come from measured round trips (RFC 6298, per motor and command class), so a slow
  adapter is waited for and a late reply is held for, not taken for the next request's (one later
  than its hold can be: such replies are counted ``ambiguous``).
* ``await bus.broadcast(command, motors)``: MyActuator's 0x280/0xCD and LK's multi-motor torque.
* Leaving the ``async with`` block, normally, by an exception or by cancellation, sends the safe
  command (stop by default) to every motor this Bus commanded, shielded, again and again until each
  motor acknowledged it or ``safe_timeout_s`` ended.
  From then on nothing else is sent: requests not yet sent, and any made later (by a task the block
  did not wait for), fail with TransportError, and so does every request still waiting for a reply
  once the block is left.

Inside, the sans-IO :class:`~servobus.scheduler.Scheduler` matches, paces and times out; the Bus only
moves frames between it and the transport (push delivery and send reports, no polling) and keeps one
timer. No global state, no signal handlers: a Bus lives inside the user's loop and task groups.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import inspect
import logging
from collections import deque
from collections.abc import AsyncIterator, Awaitable, Callable, Hashable, Iterable, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any, NoReturn, Protocol, Self, TypeVar, cast, overload

import anyio

from servobus.errors import (
    MotorBusy,
    MotorFault,
    MotorOffline,
    MotorStreaming,
    MotorTimeout,
    TransportError,
)
from servobus.frame import Frame
from servobus.metrics import Metrics
from servobus.protocols import BoundCodec, Command, Family, Reply, get_family
from servobus.scheduler import Received, Request, RequestState, Scheduler, Traffic
from servobus.ticks import Tick, ticks
from servobus.transports.events import StateChanged, TransportEvent, TransportState

__all__ = ["Bus", "FrameLink", "Motor", "MotorFrames", "MotorStatus", "command_classes"]

R = TypeVar("R")
M = TypeVar("M", bound="Motor")

logger = logging.getLogger("servobus.bus")


class FrameLink(Protocol):
    """What the Bus needs of a transport (every servobus transport is one)."""

    name: str

    @property
    def is_open(self) -> bool: ...

    async def open(self) -> None: ...

    async def close(self) -> None: ...

    def send(self, frame: Frame) -> None: ...

    def set_consumer(self, consumer: Callable[[list[Frame]], object] | None) -> None: ...

    def set_send_reporter(
        self, reporter: Callable[[Frame, float | None, str | None], object] | None
    ) -> None: ...

    def add_listener(self, listener: Callable[[TransportEvent], object]) -> None: ...

    def remove_listener(self, listener: Callable[[TransportEvent], object]) -> None: ...


Result = Reply | BaseException | None
# RequestState members as globals for the per-frame paths (an Enum member lookup is a metaclass call).
_SENT, _REPLIED, _TIMED_OUT = RequestState.SENT, RequestState.REPLIED, RequestState.TIMED_OUT


class _Tick:
    """The outcomes of one :meth:`Bus.cycle`, gathered into one future: the cycle wakes once when its
    last request ends, not once per motor (what ``asyncio.gather`` of one future per request costs)."""

    __slots__ = ("future", "left", "results")

    def __init__(self, future: asyncio.Future[list[Result]], size: int) -> None:
        self.future = future
        self.results: list[Result] = [None] * size
        self.left = size


class _Slot:
    """One request's place in a :class:`_Tick`, with the part of a future's interface the Bus and
    an observer of the request (``request.context``) use: its outcome is the tick's result there."""

    __slots__ = ("_callbacks", "_state", "index", "tick")

    def __init__(self, tick: _Tick, index: int) -> None:
        self.tick = tick
        self.index = index
        self._state = 0  # 0 pending, 1 done, 2 cancelled
        self._callbacks: list[Callable[[_Slot], object]] | None = None

    def done(self) -> bool:
        return self._state != 0

    def cancelled(self) -> bool:
        return self._state == 2

    def set_result(self, value: Result) -> None:
        self._state = 1
        tick = self.tick
        tick.results[self.index] = value
        tick.left -= 1
        if not tick.left and not tick.future.done():
            tick.future.set_result(tick.results)
        if self._callbacks:
            self._run_callbacks()

    set_exception = set_result  # an exception is the request's result, as a value

    def cancel(self) -> bool:
        """The cycle awaiting the tick was cancelled (its future is already)."""
        if self._state:
            return False
        self._state = 2
        if self._callbacks:
            self._run_callbacks()
        return True

    def result(self) -> Result:
        value = self._outcome()
        if isinstance(value, BaseException):
            raise value
        return value

    def exception(self) -> BaseException | None:
        value = self._outcome()
        return value if isinstance(value, BaseException) else None

    def _outcome(self) -> Result:
        if self._state == 2:
            raise asyncio.CancelledError
        if not self._state:
            raise asyncio.InvalidStateError("the request has not ended")
        return self.tick.results[self.index]

    def add_done_callback(self, callback: Callable[[_Slot], object]) -> None:
        """As a future's: ``callback(slot)`` soon after the request ends."""
        if self._state:
            self.tick.future.get_loop().call_soon(callback, self)
        else:
            self._callbacks = [*(self._callbacks or ()), callback]

    def _run_callbacks(self) -> None:
        callbacks, self._callbacks = self._callbacks or [], None
        loop = self.tick.future.get_loop()
        for callback in callbacks:
            loop.call_soon(callback, self)


def _awaitable(context: asyncio.Future[Any] | _Slot) -> asyncio.Future[Any]:
    """What to await for a request to end: its future, or its cycle's."""
    return context.tick.future if isinstance(context, _Slot) else context


def _detached(loop: asyncio.AbstractEventLoop) -> asyncio.Future[Any]:
    """A future for a request nobody awaits (a probe, a repeated stream "off"): its outcome is
    taken when it ends, so an exception is never reported as "never retrieved"."""
    future: asyncio.Future[Any] = loop.create_future()
    future.add_done_callback(lambda f: f.cancelled() or f.exception())
    return future


class _Default:
    """The type of an argument whose default comes from elsewhere (the transport)."""


_DEFAULT = _Default()


@dataclass(frozen=True, slots=True)
class MotorStatus:
    """A motor went offline (missed replies, or silent too long) or came back (it answered).

    Attributes:
        motor: the motor.
        online: its new state.
        at: when (the loop's clock).
        reason: why, in words (``"3 replies missed"``, ``"silent for 0.5 s"``, ``"answered"``).
    """

    motor: Motor
    online: bool
    at: float
    reason: str


def command_classes(family: str) -> dict[str, type[Command]]:
    """The command classes of ``family`` by method name (``ReadStatus2`` -> ``read_status2``): the
    names :class:`Motor` offers as methods (``await motor.read_status2()``).

    Raises:
        ValueError: no family has that name.
    """
    return get_family(family).methods()


class MotorFrames:
    """The decoded frames of one motor as an async iterator, buffered up to ``size``.

    Use ``async with motor.frames() as frames: async for reply in frames: ...``. When the reader falls
    behind, the oldest frames are dropped and counted in :attr:`dropped`, so a slow consumer never
    holds memory without end or slows the Bus.
    """

    def __init__(self, motor: Motor, size: int, kinds: frozenset[Traffic]) -> None:
        if size < 1:
            raise ValueError(f"size={size} must be at least 1")
        self.motor = motor
        self.kinds = kinds
        self.dropped = 0
        self._size = size
        self._items: deque[Reply] = deque()
        self._ready = asyncio.Event()
        self._closed = False

    def _push(self, traffic: Traffic, reply: Reply) -> None:
        if traffic not in self.kinds:
            return
        if len(self._items) >= self._size:
            self._items.popleft()
            self.dropped += 1
        self._items.append(reply)
        self._ready.set()

    async def __aenter__(self) -> Self:
        self.motor._watchers.append(self)
        return self

    async def __aexit__(self, *exc: object) -> None:
        self._end()

    def _end(self) -> None:
        """No more frames (the block was left, or the Bus closed): the iteration ends."""
        self._closed = True
        with contextlib.suppress(ValueError):
            self.motor._watchers.remove(self)
        self._ready.set()

    def __aiter__(self) -> Self:
        return self

    async def __anext__(self) -> Reply:
        while not self._items:
            if self._closed:
                raise StopAsyncIteration
            self._ready.clear()
            await self._ready.wait()
        return self._items.popleft()


class Motor:
    """One motor on a Bus: its codec, its latest telemetry, and a method per command of its family.

    ``await motor.speed_control(speed_dps=100)`` builds ``SpeedControl(speed_dps=100)`` (its range
    checks raise ValueError before anything is sent) and awaits the typed reply.

    Attributes:
        codec: the bound codec (family, id, revision, link).
        state: the latest reply, stream frame or error report received from this motor (None yet).
        last_seen: when it was received (the loop's clock; None yet).
        fault: the error flags the motor last reported (a :class:`~servobus.errors.MotorFault`, to
            read or raise), or None when its last report of them had none (or none came yet).
        online: the host-side watchdog's verdict: True once it answered, False after
            ``offline_after_misses`` missed replies in a row or ``offline_after_s`` of silence, None
            before either happened. A motor that answers again is online again.
    """

    def __init__(self, bus: Bus, codec: BoundCodec, commands: dict[str, type[Command]] | None = None) -> None:
        self.bus = bus
        self.codec = codec
        self.state: Reply | None = None
        self.last_seen: float | None = None
        self.online: bool | None = None
        self.fault: MotorFault | None = None
        self._misses = 0
        # by method name; from the Family the Bus bound it with (a plug-in may be unregistered)
        self._commands = command_classes(codec.family) if commands is None else commands
        self._watchers: list[MotorFrames] = []
        self._probe_at = 0.0  # while offline: when cycle() may next send it a command, as a probe
        # Streams switched off: the command byte -> (the "off" command, when it was last sent, the
        # stream's interval in s).
        self._ending: dict[int, tuple[Command, float, float]] = {}

    def metrics(self) -> Metrics:
        """This motor's counters and request-to-reply latency (see :class:`~servobus.metrics.Metrics`)."""
        scheduler = self.bus.scheduler
        key = id(self.codec)
        return Metrics.of(scheduler.motor_counts[key], scheduler.motor_latency[key].snapshot())

    @contextlib.asynccontextmanager
    async def stream(
        self, command: int | type[Command], *, interval_ms: int, size: int = 64
    ) -> AsyncIterator[MotorFrames]:
        """Have the motor stream ``command``'s reply every ``interval_ms`` (MyActuator 0xB6) and iterate
        the frames; the stream is switched off when the block is left, however it is left.

        ``async with motor.stream(ma.ReadStatus2, interval_ms=10) as frames: async for r in frames``.
        While a stream is on the motor answers no requests (MyActuator §9 item 18), except reads of
        the streamed command, which the next stream frame answers.

        Raises:
            ValueError: the family has no streams, the command cannot be streamed, or a bad interval.
        """
        active_reply: Callable[..., Command] | None = self._commands.get("active_reply")
        if active_reply is None:
            raise ValueError(f"{self.codec.family} motors have no active-reply streams")
        code = command if isinstance(command, int) else command.CODE
        if code is None:
            raise ValueError(f"{command!r} has no command byte to stream")
        on = active_reply(command=code, enabled=True, interval_ms=interval_ms)
        off = active_reply(command=code, enabled=False)
        async with self.frames(size=size, kinds=(Traffic.STREAM,)) as frames:
            self._ending.pop(code, None)
            await self.request(on)
            try:
                yield frames
            finally:
                with anyio.CancelScope(shield=True), contextlib.suppress(TransportError, MotorTimeout):
                    await self.request(off)
                    # "off" gets no reply: if it was lost, the frames that keep coming say so, and
                    # the Bus sends it again (Bus._stream_goes_on).
                    self._ending[code] = (off, self.bus._now(), interval_ms / 1000)

    def frames(
        self, *, size: int = 64, kinds: Iterable[Traffic] = (Traffic.STREAM, Traffic.REPORT)
    ) -> MotorFrames:
        """This motor's decoded frames of ``kinds`` (default: 0xB6 stream frames and error reports)
        as an async iterator; enable a stream first (MyActuator: ``await motor.active_reply(...)``).

        Raises:
            ValueError: ``size`` below 1.
        """
        return MotorFrames(self, size, frozenset(kinds))

    @property
    def motor_id(self) -> int:
        return self.codec.motor_id

    def __repr__(self) -> str:
        return f"<Motor {self.codec.family} {self.codec.motor_id} on {self.bus.name}>"

    async def request(self, command: Command[R], *, timeout_s: float | None = None, retries: int = 0) -> R:
        """Send ``command`` and await its reply: the type its class declares (``Command[StatusReply]``),
        None for commands that get none. A command to a motor that streams gets no reply either
        (MyActuator §4.36): then it is None too, whatever its class declares.

        Raises:
            ValueError: the command is refused by the codec (before any frame is sent).
            MotorTimeout: no reply within the timeout (the codec's default for the command).
            TransportError: the transport was lost or refused the frame.
            RuntimeError: called from another event loop than the Bus's (servobus.sync.Bus is for threads).
        """
        return await self.bus.request(self, command, timeout_s=timeout_s, retries=retries)

    if not TYPE_CHECKING:  # the typed subclass (Family.motor) spells each method; this is for the rest

        def __getattr__(self, name: str) -> Callable[..., Awaitable[Reply | None]]:
            try:
                cls = self.__dict__["_commands"][name]
            except KeyError:
                raise AttributeError(f"{self.codec.family} motors have no command {name!r}") from None

            async def call(
                *args: Any, timeout_s: float | None = None, retries: int = 0, **fields: Any
            ) -> Reply | None:
                if args:  # the command's fields in their declaration order, as the command lists them
                    fields = _positional_fields(cls, name, args, fields)
                return await self.request(cls(**fields), timeout_s=timeout_s, retries=retries)

            call.__name__ = name
            call.__doc__ = f"Send {cls.__name__} and await its reply.\n\n{cls.__doc__ or ''}"
            return call

    def __dir__(self) -> list[str]:
        return [*super().__dir__(), *self._commands]


class Bus:
    """One bus and its motors.

    Args:
        transport: the link; opened (and closed on exit) by the Bus unless it is already open.
        safe: the command every commanded motor gets when the block is left: ``"stop"``,
            ``"shutdown"``, ``"brake"``, or None for nothing.
        safe_timeout_s: how long the safe stop may take in all: it is sent again to each motor that
            has not acknowledged it (0x81 and its kin are safe to repeat) until then.
        max_in_flight: requests in flight at once (default: 64; 1 on a half-duplex line).
        name: a label for errors and logs (default: the transport's).
        min_reply_s: the least time a reply can take after its request left (default: two of the
            shortest frames at the transport's bit rate, where it has one): a frame with the reply's
            key that arrives sooner is not taken for it.
        stale_after_s: a command (not a read) that waited longer than this for its turn, on a stalled
            or slow half-duplex line, fails with TransportError instead of reaching the motor late
            (default: the transport's own ``stale_after_s``; None for no limit).
        late_hold_s: how late a reply may come after its request timed out (default: at least
            twice the request's timeout; once its motor and command class were measured 16 times,
            twice the measured timeout and 1.5 times the longest recent late round trip; before,
            twice the codec's own time for the command, or the bus's slowest measured if longer).
            The next request with its key waits that long, or until the late reply came (in
            :meth:`cycle`: MotorBusy at once), because no reply carries a sequence number. A reply
            later still could answer it: such replies are counted ``ambiguous``.
        initial_timeout_s: the timeout of a request sent before any round trip on this bus was
            measured (the first exchange through a freshly opened adapter can take tens or hundreds
            of ms); requests in flight get a measured one as soon as the first reply comes.
        min_timeout_s, max_timeout_s: bounds of a timeout derived from measured round trips. The
            floor (5 ms) is for the host, not the motor: a loaded event loop, or an adapter's reader
            thread waiting for the GIL (switched every 5 ms), delays a reply that came in time. A
            request's own ``timeout_s`` overrides all of this.
        offline_after_misses: replies missed in a row after which a motor is marked offline.
        offline_after_s: silence after which a motor that answered before is marked offline (None:
            silence alone never does; set it when the motor streams or is polled steadily).
        probe_interval_s: how often :meth:`cycle` still sends an offline motor its command (as a
            probe the tick does not wait for) until it answers.

    Attributes:
        safe_sent: the motors whose safe command left (the transport reported it sent) when the
            block was last left; empty before, and when ``safe`` is None or nothing was commanded.
        safe_acknowledged: those of them that answered it (the others are named in a warning).
    """

    def __init__(
        self,
        transport: FrameLink,
        *,
        safe: str | None = "stop",
        safe_timeout_s: float = 0.25,
        max_in_flight: int = 64,
        name: str | None = None,
        min_reply_s: float | None = None,
        late_hold_s: float | None = None,
        stale_after_s: float | _Default | None = _DEFAULT,
        offline_after_misses: int = 3,
        offline_after_s: float | None = None,
        initial_timeout_s: float = 1.0,
        min_timeout_s: float = 0.005,
        max_timeout_s: float = 10.0,
        probe_interval_s: float = 0.1,
    ) -> None:
        if safe_timeout_s <= 0:
            raise ValueError(f"safe_timeout_s={safe_timeout_s} must be positive")
        if offline_after_misses < 1:
            raise ValueError(f"offline_after_misses={offline_after_misses} must be at least 1")
        if offline_after_s is not None and offline_after_s <= 0:
            raise ValueError(f"offline_after_s={offline_after_s} must be positive (or None)")
        if probe_interval_s <= 0:
            raise ValueError(f"probe_interval_s={probe_interval_s} must be positive")
        self.probe_interval_s = probe_interval_s
        self.offline_after_misses = offline_after_misses
        self.offline_after_s = offline_after_s
        self.transport = transport
        self.name = name or transport.name
        self.safe = safe
        self.safe_timeout_s = safe_timeout_s
        half_duplex = bool(getattr(transport, "half_duplex", False))
        if min_reply_s is None:
            bitrate = getattr(transport, "bitrate", None)
            # 47 bits: a standard frame with no data, the shortest there is (request and reply).
            min_reply_s = 2 * 47 / bitrate if isinstance(bitrate, int) and bitrate > 0 else 0.0
        self.scheduler = Scheduler(
            max_in_flight=max_in_flight,
            one_at_a_time=half_duplex,
            gap_s=float(getattr(transport, "gap_s", 0.0) or 0.0) if half_duplex else 0.0,
            min_reply_s=min_reply_s,
            late_hold_s=late_hold_s,
            stale_after_s=getattr(transport, "stale_after_s", None)
            if isinstance(stale_after_s, _Default)
            else stale_after_s,
            initial_timeout_s=initial_timeout_s,
            min_timeout_s=min_timeout_s,
            max_timeout_s=max_timeout_s,
        )
        self.motors: dict[tuple[str, int], Motor] = {}
        self._by_codec: dict[int, Motor] = {}
        self._commanded: dict[int, Motor] = {}
        self._by_frame: dict[int, Request] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._owns_transport = False
        # The Bus's one timer: a loop callback at the scheduler's next deadline (no task to cancel).
        self._timer: asyncio.TimerHandle | None = None
        self._subscribers: list[Callable[[Motor, Traffic, Reply], object]] = []
        self._status_listeners: list[Callable[[MotorStatus], object]] = []
        # The silence watchdog's timer, at the earliest moment an online motor can turn silent.
        self._silence: asyncio.TimerHandle | None = None
        self._silence_at = 0.0
        self._closing = False  # the block is being left: only the safe commands may still go out
        self.safe_sent: tuple[Motor, ...] = ()
        self.safe_acknowledged: tuple[Motor, ...] = ()
        self._warned: set[int] = set()  # motors (by codec id) whose undecodable reply was logged

    # ---- life cycle ----

    async def __aenter__(self) -> Self:
        self._loop = asyncio.get_running_loop()
        self._closing = False
        self.safe_sent = self.safe_acknowledged = ()
        if not self.transport.is_open:
            await self.transport.open()
            self._owns_transport = True
        self.transport.set_consumer(self._on_frames)
        self.transport.set_send_reporter(self._on_report)
        self.transport.add_listener(self._on_event)
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool | None:
        assert self._loop is not None
        self._closing = True
        try:
            # What is still queued would go out with the safe commands, or after them.
            self._fail(self.scheduler.fail_queued(self._closed_error(), self._loop.time()))
            with anyio.CancelScope(shield=True):
                await self._safe_stop()
        finally:
            self._fail(self.scheduler.fail_all(self._closed_error(), self._loop.time()))
            for timer in (self._timer, self._silence):
                if timer is not None:
                    timer.cancel()
            self._timer = self._silence = None
            for motor in self.motors.values():  # iterators over its frames end, not hang
                for watcher in list(motor._watchers):
                    watcher._end()
            self.transport.set_consumer(None)
            self.transport.set_send_reporter(None)
            with contextlib.suppress(ValueError):
                self.transport.remove_listener(self._on_event)
            if self._owns_transport:
                await self.transport.close()
        return None

    def _closed_error(self) -> TransportError:
        return TransportError(f"{self.name}: the Bus is closed (its block was left)")

    def _fail(self, requests: Iterable[Request]) -> None:
        for request in requests:
            self._by_frame.pop(id(request.frame), None)
            self._settle(request, request.error)

    async def _safe_stop(self) -> None:
        """Send the safe command to every commanded motor, again to each one that did not answer,
        until all answered or ``safe_timeout_s`` ended."""
        if self.safe is None or not self._commanded or not self.transport.is_open:
            return
        commands: dict[Motor, Command] = {}
        for motor in list(self._commanded.values()):
            with contextlib.suppress(ValueError):
                commands[motor] = motor.codec.safe_command(self.safe)
        attempts: dict[Motor, list[Request]] = {motor: [] for motor in commands}
        acknowledged: set[Motor] = set()

        async def stop(motor: Motor, command: Command) -> None:
            while True:
                request = self._submit(motor, command, timeout_s=None, retries=0, safe=True)
                attempts[motor].append(request)
                try:
                    await _awaitable(request.context)
                except MotorTimeout:
                    continue  # lost on its way there or back: it is safe to repeat
                except TransportError:
                    if not self.transport.is_open:
                        raise
                    await asyncio.sleep(self.scheduler.min_timeout_s)  # refused (a full queue): again
                    continue
                if request.key is not None:  # (a command with no reply cannot be acknowledged)
                    acknowledged.add(motor)
                return

        try:
            with anyio.move_on_after(self.safe_timeout_s):
                await asyncio.gather(*(stop(m, c) for m, c in commands.items()), return_exceptions=True)
        finally:
            self._abandon(r for sent in attempts.values() for r in sent)
            self.safe_sent = tuple(
                m for m, tried in attempts.items() if any(r.sent_at is not None for r in tried)
            )
            self.safe_acknowledged = tuple(m for m in commands if m in acknowledged)
            missing = [m for m in commands if m not in acknowledged]
            if missing:
                logger.warning(
                    "%s: the %s command was not acknowledged by %s within %g s",
                    self.name,
                    self.safe,
                    ", ".join(repr(m) for m in missing),
                    self.safe_timeout_s,
                )

    # ---- motors ----

    @overload
    def motor(self, family: Family[M], motor_id: int, **options: Any) -> M: ...

    @overload
    def motor(self, family: str, motor_id: int, **options: Any) -> NamedMotor: ...

    def motor(self, family: Family[Any] | str, motor_id: int, **options: Any) -> Motor:
        """The motor ``motor_id`` of ``family`` on this bus (bound once; the same object after).

        Given the family object (``from servobus.protocols import myactuator as ma``;
        ``bus.motor(ma.FAMILY, 3)``), the motor is typed: each command is a method a type checker
        knows, returning the command's reply type. Given the name, the methods are the same but
        untyped.

        Args:
            family: the Family, or its name: ``"myactuator"``, ``"lk"``, ``"hollow"`` or a plug-in's.
            motor_id: the motor's id.
            **options: ``revision``, ``model``, ``link`` and family options, as ``Family.bind``.

        Raises:
            ValueError: a bad id or option, or a motor whose identifiers collide with one already on
                this bus (both named).
        """
        found = get_family(family) if isinstance(family, str) else family
        key = (found.name, motor_id)
        if key in self.motors:
            return self.motors[key]
        codec = found.bind(motor_id, **options)
        self.scheduler.add(codec)
        motor = _motor_class(found)(self, codec, found.methods())
        self.motors[key] = motor
        self._by_codec[id(codec)] = motor
        return motor

    @property
    def commanded(self) -> tuple[Motor, ...]:
        """The motors this Bus sent a command that is not a read: the safe command goes to them."""
        return tuple(self._commanded.values())

    def subscribe(self, callback: Callable[[Motor, Traffic, Reply], object]) -> None:
        """Call ``callback(motor, traffic, reply)`` for every decoded frame of a motor on this bus.

        Raises:
            TypeError: ``callback`` is a coroutine function (it is called on the receive path and
                never awaited: wrap it, e.g. in ``lambda *a: loop.create_task(f(*a))``).
        """
        _refuse_coroutine(callback, "subscribe")
        self._subscribers.append(callback)

    def subscribe_status(self, callback: Callable[[MotorStatus], object]) -> None:
        """Call ``callback(status)`` whenever the watchdog marks a motor offline or online.

        Raises:
            TypeError: ``callback`` is a coroutine function (see :meth:`subscribe`).
        """
        _refuse_coroutine(callback, "subscribe_status")
        self._status_listeners.append(callback)

    def ticks(self, hz: float, *, spin_s: float = 0.0012, count: int | None = None) -> AsyncIterator[Tick]:
        """A fixed-rate pacer: :func:`servobus.ticks.ticks` (one pacer may drive several buses)."""
        return ticks(hz, spin_s=spin_s, count=count)

    # ---- requests ----

    async def request(
        self, motor: Motor, command: Command[R], *, timeout_s: float | None = None, retries: int = 0
    ) -> R:
        """:meth:`Motor.request`."""
        if asyncio.get_running_loop() is not self._loop:
            self._not_our_loop()
        request = self._submit(motor, command, timeout_s=timeout_s, retries=retries)
        try:
            reply: Reply | None = await request.context
        except asyncio.CancelledError:
            self._abandon((request,))
            raise
        return cast(R, reply)

    def _not_our_loop(self) -> NoReturn:
        """A call from a coroutine on another event loop than the one the Bus was entered in (or
        outside the block): refused at once, before anything is queued. (Let through, its future,
        made on the Bus's loop, could not be awaited here, and asyncio would log its never-retrieved
        exception as an ERROR traceback when the block is left.)

        Raises:
            RuntimeError: always.
        """
        if self._loop is None:
            raise RuntimeError(f"{self.name}: use the Bus inside 'async with'")
        raise RuntimeError(
            f"{self.name}: this Bus runs on another event loop (the one its 'async with' entered); "
            "a Bus is used from its own loop only: use servobus.sync.Bus from other threads, or "
            "asyncio.run_coroutine_threadsafe(..., loop) to hand a call to the Bus's loop"
        )

    def _submit(
        self, motor: Motor, command: Command, *, timeout_s: float | None, retries: int, safe: bool = False
    ) -> Request:
        request = self._prepare(motor, command, timeout_s=timeout_s, retries=retries, safe=safe)
        self._enqueue(motor, request)
        self._pump()
        return request

    def _prepare(
        self,
        motor: Motor,
        command: Command,
        *,
        timeout_s: float | None,
        retries: int,
        safe: bool = False,
        context: asyncio.Future[Any] | _Slot | None = None,
    ) -> Request:
        """The request for ``command``, encoded (ValueError here, before anything is queued), settled
        into ``context`` (default: a future of its own).

        Raises:
            TransportError: the block is being left (only the safe commands go out then), or was.
        """
        if self._loop is None:
            raise RuntimeError(f"{self.name}: use the Bus inside 'async with'")
        if self._closing and not safe:
            raise self._closed_error()
        request = self.scheduler.request(
            motor.codec,
            command,
            timeout_s=timeout_s,
            retries=retries,
            context=self._loop.create_future() if context is None else context,
        )
        if request.key is None and motor.codec.streams and motor.codec.retry_safe(command):
            streams = ", ".join(f"0x{code:02X}" for code in sorted(motor.codec.streams))
            raise MotorStreaming(
                f"{motor!r} streams {streams} and answers no {type(command).__name__} until the "
                "stream is off (a read of the streamed command is answered by its next frame)"
            )
        return request

    def _enqueue(self, motor: Motor, request: Request) -> None:
        if not motor.codec.retry_safe(request.command):
            self._commanded[id(motor.codec)] = motor
            request.queued_at = self._loop.time()  # type: ignore[union-attr]
        motor.codec.note_sent(request.command)
        self.scheduler.submit(request)

    def _abandon(self, requests: Iterable[Request]) -> None:
        """The caller stopped waiting (cancelled): unresolved requests are cancelled; a reply that
        still comes is counted late."""
        assert self._loop is not None
        now = self._loop.time()
        for request in requests:
            request.context.cancel()  # (no effect on a resolved one)
            self.scheduler.cancel(request, now)  # (nor here)
            self._by_frame.pop(id(request.frame), None)
        self._pump()

    async def cycle(
        self, items: Iterable[tuple[Motor, Command]], *, timeout_s: float | None = None
    ) -> list[Result]:
        """One control tick: send every command (pipelined, paced), await every reply.

        A tick never waits on a motor that is not answering: the command of a motor the watchdog
        marks offline is not sent (MotorOffline; every ``probe_interval_s`` it is sent as a probe
        the tick does not wait for, until the motor answers), nor is one whose previous reply with
        the same key is still due (MotorBusy: that late reply could answer it).

        Returns:
            One result per item, in order: the reply (None for commands without one), or the
            exception that ended it (MotorTimeout and its MotorOffline and MotorBusy,
            MotorStreaming, ProtocolError, TransportError) as a value.

        Raises:
            ValueError: a command is refused by its codec (nothing of the tick is sent then).
            RuntimeError: called from another event loop than the Bus's (servobus.sync.Bus is for threads).
        """
        # Every command is encoded (and checked) before the first one is queued; then one pump.
        if asyncio.get_running_loop() is not self._loop:
            self._not_our_loop()
        items = list(items)
        if not items:
            return []
        loop = self._loop
        assert loop is not None  # (the loop check above)
        tick = _Tick(loop.create_future(), len(items))
        prepared = []
        skipped: list[tuple[_Slot, Motor, str, BaseException]] = []
        now = loop.time()
        scheduler = self.scheduler
        busy = None if scheduler.quiet else scheduler.busy  # (None, the common case: nothing waits)
        for i, (m, c) in enumerate(items):
            slot = _Slot(tick, i)
            try:
                request = self._prepare(m, c, timeout_s=timeout_s, retries=0, context=slot)
            except MotorStreaming as exc:
                skipped.append((slot, m, "skipped_streaming", exc))
                continue
            if m.online is False:
                why = f"{m!r} is offline ({m._misses} replies missed): the tick does not wait for it"
                if now >= m._probe_at and (busy is None or not busy(request.key, now)):  # a probe
                    m._probe_at = now + self.probe_interval_s
                    request.context = _detached(loop)
                    prepared.append((m, request))
                    skipped.append((slot, m, "probes", MotorOffline(why)))
                else:
                    skipped.append((slot, m, "skipped_offline", MotorOffline(why)))
            elif busy is not None and busy(request.key, now):
                why = f"{m!r}: the reply to its last {type(c).__name__} is still due: not sent this tick"
                skipped.append((slot, m, "skipped_busy", MotorBusy(why)))
            else:
                prepared.append((m, request))
        for motor, request in prepared:
            self._enqueue(motor, request)
        for slot, motor, counter, error in skipped:
            scheduler.motor_counts[id(motor.codec)][counter] += 1
            slot.set_result(error)
        self._pump()
        try:
            return await tick.future
        except BaseException:
            self._abandon(r for _, r in prepared if r.context.__class__ is _Slot)  # (not the probes)
            raise

    async def broadcast(
        self, command: Command, motors: Sequence[Motor], *, timeout_s: float | None = None
    ) -> dict[int, Result]:
        """One frame for several motors of one family; each motor's reply or timeout, by motor id.

        The frame waits while a request with the key of one of its replies is in flight, or held for
        a late reply (``late_hold_s``), as a request would; then it goes out at once, past the queue.

        Raises:
            ValueError: the family has no broadcast form for ``command``, or mixed families.
            RuntimeError: called from another event loop than the Bus's (servobus.sync.Bus is for threads).
        """
        if asyncio.get_running_loop() is not self._loop:
            self._not_our_loop()
        families = {m.codec.family for m in motors}
        if len(families) != 1:
            raise ValueError(f"a broadcast goes to motors of one family, not {sorted(families)}")
        plan = get_family(families.pop()).broadcast(command, [m.codec for m in motors])
        assert self._loop is not None
        keys = list(plan.replies.values())
        while True:
            held_until, flying = self.scheduler.blocking(keys, self._loop.time())
            if flying:
                timeout = None if held_until is None else max(0.0, held_until - self._loop.time())
                await asyncio.wait({_awaitable(r.context) for r in flying}, timeout=timeout)
            elif held_until is not None:
                await asyncio.sleep(max(0.0, held_until - self._loop.time()))
            else:
                break
        if self._closing:  # (the block was left while it waited)
            raise self._closed_error()
        by_id = {m.motor_id: m for m in motors}
        timeout = timeout_s if timeout_s is not None else max(m.codec.timeout_s(command) for m in motors)
        expected = {
            motor_id: self._expect(by_id[motor_id], command, key, timeout)
            for motor_id, key in plan.replies.items()
        }
        for motor in motors:
            if not motor.codec.retry_safe(command):
                self._commanded[id(motor.codec)] = motor
        try:
            self.transport.send(plan.frame)
            results = await asyncio.gather(*(r.context for r in expected.values()), return_exceptions=True)
        except BaseException:
            self._abandon(expected.values())
            raise
        return dict(zip(expected, results, strict=True))

    def _expect(self, motor: Motor, command: Command, key: Hashable, timeout_s: float) -> Request:
        """A request whose frame is sent by someone else (a broadcast): it only awaits ``key``."""
        assert self._loop is not None
        future: asyncio.Future[Any] = self._loop.create_future()
        # (its frame is never sent: the request goes into flight directly, past the queue)
        request = Request(motor.codec, command, Frame(arbitration_id=0), key, timeout_s, context=future)
        self.scheduler.expect(request, self._loop.time())
        self._kick()
        return request

    # ---- the engine ----

    def _pump(self) -> None:
        """Hand the requests the scheduler lets go to the transport."""
        assert self._loop is not None
        scheduler = self.scheduler
        for request in scheduler.next_to_send(self._loop.time()):
            self._hand_over(request)
        if scheduler._stale:
            for request in scheduler.take_stale():
                self._settle(
                    request,
                    TransportError(
                        f"{self.name}: {request.describe()} not sent (stale: waited its turn "
                        f"longer than stale_after_s={scheduler.stale_after_s:g} s)"
                    ),
                )
        self._kick()

    def _hand_over(self, request: Request) -> None:
        self._by_frame[id(request.frame)] = request
        try:
            self.transport.send(request.frame)
        except Exception as exc:  # a full queue, a lost transport: this request fails, nothing else
            self._by_frame.pop(id(request.frame), None)
            self.scheduler.not_sent(request, type(exc).__name__, self._loop.time())  # type: ignore[union-attr]
            self._settle(request, exc)

    def _on_report(self, frame: Frame, sent_at: float | None, reason: str | None) -> None:
        request = self._by_frame.pop(id(frame), None)
        if request is None:
            return
        assert self._loop is not None
        if reason is not None:
            self.scheduler.not_sent(request, reason, self._loop.time())
            self._settle(request, TransportError(f"{self.name}: {request.describe()} not sent ({reason})"))
        else:
            early = self.scheduler.sent(request, sent_at if sent_at is not None else self._loop.time())
            if early is not None and early.reply is not None:  # its reply came before this report
                self._deliver(early, self._loop.time())
            elif early is not None and early.request is not None:  # ... and did not decode
                self._undecodable(early)
            if request.state is _SENT:
                timer = self._timer
                if timer is not None and request.deadline is not None and timer.when() <= request.deadline:
                    return  # the timer already fires first (the common case: one per burst)
                self._kick()
                return
            if request.state is _REPLIED:  # nothing to wait for, or the early reply
                self._settle(request, None)
        self._pump()  # it left the wire's count: the next may go

    def _on_frames(self, frames: list[Frame]) -> None:
        assert self._loop is not None
        now = self._loop.time()
        receive = self.scheduler.receive
        for frame in frames:
            got = receive(frame, now)
            if got.codec is not None:
                if got.reply is not None:
                    self._deliver(got, now)
                elif got.request is not None:  # an undecodable reply: its request fails with why
                    self._undecodable(got)
        self._pump()

    def _undecodable(self, got: Received) -> None:
        request = got.request
        assert request is not None and got.codec is not None
        if id(got.codec) not in self._warned:  # once per motor: a wrong revision repeats every frame
            self._warned.add(id(got.codec))
            logger.warning(
                "%s: %s: the reply does not decode (%s); check the motor's revision and model (bound as %s)",
                self.name,
                request.describe(),
                request.error,
                got.codec.revision.name,
            )
        self._settle(request, request.error)

    def _deliver(self, got: Received, now: float) -> None:
        """A decoded frame of one of our motors: its state, watchdog, watchers, and its request."""
        motor = self._by_codec.get(id(got.codec))
        reply = got.reply
        assert reply is not None
        if motor is not None:
            motor.state = reply
            motor.last_seen = got.frame.timestamp or now
            motor._misses = 0
            if motor.online is not True:
                self._set_status(motor, True, now, "answered")
            if reply.FAULTS is not None:
                self._note_faults(motor, getattr(reply, reply.FAULTS))
            if motor._ending and got.request is None and got.traffic is not Traffic.STREAM:
                self._stream_goes_on(motor, got.frame, now)
            for watcher in motor._watchers:
                watcher._push(got.traffic, reply)
            for callback in self._subscribers:
                try:
                    callback(motor, got.traffic, reply)
                except Exception:  # a subscriber's bug must not stop the reader
                    logger.exception("%s: subscriber %r failed", self.name, callback)
        if got.request is not None:
            self._settle(got.request, None)

    def _stream_goes_on(self, motor: Motor, frame: Frame, now: float) -> None:
        """A frame of a stream that was switched off came: if later than a reply to the "off"
        could take, the "off" was lost; it is sent again. Once the stream was quiet for a few of its
        intervals it ended: a frame with its command byte then is another (a read's late reply)."""
        if not frame.data or self._closing or self._loop is None:
            return
        code = frame.data[0]
        ending = motor._ending.get(code)
        if ending is None:
            return
        off, sent_at, interval_s = ending
        at = frame.timestamp or now
        reach_s = self.scheduler.motor_timeout_s(motor.codec)
        if at < sent_at + reach_s:
            return  # it may have left the motor before the "off" arrived
        if at > sent_at + reach_s + 4 * interval_s:
            del motor._ending[code]  # quiet since: the stream ended
            return
        motor._ending[code] = (off, now, interval_s)
        self.scheduler.motor_counts[id(motor.codec)]["stream_off_resent"] += 1
        logger.info("%s: %r still streams 0x%02X: switching it off again", self.name, motor, code)
        try:
            request = self._prepare(motor, off, timeout_s=None, retries=0, context=_detached(self._loop))
        except (ValueError, TransportError):  # (never out of the reader)
            logger.exception("%s: %r: the stream's 'off' could not be sent again", self.name, motor)
            return
        self._enqueue(motor, request)

    def _now(self) -> float:
        return self._loop.time() if self._loop is not None else 0.0

    def _on_event(self, event: TransportEvent) -> None:
        if isinstance(event, StateChanged) and event.state is TransportState.LOST and self._loop is not None:
            error = TransportError(f"{self.name}: transport lost ({event.cause})")
            for request in self.scheduler.fail_all(error, self._loop.time()):
                self._by_frame.pop(id(request.frame), None)
                self._settle(request, error)

    def _settle(self, request: Request, error: BaseException | None) -> None:
        future: asyncio.Future[Any] | _Slot = request.context
        if future is None or future.done():
            return
        if error is not None:
            future.set_exception(error)
        elif request.state is _REPLIED:
            future.set_result(request.reply)
        elif request.state is _TIMED_OUT:
            future.set_exception(
                MotorTimeout(
                    f"{request.describe()}: no reply within {request.timeout_s:g} s"
                    + (f" ({request.attempts} attempts)" if request.attempts > 1 else "")
                )
            )
        else:
            future.set_exception(TransportError(f"{self.name}: {request.describe()} {request.state.value}"))

    def _kick(self) -> None:
        """Re-arm the timer at the scheduler's next deadline (time-outs, a half-duplex line's rest)."""
        loop = self._loop
        if loop is None:
            return
        deadline = self.scheduler.next_deadline()
        timer = self._timer
        if timer is not None:
            if deadline is not None and timer.when() == deadline:
                return
            timer.cancel()
            self._timer = None
        if deadline is not None:
            self._timer = loop.call_at(deadline, self._on_timer)

    def _on_timer(self) -> None:
        assert self._loop is not None
        self._timer = None
        now = self._loop.time()
        for request in self.scheduler.expire(now):
            self._by_frame.pop(id(request.frame), None)
            self._missed(request, now)
            self._settle(request, None)
        self._pump()

    def _note_faults(self, motor: Motor, flags: Any) -> None:
        if not flags:
            motor.fault = None
        elif motor.fault is None or motor.fault.flags != flags:
            motor.fault = MotorFault(f"{motor!r} reports {flags!r}", flags=flags, motor_id=motor.motor_id)
            logger.warning("%s: %s", self.name, motor.fault)

    # ---- the host-side watchdog ----

    def _missed(self, request: Request, now: float) -> None:
        motor = self._by_codec.get(id(request.codec))
        if motor is None:
            return
        motor._misses += 1
        if motor._misses >= self.offline_after_misses and motor.online is not False:
            self._set_status(motor, False, now, f"{motor._misses} replies missed")

    def _set_status(self, motor: Motor, online: bool, at: float, reason: str) -> None:
        motor.online = online
        status = MotorStatus(motor, online, at, reason)
        (logger.info if online else logger.warning)(
            "%s: %r %s (%s)", self.name, motor, "online" if online else "offline", reason
        )
        for callback in self._status_listeners:
            try:
                callback(status)
            except Exception:  # a listener's bug must not stop the reader
                logger.exception("%s: status listener %r failed", self.name, callback)
        if online:
            self._arm_silence()

    def _arm_silence(self) -> None:
        """Time the silence check for the online motor heard from longest ago (if none is armed)."""
        if self.offline_after_s is None or self._silence is not None or self._loop is None:
            return
        heard = [m.last_seen for m in self.motors.values() if m.online and m.last_seen is not None]
        if heard:
            self._silence_at = min(heard) + self.offline_after_s
            self._silence = self._loop.call_at(self._silence_at, self._on_silence)

    def _on_silence(self) -> None:
        self._silence = None
        assert self.offline_after_s is not None and self._loop is not None
        silent = self.offline_after_s
        for motor in self.motors.values():
            if motor.online and motor.last_seen is not None and motor.last_seen + silent <= self._silence_at:
                self._set_status(motor, False, self._loop.time(), f"silent for {silent:g} s")
        self._arm_silence()

    # ---- numbers ----

    def stats(self) -> dict[str, int]:
        """The scheduler's counters: requests, replies, timeouts, retries and every kind of frame."""
        return dict(self.scheduler.counts)

    def metrics(self) -> Metrics:
        """This bus's counters, request-to-reply latency and the line's load (from the transport)."""
        stats = getattr(self.transport, "stats", None)
        load = getattr(stats(), "bus_load_pct", None) if callable(stats) else None
        return Metrics.of(self.scheduler.counts, self.scheduler.latency().snapshot(), load)


if TYPE_CHECKING:

    class NamedMotor(Motor):
        """What a type checker knows of a motor bound by its family's name: its methods exist,
        untyped (``bus.motor(FAMILY, id)`` gives the typed ones)."""

        def __getattr__(self, name: str) -> Callable[..., Awaitable[Any]]: ...

else:
    NamedMotor = Motor


def _motor_class(family: Family[Any]) -> type[Motor]:
    """The family's typed Motor class (Motor itself where it has none), its methods documented
    with their commands' docstrings (the generated file keeps one line a method)."""
    if family.motor is None:
        return Motor
    cls: type[Motor] = family.motor()
    if "_documented" not in cls.__dict__:
        for name, command in family.methods().items():
            if name in Motor.__dict__:
                raise TypeError(f"{family.name}: command {command.__name__} would hide Motor.{name}")
            method = cls.__dict__.get(name)
            if method is not None and method.__doc__ is None:
                method.__doc__ = f"Send {command.__name__} and await its reply.\n\n{command.__doc__ or ''}"
        cls._documented = True  # type: ignore[attr-defined]
    return cls


def _positional_fields(
    cls: type[Command], name: str, args: tuple[Any, ...], fields: dict[str, Any]
) -> dict[str, Any]:
    """``args`` given to ``motor.<name>(...)`` as keyword fields of ``cls``, in declaration order."""
    names = [f.name for f in dataclasses.fields(cls) if f.init]  # type: ignore[arg-type]
    if len(args) > len(names):
        listed = ", ".join(names) or "none"
        raise TypeError(f"{name}() takes {len(names)} positional field(s) ({listed}), {len(args)} given")
    for field_name, value in zip(names, args, strict=False):
        if field_name in fields:
            raise TypeError(f"{name}() got {field_name!r} both by position and by keyword")
        fields[field_name] = value
    return fields


def _refuse_coroutine(callback: Callable[..., object], method: str) -> None:
    if inspect.iscoroutinefunction(callback) or inspect.iscoroutinefunction(type(callback).__call__):
        raise TypeError(
            f"{method}() takes a plain function: {callback!r} is async and would never be awaited "
            "(call it through loop.create_task() from a plain one)"
        )
