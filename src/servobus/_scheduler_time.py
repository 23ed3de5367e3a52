"""The scheduler's part that keeps time: timeouts from measured round trips, deadlines, expiry, and
the hold of a key for a late reply (:class:`Timing`, a part of :class:`~servobus.scheduler.Scheduler`).

Sans-IO: ``now`` is always an argument.
"""

from __future__ import annotations

import heapq
from collections import Counter, deque
from collections.abc import Hashable
from heapq import heapify, heappush
from typing import TYPE_CHECKING

from servobus._request import FROM, Received, Recent, Request, RequestState
from servobus.frame import Frame
from servobus.protocols import BoundCodec, FrameKind
from servobus.protocols._bound import KIND_REPLY
from servobus.rtt import RoundTrip

if TYPE_CHECKING:
    from servobus.metrics import LatencyWindow

__all__ = ["TRUSTED_SAMPLES", "Timing"]

#: Round trips an estimate must rest on before it bounds how late a reply may come (a late hold).
TRUSTED_SAMPLES = 16

_QUEUED = RequestState.QUEUED
_SENDING = RequestState.SENDING
_SENT = RequestState.SENT
_TIMED_OUT = RequestState.TIMED_OUT
_REPLIED = RequestState.REPLIED
_TO_SENT = FROM[_SENT]
_OUT = frozenset({_SENDING, _SENT})
_GIVEN_UP = frozenset({RequestState.CANCELLED, _TIMED_OUT})


class Timing:
    """Deadlines and timeouts (the scheduler's state is declared here for the type checker)."""

    late_hold_s: float | None
    initial_timeout_s: float
    min_timeout_s: float
    max_timeout_s: float
    report_within_s: float | None
    late_window_s: float
    max_in_flight: int
    _rtts: dict[int, dict[type, RoundTrip]]
    _any_measured: bool
    _provisional: list[Request]
    _doubtful: set[Hashable]
    _queue: deque[Request]
    _in_flight: dict[Request, None]
    _deadlines: list[tuple[float, int, Request]]
    _audit_at: float | None
    _overtaken: list[Request]
    _sent_count: int
    _recent: Recent
    _held: dict[Hashable, float]
    _rest_until: float
    _early: dict[Hashable, tuple[BoundCodec, Frame]]
    min_reply_s: float
    motor_counts: dict[int, Counter[str]]
    motor_latency: dict[int, LatencyWindow]

    if TYPE_CHECKING:

        def _leave_flight(self, request: Request, now: float) -> None: ...

        def _move(self, request: Request, state: RequestState) -> None: ...

        def _finish(self, request: Request, state: RequestState, now: float) -> None: ...

        def _ours(
            self, codec: BoundCodec, kind: FrameKind, key: Hashable | None, frame: Frame, now: float
        ) -> Received: ...

    def round_trip(self, codec: BoundCodec, command_class: type) -> RoundTrip | None:
        """The round-trip estimate of ``codec``'s motor for ``command_class`` (None: never sent)."""
        return self._rtts.get(id(codec), {}).get(command_class)

    def motor_timeout_s(self, codec: BoundCodec) -> float:
        """The longest timeout measured round trips give any command class of ``codec``'s motor
        (``min_timeout_s`` while none was measured)."""
        times = [r.timeout_s() for r in self._rtts.get(id(codec), {}).values() if r.samples]
        return max([self.min_timeout_s, *times])

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
        """The timeout of an adaptive request leaving now (see the Scheduler's docstring)."""
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

    def sent(self, request: Request, at: float) -> Received | None:
        """The link reports that ``request``'s frame left at ``at``: its deadline starts.

        Returns:
            The verdict on a reply-shaped frame with its key that came before this report (EARLY),
            now that the send time is known: the reply, or a duplicate or late frame.
        """
        if request.state not in _TO_SENT:  # (the table's guard: SENDING, the only way to SENT)
            return None  # cancelled while the frame was on its way (or timed out unreported)
        request.sent_at = at
        if request.key is None:  # nothing to wait for
            self._finish(request, _REPLIED, at)
            self.motor_counts[id(request.codec)]["replies"] += 1
            return None
        request.state = _SENT
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
        heappush(heap, (deadline, self._sent_count, request))
        if len(heap) > 64 + 4 * len(self._in_flight):  # answered ones under a long timeout pile up
            heap[:] = [e for e in heap if e[2].state in _OUT and e[2].deadline == e[0]]
            heapify(heap)
        early = self._early.pop(request.key, None) if self._early else None
        if early is None:
            return None
        codec, frame = early
        # An unstamped early reply came after the request was handed over, at an unknown time: in time.
        return self._ours(codec, KIND_REPLY, request.key, frame, frame.timestamp or at + self.min_reply_s)

    # ---- expiry ----

    def expire(self, now: float) -> list[Request]:
        """The requests whose deadline passed and that missed their reply (TIMED_OUT: the watchdog
        counts them against their motor); a retry-safe read with retries left goes back to the
        queue's front instead. A request whose frame the link never reported as sent times out
        too, once its provisional deadline passed (``report_within_s`` after it was handed over,
        plus its timeout)."""
        if self._audit_at is not None and self._audit_at <= now:
            self._audit(now)
        expired, self._overtaken = self._overtaken, []
        heap = self._deadlines
        while heap and heap[0][0] <= now:
            deadline, _, request = heapq.heappop(heap)
            if request.deadline != deadline:
                continue  # (an entry of a request that left, or was timed again)
            state = request.state
            if state is _SENDING:  # its send report never came
                self._count(request.codec, "unreported")
            elif state is not _SENT:
                continue
            if self._miss(request, now):
                expired.append(request)
        return expired

    def _miss(self, request: Request, now: float) -> bool:
        """``request`` (SENT or SENDING) missed its deadline: TIMED_OUT (True), or back in the
        queue's front for a retry (False); either way its key is held for the late reply."""
        self._leave_flight(request, now)
        if request.attempts <= request.retries and request.state is _SENT:
            self._move(request, _QUEUED)
            request.deadline = None  # (set again when it leaves: by its report, or an audit)
            self._queue.appendleft(request)
            self._count(request.codec, "retries")
            if request.key is not None:  # the retry, too, waits out the late reply
                self._expect_late(request, now)
            return False
        self._move(request, _TIMED_OUT)
        self._count(request.codec, "timeouts")
        if request.key is not None:
            self._expect_late(request, now)
        return True

    def _audit(self, now: float) -> None:
        """Look for requests handed over ``report_within_s`` ago or longer that got no send report:
        each gets a provisional deadline (that long after it was handed over, plus its timeout; a
        report that still comes times it from when it left instead). The next audit is due when
        the next of the others would be overdue. (An audit, not a record per request: the hot path
        only stamps ``handed_at``.)"""
        within = self.report_within_s
        assert within is not None
        self._audit_at = None
        for request in self._in_flight:
            if request.state is not _SENDING or request.deadline is not None or request.handed_at is None:
                continue  # (reported, or already given its provisional deadline)
            due = request.handed_at + within
            if due > now:
                if self._audit_at is None or due < self._audit_at:
                    self._audit_at = due
                continue
            request.deadline = deadline = due + request.timeout_s
            self._sent_count += 1
            heapq.heappush(self._deadlines, (deadline, self._sent_count, request))

    def _count(self, codec: BoundCodec, name: str) -> None:
        self.motor_counts[id(codec)][name] += 1

    def _expect_late(self, request: Request, now: float) -> None:
        """``request`` left and its reply may still come: count it LATE, and hold its key meanwhile."""
        key = request.key
        if self.late_hold_s is not None:
            until = now + self.late_hold_s
        elif request.sent_at is None:
            # Given up on before its send report: the frame may still be in the link's queue, and
            # its reply could answer the next request with its key. Held until the report can come
            # (report_within_s after hand-over) and a reply after it; the report re-bases this.
            handed = request.handed_at if request.handed_at is not None else now
            until = max(now, handed + (self.report_within_s or 0.0)) + request.timeout_s
        else:
            until = request.sent_at + max(2.0 * request.timeout_s, self._late_s(request))
            deadline = request.deadline
            if deadline is not None and now > deadline:
                # Noticed late: the loop stalled (a GC pause, a busy machine, a thread holding the
                # GIL). The host was not looking, and what came meanwhile may not be taken in yet:
                # the hold counts from when the timeout was noticed, as if noticed on time.
                until += now - deadline
        recent = self._recent
        entries = recent.late.setdefault(key, [])
        if entries and entries[0][0] < now:  # (a motor that never answers: its entries expire)
            entries[:] = [e for e in entries if e[0] >= now]
        entries.append((now + self.late_window_s, request.sent_at, request.rtt, until))
        if len(recent.late) > recent.limit:
            recent.prune(now)
        if until > now:
            self._held[key] = max(until, self._held.get(key, until))
        else:  # (a hold over before it began: the next reply with the key is in doubt)
            self._doubtful.add(key)

    def _ambiguous(self, request: Request, at: float, now: float) -> None:
        """``request`` took the reply received at ``at`` while its key was in doubt: requests with
        the key sent before it were given up on (their holds ended) and have had no reply. The
        reply may be the first of those's: counted ``ambiguous``. Either it was (and as many replies
        as there were such requests are still owed, the last ``request``'s own) or they were lost:
        they stay owed for as long as the earlier ones could have come (a reply taken meanwhile is
        in doubt too), and the key is held once, until ``request``'s hold would end (a frame then
        is late; none: the next exchange goes, at the cost of one hold per episode)."""
        key = request.key
        self._doubtful.discard(key)
        late = self._recent.late.get(key)
        sent_at = request.sent_at
        if not late or sent_at is None:
            return
        earlier = [e for e in late if e[0] > now and e[3] <= now and (e[1] is None or e[1] < sent_at)]
        if not earlier:
            return  # clear: nothing earlier can still answer
        self.motor_counts[id(request.codec)]["ambiguous"] += 1
        for entry in earlier:
            late.remove(entry)
        until = max(sent_at + max(2.0 * request.timeout_s, self._late_s(request)), now + request.timeout_s)
        window = max(e[0] for e in earlier)
        # (owed, with no round trip: a reply to one is no sample of anyone's)
        late.extend([(window, sent_at, None, until)] * len(earlier))
        if all(e[2] is not None for e in earlier):  # a new episode: hold once
            self._held[key] = max(until, self._held.get(key, until))

    def sent_after_all(self, request: Request, at: float) -> None:
        """The send report of a request given up on before it came (cancelled, or timed out
        unreported): its frame left at ``at``, so its key's hold for the late reply is counted
        from then (:meth:`_expect_late`), no longer from a guess."""
        if request.sent_at is not None or request.key is None or request.state not in _GIVEN_UP:
            return
        key = request.key
        entries = self._recent.late.get(key) or []
        for entry in entries:
            if entry[1] is None:  # (its entry: made with no send time)
                entries.remove(entry)
                break
        holds = [entry[3] for entry in entries]  # (the key's other holds stand)
        if holds:
            self._held[key] = max(holds)
        else:
            self._held.pop(key, None)
        request.sent_at = at
        self._expect_late(request, at)

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

    def timeout_due(self, now: float) -> bool:
        """Whether :meth:`expire` at ``now`` has a request to time out (not a line's rest or a held
        key: those only let the next requests go)."""
        if self._overtaken or (self._audit_at is not None and self._audit_at <= now):
            return True
        first = self._first_deadline()
        return first is not None and first <= now

    def _first_deadline(self) -> float | None:
        """The earliest deadline of a request still out (entries of requests that left, were
        answered or were timed again are dropped on the way)."""
        heap = self._deadlines
        while heap and (
            heap[0][2].deadline != heap[0][0]
            or (heap[0][2].state is not _SENT and heap[0][2].state is not _SENDING)
        ):
            heapq.heappop(heap)  # the request left (replied, cancelled) or was sent again
        return heap[0][0] if heap else None

    def next_deadline(self) -> float | None:
        """When :meth:`expire` or :meth:`~servobus.scheduler.Scheduler.poll` next has something to
        do (None: nothing)."""
        heap = self._deadlines
        if not self._in_flight:
            heap.clear()  # every entry is of a request that left (a whole tick answered: at once)
            self._audit_at = None
        first = self._first_deadline()
        times = [first] if first is not None else []
        if self._overtaken:  # (missed already: for expire() to say so)
            times.append(min(r.deadline or 0.0 for r in self._overtaken))
        if self._audit_at is not None:
            times.append(self._audit_at)
        if self._queue and len(self._in_flight) < self.max_in_flight:
            if self._rest_until:
                times.append(self._rest_until)
            if self._held:
                times.append(min(self._held.values()))
        return min(times) if times else None
