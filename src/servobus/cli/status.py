"""The reading commands: ``status`` (each motor's status once) and ``monitor`` (polled at a rate,
shown live). Only reads are sent: the motors keep doing what they were doing.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import anyio
import click

from servobus.cli._connect import Connection, open_bus, remote_connection_options
from servobus.cli._families import status_reads
from servobus.cli._motors import (
    Outcome,
    ask,
    ask_all,
    fail_if_any,
    plan,
    plan_motors,
    remote_ask,
    run,
    status_of,
)
from servobus.cli._output import SETTINGS, FloatRange, console, emit_json, examples, json_option
from servobus.cli._remote import open_remote
from servobus.cli._status_view import LiveStatus, status_rows, status_table, take, tick_items
from servobus.protocols import Command, Reply
from servobus.ticks import ticks

if TYPE_CHECKING:
    from servobus.cli._remote import Remote

__all__ = ["monitor", "status"]


# ---- status and monitor ----


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus status --sim 3",
        "servobus status -i slcan -c /dev/ttyACM0 --ids 1-3",
        "servobus status -i socketcan -c can0 --family lk --ids 9,10 --json",
        "servobus status --remote arm/can0 --endpoint tcp/192.168.1.20:7447   # through a bridge",
    ),
)
@remote_connection_options
@json_option
def status(conn: Connection, remote: Remote | None, as_json: bool) -> None:
    """Read each motor's position, speed, current, temperature, voltage and errors once."""
    if remote is not None:
        _, outcomes, _ = run(remote_ask(conn, remote, status_reads, {}, read_only=True))
    else:
        outcomes = ask(conn, plan(conn, status_reads(conn.family), {}))
    rows = status_rows(outcomes)
    if as_json:
        emit_json(rows)
    else:
        console().print(status_table(rows))
    fail_if_any(outcomes)


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus monitor --sim 4                    # live table until Ctrl-C",
        "servobus monitor --sim 4 --rate-hz 50 --duration 10 --json > samples.jsonl",
        "servobus monitor --remote arm/can0 --duration 10 --json   # the states the bridge publishes",
    ),
)
@remote_connection_options
@click.option("--rate-hz", type=FloatRange(min=0.1, max=1000), default=10.0, show_default=True)
@click.option("--duration", type=FloatRange(min=0), help="Stop after this many seconds [default: Ctrl-C].")
@json_option
def monitor(
    conn: Connection, remote: Remote | None, rate_hz: float, duration: float | None, as_json: bool
) -> None:
    """Poll the motors' status at a fixed rate and show it live (JSON: one line per motor and sample).

    Only reads are sent: the motors keep doing what they were doing. With --remote, the motors are
    read once, then shown as the bridge publishes their states (JSON: a line per state published,
    at most --rate-hz per motor).
    """
    live = not as_json and console(stderr=True).is_terminal
    if remote is not None:
        outcomes = run(_remote_monitor(conn, remote, rate_hz, duration, as_json, live))
    else:
        planned = plan(conn, status_reads(conn.family), {})
        outcomes = run(_monitor(conn, planned, rate_hz, duration, as_json, live))
    if not as_json:
        console().print(status_table(status_rows(outcomes)))
    fail_if_any(outcomes)


async def _monitor(
    conn: Connection,
    planned: Sequence[Sequence[Command]],
    rate_hz: float,
    duration: float | None,
    as_json: bool,
    live: bool,
) -> list[Outcome]:
    async with open_bus(conn, safe=None) as (bus, motors):
        items = tick_items(motors, planned)
        outcomes = [Outcome(m.motor_id) for m in motors]
        start = anyio.current_time()
        with LiveStatus(live, rate_hz) as view:
            async for tick in bus.ticks(rate_hz, spin_s=0.0):
                elapsed = tick.started - start
                if duration is not None and elapsed >= duration:
                    break
                fresh = take(outcomes, items, await bus.cycle(items, timeout_s=conn.timeout_s))
                if as_json:
                    for o in outcomes:
                        emit_json(
                            {"t": round(elapsed, 4), "id": o.motor_id, **status_of(fresh[o.motor_id])}
                            | {"error": o.error}
                        )
                view.show(
                    tick.index,
                    outcomes,
                    f"{len(motors)} {conn.family} motor(s), {elapsed:.1f} s (Ctrl-C stops)",
                )
        return outcomes


async def _remote_monitor(
    conn: Connection, remote: Remote, rate_hz: float, duration: float | None, as_json: bool, live: bool
) -> list[Outcome]:
    async with open_remote(conn.ids, remote, read_only=True) as (bus, motors):
        wanted = {motor.motor_id for motor in motors}
        published: dict[int, Reply] = {}
        bus.subscribe(lambda motor, reply: published.update({motor.motor_id: reply}))
        outcomes = await ask_all(motors, plan_motors(motors, status_reads, {}), timeout_s=conn.timeout_s)
        where = f"{len(motors)} motor(s) of {remote.target}"
        start = anyio.current_time()
        with LiveStatus(live, rate_hz) as view:
            async for tick in ticks(rate_hz, spin_s=0.0):
                elapsed = tick.started - start
                if duration is not None and elapsed >= duration:
                    break
                fresh = {mid: reply for mid, reply in published.items() if mid in wanted}
                published.clear()
                for outcome, motor in zip(outcomes, motors, strict=True):
                    if motor.remote.online is False:
                        outcome.error = f"motor {motor.motor_id} is offline (the bridge's watchdog)"
                    elif outcome.motor_id in fresh:  # (before the replies of other kinds it keeps)
                        new = fresh[outcome.motor_id]
                        kept = [r for r in outcome.replies if type(r) is not type(new)]
                        outcome.replies, outcome.error = [new, *kept], None
                    if as_json and outcome.motor_id in fresh:
                        emit_json(
                            {"t": round(elapsed, 4), "id": outcome.motor_id}
                            | status_of(outcome.replies)
                            | {"error": outcome.error}
                        )
                view.show(tick.index, outcomes, f"{where}, {elapsed:.1f} s (Ctrl-C stops)")
        return outcomes
