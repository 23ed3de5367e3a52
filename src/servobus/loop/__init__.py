"""The pipelined fixed-rate control loop (:class:`Loop`): one pacer drives every bus; each tick's
commands leave at the tick's deadline, and the body gets the latest state of every motor with its
age, without waiting for this tick's replies.

::

    async with Bus(t1, name="a") as bus_a, Bus(t2, name="b") as bus_b:
        motors = [bus_a.motor("myactuator", 1), bus_b.motor("myactuator", 1)]
        async with Loop(hz=1000) as loop:
            async for tick in loop:                  # or loop.ticks(count=N)
                for m in motors:
                    state = tick.state(m)            # MotorState | None (no reply yet)
                    tick.command(m, ma.SpeedControl(speed_dps=30.0))  # leaves at the NEXT deadline

``Bus.cycle`` sends and waits: right when a tick's decision needs this tick's measurement and the
replies come well inside the period. The Loop is for when they do not (a reply takes longer than a
period on most USB adapters and ptys): what upkie's spine, EtherCAT masters and ros2_control's
read, update, write do. docs/loop.md compares the two.

How a reply is attributed: motors answer in the order they are asked and these protocols carry no
sequence numbers, so each motor keeps a FIFO of its commands that left (their tick, their request);
a reply the Bus matched to one of them is attributed to the OLDEST entry still outstanding (an
earlier command whose reply was lost takes it: the age reported is then a tick too old, never too
young). An entry with no reply within its horizon (twice its request's timeout, plus a period: a
late reply could come that long after; at least twice the longest round trip seen of the motor, so
a timeout shorter than the real latency gives up on no reply still coming) is dropped and counted
``lost``.

Nothing here awaits per bus or per request: a request's outcome comes to the loop through a slotted
context (the motor's record in the loop, one per motor), the batch of each bus is sent synchronously
at the deadline (:mod:`servobus.bus.pipeline`), and the only await is the pacer's
(:func:`servobus.ticks.ticks`).

Its parts: ``_track`` (what the loop knows of each motor, and the attribution), ``_tick`` (a tick
and a motor's state, as the body sees them); the :class:`Loop` here drives them.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator, Iterable
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any, Self

import anyio

from servobus import runtime as _runtime
from servobus.bus.pipeline import Superseded, prepare, send
from servobus.bus.safety import stop_motors
from servobus.loop._tick import LoopTick, MotorState
from servobus.loop._track import Counts, Track, not_pipelined
from servobus.metrics import LatencyWindow
from servobus.protocols import Command
from servobus.scheduler import RequestState
from servobus.ticks import ticks

if TYPE_CHECKING:
    from servobus.bus import Bus, Motor
    from servobus.scheduler import Request

__all__ = ["Loop", "LoopMetrics", "LoopTick", "MotorState"]

_SENDING = RequestState.SENDING

#: a tick that starts later than this after its deadline is counted late (``late_ticks``)
LATE_TICK_S = 200e-6


@dataclass(frozen=True, slots=True)
class LoopMetrics:
    """What a :class:`Loop` counted since it was made.

    Attributes:
        ticks: ticks given to the body.
        late_ticks: ticks started more than 200 µs after their deadline.
        skipped: ticks dropped whole because their time had passed (the pacer's).
        overruns: bodies that ran past the next tick's deadline.
        commands_sent: commands handed to their link (judged at the next tick).
        commands_on_time: of those, the ones whose frame left before the next tick's deadline
            (each judged when its send report is known: one that comes later than the next tick
            is judged at a later tick, by when the frame left).
        superseded: commands replaced by the next one for their motor before they left (never sent),
            or dropped (:meth:`Loop.drop`).
        not_sent: commands not sent (the motor offline between probes, streaming, a link refusing).
        throttled: commands not sent because their motor had ``max_outstanding`` unanswered.
        lost: commands with no reply within their horizon, or whose reply the replies after it
            showed lost (the attribution resynchronised: docs/loop.md).
        stale_states: per tick, the motors commanded before with no fresh state, summed.
        state_age_p50_s, state_age_p99_s, state_age_max_s: the age (``MotorState.age_s``) of the
            state of every commanded motor at each tick's start (recent window; None: none yet).
        late_p50_s, late_p99_s: how late ticks started (recent window).
    """

    ticks: int
    late_ticks: int
    skipped: int
    overruns: int
    commands_sent: int
    commands_on_time: int
    superseded: int
    not_sent: int
    throttled: int
    lost: int
    stale_states: int
    state_age_p50_s: float | None
    state_age_p99_s: float | None
    state_age_max_s: float | None
    late_p50_s: float | None
    late_p99_s: float | None


class Loop:
    """A pipelined fixed-rate control loop over the buses of the motors it commands.

    Args:
        hz: the tick rate.
        timeout_s: each request's timeout (None: the Bus's adaptive one, from measured round trips).
        safe_stop: leaving the ``async with`` block by an exception or a cancellation sends the safe
            stop (the Bus's ``safe`` command) to every motor the loop commanded, shielded; a clean
            exit leaves the motors as they are (the Bus's own exit stops them).
        max_outstanding: the most unanswered commands a motor may have; a motor with that many gets
            no command this tick (counted ``throttled``; the next tick's supersedes it). A host or
            a link that falls behind (a busy core, a stalled adapter) then holds this many of each
            motor's replies at most, not an ever longer backlog whose state grows seconds old.

    Buses are found from the motors commanded (``motor.bus``); they must be entered (``async with``)
    around the loop, on the same event loop.
    """

    def __init__(
        self, hz: float, *, timeout_s: float | None = None, safe_stop: bool = True, max_outstanding: int = 4
    ) -> None:
        if not (hz > 0 and hz != float("inf")):
            raise ValueError(f"hz={hz!r} must be a positive number")
        if not (isinstance(max_outstanding, int) and max_outstanding >= 1):
            raise ValueError(f"max_outstanding={max_outstanding!r} must be an integer >= 1")
        self.max_outstanding = max_outstanding
        if timeout_s is not None and not timeout_s > 0:
            raise ValueError(f"timeout_s={timeout_s!r} must be positive")
        self.hz = hz
        self.period_s = 1.0 / hz
        self.timeout_s = timeout_s
        self.safe_stop = safe_stop
        #: every motor the loop commanded, with what it knows of it
        self.tracks: dict[Motor, Track] = {}
        #: the commands given for the next tick
        self.commands: dict[Motor, Command] = {}
        self.counts = Counts()
        self._time: Any = None
        self._pacer: AsyncIterator[Any] | None = None
        self._count: int | None = None
        self._last: LoopTick | None = None
        self._previous: list[Request] = []  # the last tick's requests (on time at the next?)
        #: requests whose send report had not come when their tick was judged, with its end
        self._undecided: list[tuple[Request, float]] = []
        self._ages = LatencyWindow(4096)
        self._lates = LatencyWindow(4096)
        self._n = dict.fromkeys(("ticks", "late", "skipped", "overruns", "sent", "on_time", "stale"), 0)

    async def __aenter__(self) -> Self:
        self._time = _runtime.current().time
        self.commands = {}  # (given after a block was left: never sent)
        for track in self.tracks.values():  # (entered again: the late replies come here again)
            self._install(track)
        return self

    async def __aexit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        pacer, self._pacer = self._pacer, None
        for motor, track in self.tracks.items():
            record = track.bus.engine.registry.records.get(id(motor.codec))
            if record is not None and record.late == track.late:
                record.late = None
        with anyio.CancelScope(shield=True):
            if pacer is not None:
                await pacer.aclose()  # type: ignore[attr-defined]
            if exc is not None and self.safe_stop:
                await self.stop_motors()
        self._time = None  # (a command for a new motor now is refused: Loop.add)

    def add(self, motor: Motor) -> Track:
        """Track ``motor`` (done by its first command)."""
        if self._time is None:
            raise RuntimeError("use the Loop inside 'async with'")
        track = self.tracks[motor] = Track(motor, self.counts, self._time, self.period_s)
        self._install(track)
        return track

    def _install(self, track: Track) -> None:
        record = track.bus.engine.registry.records.get(id(track.motor.codec))
        if record is not None:
            record.late = track.late  # (undone when the loop's block is left)

    def __aiter__(self) -> Self:
        return self

    def ticks(self, count: int | None = None) -> Self:
        """Iterate ``count`` ticks (None: until the body breaks out). The pacer runs on between
        iterations of one block: a later ``async for`` goes on on the same grid (the ticks whose
        time passed meanwhile are counted ``skipped``, the time between as the last body's)."""
        if count is not None and count < 0:
            raise ValueError(f"count={count} must be >= 0")
        self._count = count
        return self

    async def __anext__(self) -> LoopTick:
        body_end = self._time() if self._time is not None else 0.0
        count = self._count
        if count is not None:
            if count == 0:
                self._count = None  # (the next iteration, unless told, has no end)
                raise StopAsyncIteration
            self._count = count - 1
        if self._pacer is None:
            if self._time is None:
                raise RuntimeError("use the Loop inside 'async with'")
            self._pacer = ticks(self.hz).__aiter__()
        pace = await self._pacer.__anext__()
        return self._begin(pace, body_end)

    def _begin(self, pace: Any, body_end: float) -> LoopTick:
        """The tick the pacer gave: the last tick's requests judged, this one's sent, its view made."""
        n = self._n
        last = self._last
        index = pace.index
        deadline = pace.deadline
        overrun = last is not None and body_end > last.deadline + self.period_s
        # The last tick's commands, judged now (a send report may come after the hand-over): out
        # within their tick, i.e. before the next deadline of the grid (this one, unless skipped).
        within = last.deadline + self.period_s if last is not None else deadline
        left = on_time = 0
        previous = self._previous
        undecided = self._undecided
        for request in previous:
            if request.handed_at is not None:
                left += 1
                sent_at = request.sent_at
                if sent_at is not None and sent_at <= within:
                    on_time += 1
                elif sent_at is None and request.state is _SENDING:  # (its report is still to come)
                    undecided.append((request, within))
        n["sent"] += left
        n["on_time"] += on_time
        if undecided:
            n["on_time"] += self._judge_undecided()
        started = pace.started
        since = last.started if last is not None else started
        stale = 0
        add_age = self._ages.add
        # Commands past their horizon are given up on as of the previous tick's start: the replies
        # that came before it were taken in since, while the pacer waited (after an overrun it may
        # not have: none is given up on then).
        expiry = -math.inf if overrun else since
        for track in self.tracks.values():
            fifo = track.fifo
            if fifo:  # (expire() written out for its common case: the oldest within its horizon)
                request = fifo[0][1]
                sent_at = request.sent_at
                horizon_s = max(2.0 * request.timeout_s, 2.0 * track.rtt_max_s) + track.period_s
                if sent_at is None or expiry - sent_at > horizon_s:
                    track.expire(expiry)
            if track.commanded:
                if track.received_at < since:
                    stale += 1
                if track.reply is not None:
                    add_age(started - track.sent_s)
        sent = self._send(index)  # (after: a motor commanded first now is not stale yet)
        n["ticks"] += 1
        n["skipped"] += pace.skipped
        n["stale"] += stale
        if overrun:
            n["overruns"] += 1
        late_s = started - deadline
        self._lates.add(late_s)
        if late_s > LATE_TICK_S:
            n["late"] += 1
        commands_late = len(previous) - on_time
        tick = self._last = LoopTick(
            self, index, deadline, started, pace.skipped, overrun, stale, sent, since, commands_late
        )
        return tick

    def _judge_undecided(self) -> int:
        """The commands whose send report had not come when their tick was judged, judged now that
        it has (each against its own tick's end); returns how many left on time. Those still
        unreported wait; those that ended unreported never count."""
        on_time = 0
        waiting: list[tuple[Request, float]] = []
        for request, within in self._undecided:
            sent_at = request.sent_at
            if sent_at is not None:
                if sent_at <= within:
                    on_time += 1
            elif request.state is _SENDING:
                waiting.append((request, within))
        self._undecided = waiting
        return on_time

    def _send(self, index: int) -> int:
        """The commands given for tick ``index``, one batch per bus; returns how many left now."""
        commands = self.commands
        self._previous = []  # (judged: a ValueError below must not have them judged again)
        if not commands:
            return 0
        self.commands = {}
        tracks = self.tracks
        window = self.max_outstanding
        batches: dict[Bus, tuple[list[tuple[Motor, Command]], list[Track]]] = {}
        for motor, command in commands.items():
            track = tracks[motor]
            if len(track.fifo) >= window:  # (its replies are not being taken in: send no more)
                self.counts.throttled += 1
                continue
            batch = batches.get(track.bus)
            if batch is None:
                batch = batches[track.bus] = ([], [])
            batch[0].append((motor, command))
            batch[1].append(track)
        timeout_s = self.timeout_s
        # every bus's commands encoded before any leaves: a ValueError sends nothing of the tick
        prepared = [
            prepare(bus.engine, items, contexts, timeout_s) for bus, (items, contexts) in batches.items()
        ]
        sent: list[Request] = []
        not_sent = 0
        for (bus, (items, contexts)), requests in zip(batches.items(), prepared, strict=True):
            queued, skipped = send(bus.engine, items, requests, contexts, bus.probe_interval_s)
            not_sent += skipped
            for request in queued:
                track = request.context
                track.commanded = True
                if request.writes:
                    track.wrote = True
                if request.key is not None:
                    track.fifo.append((index, request))
            sent += queued
        self.counts.not_sent += not_sent
        self._previous = sent
        left = 0
        for request in sent:
            if request.handed_at is not None:
                left += 1
        return left

    def drop(self, motors: Iterable[Motor]) -> int:
        """Drop the commands of ``motors`` that have not left: the one given for the next tick and
        those still queued on their bus (counted ``superseded``), so that a stop sent next is not
        followed by one of them; returns how many. The body's later commands are its own: a caller
        that stops a motor stops giving it set-points too (servobus.dashboard's page does both)."""
        dropped = 0
        for motor in motors:
            if self.commands.pop(motor, None) is not None:
                self.counts.superseded += 1
                dropped += 1
            track = self.tracks.get(motor)
            if track is not None and track.bus.engine.runtime is not None:
                why = Superseded(f"{track.bus.name}: dropped")
                dropped += len(track.bus.engine.withdraw(motor, why, not_pipelined))
        return dropped

    async def stop_motors(self) -> None:
        """The safe stop (each Bus's ``safe`` command) to every motor the loop sent a command that is
        not a read (as the Bus's own safe stop), on all its buses at once; the loop's commands still
        queued are withdrawn first."""
        by_bus: dict[Bus, dict[Motor, Command]] = {}
        for motor, track in self.tracks.items():
            bus = track.bus
            engine = bus.engine
            if not track.wrote or bus.safe is None or not engine.link.is_open or engine.runtime is None:
                continue
            bus.engine.withdraw(motor, Superseded(f"{bus.name}: the loop stops"), not_pipelined)
            try:
                by_bus.setdefault(bus, {})[motor] = motor.codec.safe_command(bus.safe)
            except ValueError:
                continue
        if not by_bus:
            return
        async with anyio.create_task_group() as group:
            for bus, commands in by_bus.items():
                group.start_soon(stop_motors, bus, commands, bus.safe_timeout_s)

    def metrics(self) -> LoopMetrics:
        """What the loop counted since it was made."""
        n, counts = self._n, self.counts
        ages, lates = self._ages.snapshot(), self._lates.snapshot()
        return LoopMetrics(
            ticks=n["ticks"],
            late_ticks=n["late"],
            skipped=n["skipped"],
            overruns=n["overruns"],
            commands_sent=n["sent"],
            commands_on_time=n["on_time"],
            superseded=counts.superseded,
            not_sent=counts.not_sent,
            throttled=counts.throttled,
            lost=counts.lost,
            stale_states=n["stale"],
            state_age_p50_s=ages.p50_s,
            state_age_p99_s=ages.p99_s,
            state_age_max_s=ages.max_s,
            late_p50_s=lates.p50_s,
            late_p99_s=lates.p99_s,
        )
