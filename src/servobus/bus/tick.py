"""The outcomes of one ``Bus.cycle()`` gathered into one waiter (:class:`Tick`), each request's
place in it (:class:`Slot`), how a cycle's items are sorted (:func:`triage`), and the waiters of
requests nobody awaits (:func:`detached`).

A cycle wakes once, when its last request ends, not once per motor (what gathering one future per
request costs: measured in :class:`Slot`'s docstring). The waiter is the runtime's
(:mod:`servobus.runtime`): an ``asyncio.Future`` on asyncio, a ``TrioWaiter`` on trio; nothing here
imports either.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import TYPE_CHECKING, Any

from servobus.errors import MotorBusy, MotorOffline, MotorStreaming
from servobus.protocols import Command, Reply
from servobus.runtime import Runtime, Waiter, WaiterCancelled

if TYPE_CHECKING:
    from servobus.bus.motor import Motor, MotorRecord
    from servobus.scheduler import Request

__all__ = ["Result", "Slot", "Tick", "awaitable", "detached", "triage"]

Result = Reply | BaseException | None


class Tick:
    """The results of one cycle, in order; :attr:`future` is done when the last request ended."""

    __slots__ = ("future", "left", "results", "runtime")

    def __init__(self, runtime: Runtime, size: int) -> None:
        self.runtime = runtime
        self.future: Waiter[list[Result]] = runtime.waiter()
        self.results: list[Result] = [None] * size
        self.left = size


class Slot:
    """One request's place in a :class:`Tick`, with the part of a waiter's interface the Bus and
    an observer of the request (``request.context``) use: its outcome is the tick's result there.

    Kept beside anyio's and the runtime's primitives because the hot path needs it: one
    ``Bus.cycle`` of 32 ReadStatus2 on the bench's reflector (3,000 cycles, process CPU time, best
    of 3, issue 38) ran 55,600 to 64,600 transactions/s with Slots and 43,700 to 49,300 with one
    runtime waiter and done callback per request instead (about 20 % slower: a future per request,
    and a loop turn per callback)."""

    __slots__ = ("_callbacks", "_state", "index", "tick")

    def __init__(self, tick: Tick, index: int) -> None:
        self.tick = tick
        self.index = index
        self._state = 0  # 0 pending, 1 done, 2 cancelled
        self._callbacks: list[Callable[[Slot], object]] | None = None

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
        """The cycle awaiting the tick was cancelled (its waiter is already)."""
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
            raise WaiterCancelled("the cycle was cancelled")
        if not self._state:
            raise RuntimeError("the request has not ended")
        return self.tick.results[self.index]

    def add_done_callback(self, callback: Callable[[Slot], object]) -> None:
        """As a waiter's: ``callback(slot)`` soon after the request ends."""
        if self._state:
            self.tick.runtime.call_soon(callback, self)
        else:
            self._callbacks = [*(self._callbacks or ()), callback]

    def _run_callbacks(self) -> None:
        callbacks, self._callbacks = self._callbacks or [], None
        call_soon = self.tick.runtime.call_soon
        for callback in callbacks:
            call_soon(callback, self)


def awaitable(context: Waiter[Any] | Slot) -> Waiter[Any]:
    """What to await for a request to end: its waiter, or its cycle's."""
    return context.tick.future if isinstance(context, Slot) else context


def detached(runtime: Runtime) -> Waiter[Any]:
    """A waiter for a request nobody awaits (a probe, a repeated stream "off"): its outcome is taken
    when it ends, so an exception is never reported as "never retrieved"."""
    waiter = runtime.waiter()
    waiter.add_done_callback(_take)
    return waiter


def _take(waiter: Waiter[Any]) -> None:
    if not waiter.cancelled():
        waiter.exception()


def triage(
    tick: Tick,
    items: list[tuple[Motor, Command]],
    timeout_s: float | None,
    prepare: Callable[..., Request],
    records: dict[int, MotorRecord],
    busy: Callable[[Hashable, float], bool] | None,
    now: float,
    probe_interval_s: float,
) -> tuple[list[tuple[Motor, Request]], list[tuple[Slot, Motor, str, BaseException]]]:
    """Each item of a tick (``Engine.cycle``) prepared (``prepare(motor, command, timeout_s, 0,
    slot)``: encoded, ValueError before anything is queued) and sorted: the requests to queue, and
    the slots whose outcome is known at once, with the counter to count (MotorStreaming,
    MotorOffline, MotorBusy: a reply still due with its key, per ``busy``; an offline motor's
    command still goes every ``probe_interval_s``, as a probe nobody waits for)."""
    prepared: list[tuple[Motor, Request]] = []
    skipped: list[tuple[Slot, Motor, str, BaseException]] = []
    for i, (m, c) in enumerate(items):
        slot = Slot(tick, i)
        try:
            request = prepare(m, c, timeout_s, 0, slot)
        except MotorStreaming as exc:
            skipped.append((slot, m, "skipped_streaming", exc))
            continue
        if m.online is False:
            record = records[id(m.codec)]
            why = f"{m!r} is offline ({record.misses} replies missed): the tick does not wait for it"
            if now >= record.probe_at and (busy is None or not busy(request.key, now)):  # a probe
                record.probe_at = now + probe_interval_s
                request.context = detached(tick.runtime)
                prepared.append((m, request))
                skipped.append((slot, m, "probes", MotorOffline(why)))
            else:
                skipped.append((slot, m, "skipped_offline", MotorOffline(why)))
        elif busy is not None and busy(request.key, now):
            why = f"{m!r}: the reply to its last {type(c).__name__} is still due: not sent this tick"
            skipped.append((slot, m, "skipped_busy", MotorBusy(why)))
        else:
            prepared.append((m, request))
    return prepared, skipped
