"""The motor commands: ``status``, ``monitor``, set-points (``move``, ``speed``, ``torque``, ``mit``) and
one-shots (``stop``, ``off``, ``brake``, ``zero``, ``set-id``, ``clear-errors``, ``reset``).

Which command class each sends is the family's ``cli`` part (:mod:`servobus.cli.plugin`); here are the
options (units in their names), the confirmation of ROM writes and id changes, and the output.
Set-points are resent at ``--rate-hz`` until ``--duration`` ends, a move arrives, or Ctrl-C (or
SIGTERM); then the motors get the Bus's safe stop (``--keep`` sends once and leaves them running). A
relative move sends its increment once and then only reads where the motor is.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

import anyio
import click
from rich.live import Live

from servobus.cli import _ids
from servobus.cli._connect import Connection, connection_options, open_bus, remote_connection_options
from servobus.cli._families import current_limit_users, op, status_reads
from servobus.cli._motors import (
    STATUS_COLUMNS,
    Asked,
    Outcome,
    ask,
    ask_all,
    codecs,
    fail_if_any,
    plan,
    plan_codecs,
    run,
    status_of,
)
from servobus.cli._output import (
    SETTINGS,
    FloatRange,
    confirm,
    console,
    emit_json,
    examples,
    json_option,
    message_fields,
    message_text,
    refused,
    table,
    yes_option,
)
from servobus.errors import ServobusError
from servobus.protocols import Command, Reply
from servobus.ticks import ticks

if TYPE_CHECKING:
    from servobus.cli._remote import Remote
    from servobus.cli.plugin import Op

__all__ = [
    "brake",
    "clear_errors",
    "mit",
    "monitor",
    "move",
    "off",
    "reset",
    "set_id",
    "speed",
    "status",
    "stop",
    "torque",
    "zero",
]

F = TypeVar("F", bound=Callable[..., Any])

#: the replies to a set-point's first commands -> whether a status shows it arrived
Arrival = Callable[[Sequence[Reply | None]], Callable[[dict[str, Any]], bool]]
#: one tick's (motor, command) pairs
Items = list[tuple[Any, Command]]
#: sends one tick's items: the items answered and their results (an error, as a value, for a motor)
Cycle = Callable[[Items], Awaitable[tuple[Sequence[tuple[Any, Command]], Sequence[Any]]]]


# ---- output ----


def _status_rows(outcomes: Sequence[Outcome]) -> list[dict[str, Any]]:
    rows = []
    for o in outcomes:
        row: dict[str, Any] = {"id": o.motor_id, **status_of(o.replies)}
        row["error"] = o.error
        rows.append(row)
    return rows


def _status_table(rows: Sequence[Mapping[str, Any]], title: str | None = None) -> Any:
    columns = ("id", *STATUS_COLUMNS, "error")
    shown = [c for c in columns if c in ("id", "error") or any(r.get(c) is not None for r in rows)]
    if not any(r.get("error") for r in rows):
        shown.remove("error")
    return table(title, shown, ([r.get(c) for c in shown] for r in rows))


def _print_results(outcomes: Sequence[Outcome], sent: Sequence[Sequence[Command]], as_json: bool) -> None:
    if as_json:
        emit_json(
            [
                {
                    "id": o.motor_id,
                    "sent": [type(c).__name__ for c in commands],
                    "replies": [
                        None if r is None else {"type": type(r).__name__, "fields": message_fields(r)}
                        for r in o.replies
                    ],
                    "error": o.error,
                }
                for o, commands in zip(outcomes, sent, strict=True)
            ]
        )
        return
    rows: list[tuple[Any, ...]] = []
    for o, commands in zip(outcomes, sent, strict=True):
        reply = o.reply
        if o.error is not None:
            result = ""
        elif reply is None:
            result = "sent (no reply by the manual)"
        else:
            result = message_text(reply)
        rows.append((o.motor_id, ", ".join(type(c).__name__ for c in commands), result, o.error))
    columns = ["id", "sent", "reply", "error"]
    if not any(r[3] for r in rows):
        columns, rows = columns[:3], [r[:3] for r in rows]
    console().print(table(None, columns, rows))


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
        _, outcomes, _ = run(_remote_ask(conn, remote, status_reads, {}, read_only=True))
    else:
        outcomes = ask(conn, plan(conn, status_reads(conn.family), {}))
    rows = _status_rows(outcomes)
    if as_json:
        emit_json(rows)
    else:
        console().print(_status_table(rows))
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
        console().print(_status_table(_status_rows(outcomes)))
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
        items = _items(motors, planned)
        outcomes = [Outcome(m.motor_id) for m in motors]
        start = anyio.current_time()
        with _LiveStatus(live, rate_hz) as view:
            async for tick in bus.ticks(rate_hz, spin_s=0.0):
                elapsed = tick.started - start
                if duration is not None and elapsed >= duration:
                    break
                fresh = _take(outcomes, items, await bus.cycle(items, timeout_s=conn.timeout_s))
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
    from servobus.cli._remote import open_remote, plan_motors

    async with open_remote(conn, remote, read_only=True) as (bus, motors):
        wanted = {motor.motor_id for motor in motors}
        published: dict[int, Reply] = {}
        bus.subscribe(lambda motor, reply: published.update({motor.motor_id: reply}))
        outcomes = await ask_all(motors, plan_motors(motors, status_reads, {}), timeout_s=conn.timeout_s)
        where = f"{len(motors)} motor(s) of {remote.target}"
        start = anyio.current_time()
        with _LiveStatus(live, rate_hz) as view:
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


def _items(motors: Sequence[Asked], commands: Sequence[Sequence[Command]]) -> Items:
    """One tick's (motor, command) pairs: each motor's commands, in order."""
    return [(motor, command) for motor, each in zip(motors, commands, strict=True) for command in each]


def _take(
    outcomes: Sequence[Outcome], items: Sequence[tuple[Asked, Command]], results: Sequence[Any]
) -> dict[int, list[Reply | None]]:
    """One tick's results into each motor's outcome: its error, or its replies of this tick (a motor
    that failed keeps the replies of the last tick it answered). Returns this tick's replies by id.

    Raises:
        BaseException: a result that is not a motor's or the bus's failure (a bug, a refused frame).
    """
    fresh: dict[int, list[Reply | None]] = {o.motor_id: [] for o in outcomes}
    errors: dict[int, str] = {}
    for (motor, _), result in zip(items, results, strict=True):
        if isinstance(result, ServobusError):
            errors.setdefault(motor.motor_id, str(result))
        elif isinstance(result, BaseException):
            raise result
        else:
            fresh[motor.motor_id].append(result)
    for outcome in outcomes:
        outcome.error = errors.get(outcome.motor_id)
        if fresh[outcome.motor_id]:
            outcome.replies = fresh[outcome.motor_id]
    return fresh


class _LiveStatus:
    """The live status table on stderr (a terminal only), redrawn about four times a second."""

    def __init__(self, live: bool, rate_hz: float) -> None:
        self._view = Live(console=console(stderr=True), auto_refresh=False) if live else None
        self._every = max(1, round(rate_hz / 4))

    def __enter__(self) -> _LiveStatus:
        if self._view is not None:
            self._view.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._view is not None:
            self._view.stop()

    def show(self, tick: int, outcomes: Sequence[Outcome], title: str) -> None:
        if self._view is not None and tick % self._every == 0:
            self._view.update(_status_table(_status_rows(outcomes), title), refresh=True)


# ---- set-points ----


def _drive(
    conn: Connection,
    name: str,
    values: Mapping[str, Any],
    *,
    rate_hz: float,
    duration: float | None,
    keep: bool,
    as_json: bool,
    arrival: Arrival | None = None,
    remote: Remote | None = None,
) -> None:
    live = not as_json and console(stderr=True).is_terminal
    if remote is not None:
        _commanding(name, remote)
        if keep:
            raise click.UsageError(
                "--keep with --remote: the bridge stops the motors a client commanded when it leaves"
            )
        outcomes = run(_remote_setpoints(conn, remote, name, values, rate_hz, duration, live, arrival))
    else:
        planned, repeats = _setpoints(conn.family, name, codecs(conn), values)
        outcomes = run(_run_setpoints(conn, name, planned, repeats, rate_hz, duration, keep, live, arrival))
    rows = _status_rows(outcomes)
    if as_json:
        emit_json(rows)
    else:
        console().print(_status_table(rows))
        if keep:
            click.echo("left running (--keep): stop them with `servobus stop`", err=True)
    fail_if_any(outcomes)


def _commanding(name: str, remote: Remote) -> None:
    """Refuse ``--read-only`` for a command that commands the motors (exit 2, nothing sent)."""
    if remote.read_only:
        raise click.UsageError(f"--read-only: {name} commands the motors; drop --read-only")


def _setpoints(
    family: str, name: str, bound: Sequence[Any], values: Mapping[str, Any]
) -> tuple[list[Sequence[Command]], list[Sequence[Command]]]:
    """The commands set-point command ``name`` sends each motor (its codec in ``bound``) first, and
    those it resends: all built and encoded now.

    Raises:
        click.UsageError: the family has no such command, a value out of range, a command the revision
            lacks, a current limit the command does not carry (exit 2, nothing sent).
    """
    entry = op(family, name)
    if values.get("max_current_a") is not None and not entry.current_limit:
        raise click.UsageError(
            f"{family} {name} carries no current limit: drop --max-current-a "
            f"(it is for {current_limit_users()})"
        )
    planned = plan_codecs(bound, entry, values)
    repeat = entry.repeat
    assert repeat is not None
    with refused():  # refused here (exit 2), not after the first set-point went out
        repeats = [repeat(codec, values) for codec in bound]
        for codec, commands in zip(bound, repeats, strict=True):
            for command in commands:
                codec.encode(command)
    return planned, repeats


async def _run_setpoints(
    conn: Connection,
    name: str,
    planned: Sequence[Sequence[Command]],
    repeats: Sequence[Sequence[Command]],
    rate_hz: float,
    duration: float | None,
    keep: bool,
    live: bool,
    arrival: Arrival | None,
) -> list[Outcome]:
    async with open_bus(conn, safe=None if keep else "stop") as (bus, motors):

        async def cycle(items: Items) -> tuple[Items, Sequence[Any]]:
            return items, await bus.cycle(items, timeout_s=conn.timeout_s)

        where = f"{conn.family} {_ids(conn.motor_ids)}"
        hold = _Hold(name, where, rate_hz, duration, live, arrival)
        return await hold(motors, planned, repeats, cycle, keep=keep, timeout_s=conn.timeout_s)


async def _remote_setpoints(
    conn: Connection,
    remote: Remote,
    name: str,
    values: Mapping[str, Any],
    rate_hz: float,
    duration: float | None,
    live: bool,
    arrival: Arrival | None,
) -> list[Outcome]:
    """:func:`_run_setpoints` through a bridge: the first commands as requests (their replies come
    back), the rest as the bridge's set-points, valid for three ticks; the states the bridge published
    are the status. Leaving stops the motors (the bridge's safe stop for a client that left)."""
    from servobus.cli._remote import open_remote

    async with open_remote(conn, remote, valid_for_s=max(0.1, 3.0 / rate_hz)) as (bus, motors):
        planned: list[Sequence[Command]] = []
        repeats: list[Sequence[Command]] = []
        for motor in motors:  # (each in its own family: a bridge's bus may mix them)
            first, again = _setpoints(motor.codec.family, name, [motor.codec], values)
            planned += first
            repeats += again

        async def cycle(items: Items) -> tuple[Items, Sequence[Any]]:
            results = await bus.cycle([(motor.remote, command) for motor, command in items])
            answered = [(item, r) for item, r in zip(items, results, strict=True) if r is not None]
            return [item for item, _ in answered], [r for _, r in answered]

        families = sorted({motor.codec.family for motor in motors})
        where = f"{'/'.join(families)} {_ids([m.motor_id for m in motors])} of {remote.target}"
        hold = _Hold(name, where, rate_hz, duration, live, arrival)
        return await hold(motors, planned, repeats, cycle, keep=False, timeout_s=conn.timeout_s)


class _Hold:
    """A set-point command's run on opened motors: the first commands, then the set-point resent at
    ``rate_hz`` until ``duration``, the arrival, or Ctrl-C (the stop is the Bus's or the bridge's)."""

    def __init__(
        self,
        name: str,
        where: str,
        rate_hz: float,
        duration: float | None,
        live: bool,
        arrival: Arrival | None,
    ) -> None:
        self.name = name
        self.where = where
        self.rate_hz = rate_hz
        self.duration = duration
        self.live = live
        self.arrival = arrival

    async def __call__(
        self,
        motors: Sequence[Asked],
        planned: Sequence[Sequence[Command]],
        repeats: Sequence[Sequence[Command]],
        cycle: Cycle,
        *,
        keep: bool,
        timeout_s: float | None,
    ) -> list[Outcome]:
        name, rate_hz, duration, arrival = self.name, self.rate_hz, self.duration, self.arrival
        outcomes = await ask_all(motors, planned, timeout_s=timeout_s)
        if keep or any(o.error for o in outcomes):
            return outcomes
        if not self.live:  # (a terminal shows the live table instead)
            ends = ["arrival"] if arrival is not None else []
            ends += [f"{duration:g} s"] if duration is not None else []
            until = ", ".join(ends) + (" or " if ends else "") + "Ctrl-C"
            click.echo(f"{name}: {self.where} driven at {rate_hz:g} Hz until {until}, then stopped", err=True)
        arrived = None if arrival is None else [arrival(o.replies) for o in outcomes]
        items = _items(motors, repeats)
        settled = 0
        arrived_s: float | None = None
        start = anyio.current_time()  # (the loop's clock, the ticks')
        with _LiveStatus(self.live, rate_hz) as view:
            async for tick in ticks(rate_hz, spin_s=0.0):
                elapsed = tick.started - start
                if duration is not None and elapsed >= duration:
                    break
                _take(outcomes, *await cycle(items))
                if arrived is not None:
                    done = all(
                        o.error is None and there(status_of(o.replies))
                        for o, there in zip(outcomes, arrived, strict=True)
                    )
                    settled = settled + 1 if done else 0
                    if settled >= 3:  # three ticks in a row at the target, then still (or 1 s on):
                        arrived_s = elapsed if arrived_s is None else arrived_s  # the stop holds
                        if _still(outcomes) or elapsed - arrived_s >= SETTLE_S:  # where it is, so
                            break  # a motor still moving in (14.7° of 15°) would be frozen short
                title = f"{name}, {elapsed:.1f} s (Ctrl-C stops the motors)"
                view.show(tick.index, outcomes, title)
        return outcomes


#: after a move arrives (within --tolerance-deg), it is held until every motor turns at most this
#: slowly, for at most SETTLE_S, before the stop (which holds where the motor is)
STILL_DPS = 1.0
SETTLE_S = 1.0


def _still(outcomes: Sequence[Outcome]) -> bool:
    speeds = [status_of(o.replies).get("speed_dps") for o in outcomes]
    return all(speed is None or abs(speed) <= STILL_DPS for speed in speeds)


_rate = click.option(
    "--rate-hz",
    type=FloatRange(min=1, max=1000),
    default=50.0,
    show_default=True,
    help="How often the set-point is resent (each reply refreshes the status).",
)
_duration = click.option(
    "--duration", type=FloatRange(min=0), help="Seconds to hold the set-point [default: Ctrl-C]."
)
_max_current = click.option(
    "--max-current-a",
    type=FloatRange(min=0, min_open=True),
    help="Current limit the set-point carries (hollow move and speed, LK speed) "
    "[default: the motor's full scale: hollow I_fs, LK 2048 counts].",
)
_keep = click.option(
    "--keep", is_flag=True, help="Send the set-point once and leave the motors running (no stop at the end)."
)


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus move --sim 2 --angle-deg 90                   # until both are there, then hold",
        "servobus move --ids 1-3 -i slcan -c /dev/ttyACM0 --angle-deg -45 --max-speed-dps 60",
        "servobus move --sim 1 --angle-deg 30 --relative --duration 2",
        "servobus move --remote arm/can0 --ids 2 --angle-deg 45        # through a bridge",
    ),
)
@remote_connection_options
@click.option("--angle-deg", type=float, required=True, help="Target angle of the output shaft.")
@click.option(
    "--max-speed-dps",
    type=FloatRange(min=0, min_open=True),
    default=180.0,
    show_default=True,
    help="Speed limit of the move.",
)
@click.option("--no-speed-limit", is_flag=True, help="Send the family's 'no limit' value instead.")
@click.option("--relative", is_flag=True, help="Move by --angle-deg from where the motor is.")
@click.option(
    "--tolerance-deg",
    type=FloatRange(min=0, min_open=True),
    default=1.0,
    show_default=True,
    help="An absolute move ends when every motor reports its angle this close.",
)
@_max_current
@_rate
@_duration
@_keep
@json_option
def move(
    conn: Connection,
    remote: Remote | None,
    angle_deg: float,
    max_speed_dps: float,
    no_speed_limit: bool,
    relative: bool,
    tolerance_deg: float,
    max_current_a: float | None,
    rate_hz: float,
    duration: float | None,
    keep: bool,
    as_json: bool,
) -> None:
    """Move to an angle (or by one, --relative) and hold it: position control.

    A move ends when every motor reports the target (within --tolerance-deg) three times in a row
    and has come to rest (at most 1 dps, or 1 s after it arrived), or after --duration, or at Ctrl-C;
    the motors then stop and hold where they are. An absolute
    target is resent at --rate-hz; a relative move reads the angle, sends the increment once, and
    its target is that angle plus the increment.
    """
    values = {"angle_deg": angle_deg, "max_speed_dps": None if no_speed_limit else max_speed_dps}
    values["relative"] = relative
    values["max_current_a"] = max_current_a

    def arrival(first: Sequence[Reply | None]) -> Callable[[dict[str, Any]], bool]:
        target: float | None = angle_deg
        if relative:  # the reply to the read sent before the increment
            start = status_of(first[:1])["angle_deg"]
            target = None if start is None else start + angle_deg

        def arrived(state: dict[str, Any]) -> bool:
            angle = state.get("angle_deg")
            return target is not None and angle is not None and abs(angle - target) <= tolerance_deg

        return arrived

    _drive(
        conn,
        "move",
        values,
        rate_hz=rate_hz,
        duration=duration,
        keep=keep,
        as_json=as_json,
        arrival=arrival,
        remote=remote,
    )


def _same(func: F) -> F:
    return func


def _one_value(
    name: str, option: str, option_help: str, help_text: str, *lines: str, limit: bool = False
) -> click.Command:
    """A set-point command with one value (``--speed-dps``, ``--current-a``) and the set-point options
    (``limit``: ``--max-current-a`` too)."""
    key = option.removeprefix("--").replace("-", "_")

    @click.command(name, help=help_text, context_settings=SETTINGS, epilog=examples(*lines))
    @remote_connection_options
    @click.option(option, key, type=float, required=True, help=option_help)
    @(_max_current if limit else _same)
    @_rate
    @_duration
    @_keep
    @json_option
    def command(
        conn: Connection,
        remote: Remote | None,
        rate_hz: float,
        duration: float | None,
        keep: bool,
        as_json: bool,
        **value: float,
    ) -> None:
        _drive(
            conn, name, value, rate_hz=rate_hz, duration=duration, keep=keep, as_json=as_json, remote=remote
        )

    return command


speed = _one_value(
    "speed",
    "--speed-dps",
    "Speed of the output shaft.",
    "Turn at a speed: speed control, until --duration or Ctrl-C; then stop and hold.",
    "servobus speed --sim 2 --speed-dps 90 --duration 3",
    "servobus speed --ids 1 -i socketcan -c can0 --speed-dps -30      # until Ctrl-C",
    "servobus speed --family lk --sim 1 --speed-dps 30 --max-current-a 2 --duration 1",
    limit=True,
)
torque = _one_value(
    "torque",
    "--current-a",
    "Torque (q-axis) current.",
    "Drive a torque current: torque control, until --duration or Ctrl-C; then stop and hold.",
    "servobus torque --sim 1 --current-a 0.5 --duration 1",
    "servobus torque --family lk --ids 9 -i socketcan -c can0 --current-a -1.2",
)


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus mit --sim 1 --position-rad 1.0 --kp 20 --kd 1 --duration 2",
        "servobus mit --ids 2 -i slcan -c /dev/ttyACM0 --position-rad 0 --kp 5 --kd 0.5 --torque-ff-nm 0.3",
    ),
)
@remote_connection_options
@click.option("--position-rad", type=float, required=True, help="Target position p_des.")
@click.option("--velocity-rad-s", type=float, default=0.0, show_default=True, help="Target velocity v_des.")
@click.option("--kp", type=float, required=True, help="Position gain (N·m/rad).")
@click.option("--kd", type=float, required=True, help="Velocity gain (N·m·s/rad).")
@click.option("--torque-ff-nm", type=float, default=0.0, show_default=True, help="Feed-forward torque.")
@_rate
@_duration
@_keep
@json_option
def mit(
    conn: Connection,
    remote: Remote | None,
    position_rad: float,
    velocity_rad_s: float,
    kp: float,
    kd: float,
    torque_ff_nm: float,
    rate_hz: float,
    duration: float | None,
    keep: bool,
    as_json: bool,
) -> None:
    """Motion (MIT) mode: torque = kp·(p_des - p) + kd·(v_des - v) + t_ff, until --duration or Ctrl-C.

    The ranges are the motor revision's (MyActuator V4.4: ±12.5 rad, ±45 rad/s, kp 0..500, kd 0..5).
    """
    values = {
        "position_rad": position_rad,
        "velocity_rad_s": velocity_rad_s,
        "kp": kp,
        "kd": kd,
        "torque_ff_nm": torque_ff_nm,
    }
    _drive(
        conn, "mit", values, rate_hz=rate_hz, duration=duration, keep=keep, as_json=as_json, remote=remote
    )


# ---- one-shots ----


def _one_shot(
    conn: Connection,
    name: str,
    values: Mapping[str, Any],
    *,
    yes: bool,
    as_json: bool,
    remote: Remote | None = None,
) -> None:
    if remote is not None:
        _commanding(name, remote)
        planned, outcomes, families = run(
            _remote_ask(conn, remote, lambda family: op(family, name), values, rom=(name, yes))
        )
        notes = [note for family in families if (note := op(family, name).note)]
    else:
        entry = op(conn.family, name)
        planned = plan(conn, entry, values)
        if entry.rom:
            ids = ", ".join(str(i) for i in conn.motor_ids)
            confirm(f"{name} writes the ROM of {conn.family} motor(s) {ids}. Continue?", yes)
        outcomes = ask(conn, planned)
        notes = [entry.note] if entry.note else []
    _print_results(outcomes, planned, as_json)
    fail_if_any(outcomes)
    if not as_json:
        for note in dict.fromkeys(notes):
            click.echo(f"note: {note}", err=True)


async def _remote_ask(
    conn: Connection,
    remote: Remote,
    op_of: Callable[[str], Op],
    values: Mapping[str, Any],
    *,
    read_only: bool = False,
    rom: tuple[str, bool] | None = None,
) -> tuple[list[Sequence[Command]], list[Outcome], list[str]]:
    """:func:`servobus.cli._motors.ask` through a bridge: each motor's commands (``op_of(family)``)
    built once the bridge said the motors' families, sent as requests, their replies collected.
    ``rom``: (the command's name, ``--yes``), to ask first where it writes the ROM.

    Returns:
        The commands sent, each motor's outcome, and the motors' families.
    """
    from servobus.cli._remote import open_remote, plan_motors

    async with open_remote(conn, remote, read_only=read_only) as (_, motors):
        planned = plan_motors(motors, op_of, values)
        families = sorted({motor.codec.family for motor in motors})
        if rom is not None and any(op_of(family).rom for family in families):
            ids = ", ".join(str(m.motor_id) for m in motors)
            confirm(f"{rom[0]} writes the ROM of motor(s) {ids} of {remote.target}. Continue?", rom[1])
        return planned, await ask_all(motors, planned, timeout_s=conn.timeout_s), families


def _plain(name: str, help_text: str, *lines: str, remote: bool = False) -> click.Command:
    """A one-shot with no options of its own: ``servobus NAME`` sends the family's NAME command
    (``remote``: also to a bridge's motors, ``--remote``)."""

    @click.command(name, help=help_text, context_settings=SETTINGS, epilog=examples(*lines))
    @(remote_connection_options if remote else _local_only)
    @json_option
    def command(conn: Connection, as_json: bool, remote: Remote | None = None) -> None:
        _one_shot(conn, name, {}, yes=True, as_json=as_json, remote=remote)

    return command


def _local_only(func: F) -> F:
    """:func:`connection_options` for a command without ``--remote``."""
    return connection_options(func)


stop = _plain(
    "stop",
    "Stop and hold position (the loop stays active; hollow motors: output off).",
    "servobus stop --sim 2",
    "servobus stop -i socketcan -c can0 --ids 1-8",
    "servobus stop --remote arm/can0",
    remote=True,
)
off = _plain(
    "off",
    "Switch the output off: the shaft is free (MyActuator 0x80, LK 0x80, hollow stop).",
    "servobus off --sim 2",
    "servobus off -i socketcan -c can0 --ids 1-8",
    "servobus off --remote arm/can0 --ids 3",
    remote=True,
)
clear_errors = _plain(
    "clear-errors",
    "Clear the motors' error flags (where the family has a request for it).",
    "servobus clear-errors --family lk --sim 2",
    "servobus clear-errors --family lk -i socketcan -c can0",
)
reset = _plain(
    "reset",
    "Restart the motors' firmware (no reply comes: the motor reboots).",
    "servobus reset --sim 1",
    "servobus reset -i slcan -c /dev/ttyACM0 --ids 1-3",
)


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus brake --sim 1 --release",
        "servobus brake -i slcan -c /dev/ttyACM0 --ids 3 --lock",
        "servobus brake --remote arm/can0 --ids 3 --lock",
    ),
)
@remote_connection_options
@click.option("--lock/--release", "lock", required=True, help="Close (hold) or open the holding brake.")
@json_option
def brake(conn: Connection, remote: Remote | None, lock: bool, as_json: bool) -> None:
    """Lock or release the holding brake."""
    _one_shot(conn, "brake", {"lock": lock}, yes=True, as_json=as_json, remote=remote)


@click.command(
    context_settings=SETTINGS,
    epilog=examples("servobus zero --sim 1 --yes", "servobus zero -i slcan -c /dev/ttyACM0 --ids 2"),
)
@connection_options
@yes_option
@json_option
def zero(conn: Connection, yes: bool, as_json: bool) -> None:
    """Make the present position the zero (MyActuator and LK: written to ROM; asks first).

    Hollow motors take a zero only with the output off: their zero sends a stop first, which frees
    the shaft (a loaded axis is no longer held), and the zero holds until power-off.
    """
    _one_shot(conn, "zero", {}, yes=yes, as_json=as_json)


@click.command(
    "set-id",
    context_settings=SETTINGS,
    epilog=examples(
        "servobus set-id --sim 1 --ids 1 5 --yes", "servobus set-id -i slcan -c /dev/ttyACM0 --ids 1 2"
    ),
)
@connection_options
@click.argument("new_id", metavar="NEW_ID", type=int)
@yes_option
@json_option
def set_id(conn: Connection, new_id: int, yes: bool, as_json: bool) -> None:
    """Give one motor (--ids) a new id (written to ROM; asks first)."""
    if len(conn.motor_ids) != 1:
        raise click.UsageError(f"set-id changes one motor: give one id with --ids, not {len(conn.motor_ids)}")
    _one_shot(conn, "set-id", {"new_id": new_id}, yes=yes, as_json=as_json)
