"""``servobus record``: poll the motors (or drive them, ``--drive``) and write telemetry (CSV, JSONL)
with the set-points beside the replies, and raw frames (candump)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import anyio
import click

from servobus import runtime
from servobus.bus import Motor, command_classes
from servobus.cli import safe_exits
from servobus.cli._connect import Connection, connection_options, open_bus
from servobus.cli._drive import Drive, drive_options, drive_ticks, make_drive
from servobus.cli._families import cli_part
from servobus.cli._motors import codecs, run
from servobus.cli._output import FloatRange
from servobus.cli._watch import SeenSetpoints
from servobus.errors import MotorTimeout, TransportError
from servobus.frame import Frame
from servobus.protocols import Command, Reply, get_family
from servobus.scheduler import Traffic
from servobus.tools.logs import Scalar
from servobus.tools.recording import CandumpWriter, NewFiles, TapLink, TelemetryWriter, telemetry_row

__all__ = ["record"]

#: the read ``--poll`` sends unless told (position, speed and current in one reply, where it exists)
DEFAULT_POLL = "read_status2"

EPILOG = """\b
Polls every motor with a read (--poll, default read_status2: position, speed, current) through
Bus.cycle at --hz, and writes one row per reply: time_s, motor_id, family, reply and the reply's
fields, units in the names (.csv or .jsonl by the suffix of -o). --log writes every frame, both
directions, to a candump log (python-can), which `servobus decode` reads back. Without --drive it
only reads: no motor is commanded.

\b
--drive sine|square|step sends each motor, at --hz, the set-point of a wave (--mode position: the
family's move, --amplitude-deg/--offset-deg; --mode speed: its speed, --amplitude-dps/--offset-dps;
--period-s) in place of the poll (its reply is the status; a family whose set-point's reply has no
position, speed or current is polled too), and each reply row carries the set-point last sent to
its motor in a column after `reply`: setpoint_angle_deg or setpoint_speed_dps (plain CSV or JSON
lines: pandas reads either). At the end, on Ctrl-C or SIGTERM, the motors get the Bus's safe stop
(said in the last line). With --limits, a wave the limits would refuse or clamp is refused before
anything is sent; what they change as it runs (a motor out of its range gets speed 0) is in the
rows as sent.

\b
--watch-setpoints instead records the set-points another controller sends the motors (seen on the
bus, decoded with the family's codec; not hollow's), the last of each kind before each reply:
setpoint_angle_deg, setpoint_speed_dps, setpoint_current_a.

\b
Existing files are kept unless --force, and even then an existing file is replaced only by a
recording that is kept; on an error, only the files record created are removed. Without
--duration it records until Ctrl-C or SIGTERM (exit 0); Ctrl-C before --duration is up exits 130
(SIGTERM: 143). Either way the files are kept, whole.

\b
Examples:
  servobus record --sim 4 --drive sine --stagger --duration 3 -o run.csv
  servobus plot run.csv -o run.png
  servobus record --sim 4 --duration 5 -o telemetry.csv --log frames.log
  servobus record -i socketcan -c can0 --ids 1-3 --hz 200 -o run.jsonl
  servobus record --sim 2 --drive step --mode speed --amplitude-dps 180 --duration 2 -o step.csv
  servobus record --family lk --sim 2 --poll read_status1 --duration 2 -o status.csv"""


@dataclass
class Tally:
    replies: int = 0
    timeouts: int = 0
    errors: int = 0
    by_motor: dict[int, int] = field(default_factory=dict)


@click.command(epilog=EPILOG)
@connection_options
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), help="Telemetry file (.csv or .jsonl)."
)
@click.option("--log", type=click.Path(dir_okay=False, path_type=Path), help="Raw frames (candump .log).")
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["csv", "jsonl"]),
    help="Telemetry format [default: the suffix of -o].",
)
@click.option(
    "--hz",
    type=FloatRange(min=0, min_open=True, max=10_000),
    default=100.0,
    show_default=True,
    help="Polls (with --drive: set-points) per second.",
)
@click.option(
    "--duration",
    type=FloatRange(min=0, min_open=True),
    metavar="S",
    help="Seconds to record [default: until Ctrl-C].",
)
@click.option(
    "--poll",
    help=f"The read command to poll [default: {DEFAULT_POLL}, or the family's first status read "
    "where it has none of that name].",
)
@click.option("--force", is_flag=True, help="Overwrite existing files (replaced when the recording is kept).")
@click.option(
    "--watch-setpoints",
    is_flag=True,
    help="Record the set-points another controller sends these motors, seen on the bus (columns "
    "setpoint_angle_deg, setpoint_speed_dps, setpoint_current_a), and the replies to them.",
)
@drive_options
def record(
    conn: Connection,
    output: Path | None,
    log: Path | None,
    fmt: str | None,
    hz: float,
    duration: float | None,
    poll: str | None,
    force: bool,
    watch_setpoints: bool,
    drive_args: dict[str, Any],
) -> None:
    """Record telemetry and raw frames from the motors; --drive moves them and records the set-points."""
    if output is None and log is None:
        raise click.UsageError("nothing to write: give -o FILE (telemetry), --log FILE (frames), or both")
    if output is not None and log is not None and output.resolve() == log.resolve():
        raise click.UsageError("-o and --log name the same file")
    if output is not None:
        fmt = fmt or {".csv": "csv", ".jsonl": "jsonl", ".json": "jsonl"}.get(output.suffix.lower())
        if fmt is None:
            raise click.BadParameter(f"{output}: a .csv or .jsonl file (or give --format)", param_hint="-o")
    if log is not None and log.suffix.lower() != ".log":
        raise click.BadParameter(f"{log}: frames are written as a candump .log", param_hint="--log")
    bound = codecs(conn)
    drive = make_drive(conn.family, bound, drive_args, conn.limits)
    watch = _watch(conn, bound) if watch_setpoints else None
    if watch is not None and drive is not None:
        raise click.UsageError("--watch-setpoints records another controller's set-points: not with --drive")
    poll_class: type[Command] | None = None
    if drive is None or poll is not None or not all(drive.shows_status(codec) for codec in bound):
        poll = poll or _default_poll(conn)
        poll_class = _poll_class(conn, poll)
    files = NewFiles(force=force)
    try:
        files.check(p for p in (output, log) if p is not None)
    except FileExistsError as exc:
        raise click.UsageError(str(exc)) from None
    interrupted = False
    try:
        kinds = len(_reply_types(poll_class, drive, bound))  # (a CSV's header holds them all)
        telemetry = TelemetryWriter(files.open(output), fmt or "csv", reply_types=kinds) if output else None
        frames_file = files.open(log) if log is not None else None
        tally = Tally()
        try:
            run(_record(conn, poll_class, drive, watch, hz, duration, telemetry, frames_file, tally))
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM
            interrupted = True
        if telemetry is not None:
            telemetry.flush()  # (rows a CSV held back for its header)
        if tally.replies == 0 and not interrupted:
            asked = poll if drive is None else f"the {drive.wave.shape} set-points"
            raise click.ClickException(
                f"no motor answered {asked} in {tally.timeouts} {'polls' if drive is None else 'requests'}: "
                "nothing recorded" + (f" ({tally.errors} requests failed)" if tally.errors else "")
            )
    except BaseException as exc:
        if not isinstance(exc, KeyboardInterrupt):
            files.discard()
        raise
    finally:
        files.close()
    cut_short = interrupted and duration is not None
    _summary(tally, telemetry, output, log, interrupted, drive, watch, stops=not cut_short)
    if cut_short:
        raise KeyboardInterrupt  # cut short: exit 130, the files kept as far as they got


def _reply_types(poll_class: type[Command] | None, drive: Drive | None, bound: Sequence[Any]) -> set[type]:
    """The kinds of reply the recording asks for (the poll's, the drive's set-points')."""
    kinds: set[type] = set(poll_class.reply_types()) if poll_class is not None else set()
    for codec in bound if drive is not None else ():
        kinds |= drive.reply_types(codec)  # type: ignore[union-attr]
    return kinds


def _watch(conn: Connection, bound: Sequence[Any]) -> SeenSetpoints:
    """What ``--watch-setpoints`` keeps (refused for a family whose set-points it cannot tell)."""
    if conn.port is not None:
        raise click.UsageError(
            "--watch-setpoints: another controller's frames are seen on CAN, not on --port"
        )
    watch = SeenSetpoints(conn.family, bound, conn.bind_options())
    if not watch.columns:
        raise click.UsageError(
            f"--watch-setpoints: {conn.family} set-point frames do not say what they set "
            "(no move, speed or torque command of its own)"
        )
    return watch


def _default_poll(conn: Connection) -> str:
    """:data:`DEFAULT_POLL` where the family has it, else the method of its first status read (the
    family's ``cli`` part names them, or they are derived from its declarations)."""
    family = get_family(conn.family)
    methods = family.methods()
    if DEFAULT_POLL not in methods:
        names = {cls: name for name, cls in methods.items()}
        for read in cli_part(family).status_reads(family):
            if read in names:
                return names[read]
    return DEFAULT_POLL


def _poll_class(conn: Connection, name: str) -> type[Command]:
    """The command class ``name`` of the family, checked to be a read needing no arguments."""
    codec = get_family(conn.family).bind(conn.motor_ids[0], **conn.bind_options())
    classes = command_classes(conn.family)

    def read(cls: type[Command]) -> bool:
        try:
            command = cls()
            codec.encode(command)
        except Exception:  # needs arguments, is abstract, or is refused by this motor's codec
            return False
        return codec.retry_safe(command)

    cls = classes.get(name)
    if cls is not None and read(cls):
        return cls
    reads = sorted(n for n, c in classes.items() if read(c))
    known = f"reads without arguments: {', '.join(reads)}" if reads else "they have no read to poll"
    what = "is not a read without arguments" if cls is not None else "is not a command"
    raise click.BadParameter(f"{name} {what} of {conn.family} motors ({known})", param_hint="--poll")


async def _record(
    conn: Connection,
    poll_class: type[Command] | None,
    drive: Drive | None,
    watch: SeenSetpoints | None,
    hz: float,
    duration: float | None,
    telemetry: TelemetryWriter | None,
    frames_file: Any,
    tally: Tally,
) -> None:
    clock = runtime.current().time  # (the Bus's: the replies' last_seen are on it)
    origin = clock()
    frames = CandumpWriter(frames_file, epoch=time.time(), origin=origin) if frames_file else None
    kinds = {Traffic.REPLY, Traffic.STREAM, Traffic.REPORT, Traffic.LATE, Traffic.UNSOLICITED}
    if watch is not None:  # (the replies to the other controller's requests: the motor's state too)
        kinds.add(Traffic.CONTENDED)
    setpoints: dict[int, float] = {}  # motor id -> the set-point last sent (--drive)
    # Once the drive ended, only the replies it asked for are rows (a late one), not the safe stop's
    # echoes (those are in --log, and the last line says the stop).
    driving = True
    asked = _reply_types(poll_class, None, ())

    def on_reply(motor: Motor, traffic: Traffic, reply: Reply) -> None:
        if traffic not in kinds or not (driving or type(reply) in asked):
            return
        tally.replies += 1
        tally.by_motor[motor.motor_id] = tally.by_motor.get(motor.motor_id, 0) + 1
        if telemetry is not None:
            seen_at = motor.last_seen or clock()
            when = seen_at - origin
            extra: dict[str, Scalar] | None = None
            if drive is not None:
                extra = {drive.column: setpoints.get(motor.motor_id)}
            if watch is not None:
                extra = watch.row(motor.motor_id, seen_at)
            telemetry.write(telemetry_row(when, conn.family, motor.motor_id, reply, extra))

    def count(results: Sequence[Any]) -> None:
        for result in results:
            if isinstance(result, MotorTimeout):
                tally.timeouts += 1
            elif isinstance(result, TransportError):
                tally.errors += 1

    shown = [f for f in (frames.write if frames else None, watch.on_frame if watch else None) if f]

    def on_frame(frame: Frame, received: bool, timestamp: float) -> None:
        for each in shown:
            each(frame, received, timestamp)

    def tap(link: Any) -> TapLink:
        return TapLink(link, shown[0] if len(shown) == 1 else on_frame, clock)

    try:
        # Read only: no stop to send (nothing commanded); driven: the Bus's safe stop on the way out.
        async with open_bus(conn, wrap=tap, safe=None if drive is None else "stop") as (bus, motors):
            bus.subscribe(on_reply)
            if drive is not None:
                asked |= _reply_types(None, drive, [motor.codec for motor in motors])
                args = (bus, motors, drive, poll_class, hz, duration, conn.timeout_s, setpoints, count)
                try:
                    await drive_ticks(*args)
                finally:
                    driving = False
                return
            assert poll_class is not None
            items = [(motor, poll_class()) for motor in motors]
            scope = anyio.move_on_after(duration) if duration is not None else contextlib.nullcontext()
            with scope:
                async for _ in bus.ticks(hz):
                    count(await bus.cycle(items, timeout_s=conn.timeout_s))
    finally:
        if frames is not None:
            frames.close()


def _summary(
    tally: Tally,
    telemetry: TelemetryWriter | None,
    output: Path | None,
    log: Path | None,
    interrupted: bool,
    drive: Drive | None,
    watch: SeenSetpoints | None,
    *,
    stops: bool,
) -> None:
    """The last line; ``stops``: it names the motors the safe stop went to (else the interrupted
    line of ``servobus.cli.main`` does)."""
    per_motor = ", ".join(f"{m}: {n}" for m, n in sorted(tally.by_motor.items()))
    written = " and ".join(str(p) for p in (output, log) if p is not None)
    line = f"record: {tally.replies} replies ({per_motor}), {tally.timeouts} timeouts"
    if drive is not None:
        line = f"record: driven ({drive.describe()}), " + line.removeprefix("record: ")
    if tally.errors:
        line += f", {tally.errors} requests not sent"
    if watch is not None:
        line += f", {watch.count} set-points of another controller"
    if telemetry is not None and telemetry.skipped:
        line += f"; {telemetry.skipped} replies of another type left out of the CSV (JSONL keeps them)"
    stopped = safe_exits() if stops and drive is not None else ""
    click.echo(f"{line}{' (interrupted)' if interrupted else ''} -> {written}{stopped}", err=True)
