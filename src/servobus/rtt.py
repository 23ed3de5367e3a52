"""Round-trip estimates: how long a motor takes to answer, and so how long to wait for it.

RFC 6298's estimator (TCP's retransmission timer), on the request-to-reply times the transport
stamps: a smoothed round trip ``srtt`` and its mean deviation ``rttvar``; a reply is expected within
``srtt + max(granularity, 4 * rttvar)``. The first sample sets ``srtt = R`` and ``rttvar = R / 2``;
each later one moves them by 1/8 and 1/4 of the difference. Before any sample there is no
estimate: the caller uses a conservative first value (the first exchange through a freshly opened
adapter is often ten times slower than the next ones).

Late replies are samples too (their request is known: the scheduler holds its key until the reply
came), so the estimate follows a slow adapter instead of timing out on every reply; ``peak_s``
keeps the longest recent late one (:meth:`add_late`), decaying slowly, for how long a late reply
may still come (a reply in time is within the timeout, which :meth:`late_s` covers anyway).

Sans-IO: the caller gives every sample.
"""

from __future__ import annotations

__all__ = ["RoundTrip"]

#: A timer cannot be finer than the event loop's wake-ups (epoll counts milliseconds).
GRANULARITY_S = 0.001
# How fast the peak forgets an old long sample: by 1/64 of itself per sample.
_PEAK_KEEP = 1.0 - 1.0 / 64


class RoundTrip:
    """One smoothed round-trip estimate (one motor and command class, or one bus).

    Attributes:
        samples: how many round trips were measured.
        srtt_s: the smoothed round trip (0.0 before the first sample).
        rttvar_s: its smoothed mean deviation.
        peak_s: the longest recent late round trip (slowly forgotten), or the first sample.
        rto_s: :meth:`timeout_s`, kept up to date (an attribute read on the per-request path).
        base_s: the owner's stated time for what is measured (a codec's timeout for the command).
        floor_s: the least timeout the owner gives, whatever the estimate (a slow command keeps the
            time its codec states: a flash write measured fast once can be slow the next time).
    """

    __slots__ = ("base_s", "floor_s", "peak_s", "rto_s", "rttvar_s", "samples", "srtt_s")

    def __init__(self, base_s: float = 0.0, floor_s: float = 0.0) -> None:
        self.base_s = base_s
        self.floor_s = floor_s
        self.samples = 0
        self.srtt_s = 0.0
        self.rttvar_s = 0.0
        self.peak_s = 0.0
        self.rto_s = GRANULARITY_S

    def add(self, rtt_s: float) -> None:
        """Note one measured round trip (negative values, a clock step, count as 0)."""
        if rtt_s < 0.0:
            rtt_s = 0.0
        if self.samples:
            err = rtt_s - self.srtt_s
            self.rttvar_s += 0.25 * ((err if err >= 0.0 else -err) - self.rttvar_s)
            self.srtt_s += 0.125 * err
        else:
            self.srtt_s = self.peak_s = rtt_s
            self.rttvar_s = rtt_s / 2
        self.samples += 1
        spread = 4.0 * self.rttvar_s
        self.rto_s = self.srtt_s + (spread if spread > GRANULARITY_S else GRANULARITY_S)

    def add_late(self, rtt_s: float) -> None:
        """Note the round trip of a late reply: a sample, and the new peak if it is longer."""
        self.add(rtt_s)
        peak = self.peak_s * _PEAK_KEEP
        self.peak_s = rtt_s if rtt_s > peak else peak

    def timeout_s(self) -> float:
        """How long to wait for a reply: ``srtt + max(granularity, 4 * rttvar)`` (RFC 6298 §2)."""
        return self.rto_s

    def late_s(self) -> float:
        """How late a reply may still come after its request left: twice the timeout, and half as
        much again as the longest recent round trip."""
        a, b = 2.0 * self.timeout_s(), 1.5 * self.peak_s
        return a if a > b else b

    def __repr__(self) -> str:
        return (
            f"<RoundTrip {self.samples} samples, srtt {self.srtt_s * 1e3:.2f} ms, "
            f"rttvar {self.rttvar_s * 1e3:.2f} ms, peak {self.peak_s * 1e3:.2f} ms>"
        )
