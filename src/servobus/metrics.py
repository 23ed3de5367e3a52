"""A bus's and a motor's health in numbers: counters by kind, request-to-reply latency, bus load.

The scheduler counts and samples (sans-IO: every time is a clock value it was given); this module
holds the sample window and the frozen snapshots ``bus.metrics()`` and ``motor.metrics()`` return.
Latency is measured from when the transport reported the request's frame left to when the reply's
frame was received (the transport's own timestamps), so it is the motor's and the wire's time, not
the time the event loop took to notice.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass

__all__ = ["Latency", "LatencyWindow", "Metrics"]


@dataclass(frozen=True, slots=True)
class Latency:
    """Request-to-reply times of the most recent replies (None while there are none).

    Percentiles are nearest-rank: ``p99_s`` is a latency that was actually measured.
    """

    samples: int
    p50_s: float | None
    p99_s: float | None
    max_s: float | None


class LatencyWindow:
    """The last ``size`` latencies, in seconds."""

    __slots__ = ("_samples", "add")

    def __init__(self, size: int = 1024) -> None:
        if size < 1:
            raise ValueError(f"size={size} must be at least 1")
        self._samples: deque[float] = deque(maxlen=size)
        #: Note one latency, in seconds (the deque's own append: once per reply, no Python call).
        self.add: Callable[[float], None] = self._samples.append

    def extend(self, other: LatencyWindow) -> None:
        self._samples.extend(other._samples)

    def __len__(self) -> int:
        return len(self._samples)

    def clear(self) -> None:
        self._samples.clear()

    def snapshot(self) -> Latency:
        ordered = sorted(self._samples)
        n = len(ordered)
        if not n:
            return Latency(0, None, None, None)

        def rank(q: float) -> float:
            return ordered[max(0, math.ceil(q * n) - 1)]

        return Latency(n, rank(0.50), rank(0.99), ordered[-1])


@dataclass(frozen=True, slots=True)
class Metrics:
    """Counters since the Bus was created, the recent latency, and (for a bus) the line's load.

    Attributes:
        requests: requests submitted (a retry is not a new request). Each ends once, as one of
            ``replies``, ``timeouts``, ``cancelled`` or ``failed``: while none is pending,
            requests = replies + timeouts + cancelled + failed.
        replies: requests answered (by a reply, or by a stream frame of the streamed command), and
            requests for no reply that left.
        timeouts: requests that got no reply in time (after their retries).
        cancelled: requests their caller stopped waiting for (a cancelled task, a timeout around it).
        failed: requests that ended with an error: not sent (``not_sent``), a reply that does not
            decode, the transport lost, the Bus closed.
        retries: automatic resends of retry-safe reads.
        not_sent: requests the transport dropped (stale, purged, lost) or refused (part of ``failed``).
        skipped: commands ``cycle()`` did not send, so never requests: the motor offline
            (MotorOffline; but for the probes, which are requests), its last reply still due
            (MotorBusy), or streaming (MotorStreaming).
        ambiguous: replies that may have been the late reply of the request before (its key's hold
            ended before that reply came, so the two could not be told apart).
        stream_off_resent: 0xB6 "off" sent again because a stream kept coming after it.
        late: replies of requests that had timed out or were cancelled.
        duplicate: the same reply again, right after one answered its request.
        unsolicited: reply-shaped frames of a motor that nobody asked for.
        malformed: frames of a motor that did not decode (never taken as a reply).
        stream, report: a motor's 0xB6 stream frames and automatic error reports.
        foreign: frames of no motor on this bus (bus only; always 0 for a motor).
        foreign_requests: another host's requests to the motor (CAN is broadcast: a second
            controller on the bus).
        contended: replies to another host's requests (the motor's state; never taken as ours).
        limit_refused: commands refused because they went beyond the motor's host-side limits
            (:mod:`servobus.limits`; never requests).
        limit_clamped: commands sent clamped to the motor's host-side limits.
        latency: request-to-reply time of the last replies.
        bus_load_pct: share of the line used in the last second, from the transport (bus only;
            None when unknown).
        restarts: times a motor came back online from a restart (servobus.bus.restarts).
        not_executed: requests a motor echoed back instead of executing them (MotorNotExecuted;
            part of ``failed``).
        comm_tripped: frames in which a motor said its communication watchdog tripped (MyActuator
            0xF1; also counted in ``report``).
    """

    requests: int
    replies: int
    timeouts: int
    cancelled: int
    failed: int
    retries: int
    not_sent: int
    skipped: int
    ambiguous: int
    stream_off_resent: int
    late: int
    duplicate: int
    unsolicited: int
    malformed: int
    stream: int
    report: int
    foreign: int
    latency: Latency
    bus_load_pct: float | None = None
    restarts: int = 0
    not_executed: int = 0
    comm_tripped: int = 0
    foreign_requests: int = 0
    contended: int = 0
    limit_refused: int = 0
    limit_clamped: int = 0

    @classmethod
    def of(cls, counts: Mapping[str, int], latency: Latency, bus_load_pct: float | None = None) -> Metrics:
        """A snapshot from the scheduler's counters (``not_sent_<reason>`` summed into ``not_sent``)."""
        not_sent = sum(v for k, v in counts.items() if k.startswith("not_sent_"))
        c = counts.get
        return cls(
            requests=c("requests", 0),
            replies=c("replies", 0),
            timeouts=c("timeouts", 0),
            cancelled=c("cancelled", 0),
            failed=c("failed", 0),
            retries=c("retries", 0),
            not_sent=not_sent,
            skipped=c("skipped_offline", 0) + c("skipped_busy", 0) + c("skipped_streaming", 0),
            ambiguous=c("ambiguous", 0),
            stream_off_resent=c("stream_off_resent", 0),
            late=c("late", 0),
            duplicate=c("duplicate", 0),
            unsolicited=c("unsolicited", 0),
            malformed=c("malformed", 0),
            stream=c("stream", 0),
            report=c("report", 0),
            foreign=c("foreign", 0),
            latency=latency,
            bus_load_pct=bus_load_pct,
            restarts=c("restarts", 0),
            not_executed=c("not_executed", 0),
            comm_tripped=c("comm_tripped", 0),
            foreign_requests=c("foreign_requests", 0),
            contended=c("contended", 0),
            limit_refused=c("limit_refused", 0),
            limit_clamped=c("limit_clamped", 0),
        )
