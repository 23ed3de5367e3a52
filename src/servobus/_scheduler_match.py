"""The scheduler's part that judges received frames: which request a frame answers, and what it is
when it answers none (:class:`Matching`, a part of :class:`~servobus.scheduler.Scheduler`; the rules
are in servobus.scheduler's docstring).

Sans-IO: ``now`` is always an argument.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Hashable
from typing import TYPE_CHECKING

from servobus._request import FROM, Received, Recent, Request, RequestState, Traffic, illegal
from servobus.diagnosis import Seen
from servobus.errors import MotorNotExecuted, ProtocolError
from servobus.frame import Frame
from servobus.protocols import BoundCodec, FrameKind, Reply
from servobus.protocols._bound import KIND_NOT_OURS, KIND_REPLY, KIND_REPORT, KIND_STREAM

if TYPE_CHECKING:
    from servobus.metrics import LatencyWindow

__all__ = ["Matching"]

_FAILED = RequestState.FAILED
_REPLIED = RequestState.REPLIED
_SENDING = RequestState.SENDING
_SENT = RequestState.SENT
_TO_REPLIED = FROM[RequestState.REPLIED]
_T_DUPLICATE = Traffic.DUPLICATE
_T_EARLY = Traffic.EARLY
_T_FOREIGN = Traffic.FOREIGN
_T_LATE = Traffic.LATE
_T_MALFORMED = Traffic.MALFORMED
_T_REPLY = Traffic.REPLY
_T_UNSOLICITED = Traffic.UNSOLICITED
_T_NOT_EXECUTED = Traffic.NOT_EXECUTED


class Matching:
    """Frames in, verdicts out (the scheduler's state is declared here for the type checker)."""

    one_at_a_time: bool
    gap_s: float
    late_window_s: float
    min_reply_s: float
    _by_id: dict[int, list[BoundCodec]]
    _pending: dict[Hashable, deque[Request]]
    _in_flight: dict[Request, None]
    _recent: Recent
    _held: dict[Hashable, float]
    _early: dict[Hashable, tuple[BoundCodec, Frame]]
    _doubtful: set[Hashable]
    _any_measured: bool
    _overtaken: list[Request]
    _rest_until: float
    _bus_counts: Counter[str]
    seen: Seen
    motor_counts: dict[int, Counter[str]]
    motor_latency: dict[int, LatencyWindow]
    _by_request_id: dict[int, list[BoundCodec]]
    _foreign: dict[Hashable, deque[tuple[float, float]]]

    if TYPE_CHECKING:

        def _other_host(self, frame: Frame, now: float) -> Received: ...

        def _contended(
            self, codec: BoundCodec, key: Hashable, frame: Frame, reply: Reply, now: float
        ) -> Received | None: ...

        def _count(self, codec: BoundCodec, name: str) -> None: ...

        def _finish(self, request: Request, state: RequestState, now: float) -> None: ...

        def _first_measured(self) -> None: ...

        def _miss(self, request: Request, now: float) -> bool: ...

        def _ambiguous(self, request: Request, at: float, now: float) -> None: ...

    def receive(self, frame: Frame, now: float) -> Received:
        """Classify ``frame``, resolve the request it answers, count it."""
        for codec in self._by_id.get(frame.arbitration_id, ()):
            kind, key = codec.classify(frame)
            if kind is not KIND_NOT_OURS:
                return self._ours(codec, kind, key, frame, now)
        # Not a reply of ours: kept for a timeout's diagnosis, then another host's request to one
        # of our motors, or foreign. (An old LK motor answers on its request id: seen either way;
        # our own frames looped back are not news.)
        if frame.is_rx:
            self.seen.note(frame, now)
        if self._by_request_id:
            return self._other_host(frame, now)
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
            if waiting and waiting[0].echo == frame.data and self._fresh(waiting[0], frame, now):
                return self._not_executed(waiting[0], codec, frame, now)  # (a motion echo: no reply)
            self._count(codec, "malformed")
            return Received(_T_MALFORMED, frame, codec, error=exc, request=self._spoilt(key, frame, exc, now))
        if self._foreign and key in self._foreign and kind is KIND_REPLY:
            contended = self._contended(codec, key, frame, reply, now)  # (servobus._scheduler_hosts)
            if contended is not None:
                return contended
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
                stamp = frame.timestamp
                if stamp and request.deadline is not None and stamp > request.deadline:
                    return self._overtake(request, codec, frame, reply, now)
                echo = request.echo
                if echo is not None and frame.data == echo:
                    return self._not_executed(request, codec, frame, now)
                request.reply = reply
                # _leave_flight, written out for the hot path (a SENT request has no EARLY frame)
                waiting.popleft()
                if not waiting:
                    del self._pending[key]
                del self._in_flight[request]
                if self.one_at_a_time:
                    self._rest_until = now + self.gap_s
                if request.state not in _TO_REPLIED:  # (the table, read on the hot path)
                    illegal(request, _REPLIED)
                request.state = _REPLIED
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
                    self._ambiguous(request, frame.timestamp or now, now)  # (servobus._scheduler_time)
                return Received(traffic, frame, codec, reply, request)
        if kind is KIND_STREAM or kind is KIND_REPORT:
            self._count(codec, kind.value)
            return Received(Traffic(kind.value), frame, codec, reply)
        traffic = self._unmatched(key, now, frame.timestamp or now)
        self._count(codec, traffic.value)
        return Received(traffic, frame, codec, reply)

    def _overtake(
        self, request: Request, codec: BoundCodec, frame: Frame, reply: Reply, now: float
    ) -> Received:
        """``request``'s reply came stamped after its deadline (the loop took it in before the
        timer): the request timed out, whichever came first to the host; the frame is its late
        reply. :meth:`~servobus.scheduler.Scheduler.expire` says so next."""
        if self._miss(request, now):
            self._overtaken.append(request)
        traffic = self._unmatched(request.key, now, frame.timestamp)
        self._count(codec, traffic.value)
        return Received(traffic, frame, codec, reply)

    def _not_executed(self, request: Request, codec: BoundCodec, frame: Frame, now: float) -> Received:
        """``request``'s own bytes came back where its reply was due, for a command whose real reply
        cannot be them: the motor echoed it and did not execute it. It fails with MotorNotExecuted
        (the frame is its answer, so the same frame again is a duplicate)."""
        data = frame.data
        request.error = MotorNotExecuted(
            f"{request.describe()} was echoed back ({data.hex(' ').upper()}) instead of answered: "
            "not executed (as after the motor's communication watchdog tripped); send it again",
            motor_id=codec.motor_id,
            command=data[0] if data else None,
            raw=data,
        )
        self._finish(request, _FAILED, now)
        self._recent.replied[request.key] = now + self.late_window_s
        self.motor_counts[id(codec)]["not_executed"] += 1
        return Received(_T_NOT_EXECUTED, frame, codec, None, request)

    def _spoilt(self, key: Hashable | None, frame: Frame, error: ProtocolError, now: float) -> Request | None:
        """A frame with ``key`` that does not decode came: the request waiting for it fails with the
        codec's error (the motor answered it, in a way this codec cannot read: a revision mismatch,
        a value out of the manual's range), instead of timing out as if nothing came."""
        waiting = self._pending.get(key) if key is not None else None
        if not waiting:
            return None
        request = waiting[0]
        if not self._fresh(request, frame, now):
            return None
        request.error = error.with_context(motor_id=request.codec.motor_id)
        self._finish(request, _FAILED, now)
        self._recent.replied[key] = now + self.late_window_s  # (the same frame again: a duplicate)
        return request

    def _fresh(self, request: Request, frame: Frame, now: float) -> bool:
        """``frame`` (taken in ``now``) came late enough after ``request`` left to be its answer."""
        sent_at = request.sent_at
        if request.state is not _SENT or sent_at is None:
            return False
        return (frame.timestamp or now) >= sent_at + self.min_reply_s

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
                    if late:  # a request given up on before may still be answered: in doubt
                        self._doubtful.add(key)
                    else:
                        self._doubtful.discard(key)
                return _T_LATE
        until = recent.replied.get(key)
        if until is not None and until >= now:
            return _T_DUPLICATE
        return _T_UNSOLICITED
