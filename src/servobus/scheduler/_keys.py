"""The reply keys' memory (:class:`Keys`): which keys were answered or given up on lately, the
holds that keep a key's next exchange back until a late reply came, and so how a request that
leaves off the hot path ends (timed out, retried, cancelled, failed: :meth:`Keys.end`,
:meth:`Keys.miss`).

These protocols carry no sequence numbers: a frame with a key nobody waits for is told apart only
by what this remembers (a LATE reply to a request that timed out or was cancelled, a DUPLICATE of
one just answered, else UNSOLICITED), and a request whose key may still see a late reply waits (a
hold) so that reply cannot answer it. Sans-IO: ``now`` is always an argument.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable

from servobus.protocols import BoundCodec
from servobus.rtt import Estimates, RoundTrip
from servobus.scheduler._table import Request, RequestState, RequestTable, Traffic

__all__ = ["Keys", "Late"]

_T_DUPLICATE = Traffic.DUPLICATE
_T_LATE = Traffic.LATE
_T_UNSOLICITED = Traffic.UNSOLICITED
_GIVEN_UP = frozenset({RequestState.CANCELLED, RequestState.TIMED_OUT})
_CANCELLED = RequestState.CANCELLED
_FAILED = RequestState.FAILED
_QUEUED = RequestState.QUEUED
_SENDING = RequestState.SENDING
_SENT = RequestState.SENT
_TIMED_OUT = RequestState.TIMED_OUT

# A request whose reply may still come: until when a frame with its key counts as late (the late
# window), when it left, its round-trip estimate, and until when its key is held for that reply.
Late = tuple[float, float | None, RoundTrip | None, float]


class Keys:
    """What the bus remembers of reply keys, and until when.

    Keys come and go (an echo's key holds the value written), so ``late`` and ``replied`` are pruned
    of what has expired whenever they have grown past twice what the last pruning kept: amortised
    O(1), and bounded by the keys answered or given up on within the late window.

    Attributes:
        late: key -> the requests whose reply may still come, oldest first (:data:`Late`).
        replied: key -> until when a frame with it is a DUPLICATE of the reply just taken (the
            scheduler's reply path writes it inline, then :meth:`prune` past ``limit``).
        held: key -> until when its next exchange waits for a late reply.
        doubtful: keys whose hold ended before their late reply came: a reply taken is in doubt.
    """

    def __init__(
        self,
        late_hold_s: float | None,
        late_window_s: float,
        report_within_s: float | None,
        estimates: Estimates,
        table: RequestTable,
        count: Callable[[BoundCodec, str], None],
    ) -> None:
        self.late_hold_s = late_hold_s
        self.late_window_s = late_window_s
        self.report_within_s = report_within_s
        self.estimates = estimates
        self.table = table
        self.count = count  # (the scheduler's per-motor counters)
        self.late: dict[Hashable, list[Late]] = {}
        self.replied: dict[Hashable, float] = {}
        self.limit = 64
        self.held: dict[Hashable, float] = {}
        self.doubtful: set[Hashable] = set()

    def prune(self, now: float) -> None:
        self.replied = {key: until for key, until in self.replied.items() if until >= now}
        late: dict[Hashable, list[Late]] = {}
        for key, entries in self.late.items():
            if kept := [e for e in entries if e[0] >= now]:
                late[key] = kept
        self.late = late
        self.limit = max(64, 2 * (len(self.replied) + len(late)))

    def answered(self, key: Hashable, now: float) -> None:
        """A request with ``key`` was answered (or failed by its answer): the same frame again soon
        is a duplicate."""
        self.replied[key] = now + self.late_window_s
        if len(self.replied) > self.limit:
            self.prune(now)

    def held_until(self, keys: Iterable[Hashable], now: float) -> float | None:
        """When the last hold of one of ``keys`` ends (None: none held)."""
        held = self.held
        ends = [held[key] for key in keys if key in held and held[key] > now]
        return max(ends) if ends else None

    def release(self, now: float) -> None:
        """Holds that ended let their key's next exchange go; a late reply that never came may come
        yet, while its late window is open: the key is in doubt meanwhile."""
        held = self.held
        for key in [k for k, until in held.items() if until <= now]:
            del held[key]
            self.table.ordinary_held.pop(key, None)
            if any(e[0] > now for e in self.late.get(key, ())):
                self.doubtful.add(key)

    def expect_late(self, request: Request, now: float) -> None:
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
            until = request.sent_at + max(2.0 * request.timeout_s, self.estimates.late_s(request.rtt))
            deadline = request.deadline
            if deadline is not None and now > deadline:
                # Noticed late: the loop stalled (a GC pause, a busy machine, a thread holding the
                # GIL). The host was not looking, and what came meanwhile may not be taken in yet:
                # the hold counts from when the timeout was noticed, as if noticed on time.
                until += now - deadline
        entries = self.late.setdefault(key, [])
        if entries and entries[0][0] < now:  # (a motor that never answers: its entries expire)
            entries[:] = [e for e in entries if e[0] >= now]
        entries.append((now + self.late_window_s, request.sent_at, request.rtt, until))
        if len(self.late) > self.limit:
            self.prune(now)
        if until > now:
            self.held[key] = max(until, self.held.get(key, until))
            if not request.pipelined:
                self._hold_ordinary(key, until)
        else:  # (a hold over before it began: the next reply with the key is in doubt)
            self.doubtful.add(key)

    def ambiguous(self, request: Request, now: float) -> bool:
        """``request`` took a reply while its key was in doubt: requests with the key sent before it
        were given up on (their holds ended) and have had no reply. The reply may be the first of
        those's: True (count it ``ambiguous``). Either it was (and as many replies as there were
        such requests are still owed, the last ``request``'s own) or they were lost: they stay owed
        for as long as the earlier ones could have come, and the key stays in doubt meanwhile (a
        motor whose replies fell behind answers each request with the one before's: every reply
        taken is in doubt until a late one comes alone), and the key is held once, until
        ``request``'s hold would end (a frame then is late; none: the next exchange goes, at the
        cost of one hold per episode)."""
        key = request.key
        self.doubtful.discard(key)
        late = self.late.get(key)
        sent_at = request.sent_at
        if not late or sent_at is None:
            return False
        # (an owed entry, no round trip, is in doubt from the start: its key is held once per episode)
        earlier = [
            e
            for e in late
            if e[0] > now and (e[3] <= now or e[2] is None) and (e[1] is None or e[1] < sent_at)
        ]
        if not earlier:
            return False  # clear: nothing earlier can still answer
        for entry in earlier:
            late.remove(entry)
        late_s = self.estimates.late_s(request.rtt)
        until = max(sent_at + max(2.0 * request.timeout_s, late_s), now + request.timeout_s)
        window = max(e[0] for e in earlier)
        # (owed, with no round trip: a reply to one is no sample of anyone's)
        late.extend([(window, sent_at, None, until)] * len(earlier))
        self.doubtful.add(key)  # (a reply taken while they are owed is in doubt too)
        if any(e[2] is not None for e in earlier):  # a new episode (owed ones aside): hold once
            self.held[key] = max(until, self.held.get(key, until))
            if not request.pipelined:
                self._hold_ordinary(key, until)
        return True

    def _hold_ordinary(self, key: Hashable, until: float) -> None:
        ordinary = self.table.ordinary_held
        ordinary[key] = max(until, ordinary.get(key, until))

    def sent_after_all(self, request: Request, at: float) -> None:
        """The send report of a request given up on before it came (cancelled, or timed out
        unreported): its frame left at ``at``, so its key's hold for the late reply is counted
        from then (:meth:`expect_late`), no longer from a guess."""
        if request.sent_at is not None or request.key is None or request.state not in _GIVEN_UP:
            return
        key = request.key
        entries = self.late.get(key) or []
        for entry in entries:
            if entry[1] is None:  # (its entry: made with no send time)
                entries.remove(entry)
                break
        holds = [entry[3] for entry in entries]  # (the key's other holds stand)
        if holds:
            self.held[key] = max(holds)
        else:
            self.held.pop(key, None)
        request.sent_at = at
        self.expect_late(request, at)

    # ---- ends ----

    def end(self, request: Request, state: RequestState, now: float) -> None:
        """Move ``request`` to ``state`` off the hot paths (:meth:`RequestTable.move`); a frame that
        came before a send report that never came is judged now, and an end by cancel or failure
        is counted (replies and timeouts are counted where found)."""
        dropped = self.table.move(request, state, now)
        if dropped is not None:
            self.end_early(dropped[0], request.key, now)
        if state is _CANCELLED or state is _FAILED:
            self.count(request.codec, state.value)

    def end_early(self, codec: BoundCodec, key: Hashable, now: float) -> None:
        """A frame of ``key`` that came before a send report is judged, and counted, as its request
        leaves flight without it."""
        self.count(codec, self.unmatched(key, now).value)

    def miss(self, request: Request, now: float) -> bool:
        """``request`` (SENT or SENDING) missed its deadline: TIMED_OUT (True), or back in the
        queue's front for a retry (False); either way its key is held for the late reply."""
        retry = request.attempts <= request.retries and request.state is _SENT
        self.end(request, _QUEUED if retry else _TIMED_OUT, now)
        self.count(request.codec, "retries" if retry else "timeouts")
        if request.key is not None:  # (the retry, too, waits out the late reply)
            self.expect_late(request, now)
        return not retry

    def expire(self, now: float) -> list[Request]:
        """The requests whose deadline passed at ``now`` and that missed their reply (see
        :meth:`~servobus.scheduler.Scheduler.expire`)."""
        expired, due = self.table.overdue(now)
        for request in due:
            state = request.state
            if state is not _SENDING and state is not _SENT:  # (a second deadline of one just missed)
                continue
            if state is _SENDING:  # its send report never came
                self.count(request.codec, "unreported")
            if self.miss(request, now):
                expired.append(request)
        return expired

    def cancel(self, request: Request, now: float) -> None:
        """The caller gave up on ``request``; a reply that still comes is counted LATE."""
        was_out = request.state is _SENDING or request.state is _SENT
        self.end(request, _CANCELLED, now)
        if was_out and request.key is not None:
            self.expect_late(request, now)

    def measured(self) -> None:
        """The bus's first round trip was measured: requests timed by the first value are timed again."""
        self.estimates.first_measured()
        self.table.retime()

    # ---- frames that answer no request ----

    def unmatched(self, key: Hashable | None, now: float, at: float | None = None) -> Traffic:
        """What a frame with ``key`` that answers no request is (``at``: when it was received); a
        late reply to a request still held for is a round-trip sample."""
        late = self.late.get(key)
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
                    if not self.estimates.any_measured:
                        self.measured()
                if len(held) <= 1:  # the reply the key was held for came: the next exchange may go
                    self.held.pop(key, None)
                    self.table.ordinary_held.pop(key, None)
                    if late:  # a request given up on before may still be answered: in doubt
                        self.doubtful.add(key)
                    else:
                        self.doubtful.discard(key)
                return _T_LATE
        until = self.replied.get(key)
        if until is not None and until >= now:
            return _T_DUPLICATE
        return _T_UNSOLICITED
