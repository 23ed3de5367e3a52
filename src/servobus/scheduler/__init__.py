"""The request scheduler of one bus: sans-IO, like the codecs below it (h11's model).

The Bus is its only caller. It hands the scheduler requests, the frames the transport received and
the transport's send reports, each with a clock value (intake: :meth:`Scheduler.receive`,
:meth:`Scheduler.sent`, :meth:`Scheduler.not_sent`); the scheduler answers with decisions (what to
send and what went stale: :meth:`Scheduler.poll`; what missed its reply: :meth:`Scheduler.expire`;
when to ask again: :meth:`Scheduler.next_deadline`) and keeps every rule about matching and timing:

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
  taken as ours (servobus.scheduler._hosts).
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
* **Pipelined requests** (``request.pipelined``: a fixed-rate loop's command, one per motor per
  tick, servobus.loop): such a request leaves while requests with its key are in flight or held,
  so several with one key to one motor are out at once. Their replies are matched as any other's:
  to the oldest request in flight with the key that the frame could answer (fresh by
  ``min_reply_s``), first in, first answered, since a motor answers in the order it was asked. A
  reply to one that timed out can therefore be taken by the next one in flight (a late reply is
  matched as the next's): the loop attributes replies by its own record of what left, never to a
  younger command than the oldest it could answer. Everything else (echoes, other hosts' requests,
  late, duplicate and overtaken frames) is judged as for any request, but for one more rule: the
  bytes of the reply a pipelined request took, again with its stamp or within half the key's
  shortest round trip after the next request left, are a DUPLICATE, not the next request's reply.
  An ordinary request with the key of pipelined ones in flight waits until none is; a pipelined one
  waits while an ordinary one with its key is in flight or held for.
* **Streams**: a request whose key a motor streams (0xB6) is answered by the first stream frame that
  arrives after the request left (the same fact, fresh), as design.md's matching rule says.

Nothing here reads a clock, sleeps or awaits: ``now`` is always an argument, so every timing rule is
tested with plain calls.

**Options** of :class:`Scheduler` (keyword arguments):

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
        a crossing within the adapter's latency is of unknown order (servobus.scheduler._hosts).
    name: the bus's label, in the errors it stores (``request.error``).

**What it may import**: the base layer (servobus.errors, servobus.frame, servobus.metrics,
servobus.rtt, ...), the family contract servobus.protocols, and servobus.diagnosis (what a bus saw
instead of a reply, asked through that contract). Never a family, a link or the Bus: the Bus
(servobus.bus) calls it, never the other way round.

**Its parts**, split by the data each owns (its private members touched by none other); the
:class:`Scheduler` composes them (under 300 lines, no mixins). A part is handed the parts it reads
or changes when it is made, never the Scheduler (it counts through ``Scheduler.count``, handed in);
the imports go one way: ``_table`` <- ``_keys`` <- ``_match``, ``_hosts`` <- ``_scheduler``.

* ``_table``: the vocabulary (:class:`Request`, :class:`RequestState`, :data:`TRANSITIONS`,
  :class:`Traffic`, :class:`Received`) and the **request table** (``RequestTable``): the queue, the
  requests in flight by key, their deadlines, the pacing of what leaves when. Its ``move`` is the
  one place a request changes state, checked against :data:`TRANSITIONS`.
* :mod:`servobus.rtt`: the **round-trip estimates** (``Estimates``: one RFC 6298
  :class:`~servobus.rtt.RoundTrip` per motor and command class) and the timeouts they give; pure.
* ``_match``: **matching**, a pure function of (table, frame, now) that returns a decision, which
  the Scheduler carries out (one call per received frame).
* ``_keys``: the **keys' memory** (``Keys``): which reply keys were answered or given up on lately
  (late, duplicate, unsolicited), the holds for late replies, and so the ends of requests off the
  hot path (timed out, retried, cancelled, failed). ``_match.judge`` carries out the decisions that
  are not a plain answer on the table and this memory.
* ``_hosts``: **other hosts** (``OtherHosts``): their requests to our motors, as placeholders in
  our motors' order of replies, and the frames no motor claims (``seen``, counted ``foreign``).

On one control tick (a ``Bus.cycle`` of many motors) only the Scheduler's module, ``_table``,
``_match`` and servobus.rtt run; ``_keys`` and ``_hosts`` run on timeouts, late or foreign frames.
"""

from servobus.rtt import TRUSTED_SAMPLES
from servobus.scheduler._scheduler import Scheduler, batch_requests, submit_batch
from servobus.scheduler._table import FINAL, TRANSITIONS, Received, Request, RequestState, Traffic

__all__ = [
    "FINAL",
    "TRANSITIONS",
    "TRUSTED_SAMPLES",
    "Received",
    "Request",
    "RequestState",
    "Scheduler",
    "Traffic",
    "batch_requests",
    "submit_batch",
]
