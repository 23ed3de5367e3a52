"""``servobus scan``: which motors answer, and what they are.

Each id is probed with the family's first status read (a read changes nothing on a motor), with a
progress bar; the motors that answered are then asked what the family can tell: revision, model,
firmware date, state and error flags. The family's ``cli`` part says how (``identify`` and
``describe``, :class:`servobus.cli.plugin.Query`): a motor is probed as the revision given (the
family's default) and then described in the revision its ``identify`` named (MyActuator: the one its
firmware date implies).
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import click
from rich.progress import Progress

from servobus.bus import Bus
from servobus.cli._connect import Connection, remote_connection_options
from servobus.cli._families import cli_part, status_reads
from servobus.cli._motors import Asked, codecs, run
from servobus.cli._output import SETTINGS, console, emit_json, examples, json_option, jsonable, table
from servobus.cli.plugin import Query
from servobus.errors import ServobusError
from servobus.protocols import Reply, get_family

if TYPE_CHECKING:
    from servobus.cli._remote import Remote

__all__ = ["scan"]

COLUMNS = ("id", "family", "revision", "model", "firmware", "state", "errors")
#: the ids probed without --ids (those of them the family allows)
DEFAULT_IDS = tuple(range(1, 33))


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus scan --sim 4",
        "servobus scan -i slcan -c /dev/ttyACM0",
        "servobus scan -i socketcan -c can0 --family lk --ids 1-8 --json",
        "servobus scan --remote arm/can0          # the motors a bridge serves on its bus can0",
    ),
)
@remote_connection_options
@json_option
def scan(conn: Connection, remote: Remote | None, as_json: bool) -> None:
    """Probe ids 1-32 (those of them the family allows; or --ids) for motors of the family; list id,
    revision, model, firmware date, state and error flags of those that answer. (With --sim N the
    simulated motors are 1..N; with --remote, the motors the bridge serves on the bus.)"""
    if remote is not None:
        rows = run(_scan_remote(conn, remote))
        where = f"of {remote.target}"
    else:
        reads = status_reads(conn.family)  # refused here for a family without a read-only request
        ids = conn.ids or tuple(i for i in DEFAULT_IDS if i in get_family(conn.family).motor_ids)
        rows = run(_scan(conn, ids, reads.first(codecs(conn)[0], {})[0], as_json))
        where = f"on ids {_span(ids)}"
    if as_json:
        emit_json(rows)
    elif rows:
        console().print(table(None, COLUMNS, ([r.get(c) for c in COLUMNS] for r in rows)))
    if not rows:
        family = remote.family if remote is not None else conn.family
        raise click.ClickException(f"no {family + ' ' if family else ''}motor answered {where}")


def _span(ids: Sequence[int]) -> str:
    return f"{ids[0]}-{ids[-1]}" if list(ids) == list(range(ids[0], ids[-1] + 1)) else ",".join(map(str, ids))


async def _scan(conn: Connection, ids: Sequence[int], probe: Any, quiet: bool) -> list[dict[str, Any]]:
    transport = dataclasses.replace(conn, ids=()).transport()  # --sim N: motors 1..N, whatever is probed
    part = cli_part(conn.family)
    rows: list[dict[str, Any]] = []
    async with transport:
        async with Bus(transport, safe=None) as bus:
            shown = console(stderr=True)
            with Progress(console=shown, transient=True, disable=quiet or not shown.is_terminal) as progress:
                task = progress.add_task(f"probing {conn.family} ids {_span(ids)}", total=len(ids))
                for motor_id in ids:
                    motor = bus.motor(conn.family, motor_id, **conn.bind_options())
                    try:
                        reply = await motor.request(probe, timeout_s=conn.timeout_s)
                    except ServobusError:
                        progress.advance(task)
                        continue
                    row = _row(motor, reply)
                    with contextlib.suppress(ServobusError):
                        row.update(await _ask(motor, part.identify, conn.timeout_s))
                    rows.append(row)
                    progress.advance(task)
        async with Bus(transport, safe=None) as bus:  # a fresh Bus: each motor in its own revision
            for row in rows:
                options = conn.bind_options()
                if conn.revision is None:
                    options["revision"] = row["revision"]
                try:
                    motor = bus.motor(conn.family, row["id"], **options)
                    row.update(await _ask(motor, part.describe, conn.timeout_s))
                except ServobusError as exc:
                    row["state"] = f"answered the probe, then: {exc}"
    return rows


def _row(motor: Asked, reply: Reply) -> dict[str, Any]:
    """A motor's row from its reply to the probe: id, family, revision, state and error flags."""
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row.update(id=motor.motor_id, family=motor.codec.family, revision=motor.codec.revision.name)
    faults = getattr(reply, "FAULTS", None)
    row["errors"] = jsonable(getattr(reply, faults)) if faults else None
    row["state"] = jsonable(getattr(reply, "motor_state", None))
    return row


async def _scan_remote(conn: Connection, remote: Remote) -> list[dict[str, Any]]:
    """The motors the bridge serves on the bus (or those of them ``--ids`` names), each probed with
    its family's first status read and then asked what the family's ``cli`` part asks, as bound on the
    bridge (its revision is the bridge's)."""
    from servobus.cli._remote import open_remote

    rows: list[dict[str, Any]] = []
    async with open_remote(conn, remote, read_only=True) as (_, motors):
        for motor in motors:
            family = motor.codec.family
            probe = status_reads(family).first(motor.codec, {})[0]
            try:
                reply = await motor.request(probe, timeout_s=conn.timeout_s)
            except ServobusError:
                continue
            row = _row(motor, reply)
            part = cli_part(family)
            with contextlib.suppress(ServobusError):
                row.update(await _ask(motor, part.identify, conn.timeout_s))
            try:
                row.update(await _ask(motor, part.describe, conn.timeout_s))
            except ServobusError as exc:
                row["state"] = f"answered the probe, then: {exc}"
            rows.append(row)
    return rows


async def _ask(motor: Asked, query: Query | None, timeout_s: float | None) -> dict[str, Any]:
    """The columns ``query`` makes of the motor's replies to its reads (nothing without a query).

    Raises:
        ServobusError: a read was not answered.
    """
    if query is None:
        return {}
    replies = [await motor.request(read, timeout_s=timeout_s) for read in query.reads(motor.codec)]
    return {key: jsonable(value) for key, value in query.columns(motor.codec, replies).items()}
