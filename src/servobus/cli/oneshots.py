"""The one-shot commands: ``stop``, ``off``, ``brake``, ``zero``, ``set-id``, ``clear-errors`` and
``reset``: each motor is sent its family's command once and its reply printed.

Which command class each sends is the family's ``cli`` part (:mod:`servobus.cli.plugin`); here are the
options, the confirmation of ROM writes and id changes, and the output.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, TypeVar

import click

from servobus.cli._connect import Connection, connection_options, remote_connection_options
from servobus.cli._families import op
from servobus.cli._motors import Outcome, ask, fail_if_any, plan, remote_ask, run
from servobus.cli._output import (
    SETTINGS,
    confirm,
    console,
    emit_json,
    examples,
    json_option,
    message_fields,
    message_text,
    table,
    yes_option,
)
from servobus.protocols import Command

if TYPE_CHECKING:
    from servobus.cli._remote import Remote

__all__ = ["brake", "clear_errors", "off", "reset", "set_id", "stop", "zero"]

F = TypeVar("F", bound=Callable[..., Any])


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
        remote.commanding(name)
        planned, outcomes, families = run(
            remote_ask(conn, remote, lambda family: op(family, name), values, rom=(name, yes))
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
