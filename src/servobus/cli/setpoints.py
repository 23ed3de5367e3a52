"""The set-point commands: ``move``, ``speed``, ``torque`` and ``mit``.

Which command class each sends is the family's ``cli`` part (:mod:`servobus.cli.plugin`); here are the
options (units in their names) and the run. Set-points are resent at ``--rate-hz`` until ``--duration``
ends, a move arrives, or Ctrl-C (or SIGTERM); then the motors get the Bus's safe stop (``--keep`` sends
once and leaves them running). A relative move sends its increment once and then only reads where the
motor is. With ``--remote`` the bridge's own tick loop resends them and stops the motors when this
client leaves.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

import anyio
import click

from servobus.cli import _ids
from servobus.cli._connect import Connection, open_bus, remote_connection_options
from servobus.cli._families import current_limit_users, op
from servobus.cli._motors import Asked, Outcome, ask_all, codecs, fail_if_any, plan_codecs, run, status_of
from servobus.cli._output import SETTINGS, FloatRange, console, emit_json, examples, json_option, refused
from servobus.cli._remote import open_remote
from servobus.cli._status_view import Items, LiveStatus, status_rows, status_table, take, tick_items
from servobus.limits import LimitBook
from servobus.protocols import Command, Reply
from servobus.ticks import ticks

if TYPE_CHECKING:
    from servobus.cli._remote import Remote

__all__ = ["mit", "move", "speed", "torque"]

F = TypeVar("F", bound=Callable[..., Any])

#: the replies to a set-point's first commands -> whether a status shows it arrived
Arrival = Callable[[Sequence[Reply | None]], Callable[[dict[str, Any]], bool]]
#: sends one tick's items: the items answered and their results (an error, as a value, for a motor)
Cycle = Callable[[Items], Awaitable[tuple[Sequence[tuple[Any, Command]], Sequence[Any]]]]


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
        remote.commanding(name)
        if keep:
            raise click.UsageError(
                "--keep with --remote: the bridge stops the motors a client commanded when it leaves"
            )
        outcomes = run(_remote_setpoints(conn, remote, name, values, rate_hz, duration, live, arrival))
    else:
        planned, repeats = _setpoints(conn.family, name, codecs(conn), values, conn.limits)
        outcomes = run(_run_setpoints(conn, name, planned, repeats, rate_hz, duration, keep, live, arrival))
    rows = status_rows(outcomes)
    if as_json:
        emit_json(rows)
    else:
        console().print(status_table(rows))
        if keep:
            click.echo("left running (--keep): stop them with `servobus stop`", err=True)
    fail_if_any(outcomes)


def _setpoints(
    family: str, name: str, bound: Sequence[Any], values: Mapping[str, Any], limits: LimitBook | None = None
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
    planned = plan_codecs(bound, entry, values, limits)
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
    async with open_remote(conn.ids, remote, valid_for_s=max(0.1, 3.0 / rate_hz)) as (bus, motors):
        planned: list[Sequence[Command]] = []
        repeats: list[Sequence[Command]] = []
        for motor in motors:  # (each in its own family: a bridge's bus may mix them)
            first, again = _setpoints(motor.codec.family, name, [motor.codec], values, conn.limits)
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
        items = tick_items(motors, repeats)
        settled = 0
        arrived_s: float | None = None
        start = anyio.current_time()  # (the loop's clock, the ticks')
        with LiveStatus(self.live, rate_hz) as view:
            async for tick in ticks(rate_hz, spin_s=0.0):
                elapsed = tick.started - start
                if duration is not None and elapsed >= duration:
                    break
                take(outcomes, *await cycle(items))
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
    help="Speed limit of the move [default: the lowest speed_dps of --limits, else none: the family's "
    "move sends its 'no limit' (MyActuator maxSpeed 0, LK none, hollow its full speed)].",
)
@click.option(
    "--no-speed-limit",
    is_flag=True,
    help="Send the family's 'no limit' value (None) even where --max-speed-dps or --limits gives a speed.",
)
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
    max_speed_dps: float | None,
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
    its target is that angle plus the increment. The move's speed is limited only where the user
    says so: --max-speed-dps, else the lowest speed limit --limits gives the motors; without either
    the family's move is given no limit (None). A move that takes no speed limit (an MIT law's: its
    gains set the pace) refuses --max-speed-dps.
    """
    if not op(conn.family, "move").speed_limit:  # (an MIT law's move: its gains set the pace)
        if max_speed_dps is not None:
            raise click.UsageError(f"{conn.family} move carries no speed limit: drop --max-speed-dps")
        no_speed_limit = True
    if max_speed_dps is None and not no_speed_limit:
        max_speed_dps = _limits_speed(conn)
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


def _limits_speed(conn: Connection) -> float | None:
    """The lowest speed limit ``--limits`` gives the motors addressed (None: it gives none)."""
    if conn.limits is None:
        return None
    given = [
        own.speed_dps
        for motor_id in conn.motor_ids
        if (own := conn.limits.of(motor_id)) is not None and own.speed_dps is not None
    ]
    return min(given, default=None)


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
    _drive(conn, "mit", values, rate_hz=rate_hz, duration=duration, keep=keep, as_json=as_json, remote=remote)
