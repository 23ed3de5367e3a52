"""``servobus scan``: which motors answer, and what they are.

Each id is probed with the family's status read (a read changes nothing on a motor), with a progress
bar; the motors that answered are then asked what the family can tell: revision, model (MyActuator
0xB5), firmware date (0xB2), state and error flags. A per-family table (:data:`DETAILS`) says how.
MyActuator motors are probed as the revision given (V4.4 by default) and then asked for their model
in the revision their firmware date implies.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import Any

import click
from rich.progress import Progress

from servobus.bus import Bus, Motor
from servobus.cli._connect import Connection, connection_options
from servobus.cli._families import status_reads
from servobus.cli._motors import run
from servobus.cli._output import SETTINGS, console, emit_json, examples, json_option, jsonable, table
from servobus.errors import ServobusError

__all__ = ["scan"]

COLUMNS = ("id", "family", "revision", "model", "firmware", "state", "errors")
DEFAULT_IDS = tuple(range(1, 33))


async def _myactuator_identify(motor: Motor, timeout_s: float | None) -> dict[str, Any]:
    """Firmware date and the revision it implies (0xB2 reads the same in V4.3 and V4.4)."""
    from servobus.protocols import myactuator as ma

    date = await motor.request(ma.ReadVersionDate(), timeout_s=timeout_s)
    version = getattr(date, "version_date", None)
    if not version:
        return {}
    return {"firmware": str(version), "revision": ma.revision_from_version_date(version).name}


async def _myactuator_describe(motor: Motor, timeout_s: float | None) -> dict[str, Any]:
    """Model (0xB5, in the motor's revision's form) and operating mode (0x70)."""
    from servobus.protocols import myactuator as ma

    out: dict[str, Any] = {}
    if motor.codec.revision is ma.Revision.V4_4:
        parts = [await motor.request(ma.ReadModelPart(part=part), timeout_s=timeout_s) for part in (1, 2, 3)]
        out["model"] = ma.join_model(p for p in parts if isinstance(p, ma.ModelPartReply))
    else:
        out["model"] = getattr(await motor.request(ma.ReadModel(), timeout_s=timeout_s), "model", None)
    mode = getattr(await motor.request(ma.ReadRunMode(), timeout_s=timeout_s), "mode", None)
    if mode is not None:
        out["state"] = jsonable(mode)
    return out


async def _nothing(motor: Motor, timeout_s: float | None) -> dict[str, Any]:
    return {}


@dataclass(frozen=True, slots=True)
class Details:
    """What to ask a motor that answered the probe: ``identify`` on the probe's binding (may name the
    revision), then ``describe`` on a binding in that revision; each given the reply timeout."""

    identify: Callable[[Motor, float | None], Awaitable[dict[str, Any]]] = _nothing
    describe: Callable[[Motor, float | None], Awaitable[dict[str, Any]]] = _nothing


#: family -> what else a motor can say about itself
DETAILS: dict[str, Details] = {
    "myactuator": Details(_myactuator_identify, _myactuator_describe),
    "lk": Details(),
}


@click.command(
    context_settings=SETTINGS,
    epilog=examples(
        "servobus scan --sim 4",
        "servobus scan -i slcan -c /dev/ttyACM0",
        "servobus scan -i socketcan -c can0 --family lk --ids 1-8 --json",
    ),
)
@connection_options
@json_option
def scan(conn: Connection, as_json: bool) -> None:
    """Probe ids 1-32 (or --ids) for motors of the family; list id, revision, model, firmware date,
    state and error flags of those that answer. (With --sim N the simulated motors are 1..N.)"""
    reads = status_reads(conn.family)  # refused here for a family without a read-only request
    ids = conn.ids or DEFAULT_IDS
    rows = run(_scan(conn, ids, reads.first(None, {})[0], as_json))
    if as_json:
        emit_json(rows)
    elif rows:
        console().print(table(None, COLUMNS, ([r.get(c) for c in COLUMNS] for r in rows)))
    if not rows:
        raise click.ClickException(f"no {conn.family} motor answered on ids {_span(ids)}")


def _span(ids: Sequence[int]) -> str:
    return f"{ids[0]}-{ids[-1]}" if list(ids) == list(range(ids[0], ids[-1] + 1)) else ",".join(map(str, ids))


async def _scan(conn: Connection, ids: Sequence[int], probe: Any, quiet: bool) -> list[dict[str, Any]]:
    transport = dataclasses.replace(conn, ids=()).transport()  # --sim N: motors 1..N, whatever is probed
    details = DETAILS[conn.family]
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
                    row: dict[str, Any] = dict.fromkeys(COLUMNS)
                    row.update(id=motor_id, family=conn.family, revision=motor.codec.revision.name)
                    faults = getattr(reply, "FAULTS", None)
                    row["errors"] = jsonable(getattr(reply, faults)) if faults else None
                    row["state"] = jsonable(getattr(reply, "motor_state", None))
                    with contextlib.suppress(ServobusError):
                        row.update(await details.identify(motor, conn.timeout_s))
                    rows.append(row)
                    progress.advance(task)
        async with Bus(transport, safe=None) as bus:  # a fresh Bus: each motor in its own revision
            for row in rows:
                options = conn.bind_options()
                if conn.revision is None:
                    options["revision"] = row["revision"]
                try:
                    motor = bus.motor(conn.family, row["id"], **options)
                    row.update(await details.describe(motor, conn.timeout_s))
                except ServobusError as exc:
                    row["state"] = f"answered the probe, then: {exc}"
    return rows
