"""A request's life (:class:`Request`, :class:`RequestState`, :data:`TRANSITIONS`) and the verdict on a
received frame (:class:`Received`, :class:`Traffic`): the scheduler's vocabulary, shared by its parts
(servobus.scheduler re-exports all of it; import it from there)."""

from __future__ import annotations

import enum
from collections.abc import Hashable
from dataclasses import dataclass, field
from typing import Any, NoReturn

from servobus.errors import ProtocolError, RequestStateError
from servobus.frame import Frame
from servobus.protocols import BoundCodec, Command, Reply
from servobus.rtt import RoundTrip

__all__ = ["TRANSITIONS", "Received", "Request", "RequestState", "Traffic"]


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
    # (counted ``ambiguous`` once; servobus._scheduler_hosts).
    crossed: bool = False

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
Late = tuple[float, float | None, RoundTrip | None, float]


@dataclass(slots=True)
class Recent:
    """Keys that may still see a frame nobody waits for, and until when.

    Keys come and go (an echo's key holds the value written), so the tables are pruned of what has
    expired whenever they have grown past twice what the last pruning kept: amortised O(1), and
    bounded by the keys answered or given up on within the late window.
    """

    # key -> the requests whose reply may still come, oldest first (Late)
    late: dict[Hashable, list[Late]] = field(default_factory=dict)
    replied: dict[Hashable, float] = field(default_factory=dict)
    limit: int = 64

    def prune(self, now: float) -> None:
        self.replied = {key: until for key, until in self.replied.items() if until >= now}
        late: dict[Hashable, list[Late]] = {}
        for key, entries in self.late.items():
            if kept := [e for e in entries if e[0] >= now]:
                late[key] = kept
        self.late = late
        self.limit = max(64, 2 * (len(self.replied) + len(late)))
