"""The request scheduler of one bus: sans-IO, like the codecs below it (h11's model).

The Bus is its only caller. It hands the scheduler requests, the frames the transport received and
the transport's send reports, each with a clock value; the scheduler answers with decisions and keeps
every rule about matching and timing in this one file:

* **Matching** is by the key the motor's bound codec gives (``reply_key`` for a request, ``classify``
  for a frame); requests with equal keys wait in FIFO order. A frame whose key matches nothing is
  classified, never dropped silently: a **late** reply (to a request that timed out or was
  cancelled), a **duplicate** (the same key again right after a reply), a **stream** or **report**
  frame of a motor, an **unsolicited** reply, a frame of **another** node, or a **malformed** one (it
  claims to be a reply but does not decode). A malformed frame never resolves a request with data:
  the request waiting for its key FAILS with the codec's ProtocolError (the motor answered, in a way
  this codec cannot read), instead of timing out as if nothing came.
* **Life cycle** of a request (one table, :data:`TRANSITIONS`): QUEUED -> SENDING (handed to the
  transport) -> SENT (the transport reported when it left; the deadline starts there) -> REPLIED, or
  TIMED_OUT (deadline passed; a retry-safe read with retries left goes back to QUEUED), or CANCELLED,
  or FAILED (the transport never sent it, or was lost, or its reply did not decode). A request with
  no key (no reply expected) is REPLIED as soon as it left. Each is counted once, by its end.
* **Timing**: with no ``timeout_s`` of its own, a request's timeout comes from the round trips
  measured for its motor and command class (:class:`~servobus.rtt.RoundTrip`, RFC 6298); after a
  timeout its key is held for the late reply (``late_hold_s``), and a reply that comes after a hold
  ended without its late reply is counted ``ambiguous``.
* **Pacing**: at most ``max_in_flight`` requests SENDING or SENT at once; a half-duplex line
  (``one_at_a_time``) allows one, and rests ``gap_s`` after each exchange before the next frame.
* **Streams**: a request whose key a motor streams (0xB6) is answered by the first stream frame that
  arrives after the request left (the same fact, fresh), as design.md's matching rule says.

Nothing here reads a clock, sleeps or awaits: ``now`` is always an argument, so every timing rule is
tested with plain calls.
"""

from __future__ import annotations

import enum
import heapq
from collections import Counter, deque
from collections.abc import Hashable, Iterable
from dataclasses import dataclass, field
from typing import Any

from servobus.errors import ProtocolError
from servobus.frame import Frame
from servobus.metrics import LatencyWindow
from servobus.protocols import BoundCodec, Command, FrameKind, Reply, check_bus
from servobus.protocols._bound import KIND_NOT_OURS, KIND_REPLY, KIND_REPORT, KIND_STREAM
from servobus.rtt import RoundTrip

__all__ = [
    "TRANSITIONS",
    "Received",
    "Request",
    "RequestState",
    "Scheduler",
    "Traffic",
]


class RequestState(enum.Enum):
    QUEUED = "queued"
    SENDING = "sending"
    SENT = "sent"
    REPLIED = "replied"
    TIMED_OUT = "timed out"
    CANCELLED = "cancelled"
    FAILED = "failed"


S = RequestState
#: Every legal move; anything else is a bug in the caller and raises RuntimeError naming the request.
TRANSITIONS: dict[RequestState, frozenset[RequestState]] = {
    S.QUEUED: frozenset({S.SENDING, S.CANCELLED, S.FAILED}),
    S.SENDING: frozenset({S.SENT, S.REPLIED, S.CANCELLED, S.FAILED}),
    S.SENT: frozenset({S.REPLIED, S.TIMED_OUT, S.QUEUED, S.CANCELLED, S.FAILED}),
    S.REPLIED: frozenset(),
    S.TIMED_OUT: frozenset(),
    S.CANCELLED: frozenset(),
    S.FAILED: frozenset(),
}
FINAL = frozenset({S.REPLIED, S.TIMED_OUT, S.CANCELLED, S.FAILED})
# The same table as each state's ``next`` tuple: checked by identity on the hot path (an Enum's
# hash is a Python-level call).
for _state, _allowed in TRANSITIONS.items():
    _state.next = tuple(_allowed)  # type: ignore[attr-defined]


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
    state: RequestState = RequestState.QUEUED
    sent_at: float | None = None
    deadline: float | None = None
    reply: Reply | None = None
    error: BaseException | None = None
    attempts: int = 0
    submitted: bool = False
    queued_at: float | None = None  # when a command (not a read) was made: its freshness counts from here

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


# A request whose reply may still come: until when a frame with its key counts as late (the late
# window), when it left, its round-trip estimate, and until when its key is held for that reply.
_Late = tuple[float, float | None, RoundTrip | None, float]


@dataclass(slots=True)
class _Recent:
    """Keys that may still see a frame nobody waits for, and until when.

    Keys come and go (an echo's key holds the value written), so the tables are pruned of what has
    expired whenever they have grown past twice what the last pruning kept: amortised O(1), and
    bounded by the keys answered or given up on within the late window.
    """

    # key -> the requests whose reply may still come, oldest first (_Late)
    late: dict[Hashable, list[_Late]] = field(default_factory=dict)
    replied: dict[Hashable, float] = field(default_factory=dict)
    limit: int = 64

    def prune(self, now: float) -> None:
        self.replied = {key: until for key, until in self.replied.items() if until >= now}
        late: dict[Hashable, list[_Late]] = {}
        for key, entries in self.late.items():
            if kept := [e for e in entries if e[0] >= now]:
                late[key] = kept
        self.late = late
        self.limit = max(64, 2 * (len(self.replied) + len(late)))


#: Round trips an estimate must rest on before it bounds how late a reply may come (a late hold).
TRUSTED_SAMPLES = 16

# Enum members as module globals for the hot paths: in Python 3.11 ``RequestState.SENT`` is a
# metaclass attribute lookup (~55 ns, several per exchange), a global is one dict read.
_CANCELLED = S.CANCELLED
_FAILED = S.FAILED
_QUEUED = S.QUEUED
_REPLIED = S.REPLIED
_SENDING = S.SENDING
_SENT = S.SENT
_TIMED_OUT = S.TIMED_OUT
_T_DUPLICATE = Traffic.DUPLICATE
_T_EARLY = Traffic.EARLY
_T_FOREIGN = Traffic.FOREIGN
_T_LATE = Traffic.LATE
_T_MALFORMED = Traffic.MALFORMED
_T_REPLY = Traffic.REPLY
_T_UNSOLICITED = Traffic.UNSOLICITED


class Scheduler:
    """Pending requests of one bus, matched by key, paced, timed out, counted.

    Args:
        codecs: the motors on the bus (checked together with :func:`~servobus.protocols.check_bus`).
        max_in_flight: requests SENDING or SENT at once.
        one_at_a_time: a half-duplex line: one exchange at a time, ``gap_s`` of rest after each.
        gap_s: rest after an exchange before the next frame (half-duplex lines).
        late_window_s: how long after a timeout or cancel a frame with that key counts as LATE (and
            after a reply, as DUPLICATE) rather than UNSOLICITED.
        min_reply_s: the least time from a request leaving to its reply arriving (the two frames'
            wire time): a frame with the key that arrives sooner cannot be the reply.
        stale_after_s: a request with ``queued_at`` set (a command; reads are never stale) that
            waited longer than this for its turn (a stalled half-duplex line) fails ``not_sent_stale``
            instead of leaving: for a motor, a stale command is worse than none (None: no limit).
        late_hold_s: after a request that left times out or is cancelled, the next request with its
            key waits until the late reply came or this long passed (None: from when the request
            left, at least twice its timeout, and :meth:`_late_s`: the estimate's
            :meth:`~servobus.rtt.RoundTrip.late_s` once it rests on ``TRUSTED_SAMPLES`` round
            trips, before that twice the codec's own time). These protocols carry no sequence
            numbers: a reply later than the hold could answer the next request with the same key;
            such a reply is counted ``ambiguous``.
        initial_timeout_s: the timeout of a request (with no ``timeout_s`` of its own) sent before
            anything on the bus was measured: conservative, since the first exchange through a
            freshly opened adapter can be slow (RFC 6298's first RTO is 1 s). Requests sent with it
            are timed again by the first round trip measured.
        min_timeout_s, max_timeout_s: bounds of a timeout derived from measured round trips.

    Raises:
        ValueError: motors that cannot share a bus, or options out of range.
    """

    def __init__(
        self,
        codecs: Iterable[BoundCodec] = (),
        *,
        max_in_flight: int = 64,
        one_at_a_time: bool = False,
        gap_s: float = 0.0,
        late_window_s: float = 1.0,
        min_reply_s: float = 0.0,
        late_hold_s: float | None = None,
        stale_after_s: float | None = None,
        initial_timeout_s: float = 1.0,
        min_timeout_s: float = 0.005,
        max_timeout_s: float = 10.0,
    ) -> None:
        if (
            max_in_flight < 1
            or gap_s < 0
            or late_window_s < 0
            or (late_hold_s is not None and late_hold_s < 0)
        ):
            raise ValueError(
                f"max_in_flight={max_in_flight} must be >= 1, gap_s={gap_s}, "
                f"late_window_s={late_window_s} and late_hold_s={late_hold_s} >= 0"
            )
        if not 0 < min_timeout_s <= max_timeout_s or not min_timeout_s <= initial_timeout_s <= max_timeout_s:
            raise ValueError(
                f"timeouts must be 0 < min_timeout_s={min_timeout_s} <= "
                f"initial_timeout_s={initial_timeout_s} <= max_timeout_s={max_timeout_s}"
            )
        self.late_hold_s = late_hold_s
        self.initial_timeout_s = initial_timeout_s
        self.min_timeout_s = min_timeout_s
        self.max_timeout_s = max_timeout_s
        self._rtts: dict[int, dict[type, RoundTrip]] = {}  # id(codec) -> command class -> estimate
        self._any_measured = False
        self._provisional: list[Request] = []  # sent before anything was measured: timed again then
        self._doubtful: set[Hashable] = set()  # keys whose hold ended before their late reply came
        self.stale_after_s = stale_after_s
        self._stale: list[Request] = []
        self.max_in_flight = 1 if one_at_a_time else max_in_flight
        self.one_at_a_time = one_at_a_time
        self.gap_s = gap_s
        self.late_window_s = late_window_s
        self.min_reply_s = min_reply_s
        self.codecs: list[BoundCodec] = []
        self._by_id: dict[int, list[BoundCodec]] = {}
        self._queue: deque[Request] = deque()
        self._pending: dict[Hashable, deque[Request]] = {}
        self._in_flight: dict[Request, None] = {}  # SENDING or SENT, in send order
        self._deadlines: list[tuple[float, int, Request]] = []  # a heap; entries of left requests stay
        self._sent_count = 0  # a tie-breaker for the heap
        self._recent = _Recent()
        self._held: dict[Hashable, float] = {}  # key -> until when its next exchange waits
        self._early: dict[Hashable, tuple[BoundCodec, Frame]] = {}  # key -> a reply before its report
        self._rest_until = 0.0
        self._bus_counts: Counter[str] = Counter()  # frames of no motor
        # Per motor (by codec identity: a plug-in's codec need not be hashable); the bus's counts
        # are their sum, so the hot path counts once.
        self.motor_counts: dict[int, Counter[str]] = {}
        self.motor_latency: dict[int, LatencyWindow] = {}
        for codec in codecs:
            self.add(codec)

    # ---- motors ----

    def add(self, codec: BoundCodec) -> None:
        """Put a motor on the bus.

        Raises:
            ValueError: it collides with a motor already there (both named).
        """
        check_bus([*self.codecs, codec])
        self.codecs.append(codec)
        self.motor_counts[id(codec)] = Counter()
        self._rtts[id(codec)] = {}
        self.motor_latency[id(codec)] = LatencyWindow(1024)
        for ident in codec.reply_ids | codec.shared_ids:
            self._by_id.setdefault(ident & 0x1FFFFFFF, []).append(codec)

    # ---- requests ----

    def request(
        self,
        codec: BoundCodec,
        command: Command,
        *,
        timeout_s: float | None = None,
        retries: int = 0,
        context: Any = None,
    ) -> Request:
        """A request for ``command`` to ``codec``'s motor, encoded now (nothing is queued yet).

        Raises:
            ValueError: the command is refused by the codec (before any frame exists), a negative
                timeout or retry count, or retries asked for a command that is not safe to repeat.
        """
        rtts = self._rtts.get(id(codec))
        if rtts is None:
            raise ValueError(f"{codec!r} is not on this bus: add() it first")
        frame = codec.encode(command)
        base = codec.timeout_s(command)
        timeout = base if timeout_s is None else timeout_s
        if timeout <= 0 or retries < 0:
            raise ValueError(f"timeout_s={timeout} must be > 0 and retries={retries} >= 0")
        if retries and not codec.retry_safe(command):
            raise ValueError(f"{type(command).__name__} changes the motor: it is never retried automatically")
        rtt = rtts.get(type(command))
        if rtt is None:
            rtt = rtts[type(command)] = RoundTrip(base)
            self._set_floors(rtts)
        key = codec.reply_key(command)
        return Request(codec, command, frame, key, timeout, retries, context, rtt, timeout_s is None)

    def round_trip(self, codec: BoundCodec, command_class: type[Command]) -> RoundTrip | None:
        """The round-trip estimate of ``codec``'s motor for ``command_class`` (None: never sent)."""
        return self._rtts.get(id(codec), {}).get(command_class)

    def _measured(self) -> list[RoundTrip]:
        """Every estimate with a sample, of every motor and command class."""
        return [r for rtts in self._rtts.values() for r in rtts.values() if r.samples]

    def _set_floors(self, rtts: dict[type, RoundTrip]) -> None:
        """The least timeout of each command class of one motor: ``min_timeout_s``, and for a class
        its codec gives more time than its quickest class (a ROM write, the brake), that time."""
        quickest = min(r.base_s for r in rtts.values())
        for rtt in rtts.values():
            rtt.floor_s = max(self.min_timeout_s, rtt.base_s if rtt.base_s > quickest else 0.0)

    def _timeout(self, request: Request) -> float:
        """The timeout of an adaptive request leaving now (see the class docstring)."""
        rtt = request.rtt
        assert rtt is not None
        if rtt.samples:
            timeout = max(rtt.timeout_s(), rtt.floor_s)
        elif self._any_measured:
            # Not measured yet: the codec's own time for the command, or twice the slowest measured
            # on this bus if that is longer (the adapter's and the host's share is the same for all).
            link = max(r.timeout_s() for r in self._measured())
            timeout = max(rtt.base_s, 2.0 * link)
        else:
            provisional = self._provisional
            if len(provisional) >= 64:  # (nothing answers: keep only those still waiting)
                provisional[:] = [r for r in provisional if r.state is _SENT]
            provisional.append(request)
            return max(rtt.base_s, self.initial_timeout_s)
        return min(max(timeout, self.min_timeout_s), self.max_timeout_s)

    def _first_measured(self) -> None:
        """The bus's first round trip was measured."""
        self._any_measured = True
        if self._provisional:
            # The first measurement: requests timed by the conservative first value get real ones.
            for waiting in self._provisional:
                if waiting.state is _SENT and waiting.adaptive and waiting.sent_at is not None:
                    timeout = self._timeout(waiting)
                    if timeout < waiting.timeout_s:
                        waiting.timeout_s = timeout
                        waiting.deadline = deadline = waiting.sent_at + timeout
                        self._sent_count += 1
                        heapq.heappush(self._deadlines, (deadline, self._sent_count, waiting))
            self._provisional = []

    def submit(self, request: Request) -> None:
        """Queue ``request`` behind the others (FIFO)."""
        if request.submitted:
            where = "already queued" if request.state is _QUEUED else request.state.value
            raise RuntimeError(f"{request.describe()} is {where}: a request is submitted once")
        request.submitted = True
        self._queue.append(request)
        self.motor_counts[id(request.codec)]["requests"] += 1

    def blocking(self, keys: Iterable[Hashable], now: float) -> tuple[float | None, list[Request]]:
        """What a frame that skips the queue (a broadcast) waits for before it may go out: the requests
        in flight with one of ``keys``, and when the last hold of one of them ends (None: none held).

        Its replies come on ``keys``; while one is in flight or held for a late reply, a reply could
        answer the wrong request, as for a queued request (:meth:`next_to_send`).
        """
        held = self._held
        ends = [held[key] for key in keys if key in held and held[key] > now]
        flying = [request for key in keys for request in self._pending.get(key, ())]
        return (max(ends) if ends else None), flying

    @property
    def quiet(self) -> bool:
        """Nothing is in flight with a key and no key is held: no request would wait (:meth:`busy`)."""
        return not self._pending and not self._held

    def busy(self, key: Hashable | None, now: float) -> bool:
        """Would a request with ``key`` wait now: one with that key is in flight, or the key is held
        for a late reply (:meth:`next_to_send`)?"""
        if key is None:
            return False
        if key in self._pending:
            return True
        until = self._held.get(key)
        return until is not None and until > now

    def motor_timeout_s(self, codec: BoundCodec) -> float:
        """The longest timeout measured round trips give any command class of ``codec``'s motor
        (``min_timeout_s`` while none was measured)."""
        times = [r.timeout_s() for r in self._rtts.get(id(codec), {}).values() if r.samples]
        return max([self.min_timeout_s, *times])

    def expect(self, request: Request, at: float) -> None:
        """``request``'s frame was sent by someone else at ``at`` (a broadcast): it is in flight from
        then, past the queue and its pacing, and only awaits its reply. Nothing of :meth:`blocking`
        may be left for its key (the caller waited).

        Raises:
            RuntimeError: the request was submitted before.
        """
        if request.submitted:
            raise RuntimeError(f"{request.describe()} is {request.state.value}: a request is submitted once")
        request.submitted = True
        self.motor_counts[id(request.codec)]["requests"] += 1
        self._move(request, _SENDING)
        request.attempts += 1
        self._in_flight[request] = None
        if request.key is not None:
            self._pending.setdefault(request.key, deque()).append(request)
        self.sent(request, at)

    def next_to_send(self, now: float) -> list[Request]:
        """The requests that may leave now, in order (they become SENDING; write their frames).

        A request whose key is already on the wire waits for that exchange to end: two replies with
        one key cannot be told apart, so a duplicated or late frame could otherwise answer the
        second request with the first one's data.
        """
        out: list[Request] = []
        held = self._held
        if held:
            for key in [k for k, until in held.items() if until <= now]:
                del held[key]
                if self._recent.late.get(key):  # its late reply never came: it may come yet
                    self._doubtful.add(key)
        if self._rest_until:
            if now < self._rest_until:
                return out
            self._rest_until = 0.0  # the rest is over (and no longer a deadline)
        if not self._queue:
            return out
        waiting: deque[Request] = deque()
        queue = self._queue
        limit = self.stale_after_s
        pending, in_flight = self._pending, self._in_flight
        while queue and len(in_flight) < self.max_in_flight:
            request = queue.popleft()
            if limit is not None and request.queued_at is not None and now - request.queued_at > limit:
                request.error = RuntimeError(f"{request.describe()}: frame not sent (stale)")
                self._move(request, _FAILED)
                self._count(request.codec, "failed")
                self._count(request.codec, "not_sent_stale")
                self._stale.append(request)
                continue
            key = request.key
            if key is not None and (key in pending or key in held):
                waiting.append(request)
                continue
            request.state = _SENDING  # (QUEUED -> SENDING, in TRANSITIONS; the hot path)
            request.attempts += 1
            in_flight[request] = None
            if key is not None:
                pending[key] = deque((request,))
            out.append(request)
        waiting.extend(queue)
        self._queue = waiting
        return out

    def take_stale(self) -> list[Request]:
        """The requests :meth:`next_to_send` failed as stale since the last call (to tell their callers)."""
        stale, self._stale = self._stale, []
        return stale

    def sent(self, request: Request, at: float) -> Received | None:
        """The transport reports that ``request``'s frame left at ``at``: its deadline starts.

        Returns:
            The verdict on a reply-shaped frame with its key that came before this report (EARLY),
            now that the send time is known: the reply, or a duplicate or late frame.
        """
        if request.state is not _SENDING:
            return None  # cancelled while the frame was on its way
        request.sent_at = at
        if request.key is None:  # nothing to wait for
            self._finish(request, _REPLIED, at)
            self.motor_counts[id(request.codec)]["replies"] += 1
            return None
        request.state = _SENT  # (SENDING -> SENT, in TRANSITIONS; the hot path)
        if request.adaptive:
            rtt = request.rtt
            if rtt is not None and rtt.samples:  # (_timeout, written out for the hot path)
                timeout = rtt.rto_s
                if timeout < rtt.floor_s:
                    timeout = rtt.floor_s
                elif timeout > self.max_timeout_s:
                    timeout = self.max_timeout_s
                request.timeout_s = timeout
            else:
                request.timeout_s = self._timeout(request)
        request.deadline = deadline = at + request.timeout_s
        self._sent_count += 1
        heap = self._deadlines
        heapq.heappush(heap, (deadline, self._sent_count, request))
        if len(heap) > 64 + 4 * len(self._in_flight):  # answered ones under a long timeout pile up
            heap[:] = [e for e in heap if e[2].state is _SENT and e[2].deadline == e[0]]
            heapq.heapify(heap)
        early = self._early.pop(request.key, None) if self._early else None
        if early is None:
            return None
        codec, frame = early
        # An unstamped early reply came after the request was handed over, at an unknown time: in time.
        return self._ours(codec, KIND_REPLY, request.key, frame, frame.timestamp or at + self.min_reply_s)

    def not_sent(self, request: Request, reason: str, now: float) -> None:
        """The transport dropped ``request``'s frame (stale, purged, ...): it fails."""
        if request.state in FINAL:
            return
        request.error = RuntimeError(f"{request.describe()}: frame not sent ({reason})")
        self._finish(request, _FAILED, now)
        self._count(request.codec, f"not_sent_{reason}")

    def cancel(self, request: Request, now: float) -> None:
        """The caller gave up on ``request``; a reply that still comes is counted LATE."""
        if request.state in FINAL:
            return
        was_out = request.state in (_SENDING, _SENT)
        self._finish(request, _CANCELLED, now)
        if was_out and request.key is not None:
            self._expect_late(request, now)

    def fail_queued(self, error: BaseException, now: float) -> list[Request]:
        """Every request not yet handed to the transport fails with ``error`` (the Bus is closing)."""
        failed = list(self._queue)
        for request in failed:
            request.error = error
            self._finish(request, _FAILED, now)
        return failed

    def fail_all(self, error: BaseException, now: float) -> list[Request]:
        """The transport was lost: every request not yet answered fails with ``error``."""
        failed = [*self._in_flight, *self._queue]  # in the order they were sent or queued
        for request in failed:
            request.error = error
            self._finish(request, _FAILED, now)
        self._queue.clear()
        return failed

    # ---- time ----

    def expire(self, now: float) -> list[Request]:
        """Requests whose deadline passed: TIMED_OUT, or back in the queue's front for a retry."""
        expired: list[Request] = []
        heap = self._deadlines
        while heap and heap[0][0] <= now:
            deadline, _, request = heapq.heappop(heap)
            if request.state is _SENT and request.deadline == deadline:
                self._leave_flight(request, now)
                if request.attempts <= request.retries:
                    self._move(request, _QUEUED)
                    self._queue.appendleft(request)
                    self._count(request.codec, "retries")
                    if request.key is not None:  # the retry, too, waits out the late reply
                        self._expect_late(request, now)
                    continue
                self._move(request, _TIMED_OUT)
                self._count(request.codec, "timeouts")
                if request.key is not None:
                    self._expect_late(request, now)
                expired.append(request)
        return expired

    def _expect_late(self, request: Request, now: float) -> None:
        """``request`` left and its reply may still come: count it LATE, and hold its key meanwhile."""
        key = request.key
        if self.late_hold_s is not None:
            until = now + self.late_hold_s
        elif request.sent_at is None:  # (cancelled before its send report: its time is unknown)
            until = now + request.timeout_s
        else:
            until = request.sent_at + max(2.0 * request.timeout_s, self._late_s(request))
        recent = self._recent
        entries = recent.late.setdefault(key, [])
        if entries and entries[0][0] < now:  # (a motor that never answers: its entries expire)
            entries[:] = [e for e in entries if e[0] >= now]
        entries.append((now + self.late_window_s, request.sent_at, request.rtt, until))
        if len(recent.late) > recent.limit:
            recent.prune(now)
        if until > now:
            self._held[key] = max(until, self._held.get(key, until))

    def _late_s(self, request: Request) -> float:
        """How late ``request``'s reply may come after it left: from its estimate once that rests
        on ``TRUSTED_SAMPLES`` round trips; before, twice the codec's own time for the command, or
        the bus's slowest trusted estimate if longer. A tail guessed from a few samples is too
        short: the first replies through a jittery adapter said 1.1 ms where 11 ms came."""
        rtt = request.rtt
        if rtt is not None and rtt.samples >= TRUSTED_SAMPLES:
            return rtt.late_s()
        trusted = [r.late_s() for r in self._measured() if r.samples >= TRUSTED_SAMPLES]
        return max([2.0 * rtt.base_s if rtt is not None else 0.0, *trusted])

    def next_deadline(self) -> float | None:
        """When :meth:`expire` or :meth:`next_to_send` next has something to do (None: nothing)."""
        heap = self._deadlines
        if not self._in_flight:
            heap.clear()  # every entry is of a request that left (a whole tick answered: at once)
        while heap and (heap[0][2].state is not _SENT or heap[0][2].deadline != heap[0][0]):
            heapq.heappop(heap)  # the request left (replied, cancelled) or was sent again
        times = [heap[0][0]] if heap else []
        if self._queue and len(self._in_flight) < self.max_in_flight:
            if self._rest_until:
                times.append(self._rest_until)
            if self._held:
                times.append(min(self._held.values()))
        return min(times) if times else None

    # ---- receiving ----

    def receive(self, frame: Frame, now: float) -> Received:
        """Classify ``frame``, resolve the request it answers, count it."""
        for codec in self._by_id.get(frame.arbitration_id, ()):
            kind, key = codec.classify(frame)
            if kind is not KIND_NOT_OURS:
                return self._ours(codec, kind, key, frame, now)
        self._bus_counts["foreign"] += 1
        return Received(_T_FOREIGN, frame)

    def _ours(
        self, codec: BoundCodec, kind: FrameKind, key: Hashable | None, frame: Frame, now: float
    ) -> Received:
        try:
            reply = codec.decode(frame)
        except ProtocolError as exc:
            waiting = self._pending.get(key) if key is not None else None
            if waiting and waiting[0].state is _SENDING and kind is KIND_REPLY and key not in self._early:
                self._early[key] = (codec, frame)  # judged (and counted) when the send report comes
                return Received(_T_EARLY, frame, codec)
            self._count(codec, "malformed")
            return Received(_T_MALFORMED, frame, codec, error=exc, request=self._spoilt(key, frame, exc, now))
        waiting = self._pending.get(key) if key is not None else None
        if waiting:
            request = waiting[0]
            # A reply cannot arrive before its request left plus the two frames' wire time; a stream
            # frame answers a read only if it came after the request left (the same fact, fresh).
            if request.state is _SENDING and kind is KIND_REPLY:
                # It beat the transport's send report (a reader and a writer thread): judged when
                # the report says when the request left.
                if key in self._early:  # the same reply twice before the report
                    self._count(codec, _T_DUPLICATE.value)
                    return Received(_T_DUPLICATE, frame, codec, reply)
                self._early[key] = (codec, frame)
                return Received(_T_EARLY, frame, codec)
            sent_at = request.sent_at
            if kind is KIND_REPLY:
                # (an unstamped frame counts from ``now``, when it was taken in: 0.0 is no time)
                fresh = sent_at is None or (frame.timestamp or now) >= sent_at + self.min_reply_s
            else:
                fresh = sent_at is not None and frame.timestamp >= sent_at
            if request.state is _SENT and fresh:
                request.reply = reply
                # _leave_flight, written out for the hot path (a SENT request has no EARLY frame)
                waiting.popleft()
                if not waiting:
                    del self._pending[key]
                del self._in_flight[request]
                if self.one_at_a_time:
                    self._rest_until = now + self.gap_s
                request.state = _REPLIED  # (SENT -> REPLIED, in TRANSITIONS; the hot path)
                recent = self._recent
                recent.replied[key] = now + self.late_window_s
                if len(recent.replied) > recent.limit:
                    recent.prune(now)
                counts = self.motor_counts[id(codec)]
                counts["replies"] += 1
                if kind is KIND_REPLY:
                    traffic = _T_REPLY
                else:
                    traffic = Traffic(kind.value)
                    counts[traffic.value] += 1
                if sent_at is not None:
                    rtt_s = (frame.timestamp or now) - sent_at
                    self.motor_latency[id(codec)].add(rtt_s)
                    rtt = request.rtt
                    if rtt is not None and kind is KIND_REPLY:  # (a stream frame's time is not one)
                        rtt.add(rtt_s)
                        if not self._any_measured:
                            self._first_measured()
                if self._doubtful and key in self._doubtful:
                    self._doubtful.discard(key)
                    counts["ambiguous"] += 1  # it may be the reply of the request before
                return Received(traffic, frame, codec, reply, request)
        if kind is KIND_STREAM or kind is KIND_REPORT:
            self._count(codec, kind.value)
            return Received(Traffic(kind.value), frame, codec, reply)
        traffic = self._unmatched(key, now, frame.timestamp or now)
        self._count(codec, traffic.value)
        return Received(traffic, frame, codec, reply)

    def _spoilt(self, key: Hashable | None, frame: Frame, error: ProtocolError, now: float) -> Request | None:
        """A frame with ``key`` that does not decode came: the request waiting for it fails with the
        codec's error (the motor answered it, in a way this codec cannot read: a revision mismatch,
        a value out of the manual's range), instead of timing out as if nothing came."""
        waiting = self._pending.get(key) if key is not None else None
        if not waiting:
            return None
        request = waiting[0]
        at = frame.timestamp or now
        if request.state is not _SENT or request.sent_at is None or at < request.sent_at + self.min_reply_s:
            return None
        request.error = error.with_context(motor_id=request.codec.motor_id)
        self._finish(request, _FAILED, now)
        self._recent.replied[key] = now + self.late_window_s  # (the same frame again: a duplicate)
        return request

    def _unmatched(self, key: Hashable | None, now: float, at: float | None = None) -> Traffic:
        """What a frame with ``key`` that answers no request is; ``at``: when it was received."""
        recent = self._recent
        late = recent.late.get(key)
        if late:
            late[:] = [e for e in late if e[0] >= now]
            if late:
                # Replies come in order: the oldest request still held for is answered. One whose
                # hold ended was given up on (its reply lost, most likely): a frame now is not timed
                # against it, since one wrong sample of a second would stretch every timeout and
                # hold of the motor.
                held = [e for e in late if e[3] >= now]
                entry = held[0] if held else late[0]
                late.remove(entry)
                _, sent_at, rtt, _ = entry
                if held and sent_at is not None and at is not None and rtt is not None:
                    rtt.add_late(at - sent_at)
                    if not self._any_measured:
                        self._first_measured()
                if len(held) <= 1:  # the reply the key was held for came: the next exchange may go
                    self._held.pop(key, None)
                    if not late:  # (a request given up on before it may still be answered)
                        self._doubtful.discard(key)
                return _T_LATE
        until = recent.replied.get(key)
        if until is not None and until >= now:
            return _T_DUPLICATE
        return _T_UNSOLICITED

    # ---- bookkeeping ----

    @property
    def counts(self) -> Counter[str]:
        """Every counter of the bus: the motors' summed, and frames of no motor (``foreign``)."""
        total = Counter(self._bus_counts)
        for counts in self.motor_counts.values():
            total.update(counts)
        return total

    def latency(self) -> LatencyWindow:
        """The latencies of every motor's last replies, in one window."""
        window = LatencyWindow(sum(len(w) for w in self.motor_latency.values()) or 1)
        for motor in self.motor_latency.values():
            window.extend(motor)
        return window

    @property
    def pending(self) -> int:
        """Requests not yet resolved (queued, sending or sent)."""
        return len(self._queue) + len(self._in_flight)

    def _count(self, codec: BoundCodec, name: str) -> None:
        self.motor_counts[id(codec)][name] += 1

    def _move(self, request: Request, state: RequestState) -> None:
        if state not in request.state.next:  # type: ignore[attr-defined]
            raise RuntimeError(f"{request.describe()}: {request.state.value} -> {state.value} is not allowed")
        request.state = state

    def _finish(self, request: Request, state: RequestState, now: float) -> None:
        if request.state is _QUEUED:
            self._queue.remove(request)
        else:
            self._leave_flight(request, now)
        self._move(request, state)
        if state is _CANCELLED or state is _FAILED:  # (replies and timeouts are counted where found)
            self._count(request.codec, state.value)

    def _leave_flight(self, request: Request, now: float) -> None:
        if self._early and request.key in self._early:  # it never got its send report
            codec, _ = self._early.pop(request.key)
            self._count(codec, self._unmatched(request.key, now).value)
        if self._in_flight.pop(request, 0) is None and self.one_at_a_time:  # None: it was in flight
            self._rest_until = now + self.gap_s
        if request.key is not None:
            waiting = self._pending.get(request.key)
            if waiting is not None:
                if waiting[0] is request:
                    waiting.popleft()
                elif request in waiting:  # (a retry already left the deque)
                    waiting.remove(request)
                if not waiting:
                    del self._pending[request.key]
