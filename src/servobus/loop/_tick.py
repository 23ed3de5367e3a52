"""One tick of a :class:`~servobus.loop.Loop` as its body sees it (:class:`LoopTick`), and a motor's
state in it (:class:`MotorState`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple, Protocol

from servobus.loop._track import Counts, Track
from servobus.protocols import Command, Reply

if TYPE_CHECKING:
    from servobus.bus import Motor

__all__ = ["LoopHost", "LoopTick", "MotorState"]


class LoopHost(Protocol):
    """What a tick asks of its loop (:class:`~servobus.loop.Loop` is one)."""

    tracks: dict[Motor, Track]
    commands: dict[Motor, Command]
    counts: Counts

    def add(self, motor: Motor) -> Track: ...


class MotorState(NamedTuple):
    """A motor's latest state, as a tick's body sees it (:meth:`LoopTick.state`).

    A NamedTuple, not a frozen dataclass: one is made per motor and tick, and a frozen slotted
    dataclass of six fields took 2.5 µs to make against 0.84 µs for this (3.11, this machine).

    Attributes:
        reply: the decoded reply (typed, the family's).
        tick: the index of the tick whose command it answers (the tick at whose deadline it left).
        age_ticks: the asking tick's index minus ``tick``.
        age_s: the asking tick's start minus when that command left: an upper bound on the
            measurement's age.
        received_at: when the reply came in (the loop's clock).
        fresh: a reply came since the previous tick started.
    """

    reply: Reply
    tick: int
    age_ticks: int
    age_s: float
    received_at: float
    fresh: bool


_new_state = tuple.__new__


class LoopTick:
    """One tick of a :class:`Loop`: the pacer's (:class:`servobus.ticks.Tick`) fields, what the loop
    saw, the motors' states, and where the next tick's commands are given.

    Attributes:
        index, deadline, started, late_s, skipped: as :class:`servobus.ticks.Tick`.
        overrun: the previous body ran past this tick's deadline.
        stale: motors commanded before with no fresh state (no reply since the previous tick started).
        sent: requests handed to their links at this deadline.
        commands_late: of the previous tick's commands, those that did not leave before this
            tick's deadline (0: every one left within its tick); one whose send report has not
            come yet counts here (``LoopMetrics.commands_on_time`` judges it when it comes).
    """

    __slots__ = (
        "_loop",
        "_since",
        "commands_late",
        "deadline",
        "index",
        "late_s",
        "overrun",
        "sent",
        "skipped",
        "stale",
        "started",
    )

    def __init__(
        self,
        loop: LoopHost,
        index: int,
        deadline: float,
        started: float,
        skipped: int,
        overrun: bool,
        stale: int,
        sent: int,
        since: float,
        commands_late: int,
    ) -> None:
        self._loop = loop
        self.commands_late = commands_late
        self.index = index
        self.deadline = deadline
        self.started = started
        self.late_s = started - deadline
        self.skipped = skipped
        self.overrun = overrun
        self.stale = stale
        self.sent = sent
        self._since = since

    def state(self, motor: Motor) -> MotorState | None:
        """``motor``'s latest state as of this tick's start (None: no reply by then, or a motor the
        loop never commanded). A reply taken in while the body awaits is the next tick's."""
        track = self._loop.tracks.get(motor)
        if track is None or track.reply is None:
            return None
        started = self.started
        if track.received_at <= started:  # (the common case)
            reply, tick, received_at, sent_s = track.reply, track.tick, track.received_at, track.sent_s
        elif track.previous is not None:  # (if it came during the body too, it is the older one)
            reply, tick, received_at, sent_s = track.previous
        else:
            return None
        # (MotorState's own __new__ is a Python function: tuple.__new__ makes the same tuple, in C)
        return _new_state(
            MotorState,
            (reply, tick, self.index - tick, started - sent_s, received_at, received_at >= self._since),
        )

    def command(self, motor: Motor, command: Command) -> None:
        """``command`` goes to ``motor`` at the next tick's deadline (a second one this tick replaces
        it, counted ``superseded``; the motor's command of this tick, if still queued then, is
        withdrawn there, not here: it may still leave within its own tick). A command out of range
        raises ValueError at that deadline, before any frame of the tick leaves."""
        loop = self._loop
        track = loop.tracks.get(motor)
        if track is None:
            track = loop.add(motor)
        if loop.commands.setdefault(motor, command) is not command:
            loop.commands[motor] = command
            loop.counts.superseded += 1
