"""``servobus scan``: which motors answer, and what they are.

Each id is probed with the family's first status read (a read changes nothing on a motor), all ids
of a round at once (a round: motors that could share a bus, :func:`servobus.cli.plugin.sharing_rounds`;
one round unless some ids' request and reply identifiers collide) with a short first timeout
(:data:`FIRST_TIMEOUT_S`), then those that did not answer once more with a longer one
(:data:`SECOND_TIMEOUT_S`; on a line that said nothing at all, one id first with the library's; with
``--timeout-ms``, one probe of all ids with that), with a progress bar: a bus of motors of another
family costs about a second, not a timeout per id. When nobody answers,
the message says what the bus saw instead (:mod:`servobus.diagnosis`): another family's replies
("--family lk?"), frames on other ids, or no frame at all (bitrate, wiring, termination, another
program on the port). The motors that answered are then asked what the family can tell: revision,
model, firmware date, state and error flags. The family's ``cli`` part says how (``identify`` and
``describe``, :class:`servobus.cli.plugin.Query`): a motor is probed as the revision given (the
family's default) and then described in the revision its ``identify`` named (MyActuator: the one its
firmware date implies).
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import anyio
import click
from rich.progress import Progress

from servobus.bus import Bus
from servobus.cli._connect import Connection, remote_connection_options
from servobus.cli._families import cli_part, status_reads
from servobus.cli._motors import Asked, codecs, run
from servobus.cli._output import SETTINGS, console, emit_json, examples, json_option, jsonable, refused, table
from servobus.cli.plugin import Query, fault_names, sharing_rounds
from servobus.diagnosis import NOTHING_AT_ALL, SeenId, explain
from servobus.errors import ServobusError
from servobus.protocols import Reply, get_family

if TYPE_CHECKING:
    from servobus.cli._remote import Remote

__all__ = ["default_ids", "scan"]

COLUMNS = ("id", "family", "revision", "model", "firmware", "state", "errors")
#: the ids probed without --ids where the family's cli part declares none (``scan_ids``), those of them
#: the family allows
DEFAULT_IDS = tuple(range(1, 33))
#: the first probe's timeout (every id at once): a motor on a bus answers within a few ms
FIRST_TIMEOUT_S = 0.1
#: the second probe's, of the ids that were silent; on a line that said nothing at all, one of them
#: is probed first with the library's timeout (a fresh adapter's first exchange can be that slow)
SECOND_TIMEOUT_S = 0.3


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
    """Probe ids 1-32 (or the ids the family's CLI part declares, those of them the family allows; or
    --ids) for motors of the family; list id, revision, model, firmware date, state and errors (flags,
    or a fault code) of those that answer. (With --sim N the simulated motors are the first N ids of
    --ids, or 1..N; with --remote, the motors the bridge serves on the bus.)

    The ids are probed in rounds: two ids whose request or reply identifiers collide (Damiao: motor
    1's feedback 0x11 is motor 17's command id) are never probed at once, each round being motors
    that could share a bus, so --ids 1-32 works for such a family too.
    """
    if remote is not None:
        rows = run(_scan_remote(conn, remote))
        where = f"of {remote.target}"
    else:
        reads = status_reads(conn.family)  # refused here for a family without a read-only request
        ids = conn.ids or default_ids(conn.family)
        rows, seen = run(_scan(conn, ids, reads.first(codecs(conn)[0], {})[0], as_json))
        where = f"on ids {_span(ids)}"
        if rows and seen:  # (the motors found are listed; what else answered is worth a line)
            console(stderr=True).print(f"also seen: {seen}", markup=False, highlight=False)
        elif not rows:
            where += f"; {seen or NOTHING_AT_ALL}"
    if as_json:
        emit_json(rows)
    elif rows:
        console().print(table(None, COLUMNS, ([r.get(c) for c in COLUMNS] for r in rows)))
    if not rows:
        family = remote.family if remote is not None else conn.family
        raise click.ClickException(f"no {family + ' ' if family else ''}motor answered {where}")


def default_ids(family: str) -> tuple[int, ...]:
    """The ids ``scan`` probes without ``--ids``: the family's ``cli`` part's ``scan_ids``, or
    :data:`DEFAULT_IDS`; those of them the family's ``motor_ids`` allow."""
    declared = cli_part(family).scan_ids
    allowed = get_family(family).motor_ids
    return tuple(i for i in (DEFAULT_IDS if declared is None else declared) if i in allowed)


def _span(ids: Sequence[int]) -> str:
    return f"{ids[0]}-{ids[-1]}" if list(ids) == list(range(ids[0], ids[-1] + 1)) else ",".join(map(str, ids))


async def _scan(
    conn: Connection, ids: Sequence[int], probe: Any, quiet: bool
) -> tuple[list[dict[str, Any]], str | None]:
    """The rows of the motors that answered, by id, and what else the bus saw (None: nothing).

    The ids are probed in rounds of motors that can share a bus (:func:`sharing_rounds`), a Bus each;
    one round for a family whose motors' ids never collide."""
    transport = conn.transport()  # --sim N: the first N ids of --ids (1..N), whatever is probed
    part = cli_part(conn.family)
    family = get_family(conn.family)
    with refused():
        rounds = sharing_rounds([family.bind(i, **conn.bind_options()) for i in ids])
    found: dict[int, dict[str, Any]] = {}
    seen: dict[int, SeenId] = {}  # what else each round's Bus saw, by identifier
    async with transport:
        shown = console(stderr=True)
        with Progress(console=shown, transient=True, disable=quiet or not shown.is_terminal) as progress:
            task = progress.add_task(f"probing {conn.family} ids {_span(ids)}", total=len(ids))
            for members in rounds:
                async with Bus(transport, safe=None) as bus:
                    began = anyio.current_time()  # (the Bus's clock: the loop's)
                    motors = [bus.motor(conn.family, c.motor_id, **conn.bind_options()) for c in members]
                    heard = bool(found or seen)  # (an earlier round heard the line)
                    replies = await _probe_round(bus, motors, probe, conn.timeout_s, began, heard)
                    progress.advance(task, len(motors))
                    for motor in motors:
                        if motor.motor_id in replies:
                            row = _row(motor, replies[motor.motor_id])
                            with contextlib.suppress(ServobusError):
                                row.update(await _ask(motor, part.identify, conn.timeout_s))
                            found[motor.motor_id] = row
                    seen.update((e.frame.arbitration_id, e) for e in bus.scheduler.seen.since(began))
        rows = [found[i] for i in sorted(found)]
        by_id = {row["id"]: row for row in rows}
        # a fresh Bus a round: each motor in its own revision
        for members in sharing_rounds([c for r in rounds for c in r if c.motor_id in by_id]):
            async with Bus(transport, safe=None) as bus:
                for codec in sorted(members, key=lambda c: c.motor_id):
                    await _describe(bus, conn, part.describe, by_id[codec.motor_id])
    ours = {i for members in rounds for c in members for i in c.request_ids | c.reply_ids}
    others = [seen[i] for i in sorted(seen) if i not in ours]  # (a late reply of another round's motor)
    return rows, explain(others, conn.family)


async def _probe_round(
    bus: Bus, motors: Sequence[Asked], probe: Any, timeout_s: float | None, began: float, heard: bool
) -> dict[int, Reply]:
    """One round's replies to ``probe``: with ``timeout_s`` (--timeout-ms), one probe of all at once
    with it; else a short first probe, and a longer second one of those that were silent (on a line
    that said nothing at all, in this round or before it (``heard``), one of them first with the
    library's timeout)."""
    replies = await _probe_all(motors, probe, FIRST_TIMEOUT_S if timeout_s is None else timeout_s)
    silent = [m for m in motors if m.motor_id not in replies]
    if timeout_s is None and silent:
        again = silent
        if not heard and not _heard(bus, began):  # one probe with the library's (first) timeout
            replies.update(await _probe_all(silent[:1], probe, None))
            again = [m for m in silent[1:] if m.motor_id not in replies]
        replies.update(await _probe_all(again, probe, SECOND_TIMEOUT_S))  # (a slow motor)
    return replies


async def _describe(bus: Bus, conn: Connection, describe: Query | None, row: dict[str, Any]) -> None:
    """``row`` completed with what ``describe`` asks the motor, bound in the revision its row names
    (unless --revision); what failed is said in its state."""
    options = conn.bind_options()
    if conn.revision is None:
        options["revision"] = row["revision"]
    try:
        motor = bus.motor(conn.family, row["id"], **options)
        row.update(await _ask(motor, describe, conn.timeout_s))
    except ServobusError as exc:
        row["state"] = f"answered the probe, then: {exc}"


def _heard(bus: Bus, since: float) -> bool:
    """Whether the bus received any frame since ``since``: a reply (even a late one) or another."""
    seen = any(m.last_seen is not None and m.last_seen >= since for m in bus.motors.values())
    return seen or bool(bus.scheduler.seen.since(since))


async def _probe_all(motors: Sequence[Asked], probe: Any, timeout_s: float | None) -> dict[int, Reply]:
    """Each motor's reply to ``probe``, all in flight at once; those that gave none are left out."""
    replies: dict[int, Reply] = {}

    async def one(motor: Asked) -> None:
        with contextlib.suppress(ServobusError):
            replies[motor.motor_id] = await motor.request(probe, timeout_s=timeout_s)

    async with anyio.create_task_group() as group:
        for motor in motors:
            group.start_soon(one, motor)
    return replies


def _row(motor: Asked, reply: Reply) -> dict[str, Any]:
    """A motor's row from its reply to the probe: id, family, revision, state and error flags."""
    row: dict[str, Any] = dict.fromkeys(COLUMNS)
    row.update(id=motor.motor_id, family=motor.codec.family, revision=motor.codec.revision.name)
    row["errors"] = fault_names(reply)
    state = getattr(reply, "motor_state", None)
    if state is None and reply.FAULT_CODE is not None:  # (a code that is no fault is a state)
        state = getattr(reply, reply.FAULT_CODE)
    row["state"] = jsonable(state)
    return row


async def _scan_remote(conn: Connection, remote: Remote) -> list[dict[str, Any]]:
    """The motors the bridge serves on the bus (or those of them ``--ids`` names), each probed with
    its family's first status read and then asked what the family's ``cli`` part asks, as bound on the
    bridge (its revision is the bridge's)."""
    from servobus.cli._remote import open_remote

    rows: list[dict[str, Any]] = []
    async with open_remote(conn.ids, remote, read_only=True) as (_, motors):
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
