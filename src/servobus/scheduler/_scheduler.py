"""The :class:`Scheduler`: the request table, the round-trip estimates, the keys' memory and the
other hosts' placeholders, composed; it carries out what :func:`~servobus.scheduler._match.match`
decides about each received frame. (The rules are in servobus.scheduler's docstring.)

Sans-IO: ``now`` is always an argument.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Collection, Hashable, Iterable, Sequence
from typing import Any

from servobus.errors import RequestStateError, TransportError
from servobus.frame import Frame
from servobus.metrics import LatencyWindow
from servobus.protocols import BoundCodec, Command, check_bus
from servobus.protocols._bound import KIND_REPLY
from servobus.rtt import Estimates
from servobus.scheduler._hosts import OtherHosts
from servobus.scheduler._keys import Keys
from servobus.scheduler._match import ANSWER, NO_MOTOR, judge, match
from servobus.scheduler._table import (
    FINAL,
    FROM,
    Received,
    Request,
    RequestState,
    RequestTable,
    Traffic,
    note_answer,
)

__all__ = ["Scheduler", "batch_requests", "submit_batch"]

_FAILED = RequestState.FAILED
_QUEUED = RequestState.QUEUED
_REPLIED = RequestState.REPLIED
_SENDING = RequestState.SENDING
_SENT = RequestState.SENT
_T_REPLY = Traffic.REPLY


class Scheduler:
    """Pending requests of one bus, matched by key, paced, timed out, counted.

    Args:
        codecs: the motors on the bus (checked together with :func:`~servobus.protocols.check_bus`).
        others: the options, each described in servobus.scheduler's docstring.

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
        timeouts = (min_timeout_s, initial_timeout_s, max_timeout_s)
        _check(max_in_flight, gap_s, late_window_s, late_hold_s, report_within_s, timeouts)
        self.name = name
        self.min_timeout_s = min_timeout_s
        self.codecs: list[BoundCodec] = []
        # Per motor (by codec identity: a plug-in's codec need not be hashable); the bus's counts
        # are their sum (and the other hosts' part's), so the hot path counts once.
        self.motor_counts: dict[int, Counter[str]] = {}
        self.motor_latency: dict[int, LatencyWindow] = {}
        # The parts, each the owner of its data (servobus.scheduler's docstring says which).
        rtts = self.estimates = Estimates(initial_timeout_s, min_timeout_s, max_timeout_s)
        pacing = (max_in_flight, one_at_a_time, gap_s, min_reply_s, stale_after_s, report_within_s)
        table = self.table = RequestTable(name, *pacing, rtts)
        self.keys = Keys(late_hold_s, late_window_s, report_within_s, rtts, table, self.count)
        self.hosts = OtherHosts(name, exact_order, table, self.keys, rtts, self.count)
        self.seen = self.hosts.seen  # (frames of no motor, for the diagnosis of a silent one)
        for codec in codecs:
            self.add(codec)

    @property
    def max_in_flight(self) -> int:
        """Requests SENDING or SENT at once (1 on a half-duplex line): the table's pacing."""
        return self.table.max_in_flight

    @property
    def one_at_a_time(self) -> bool:
        """A half-duplex line: one exchange at a time, ``gap_s`` of rest after each."""
        return self.table.one_at_a_time

    def add(self, codec: BoundCodec) -> None:
        """Put a motor on the bus (ValueError: it collides with a motor already there, both named)."""
        check_bus([*self.codecs, codec])
        self.codecs.append(codec)
        self.motor_counts[id(codec)] = Counter()
        self.motor_latency[id(codec)] = LatencyWindow(1024)
        self.estimates.add_motor(id(codec))
        self.table.add_motor(codec)
        self.hosts.add_motor(codec)

    def request(
        self,
        codec: BoundCodec,
        command: Command,
        timeout_s: float | None = None,
        retries: int = 0,
        context: Any = None,
    ) -> Request:
        """A request for ``command`` to ``codec``'s motor, encoded now (nothing is queued yet).
        ValueError: the codec refuses the command (before any frame exists), a negative timeout or
        retry count, or retries asked for a command that is not safe to repeat."""
        rtts = self.estimates.motors.get(id(codec))
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
            rtt = self.estimates.new(id(codec), type(command), base)
        key = codec.reply_key(command)
        # (all positional: a keyword costs more, and this is once per request)
        adaptive = timeout_s is None
        request = Request(codec, command, frame, key, timeout, retries, context, rtt, adaptive, writes)
        # (codec.may_echo, written out; a plug-in codec from before ``echoing`` is never echoing)
        if key is not None and (command.NEVER_ECHOED or getattr(codec, "echoing", False)):
            request.echo = frame.data
        return request

    def submit(self, request: Request, now: float) -> None:
        """Queue ``request`` behind the others (FIFO); a command's freshness counts from ``now``
        (RequestStateError: it was submitted before)."""
        if request.submitted:  # (the check written out: submit is on the hot path)
            _submit_once(request)
        request.submitted = True
        if request.writes:
            request.queued_at = now
        self.table.queue.append(request)
        self.motor_counts[id(request.codec)]["requests"] += 1

    def expect(self, request: Request, at: float) -> None:
        """``request``'s frame was sent by someone else at ``at`` (a broadcast): it is in flight from
        then, past the queue and its pacing, and only awaits its reply. Nothing of :meth:`blocking`
        may be left for its key (the caller waited). RequestStateError: it was submitted before."""
        _submit_once(request)
        self.motor_counts[id(request.codec)]["requests"] += 1
        self.table.move(request, _SENDING, at)
        request.handed_at = None  # (not handed over by this Bus: the other-hosts rules read it)
        self.sent(request, at)

    def not_sent(
        self, request: Request, reason: str, now: float, error: TransportError | None = None
    ) -> None:
        """The link dropped ``request``'s frame (stale, purged, queue_full, bus_off, ...): it fails,
        with ``error`` (default: a TransportError that says why) in ``request.error``."""
        if request.state in FINAL:
            return
        request.error = error or TransportError(f"{self.name}: {request.describe()} not sent ({reason})")
        self.keys.end(request, _FAILED, now)
        self.count(request.codec, f"not_sent_{reason}")

    def cancel(self, request: Request, now: float) -> None:
        """The caller gave up on ``request``; a reply that still comes is counted LATE."""
        if request.state not in FINAL:
            self.keys.cancel(request, now)

    def fail(self, error: BaseException, now: float, *, queued_only: bool = False) -> list[Request]:
        """Every request not yet answered (``queued_only``: not yet handed to the link) fails with
        ``error``; returns them, in the order they were sent or queued (the transport was lost, or
        the Bus is closing)."""
        failed = self.table.unanswered(queued_only)
        for request in failed:
            request.error = error
            self.keys.end(request, _FAILED, now)
        return failed

    def queued(self, codec: BoundCodec) -> list[Request]:
        """The requests to ``codec``'s motor not yet handed to the link, in their order."""
        return [request for request in self.table.queue if request.codec is codec]

    # ---- the link's reports, and time ----

    def poll(self, now: float) -> tuple[Sequence[Request], Sequence[Request]]:
        """What happens now: the requests that may leave, in order (they become SENDING: hand their
        frames to the link), and the commands that waited too long for their turn (FAILED with a
        TransportError in ``request.error``: tell their callers). See ``RequestTable.take``."""
        keys = self.keys
        if keys.held:
            keys.release(now)
        out, stale = self.table.take(now, keys.held)
        for request in stale:
            self.count(request.codec, "failed")
            self.count(request.codec, "not_sent_stale")
        return out, stale

    def sent(self, request: Request, at: float) -> Received | None:
        """The link reports that ``request``'s frame left at ``at``: its deadline starts. Returns the
        verdict on a reply-shaped frame with its key that came before this report (EARLY), now that
        the send time is known: the reply, or a duplicate or late frame."""
        if request.state not in FROM[_SENT]:  # (the table's guard: SENDING, the only way to SENT)
            return None  # cancelled while the frame was on its way (or timed out unreported)
        if request.key is None:  # nothing to wait for
            request.sent_at = at
            self.keys.end(request, _REPLIED, at)
            self.motor_counts[id(request.codec)]["replies"] += 1
            return None
        table = self.table
        table.move(request, _SENT, at)  # (an adaptive request is timed by the estimates there)
        early = table.take_early(request.key) if table.early else None
        if early is None:
            return None
        frame = early[1]  # (unstamped, it came after the hand-over at an unknown time: in time)
        return self.receive(frame, frame.timestamp or at + table.min_reply_s)

    def sent_after_all(self, request: Request, at: float) -> None:
        """The send report of a request given up on before it came (cancelled, or timed out
        unreported): its key's hold for the late reply counts from ``at`` (see :class:`Keys`)."""
        self.keys.sent_after_all(request, at)

    def expire(self, now: float) -> list[Request]:
        """The requests whose deadline passed and that missed their reply (TIMED_OUT: the watchdog
        counts them against their motor); a retry-safe read with retries left goes back to the
        queue's front instead (see :meth:`Keys.expire`)."""
        return self.keys.expire(now)

    def timeout_due(self, now: float) -> bool:
        """Whether :meth:`expire` at ``now`` has a request to time out (not a line's rest or a held
        key: those only let the next requests go)."""
        return self.table.due(now)

    def next_deadline(self) -> float | None:
        """When :meth:`expire` or :meth:`poll` next has something to do (None: nothing)."""
        return self.table.next_deadline(self.keys.held)

    # ---- received frames ----

    def receive(self, frame: Frame, now: float) -> Received:
        """Classify ``frame`` (:func:`~servobus.scheduler._match.match`), resolve its request, count it."""
        what, codec, kind, key, reply, request, error = match(self.table, frame, now)
        hosts, keys = self.hosts, self.keys
        if hosts.foreign and key in hosts.foreign and kind is KIND_REPLY and error is None:
            assert codec is not None and reply is not None
            contended = hosts.contended(codec, key, frame, reply, now)  # (servobus.scheduler._hosts)
            if contended is not None:
                return contended
        if what != ANSWER:
            if what == NO_MOTOR:
                return hosts.not_ours(frame, now)
            return judge((what, codec, kind, key, reply, request, error), frame, now, self.table, keys)
        assert request is not None and codec is not None and kind is not None
        if self.table.move(request, _REPLIED, now) is not None:  # (an early frame of its key, unjudged)
            keys.end_early(codec, key, now)
        request.reply = reply
        if request.pipelined and request.sent_at is not None:  # (its duplicate is told: _match.REPEATED)
            note_answer(self.table, key, (at := frame.timestamp or now) - request.sent_at, frame.data, at)
        replied = keys.replied  # (Keys.answered, written out for the hot path)
        replied[key] = now + keys.late_window_s
        if len(replied) > keys.limit:
            keys.prune(now)
        counts = self.motor_counts[id(codec)]
        counts["replies"] += 1
        if kind is KIND_REPLY:
            traffic = _T_REPLY
        else:
            traffic = Traffic(kind.value)
            counts[traffic.value] += 1
        sent_at = request.sent_at
        if sent_at is not None:
            rtt_s = (frame.timestamp or now) - sent_at
            self.motor_latency[id(codec)].add(rtt_s)
            rtt = request.rtt
            if rtt is not None and kind is KIND_REPLY:  # (a stream frame's time is not one)
                rtt.add(rtt_s)
                if not self.estimates.any_measured:
                    keys.measured()
        if keys.doubtful and key in keys.doubtful and keys.ambiguous(request, now):
            counts["ambiguous"] += 1
        return Received(traffic, frame, codec, reply, request)

    def blocking(self, keys: Iterable[Hashable], now: float) -> tuple[float | None, list[Request]]:
        """What a frame that skips the queue (a broadcast) waits for before it may go out: the requests
        in flight with one of ``keys``, and when the last hold of one of them ends (None: none held).
        (Its replies come on ``keys``: as for a queued request, see :meth:`poll`.)"""
        keys = list(keys)
        return self.keys.held_until(keys, now), self.table.flying(keys)

    @property
    def quiet(self) -> bool:
        """Nothing is in flight with a key and no key is held: no request would wait (:meth:`busy`)."""
        return not self.table.pending and not self.keys.held

    def busy(self, key: Hashable | None, now: float) -> bool:
        """Would a request with ``key`` wait now: one with that key is in flight, or the key is held
        for a late reply (:meth:`poll`)?"""
        if key is None:
            return False
        if key in self.table.pending:
            return True
        until = self.keys.held.get(key)  # (held for a late reply until then)
        return until is not None and until > now

    def count(self, codec: BoundCodec, counter: str, n: int = 1) -> None:
        """Add ``n`` to ``counter`` of ``codec``'s motor (in :attr:`motor_counts` and :attr:`counts`)."""
        self.motor_counts[id(codec)][counter] += n

    @property
    def counts(self) -> Counter[str]:
        """Every counter of the bus: the motors' summed, and frames of no motor (``foreign``)."""
        total = Counter(self.hosts.counts)
        for counts in self.motor_counts.values():
            total.update(counts)
        return total

    def latency(self) -> LatencyWindow:
        """The latencies of every motor's last replies, in one window."""
        return _merged(self.motor_latency.values())

    @property
    def pending(self) -> int:
        """Requests not yet resolved (queued, sending or sent)."""
        return len(self.table.queue) + len(self.table.in_flight)

    def motor_timeout_s(self, codec: BoundCodec) -> float:
        """The longest timeout measured round trips give any command class of ``codec``'s motor
        (``min_timeout_s`` while none was measured)."""
        return self.estimates.motor_timeout_s(id(codec))


def batch_requests(
    scheduler: Scheduler, items: Sequence[tuple[BoundCodec, Command, Any]], timeout_s: float | None = None
) -> list[Request]:
    """:meth:`Scheduler.request` for each (codec, command, context) of a batch, with no retries (a
    pipelined loop's tick: one call per bus, not per request). ValueError as ``request``, before
    any of the batch is returned. (Beside the class: it is near its 300 lines.)"""
    if timeout_s is not None and timeout_s <= 0:
        raise ValueError(f"timeout_s={timeout_s} must be > 0 and retries=0 >= 0")
    motors = scheduler.estimates.motors
    adaptive = timeout_s is None
    out: list[Request] = []
    for codec, command, context in items:
        # (request()'s body written out for the batch: keep the two in step)
        rtts = motors.get(id(codec))
        if rtts is None:
            raise ValueError(f"{codec!r} is not on this bus: add() it first")
        frame = codec.encode(command)
        base = codec.timeout_s(command)
        timeout = base if timeout_s is None else timeout_s
        if timeout <= 0:
            raise ValueError(f"timeout_s={timeout} must be > 0 and retries=0 >= 0")
        writes = not codec.retry_safe(command)
        rtt = rtts.get(type(command))
        if rtt is None:
            rtt = scheduler.estimates.new(id(codec), type(command), base)
        key = codec.reply_key(command)
        request = Request(codec, command, frame, key, timeout, 0, context, rtt, adaptive, writes)
        if key is not None and (command.NEVER_ECHOED or getattr(codec, "echoing", False)):
            request.echo = frame.data
        out.append(request)
    return out


def submit_batch(scheduler: Scheduler, requests: Iterable[Request], now: float) -> None:
    """:meth:`Scheduler.submit` each of ``requests``, in order (one call per batch)."""
    queue = scheduler.table.queue
    counts = scheduler.motor_counts
    for request in requests:
        if request.submitted:
            _submit_once(request)
        request.submitted = True
        if request.writes:
            request.queued_at = now
        queue.append(request)
        counts[id(request.codec)]["requests"] += 1


def _merged(windows: Collection[LatencyWindow]) -> LatencyWindow:
    merged = LatencyWindow(sum(len(w) for w in windows) or 1)
    for window in windows:
        merged.extend(window)
    return merged


def _submit_once(request: Request) -> None:
    """Mark ``request`` submitted (RequestStateError: it was before)."""
    if request.submitted:
        where = "already queued" if request.state is _QUEUED else request.state.value
        raise RequestStateError(f"{request.describe()} is {where}: a request is submitted once")
    request.submitted = True


def _check(
    max_in_flight: int,
    gap_s: float,
    late_window_s: float,
    late_hold_s: float | None,
    report_within_s: float | None,
    timeouts: tuple[float, float, float],
) -> None:
    """The Scheduler's options in range (``timeouts``: min, initial, max), else ValueError."""
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
    least, initial, most = timeouts
    if not 0 < least <= most or not least <= initial <= most:
        raise ValueError(
            f"timeouts must be 0 < min_timeout_s={least} <= initial_timeout_s={initial} <= "
            f"max_timeout_s={most}"
        )
