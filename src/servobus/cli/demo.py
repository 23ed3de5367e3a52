"""``servobus demo``: simulated motors following smooth trajectories at 1 kHz, no hardware.

The motors are ``--family``'s (default: the registry's first, MyActuator), asked of the family
itself: its simulator part (``FAMILY.part("sim")``) builds them and says their turnaround, its
command-line part's ``move`` (``FAMILY.part("cli")``) makes the absolute position set-point (0xA4
for MyActuator). Each simulated 1 Mbit/s CAN bus is a :class:`~servobus.transports.sim.SimTransport`
with its motors, driven by its own :class:`~servobus.bus.Bus`; one pacer
(:func:`servobus.ticks.ticks`) drives every bus: at each tick every motor gets its set-point along a
sine, and the buses' ``cycle()``\\ s run together (a task each, in the tick's task group). A live view
shows each motor's position, speed, current and temperature with the achieved rate, missed ticks,
latency, bus load and errors; with ``--duration`` the demo runs without it and prints a summary,
including, when the rate was not kept, what was achieved and why (CPU time per tick, the
simulator's share, the cores it would need).

Real time, one process: the simulated motors run on the same event loop as the host side, so the
machine's one core pays for both. Ctrl-C or SIGTERM (or the end of ``--duration``) ends the loop
(:func:`~servobus.cli._motors.stop_scope`) and every Bus sends its motors their stop. The loop runs on
asyncio by default (``--backend trio``: on trio), through anyio either way.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import anyio
import anyio.abc
import click

from servobus import runtime
from servobus.bus import Bus, Motor
from servobus.cli._connect import FamilyChoice, note_exit, sim_part, timeout_option
from servobus.cli._demo_report import Layout, Summary, layout, live_view, summary_lines
from servobus.cli._motors import BACKENDS, run, stop_scope
from servobus.cli._output import SETTINGS, FloatRange, console, emit_json, examples, json_option
from servobus.protocols import DEFAULT_FAMILY, Command, get_family
from servobus.sim.family import SimFamily, SimOptions
from servobus.ticks import ticks

if TYPE_CHECKING:
    from servobus.cli.plugin import CliFamily, Op

__all__ = ["demo"]

AMPLITUDE_DEG = 90.0
PERIOD_S = 4.0
MAX_SPEED_DPS = 500.0
REFRESH_S = 0.25


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus demo                      # live view until Ctrl-C",
        "servobus demo --duration 5         # no live view: a summary after 5 s",
        "servobus demo --hz 100 --motors 8  # what this machine keeps up with",
        "servobus demo --duration 5 --json",
    ),
)
@click.option(
    "--duration",
    type=FloatRange(min=0, min_open=True),
    help="Run this many seconds without the live view, then print a summary.",
)
@click.option("--hz", type=FloatRange(min=1, max=2000), default=1000.0, show_default=True, help="Tick rate.")
@click.option(
    "--motors", type=click.IntRange(1, 320), default=32, show_default=True, help="Simulated motors."
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
    help="Protocol family of the simulated motors (one with a simulator and a move).",
)
@click.option(
    "--backend",
    type=click.Choice(BACKENDS),
    default="asyncio",
    show_default=True,
    help="The event loop the buses and the simulator run on (through anyio).",
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
    timeout_s: float | None,
    as_json: bool,
) -> None:
    """Simulated motors on simulated CAN buses following sine trajectories, in real time.

    No hardware and no arguments needed: 32 MyActuator motors at 1 kHz by default, spread over as
    many simulated 1 Mbit/s buses as classic CAN needs for that rate. Ctrl-C stops the motors cleanly.
    """
    parts = _parts(family)
    if buses is not None and buses > motors:
        raise click.BadParameter(
            f"{buses} buses for {motors} motors: at most one bus per motor", param_hint="--buses"
        )
    if as_json and duration is None:
        raise click.UsageError("--json prints the summary of a run: give --duration")
    plan = layout(hz, motors, buses, parts.sim.turnaround_s)
    if not as_json:
        where = f"{plan.buses} simulated CAN bus" + ("es" if plan.buses > 1 else "")
        click.echo(f"servobus demo: {motors} simulated {family} motor(s) on {where}, {hz:g} Hz")
        click.echo(plan.why())
        if (warning := plan.overload()) is not None:
            click.echo(f"warning: {warning}")
    summary = run(_run(plan, parts, duration, live=duration is None, timeout_s=timeout_s), backend=backend)
    if as_json:
        emit_json(summary.as_dict())
    else:
        for line in summary_lines(summary):
            click.echo(line)
    if summary.interrupted:
        raise KeyboardInterrupt  # exit 130 (SIGTERM: 143), after the summary (the motors were stopped)
    if summary.errors:
        raise click.ClickException(f"{summary.errors} request(s) failed during the demo")


@dataclass(frozen=True, slots=True)
class _Parts:
    """What the demo asks of the family: its simulator and its ``move`` set-point."""

    family: str
    sim: SimFamily
    move: Op

    def setpoint(self, motor: Motor, angle_deg: float) -> Command:
        """The absolute position set-point to ``angle_deg`` for ``motor``."""
        values = {
            "angle_deg": angle_deg,
            "max_speed_dps": MAX_SPEED_DPS,
            "relative": False,
            "max_current_a": None,
        }
        return self.move.first(motor.codec, values)[-1]


def _parts(family: str) -> _Parts:
    """The family's simulator and ``move``, or a one-line refusal (exit 2) saying which it lacks."""
    try:
        sim = sim_part(family)
        sim.check(SimOptions())
    except ValueError as exc:
        raise click.BadParameter(str(exc).removeprefix("--sim: "), param_hint="--family") from None
    try:
        cli: CliFamily = get_family(family).part("cli")
    except LookupError as exc:
        raise click.BadParameter(
            f"{exc}: the demo moves motors with its move", param_hint="--family"
        ) from None
    move = cli.op("move")
    if move is None:
        why = cli.why_not.get("move", "")
        raise click.BadParameter(
            f"the demo moves motors, and {family} motors have no move" + (f": {why}" if why else ""),
            param_hint="--family",
        )
    return _Parts(family, sim, move)


class _SimClock:
    """Time spent in the simulator: the networks' own entry points, timed.

    On ``time.perf_counter``: the entry points never block or sleep, so their wall time is their CPU
    time, and the counter is read in tens of nanoseconds where ``time.thread_time`` is a system call
    (timed with it, the demo spent a third of its loop reading the clock).
    """

    def __init__(self) -> None:
        self.seconds = 0.0

    def wrap(self, network: Any) -> None:
        for name in ("send", "advance", "run_ahead"):
            setattr(network, name, self._timed(getattr(network, name)))

    def _timed(self, method: Callable[..., Any]) -> Callable[..., Any]:
        clock = time.perf_counter

        def timed(*args: Any, **kwargs: Any) -> Any:
            start = clock()
            try:
                return method(*args, **kwargs)
            finally:
                self.seconds += clock() - start

        return timed


async def _run(
    plan: Layout, parts: _Parts, duration: float | None, *, live: bool, timeout_s: float | None
) -> Summary:
    from servobus.transports.sim import SimTransport

    revision = get_family(parts.family).default_revision

    clock = runtime.current().time
    sim_clock = _SimClock()
    async with contextlib.AsyncExitStack() as stack:
        buses: list[tuple[Bus, list[Motor]]] = []

        def noted() -> None:
            for bus, _ in buses:
                note_exit(bus)

        stack.callback(noted)  # (first in, so it runs after every Bus was left)
        for b, count in enumerate(plan.per_bus):
            ids = range(1, count + 1)
            setup = parts.sim.devices(ids, revision, SimOptions())
            transport = SimTransport(devices=setup.can_devices, name=f"sim{b + 1}")
            sim_clock.wrap(transport.network)
            bus = await stack.enter_async_context(Bus(transport, name=f"bus {b + 1}"))
            buses.append((bus, [bus.motor(parts.family, i) for i in ids]))
        flat = [(b, m) for b, (_, motors) in enumerate(buses) for m in motors]
        phases = [2 * math.pi * n / len(flat) for n in range(len(flat))]
        latest: list[Any] = [None] * len(flat)
        targets = [0.0] * len(flat)
        failed = 0
        skipped = 0
        lateness: list[float] = []
        durations: list[float] = []  # tick start -> every bus's last reply
        count = 0
        view = None
        if live:
            from rich.live import Live

            view = Live(console=console(), auto_refresh=False, transient=False)
            view.start()
        cpu0, wall0 = time.process_time(), time.perf_counter()
        start = clock()
        next_refresh = start
        cycles = _Cycles(buses, timeout_s)
        try:
            async with anyio.create_task_group() as workers:
                await cycles.start(workers)
                with stop_scope() as stopping:  # Ctrl-C, SIGTERM: leave the loop; the Buses stop the motors
                    async for tick in ticks(plan.hz):
                        t = tick.deadline - start
                        if duration is not None and t >= duration:
                            break
                        count += 1
                        skipped += tick.skipped
                        lateness.append(tick.late_s)
                        items_by_bus: list[list[tuple[Motor, Command]]] = [[] for _ in buses]
                        for n, (b, motor) in enumerate(flat):
                            targets[n] = AMPLITUDE_DEG * math.sin(2 * math.pi * t / PERIOD_S + phases[n])
                            items_by_bus[b].append((motor, parts.setpoint(motor, round(targets[n], 2))))
                        results = await cycles.tick(items_by_bus)
                        durations.append(clock() - tick.started)
                        n = 0
                        for per_bus in results:
                            for result in per_bus:
                                if isinstance(result, BaseException):
                                    failed += 1
                                else:
                                    latest[n] = result
                                n += 1
                        if view is not None and tick.started >= next_refresh:
                            next_refresh = tick.started + REFRESH_S
                            header = _header(plan, buses, count, skipped, tick.started - start, failed)
                            view.update(live_view(header, _rows(flat, latest, targets)), refresh=True)
                workers.cancel_scope.cancel()  # (parked on their next tick)
        finally:
            if view is not None:
                view.stop()
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        summary = _summarise(plan, buses, count, skipped, lateness, durations, wall, cpu, sim_clock.seconds)
        summary.interrupted = stopping.cancelled_caught
        summary.live = view is not None
    return summary


class _Cycles:
    """Every bus's ``cycle()`` at once, each tick: a worker task per bus, started once in the run's
    task group, parked on a one-shot waiter (:meth:`servobus.runtime.Runtime.waiter`) that the tick
    resolves with its set-points. (A task group per tick starts 11 tasks every tick: ~0.25 ms more per
    tick than this on asyncio, a quarter of the 1 kHz demo's rate.)

    The replies are due within the tick, sooner than a sleeping loop wakes: the selector's timeout
    has whole milliseconds (as :mod:`servobus.ticks` says), so a loop that sleeps until the
    simulator's next reply, due 0.25 ms on, wakes after 1 ms. :meth:`tick` therefore yields
    (``anyio.sleep(0)``) until the cycles are done, keeping the loop turning: the same spin as the
    pacer's before a deadline.
    """

    def __init__(self, buses: list[tuple[Bus, list[Motor]]], timeout_s: float | None) -> None:
        self._buses = [bus for bus, _ in buses]
        self._timeout_s = timeout_s
        self._runtime = runtime.current()
        self._wake: list[Any] = [None] * len(buses)
        self._results: list[list[Any]] = [[] for _ in buses]
        self._pending = 0

    async def start(self, group: anyio.abc.TaskGroup) -> None:
        """Start the workers in ``group`` (cancel it to end them)."""
        for b in range(len(self._buses)):
            await group.start(self._work, b, name=f"servobus demo: bus {b + 1}")

    async def tick(self, items_by_bus: list[list[tuple[Motor, Command]]]) -> list[list[Any]]:
        """Run every bus's cycle with its items; the results in bus order (valid until the next tick)."""
        self._pending = len(self._buses)
        for wake, items in zip(self._wake, items_by_bus, strict=True):
            wake.set_result(items)
        while self._pending:
            await anyio.sleep(0)
        return self._results

    async def _work(self, b: int, *, task_status: anyio.abc.TaskStatus[None]) -> None:
        bus = self._buses[b]
        self._wake[b] = wake = self._runtime.waiter()
        task_status.started()
        while True:
            items = await wake
            self._results[b] = await bus.cycle(items, timeout_s=self._timeout_s)
            self._wake[b] = wake = self._runtime.waiter()
            self._pending -= 1


#: the reply fields the live view shows, where the set-point's reply has them
_COLUMNS = (("angle_deg", "8.2f"), ("speed_dps", "8.1f"), ("current_a", "6.2f"), ("temperature_c", ""))


def _rows(flat: list[tuple[int, Motor]], latest: list[Any], targets: list[float]) -> list[tuple[Any, ...]]:
    rows = []
    for n, ((b, motor), reply) in enumerate(zip(flat, latest, strict=True)):
        values = tuple(
            "" if (value := getattr(reply, name, None)) is None else format(value, spec)
            for name, spec in _COLUMNS
        )
        rows.append((str(n + 1), f"{b + 1}/{motor.motor_id}", values[0], f"{targets[n]:8.2f}", *values[1:]))
    return rows


def _header(
    plan: Layout,
    buses: list[tuple[Bus, list[Motor]]],
    ticks_run: int,
    skipped: int,
    elapsed: float,
    failed: int,
) -> list[str]:
    metrics = [bus.metrics() for bus, _ in buses]
    p99 = [m.latency.p99_s for m in metrics if m.latency.p99_s is not None]
    loads = [m.bus_load_pct for m in metrics if m.bus_load_pct is not None]
    rate = ticks_run / elapsed if elapsed > 0 else 0.0
    return [
        f"{plan.motors} motors, {plan.buses} buses, target {plan.hz:g} Hz, {elapsed:.1f} s (Ctrl-C stops)",
        f"loop {rate:,.1f}/s  missed {skipped:,}  p99 {max(p99) * 1e3 if p99 else 0:.2f} ms  "
        f"load {sum(loads) / len(loads) if loads else 0:.0f} %  errors {failed}",
    ]


def _summarise(
    plan: Layout,
    buses: list[tuple[Bus, list[Motor]]],
    ticks_run: int,
    skipped: int,
    lateness: list[float],
    durations: list[float],
    wall: float,
    cpu: float,
    sim_cpu: float,
) -> Summary:
    metrics = [bus.metrics() for bus, _ in buses]
    p50 = [m.latency.p50_s for m in metrics if m.latency.p50_s is not None]
    p99 = [m.latency.p99_s for m in metrics if m.latency.p99_s is not None]
    loads = [m.bus_load_pct for m in metrics if m.bus_load_pct is not None]
    late = sorted(lateness)
    took = sorted(durations)
    faults = sum(1 for _, motors in buses for m in motors if m.fault is not None)
    return Summary(
        hz=plan.hz,
        motors=plan.motors,
        buses=plan.buses,
        seconds=wall,
        ticks=ticks_run,
        missed_ticks=skipped,
        late_p99_ms=late[max(0, math.ceil(0.99 * len(late)) - 1)] * 1e3 if late else 0.0,
        tick_p50_ms=took[len(took) // 2] * 1e3 if took else 0.0,
        wire_ms=plan.tick_wire_s(max(plan.per_bus)) * 1e3,
        pairs=sum(m.replies for m in metrics),
        latency_p50_ms=max(p50) * 1e3 if p50 else None,
        latency_p99_ms=max(p99) * 1e3 if p99 else None,
        bus_load_mean_pct=sum(loads) / len(loads) if loads else None,
        bus_load_max_pct=max(loads) if loads else None,
        timeouts=sum(m.timeouts for m in metrics),
        not_sent=sum(m.not_sent for m in metrics),
        malformed=sum(m.malformed for m in metrics),
        faults=faults,
        cpu_s=cpu,
        simulator_cpu_s=sim_cpu,
    )
