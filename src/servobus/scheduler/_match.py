"""Matching: which request a received frame answers, as a pure function of the request table, the
frame and the time (:func:`match`). It changes nothing: it returns a :data:`Decision`. The
:class:`~servobus.scheduler.Scheduler` carries out an ANSWER (the hot path) and a frame of no motor
itself; :func:`judge` carries out the others, on the request table and the keys' memory (the rules
are in servobus.scheduler's docstring).

Sans-IO: ``now`` is always an argument.
"""

from __future__ import annotations

from collections.abc import Hashable

from servobus.errors import MotorNotExecuted, ProtocolError
from servobus.frame import Frame
from servobus.protocols import BoundCodec, FrameKind, Reply
from servobus.protocols._bound import KIND_NOT_OURS, KIND_REPLY, KIND_REPORT, KIND_STREAM
from servobus.scheduler._keys import Keys
from servobus.scheduler._table import Received, Request, RequestState, RequestTable, Traffic, early_room

__all__ = [
    "ALONE",
    "ANSWER",
    "EARLY",
    "EARLY_AGAIN",
    "ECHOED",
    "MALFORMED",
    "NO_MOTOR",
    "OVERTAKEN",
    "REPEATED",
    "UNMATCHED",
    "Decision",
    "judge",
    "match",
]

# What a frame is (a Decision's first item; plain ints: cheap to compare on the hot path).
NO_MOTOR = 0  # no motor of the bus claims it (another host's request, or foreign)
ANSWER = 1  # it answers ``request`` (a reply, or a stream frame answering a read of what it streams)
EARLY = 2  # reply-shaped, before ``request``'s send report: kept, judged when the report comes
EARLY_AGAIN = 3  # the same reply twice before the report: a duplicate
ECHOED = 4  # ``request``'s own bytes back where its reply was due: echoed, not executed
MALFORMED = 5  # does not decode (``error``); ``request``: the one it answered and so spoils, or None
OVERTAKEN = 6  # ``request``'s reply, stamped after its deadline: it timed out, this is its late reply
ALONE = 7  # a stream or report frame that answers no request
UNMATCHED = 8  # a reply that answers no request: late, duplicate or unsolicited (the keys' memory says)
REPEATED = 9  # the reply a pipelined request's key last took, again too soon to be the next one's

#: (what, codec, kind, key, reply, request, error): the motor whose frame it is, its kind and reply
#: key, the decoded reply, the request it concerns, the codec's error if it does not decode.
Decision = tuple[
    int,
    BoundCodec | None,
    FrameKind | None,
    Hashable | None,
    Reply | None,
    Request | None,
    ProtocolError | None,
]

_SENDING = RequestState.SENDING
_SENT = RequestState.SENT
_FAILED = RequestState.FAILED
_NO_MOTOR: Decision = (NO_MOTOR, None, None, None, None, None, None)


def match(table: RequestTable, frame: Frame, now: float) -> Decision:
    """What ``frame``, taken in at ``now``, is to the requests of ``table`` (it changes nothing).

    A reply cannot arrive before its request left plus the two frames' wire time
    (``table.min_reply_s``); a stream frame answers a read only if it came after the request left
    (the same fact, fresh). A frame that does not decode never answers a request with data: it
    spoils the request waiting for its key (it answered, in a way the codec cannot read)."""
    for codec in table.motors.get(frame.arbitration_id, ()):
        kind, key = codec.classify(frame)
        if kind is not KIND_NOT_OURS:
            break
    else:
        return _NO_MOTOR
    waiting = table.pending.get(key) if key is not None else None
    try:
        reply = codec.decode(frame)
    except ProtocolError as exc:
        if waiting:
            first = waiting[0]
            if first.state is _SENDING and kind is KIND_REPLY and key not in table.early:
                return (EARLY, codec, kind, key, None, first, exc)
            if _fresh(table, first, frame, now):
                return (ECHOED if first.echo == frame.data else MALFORMED, codec, kind, key, None, first, exc)
        return (MALFORMED, codec, kind, key, None, None, exc)
    if waiting:
        request = waiting[0]
        if request.state is _SENDING and kind is KIND_REPLY:
            # It beat the transport's send report (a reader and a writer thread).
            again = key in table.early and not early_room(table, key)
            return (EARLY_AGAIN if again else EARLY, codec, kind, key, reply, request, None)
        sent_at = request.sent_at
        if kind is KIND_REPLY:
            # (an unstamped frame counts from ``now``, when it was taken in: 0.0 is no time)
            fresh = sent_at is None or (frame.timestamp or now) >= sent_at + table.min_reply_s
        else:
            fresh = sent_at is not None and frame.timestamp >= sent_at
        if request.state is _SENT and fresh:
            stamp = frame.timestamp
            if stamp and request.deadline is not None and stamp > request.deadline:
                return (OVERTAKEN, codec, kind, key, reply, request, None)
            echo = request.echo
            if echo is not None and frame.data == echo:
                return (ECHOED, codec, kind, key, reply, request, None)
            if request.pipelined and sent_at is not None:
                # The bytes of the key's last answer again, with its stamp (two frames cannot end on
                # the wire at once) or within half the key's shortest round trip after this request
                # left: that answer again (a duplicate), not this request's reply. (Not "sooner than
                # any reply took": a motor's turnaround is steady, so half its replies would come a
                # hair sooner than the shortest yet. Two real, equal replies read in one chunk share
                # a stamp: the second is then taken for a duplicate and its request times out, the
                # safe side of the doubt: a state older than the truth, never younger.)
                last = table.answers.get(key)
                at = stamp or now
                if (
                    last is not None
                    and last[1] == frame.data
                    and (at == last[2] or at < sent_at + 0.5 * last[0])
                ):
                    return (REPEATED, codec, kind, key, reply, request, None)
            return (ANSWER, codec, kind, key, reply, request, None)
    if kind is KIND_STREAM or kind is KIND_REPORT:
        return (ALONE, codec, kind, key, reply, None, None)
    return (UNMATCHED, codec, kind, key, reply, None, None)


def _fresh(table: RequestTable, request: Request, frame: Frame, now: float) -> bool:
    """``frame`` (taken in ``now``) came late enough after ``request`` left to be its answer."""
    sent_at = request.sent_at
    if request.state is not _SENT or sent_at is None:
        return False
    return (frame.timestamp or now) >= sent_at + table.min_reply_s


def judge(decision: Decision, frame: Frame, now: float, table: RequestTable, keys: Keys) -> Received:
    """Carry out ``decision`` about ``frame`` (taken in at ``now``) when it is neither an ANSWER nor
    NO_MOTOR: keep an early frame, fail the request it spoils, or say what the keys' memory makes of
    a frame that answers nothing; count it."""
    what, codec, kind, key, reply, request, error = decision
    assert codec is not None
    count = keys.count
    if what == EARLY:
        assert key is not None
        table.keep_early(key, codec, frame)  # judged (and counted) when the send report comes
        return Received(Traffic.EARLY, frame, codec)
    if what in (EARLY_AGAIN, REPEATED):
        count(codec, Traffic.DUPLICATE.value)
        return Received(Traffic.DUPLICATE, frame, codec, reply)
    if what == ECHOED and request is not None:
        # Its own bytes back, for a command whose real reply cannot be them: the motor echoed it
        # and did not execute it (the frame is its answer: the same again is a duplicate).
        request.error = _echoed(request, codec, frame.data)
        keys.end(request, _FAILED, now)
        keys.answered(key, now)
        count(codec, "not_executed")
        return Received(Traffic.NOT_EXECUTED, frame, codec, None, request)
    if what == MALFORMED:
        assert error is not None
        count(codec, "malformed")
        if request is not None:  # it answered ``request``, in a way this codec cannot read
            request.error = error.with_context(motor_id=request.codec.motor_id)
            keys.end(request, _FAILED, now)
            keys.answered(key, now)  # (the same frame again: a duplicate)
        return Received(Traffic.MALFORMED, frame, codec, error=error, request=request)
    if what == ALONE and kind is not None:
        count(codec, kind.value)
        return Received(Traffic(kind.value), frame, codec, reply)
    at: float | None = frame.timestamp or now
    if what == OVERTAKEN and request is not None:
        # Stamped after its deadline (the loop took it in before the timer): the request timed out,
        # whichever came first to the host; the frame is its late reply (Scheduler.expire says so).
        if keys.miss(request, now):
            table.overtaken(request)
        at = frame.timestamp
    traffic = keys.unmatched(key, now, at)
    count(codec, traffic.value)
    return Received(traffic, frame, codec, reply)


def _echoed(request: Request, codec: BoundCodec, data: bytes) -> MotorNotExecuted:
    """The error of ``request`` whose own bytes came back where its reply was due."""
    return MotorNotExecuted(
        f"{request.describe()} was echoed back ({data.hex(' ').upper()}) instead of answered: "
        "not executed (as after the motor's communication watchdog tripped); send it again",
        motor_id=codec.motor_id,
        command=data[0] if data else None,
        raw=data,
    )
