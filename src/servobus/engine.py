"""The request engine of a Bus: the glue between its sans-IO scheduler and its link (:class:`Engine`).

It moves frames and decisions, and owns the Bus's one timer:

* **Hand-over**: what the scheduler lets go (:meth:`~servobus.scheduler.Scheduler.poll`) is sent
  with ``link.send(request.frame, request)``: the Request is the send's handle, echoed by the
  link's report (a link may copy the frame). A link that does not report sends
  (``rules.reports_sends`` False) has each request's deadline start at hand-over.
* **Intake**: send reports, received frames (decoded, delivered to their motor, settling the
  request they answer), the link's events (a lost link fails what is pending).
* **Time**: ONE task (:meth:`Engine.run`, in the Bus's task group) sleeps in a cancel scope whose
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
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

import anyio
import anyio.lowlevel
from anyio.abc import TaskStatus

from servobus.delivery import Delivery
from servobus.diagnosis import diagnose
from servobus.errors import MotorStreaming, MotorTimeout, TransportError
from servobus.protocols import Command
from servobus.runtime import Runtime, RuntimeMismatch
from servobus.scheduler import Received, Request, RequestState, Scheduler
from servobus.transports._sending import not_sent_error
from servobus.transports.contract import FrameLink
from servobus.transports.events import StateChanged, TransportEvent, TransportState
from servobus.watchdog import Watchdog

if TYPE_CHECKING:
    from servobus.bus import Bus
    from servobus.motor import Motor

__all__ = ["Engine", "LinkKeeper"]

logger = logging.getLogger("servobus.bus")

# RequestState members as globals for the per-frame paths (an Enum member lookup is a metaclass call).
_SENDING, _SENT, _REPLIED = RequestState.SENDING, RequestState.SENT, RequestState.REPLIED
_TIMED_OUT = RequestState.TIMED_OUT


#: turns of the loop the timer lets pass before it times a request out (see Engine.run)
_SETTLE_TURNS = 3


class Engine:
    """Requests between one Bus's scheduler and its link, and the Bus's one timer.

    Args:
        bus: the Bus (its motors, its name, its stream bookkeeping).
        scheduler: the Bus's scheduler.
        link: the Bus's link.
        watchdog: the Bus's watchdog (told of misses and answers; its silence check is timed here).
    """

    def __init__(self, bus: Bus, scheduler: Scheduler, link: FrameLink, watchdog: Watchdog) -> None:
        self.bus = bus
        self.name = bus.name
        self.scheduler = scheduler
        self.link = link
        self.watchdog = watchdog
        self.reports_sends = link.rules.reports_sends
        self.runtime: Runtime | None = None
        self._scope: anyio.CancelScope | None = None
        self._life: anyio.CancelScope | None = None  # the timer task's
        self.keeper = LinkKeeper(link)
        self._armed = math.inf  # the timer's deadline
        self.delivery = Delivery(self)
        watchdog.rearm = self.kick

    # ---- life cycle ----

    def attach(self, runtime: Runtime) -> None:
        """Take the link's frames, reports and events (the Bus is being entered on ``runtime``)."""
        self.runtime = runtime
        self.time = runtime.time
        self.link.set_consumer(self.delivery.on_frames)
        self.link.set_send_reporter(self.on_report)
        self.link.add_listener(self.on_event)

    def detach(self, error: BaseException) -> None:
        """The Bus was left: every request not yet answered fails with ``error``, iterators over
        motors' frames end (not hang), and the link is left alone (the timer task ends with the
        Bus's task group)."""
        self.fail(self.scheduler.fail(error, self.time()))
        for motor in self.bus.motors.values():
            for watcher in list(motor._watchers):
                watcher._end()
        self.watchdog.stop()
        self.link.set_consumer(None)
        self.link.set_send_reporter(None)
        with contextlib.suppress(ValueError):
            self.link.remove_listener(self.on_event)

    async def run(self, *, task_status: TaskStatus[None] = anyio.TASK_STATUS_IGNORED) -> None:
        """The Bus's one timer: sleeps until the armed deadline (re-armed by :meth:`kick`), then
        expires what is due, runs the silence check and lets the next requests go. Shielded from
        the cancellation of the block around the Bus (the safe stop needs its time-outs): it runs
        until :meth:`stop`."""
        started = False
        with anyio.CancelScope(shield=True) as self._life:
            try:
                while True:
                    with anyio.CancelScope(deadline=self._wake_at()) as scope:
                        self._scope = scope
                        self._armed = scope.deadline
                        if not started:
                            started = True
                            task_status.started()
                        await anyio.sleep_forever()
                    self._scope = None
                    woke_at = self.time()
                    # Replies that came in time go first, also after the loop stalled past the
                    # deadline (a GC pause, a busy host): they wait in ready callbacks, due timers
                    # (the simulator's) and the kernel, which a few turns of the loop take in. On
                    # trio a callback and a task woken in the same batch run in any order.
                    turns = _SETTLE_TURNS if self.scheduler.timeout_due(woke_at) else 1
                    for _ in range(turns):
                        await anyio.lowlevel.cancel_shielded_checkpoint()
                    self.on_timer(woke_at)
            finally:
                self._scope = None

    def stop(self) -> None:
        """End the timer task and release the link (the Bus's task group is being left)."""
        if self._life is not None:
            self._life.cancel()
        self.keeper.release()

    def abort(self) -> None:
        """:meth:`stop`, and an opening of the link still under way is cancelled (entering the Bus
        failed, or was cancelled)."""
        self.stop()
        self.keeper.cancel()

    def _wake_at(self) -> float:
        deadline = self.scheduler.next_deadline()
        silence = self.watchdog.silence_at
        if silence is not None and (deadline is None or silence < deadline):
            return silence
        return math.inf if deadline is None else deadline

    def kick(self) -> None:
        """Re-arm the timer for the next deadline (time-outs, a half-duplex line's rest, silence)
        when that is earlier than the one it is armed for; a later one waits for its wake-up (one
        re-arm per burst of requests: a re-arm costs more than a wake-up now and then)."""
        scope = self._scope
        if scope is None:
            return  # (the timer task is running: it reads the deadline when it sleeps again)
        deadline = self._wake_at()
        if deadline < self._armed:
            self._armed = deadline
            scope.deadline = deadline

    def on_timer(self, now: float | None = None) -> None:
        """Time out what missed its deadline by ``now`` (default: the clock's now), run the silence
        check, and let the next requests go."""
        if now is None:
            now = self.time()
        by_codec = self.bus._by_codec
        for request in self.scheduler.expire(now):
            motor = by_codec.get(id(request.codec))
            if motor is not None:
                self.watchdog.missed(motor, now)
            self.settle(request, None)
        silence = self.watchdog.silence_at
        if silence is not None and silence <= now:
            self.watchdog.check_silence(now)
        self.pump()

    # ---- requests in ----

    def submit(
        self, motor: Motor, command: Command, timeout_s: float | None, retries: int, safe: bool = False
    ) -> Request:
        """A request for ``command``, queued, and what may go sent (see :meth:`prepare`)."""
        request = self.prepare(motor, command, timeout_s, retries, None, safe)
        self.enqueue(motor, request)
        self.pump()
        return request

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
        into ``context`` (default: a waiter of its own).

        Raises:
            TransportError: the block is being left (only the safe commands go out then), or was.
            MotorStreaming: the motor streams and will not answer this command.
        """
        runtime = self.runtime
        if runtime is None:
            raise RuntimeMismatch(f"{self.name}: use the Bus inside 'async with'")
        if self.bus._closing and not safe:
            raise self.bus._closed_error()
        # (positional: a call by keyword costs more, and this is once per request)
        request = self.scheduler.request(
            motor.codec, command, timeout_s, retries, runtime.waiter() if context is None else context
        )
        if request.key is None and motor.codec.streams and not request.writes:
            streams = ", ".join(f"0x{code:02X}" for code in sorted(motor.codec.streams))
            raise MotorStreaming(
                f"{motor!r} streams {streams} and answers no {type(command).__name__} until the "
                "stream is off (a read of the streamed command is answered by its next frame)"
            )
        return request

    def enqueue(self, motor: Motor, request: Request, now: float | None = None) -> None:
        """Queue ``request`` (made ``now``, the loop's clock when not given)."""
        if request.writes:
            self.bus._commanded[id(motor.codec)] = motor
        motor.codec.note_sent(request.command)
        self.scheduler.submit(request, self.time() if now is None else now)

    # ---- requests out ----

    def pump(self) -> None:
        """Hand the requests the scheduler lets go to the link; tell the stale ones' callers."""
        while True:
            send, stale = self.scheduler.poll(self.time())
            for request in send:
                self.hand_over(request)
            for request in stale:
                self.settle(request, request.error)
            if not send or self.reports_sends:
                break  # (on a link that does not report, what left may have made room for more)
        self.kick()

    def hand_over(self, request: Request) -> None:
        try:
            self.link.send(request.frame, request)
        except Exception as exc:  # a full queue, bus-off, a lost transport: this request fails, nothing else
            # (a refusal with a reason of its own, queue_full or bus_off, counts as its report would)
            self.scheduler.not_sent(request, getattr(exc, "reason", None) or type(exc).__name__, self.time())
            self.settle(request, exc)
            return
        if not self.reports_sends:  # its deadline starts now
            self._judged(request, self.scheduler.sent(request, self.time()))

    def abandon(self, requests: Iterable[Request]) -> None:
        """The caller stopped waiting (cancelled): unresolved requests are cancelled; a reply that
        still comes is counted late."""
        now = self.time()
        for request in requests:
            request.context.cancel()  # (no effect on a resolved one)
            self.scheduler.cancel(request, now)  # (nor here)
        self.pump()

    def withdraw(self, motor: Motor, error: BaseException, spare: Callable[[Request], bool]) -> list[Request]:
        """The requests to ``motor`` not yet handed to the link, but those ``spare`` keeps, never
        will be: they end (cancelled) and their callers get ``error``; returns them. Synchronous: a
        request submitted after this call (a stop) cannot be overtaken by them, whereas a request
        queued behind a reply still due would leave after a stop that has another reply key. What
        was handed over is left alone (its frame leaves before anything submitted later)."""
        now = self.time()
        withdrawn = [r for r in self.scheduler.queued(motor.codec) if not spare(r)]
        for request in withdrawn:
            self.scheduler.cancel(request, now)
            self.settle(request, error)
        return withdrawn

    # ---- intake ----

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
                if deadline is None or deadline < self._armed:
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
        """``request`` was reported sent (its deadline starts): ``early``, the verdict on a reply
        that came before the report, is delivered. True when nothing more is to be done (it waits
        for its reply, and the timer fires in time)."""
        if early is not None and early.reply is not None:  # its reply came before this report
            self.delivery.deliver(early, self.time())
        elif early is not None and early.request is not None:  # ... and did not decode
            self.delivery.undecodable(early)
        if request.state is _SENT:
            if request.deadline is not None and self._armed <= request.deadline:
                return True  # the timer already fires first (the common case: one per burst)
            self.kick()
            return True
        if request.state is _REPLIED:  # nothing to wait for, or the early reply
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

    # ---- outcomes ----

    def fail(self, requests: Iterable[Request]) -> None:
        for request in requests:
            self.settle(request, request.error)

    def settle(self, request: Request, error: BaseException | None) -> None:
        future = request.context
        if future is None or future.done():
            return
        if error is not None:
            future.set_exception(error)
        elif request.state is _REPLIED:
            future.set_result(request.reply)
        elif request.state is _TIMED_OUT:
            future.set_exception(self.timed_out(request))
        else:
            future.set_exception(
                request.error or TransportError(f"{self.name}: {request.describe()} {request.state.value}")
            )

    def timed_out(self, request: Request) -> MotorTimeout:
        """The error of a request that got no reply, saying what the bus saw instead (computed here,
        off the reply path: only a time-out pays for it)."""
        now = self.time()
        since = request.sent_at if request.sent_at is not None else now - request.timeout_s
        heard = any(m.last_seen is not None and m.last_seen >= since for m in self.bus.motors.values())
        diagnosis = diagnose(request.codec, self.scheduler.seen, since, heard=heard, sent=request.frame)
        attempts = f" ({request.attempts} attempts)" if request.attempts > 1 else ""
        return MotorTimeout(
            f"{request.describe()}: no reply within {request.timeout_s:g} s{attempts}; {diagnosis}",
            diagnosis=diagnosis,
        )


class LinkKeeper:
    """The task that opens a Bus's link and closes it (when the Bus opened it)."""

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

    def release(self) -> None:
        """Close the link (the Bus's task group is being left)."""
        if self._released is not None:
            self._released.set()

    def cancel(self) -> None:
        """Give up an opening still under way."""
        if self._keeper is not None:
            self._keeper.cancel()
