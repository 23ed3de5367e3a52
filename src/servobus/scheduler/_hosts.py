"""The scheduler's part that knows other hosts on the bus (:class:`OtherHosts`, owned by the
:class:`~servobus.scheduler.Scheduler`).

CAN is a broadcast medium: the adapter receives the requests another controller (a second PC, a
teach pendant, a forgotten script) sends to our motors, and the motor answers them on the reply
identifier it answers ours on, with the same DATA[0]. Replies carry no sequence number, but a motor
answers in the order requests reached it. So a request of another host to one of our motors takes
its place in that motor's order of expected replies (a placeholder, owned by nobody): the reply
that answers it is the motor's state (counted ``contended``, given to subscribers), never the
answer to our request with that key.

Order on the wire. Replies come in the order the requests reached the motor, and our adapter
receives frames in the order they were on the wire: a reply received before another host's request
answers an earlier request (ours), by order alone. A reply received after it answers whichever of
the two reached the motor first, and times must tell which:

* On a link whose times are the wire's own (``exact_order``: the in-process simulator, whose send
  report is when the frame was queued on its wire and whose stamps are when frames ended there),
  ours left at ``sent_at`` (its send report), theirs is stamped when it ended; one that ended
  before ours left, or while it may still have been on the wire when ours was (one frame's time,
  from ``min_reply_s``), reached the motor first.
* Through an adapter (a reader thread, USB, a serial line) both times are off by its latency, which
  is not known and is easily milliseconds: ours may wait in the adapter after its send report, and
  theirs was on the wire some time before we stamped it. Theirs reached the motor first for sure
  only if it was stamped before ours was even handed over (``handed_at``). Stamped after that (and
  before this reply), the two *crossed*: the order is not known. Then ours is answered with the
  **later of the two replies**, and counted ``ambiguous`` (``request.crossed``). That reply was
  sent after the motor had both requests, so it is the motor's state after our command whichever
  came first; if theirs came second, it shows theirs in force, which is the truth a control loop
  needs, never a stale "confirmation" of ours. A further request of another host stamped later
  is taken as after ours (ours waits for one reply more at most). It is never silent: a reply that
  may be the other host's is counted, and the warning names the other host's identifier and rate.
  The price is ambiguity on such a link while another host is on the bus; the cure is to remove the
  second controller, or a link that tells when our own frame was on the wire (below).

Our own frames that an adapter loops back (``is_rx`` False: python-can's ``receive_own_messages``,
SocketCAN's loop-back; or as received, on adapters that echo) are never taken for another host's:
the first frame with our in-flight request's very bytes is ours. Its stamp is then when ours was
on the wire, which orders it exactly against another host's.

A request of another host received before its motor was added to the Bus is not known (counted
``foreign``): its reply, if it comes after ours was sent, is taken as ours. Add the motors before
commanding them on a bus another host uses.

Sans-IO: ``now`` is always an argument.
"""

from __future__ import annotations

import dataclasses
import logging
from collections import Counter, deque
from collections.abc import Callable, Hashable

from servobus.diagnosis import Seen
from servobus.frame import Frame
from servobus.protocols import BoundCodec, Reply
from servobus.rtt import Estimates
from servobus.scheduler._keys import Keys
from servobus.scheduler._table import Received, RequestState, RequestTable, Traffic

__all__ = ["RATE_WINDOW_S", "WARN_AFTER", "OtherHosts"]

logger = logging.getLogger("servobus.bus")

#: Requests of another host to one motor seen, over at least RATE_WINDOW_S, before the warning
#: (so it can name their rate).
WARN_AFTER = 8
RATE_WINDOW_S = 0.05

_SENDING = RequestState.SENDING
_SENT = RequestState.SENT
_T_OTHER_HOST = Traffic.OTHER_HOST
_T_CONTENDED = Traffic.CONTENDED
_T_FOREIGN = Traffic.FOREIGN


class OtherHosts:
    """Other hosts' requests to our motors: the placeholders they take in our motors' order of
    replies. It reads the request table (ours in flight) and the keys' memory (late replies of ours
    still due), and counts through ``count`` (the scheduler's per-motor counters).

    It owns what the bus knows of frames no motor of ours claims: ``seen`` (per arbitration id,
    for the diagnosis of a silent motor: servobus.diagnosis) and ``counts`` (``foreign``).

    Attributes:
        foreign: key -> another host's requests still to be answered, oldest first: (when it ended
            on the wire, until when its reply is expected). Empty: nothing to contend with.
    """

    def __init__(
        self,
        name: str,
        exact_order: bool,
        table: RequestTable,
        keys: Keys,
        estimates: Estimates,
        count: Callable[[BoundCodec, str], None],
    ) -> None:
        self.name = name
        self.exact_order = exact_order
        self.table = table
        self.keys = keys
        self.estimates = estimates
        self.count = count
        self.foreign: dict[Hashable, deque[tuple[float, float]]] = {}
        self.seen = Seen()
        self.counts: Counter[str] = Counter()
        self._by_request_id: dict[int, list[BoundCodec]] = {}
        # motor (codec id) -> (requests seen, first stamp); -1 requests: warned already
        self._hosts_seen: dict[int, tuple[int, float]] = {}

    def add_motor(self, codec: BoundCodec) -> None:
        """Listen for other hosts' requests to ``codec``'s motor (a family that can tell them)."""
        if getattr(codec, "request_key", None) is None:
            return  # (a plug-in family without it: such frames stay ``foreign``)
        for ident in {i & 0x1FFFFFFF for i in codec.request_ids}:
            self._by_request_id.setdefault(ident, []).append(codec)

    def not_ours(self, frame: Frame, now: float) -> Received:
        """A frame no motor claims: kept for a timeout's diagnosis (an old LK motor answers on its
        request id: seen either way; our own frames looped back are not news), then another host's
        request to one of our motors (a placeholder in its order of replies), or ``foreign``."""
        if frame.is_rx:
            self.seen.note(frame, now)
        for codec in self._by_request_id.get(frame.arbitration_id, ()):
            if not frame.is_rx:  # our own frame, looped back: when it was on the wire
                as_received = dataclasses.replace(frame, is_rx=True)  # (how the codec judges it)
                key = codec.request_key(as_received)  # type: ignore[attr-defined]
                self._looped(key, frame, frame.timestamp or now)
                break
            key = codec.request_key(frame)  # type: ignore[attr-defined]
            if key is None:
                continue
            at = frame.timestamp or now
            if self._looped(key, frame, at):
                break
            reply_s = 2.0 * self.estimates.motor_timeout_s(id(codec))
            self.foreign.setdefault(key, deque()).append((at, at + reply_s))
            self.count(codec, "foreign_requests")
            self._seen(codec, at)
            return Received(_T_OTHER_HOST, frame, codec)
        self.counts["foreign"] += 1
        return Received(_T_FOREIGN, frame)

    def _looped(self, key: Hashable | None, frame: Frame, at: float) -> bool:
        """Is ``frame`` our own request coming back (an adapter that loops sent frames back, as
        received or as sent)? The first frame with the very bytes of our request in flight, after
        it left; its stamp is when ours was on the wire (what orders it against another host's)."""
        if key is None:
            return False
        for request in self.table.pending.get(key, ()):
            if (
                not request.looped
                and request.frame.data == frame.data
                and request.frame.arbitration_id == frame.arbitration_id
                and (request.state is _SENDING or (request.sent_at is not None and at >= request.sent_at))
            ):
                request.looped = True
                request.on_wire_at = at if frame.timestamp else None
                return True
        return False

    def _seen(self, codec: BoundCodec, at: float) -> None:
        """Count another host's request to ``codec``'s motor; warn once, naming the id and rate."""
        count, first = self._hosts_seen.get(id(codec), (0, at))
        if count < 0:
            return  # (warned)
        count += 1
        self._hosts_seen[id(codec)] = (count, first)
        # (over a short window at least: through an adapter frames come in bunches, whose stamps
        # alone would make the rate look higher)
        if count >= WARN_AFTER and at - first >= RATE_WINDOW_S:
            self._hosts_seen[id(codec)] = (-1, first)
            ident = min(i & 0x1FFFFFFF for i in codec.request_ids)
            rate = (count - 1) / (at - first) if at > first else float("nan")
            logger.warning(
                "%s: another host sends requests to %s motor %d (0x%03X), about %.0f per second: "
                "its replies are kept apart from ours by order (counted 'contended')",
                self.name,
                codec.family,
                codec.motor_id,
                ident,
                rate,
            )

    def contended(
        self, codec: BoundCodec, key: Hashable, frame: Frame, reply: Reply, now: float
    ) -> Received | None:
        """The reply ``frame`` with ``key``, while another host's request with that key waits: the
        verdict if it answers that one (it reached the motor before our request waiting for the key,
        and after any of ours whose late reply is held for), else None (matched as usual)."""
        placeholders = self.foreign[key]
        at = frame.timestamp or now
        # Never answered (lost, or not to be), by the reply's own stamp. Or answered this late (a
        # stalled host, a slow adapter): then this reply may be its answer, so a request of ours
        # handed over while that one's reply was still expected, that takes it, is ambiguous.
        if placeholders[0][1] < at:
            expected = 0.0
            while placeholders and placeholders[0][1] < at:
                expected = placeholders.popleft()[1]
            waiting = self.table.pending.get(key)
            if waiting:
                ours = waiting[0]
                if ours.handed_at is not None and ours.handed_at < expected and not ours.crossed:
                    ours.crossed = True
                    self.count(codec, "ambiguous")
        if not placeholders:
            del self.foreign[key]
            return None
        stamp = placeholders[0][0]
        if at < stamp + self.table.min_reply_s and self.exact_order:
            return None  # too early to answer it (through an adapter, stamps of one read are alike)
        waiting = self.table.pending.get(key)
        if waiting:
            ours = waiting[0]
            if ours.on_wire_at is not None:  # (looped back: its end on the wire, as theirs)
                if stamp > ours.on_wire_at:
                    return None  # ours reached the motor first
            elif self.exact_order:
                left = ours.sent_at if ours.state is _SENT else ours.handed_at
                # one frame's time: it may still have been on the wire when ours was handed over
                if left is not None and stamp > left + 1.5 * self.table.min_reply_s:
                    return None  # ours reached the motor first
            elif ours.handed_at is not None and stamp > ours.handed_at:
                # Theirs came in after ours was handed over, before this reply: the order the two
                # reached the motor in is not known. Ours takes the later of the two replies.
                if ours.crossed:
                    return None  # (the later one: another host's request after that is after ours)
                ours.crossed = True
                self.count(codec, "ambiguous")
        late = self.keys.late.get(key)
        if late and any(e[1] is not None and e[1] < stamp and e[3] >= now for e in late):
            return None  # a late reply of ours is due first
        placeholders.popleft()
        if not placeholders:
            del self.foreign[key]
        self.count(codec, "contended")
        return Received(_T_CONTENDED, frame, codec, reply)
