"""``servobus record``: poll the motors and write telemetry (CSV, JSONL) and raw frames (candump)."""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import anyio
import click

from servobus import runtime
from servobus.bus import Bus, Motor, command_classes
from servobus.cli._connect import Connection, connection_options
from servobus.cli._families import cli_part
from servobus.cli._motors import run
from servobus.cli._output import FloatRange
from servobus.errors import MotorTimeout, TransportError
from servobus.protocols import Command, Reply, get_family
from servobus.scheduler import Traffic
from servobus.tools.recording import CandumpWriter, NewFiles, TapLink, TelemetryWriter, telemetry_row

__all__ = ["record"]

#: the read ``--poll`` sends unless told (position, speed and current in one reply, where it exists)
DEFAULT_POLL = "read_status2"

EPILOG = """\b
Polls every motor with a read (--poll, default read_status2: position, speed, current) through
Bus.cycle at --hz, and writes one row per reply: time_s, motor_id, family, reply and the reply's
fields, units in the names (.csv or .jsonl by the suffix of -o). --log writes every frame, both
directions, to a candump log (python-can), which `servobus decode` reads back. Reads only: no motor
is commanded. Existing files are kept unless --force, and even then an existing file is replaced
only by a recording that is kept; on an error, only the files record created are removed.
Without --duration it records until Ctrl-C or SIGTERM (exit 0); Ctrl-C before --duration is up
exits 130 (SIGTERM: 143). Either way the files are kept, whole.

\b
Examples:
  servobus record --sim 4 --duration 5 -o telemetry.csv --log frames.log
  servobus record -i socketcan -c can0 --ids 1-3 --hz 200 -o run.jsonl
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
    help="Polls per second.",
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
def record(
    conn: Connection,
    output: Path | None,
    log: Path | None,
    fmt: str | None,
    hz: float,
    duration: float | None,
    poll: str | None,
    force: bool,
) -> None:
    """Record telemetry and raw frames from the motors."""
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
    poll = poll or _default_poll(conn)
    poll_class = _poll_class(conn, poll)
    files = NewFiles(force=force)
    try:
        files.check(p for p in (output, log) if p is not None)
    except FileExistsError as exc:
        raise click.UsageError(str(exc)) from None
    interrupted = False
    try:
        telemetry = TelemetryWriter(files.open(output), fmt or "csv") if output is not None else None
        frames_file = files.open(log) if log is not None else None
        tally = Tally()
        try:
            run(_record(conn, poll_class, hz, duration, telemetry, frames_file, tally))
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM
            interrupted = True
        if tally.replies == 0 and not interrupted:
            raise click.ClickException(
                f"no motor answered {poll} in {tally.timeouts} polls: nothing recorded"
                + (f" ({tally.errors} requests failed)" if tally.errors else "")
            )
    except BaseException as exc:
        if not isinstance(exc, KeyboardInterrupt):
            files.discard()
        raise
    finally:
        files.close()
    _summary(tally, telemetry, output, log, interrupted)
    if interrupted and duration is not None:
        raise KeyboardInterrupt  # cut short: exit 130, the files kept as far as they got


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
    poll_class: type[Command],
    hz: float,
    duration: float | None,
    telemetry: TelemetryWriter | None,
    frames_file: Any,
    tally: Tally,
) -> None:
    clock = runtime.current().time  # (the Bus's: the replies' last_seen are on it)
    origin = clock()
    frames = CandumpWriter(frames_file, epoch=time.time(), origin=origin) if frames_file else None
    tap = TapLink(conn.transport(), frames.write if frames else lambda *_: None, clock)
    kinds = {Traffic.REPLY, Traffic.STREAM, Traffic.REPORT, Traffic.LATE, Traffic.UNSOLICITED}

    def on_reply(motor: Motor, traffic: Traffic, reply: Reply) -> None:
        if traffic not in kinds:
            return
        tally.replies += 1
        tally.by_motor[motor.motor_id] = tally.by_motor.get(motor.motor_id, 0) + 1
        if telemetry is not None:
            when = (motor.last_seen or clock()) - origin
            telemetry.write(telemetry_row(when, conn.family, motor.motor_id, reply))

    try:
        async with Bus(tap) as bus:
            motors = [bus.motor(conn.family, i, **conn.bind_options()) for i in conn.motor_ids]
            bus.subscribe(on_reply)
            items = [(motor, poll_class()) for motor in motors]
            scope = anyio.move_on_after(duration) if duration is not None else contextlib.nullcontext()
            with scope:
                async for _ in bus.ticks(hz):
                    for result in await bus.cycle(items, timeout_s=conn.timeout_s):
                        if isinstance(result, MotorTimeout):
                            tally.timeouts += 1
                        elif isinstance(result, TransportError):
                            tally.errors += 1
    finally:
        if frames is not None:
            frames.close()


def _summary(
    tally: Tally, telemetry: TelemetryWriter | None, output: Path | None, log: Path | None, interrupted: bool
) -> None:
    per_motor = ", ".join(f"{m}: {n}" for m, n in sorted(tally.by_motor.items()))
    written = " and ".join(str(p) for p in (output, log) if p is not None)
    line = f"record: {tally.replies} replies ({per_motor}), {tally.timeouts} timeouts"
    if tally.errors:
        line += f", {tally.errors} requests not sent"
    if telemetry is not None and telemetry.skipped:
        line += f"; {telemetry.skipped} replies of another type left out of the CSV (JSONL keeps them)"
    click.echo(f"{line}{' (interrupted)' if interrupted else ''} -> {written}", err=True)
