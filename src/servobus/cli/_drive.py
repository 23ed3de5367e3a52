"""``record --drive``: the set-points a recording sends (a sine, a square wave or a step), and the
recording's ticks that send them.

The commands are the family's own: its ``cli`` part's ``move`` (``--mode position``) or ``speed``
(``--mode speed``), built for each motor's bound codec as ``servobus move/speed`` build them (the
first commands once, hollow's mode and Start among them; then the set-point each tick). Where the
set-point's reply carries no position, speed or current, the recording's read (``--poll``) is sent
with it each tick; where it does (MyActuator's 0xA2/0xA4, LK's, hollow's), the reply is the status.
Every value the wave can reach is built and encoded for every motor before anything is sent, so a
value out of range is refused in one line (exit 2) with nothing sent.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, MutableMapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

import anyio
import click

from servobus.bus import Bus, Motor
from servobus.cli._families import op
from servobus.cli._output import FloatRange, refused
from servobus.cli.plugin import STATUS_SOURCES, Op
from servobus.limits import LimitBook, LimitExceeded, Limits
from servobus.protocols import Command
from servobus.tools.logs import message_values

__all__ = ["MODES", "WAVES", "Drive", "Wave", "drive_options", "drive_ticks", "make_drive"]

F = TypeVar("F", bound=Callable[..., Any])

WAVES = ("sine", "square", "step")
#: ``--mode`` -> (the CLI command whose set-point is sent, its value's name, the unit)
MODES: Mapping[str, tuple[str, str, str]] = {
    "position": ("move", "angle_deg", "deg"),
    "speed": ("speed", "speed_dps", "dps"),
}
#: defaults: a wave the simulated motors follow (90° at 2 s: 283 dps at most, under the speed limit)
AMPLITUDE = {"position": 90.0, "speed": 90.0}
PERIOD_S = 2.0
MAX_SPEED_DPS = 500.0
#: set-points are given on a 0.01 grid (MyActuator's and LK's resolution, 0.01° and 0.01 dps)
DIGITS = 2
_STATUS_FIELDS = frozenset(name for sources in STATUS_SOURCES.values() for name, _ in sources)


@dataclass(frozen=True, slots=True)
class Wave:
    """A set-point against time ``t`` (seconds since the drive started).

    ``sine``: ``offset + amplitude·sin(2πt/period)``; ``square``: ``offset + amplitude`` for the first
    half of each period, ``offset - amplitude`` for the second; ``step``: ``offset`` for the first
    half period, then ``offset + amplitude``, held. Rounded to 0.01.
    """

    shape: str
    amplitude: float
    offset: float
    period_s: float

    def at(self, t: float) -> float:
        if self.shape == "sine":
            value = self.offset + self.amplitude * math.sin(2 * math.pi * t / self.period_s)
        elif self.shape == "square":
            half = (t % self.period_s) < self.period_s / 2
            value = self.offset + (self.amplitude if half else -self.amplitude)
        else:
            value = self.offset + (self.amplitude if t >= self.period_s / 2 else 0.0)
        return round(value, DIGITS) + 0.0  # (+ 0.0: no -0.0 in a row)

    def extremes(self) -> tuple[float, ...]:
        """Every value the wave reaches at its ends (what is checked before anything is sent)."""
        swing = (self.amplitude,) if self.shape == "step" else (self.amplitude, -self.amplitude)
        return tuple(round(self.offset + value, DIGITS) for value in (0.0, *swing))


@dataclass(frozen=True, slots=True)
class Drive:
    """What ``record --drive`` sends: the wave, in ``mode``, through the family's ``op``."""

    wave: Wave
    mode: str
    op: Op
    max_speed_dps: float
    #: each motor's wave later than the one before by this (``--stagger``: the period over the motors)
    stagger_s: float = 0.0

    @property
    def name(self) -> str:
        """The value's name, units in it (``angle_deg``)."""
        return MODES[self.mode][1]

    @property
    def column(self) -> str:
        """The telemetry column of the set-point (``setpoint_angle_deg``)."""
        return f"setpoint_{self.name}"

    def values(self, target: float) -> dict[str, Any]:
        """The command line's values for the family's builder (see :mod:`servobus.protocols.cli`)."""
        if self.mode == "position":
            return {
                "angle_deg": target,
                "max_speed_dps": self.max_speed_dps,
                "relative": False,
                "max_current_a": None,
            }
        return {"speed_dps": target, "max_current_a": None}

    def first(self, codec: Any, target: float) -> Sequence[Command]:
        return self.op.first(codec, self.values(target))

    def repeat(self, codec: Any, target: float) -> Sequence[Command]:
        again = self.op.repeat
        return again(codec, self.values(target)) if again is not None else self.first(codec, target)

    def reply_types(self, codec: Any) -> set[type]:
        """The replies the resent commands get."""
        return {
            reply for command in self.repeat(codec, self.wave.offset) for reply in type(command).reply_types()
        }

    def shows_status(self, codec: Any) -> bool:
        """The replies to the resent commands carry a position, speed or current (no poll needed)."""
        for command in self.repeat(codec, self.wave.offset):
            for reply in type(command).reply_types():
                if dataclasses.is_dataclass(reply) and _STATUS_FIELDS & {
                    f.name for f in dataclasses.fields(reply)
                }:
                    return True
        return False

    def check(self, codecs: Sequence[Any], limits: LimitBook | None = None) -> None:
        """Build and encode every value the wave reaches for every motor, and meet each motor's
        ``limits`` (``--limits``) with it: nothing is sent.

        A limit the file clamps to may clamp what else a set-point carries (its speed limit: the
        Bus does so as it sends), never the wave's own value: the rows say what was sent.

        Raises:
            click.UsageError: a value out of range or beyond a limit, a command the motor's
                revision lacks (exit 2).
        """
        if not codecs:
            return
        carried = moved_fields(self.op, codecs[0], self.name, self.values(0.0))
        lines: set[str] = set()  # (each clamp said once)
        with refused():
            for codec in codecs:
                own = None if limits is None else limits.of(codec.motor_id)
                for target in self.wave.extremes():
                    for command in (*self.first(codec, target), *self.repeat(codec, target)):
                        codec.encode(command)
                        if own is not None and not command.READ:
                            self._within(codec, own, command, target, carried, lines)

    def _within(
        self,
        codec: Any,
        limits: Limits,
        command: Command,
        target: float,
        carried: Mapping[type, tuple[str, float]],
        lines: set[str],
    ) -> None:
        """``command`` meets ``limits`` with the wave's value as it is.

        Raises:
            ValueError: a limit refuses it (LimitExceeded), or would clamp the wave's value.
        """
        where = f"{codec.family} motor {codec.motor_id}"
        field = carried.get(type(command))
        try:
            checked = limits.apply(command)
        except LimitExceeded as exc:
            mine = field is not None and exc.field.endswith(f".{field[0]}")
            said = f"the wave reaches {self.name}={target:g}: " if mine else ""
            raise ValueError(f"{where}: {said}{exc}") from None
        if field is not None and getattr(checked, field[0]) != getattr(command, field[0]):
            raise ValueError(
                f"{where}: the wave reaches {self.name}={target:g}, which --limits clamps to "
                f"{getattr(checked, field[0]) / field[1]:g}: a smaller wave, or the recording would "
                "not be what was sent"
            )
        if checked is not command:  # another field clamped (the speed limit it carries): said once
            for name in (f.name for f in dataclasses.fields(command)):  # type: ignore[arg-type]
                before, after = getattr(command, name), getattr(checked, name)
                what = f"{where}: {type(command).__name__}.{name}"
                said = f"{what} {_said(before)} clamped to {_said(after)} (--limits)"
                if before != after and said not in lines:
                    lines.add(said)
                    click.echo(f"servobus: {said}", err=True)

    def describe(self) -> str:
        """``sine, position 0 ± 90 deg, period 2 s``; ``step, speed 0 → 180 dps at 1 s``."""
        unit = MODES[self.mode][2]
        wave = self.wave
        if wave.shape == "step":
            to = f"{wave.offset:g} → {wave.offset + wave.amplitude:g} {unit}"
            return f"step, {self.mode} {to} at {wave.period_s / 2:g} s"
        around = f"{wave.offset:g} {'±' if wave.amplitude >= 0 else '∓'} {abs(wave.amplitude):g} {unit}"
        return f"{wave.shape}, {self.mode} {around}, period {wave.period_s:g} s"


def _finite(ctx: click.Context, param: click.Parameter, value: float | None) -> float | None:
    """A number, not NaN or infinity (a wave of them would be refused only after the first frame)."""
    if value is not None and not math.isfinite(value):
        raise click.BadParameter(f"{value} is not a number", ctx, param)
    return value


def drive_options(func: F) -> F:
    """The ``--drive`` options; the command receives them as ``drive_args`` (a dict)."""
    options = [
        click.option(
            "--drive",
            type=click.Choice(WAVES),
            help="Drive the motors with this wave and record the set-points beside the replies "
            "[default: read only, nothing commanded].",
        ),
        click.option(
            "--mode",
            type=click.Choice(tuple(MODES)),
            help="What --drive sets: position (the family's move) or speed [default: position].",
        ),
        click.option(
            "--amplitude-deg",
            type=float,
            callback=_finite,
            help=f"The wave's amplitude in position mode [default: {AMPLITUDE['position']:g}].",
        ),
        click.option(
            "--amplitude-dps",
            type=float,
            callback=_finite,
            help=f"The wave's amplitude in speed mode [default: {AMPLITUDE['speed']:g}].",
        ),
        click.option(
            "--offset-deg",
            type=float,
            callback=_finite,
            help="The wave's centre in position mode [default: 0].",
        ),
        click.option(
            "--offset-dps", type=float, callback=_finite, help="The wave's centre in speed mode [default: 0]."
        ),
        click.option(
            "--period-s",
            type=FloatRange(min=0, min_open=True),
            help=f"The wave's period (a step comes after half of it) [default: {PERIOD_S:g}].",
        ),
        click.option(
            "--stagger",
            is_flag=True,
            default=None,
            help="Delay each motor's wave by a period over the number of motors more than the one "
            "before's (their lines apart in a plot) [default: all alike].",
        ),
        click.option(
            "--max-speed-dps",
            type=FloatRange(min=0, min_open=True),
            help=f"The speed limit position set-points carry [default: {MAX_SPEED_DPS:g}, or the "
            "lowest speed_dps of --limits].",
        ),
    ]

    def wrapper(**kwargs: Any) -> Any:
        names = ("drive", "mode", "amplitude_deg", "amplitude_dps", "offset_deg", "offset_dps", "period_s")
        drive_args = {name: kwargs.pop(name) for name in (*names, "stagger", "max_speed_dps")}
        return func(drive_args=drive_args, **kwargs)

    wrapped = functools.wraps(func)(wrapper)
    for option in reversed(options):
        wrapped = option(wrapped)
    return wrapped  # type: ignore[return-value]


def make_drive(
    family: str, codecs: Sequence[Any], args: Mapping[str, Any], limits: LimitBook | None = None
) -> Drive | None:
    """The drive the options say (None: no ``--drive``), checked for every motor's codec and
    ``limits``.

    Raises:
        click.UsageError: a wave option without ``--drive``, an option of the other mode, a family
            without the mode's command, a value out of range (exit 2, nothing sent).
    """
    given = [
        f"--{name.replace('_', '-')}" for name, value in args.items() if name != "drive" and value is not None
    ]
    if args["drive"] is None:
        if given:
            raise click.UsageError(f"{', '.join(given)}: only with --drive sine|square|step")
        return None
    mode = args["mode"] or "position"
    unit = MODES[mode][2]
    wrong = [flag for flag in given if _MODE_OF.get(flag, mode) != mode]
    if wrong:
        raise click.UsageError(f"{', '.join(wrong)}: not for --mode {mode} (its values are in {unit})")
    wave = Wave(
        shape=args["drive"],
        amplitude=_first(args[f"amplitude_{unit}"], AMPLITUDE[mode]),
        offset=_first(args[f"offset_{unit}"], 0.0),
        period_s=_first(args["period_s"], PERIOD_S),
    )
    stagger_s = wave.period_s / len(codecs) if args["stagger"] else 0.0
    max_speed_dps = _first(args["max_speed_dps"], _speed_limit(limits, codecs))
    drive = Drive(wave, mode, op(family, MODES[mode][0]), max_speed_dps, stagger_s)
    drive.check(codecs, limits)
    return drive


#: the options of one mode only
_MODE_OF = {
    "--amplitude-deg": "position",
    "--offset-deg": "position",
    "--max-speed-dps": "position",
    "--amplitude-dps": "speed",
    "--offset-dps": "speed",
}


def moved_fields(
    entry: Op, codec: Any, key: str, others: Mapping[str, Any]
) -> dict[type[Command], tuple[str, float]]:
    """Command class -> (the field that carries the command line's value ``key``, its value per unit
    of ``key``'s) for what ``entry`` builds: found by building it for two values (``others``
    besides) and seeing which one field moved. Reads, and commands where not one field moved, are
    left out; so is all of it when the builder needs more than ``others`` give.
    """
    try:
        low, high = (_built(entry, codec, {**others, key: value}) for value in (10.0, 20.0))
    except (ValueError, TypeError, KeyError):
        return {}
    found: dict[type[Command], tuple[str, float]] = {}
    for a, b in zip(low, high, strict=True):
        cls = type(a)
        if cls is not type(b) or cls.READ:
            continue
        before, after = message_values(a), message_values(b)
        moved = [k for k, v in before.items() if isinstance(v, int | float) and v != after.get(k)]
        if len(moved) == 1:
            found[cls] = (moved[0], (float(after[moved[0]]) - float(before[moved[0]])) / 10.0)  # type: ignore[arg-type]
    return found


def _built(entry: Op, codec: Any, values: Mapping[str, Any]) -> list[Command]:
    return [*entry.first(codec, values), *(entry.repeat(codec, values) if entry.repeat else ())]


def _said(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else "none" if value is None else str(value)


def _speed_limit(limits: LimitBook | None, codecs: Sequence[Any]) -> float:
    """:data:`MAX_SPEED_DPS`, or the lowest speed limit ``--limits`` gives these motors."""
    lowest = MAX_SPEED_DPS
    for codec in codecs if limits is not None else ():
        own = limits.of(codec.motor_id)  # type: ignore[union-attr]
        if own is not None and own.speed_dps is not None:
            lowest = min(lowest, own.speed_dps)
    return lowest


def _first(value: float | None, default: float) -> float:
    return default if value is None else float(value)


async def drive_ticks(
    bus: Bus,
    motors: Sequence[Motor],
    drive: Drive,
    poll: type[Command] | None,
    hz: float,
    duration: float | None,
    timeout_s: float | None,
    setpoints: MutableMapping[int, float],
    count: Callable[[Sequence[Any]], object],
) -> None:
    """Start every motor's set-point as the family starts one (a ``Bus.cycle`` per step), then at
    each tick send each its set-point (and ``poll``) for the time since the start, until
    ``duration``. ``setpoints`` holds each motor's last set-point sent (its rows' value); ``count``
    is given each cycle's results. Leaving the Bus stops the motors (its safe stop)."""
    clock = anyio.current_time
    start = clock()
    scope = anyio.move_on_after(duration) if duration is not None else contextlib.nullcontext()
    carried = moved_fields(drive.op, motors[0].codec, drive.name, drive.values(0.0)) if motors else {}

    def sent(motor: Motor, commands: Sequence[Command], target: float) -> Sequence[Command]:
        """``commands`` as the Bus sends them (within the motor's limits, which a check before the
        start cannot see all of: the range's rule for a motor out of it), its rows' set-point the
        value they carry; none this tick when a limit refuses one."""
        if motor.limits is None:
            setpoints[motor.motor_id] = target
            return commands
        try:
            checked = [motor.limited(command) for command in commands]
        except LimitExceeded:
            return ()
        for before, after in zip(commands, checked, strict=True):
            field = carried.get(type(after))
            if field is not None and after is not before:
                target = getattr(after, field[0]) / field[1]
        setpoints[motor.motor_id] = target
        return checked

    with scope:
        first = [
            sent(
                motor,
                drive.first(motor.codec, drive.wave.at(-n * drive.stagger_s)),
                drive.wave.at(-n * drive.stagger_s),
            )
            for n, motor in enumerate(motors)
        ]
        for step in range(max(len(commands) for commands in first)):
            items = [(m, c[step]) for m, c in zip(motors, first, strict=True) if step < len(c)]
            if items:
                count(await bus.cycle(items, timeout_s=timeout_s))
        async for _ in bus.ticks(hz):
            t = clock() - start
            items = []
            for n, motor in enumerate(motors):
                target = drive.wave.at(t - n * drive.stagger_s)
                items += [
                    (motor, command) for command in sent(motor, drive.repeat(motor.codec, target), target)
                ]
                if poll is not None:
                    items.append((motor, poll()))
            count(await bus.cycle(items, timeout_s=timeout_s))
