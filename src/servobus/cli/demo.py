"""``servobus demo``: simulated motors following smooth trajectories at 1 kHz, no hardware.

The motors are ``--family``'s (default: the registry's first, MyActuator), asked of the family itself:
its simulator part (``FAMILY.part("sim")``) builds them and says their turnaround, its command-line
part's ``move`` (``FAMILY.part("cli")``) makes the absolute position set-point (0xA4 for MyActuator; a
family without ``move``: its ``mit`` set-point, :mod:`servobus.cli._demo_parts`). Each simulated 1
Mbit/s CAN bus is a :class:`~servobus.transports.sim.SimTransport` with its motors, driven by its own
:class:`~servobus.bus.Bus`. Every motor's move is first started as the family starts one (hollow: its
mode, the set-point, Start; a ``Bus.cycle`` per step), then one pipelined :class:`~servobus.loop.Loop`
drives every bus: at each tick every motor is given its next set-point along a sine (``tick.command``;
it leaves at the next tick's deadline, every bus's batch at once), and nothing waits for the replies:
the body sees each motor's latest state and its age (``tick.state``). A live view shows each motor's
position, speed, current, temperature and state age with the achieved rate, missed ticks, overruns, bus
load and errors; with ``--duration`` the demo runs without it and prints a summary: the rate, the host's
CPU per tick with the simulator's share apart, the state's age, the latency and the errors, and, when
the rate was not kept, why. At the end of ``--duration`` the demo waits (a few ticks at most) for the
replies to the last set-points, so that every tick counted was answered.

Real time, one process: the simulated motors run on the same event loop as the host side, so one
core pays for both. Ctrl-C or SIGTERM (or the end of ``--duration``) ends the loop
(:func:`~servobus.cli._motors.stop_scope`): on a signal the Loop sends its motors the safe stop, and
every Bus sends its motors their stop as it is left. The loop runs on asyncio by default
(``--backend trio``: on trio), through anyio either way.

``--dashboard [HOST:PORT]`` serves the live web page of :mod:`servobus.dashboard` while the demo runs
(read-only, on this host only: ``servobus dashboard`` serves beyond it, with users): each simulated
link tapped for the raw frames, every Bus and the Loop watched. Its URL is the first line (on stderr
with ``--json``, so that stdout stays one JSON document).
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import anyio
import click

from servobus.bus import Bus, Motor
from servobus.cli._connect import FamilyChoice, note_exit, timeout_option
from servobus.cli._demo_parts import Parts, parts
from servobus.cli._demo_report import Layout, Summary, layout, live_view, summary_lines
from servobus.cli._motors import BACKENDS, run, stop_scope
from servobus.cli._output import SETTINGS, FloatRange, console, emit_json, examples, json_option
from servobus.cli._page import DemoPage
from servobus.cli.plugin import STATUS_SOURCES
from servobus.protocols import DEFAULT_FAMILY, Command, get_family
from servobus.sim.family import SimOptions

try:
    import resource
except ImportError:  # (not on Windows: no preemption count there)
    resource = None  # type: ignore[assignment]

if TYPE_CHECKING:
    from servobus.loop import Loop, LoopMetrics
    from servobus.loop import LoopTick as LoopTick
    from servobus.metrics import Metrics

__all__ = ["demo"]

_parts = parts  # (the dashboard's demo motion asks for it here, with _Sine and _start)

AMPLITUDE_DEG = 90.0
PERIOD_S = 4.0
REFRESH_S = 0.25
#: where ``--dashboard`` given bare serves (servobus.dashboard's DEFAULT_PORT: the extra is not imported
#: unless asked)
DASHBOARD_AT = "127.0.0.1:8765"


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus demo                      # live view until Ctrl-C",
        "servobus demo --duration 5         # no live view: a summary after 5 s",
        "servobus demo --hz 100 --motors 8  # what this machine keeps up with",
        "servobus demo --duration 5 --json",
        "servobus demo --dashboard          # and watch it in a browser: open the URL it prints",
    ),
)
@click.option(
    "--duration",
    type=FloatRange(min=0, min_open=True),
    help="Run this many seconds without the live view, then print a summary.",
)
@click.option("--hz", type=FloatRange(min=1, max=2000), default=1000.0, show_default=True, help="Tick rate.")
@click.option(
    "--motors",
    type=click.IntRange(1, 320),
    default=32,
    show_default=True,
    help="Simulated motors, ids 1.. on each bus (the demo has no --sim/--ids: every motor is simulated, "
    "spread over --buses).",
)
@click.option(
    "--buses",
    type=click.IntRange(1, 320),
    help="Simulated 1 Mbit/s buses [default: as few as carry the motors at --hz].",
)
@click.option(
    "--family",
    "-f",
    type=FamilyChoice(),
    default=DEFAULT_FAMILY,
    show_default=True,
    help="Protocol family of the simulated motors (one with a simulator, and a move or mit).",
)
@click.option(
    "--backend",
    type=click.Choice(BACKENDS),
    default="asyncio",
    show_default=True,
    help="The event loop the buses and the simulator run on (through anyio).",
)
@click.option(
    "--dashboard",
    "dashboard_at",
    is_flag=False,
    flag_value=DASHBOARD_AT,
    default=None,
    metavar="[HOST:PORT]",
    help=f"Serve the live web page of the buses and the loop while the demo runs (read-only; this host "
    f"only; port 0: any free port) [bare: {DASHBOARD_AT}].",
)
@timeout_option
@json_option
def demo(
    duration: float | None,
    hz: float,
    motors: int,
    buses: int | None,
    family: str,
    backend: str,
    dashboard_at: str | None,
    timeout_s: float | None,
    as_json: bool,
) -> None:
    """Simulated motors on simulated CAN buses following sine trajectories, in real time.

    No hardware and no arguments needed: 32 MyActuator motors at 1 kHz by default, spread over as
    many simulated 1 Mbit/s buses as classic CAN needs for that rate, driven by one pipelined loop
    (each tick's set-points leave at the next deadline; the replies are not waited for). The summary
    gives the rate kept, the host's CPU per tick and the state's age. Ctrl-C stops the motors cleanly.

    Each motor is moved by its family's move, at most 500 dps (the demo's own limit); a family
    without a move is driven by its mit set-point (the target position, velocity 0, kp 20, kd 1);
    one with neither is refused.
    """
    parts = _parts(family)
    if buses is not None and buses > motors:
        raise click.BadParameter(
            f"{buses} buses for {motors} motors: at most one bus per motor", param_hint="--buses"
        )
    if as_json and duration is None:
        raise click.UsageError("--json prints the summary of a run: give --duration")
    plan = layout(hz, motors, buses, parts.sim.turnaround_s)
    parts.ids(max(plan.per_bus))  # (refused here, in one line, where the family has too few)
    page = DemoPage.listen(dashboard_at) if dashboard_at is not None else None
    with page.sock if page is not None else contextlib.nullcontext():
        if page is not None:
            page.announce(plan.buses, err=as_json)
        summary = _demo(plan, parts, family, duration, backend, timeout_s, as_json, page)
    if summary.interrupted:
        raise KeyboardInterrupt  # exit 130 (SIGTERM: 143), after the summary (the motors were stopped)
    if summary.errors:
        raise click.ClickException(f"{summary.errors} request(s) failed during the demo")


def _demo(
    plan: Layout,
    parts: Parts,
    family: str,
    duration: float | None,
    backend: str,
    timeout_s: float | None,
    as_json: bool,
    page: DemoPage | None,
) -> Summary:
    """The demo's own lines, the run, and its summary printed."""
    if not as_json:
        where = f"{plan.buses} simulated CAN bus" + ("es" if plan.buses > 1 else "")
        click.echo(f"servobus demo: {plan.motors} simulated {family} motor(s) on {where}, {plan.hz:g} Hz")
        click.echo(plan.why())
        if parts.uses != "move":
            click.echo(f"{family} motors have no move: each follows its {parts.uses} set-point ({parts.how})")
        if (warning := plan.overload()) is not None:
            click.echo(f"warning: {warning}")
    summary = run(
        _run(plan, parts, duration, live=duration is None, timeout_s=timeout_s, page=page), backend=backend
    )
    if as_json:
        emit_json(summary.as_dict())
    else:
        for line in summary_lines(summary):
            click.echo(line)
    return summary


class _SimClock:
    """Time spent in the simulator: the networks' own entry points, timed.

    On ``time.perf_counter``: the entry points never block or sleep, so their wall time is their CPU
    time, and the counter is read in tens of nanoseconds where ``time.thread_time`` is a system call
    (timed with it, the demo spent a third of its loop reading the clock). An entry point called from
    another (on the same network) is timed once, by the outer one.
    """

    #: the networks' entry points the host side calls (those a network has; ``host_turn``: advance,
    #: run ahead and the next event in one call, where the network offers it)
    ENTRY_POINTS = ("send", "send_many", "advance", "run_ahead", "host_turn", "next_event_s")

    def __init__(self) -> None:
        self.seconds = 0.0
        self._depth = 0

    def wrap(self, network: Any) -> None:
        for name in self.ENTRY_POINTS:
            if callable(method := getattr(network, name, None)):
                setattr(network, name, self._timed(method))

    def _timed(self, method: Callable[..., Any]) -> Callable[..., Any]:
        clock = time.perf_counter

        def timed(*args: Any, **kwargs: Any) -> Any:
            if self._depth:
                return method(*args, **kwargs)
            self._depth = 1
            start = clock()
            try:
                return method(*args, **kwargs)
            finally:
                self.seconds += clock() - start
                self._depth = 0

        return timed


async def _run(
    plan: Layout,
    parts: Parts,
    duration: float | None,
    *,
    live: bool,
    timeout_s: float | None,
    page: DemoPage | None = None,
) -> Summary:
    from servobus.loop import Loop
    from servobus.transports.sim import SimTransport

    revision = get_family(parts.family).default_revision
    sim_clock = _SimClock()
    async with contextlib.AsyncExitStack() as stack:
        buses: list[tuple[Bus, list[Motor]]] = []

        def noted() -> None:
            for bus, _ in buses:
                note_exit(bus)

        stack.callback(noted)  # (first in, so it runs after every Bus was left)
        for b, count in enumerate(plan.per_bus):
            ids = parts.ids(count)  # (1..count where the family's ids never collide)
            setup = parts.sim.devices(ids, revision, SimOptions())
            transport = SimTransport(devices=setup.can_devices, name=f"sim{b + 1}")
            sim_clock.wrap(transport.network)
            link = page.dash.tap(transport) if page is not None else transport
            bus = await stack.enter_async_context(Bus(link, name=f"bus {b + 1}"))
            buses.append((bus, [bus.motor(parts.family, i) for i in ids]))
            if page is not None:
                page.dash.watch(bus)
        sine = _Sine([m for _, motors in buses for m in motors], parts)
        before = [bus.metrics() for bus, _ in buses]
        view = None
        if live:
            from rich.live import Live

            view = Live(console=console(), auto_refresh=False, transient=False)
            view.start()
        loop = Loop(plan.hz, timeout_s=timeout_s)
        if page is not None:
            page.dash.watch_loop(loop)
            await stack.enter_async_context(page.serving())  # (left first: the page ends before the Buses)
        run = _Ticks(sim_clock)
        try:
            with stop_scope() as stopping:  # Ctrl-C, SIGTERM: the loop sends its stop, the Buses theirs
                await _start(buses, sine, timeout_s)
                before = [bus.metrics() for bus, _ in buses]  # (the loop's figures count from here)
                async with loop:
                    await run.go(loop, sine, duration, view, plan, buses)
        finally:
            if view is not None:
                view.stop()
                if not view.console.is_terminal:  # (rich ends the last frame's line on a terminal only)
                    view.console.line()
        summary = _summarise(plan, buses, run, loop.metrics(), before)
        summary.interrupted = stopping.cancelled_caught
        summary.live = view is not None
    return summary


async def _start(buses: list[tuple[Bus, list[Motor]]], sine: _Sine, timeout_s: float | None) -> None:
    """Start every motor's move at its first target as the family's ``move`` does (hollow: its mode,
    the set-point, Start), a ``Bus.cycle`` per step, every bus at once; a failure is counted in the
    Bus's metrics, like the loop's."""
    first = {id(m): sine.parts.start(m, sine.target(n, 0.0)) for n, m in enumerate(sine.motors)}

    async def start(bus: Bus, motors: list[Motor]) -> None:
        for step in range(max(len(first[id(m)]) for m in motors)):
            await bus.cycle(
                [(m, first[id(m)][step]) for m in motors if step < len(first[id(m)])], timeout_s=timeout_s
            )

    async with anyio.create_task_group() as group:
        for bus, motors in buses:
            group.start_soon(start, bus, motors)


class _Sine:
    """Each motor's target along its sine (phases spread over the motors), and its set-point.

    The targets are on a 0.01° grid and a sine revisits its values (every motor the same ones,
    shifted by its phase), so each set-point is made once and reused: a command is an immutable value,
    and making 32 a tick through the move's builder, range checks included, costs the host ~5 µs
    each, as much as the loop's own work for them. Motors share a cache when their set-points are
    equal (same family, revision and model: the motor's id is not in the command).
    """

    #: angles at which two motors' set-points are compared to share a cache
    PROBES_DEG = (-45.67, 0.0, 12.34)

    def __init__(self, motors: list[Motor], parts: Parts) -> None:
        self.motors = motors
        self.parts = parts
        self.phases = [2 * math.pi * n / len(motors) for n in range(len(motors))]
        self.targets = [0.0] * len(motors)
        self._caches: list[dict[float, Command]] = []  # each motor's
        kinds: list[tuple[tuple[Command, ...], dict[float, Command]]] = []
        for motor in motors:
            probes = tuple(parts.setpoint(motor, angle) for angle in self.PROBES_DEG)
            cache = next((c for p, c in kinds if p == probes), None)
            if cache is None:
                cache = {}
                kinds.append((probes, cache))
            self._caches.append(cache)

    def target(self, n: int, t: float) -> float:
        return round(AMPLITUDE_DEG * math.sin(2 * math.pi * t / PERIOD_S + self.phases[n]), 2)

    def command(self, tick: LoopTick, t: float) -> None:
        """Give every motor its set-point for ``t`` (it leaves at the next tick's deadline): the
        targets as :meth:`target` makes them, written out (32 motors a tick)."""
        setpoint, command, targets, sin = self.parts.setpoint, tick.command, self.targets, math.sin
        base = 2 * math.pi * t / PERIOD_S
        for n, (motor, cache, phase) in enumerate(zip(self.motors, self._caches, self.phases, strict=True)):
            targets[n] = angle = round(AMPLITUDE_DEG * sin(base + phase), 2)
            made = cache.get(angle)
            if made is None:
                made = cache[angle] = setpoint(motor, angle)
            command(motor, made)


class _Ticks:
    """The demo's loop body and what it measures: the process's CPU between tick starts (one
    ``process_time`` read per tick); the age of the state one motor sees, a motor each tick in turn
    (over the whole run, where the loop's own figures are of a recent window); and over the ticks
    run, the CPU, the simulator's share of it, the wall time and the preemptions."""

    def __init__(self, sim_clock: _SimClock) -> None:
        self.count = 0  # ticks that gave every motor its set-point
        self.tick_cpu: list[float] = []
        self.ages_s: list[float] = []
        self.wall_s = self.cpu_s = self.sim_s = 0.0
        self.preempted = 0
        self._sim_clock = sim_clock
        self._from: tuple[float, float, float, int] = (0.0, 0.0, 0.0, 0)

    async def go(
        self,
        loop: Loop,
        sine: _Sine,
        duration: float | None,
        view: Any,
        plan: Layout,
        buses: list[tuple[Bus, list[Motor]]],
    ) -> None:
        cpu = time.process_time
        self._from = (time.perf_counter(), cpu(), self._sim_clock.seconds, _preemptions())
        last_cpu = self._from[1]
        motors = sine.motors
        drain = max(2, math.ceil(_DRAIN_S * loop.hz))
        start: float | None = None
        next_refresh = -math.inf
        sent_at: int | None = None  # the tick whose deadline the last set-points left at
        try:
            async for tick in loop:
                now_cpu = cpu()
                if start is None:
                    start = tick.deadline
                elif sent_at is None:
                    self.tick_cpu.append(now_cpu - last_cpu)
                last_cpu = now_cpu
                t = tick.deadline - start
                if duration is not None and t >= duration:
                    # The last set-points left at this deadline: wait (a few ticks at most) for their
                    # replies, so that each tick run is answered before the summary counts it.
                    if sent_at is None:
                        sent_at = tick.index
                        self._measured()
                    if tick.index - sent_at > drain or _answered(tick, motors, sent_at):
                        break
                    continue
                if (state := tick.state(motors[self.count % len(motors)])) is not None:
                    self.ages_s.append(state.age_s)
                self.count += 1
                sine.command(tick, t)
                if view is not None and tick.started >= next_refresh:
                    next_refresh = tick.started + REFRESH_S
                    header = _header(plan, buses, loop, self.count, tick.started - start)
                    view.update(live_view(header, _rows(tick, sine), view.console.width), refresh=True)
        finally:
            if sent_at is None:  # (stopped by a signal: up to now)
                self._measured()

    def _measured(self) -> None:
        wall0, cpu0, sim0, preempted0 = self._from
        self.wall_s, self.cpu_s = time.perf_counter() - wall0, time.process_time() - cpu0
        self.sim_s = self._sim_clock.seconds - sim0
        self.preempted = _preemptions() - preempted0


def _preemptions() -> int:
    """The process's involuntary context switches so far (0 where the OS does not count them)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_nivcsw if resource is not None else 0


#: how long past the end the demo waits for the last set-points' replies (2 ticks at least)
_DRAIN_S = 0.05


def _answered(tick: LoopTick, motors: list[Motor], index: int) -> bool:
    """Every motor's state answers the set-point that left at tick ``index``."""
    for motor in motors:
        state = tick.state(motor)
        if state is None or state.tick < index:
            return False
    return True


#: the status columns the live view shows (read from the reply's fields as STATUS_SOURCES says: an
#: MIT reply's ``position_rad`` is shown in degrees), where the set-point's reply has them
_COLUMNS = (("angle_deg", "8.2f"), ("speed_dps", "8.1f"), ("current_a", "6.2f"), ("temperature_c", ""))


def _column(reply: Any, column: str) -> float | None:
    for name, factor in STATUS_SOURCES[column]:
        value = getattr(reply, name, None)
        if isinstance(value, int | float) and not isinstance(value, bool):
            return value * factor
    return None


def _rows(tick: LoopTick, sine: _Sine) -> list[tuple[str, ...]]:
    """Each motor's latest state as this tick sees it (its reply's fields and its age), and target."""
    rows = []
    for n, motor in enumerate(sine.motors):
        state = tick.state(motor)
        reply = state.reply if state is not None else None
        values = tuple(
            "" if (value := _column(reply, name)) is None else format(value, spec) for name, spec in _COLUMNS
        )
        age = "" if state is None else f"{state.age_s * 1e3:6.2f}"
        where = f"{motor.bus.name.removeprefix('bus ')}/{motor.motor_id}"
        rows.append((str(n + 1), where, values[0], f"{sine.targets[n]:8.2f}", *values[1:], age))
    return rows


def _header(
    plan: Layout, buses: list[tuple[Bus, list[Motor]]], loop: Loop, ticks_run: int, elapsed: float
) -> list[str]:
    metrics = [bus.metrics() for bus, _ in buses]
    done = loop.metrics()
    loads = [m.bus_load_pct for m in metrics if m.bus_load_pct is not None]
    failed = sum(m.timeouts + m.malformed for m in metrics) + done.not_sent
    rate = ticks_run / elapsed if elapsed > 0 else 0.0
    age = done.state_age_p99_s
    return [
        f"{plan.motors} motors, {plan.buses} buses, target {plan.hz:g} Hz, {elapsed:.1f} s (Ctrl-C stops)",
        f"loop {rate:,.1f}/s  missed {done.skipped:,}  overruns {done.overruns:,}  "
        f"state age p99 {age * 1e3 if age is not None else 0:.2f} ms  "
        f"load {sum(loads) / len(loads) if loads else 0:.0f} %  errors {failed}",
    ]


def _summarise(
    plan: Layout,
    buses: list[tuple[Bus, list[Motor]]],
    run: _Ticks,
    done: LoopMetrics,
    before: list[Metrics],
) -> Summary:
    metrics = [bus.metrics() for bus, _ in buses]
    p50 = [m.latency.p50_s for m in metrics if m.latency.p50_s is not None]
    p99 = [m.latency.p99_s for m in metrics if m.latency.p99_s is not None]
    loads = [m.bus_load_pct for m in metrics if m.bus_load_pct is not None]
    took = sorted(run.tick_cpu)
    ages = sorted(run.ages_s)
    faults = sum(1 for _, motors in buses for m in motors if m.fault is not None)

    return Summary(
        hz=plan.hz,
        motors=plan.motors,
        buses=plan.buses,
        seconds=run.wall_s,
        ticks=run.count,
        missed_ticks=done.skipped,
        late_p99_ms=(done.late_p99_s or 0.0) * 1e3,
        tick_p50_ms=took[len(took) // 2] * 1e3 if took else 0.0,
        wire_ms=plan.tick_wire_s(max(plan.per_bus)) * 1e3,
        pairs=sum(m.replies for m in metrics) - sum(m.replies for m in before),
        latency_p50_ms=max(p50) * 1e3 if p50 else None,
        latency_p99_ms=max(p99) * 1e3 if p99 else None,
        bus_load_mean_pct=sum(loads) / len(loads) if loads else None,
        bus_load_max_pct=max(loads) if loads else None,
        timeouts=sum(m.timeouts for m in metrics),
        # (the loop counts its own requests the links refused: the Buses', before it, are the start's)
        not_sent=sum(m.not_sent for m in before) + done.not_sent,
        malformed=sum(m.malformed for m in metrics),
        faults=faults,
        cpu_s=run.cpu_s,
        simulator_cpu_s=run.sim_s,
        state_age_p50_ms=ages[len(ages) // 2] * 1e3 if ages else None,
        state_age_p99_ms=ages[max(0, math.ceil(0.99 * len(ages)) - 1)] * 1e3 if ages else None,
        state_age_max_ms=ages[-1] * 1e3 if ages else None,
        late_ticks=done.late_ticks,
        overruns=done.overruns,
        stale_states=done.stale_states,
        superseded=done.superseded,
        lost=done.lost,
        preempted=run.preempted,
    )
