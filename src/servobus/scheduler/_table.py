"""The request table: a request's life (:class:`Request`, :class:`RequestState`, :data:`TRANSITIONS`),
the verdict on a received frame (:class:`Received`, :class:`Traffic`), and :class:`RequestTable`, the
one owner of the bus's requests (queued, in flight by key, their deadlines) and the only code that
moves one, through :meth:`RequestTable.move`, checked against :data:`TRANSITIONS`.

(servobus.scheduler re-exports the vocabulary; import it from there.) Sans-IO: ``now`` is always an
argument.
"""

from __future__ import annotations

import enum
from collections import deque
from collections.abc import Hashable, Iterable, Sequence
from dataclasses import dataclass
from heapq import heapify, heappop, heappush
from typing import Any, NoReturn

from servobus.errors import ProtocolError, RequestStateError, TransportError
from servobus.frame import Frame
from servobus.protocols import BoundCodec, Command, Reply
from servobus.rtt import Estimates, RoundTrip
from servobus.timing import format_duration

__all__ = [
    "FINAL",
    "FROM",
    "TRANSITIONS",
    "Received",
    "Request",
    "RequestState",
    "RequestTable",
    "Traffic",
    "early_room",
    "note_answer",
    "passes",
]


class RequestState(enum.Enum):
    QUEUED = "queued"
    SENDING = "sending"
    SENT = "sent"
    REPLIED = "replied"
    TIMED_OUT = "timed out"
    CANCELLED = "cancelled"
    FAILED = "failed"

    # Members are singletons compared by identity: their hash is the object's (a C call), not
    # Enum's (a Python call on the name), so a look-up in TRANSITIONS is cheap on the hot path.
    __hash__ = object.__hash__


S = RequestState
#: Every legal move; anything else is a bug in the caller and raises RequestStateError naming the
#: request. (SENDING -> TIMED_OUT: the link never reported the frame, and its provisional deadline
#: passed.)
TRANSITIONS: dict[RequestState, frozenset[RequestState]] = {
    S.QUEUED: frozenset({S.SENDING, S.CANCELLED, S.FAILED}),
    S.SENDING: frozenset({S.SENT, S.REPLIED, S.TIMED_OUT, S.CANCELLED, S.FAILED}),
    S.SENT: frozenset({S.REPLIED, S.TIMED_OUT, S.QUEUED, S.CANCELLED, S.FAILED}),
    S.REPLIED: frozenset(),
    S.TIMED_OUT: frozenset(),
    S.CANCELLED: frozenset(),
    S.FAILED: frozenset(),
}
FINAL = frozenset(state for state, allowed in TRANSITIONS.items() if not allowed)
#: The table read backwards: the states a request may come to each state from. A tuple: the hot
#: paths check a move with ``state in FROM[to]``, which compares by identity first (no hashing).
FROM: dict[RequestState, tuple[RequestState, ...]] = {
    to: tuple(at for at, allowed in TRANSITIONS.items() if to in allowed) for to in RequestState
}


def illegal(request: Request, to: RequestState) -> NoReturn:
    raise RequestStateError(f"{request.describe()}: {request.state.value} -> {to.value} is not allowed")


class Traffic(enum.Enum):
    """What a received frame was to the scheduler (each kind is counted)."""

    REPLY = "reply"  # resolved a request
    STREAM = "stream"  # a motor's 0xB6 frame (may also have answered a read of the streamed command)
    REPORT = "report"  # an automatic error report
    LATE = "late"  # the reply of a request that timed out or was cancelled
    DUPLICATE = "duplicate"  # the same reply again, right after one resolved its request
    UNSOLICITED = "unsolicited"  # a reply-shaped frame of one of our motors that nobody asked for
    MALFORMED = "malformed"  # one of our motors' frames that does not decode
    FOREIGN = "foreign"  # not ours: another node, our own loop-back
    EARLY = "early"  # came before its request's send report: judged (and counted) when that comes
    NOT_EXECUTED = "not_executed"  # the request's own bytes back: echoed, not executed (it failed)
    OTHER_HOST = "other host"  # another host's request to one of our motors (CAN is broadcast)
    CONTENDED = "contended"  # the reply to another host's request: the motor's state, never ours


@dataclass(eq=False, slots=True)
class Request:
    """One command to one motor and what became of it."""

    codec: BoundCodec
    command: Command
    frame: Frame
    key: Hashable | None
    timeout_s: float
    retries: int = 0
    context: Any = None  # the caller's (the Bus keeps its future here)
    # The round-trip estimate of its motor and command class; with ``adaptive`` its ``timeout_s`` is
    # set from it when the frame leaves (``rtt.base_s``: the codec's own time for the command).
    rtt: RoundTrip | None = None
    adaptive: bool = False
    # A command that changes the motor (not safe to repeat): its freshness counts from ``queued_at``,
    # stamped by the scheduler when it is submitted.
    writes: bool = False
    state: RequestState = RequestState.QUEUED
    sent_at: float | None = None
    deadline: float | None = None
    reply: Reply | None = None
    error: BaseException | None = None
    attempts: int = 0
    submitted: bool = False
    queued_at: float | None = None
    handed_at: float | None = None  # when its frame was last handed to the link
    # The bytes it sent, when a reply that is those bytes means "echoed, not executed" (the codec's
    # ``may_echo``): compared only then, so other requests cost one attribute read per reply.
    echo: bytes | None = None
    looped: bool = False  # its own frame came back from the link already (an adapter's loop-back)
    on_wire_at: float | None = None  # when that loop-back says it ended on the wire (None: unknown)
    # Another host's request crossed it in an order that cannot be known: it takes the later reply
    # (counted ``ambiguous`` once; servobus.scheduler._hosts).
    crossed: bool = False
    # It may leave while requests with its key are in flight or held (a pipelined loop's command,
    # repeated every tick): its reply is matched in order like any other, the oldest first.
    pipelined: bool = False

    def describe(self) -> str:
        return f"{self.codec.family} motor {self.codec.motor_id} {type(self.command).__name__}"


@dataclass(slots=True)
class Received:
    """The verdict on one received frame."""

    traffic: Traffic
    frame: Frame
    codec: BoundCodec | None = None
    reply: Reply | None = None
    request: Request | None = None  # the request it resolved
    error: ProtocolError | None = None


# Enum members as module globals for the hot paths: in Python 3.11 ``RequestState.SENT`` is a
# metaclass attribute lookup (~55 ns, several per exchange), a global is one dict read.
_QUEUED = RequestState.QUEUED
_SENDING = RequestState.SENDING
_SENT = RequestState.SENT
_FAILED = RequestState.FAILED
_NOTHING: tuple[Sequence[Request], Sequence[Request]] = ((), ())


class RequestTable:
    """The requests of one bus and the motors they go to: queued (FIFO), in flight (in send order,
    and by reply key: the FIFO of requests waiting for a key), their deadlines (a heap), and the
    pacing of what leaves when. Every move of a request is made by :meth:`move`.

    Attributes (read by the scheduler's parts; changed only here, but for ``queue``, which
    ``Scheduler.submit`` appends to):
        motors: reply identifier -> the motors answering on it (their bound codecs).
        queue: the requests not yet handed to the link, in order.
        pending: reply key -> the requests in flight with that key, oldest first.
        in_flight: the requests SENDING or SENT, in send order.
        early: reply key -> a reply-shaped frame that came before its request's send report.
        answers: reply key -> the shortest round trip of a pipelined request's reply, the last's bytes
            and stamp (those bytes again: a duplicate, ``_match.REPEATED``).
        ordinary_held: reply key -> until when it is held for an ORDINARY request's late reply.
    """

    def __init__(
        self,
        name: str,
        max_in_flight: int,
        one_at_a_time: bool,
        gap_s: float,
        min_reply_s: float,
        stale_after_s: float | None,
        report_within_s: float | None,
        estimates: Estimates,
    ) -> None:
        self.name = name
        self.estimates = estimates  # (what times an adaptive request when it leaves)
        self.max_in_flight = 1 if one_at_a_time else max_in_flight
        self.one_at_a_time = one_at_a_time
        self.gap_s = gap_s
        self.min_reply_s = min_reply_s
        self.stale_after_s = stale_after_s
        self.report_within_s = report_within_s
        self.motors: dict[int, list[BoundCodec]] = {}
        self.queue: deque[Request] = deque()
        self.pending: dict[Hashable, deque[Request]] = {}
        self.in_flight: dict[Request, None] = {}
        self.early: dict[Hashable, tuple[BoundCodec, Frame]] = {}
        self.early_more: dict[Hashable, deque[tuple[BoundCodec, Frame]]] = {}  # (later requests')
        self.answers: dict[Hashable, tuple[float, bytes, float]] = {}
        self.ordinary_held: dict[Hashable, float] = {}
        self.deadlines: list[tuple[float, int, Request]] = []  # a heap; entries of left requests stay
        self.provisional: list[Request] = []  # sent before anything was measured: timed again then
        self._overtaken: list[Request] = []  # timed out by a reply stamped after their deadline
        self._audit_at: float | None = None  # when to look for sends never reported (report_within_s)
        self._sent_count = 0  # a tie-breaker for the heap
        self._rest_until = 0.0

    def add_motor(self, codec: BoundCodec) -> None:
        for ident in codec.reply_ids | codec.shared_ids:
            self.motors.setdefault(ident & 0x1FFFFFFF, []).append(codec)

    # ---- moves ----

    def move(self, request: Request, to: RequestState, now: float) -> tuple[BoundCodec, Frame] | None:
        """Move ``request`` to ``to`` at ``now``, and keep the table in step: handed over (SENDING:
        in flight), its frame left (SENT at ``now``: its deadline, ``now`` plus its ``timeout_s``,
        starts; an adaptive request's timeout is set then, from the estimates), or out of the queue
        or out of flight (back to the queue's front for a retry).

        Returns:
            A reply-shaped frame with its key that came before a send report that never came (the
            request left flight without it): for the caller to judge as unmatched.

        Raises:
            RequestStateError: :data:`TRANSITIONS` does not allow it (a bug in the caller).
        """
        at = request.state
        if at not in FROM[to]:  # (a tuple: compared by identity first)
            illegal(request, to)
        request.state = to
        if to is _SENT:
            request.sent_at = now
            rtt = request.rtt
            if request.adaptive and rtt is not None:
                if rtt.samples:  # (Estimates.timeout_s, written out for the hot path)
                    timeout = rtt.rto_s
                    if timeout < rtt.floor_s:
                        timeout = rtt.floor_s
                    elif timeout > self.estimates.max_timeout_s:
                        timeout = self.estimates.max_timeout_s
                    request.timeout_s = timeout
                else:
                    request.timeout_s = self._first_timeout(request, rtt)
            request.deadline = deadline = now + request.timeout_s
            self._sent_count += 1
            heap = self.deadlines
            heappush(heap, (deadline, self._sent_count, request))
            if len(heap) > 64 + 4 * len(self.in_flight):  # answered ones under a long timeout pile up
                heap[:] = [e for e in heap if e[2].state in _OUT and e[2].deadline == e[0]]
                heapify(heap)
            return None
        key = request.key
        if at is _QUEUED:
            if to is _SENDING:
                request.attempts += 1
                request.handed_at = now
                self.in_flight[request] = None
                if key is not None:
                    waiting = self.pending.get(key)
                    if waiting is None:
                        self.pending[key] = deque((request,))
                    else:  # (a broadcast's, expected: see Scheduler.expect)
                        waiting.append(request)
            elif request in self.queue:  # (a stale one was taken off the queue already)
                self.queue.remove(request)
            return None
        # Out of flight (SENDING or SENT to anything but SENT). (A SENT one's: a later request's.)
        dropped = self.early.pop(key, None) if at is _SENDING and self.early and key in self.early else None
        if dropped is not None:
            self.early_more.pop(key, None)
        if self.in_flight.pop(request, 0) is None and self.one_at_a_time:  # None: it was in flight
            self._rest_until = now + self.gap_s
        if key is not None:
            waiting = self.pending.get(key)
            if waiting is not None:
                if waiting[0] is request:
                    waiting.popleft()
                elif request in waiting:  # (a retry already left the deque)
                    waiting.remove(request)
                if not waiting:
                    del self.pending[key]
        if to is _QUEUED:  # a retry: first in line, timed when it leaves again
            request.deadline = None
            self.queue.appendleft(request)
        return dropped

    def take(self, now: float, held: dict[Hashable, float]) -> tuple[Sequence[Request], Sequence[Request]]:
        """Pacing: the requests that may leave now, in order (moved to SENDING), and the commands that
        waited longer than ``stale_after_s`` for their turn (moved to FAILED). At most
        ``max_in_flight`` out at once; a half-duplex line rests ``gap_s`` after each exchange; a
        request whose key is in flight or ``held`` (for a late reply) waits, keeping its place,
        unless it is ``pipelined`` and :func:`passes` lets it."""
        if self._rest_until:
            if now < self._rest_until:
                return _NOTHING
            self._rest_until = 0.0  # the rest is over (and no longer a deadline)
        queue = self.queue
        if not queue:
            return _NOTHING
        out: list[Request] = []
        stale: list[Request] = []
        waiting: deque[Request] = deque()
        limit = self.stale_after_s
        pending, in_flight, move = self.pending, self.in_flight, self.move
        while queue and len(in_flight) < self.max_in_flight:
            request = queue.popleft()
            if limit is not None and request.queued_at is not None and now - request.queued_at > limit:
                request.error = TransportError(
                    f"{self.name}: {request.describe()} not sent (stale: waited its turn longer than "
                    f"{format_duration(limit)}, the link's stale_after_s)"
                )
                move(request, _FAILED, now)
                stale.append(request)
                continue
            key = request.key
            busy = key is not None and (key in pending or key in held)
            if busy and not (request.pipelined and passes(self, key, now)):
                waiting.append(request)
                continue
            move(request, _SENDING, now)
            out.append(request)
        waiting.extend(queue)
        self.queue = waiting
        if out and self._audit_at is None and self.report_within_s is not None:
            self._audit_at = now + self.report_within_s  # (see overdue)
        return out, stale

    def take_early(self, key: Hashable) -> tuple[BoundCodec, Frame] | None:
        """The frame with ``key`` that came before its request's send report, if one did (once)."""
        first = self.early.pop(key, None)
        if first is not None and self.early_more.get(key):  # (the next request's comes first next)
            self.early[key] = self.early_more[key].popleft()
        return first

    def keep_early(self, key: Hashable, codec: BoundCodec, frame: Frame) -> None:
        """A reply-shaped ``frame`` with ``key`` came before its request's send report: kept to be
        judged when the report says when the request left (in order: :func:`early_room`)."""
        if key in self.early:
            self.early_more.setdefault(key, deque()).append((codec, frame))
        else:
            self.early[key] = (codec, frame)

    def overtaken(self, request: Request) -> None:
        """``request`` timed out by a reply stamped after its deadline: :meth:`overdue` says so next."""
        self._overtaken.append(request)

    def retime(self) -> None:
        """The bus's first round trip was measured: requests timed by the conservative first value
        get the timeouts the estimates give now (if shorter)."""
        for waiting in self.provisional:
            if waiting.state is _SENT and waiting.adaptive and waiting.sent_at is not None:
                assert waiting.rtt is not None
                timeout = self.estimates.timeout_s(waiting.rtt)
                if timeout is not None and timeout < waiting.timeout_s:
                    waiting.timeout_s = timeout
                    waiting.deadline = deadline = waiting.sent_at + timeout
                    self._sent_count += 1
                    heappush(self.deadlines, (deadline, self._sent_count, waiting))
        self.provisional = []

    def _first_timeout(self, request: Request, rtt: RoundTrip) -> float:
        """The timeout of an adaptive request whose command class was never measured; while nothing
        on the bus was, a conservative first value, and the request is timed again by :meth:`retime`."""
        timeout = self.estimates.timeout_s(rtt)
        if timeout is not None:
            return timeout
        provisional = self.provisional
        if len(provisional) >= 64:  # (nothing answers: keep only those still waiting)
            provisional[:] = [r for r in provisional if r.state is _SENT]
        provisional.append(request)
        return max(rtt.base_s, self.estimates.initial_timeout_s)

    # ---- deadlines ----

    def overdue(self, now: float) -> tuple[list[Request], list[Request]]:
        """The requests overtaken since last asked (timed out already), and those whose deadline
        passed (SENT, or SENDING past a provisional deadline: see :meth:`_audit`), in order."""
        if self._audit_at is not None and self._audit_at <= now:
            self._audit(now)
        overtaken, self._overtaken = self._overtaken, []
        due: list[Request] = []
        heap = self.deadlines
        while heap and heap[0][0] <= now:
            deadline, _, request = heappop(heap)
            if request.deadline == deadline and request.state in _OUT:  # (else: left, or timed again)
                due.append(request)
        return overtaken, due

    def _audit(self, now: float) -> None:
        """Look for requests handed over ``report_within_s`` ago or longer that got no send report:
        each gets a provisional deadline (that long after it was handed over, plus its timeout; a
        report that still comes times it from when it left instead). The next audit is due when
        the next of the others would be overdue. (An audit, not a record per request: the hot path
        only stamps ``handed_at``.)"""
        within = self.report_within_s
        assert within is not None
        self._audit_at = None
        for request in self.in_flight:
            if request.state is not _SENDING or request.deadline is not None or request.handed_at is None:
                continue  # (reported, or already given its provisional deadline)
            due = request.handed_at + within
            if due > now:
                if self._audit_at is None or due < self._audit_at:
                    self._audit_at = due
                continue
            request.deadline = deadline = due + request.timeout_s
            self._sent_count += 1
            heappush(self.deadlines, (deadline, self._sent_count, request))

    def due(self, now: float) -> bool:
        """Whether :meth:`overdue` at ``now`` has a request to time out."""
        if self._overtaken or (self._audit_at is not None and self._audit_at <= now):
            return True
        first = self._first_deadline()
        return first is not None and first <= now

    def _first_deadline(self) -> float | None:
        """The earliest deadline of a request still out (entries of requests that left, were
        answered or were timed again are dropped on the way)."""
        heap = self.deadlines
        while heap and (
            heap[0][2].deadline != heap[0][0]
            or (heap[0][2].state is not _SENT and heap[0][2].state is not _SENDING)
        ):
            heappop(heap)  # the request left (replied, cancelled) or was sent again
        return heap[0][0] if heap else None

    def next_deadline(self, held: dict[Hashable, float]) -> float | None:
        """When :meth:`overdue` or :meth:`take` next has something to do (None: nothing); ``held``:
        the keys held for a late reply, and until when."""
        if not self.in_flight:
            self.deadlines.clear()  # every entry is of a request that left (a whole tick answered: at once)
            self._audit_at = None
            if not self._overtaken and not self.queue:
                return None  # (the common case after a burst was answered, without building a list)
        first = self._first_deadline()
        times = [first] if first is not None else []
        if self._overtaken:  # (missed already: for overdue() to say so)
            times.append(min(r.deadline or 0.0 for r in self._overtaken))
        if self._audit_at is not None:
            times.append(self._audit_at)
        if self.queue and len(self.in_flight) < self.max_in_flight:
            if self._rest_until:
                times.append(self._rest_until)
            if held:
                times.append(min(held.values()))
        return min(times) if times else None

    def flying(self, keys: Iterable[Hashable]) -> list[Request]:
        """The requests in flight with one of ``keys``."""
        return [request for key in keys for request in self.pending.get(key, ())]

    def unanswered(self, queued_only: bool) -> list[Request]:
        """The requests not yet answered (``queued_only``: not yet handed over), sent ones first."""
        return [*self.queue] if queued_only else [*self.in_flight, *self.queue]


_OUT = frozenset({_SENDING, _SENT})


def passes(table: RequestTable, key: Hashable, now: float) -> bool:
    """Whether a pipelined request with ``key`` may leave past what is in flight or held with it:
    only pipelined requests of its key and the holds they caused (an ordinary request's reply, or
    late reply, must never answer it, nor it the other's)."""
    if table.ordinary_held.get(key, 0.0) > now:
        return False
    return all(request.pipelined for request in table.pending.get(key, ()))


def note_answer(table: RequestTable, key: Hashable, rtt_s: float, data: bytes, stamp: float) -> None:
    """A pipelined request with ``key`` took a reply of ``data`` stamped ``stamp`` after ``rtt_s``
    (``table.answers``)."""
    last = table.answers.get(key)
    table.answers[key] = (rtt_s if last is None or rtt_s < last[0] else last[0], data, stamp)


def early_room(table: RequestTable, key: Hashable) -> bool:
    """Whether an early frame with ``key`` may be kept: fewer are than requests with it await their
    send report (more is a duplicate)."""
    kept = (key in table.early) + len(table.early_more.get(key, ()))
    return kept < sum(1 for request in table.pending.get(key, ()) if request.state is _SENDING)
