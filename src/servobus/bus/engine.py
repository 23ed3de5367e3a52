"""The request engine of a Bus (:class:`Engine`): the ONE object that talks to the Bus's sans-IO
scheduler and its link, through a small public API that the tick (:meth:`Engine.cycle`), single
requests (:meth:`Engine.submit`), broadcasts (:meth:`Engine.expect`, :meth:`Engine.send_broadcast`),
the safe stop and frame delivery (:meth:`Engine.on_frames`) all use.

* **Hand-over**: what the scheduler lets go (:meth:`~servobus.scheduler.Scheduler.poll`) is sent
  with ``link.send(request.frame, request)``: the Request is the send's handle, echoed by the
  link's report (a link may copy the frame). A link that does not report sends
  (``rules.reports_sends`` False) has each request's deadline start at hand-over.
* **Intake**: send reports, received frames (judged by the scheduler, then delivered to their motor
  by :mod:`servobus.bus.delivery`, settling the request they answer), the link's events (a lost link
  fails what is pending).
* **Time**: ONE task (:class:`Timer`, in the Bus's task group) sleeps in a cancel scope whose
  deadline is re-armed for the scheduler's next deadline and the watchdog's silence check.
* **Settling**: a request's outcome goes into its waiter (``request.context``): the reply, or the
  error that ended it (MotorTimeout, TransportError, the codec's ProtocolError).

Nothing here imports asyncio or trio: the clock and the waiters are the runtime's
(:mod:`servobus.runtime`), the timer is anyio's.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Callable, Hashable, Iterable
from typing import Any

import anyio
import anyio.lowlevel
from anyio.abc import TaskStatus

from servobus.bus.delivery import Delivery
from servobus.bus.motor import Motor, Registry
from servobus.bus.tick import Tick, detached, triage
from servobus.bus.watchdog import Watchdog
from servobus.diagnosis import diagnose
from servobus.errors import MotorStreaming, MotorTimeout, TransportError
from servobus.frame import Frame
from servobus.protocols import BoundCodec, Command, Reply
from servobus.runtime import Runtime, RuntimeMismatch, Waiter
from servobus.scheduler import Received, Request, RequestState, Scheduler, Traffic
from servobus.timing import format_duration
from servobus.transports._sending import not_sent_error
from servobus.transports.contract import FrameLink
from servobus.transports.events import StateChanged, TransportEvent, TransportState

__all__ = ["Engine", "LinkKeeper", "Timer"]

logger = logging.getLogger("servobus.bus")

# RequestState members as globals for the per-frame paths (an Enum member lookup is a metaclass call).
_SENDING, _SENT, _REPLIED = RequestState.SENDING, RequestState.SENT, RequestState.REPLIED
_NOT_EXECUTED = Traffic.NOT_EXECUTED

#: turns of the loop the timer lets pass before it times a request out (see Timer.run)
_SETTLE_TURNS = 3


def _no_clock() -> float:
    return 0.0  # (before the Bus is entered)


class Engine:
    """Requests between one Bus's scheduler (``scheduler``) and its link (``link``), for the Bus
    ``name`` with its ``watchdog`` (told of misses; its silence check is timed here), its motors
    (``registry``) and its ``subscribe`` callbacks (``subscribers``, called by the intake)."""

    def __init__(
        self,
        name: str,
        scheduler: Scheduler,
        link: FrameLink,
        watchdog: Watchdog,
        registry: Registry,
        subscribers: list[Callable[[Motor, Traffic, Reply], object]],
    ) -> None:
        self.name = name
        self.scheduler = scheduler
        self.link = link
        self.watchdog = watchdog
        self.registry = registry
        self._records = registry.records  # (the registry's, for good: read per request)
        self.reports_sends = link.rules.reports_sends
        self.runtime: Runtime | None = None
        self.time: Callable[[], float] = _no_clock  # the loop's clock once attached
        #: the block is being left: only the safe commands may still go out
        self.closing = False
        self.keeper = LinkKeeper(link)
        self.timer = Timer(self)
        self.delivery = Delivery(self, registry.records, watchdog, subscribers)
        self._deliver = self.delivery.deliver  # (once per reply: bound here)
        self.settle, self.fail = self.delivery.settle, self.delivery.fail
        watchdog.rearm = self.kick = self.timer.kick

    def attach(self, runtime: Runtime) -> None:
        """Take the link's frames, reports and events (the Bus is being entered on ``runtime``)."""
        self.runtime = runtime
        self.time = runtime.time
        self.closing = False
        self.keeper.hook(self.on_frames, self.on_report, self.on_event)

    def close(self) -> None:
        """The block is being left: only the safe commands go out from now on; what is queued fails."""
        self.closing = True
        self.fail(self.scheduler.fail(self.closed_error(), self.time(), queued_only=True))

    def closed_error(self) -> TransportError:
        return TransportError(f"{self.name}: the Bus is closed (its block was left)")

    def detach(self, error: BaseException) -> None:
        """The Bus was left: every request not yet answered fails with ``error``, iterators over motors'
        frames end (not hang), the link is left alone (the timer ends with the Bus's task group)."""
        self.fail(self.scheduler.fail(error, self.time()))
        self.registry.end_watchers()
        self.watchdog.stop()
        self.keeper.unhook(self.on_event)

    def wake_at(self) -> float:
        """When the timer should next wake: the scheduler's next deadline, or the silence check's."""
        scheduler = self.scheduler  # (Scheduler.next_deadline written out: once per pump)
        deadline = scheduler.table.next_deadline(scheduler.keys.held)
        silence = self.watchdog.silence_at
        if silence is not None and (deadline is None or silence < deadline):
            return silence
        return math.inf if deadline is None else deadline

    def settle_turns(self, now: float) -> int:
        """Turns of the loop the timer lets pass before it acts (more when a time-out is due)."""
        return _SETTLE_TURNS if self.scheduler.timeout_due(now) else 1

    def on_timer(self, now: float) -> None:
        """Time out what missed its deadline by ``now``, run the silence check, let the next go."""
        records = self._records
        for request in self.scheduler.expire(now):
            record = records.get(id(request.codec))
            if record is not None:
                self.watchdog.missed(record, now)
            self.settle(request, None)
        silence = self.watchdog.silence_at
        if silence is not None and silence <= now:
            self.watchdog.check_silence(now)
        self.pump()

    def count(self, codec: BoundCodec, counter: str) -> None:
        """One more ``counter`` in ``codec``'s motor's counts (``Motor.metrics``)."""
        self.scheduler.count(codec, counter)

    def reach_s(self, codec: BoundCodec) -> float:
        """The longest a reply of ``codec``'s motor is waited for now (its measured timeout)."""
        return self.scheduler.motor_timeout_s(codec)

    def cycle(
        self, items: list[tuple[Motor, Command]], timeout_s: float | None, probe_interval_s: float
    ) -> tuple[Tick, list[Request]]:
        """One tick (``Bus.cycle``, ``items`` not empty): its requests sorted (:func:`.tick.triage`:
        ValueError before anything is queued), queued, then one pump. Returns the tick to await, and
        the requests queued (a probe's context is not a Slot: the tick does not wait for it)."""
        runtime = self.runtime
        if runtime is None:
            raise RuntimeMismatch(f"{self.name}: use the Bus inside 'async with'")
        tick = Tick(runtime, len(items))
        now = self.time()
        busy = None if self.scheduler.quiet else self.scheduler.busy  # (None, the common case: nothing waits)
        prepared, skipped = triage(
            tick, items, timeout_s, self.prepare, self._records, busy, now, probe_interval_s
        )
        enqueue = self.enqueue
        for motor, request in prepared:
            enqueue(motor, request, now)
        for slot, motor, counter, error in skipped:
            self.count(motor.codec, counter)
            slot.set_result(error)
        self.pump()
        return tick, [request for _, request in prepared]

    def submit(
        self, motor: Motor, command: Command, timeout_s: float | None, retries: int, safe: bool = False
    ) -> Request:
        """A request for ``command``, queued, and what may go sent (see :meth:`prepare`)."""
        request = self.prepare(motor, command, timeout_s, retries, None, safe)
        self.enqueue(motor, request)
        self.pump()
        return request

    def send_unawaited(self, motor: Motor, command: Command) -> None:
        """Queue ``command`` for ``motor``, nobody waiting for it (a stream's "off" again; once entered)."""
        if self.runtime is not None:
            self.enqueue(motor, self.prepare(motor, command, None, 0, detached(self.runtime)))

    def prepare(
        self,
        motor: Motor,
        command: Command,
        timeout_s: float | None,
        retries: int,
        context: Any = None,
        safe: bool = False,
    ) -> Request:
        """The request for ``command``, encoded (ValueError here, before anything is queued), settled
        into ``context`` (default: a waiter of its own). TransportError: the block is being left (only
        the safe commands go out then), or was; MotorStreaming: the motor streams, will not answer."""
        runtime = self.runtime
        if runtime is None:
            raise RuntimeMismatch(f"{self.name}: use the Bus inside 'async with'")
        if self.closing and not safe:
            raise self.closed_error()
        command = command if motor.limits is None else motor.limited(command)  # (LimitExceeded, or clamped)
        request = self.scheduler.request(  # (positional: a keyword costs more, once per request)
            motor.codec, command, timeout_s, retries, runtime.waiter() if context is None else context
        )
        if request.key is None and motor.codec.streams and not request.writes:
            raise _streaming(motor, command)
        return request

    def enqueue(self, motor: Motor, request: Request, now: float | None = None) -> None:
        """Queue ``request`` (made ``now``, the loop's clock when not given)."""
        if request.writes:
            record = self._records.get(id(motor.codec))
            if record is not None and not record.commanded:
                self.registry.command(motor)
        motor.codec.note_sent(request.command)
        self.scheduler.submit(request, self.time() if now is None else now)

    def blocking(self, keys: list[Hashable]) -> tuple[float | None, list[Request]]:
        """What a broadcast with replies ``keys`` waits for: until when one is held, and those in flight."""
        return self.scheduler.blocking(keys, self.time())

    def expect(self, motor: Motor, command: Command, key: Hashable, timeout_s: float) -> Request:
        """A request whose frame a broadcast sends (:meth:`send_broadcast`): it only awaits ``key``."""
        assert self.runtime is not None
        request = _expected(motor, command, key, timeout_s, self.runtime.waiter())
        self.scheduler.expect(request, self.time())
        self.kick()
        return request

    def send_broadcast(self, frame: Frame, commanded: Iterable[Motor]) -> None:
        """Send a broadcast's ``frame``, past the scheduler (its replies are :meth:`expect`'s);
        ``commanded``: the motors it commands (they get the safe command)."""
        for motor in commanded:
            self.registry.command(motor)
        self.link.send(frame)

    def pump(self) -> None:
        """Hand the requests the scheduler lets go to the link; tell the stale ones' callers."""
        scheduler = self.scheduler
        if not scheduler.table.queue and not scheduler.keys.held:
            self.kick()  # (nothing can leave or go stale: poll() would change nothing)
            return
        while True:
            send, stale = scheduler.poll(self.time())
            for request in send:
                try:
                    self.link.send(request.frame, request)
                except Exception as exc:  # a full queue, bus-off, a lost transport: this request fails
                    # (a refusal with a reason of its own, queue_full or bus_off, counts as its report would)
                    reason = getattr(exc, "reason", None) or type(exc).__name__
                    self.scheduler.not_sent(request, reason, self.time())
                    self.settle(request, exc)
                    continue
                if not self.reports_sends:  # its deadline starts now
                    self._judged(request, self.scheduler.sent(request, self.time()))
            for request in stale:
                self.settle(request, request.error)
            if not send or self.reports_sends:
                break  # (on a link that does not report, what left may have made room for more)
        self.kick()

    def abandon(self, requests: Iterable[Request]) -> None:
        """The caller stopped waiting (cancelled): unresolved requests are cancelled; a reply that
        still comes is counted late."""
        now = self.time()
        for request in requests:
            request.context.cancel()  # (no effect on a resolved one)
            self.scheduler.cancel(request, now)  # (nor here)
        self.pump()

    def withdraw(self, motor: Motor, error: BaseException, spare: Callable[[Request], bool]) -> list[Request]:
        """The requests to ``motor`` not yet handed to the link, but those ``spare`` keeps, never will
        be: they end (cancelled), their callers get ``error``; returns them. Synchronous: a request
        submitted after (a stop) cannot be overtaken by them; what was handed over is left alone."""
        now = self.time()
        withdrawn = [r for r in self.scheduler.queued(motor.codec) if not spare(r)]
        for request in withdrawn:
            self.scheduler.cancel(request, now)
            self.settle(request, error)
        return withdrawn

    def on_frames(self, frames: list[Frame]) -> None:
        """The link's consumer: each frame judged by the scheduler, then delivered."""
        now = self.time()
        receive = self.scheduler.receive
        deliver = self._deliver
        for frame in frames:
            got = receive(frame, now)
            if got.codec is not None:
                if got.reply is not None:
                    deliver(got, now)
                elif got.traffic is _NOT_EXECUTED:  # its request's own bytes: echoed, not executed
                    self.delivery.not_executed(got)
                elif got.request is not None:  # an undecodable reply: its request fails with why
                    self.delivery.undecodable(got)
        self.pump()

    def on_report(self, handle: object, sent_at: float | None, reason: str | None) -> None:
        """The link's send report: ``handle`` is the Request handed over (anything else, a frame
        sent past the scheduler, is not ours to time)."""
        try:
            state = handle.state  # type: ignore[attr-defined]
        except AttributeError:
            return  # (a frame sent past the scheduler: a broadcast's)
        request: Request = handle  # type: ignore[assignment]
        if state is not _SENDING:  # (cancelled, or timed out unreported, while its frame was on its way)
            if sent_at is not None:
                self.scheduler.sent_after_all(request, sent_at)  # (its late reply's hold)
            return
        if reason is None and sent_at is not None:  # (the common case, written out: one per request)
            early = self.scheduler.sent(request, sent_at)
            if early is None and request.state is _SENT:
                deadline = request.deadline
                if deadline is None or deadline < self.timer.armed:
                    self.kick()
                return  # (else the timer already fires first: one re-arm per burst)
            if self._judged(request, early):
                return
        elif reason is not None:
            error = not_sent_error(reason, f"{self.name}: {request.describe()} not sent ({reason})")
            self.scheduler.not_sent(request, reason, self.time(), error)
            self.settle(request, request.error)
        elif self._judged(request, self.scheduler.sent(request, self.time())):
            return
        self.pump()  # it left the wire's count: the next may go

    def _judged(self, request: Request, early: Received | None) -> bool:
        """``request`` was reported sent (its deadline starts); ``early``, a reply before the report, is
        delivered. True when nothing more is to be done (it waits, and the timer fires in time)."""
        settled = False  # (the early reply's delivery settled it: settled once, never twice)
        if early is not None and early.reply is not None:  # its reply came before this report
            self._deliver(early, self.time())
            settled = early.request is request
        elif early is not None and early.request is not None:  # ... and did not decode
            self.delivery.undecodable(early)
        if request.state is _SENT:
            if request.deadline is not None and self.timer.armed <= request.deadline:
                return True  # the timer already fires first (the common case: one per burst)
            self.kick()
            return True
        if request.state is _REPLIED and not settled:  # nothing to wait for, or the early reply
            self.settle(request, None)
        return False

    def on_event(self, event: TransportEvent) -> None:
        if (
            isinstance(event, StateChanged)
            and event.state is TransportState.LOST
            and self.runtime is not None
        ):
            error = TransportError(f"{self.name}: transport lost ({event.cause})")
            self.fail(self.scheduler.fail(error, self.time()))

    def timed_out(self, request: Request) -> MotorTimeout:
        """The error of ``request``, which got no reply (the intake settles it with this)."""
        return _timed_out(request, self.time(), self.scheduler.seen, self.registry.named.values())


#: how long before a silent request another motor's reply still shows the line works (seconds): a
#: command asking one motor after the other (servobus status) heard the last one just before
HEARD_BEFORE_S = 0.1


def _timed_out(request: Request, now: float, seen: Any, motors: Iterable[Motor]) -> MotorTimeout:
    """The error of a request that got no reply, saying what the bus saw instead (computed off the
    reply path: only a time-out pays for it). ``seen``: the scheduler's record of recent frames."""
    since = request.sent_at if request.sent_at is not None else now - request.timeout_s
    # another motor heard since, or just before, shows the line works; the silent one never does
    own, before = request.codec, since - HEARD_BEFORE_S
    heard = any(m.last_seen is not None and m.last_seen >= before and m.codec is not own for m in motors)
    diagnosis = diagnose(request.codec, seen, since, heard=heard, sent=request.frame)
    attempts = f" ({request.attempts} attempts)" if request.attempts > 1 else ""
    return MotorTimeout(
        f"{request.describe()}: no reply within {format_duration(request.timeout_s)}{attempts}; {diagnosis}",
        diagnosis=diagnosis,
    )


def _streaming(motor: Motor, command: Command) -> MotorStreaming:
    streams = ", ".join(f"0x{code:02X}" for code in sorted(motor.codec.streams))
    return MotorStreaming(
        f"{motor!r} streams {streams} and answers no {type(command).__name__} until the "
        "stream is off (a read of the streamed command is answered by its next frame)"
    )


def _expected(
    motor: Motor, command: Command, key: Hashable, timeout_s: float, waiter: Waiter[Any]
) -> Request:
    """A request whose frame is sent by someone else (a broadcast): it only awaits ``key``; its
    frame is never sent (it goes into flight directly, past the queue)."""
    request = Request(motor.codec, command, Frame(arbitration_id=0), key, timeout_s, context=waiter)
    # each motor echoes the broadcast's bytes (its own request's); a plug-in codec from before
    # ``may_echo`` answers as it always did
    may_echo = getattr(motor.codec, "may_echo", None)
    if may_echo is not None and may_echo(command):
        request.echo = motor.codec.encode(command).data
    return request


class Timer:
    """The Bus's one timer: ONE task (:meth:`run`, in the Bus's task group) sleeps until the armed
    deadline (re-armed by :meth:`kick`), then has the engine expire what is due, run the silence
    check and let the next requests go (:meth:`Engine.on_timer`).

    Args:
        engine: the engine it times (its deadlines, and what to do when one came).
    """

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        #: the deadline the timer is armed for
        self.armed = math.inf
        self._scope: anyio.CancelScope | None = None
        self._life: anyio.CancelScope | None = None  # the timer task's

    async def run(self, *, task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED) -> None:
        """Shielded from the cancellation of the block around the Bus (the safe stop needs its
        time-outs): it runs until :meth:`stop`."""
        engine = self.engine
        started = False
        with anyio.CancelScope(shield=True) as self._life:
            try:
                while True:
                    with anyio.CancelScope(deadline=engine.wake_at()) as scope:
                        self._scope = scope
                        self.armed = scope.deadline
                        if not started:
                            started = True
                            task_status.started()
                        await anyio.sleep_forever()
                    self._scope = None
                    woke_at = engine.time()
                    # Replies that came in time go first, also after the loop stalled past the
                    # deadline (a GC pause, a busy host): they wait in ready callbacks, due timers
                    # (the simulator's) and the kernel, which a few turns of the loop take in. On
                    # trio a callback and a task woken in the same batch run in any order.
                    for _ in range(engine.settle_turns(woke_at)):
                        await anyio.lowlevel.cancel_shielded_checkpoint()
                    engine.on_timer(woke_at)
            finally:
                self._scope = None

    def stop(self) -> None:
        """End the timer task (the Bus's task group is being left)."""
        if self._life is not None:
            self._life.cancel()

    def kick(self) -> None:
        """Re-arm the timer for the next deadline (time-outs, a half-duplex line's rest, silence)
        when that is earlier than the one it is armed for; a later one waits for its wake-up (one
        re-arm per burst of requests: a re-arm costs more than a wake-up now and then)."""
        scope = self._scope
        if scope is None:
            return  # (the timer task is running: it reads the deadline when it sleeps again)
        deadline = self.engine.wake_at()
        if deadline < self.armed:
            self.armed = deadline
            scope.deadline = deadline


class LinkKeeper:
    """The task that opens a Bus's link and closes it (when the Bus opened it), and the engine's
    hooks on the link."""

    def __init__(self, link: FrameLink) -> None:
        self.link = link
        self._released: anyio.Event | None = None  # set: the link-keeping task closes the link
        self._keeper: anyio.CancelScope | None = None  # the link-keeping task's (shielded) scope
        self._open_error: Exception | None = None

    async def open(self, group: anyio.abc.TaskGroup) -> None:
        """Open the link in a task of ``group`` that keeps it open until :meth:`release`, then
        closes it (one task does both, as the contract asks). That task is shielded: the link's own
        tasks live in its scope, so the cancellation of the block around the Bus does not stop
        them before the safe stop went out; :meth:`cancel` cancels it (an opening the block gave
        up on). The link's error on opening is raised here, as it is."""
        self._released, opened, self._open_error = anyio.Event(), anyio.Event(), None
        group.start_soon(self._keep_link, opened)
        await opened.wait()
        if self._open_error is not None:
            raise self._open_error

    async def _keep_link(self, opened: anyio.Event) -> None:
        assert self._released is not None
        with anyio.CancelScope(shield=True) as self._keeper:
            try:
                await self.link.open()
            except Exception as exc:
                self._open_error = exc
                return
            finally:
                opened.set()
            try:
                await self._released.wait()
            finally:
                await self.link.close()

    def hook(
        self,
        consumer: Callable[[list[Frame]], None],
        reporter: Callable[[object, float | None, str | None], None],
        listener: Callable[[TransportEvent], None],
    ) -> None:
        """Have the link hand its frames, send reports and events to these (the engine's)."""
        self.link.set_consumer(consumer)
        self.link.set_send_reporter(reporter)
        self.link.add_listener(listener)

    def unhook(self, listener: Callable[[TransportEvent], None]) -> None:
        """The link's frames, reports and events go nowhere any more."""
        self.link.set_consumer(None)
        self.link.set_send_reporter(None)
        with contextlib.suppress(ValueError):
            self.link.remove_listener(listener)

    def release(self) -> None:
        """Close the link (the Bus's task group is being left)."""
        if self._released is not None:
            self._released.set()

    def cancel(self) -> None:
        """Give up an opening still under way."""
        if self._keeper is not None:
            self._keeper.cancel()
