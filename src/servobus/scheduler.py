"""The request scheduler of one bus: sans-IO, like the codecs below it (h11's model).

The Bus is its only caller. It hands the scheduler requests, the frames the transport received and
the transport's send reports, each with a clock value (intake: :meth:`Scheduler.receive`,
:meth:`Scheduler.sent`, :meth:`Scheduler.not_sent`); the scheduler answers with decisions (what to
send and what went stale: :meth:`Scheduler.poll`; what missed its reply: :meth:`Scheduler.expire`;
when to ask again: :meth:`Scheduler.next_deadline`) and keeps every rule about matching and timing
(in its parts: servobus._scheduler_match, servobus._scheduler_pace, servobus._scheduler_time):

* **Matching** is by the key the motor's bound codec gives (``reply_key`` for a request, ``classify``
  for a frame); requests with equal keys wait in FIFO order. A frame whose key matches nothing is
  classified, never dropped silently: a **late** reply (to a request that timed out or was
  cancelled), a **duplicate** (the same key again right after a reply), a **stream** or **report**
  frame of a motor, an **unsolicited** reply, a frame of **another** node, or a **malformed** one (it
  claims to be a reply but does not decode). A malformed frame never resolves a request with data:
  the request waiting for its key FAILS with the codec's ProtocolError (the motor answered, in a way
  this codec cannot read), instead of timing out as if nothing came.
* **Other hosts**: another host's request to one of our motors (CAN is broadcast) takes its place
  in that motor's order of replies, and the reply that answers it is counted ``contended``, never
  taken as ours (servobus._scheduler_hosts).
* **Life cycle** of a request (one table, :data:`TRANSITIONS`, every move checked against it; an
  illegal one raises :class:`~servobus.errors.RequestStateError`): QUEUED -> SENDING (handed to the
  transport) -> SENT (the transport reported when it left; the deadline starts there) -> REPLIED, or
  TIMED_OUT (deadline passed; a retry-safe read with retries left goes back to QUEUED), or CANCELLED,
  or FAILED (the transport never sent it, or was lost, or its reply did not decode: ``request.error``
  says why, and is what its caller gets). A request with no key (no reply expected) is REPLIED as
  soon as it left. Each is counted once, by its end. A request whose send report never comes still
  times out: ``report_within_s`` after it was handed over it gets a provisional deadline (that plus
  its timeout; counted ``unreported``), and a report that comes in time re-bases it on when the
  frame left.
* **Timing**: with no ``timeout_s`` of its own, a request's timeout comes from the round trips
  measured for its motor and command class (:class:`~servobus.rtt.RoundTrip`, RFC 6298); after a
  timeout its key is held for the late reply (``late_hold_s``), counted from when the timeout was
  noticed if the loop noticed it late (a stall: the host was not looking). While a request given up
  on may still be answered (its hold ended without its reply) the key is in doubt: a reply taken
  then is counted ``ambiguous``, and the key is held for the replies still owed if it was the
  earlier one's.
* **Pacing**: at most ``max_in_flight`` requests SENDING or SENT at once; a half-duplex line
  (``one_at_a_time``) allows one, and rests ``gap_s`` after each exchange before the next frame.
* **Streams**: a request whose key a motor streams (0xB6) is answered by the first stream frame that
  arrives after the request left (the same fact, fresh), as design.md's matching rule says.

Nothing here reads a clock, sleeps or awaits: ``now`` is always an argument, so every timing rule is
tested with plain calls.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Hashable, Iterable, Sequence
from typing import Any, NoReturn

from servobus._request import (
    FINAL,
    FROM,
    TRANSITIONS,
    Received,
    Recent,
    Request,
    RequestState,
    Traffic,
    illegal,
)
from servobus._scheduler_hosts import OtherHosts
from servobus._scheduler_match import Matching
from servobus._scheduler_pace import Pacing
from servobus._scheduler_time import TRUSTED_SAMPLES, Timing
from servobus.diagnosis import Seen
from servobus.errors import RequestStateError, TransportError
from servobus.frame import Frame
from servobus.metrics import LatencyWindow
from servobus.protocols import BoundCodec, Command, check_bus
from servobus.rtt import RoundTrip

__all__ = [
    "TRANSITIONS",
    "TRUSTED_SAMPLES",
    "Received",
    "Request",
    "RequestState",
    "Scheduler",
    "Traffic",
]

# Enum members as module globals for the hot paths: in Python 3.11 ``RequestState.SENT`` is a
# metaclass attribute lookup (~55 ns, several per exchange), a global is one dict read.
_CANCELLED = RequestState.CANCELLED
_FAILED = RequestState.FAILED
_QUEUED = RequestState.QUEUED
_REPLIED = RequestState.REPLIED
_SENDING = RequestState.SENDING
_SENT = RequestState.SENT
_TO_SENDING = FROM[_SENDING]
_TO_SENT = FROM[_SENT]
_NOTHING: tuple[Sequence[Request], Sequence[Request]] = ((), ())


class Scheduler(Pacing, Matching, OtherHosts, Timing):
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
        stale_after_s: a command (a request that ``writes``; reads are never stale) that waited
            longer than this for its turn since it was submitted (a stalled half-duplex line) fails
            ``not_sent_stale`` instead of leaving: for a motor, a stale command is worse than none
            (None: no limit).
        late_hold_s: after a request that left times out or is cancelled, the next request with its
            key waits until the late reply came or this long passed (None: from when the request
            left, at least twice its timeout, and the estimate's
            :meth:`~servobus.rtt.RoundTrip.late_s` once it rests on ``TRUSTED_SAMPLES`` round
            trips, before that twice the codec's own time). These protocols carry no sequence
            numbers: a reply later than the hold could answer the next request with the same key;
            such a reply is counted ``ambiguous``.
        initial_timeout_s: the timeout of a request (with no ``timeout_s`` of its own) sent before
            anything on the bus was measured: conservative, since the first exchange through a
            freshly opened adapter can be slow (RFC 6298's first RTO is 1 s). Requests sent with it
            are timed again by the first round trip measured.
        min_timeout_s, max_timeout_s: bounds of a timeout derived from measured round trips.
        report_within_s: the longest a send report may take after a frame was handed over (the
            frames ahead of it on the line, the link's own staleness limit): a request still not
            reported then gets a provisional deadline, that plus its timeout (None: reports always
            come, as from the sans-IO tests' plain calls).
        exact_order: send reports and received frames' stamps are times on the wire itself (the
            link's ``rules.exact_times``): our request and another host's are ordered by them; else
            a crossing within the adapter's latency is of unknown order (servobus._scheduler_hosts).
        name: the bus's label, in the errors it stores (``request.error``).

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
        report_within_s: float | None = None,
        exact_order: bool = True,
        name: str = "bus",
    ) -> None:
        if (
            max_in_flight < 1
            or gap_s < 0
            or late_window_s < 0
            or (late_hold_s is not None and late_hold_s < 0)
            or (report_within_s is not None and report_within_s < 0)
        ):
            raise ValueError(
                f"max_in_flight={max_in_flight} must be >= 1, gap_s={gap_s}, late_window_s={late_window_s}, "
                f"late_hold_s={late_hold_s} and report_within_s={report_within_s} >= 0"
            )
        if not 0 < min_timeout_s <= max_timeout_s or not min_timeout_s <= initial_timeout_s <= max_timeout_s:
            raise ValueError(
                f"timeouts must be 0 < min_timeout_s={min_timeout_s} <= "
                f"initial_timeout_s={initial_timeout_s} <= max_timeout_s={max_timeout_s}"
            )
        self.name = name
        self.late_hold_s = late_hold_s
        self.initial_timeout_s = initial_timeout_s
        self.min_timeout_s = min_timeout_s
        self.max_timeout_s = max_timeout_s
        self.report_within_s = report_within_s
        self._rtts: dict[int, dict[type, RoundTrip]] = {}  # id(codec) -> command class -> estimate
        self._any_measured = False
        self._provisional: list[Request] = []  # sent before anything was measured: timed again then
        self._doubtful: set[Hashable] = set()  # keys whose hold ended before their late reply came
        self.stale_after_s = stale_after_s
        self.max_in_flight = 1 if one_at_a_time else max_in_flight
        self.one_at_a_time = one_at_a_time
        self.gap_s = gap_s
        self.late_window_s = late_window_s
        self.min_reply_s = min_reply_s
        self.exact_order = exact_order
        self.codecs: list[BoundCodec] = []
        self._by_id: dict[int, list[BoundCodec]] = {}
        self._by_request_id: dict[int, list[BoundCodec]] = {}  # (servobus._scheduler_hosts)
        self._foreign: dict[Hashable, deque[tuple[float, float]]] = {}
        self._hosts_seen: dict[int, tuple[int, float]] = {}
        self._queue: deque[Request] = deque()
        self._pending: dict[Hashable, deque[Request]] = {}
        self._in_flight: dict[Request, None] = {}  # SENDING or SENT, in send order
        self._deadlines: list[tuple[float, int, Request]] = []  # a heap; entries of left requests stay
        self._audit_at: float | None = None  # when to look for sends never reported (report_within_s)
        self._overtaken: list[Request] = []  # timed out by a reply stamped after their deadline
        self._sent_count = 0  # a tie-breaker for the heap
        self._recent = Recent()
        self.seen = Seen()  # frames of no motor, for the diagnosis of a silent one (servobus.diagnosis)
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
        self._index_requests(codec)

    # ---- requests ----

    def request(
        self,
        codec: BoundCodec,
        command: Command,
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
        writes = not codec.retry_safe(command)
        if retries and writes:
            raise ValueError(f"{type(command).__name__} changes the motor: it is never retried automatically")
        rtt = rtts.get(type(command))
        if rtt is None:
            rtt = rtts[type(command)] = RoundTrip(base)
            self._set_floors(rtts)
        key = codec.reply_key(command)
        # (all positional: a keyword costs more, and this is once per request)
        adaptive = timeout_s is None
        request = Request(codec, command, frame, key, timeout, retries, context, rtt, adaptive, writes)
        # (codec.may_echo, written out; a plug-in codec from before ``echoing`` is never echoing)
        if key is not None and (command.NEVER_ECHOED or getattr(codec, "echoing", False)):
            request.echo = frame.data
        return request

    def submit(self, request: Request, now: float) -> None:
        """Queue ``request`` behind the others (FIFO); a command's freshness counts from ``now``.

        Raises:
            RequestStateError: it was submitted before.
        """
        if request.submitted:
            where = "already queued" if request.state is _QUEUED else request.state.value
            raise_twice(request, where)
        request.submitted = True
        if request.writes:
            request.queued_at = now
        self._queue.append(request)
        self.motor_counts[id(request.codec)]["requests"] += 1

    def expect(self, request: Request, at: float) -> None:
        """``request``'s frame was sent by someone else at ``at`` (a broadcast): it is in flight from
        then, past the queue and its pacing, and only awaits its reply. Nothing of :meth:`blocking`
        may be left for its key (the caller waited).

        Raises:
            RequestStateError: the request was submitted before.
        """
        if request.submitted:
            raise_twice(request, request.state.value)
        request.submitted = True
        self.motor_counts[id(request.codec)]["requests"] += 1
        self._move(request, _SENDING)
        request.attempts += 1
        self._in_flight[request] = None
        if request.key is not None:
            self._pending.setdefault(request.key, deque()).append(request)
        self.sent(request, at)

    def not_sent(
        self, request: Request, reason: str, now: float, error: TransportError | None = None
    ) -> None:
        """The link dropped ``request``'s frame (stale, purged, queue_full, bus_off, ...): it fails,
        with ``error`` (default: a TransportError that says why) in ``request.error``."""
        if request.state in FINAL:
            return
        request.error = error or TransportError(f"{self.name}: {request.describe()} not sent ({reason})")
        self._finish(request, _FAILED, now)
        self._count(request.codec, f"not_sent_{reason}")

    def cancel(self, request: Request, now: float) -> None:
        """The caller gave up on ``request``; a reply that still comes is counted LATE."""
        if request.state in FINAL:
            return
        was_out = request.state is _SENDING or request.state is _SENT
        self._finish(request, _CANCELLED, now)
        if was_out and request.key is not None:
            self._expect_late(request, now)

    def fail(self, error: BaseException, now: float, *, queued_only: bool = False) -> list[Request]:
        """Every request not yet answered (``queued_only``: not yet handed to the link) fails with
        ``error``; returns them, in the order they were sent or queued (the transport was lost, or
        the Bus is closing)."""
        failed = [*self._queue] if queued_only else [*self._in_flight, *self._queue]
        for request in failed:
            request.error = error
            self._finish(request, _FAILED, now)
        return failed

    def queued(self, codec: BoundCodec) -> list[Request]:
        """The requests to ``codec``'s motor not yet handed to the link, in their order."""
        return [request for request in self._queue if request.codec is codec]

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

    def _move(self, request: Request, state: RequestState) -> None:
        if state not in TRANSITIONS[request.state]:
            illegal(request, state)
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


_OUT = frozenset({_SENDING, _SENT})


def raise_twice(request: Request, where: str) -> NoReturn:
    raise RequestStateError(f"{request.describe()} is {where}: a request is submitted once")
