"""What ``servobus demo`` shows: the plan (why so many buses), the live view, and the summary.

Numbers only come in here (:class:`Summary`, built by the demo from the Bus's metrics, the pacer's
ticks and the process's CPU time); nothing here talks to a bus.
"""

from __future__ import annotations

import itertools
import math
import os
from dataclasses import asdict, dataclass
from typing import Any

from rich.text import Text

from servobus.timing import frame_time_s

__all__ = ["Layout", "Summary", "layout", "live_view", "summary_lines"]

#: a tick's bus traffic must fit in this share of the period
MARGIN = 0.9


@dataclass(frozen=True, slots=True)
class Layout:
    """How the motors are spread over buses, and why."""

    hz: float
    motors: int
    per_bus: tuple[int, ...]  # motors on each bus
    capacity: int  # motors one bus carries per tick within the margin
    pair_s: float  # wire time of one request and its reply
    turnaround_s: float

    @property
    def buses(self) -> int:
        return len(self.per_bus)

    def tick_wire_s(self, k: int) -> float:
        """Wire time of one tick on a bus of ``k`` motors: requests win arbitration over replies, the
        first reply waits for its motor's turnaround, then the replies follow one another."""
        frame = self.pair_s / 2
        return max(k * self.pair_s, frame + self.turnaround_s + k * frame)

    def why(self) -> str:
        period_ms = 1e3 / self.hz
        return (
            f"classic CAN at 1 Mbit/s: a request and its reply take {self.pair_s * 1e3:.2f} ms of wire time, "
            f"so one bus carries at most {self.capacity} motor(s) per {period_ms:g} ms tick with margin "
            f"({self.tick_wire_s(self.capacity) * 1e3:.2f} ms of {MARGIN * period_ms:.2f} ms): "
            f"{self.motors} motor(s) -> {self.buses} bus" + ("es" if self.buses > 1 else "")
        )

    def overload(self) -> str | None:
        """A warning when a bus carries more motors than fit in a tick."""
        worst = max(self.per_bus)
        wire = self.tick_wire_s(worst)
        if wire <= 1 / self.hz:
            return None
        return (
            f"{worst} motors on one bus need {wire * 1e3:.2f} ms of wire time per tick, more than the "
            f"{1e3 / self.hz:g} ms period: ticks will be missed (use more --buses or a lower --hz)"
        )


def layout(hz: float, motors: int, buses: int | None, turnaround_s: float) -> Layout:
    """Spread ``motors`` over ``buses`` (default: as few as carry them at ``hz`` within the margin)."""
    from servobus.frame import Frame

    # An 8-byte position command and an 8-byte status reply (all-zero data: most stuff bits).
    pair = frame_time_s(Frame(arbitration_id=0x141, data=bytes(8))) + frame_time_s(
        Frame(arbitration_id=0x241, data=bytes(8))
    )
    probe = Layout(hz, motors, (), 0, pair, turnaround_s)
    capacity = 0
    while probe.tick_wire_s(capacity + 1) <= MARGIN / hz:
        capacity += 1
    count = buses or max(1, math.ceil(motors / max(capacity, 1)))
    count = min(count, motors)
    per_bus = tuple(motors // count + (1 if b < motors % count else 0) for b in range(count))
    return Layout(hz, motors, per_bus, capacity, pair, turnaround_s)


@dataclass(slots=True)
class Summary:
    """What a run achieved.

    The CPU figures are the process's (``time.process_time``): with a pacer that sleeps between ticks
    they are the work a tick costs, host and simulator, not the wall time it spans. The simulator's
    share is timed apart (its networks' entry points), so the host's is the rest.
    """

    hz: float
    motors: int
    buses: int
    seconds: float
    ticks: int
    missed_ticks: int
    late_p99_ms: float
    tick_p50_ms: float  # median CPU time of a tick: the process's, from its start to the next's
    wire_ms: float  # what the busiest bus's wire needs per tick
    pairs: int
    latency_p50_ms: float | None
    latency_p99_ms: float | None
    bus_load_mean_pct: float | None
    bus_load_max_pct: float | None
    timeouts: int
    not_sent: int
    malformed: int
    faults: int
    cpu_s: float
    simulator_cpu_s: float
    # the pipelined loop's own counts (servobus.loop.LoopMetrics)
    state_age_p50_ms: float | None = None  # tick start - when the command its state answers left
    state_age_p99_ms: float | None = None
    state_age_max_ms: float | None = None
    late_ticks: int = 0  # started more than 200 µs after their deadline
    overruns: int = 0  # a body ran past the next tick's deadline
    stale_states: int = 0  # (motor, tick): a commanded motor without fresh state
    superseded: int = 0  # commands withdrawn for a newer one before they left
    lost: int = 0  # the loop's: commands with no reply within its horizon (the Bus timed them out)
    preempted: int = 0  # involuntary context switches: the kernel gave the core to other work
    interrupted: bool = False
    live: bool = False  # the live view was drawn (not under --duration)

    @property
    def achieved_hz(self) -> float:
        return self.ticks / self.seconds if self.seconds > 0 else 0.0

    @property
    def errors(self) -> int:
        # (the Bus's counts: a command the loop calls lost timed out there first, counted once)
        return self.timeouts + self.not_sent + self.malformed + self.faults

    @property
    def run_pct(self) -> float:
        """Ticks run, in % of the ticks due (run + missed)."""
        due = self.ticks + self.missed_ticks
        return 100.0 * self.ticks / due if due else 0.0

    @property
    def host_us_per_tick(self) -> float:
        """The host side's CPU per tick (the loop, the buses, the demo's body), the simulator's apart."""
        return max(0.0, self.cpu_s - self.simulator_cpu_s) / self.ticks * 1e6 if self.ticks else 0.0

    @property
    def simulator_us_per_tick(self) -> float:
        return self.simulator_cpu_s / self.ticks * 1e6 if self.ticks else 0.0

    @property
    def cpu_pct(self) -> float:
        """The process's CPU in % of one core over the run."""
        return 100.0 * self.cpu_s / self.seconds if self.seconds > 0 else 0.0

    def machine(self) -> str:
        """This machine and its load, as the summary states them beside its figures."""
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
        return f"this machine: {os.cpu_count() or 1} cores, load average {load:.1f}"

    def why(self) -> str | None:
        """Why the target rate was not kept (None when it was: 99 % of it)."""
        if self.ticks == 0 or self.achieved_hz >= 0.99 * self.hz:
            return None
        period_ms = 1e3 / self.hz
        cpu_share = self.cpu_s / self.seconds if self.seconds > 0 else 0.0
        sim_ms = self.simulator_cpu_s / self.ticks * 1e3
        host_ms = self.host_us_per_tick / 1e3
        mean_ms = self.cpu_s / self.ticks * 1e3
        cores = os.cpu_count() or 1
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
        machine = self.machine()
        if cpu_share < 0.8:
            machine += f"; the process got only {cpu_share:.0%} of a core, other work held the rest"
        if self.tick_p50_ms > period_ms:
            return (
                f"CPU-bound: a tick took {self.tick_p50_ms:.2f} ms of CPU (median; the wire needs "
                f"{self.wire_ms:.2f} ms), {mean_ms:.2f} ms on average, {sim_ms:.2f} ms of it simulating "
                f"{self.motors} motors and {host_ms:.2f} ms the host's loop; simulator and host share one "
                "core in one process, "
                f"and {self.hz:g} Hz leaves {period_ms:.2f} ms per tick ({machine}). Fewer --motors or "
                "a lower --hz keep up."
            )
        # A median tick's CPU fits the period: the wall time lost went to other work (the process
        # ran less than the ticks it ran needed), or to pauses and ticks far dearer than the median.
        if cpu_share < 0.8 * min(1.0, self.hz * mean_ms / 1e3):
            return (
                f"the process got only {cpu_share:.0%} of a CPU core ({cores} cores, load average "
                f"{load:.1f}, preempted {self.preempted:,} times): other work held the processor; a "
                f"tick took {self.tick_p50_ms:.2f} ms of CPU (median; {mean_ms:.2f} ms on average) of "
                f"{period_ms:.2f} ms"
            )
        return (
            f"most ticks fit (median {self.tick_p50_ms:.2f} ms of CPU of {period_ms:.2f} ms, "
            f"{sim_ms:.2f} ms of it simulating; {mean_ms:.2f} ms on average, {self.overruns:,} "
            f"overrun(s)), but the loop paused now and then ({machine}): "
            + ("a redraw of the live view, or other processes" if self.live else "other processes")
        )

    def as_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out.update(
            achieved_hz=round(self.achieved_hz, 2),
            run_pct=round(self.run_pct, 2),
            host_us_per_tick=round(self.host_us_per_tick, 1),
            simulator_us_per_tick=round(self.simulator_us_per_tick, 1),
            cpu_pct=round(self.cpu_pct, 1),
            errors=self.errors,
            why=self.why(),
        )
        del out["live"]  # (a summary in JSON comes of --duration: never live)
        return out


def _ms(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2f} ms"


def _pct(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.1f} %"


def summary_lines(s: Summary) -> list[str]:
    """The summary, one fact per line."""
    lines = [
        f"achieved    {s.achieved_hz:,.1f} ticks/s of {s.hz:g} Hz over {s.seconds:.2f} s "
        f"({s.ticks:,} ticks, {s.pairs:,} request/reply pairs, {s.pairs / max(s.seconds, 1e-9):,.0f}/s)",
        f"missed      {s.missed_ticks:,} ticks (pacer lateness p99 {s.late_p99_ms:.2f} ms; "
        f"{s.late_ticks:,} late ticks, {s.overruns:,} overruns, {s.superseded:,} commands superseded)",
        f"ran         {s.run_pct:.2f} % of the {s.ticks + s.missed_ticks:,} ticks due ({s.machine()})",
        f"host CPU    {s.host_us_per_tick:,.0f} µs per tick, the simulator's "
        f"{s.simulator_us_per_tick:,.0f} µs apart ({s.cpu_pct:.0f} % of a core in all; "
        f"preempted {s.preempted:,} times)",
        f"state age   p50 {_ms(s.state_age_p50_ms)}, p99 {_ms(s.state_age_p99_ms)}, max "
        f"{_ms(s.state_age_max_ms)} (tick start - its state's command left; {s.stale_states:,} stale, "
        f"{s.lost:,} lost)",
        f"latency     p50 {_ms(s.latency_p50_ms)}, p99 {_ms(s.latency_p99_ms)} "
        "(request left -> reply in; worst bus)",
        f"bus load    mean {_pct(s.bus_load_mean_pct)}, max {_pct(s.bus_load_max_pct)}",
        f"errors      {s.errors} (timeouts {s.timeouts}, not sent {s.not_sent}, malformed {s.malformed}, "
        f"motor faults {s.faults})",
    ]
    why = s.why()
    if why:
        lines.append(f"why         {why}")
    if s.interrupted:
        from servobus.cli import safe_exits, stopped_by

        by = stopped_by()
        stops = safe_exits().removeprefix("; ") or "no motor was commanded"
        lines.append(f"stopped     {by}: {stops}")
    return lines


#: the live view's columns (a row gives one value for each)
COLUMNS = ("motor", "bus", "angle °", "target °", "speed dps", "current A", "temp °C", "age ms")


def live_view(header: list[str], rows: list[tuple[str, ...]], width: int | None = None) -> Text:
    """The live view: a few header lines and the motors' table (two side by side above 16 motors,
    where ``width`` allows).

    One :class:`~rich.text.Text` of fixed-width lines: rich draws it in about a millisecond, where a
    :class:`~rich.table.Table` of 32 motors took 50-150 ms here, a pause of as many ticks at 1 kHz
    with every motor's request in flight.
    """
    widths = [max(len(name), *(len(row[i]) for row in rows)) for i, name in enumerate(COLUMNS)]
    head = "  ".join(name.rjust(w) for name, w in zip(COLUMNS, widths, strict=True))
    halves = [rows]
    if len(rows) > 16 and (width is None or width >= 2 * len(head) + 3):
        halves = [rows[: (len(rows) + 1) // 2], rows[(len(rows) + 1) // 2 :]]
    lines = [[head, "-" * len(head)] for _ in halves]
    for half, out in zip(halves, lines, strict=True):
        out.extend("  ".join(v.rjust(w) for v, w in zip(row, widths, strict=True)) for row in half)
    table = [" | ".join(parts).rstrip() for parts in itertools.zip_longest(*lines, fillvalue=" " * len(head))]
    above = "".join(line + "\n" for line in [*header, ""])
    text = Text(above + "\n".join(table))
    text.stylize("bold", len(above), len(above) + len(table[0]))  # (the column names)
    return text
