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

:class:`Estimates` keeps one :class:`RoundTrip` per motor and command class for a bus (the
scheduler's), and the rules that turn them into timeouts and late holds.

Sans-IO: the caller gives every sample.
"""

from __future__ import annotations

__all__ = ["TRUSTED_SAMPLES", "Estimates", "RoundTrip"]

#: Round trips an estimate must rest on before it bounds how late a reply may come (a late hold).
TRUSTED_SAMPLES = 16

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


class Estimates:
    """The round-trip estimates of one bus: one :class:`RoundTrip` per motor (by the identity of
    its codec: a plug-in's codec need not be hashable) and command class, and the timeouts they give.

    Attributes:
        motors: motor -> command class -> estimate (a class appears once a request for it was made).
        any_measured: a round trip was measured on the bus (before: ``initial_timeout_s``).
        initial_timeout_s, min_timeout_s, max_timeout_s: see :class:`~servobus.scheduler.Scheduler`.
    """

    __slots__ = ("any_measured", "initial_timeout_s", "max_timeout_s", "min_timeout_s", "motors")

    def __init__(self, initial_timeout_s: float, min_timeout_s: float, max_timeout_s: float) -> None:
        self.initial_timeout_s = initial_timeout_s
        self.min_timeout_s = min_timeout_s
        self.max_timeout_s = max_timeout_s
        self.motors: dict[int, dict[type, RoundTrip]] = {}
        self.any_measured = False

    def add_motor(self, motor: int) -> None:
        self.motors[motor] = {}

    def new(self, motor: int, command_class: type, base_s: float) -> RoundTrip:
        """The estimate of a command class not measured before on ``motor`` (``base_s``: the codec's
        own time for it); the least timeout of each class of the motor is set again: ``min_timeout_s``,
        and for a class its codec gives more time than its quickest class (a ROM write), that time."""
        rtts = self.motors[motor]
        rtt = rtts[command_class] = RoundTrip(base_s)
        quickest = min(r.base_s for r in rtts.values())
        for each in rtts.values():
            each.floor_s = max(self.min_timeout_s, each.base_s if each.base_s > quickest else 0.0)
        return rtt

    def get(self, motor: int, command_class: type) -> RoundTrip | None:
        """The estimate of ``motor`` for ``command_class`` (None: never requested)."""
        return self.motors.get(motor, {}).get(command_class)

    def motor_timeout_s(self, motor: int) -> float:
        """The longest timeout measured round trips give any command class of ``motor``
        (``min_timeout_s`` while none was measured)."""
        times = [r.timeout_s() for r in self.motors.get(motor, {}).values() if r.samples]
        return max([self.min_timeout_s, *times])

    def measured(self) -> list[RoundTrip]:
        """Every estimate with a sample, of every motor and command class."""
        return [r for rtts in self.motors.values() for r in rtts.values() if r.samples]

    def first_measured(self) -> None:
        """The bus's first round trip was measured: timeouts come from estimates from now on."""
        self.any_measured = True

    def timeout_s(self, rtt: RoundTrip) -> float | None:
        """The timeout of a request timed by ``rtt`` leaving now: its estimate's, at least its floor;
        not measured yet, the codec's own time or twice the slowest measured on this bus if longer
        (the adapter's and the host's share is the same for all); None while nothing on the bus was
        measured (the caller's first value, ``max(rtt.base_s, initial_timeout_s)``, is provisional)."""
        if rtt.samples:
            timeout = max(rtt.timeout_s(), rtt.floor_s)
        elif self.any_measured:
            link = max(r.timeout_s() for r in self.measured())
            timeout = max(rtt.base_s, 2.0 * link)
        else:
            return None
        return min(max(timeout, self.min_timeout_s), self.max_timeout_s)

    def late_s(self, rtt: RoundTrip | None) -> float:
        """How late a reply timed by ``rtt`` may come after its request left: from its estimate once
        that rests on ``TRUSTED_SAMPLES`` round trips; before, twice the codec's own time for the
        command, or the bus's slowest trusted estimate if longer. A tail guessed from a few samples
        is too short: the first replies through a jittery adapter said 1.1 ms where 11 ms came."""
        if rtt is not None and rtt.samples >= TRUSTED_SAMPLES:
            return rtt.late_s()
        trusted = [r.late_s() for r in self.measured() if r.samples >= TRUSTED_SAMPLES]
        return max([2.0 * rtt.base_s if rtt is not None else 0.0, *trusted])
