"""The Bus: one physical bus, its motors, and every request's life on it, on asyncio or trio (anyio).

``async with Bus(link) as bus`` takes a link (CAN through python-can, the native SLCAN link, an
RS485 line, the in-process simulator, or any :class:`~servobus.transports.contract.FrameLink`), and
then:

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
* A request's deadline starts when the link reports its frame sent; a link whose rules say it does
  not report starts it at hand-over, and one that does but stays silent about a frame still has it
  time out (:func:`report_within_s` after hand-over, plus its timeout).
* Leaving the ``async with`` block, normally, by an exception or by cancellation, sends the safe
  command (stop by default) to every motor this Bus commanded, shielded, again and again until each
  motor acknowledged it or ``safe_timeout_s`` ended.
  From then on nothing else is sent: requests not yet sent, and any made later (by a task the block
  did not wait for), fail with TransportError, and so does every request still waiting for a reply
  once the block is left.
* SIGTERM, by default, does what Ctrl-C does: while a Bus is open in the main thread and SIGTERM has
  Python's default disposition, the signal cancels the block, the safe stop goes out and the process
  exits with status 143 (``sigterm=False``: not this Bus; :mod:`servobus.signals`).

The Bus is a thin router between its parts (the walk of one tick is in :mod:`servobus.bus`): the
sans-IO :class:`~servobus.scheduler.Scheduler` matches, paces and times out; the
:class:`~servobus.bus.engine.Engine` is the one object that talks to it and to the link, and owns the
Bus's one timer task; the :class:`~servobus.bus.motor.Registry` holds one record per motor; the
:class:`~servobus.bus.watchdog.Watchdog` says which motors are offline; ``servobus.bus.tick``
gathers a cycle's outcomes; ``servobus.bus.safety`` stops the motors. The Bus owns a task group
(entered with its block, left after the safe stop) that runs the timer: nothing outlives the block,
and an error of that task is raised from it. No global state but SIGTERM's default handler (one for
the process, only where the program set none): a Bus lives inside the user's loop and task groups.
"""

from __future__ import annotations

import logging
import signal
import sys
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable, Sequence
from types import TracebackType
from typing import Any, NoReturn, Self, TypeVar, cast, overload

import anyio

from servobus import runtime as _runtime
from servobus.bus.broadcast import broadcast as _broadcast
from servobus.bus.engine import Engine
from servobus.bus.motor import (
    Motor,
    MotorFrames,
    NamedMotor,
    Registry,
    command_classes,
    motor_class,
    refuse_coroutine,
)
from servobus.bus.restarts import Restarts
from servobus.bus.safety import safe_stop
from servobus.bus.tick import Result, Slot
from servobus.bus.watchdog import MotorStatus, Watchdog
from servobus.limits import LimitBook, Limits
from servobus.metrics import Metrics
from servobus.protocols import Command, Family, Reply, get_family
from servobus.scheduler import Scheduler, Traffic
from servobus.signals import SigtermTaken, take_sigterm
from servobus.ticks import Tick as PacerTick
from servobus.ticks import ticks
from servobus.transports.contract import FrameLink, LineRules

__all__ = ["Bus", "FrameLink", "Motor", "MotorFrames", "MotorStatus", "command_classes"]

R = TypeVar("R")
M = TypeVar("M", bound=Motor)

logger = logging.getLogger("servobus.bus")

#: What a send report may take beyond the frames ahead of it: a reader or writer thread's hop and
#: a loaded loop (a correctly reporting link's report comes well within it).
HOST_SLACK_S = 0.1


def report_within_s(rules: LineRules, in_flight: int) -> float:
    """The longest a correctly reporting link may take to report a frame handed over: the frames
    ahead of it (``in_flight``, each at most 1200 bits: a CAN FD frame of 64 bytes at the nominal
    rate, or a long serial frame), the line's rests, the link's own staleness limit (it reports a
    frame stale by then), and :data:`HOST_SLACK_S`."""
    frame_s = 1200 / rules.bitrate if rules.bitrate else 0.002
    rests_s = (rules.gap_s + rules.turnaround_s) * (in_flight + 1) if rules.half_duplex else 0.0
    return (rules.stale_after_s or 0.0) + (in_flight + 1) * frame_s + rests_s + HOST_SLACK_S


def _scheduler(
    rules: LineRules,
    name: str,
    *,
    max_in_flight: int,
    min_reply_s: float | None,
    late_hold_s: float | None,
    stale_after_s: float | _Default | None,
    timeouts_s: tuple[float, float, float],
) -> Scheduler:
    """The Bus's scheduler, for a line with ``rules`` (the defaults the Bus's arguments say)."""
    if min_reply_s is None:  # 47 bits: a standard frame with no data, the shortest there is
        min_reply_s = 2 * 47 / rules.bitrate if rules.bitrate else 0.0
    in_flight = 1 if rules.half_duplex else max_in_flight
    initial_timeout_s, min_timeout_s, max_timeout_s = timeouts_s
    return Scheduler(
        max_in_flight=max_in_flight,
        one_at_a_time=rules.half_duplex,
        gap_s=rules.gap_s if rules.half_duplex else 0.0,
        min_reply_s=min_reply_s,
        late_hold_s=late_hold_s,
        stale_after_s=rules.stale_after_s if isinstance(stale_after_s, _Default) else stale_after_s,
        initial_timeout_s=initial_timeout_s,
        min_timeout_s=min_timeout_s,
        max_timeout_s=max_timeout_s,
        report_within_s=report_within_s(rules, in_flight) if rules.reports_sends else None,
        exact_order=rules.exact_times,
        name=name,
    )


class _Default:
    """The type of an argument whose default comes from elsewhere (the link's rules)."""


_DEFAULT = _Default()


def _elsewhere() -> bool:
    return False


def _loop_check(runtime: _runtime.Runtime) -> Callable[[], bool]:
    """True when called from ``runtime``'s loop: on asyncio one C call (the running loop, compared),
    so a cycle's path enters no other module; elsewhere the runtime's own check."""
    loop = getattr(runtime, "loop", None)
    asyncio = sys.modules.get("asyncio")
    if runtime.name != "asyncio" or loop is None or asyncio is None:
        return runtime.is_current
    running = asyncio.get_running_loop

    def is_current() -> bool:
        try:
            return running() is loop
        except RuntimeError:  # no asyncio loop runs here (trio's, or none)
            return False

    return is_current


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
            shortest frames at the link's bit rate, where it has one): a frame with the reply's
            key that arrives sooner is not taken for it.
        stale_after_s: a command (not a read) that waited longer than this for its turn, on a stalled
            or slow half-duplex line, fails with TransportError instead of reaching the motor late
            (default: the link's ``rules.stale_after_s``; None for no limit).
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
        sigterm: SIGTERM leaves the block as Ctrl-C does (safe stop, then exit status 143) while
            the Bus is open in the main thread and SIGTERM has Python's default disposition; False:
            this Bus takes no signal (:mod:`servobus.signals`).
        limits: its motors' host-side limits (:mod:`servobus.limits`): a ``LimitBook`` by motor id
            (``servobus.limits.load(path)``) or one ``Limits`` for all; each motor bound gets its own
            ``Motor.limits``, which every command meets before its frame leaves.

    Attributes:
        safe_sent: the motors whose safe command left (the link reported it sent) when the
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
        sigterm: bool = True,
        limits: LimitBook | Limits | None = None,
    ) -> None:
        if safe_timeout_s <= 0:
            raise ValueError(f"safe_timeout_s={safe_timeout_s} must be positive")
        if probe_interval_s <= 0:
            raise ValueError(f"probe_interval_s={probe_interval_s} must be positive")
        self.probe_interval_s = probe_interval_s
        self.limits = LimitBook(limits) if isinstance(limits, Limits) else limits
        self.sigterm = sigterm
        self._sigterm: SigtermTaken | None = None  # this block's share of SIGTERM's default handler
        self.transport = transport
        self.name = name or transport.name
        self.safe = safe
        self.safe_timeout_s = safe_timeout_s
        self.registry = Registry()
        self.motors: dict[tuple[str, int], Motor] = self.registry.named
        self._watchdog = Watchdog(
            self.name,
            self.motors.values,
            offline_after_misses=offline_after_misses,
            offline_after_s=offline_after_s,
        )
        self.scheduler = _scheduler(
            transport.rules,
            self.name,
            max_in_flight=max_in_flight,
            min_reply_s=min_reply_s,
            late_hold_s=late_hold_s,
            stale_after_s=stale_after_s,
            timeouts_s=(initial_timeout_s, min_timeout_s, max_timeout_s),
        )
        self._subscribers: list[Callable[[Motor, Traffic, Reply], object]] = []
        #: the one object that talks to the scheduler and the link (servobus.bus.engine)
        self.engine = Engine(
            self.name, self.scheduler, transport, self._watchdog, self.registry, self._subscribers
        )
        restarts = Restarts(self.engine, self._spawn)
        self._watchdog.listeners.append(restarts.on_status)  # (first: before the users')
        self._is_current: Callable[[], bool] = _elsewhere
        self._group: anyio.abc.TaskGroup | None = None
        self.safe_sent: tuple[Motor, ...] = ()
        self.safe_acknowledged: tuple[Motor, ...] = ()

    @property
    def offline_after_misses(self) -> int:
        """Replies missed in a row after which a motor is marked offline."""
        return self._watchdog.offline_after_misses

    @property
    def offline_after_s(self) -> float | None:
        """Silence after which a motor that answered before is marked offline (None: never)."""
        return self._watchdog.offline_after_s

    async def __aenter__(self) -> Self:
        runtime = _runtime.current()
        self._is_current = _loop_check(runtime)
        self.safe_sent = self.safe_acknowledged = ()
        self._group = await _start(self.engine, runtime)
        if self.sigterm:  # (last: the block's scope is the innermost, left first)
            self._sigterm = _take_sigterm(runtime)
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool | None:
        taken, self._sigterm = self._sigterm, None
        if taken is None:
            return await self._close(exc_type, exc, tb)
        return await _close_taken(taken, self._close, exc_type, exc, tb)

    async def _close(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool | None:
        """Leave the block: the safe stop, then the Bus's task group (``exc``: how the block ended)."""
        engine, group = self.engine, self._group
        self._group = None
        suppress: bool | None = None
        try:
            engine.close()  # (what is still queued would go out with the safe commands, or after them)
            with anyio.CancelScope(shield=True):
                await safe_stop(self)
        finally:
            engine.detach(engine.closed_error())
            _stop(engine)
            if group is not None:
                suppress = await _leave(group, exc_type, exc, tb)
        return suppress

    def _spawn(self, fn: Callable[..., Any], *args: Any) -> bool:
        """Run ``fn(*args)`` in a task of the Bus's task group; False when it has none (not open)."""
        if self._group is None:
            return False
        self._group.start_soon(fn, *args)
        return True

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
        motor = self.registry.add(key, motor_class(found), self, codec, found.methods())
        motor.limits = None if self.limits is None else self.limits.of(motor_id)  # (its own: settable)
        return motor

    @property
    def commanded(self) -> tuple[Motor, ...]:
        """The motors this Bus sent a command that is not a read: the safe command goes to them."""
        return self.registry.commanded()

    def subscribe(self, callback: Callable[[Motor, Traffic, Reply], object]) -> None:
        """Call ``callback(motor, traffic, reply)`` for every decoded frame of a motor on this bus.

        Raises:
            TypeError: ``callback`` is a coroutine function (it is called on the receive path and
                never awaited: wrap it in a plain function that hands it to a task group).
        """
        refuse_coroutine(callback, "subscribe")
        self._subscribers.append(callback)

    def subscribe_status(self, callback: Callable[[MotorStatus], object]) -> None:
        """Call ``callback(status)`` whenever the watchdog marks a motor offline or online.

        Raises:
            TypeError: ``callback`` is a coroutine function (see :meth:`subscribe`).
        """
        refuse_coroutine(callback, "subscribe_status")
        self._watchdog.listeners.append(callback)

    def ticks(
        self, hz: float, *, spin_s: float = 0.0012, count: int | None = None
    ) -> AsyncIterator[PacerTick]:
        """A fixed-rate pacer: :func:`servobus.ticks.ticks` (one pacer may drive several buses)."""
        return ticks(hz, spin_s=spin_s, count=count)

    async def request(
        self, motor: Motor, command: Command[R], *, timeout_s: float | None = None, retries: int = 0
    ) -> R:
        """:meth:`Motor.request`."""
        if not self._is_current():
            _not_our_loop(self.name, self.engine.runtime is not None)
        request = self.engine.submit(motor, command, timeout_s, retries)
        try:
            reply: Reply | None = await request.context
        except BaseException:  # cancelled or interrupted: given up, not left in flight (a no-op if it ended)
            self.engine.abandon((request,))
            raise
        return cast(R, reply)

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
        if not self._is_current():
            _not_our_loop(self.name, self.engine.runtime is not None)
        items = list(items)
        if not items:
            return []
        tick, queued = self.engine.cycle(items, timeout_s, self.probe_interval_s)
        try:
            return await tick.future
        except BaseException:
            self.engine.abandon(r for r in queued if r.context.__class__ is Slot)  # (not probes)
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
        if not self._is_current():
            _not_our_loop(self.name, self.engine.runtime is not None)
        return await _broadcast(self.engine, command, motors, timeout_s)

    def time(self) -> float:
        """The Bus's clock: its loop's (0.0 before the block is entered)."""
        return self.engine.time()

    def stats(self) -> dict[str, int]:
        """The scheduler's counters: requests, replies, timeouts, retries and every kind of frame."""
        return dict(self.scheduler.counts)

    def metrics(self) -> Metrics:
        """This bus's counters, request-to-reply latency and the line's load (from the link)."""
        load = self.transport.stats().bus_load_pct
        return Metrics.of(self.scheduler.counts, self.scheduler.latency().snapshot(), load)


async def _start(engine: Engine, runtime: _runtime.Runtime) -> anyio.abc.TaskGroup:
    """The Bus's task group, entered, with the link open (by a task of it, unless it was) and the
    engine's timer running in it; left again if that fails."""
    group = anyio.create_task_group()
    await group.__aenter__()
    try:
        if not engine.link.is_open:  # opened (and closed) by a task of the Bus's
            await engine.keeper.open(group)
        engine.attach(runtime)
        await group.start(engine.timer.run)
    except BaseException as exc:
        _stop(engine, abort=True)
        await _leave(group, type(exc), exc, exc.__traceback__)
        raise
    return group


def _stop(engine: Engine, abort: bool = False) -> None:
    """End the timer task and release the link (the Bus's task group is being left); ``abort``: an
    opening of the link still under way is cancelled (entering the Bus failed, or was cancelled)."""
    engine.timer.stop()
    engine.keeper.release()
    if abort:
        engine.keeper.cancel()


def _take_sigterm(runtime: _runtime.Runtime) -> SigtermTaken | None:
    """This block's share of SIGTERM's default handler: a cancel scope, entered, that the signal
    cancels (None: the signal is not the Bus's to take)."""
    scope = anyio.CancelScope()
    scope.__enter__()
    taken = take_sigterm(scope, runtime.call_soon_threadsafe)
    if taken is None:
        scope.__exit__(None, None, None)
    return taken


async def _close_taken(
    taken: SigtermTaken,
    close: Callable[..., Awaitable[bool | None]],
    exc_type: type[BaseException] | None,
    exc: BaseException | None,
    tb: TracebackType | None,
) -> bool | None:
    """Leave a block that took SIGTERM: its scope, then ``close`` (the safe stop...); SystemExit(143)
    after it when the signal came. SIGTERM's handler is let go after the safe stop: a second SIGTERM
    meanwhile is ignored."""
    try:
        signalled = bool(taken.scope.__exit__(exc_type, exc, tb))  # its cancellation, ended here
        if signalled:
            await close(None, None, None)
            suppress: bool | None = True
        else:
            suppress = await close(exc_type, exc, tb)
    finally:
        taken.release()
    if taken.exits and (exc is None or signalled):
        raise SystemExit(128 + signal.SIGTERM)  # after the safe stop, as Ctrl-C's KeyboardInterrupt
    return suppress


async def _leave(
    group: anyio.abc.TaskGroup,
    exc_type: type[BaseException] | None,
    exc: BaseException | None,
    tb: TracebackType | None,
) -> bool | None:
    """Leave the Bus's task group (its tasks were told to end): an error of one is raised here. The
    block's own exception is not the group's to wrap (it goes on as it is); a cancellation is
    the group's to see (it may be its own)."""
    group.cancel_scope.cancel()
    if exc is not None and isinstance(exc, anyio.get_cancelled_exc_class()):
        return await group.__aexit__(exc_type, exc, tb)
    await group.__aexit__(None, None, None)
    return None


def _not_our_loop(name: str, entered: bool) -> NoReturn:
    """A call from another event loop than the one the Bus was entered in (or outside the block):
    refused at once, before anything is queued (its waiter, made on the Bus's loop, could not be
    awaited here).

    Raises:
        RuntimeMismatch: always (a RuntimeError).
    """
    if not entered:
        raise _runtime.RuntimeMismatch(f"{name}: use the Bus inside 'async with'")
    raise _runtime.RuntimeMismatch(
        f"{name}: this Bus runs on another event loop (the one its 'async with' entered); "
        "a Bus is used from its own loop only: use servobus.sync.Bus from other threads, or hand "
        "the call to the Bus's loop (anyio.from_thread with a portal, or the loop's own way)"
    )
