"""``servobus config list|get|set``: the motors' settings (PID, acceleration, communication timeout,
CAN-id filter, limits), by key: the family's ``cli`` part says which (:mod:`servobus.cli.plugin`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import click

from servobus.cli._connect import Connection, connection_options, family_option
from servobus.cli._families import setting, settings
from servobus.cli._motors import Outcome, ask, fail_if_any, plan
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

__all__ = ["config"]


@click.group(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus config list",
        "servobus config get --sim 2 pid.speed_kp pid.speed_ki",
        "servobus config set --sim 1 pid.speed_kp 0.25",
        "servobus config set -i slcan -c /dev/ttyACM0 --ids 3 comm_timeout_ms 200 --yes",
        "servobus config get --family lk --sim 1 pid.speed --json",
    ),
)
def config() -> None:
    """Read and write the motors' settings: PID, acceleration, communication timeout, CAN-id filter,
    limits. Writes that reach ROM ask first (--yes skips)."""


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
    out.columns[-1].justify = "left"
    console().print(out)


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
