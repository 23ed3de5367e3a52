"""``servobus config list|get|set|dump|restore``: the motors' settings (PID, acceleration,
communication timeout, CAN-id filter, limits), by key or as a file: the family's ``cli`` part says
which (:mod:`servobus.cli.plugin`); the file is :mod:`servobus.cli._config_file`'s."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import click

from servobus.cli import _config_file as cfg
from servobus.cli._connect import Connection, connection_options, family_option
from servobus.cli._families import setting, settings
from servobus.cli._motors import Outcome, ask, codecs, fail_if_any, plan, plan_codecs
from servobus.cli._output import (
    SETTINGS,
    NegativeNumbers,
    confirm,
    console,
    emit_json,
    examples,
    json_option,
    jsonable,
    table,
    yes_option,
)
from servobus.cli.plugin import Op, Setting
from servobus.protocols import get_family
from servobus.tools.recording import NewFiles

__all__ = ["config"]


@click.group(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus config list",
        "servobus config get --sim 2 pid.speed_kp pid.speed_ki",
        "servobus config set --sim 1 pid.speed_kp 0.25",
        "servobus config set -i slcan -c /dev/ttyACM0 --ids 3 comm_timeout_ms 200 --yes",
        "servobus config get --family lk --sim 1 pid.speed --json",
        "servobus config dump --sim 2 -o motors.toml",
        "servobus config restore motors.toml --sim 2 --dry-run",
    ),
)
def config() -> None:
    """Read and write the motors' settings: PID, acceleration, communication timeout, CAN-id filter,
    limits; one key at a time (get, set) or all of them through a file (dump, restore). Writes that
    reach ROM ask first (--yes skips)."""


@config.command(
    "list",
    context_settings=SETTINGS,
    epilog=examples("servobus config list", "servobus config list --family lk --json"),
)
@family_option
@json_option
def list_(family: str, as_json: bool) -> None:
    """The settings of a family: key, read/write, ROM, and what each is."""
    rows = [
        {
            "key": s.key,
            "read": s.read is not None,
            "write": s.write is not None,
            "rom": {True: "always", False: "no", None: "with --rom"}[s.rom],
            "help": s.help,
        }
        for s in settings(family).values()
    ]
    if not rows:
        raise click.UsageError(f"{family} motors have no settings the CLI can read or write")
    if as_json:
        emit_json(rows)
        return
    out = table(None, ["key", "read", "write", "rom", "help"], ([r[k] for k in r] for r in rows))
    # the keys whole on a narrow terminal too: the help wraps instead
    out.columns[0].no_wrap = True
    out.columns[0].min_width = max(len(s.key) for s in settings(family).values())
    out.columns[-1].justify = "left"
    _print(out)


@config.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus config get --sim 2 pid.speed_kp position_acceleration_dps_s",
        "servobus config get -i socketcan -c can0 --family lk --ids 9 pid.speed --json",
    ),
)
@connection_options
@click.argument("keys", nargs=-1, required=True, metavar="KEY...")
@json_option
def get(conn: Connection, keys: tuple[str, ...], as_json: bool) -> None:
    """Read settings from each motor."""
    wanted = [setting(conn.family, key) for key in keys]
    for s in wanted:
        if s.read is None:
            raise click.BadParameter(
                f"{conn.family} motors cannot report {s.key} (it can only be written)", param_hint="KEY"
            )
    reads = [s.read for s in wanted if s.read is not None]
    outcomes = ask(conn, plan(conn, Op(first=lambda codec, v: tuple(read() for read in reads)), {}))
    rows = _rows(outcomes, wanted, lambda s, reply: s.value_of(reply))
    _show(rows, as_json)
    fail_if_any(outcomes)


@config.command(
    "set",
    cls=NegativeNumbers,  # config set KEY -5
    context_settings=SETTINGS,
    epilog=examples(
        "servobus config set --sim 1 pid.speed_kp 0.25            # RAM",
        "servobus config set --sim 1 pid.speed_kp 0.25 --rom --yes  # ROM, no question",
        "servobus config set --sim 1 comm_timeout_ms off --yes",
        "servobus config set --family lk --sim 1 pid.speed 100,20,0",
        "servobus config set --sim 1 limit.max_negative_angle_raw -9000 --yes",
    ),
)
@connection_options
@click.argument("key", metavar="KEY")
@click.argument("value", metavar="VALUE")
@click.option("--rom", is_flag=True, help="Write to ROM where the setting has a RAM and a ROM form.")
@yes_option
@json_option
def set_(conn: Connection, key: str, value: str, rom: bool, yes: bool, as_json: bool) -> None:
    """Write one setting to each motor (a negative VALUE needs no ``--``)."""
    s = setting(conn.family, key)
    write = s.write
    if write is None:
        raise click.BadParameter(f"{conn.family} motors cannot write {s.key}", param_hint="KEY")
    if rom and s.rom is not None:
        where = "always reaches ROM" if s.rom else "has no ROM form"
        raise click.BadParameter(f"{s.key} {where}: drop --rom", param_hint="--rom")
    try:
        parsed = s.parse(value)
    except ValueError as exc:
        raise click.BadParameter(f"{s.key} {value}: {exc}", param_hint="VALUE") from None
    try:
        command = write(parsed, rom)  # the range checks, before anything is sent
        for motor_id in conn.motor_ids if conn.limits is not None else ():  # (a setting is never clamped)
            own = conn.limits.of(motor_id)  # type: ignore[union-attr]
            if own is not None:
                own.check(command)
    except ValueError as exc:
        raise click.BadParameter(f"{s.key} {value}: {exc}", param_hint="VALUE") from None
    op = Op(first=lambda codec, v: (command,))
    if s.rom or rom:
        ids = ", ".join(str(i) for i in conn.motor_ids)
        confirm(f"{s.key} = {value} is written to the ROM of {conn.family} motor(s) {ids}. Continue?", yes)
    outcomes = ask(conn, plan(conn, op, {}))
    rows = _rows(outcomes, [s], lambda s, reply: value if parsed is None else parsed)
    _show(rows, as_json)
    fail_if_any(outcomes)


def _print(out: Any) -> None:
    """``out`` on stdout; piped, as wide as it is (rich would cut it to 80 columns): one line per
    row, for grep."""
    screen = console()
    if not screen.is_terminal:
        screen.width = 10_000
    screen.print(out)


def _rows(outcomes: Sequence[Outcome], wanted: Sequence[Setting], value: Any) -> list[dict[str, Any]]:
    rows = []
    for outcome in outcomes:
        for i, s in enumerate(wanted):
            reply = outcome.replies[i] if i < len(outcome.replies) else None
            done = i < len(outcome.replies)
            rows.append(
                {
                    "id": outcome.motor_id,
                    "key": s.key,
                    "value": jsonable(value(s, reply)) if done else None,
                    "error": None if done else outcome.error,
                }
            )
    return rows


def _show(rows: Sequence[dict[str, Any]], as_json: bool) -> None:
    if as_json:
        emit_json(rows)
        return
    columns = ["id", "key", "value", "error"]
    if not any(r["error"] for r in rows):
        columns.pop()
    out = table(None, columns, ([r[c] for c in columns] for r in rows))
    out.columns[2].justify = "left"
    console().print(out)


# ---- the settings as a file ----

_output = click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, allow_dash=True, path_type=Path),
    default="-",
    show_default=True,
    help="The file to write (TOML); '-' is stdout.",
)


@config.command(
    context_settings=SETTINGS,
    short_help="Every setting of each motor to a TOML file, with units and RAM/ROM.",
    epilog=examples(
        "servobus config dump --sim 2",
        "servobus config dump -i slcan -c /dev/ttyACM0 --ids 1-4 -o bench.toml",
        "servobus config dump --family lk --revision V2_35 --sim 1 -o lk.toml --force",
    ),
)
@connection_options
@_output
@click.option("--force", is_flag=True, help="Overwrite FILE if it exists (replaced once the dump is read).")
def dump(conn: Connection, output: Path, force: bool) -> None:
    """Write every setting each motor reports to a TOML file: the family, the revision, a table
    per motor id, each key with its value in config set's units and a comment saying what it is
    and whether a write goes to RAM or ROM. Give the file to config restore.

    Settings the motor cannot report (write-only) are in the file commented out, without a value:
    give one a value and restore writes it. A read-only setting would be commented out with its
    value (restore compares it, never writes it). Nothing is written unless every motor answered;
    an existing FILE only with --force.
    """
    known = settings(conn.family)
    if not known:
        raise click.UsageError(f"{conn.family} motors have no settings the CLI can read or write")
    bound = codecs(conn)
    kept, missing = _in_revision(known.values(), bound[0])
    files = NewFiles(force=force)
    to_file = str(output) != "-"
    if to_file:
        try:
            files.check([output])
        except FileExistsError as exc:
            raise click.UsageError(str(exc)) from None
    reads = [s for s in kept if s.read is not None]
    op = Op(first=lambda codec, v: tuple(s.read() for s in reads))  # type: ignore[misc]
    outcomes = ask(conn, plan_codecs(bound, op, {}))
    _nothing_written(outcomes, "nothing written")
    motors = {
        o.motor_id: {s.key: cfg.file_value(s.value_of(r)) for s, r in zip(reads, o.replies, strict=True)}
        for o in outcomes
    }
    text = cfg.render(conn.family, bound[0].revision.name, motors, kept, missing)
    if not to_file:
        click.echo(text, nl=False)
        return
    try:
        with files.open(output) as out:
            out.write(text)
    except BaseException:
        files.discard()
        raise
    files.close()
    click.echo(f"{len(motors)} motor(s), {len(reads)} settings each: {output}", err=True)


def _in_revision(known: Any, codec: Any) -> tuple[list[Setting], list[str]]:
    """The settings whose read the motor's revision has (write-only ones: all), and the keys of the
    others."""
    kept, missing = [], []
    for s in known:
        try:
            if s.read is not None:
                codec.encode(s.read())
        except ValueError:
            missing.append(s.key)
            continue
        kept.append(s)
    return kept, missing


def _nothing_written(outcomes: Sequence[Outcome], what: str) -> None:
    """One line and exit 1 when a motor did not answer (before anything is written).

    Raises:
        click.ClickException: a motor failed.
    """
    for o in outcomes:
        if o.error is not None:
            raise click.ClickException(f"motor {o.motor_id}: {o.error}: {what}")


@config.command(
    context_settings=SETTINGS,
    short_help="A dump back to the motors: what differs, asked, written, read back.",
    epilog=examples(
        "servobus config restore motors.toml --sim 2 --dry-run",
        "servobus config restore motors.toml -i slcan -c /dev/ttyACM0 --yes",
        "servobus config restore one.toml -i slcan -c /dev/ttyACM0 --ids 1-6   # one file, six motors",
        "servobus config restore motors.toml -i slcan -c /dev/ttyACM0 --rom --yes",
    ),
)
@connection_options
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--rom", is_flag=True, help="Write to ROM the settings that have a RAM and a ROM form.")
@click.option("--dry-run", is_flag=True, help="Show what differs; write nothing.")
@yes_option
def restore(conn: Connection, file: Path, rom: bool, dry_run: bool, yes: bool) -> None:
    """Write a file from config dump back to the motors: the whole file is checked first (its
    family is --family's, every key known and every value in range: else one line, exit 2,
    nothing sent); then each motor's settings are read, what differs is shown and, once confirmed
    (--yes skips; the question names the writes that reach ROM), written and read back (exit 1
    naming the keys that did not take).

    The motors are the file's ids, or --ids: a file of one motor is written to every motor --ids
    names (dump one motor, restore it onto a bench of them); of several, --ids picks some of them.
    With --sim N, the first N of these ids are simulated, at their defaults (fresh at each command).
    The revision is the file's (--revision must agree). Write-only settings given a value are
    written every time and cannot be checked; read-only ones are compared, never written. With
    --rom, the settings that have both forms are written to ROM even where their running (RAM)
    value already matches: the ROM cannot be read.
    """
    found = cfg.load(file)
    if found.family != conn.family:
        raise click.UsageError(
            f"{file} holds {found.family} settings and --family is {conn.family}: "
            f"give --family {found.family}"
        )
    known = settings(conn.family)
    if not known:
        raise click.UsageError(f"{conn.family} motors have no settings the CLI can read or write")
    conn, tables = _targets(conn, found)
    bound = codecs(conn)
    checked = [
        cfg.entries(
            found, table, known, codec, rom, None if conn.limits is None else conn.limits.of(motor_id)
        )
        for table, codec, motor_id in zip(tables, bound, conn.motor_ids, strict=True)
    ]
    reads = [[e for e in entries if e.setting.read is not None] for entries in checked]
    outcomes = ask(conn, [[e.setting.read() for e in motor] for motor in reads])  # type: ignore[misc]
    _nothing_written(outcomes, "nothing written")
    changes = [
        _changes(entries, motor, o.replies, codec, rom)
        for entries, motor, o, codec in zip(checked, reads, outcomes, bound, strict=True)
    ]
    _show_diff(conn.motor_ids, changes)
    writes = [[c for c in motor if c.entry.command is not None] for motor in changes]
    if not any(writes):
        click.echo(f"motor(s) {_ids(conn.motor_ids)} match {file}: nothing to write", err=True)
        return
    if dry_run:
        return
    _confirm(conn, writes, yes)
    planned = [
        [
            *(c.entry.command for c in motor),
            *(c.entry.setting.read() for c in motor if c.entry.setting.read is not None),
        ]
        for motor in writes
    ]
    outcomes = ask(conn, planned)  # type: ignore[arg-type]
    _check_back(conn, writes, outcomes, bound, rom)


def _targets(conn: Connection, found: cfg.SettingsFile) -> tuple[Connection, list[int]]:
    """The connection to the file's motors (its ids unless --ids, its revision) and the table each
    motor gets, in the connection's order.

    Raises:
        click.UsageError: a revision other than the file's, or an id the file has no table for.
    """
    family = get_family(conn.family)
    try:
        revision = family.revision(found.revision)
    except ValueError as exc:
        raise click.UsageError(f"{found.path}: {exc}") from None
    if conn.revision is not None and family.revision(conn.revision) is not revision:
        raise click.UsageError(
            f"{found.path} holds {revision.name} settings and --revision is {conn.revision}: drop --revision"
        )
    in_file = list(found.motors)
    if not conn.ids:
        ids = tuple(in_file)
        tables = in_file
    elif len(in_file) == 1:
        ids, tables = conn.ids, [in_file[0]] * len(conn.ids)
    else:
        absent = [i for i in conn.ids if i not in found.motors]
        if absent:
            raise click.UsageError(
                f"{found.path} has no [motor.{absent[0]}] (it holds {_ids(in_file)}); "
                "a file of one motor is written to every --ids"
            )
        ids, tables = conn.ids, list(conn.ids)
    return dataclasses.replace(conn, ids=ids, revision=revision.name), tables


@dataclasses.dataclass(frozen=True, slots=True)
class _Change:
    """A key of one motor to write (or a read-only one that differs): the value read, where to."""

    entry: cfg.Entry
    now: str  # as the file would hold it ("?": write-only)
    to: str


def _changes(
    entries: Sequence[cfg.Entry], reads: Sequence[cfg.Entry], replies: Sequence[Any], codec: Any, rom: bool
) -> list[_Change]:
    """The entries of one motor that differ from what it reported (``replies`` to ``reads``), and
    those written anyway: write-only ones (nothing to compare with), and with --rom the ones that
    have a ROM form (the ROM cannot be read)."""
    now_of = {id(e): e.setting.value_of(reply) for e, reply in zip(reads, replies, strict=True)}
    out = []
    for e in entries:
        s = e.setting
        if s.read is None:
            out.append(_Change(e, "?", f"{cfg.where(s, rom)} (write-only: not read back)"))
            continue
        now = now_of[id(e)]
        if not cfg.same(e, now, codec, rom):
            out.append(
                _Change(e, cfg.shown(now), "read-only: not written" if s.write is None else cfg.where(s, rom))
            )
        elif rom and s.rom is None and s.write is not None:
            out.append(_Change(e, cfg.shown(now), "ROM (RAM already holds it)"))
    return out


def _ids(ids: Sequence[int]) -> str:
    return ", ".join(str(i) for i in ids)


def _show_diff(ids: Sequence[int], changes: Sequence[Sequence[_Change]]) -> None:
    rows = [
        (motor_id, c.entry.setting.key, c.now, cfg.shown(c.entry.value), c.to)
        for motor_id, motor in zip(ids, changes, strict=True)
        for c in motor
    ]
    if rows:
        out = table(None, ["id", "key", "now", "file", "written to"], rows)
        for column in out.columns[2:]:
            column.justify = "left"
        _print(out)


def _confirm(conn: Connection, writes: Sequence[Sequence[_Change]], yes: bool) -> None:
    count = sum(len(motor) for motor in writes)
    to_rom = sorted({c.entry.setting.key for motor in writes for c in motor if c.to.startswith("ROM")})
    where = (
        f"to ROM (kept after power-off): {', '.join(to_rom)}" if to_rom else "all to RAM (lost at power-off)"
    )
    confirm(f"Write {count} setting(s) to motor(s) {_ids(_written(conn, writes))}, {where}. Continue?", yes)


def _written(conn: Connection, writes: Sequence[Sequence[_Change]]) -> list[int]:
    """The motors that get a write (those whose settings all match get none)."""
    return [motor_id for motor_id, motor in zip(conn.motor_ids, writes, strict=True) if motor]


def _check_back(
    conn: Connection,
    writes: Sequence[Sequence[_Change]],
    outcomes: Sequence[Outcome],
    bound: Sequence[Any],
    rom: bool,
) -> None:
    """Say what was written and read back; exit 1 naming the keys that did not take.

    Raises:
        click.ClickException: a motor failed, or a value read back is not the file's.
    """
    failed: list[str] = []
    unchecked: set[str] = set()
    for motor, outcome, codec in zip(writes, outcomes, bound, strict=True):
        if outcome.error is not None:
            done = ", ".join(c.entry.setting.key for c in motor[: len(outcome.replies)]) or "nothing"
            failed.append(f"motor {outcome.motor_id}: {outcome.error} (written: {done})")
            continue
        backs = iter(outcome.replies[len(motor) :])
        for c in motor:
            entry, s = c.entry, c.entry.setting
            if s.read is None:
                unchecked.add(s.key)
                continue
            value = s.value_of(next(backs))
            if not cfg.same(entry, value, codec, rom):
                failed.append(
                    f"motor {outcome.motor_id}: {s.key} did not take "
                    f"(wrote {cfg.shown(entry.value)}, reads {cfg.shown(value)})"
                )
    count = sum(len(motor) for motor in writes)
    note = f"; not read back (write-only): {', '.join(sorted(unchecked))}" if unchecked else ""
    if failed:
        raise click.ClickException("; ".join(failed))
    ids = _ids(_written(conn, writes))
    click.echo(f"wrote {count} setting(s) to motor(s) {ids}, read back the same{note}", err=True)
