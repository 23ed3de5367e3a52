"""What a :class:`~servobus.loop.Loop` knows of each motor it commands (:class:`Track`): its latest
state and the FIFO of its commands still outstanding, to which each reply is attributed in order;
it is also the context the Bus settles those requests' outcomes into."""

from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING, Any

from servobus.bus.pipeline import Superseded
from servobus.errors import MotorNotExecuted, ProtocolError
from servobus.frame import Frame
from servobus.protocols import Command, Reply
from servobus.scheduler import RequestState

if TYPE_CHECKING:
    from servobus.bus import Bus, Motor
    from servobus.scheduler import Request

__all__ = ["Counts", "Track", "not_pipelined"]

_QUEUED, _FAILED = RequestState.QUEUED, RequestState.FAILED
#: round trips a motor's replies must have shown before a reply is taken to show a loss (resync)
_RESYNC_SAMPLES = 16
#: replies in a row that show the FIFO's front lost before it is dropped (resync)
_RESYNC_REPLIES = 3


class Counts:
    """The counters the motors' records and the contexts add to (one object, shared)."""

    __slots__ = ("lost", "not_sent", "superseded", "throttled")

    def __init__(self) -> None:
        self.lost = 0
        self.not_sent = 0
        self.superseded = 0
        self.throttled = 0


class Track:
    """What the loop knows of one motor: its latest reply (which tick it answers, when that command
    left, when it came) and the FIFO of its commands still outstanding ((tick, request), oldest
    first). It is also the context (``request.context``) of every request the loop sends the motor:
    the Bus settles each outcome into it as into a waiter (``done``, ``set_result``,
    ``set_exception``, ``cancel``, ``cancelled``), with no object per request."""

    __slots__ = (
        "bus",
        "command",
        "commanded",
        "counts",
        "fifo",
        "motor",
        "period_s",
        "previous",
        "received_at",
        "reply",
        "rtt_max_s",
        "rtt_min_s",
        "samples",
        "sent_s",
        "suspect",
        "taken",
        "tick",
        "time",
        "wrote",
    )

    def __init__(self, motor: Motor, counts: Counts, time: Any, period_s: float) -> None:
        self.motor = motor
        self.bus: Bus = motor.bus  # type: ignore[assignment]
        self.counts = counts
        self.time = time
        self.period_s = period_s
        self.fifo: deque[tuple[int, Request]] = deque()
        self.reply: Reply | None = None
        self.tick = -1
        self.sent_s = 0.0
        self.received_at = -1.0
        #: the longest round trip a reply attributed here took (the horizon is at least twice it)
        self.rtt_max_s = 0.0
        self.rtt_min_s = math.inf  # (and the shortest)
        self.samples = 0  # (how many round trips those two were taken from)
        self.suspect = 0  # replies in a row that showed the front's reply lost (``shifted``)
        self.taken: Reply | None = None  # the last reply taken (settled twice, it counts once)
        #: the state before the latest: (reply, tick, received_at, sent_s), for a tick that asks
        #: after a newer reply came in during its body (it sees the state as of its start)
        self.previous: tuple[Reply, int, float, float] | None = None
        self.commanded = False
        self.wrote = False  # (a command that is not a read: the motor gets the safe stop)
        self.command: Command | None = None  # (the next tick's, while it is being sent)

    # ---- a waiter's interface, for the Bus (servobus.bus.delivery.Delivery.settle) ----

    # Never done (every outcome is taken), never cancelled: ``bool()`` is False, and a C call (done()
    # is asked once per reply).
    done = cancelled = staticmethod(bool)

    def cancel(self) -> bool:
        return False

    def set_exception(self, error: BaseException) -> None:
        """One of the motor's requests ended without a reply: a timeout stays outstanding (its late
        reply may still come, in order); a reply that does not decode answered, in order; the others
        never left (dropped from the FIFO when they come to its front)."""
        if isinstance(error, ProtocolError | MotorNotExecuted):
            self.answered(None, spoiled=True)
        elif isinstance(error, Superseded):
            self.counts.superseded += 1

    # ---- attribution ----

    def answered(self, reply: Reply | None, spoiled: bool = False) -> None:
        """A reply came (the Bus matched it to one of this motor's requests, or it is the late reply
        of one that timed out: :meth:`late`): it answers the OLDEST outstanding command. ``reply``
        None: a command with no reply left (nothing to attribute), or with ``spoiled`` the motor
        answered in a way that does not decode (it took its place in the order all the same).

        No command is given up on here, however old: a reply taken in after a stall of the loop may
        be the oldest's, and skipping it would make the state younger than it is (:meth:`expire`
        gives them up, at a tick's start)."""
        if reply is None and not spoiled:
            return
        if reply is not None:
            if reply is self.taken:
                return  # (the same outcome settled again: one reply answers one command)
            self.taken = reply
        # (when it came in: the intake stamped the motor just before; no clock read per reply)
        now = self.motor.last_seen if reply is not None else None
        if now is None:
            now = self.time()
        fifo = self.fifo
        while fifo:
            tick, request = fifo[0]
            left = request.sent_at
            if left is None:
                left = request.handed_at
                if left is None or request.state is _FAILED:
                    if request.state is _QUEUED:
                        return  # (nothing older is outstanding: not ours to attribute)
                    self.dropped(request)
                    continue
            if reply is not None and now - left > self.rtt_max_s + 0.5 * self.period_s and self.shifted(now):
                self.suspect += 1
                if self.suspect >= _RESYNC_REPLIES:  # the front's reply was lost: this is the next's
                    self.suspect = 0
                    fifo.popleft()
                    self.counts.lost += 1
                    continue
                fifo.popleft()  # (in doubt meanwhile: the front's, a tick older, never younger)
            else:
                self.suspect = 0
                fifo.popleft()
                if reply is not None:
                    rtt_s = now - left
                    self.samples += 1
                    if rtt_s > self.rtt_max_s:
                        self.rtt_max_s = rtt_s
                    if rtt_s < self.rtt_min_s:
                        self.rtt_min_s = rtt_s
            if reply is not None and tick >= self.tick:
                if self.reply is not None:
                    self.previous = (self.reply, self.tick, self.received_at, self.sent_s)
                self.reply, self.tick, self.received_at, self.sent_s = reply, tick, now, left
            return

    def shifted(self, now: float) -> bool:
        """A reply came ``now``, later after the FIFO's front left than any of enough replies of the
        motor took, by more than their spread (and half a period), yet the next entry left a round
        trip within those seen before: the front's reply may have been lost. Only
        ``_RESYNC_REPLIES`` such replies in a row drop the front (counted ``lost``): a stall of
        the host delays replies once, a loss shifts every later one."""
        fifo = self.fifo
        if self.samples < _RESYNC_SAMPLES or len(fifo) < 2:
            return False
        left, after = fifo[0][1].sent_at, fifo[1][1].sent_at
        if left is None or after is None:
            return False
        if now - left <= self.rtt_max_s + max(0.5 * self.period_s, self.rtt_max_s - self.rtt_min_s):
            return False
        return self.rtt_min_s <= now - after <= self.rtt_max_s

    #: the Bus settles a request's reply here (None: a command with no reply left)
    set_result = answered

    def late(self, reply: Reply, frame: Frame) -> None:
        """The late reply of one of the motor's requests that timed out (``MotorRecord.late``, called
        by the Bus's intake): taken in order if it has the key of the loop's commands (else it was
        another caller's)."""
        key = self.motor.codec.classify(frame)[1]
        if any(request.key == key for _, request in self.fifo):
            self.answered(reply)

    def dropped(self, request: Request) -> None:
        """The FIFO's front never left: withdrawn (counted superseded), or the link refused it."""
        self.fifo.popleft()
        if request.state is _FAILED:
            self.counts.not_sent += 1

    def expire(self, now: float) -> None:
        """Drop the commands that can no longer be answered: never left (superseded, refused), or
        outstanding past their horizon (twice the request's timeout, as the scheduler holds a key
        for a late reply, or twice the longest round trip seen of the motor if longer, plus a
        period; counted ``lost``): a reply still coming is never given up on."""
        fifo = self.fifo
        while fifo:
            request = fifo[0][1]
            left = request.sent_at
            if left is None:
                left = request.handed_at
                if left is None or request.state is _FAILED:
                    if request.state is _QUEUED:
                        return  # (waits for its turn)
                    self.dropped(request)
                    continue
            if now - left <= max(2.0 * request.timeout_s, 2.0 * self.rtt_max_s) + self.period_s:
                return
            fifo.popleft()
            self.counts.lost += 1


def not_pipelined(request: Request) -> bool:
    return not request.pipelined
