"""Talking to the motors a command names: build every command first, then ask each motor, collect.

Commands are built and encoded for every motor before the first frame goes out, so a value out of
range or a command the motor's revision lacks stops the whole command with one line (exit 2) and
nothing sent. A motor that does not answer is a result (its error), not the end of the command:
the others still get theirs, and :func:`fail_if_any` turns the failures into one line and exit 1.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import signal
from collections.abc import Callable, Coroutine, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import anyio
import click

from servobus.cli._connect import Connection, open_bus
from servobus.cli._output import confirm, refused
from servobus.cli._remote import Remote, open_remote
from servobus.cli.plugin import STATUS_SOURCES, Op, fault_names
from servobus.errors import ServobusError
from servobus.limits import LimitBook, LimitExceeded, Limits, safe_commands
from servobus.protocols import Command, Reply, get_family
from servobus.signals import StopOn, stop_on

if TYPE_CHECKING:
    from servobus.cli._remote import RemoteCliMotor

__all__ = [
    "BACKENDS",
    "Asked",
    "Outcome",
    "ask",
    "ask_all",
    "codecs",
    "fail_if_any",
    "plan",
    "plan_codecs",
    "plan_motors",
    "remote_ask",
    "run",
    "status_of",
    "stop_scope",
]

T = TypeVar("T")


#: the event loops a command may run on (``--backend``); asyncio is the default and the fastest here
BACKENDS = ("asyncio", "trio")

#: the run's signal block, for :func:`stop_scope`
_STOP: contextvars.ContextVar[StopOn] = contextvars.ContextVar("servobus.cli.stop")


def run(coro: Coroutine[Any, Any, T], *, backend: str = "asyncio") -> T:
    """Run ``coro`` on a fresh event loop (``anyio.run``, asyncio unless ``backend`` says trio),
    Ctrl-C and SIGTERM alike cancelling it: every ``async with Bus`` in it is left through its safe
    stop, and the command ends here as KeyboardInterrupt, which ``servobus.cli.main`` turns into the
    line naming the motors stopped and exit 130 (Ctrl-C) or 143 (SIGTERM: systemd, ``docker stop``,
    ``timeout``).

    Both signals are taken by :func:`servobus.signals.stop_on` while ``coro`` runs (the handlers
    before are put back after) and SIGTERM is noted in :data:`servobus.cli.SIGNALLED` for the exit code. A
    second signal while the safe stop runs is ignored: the stop is bounded by the Bus's
    ``safe_timeout_s``. A command that ends its own run on the signal (:func:`stop_scope`, like
    ``demo``) returns its value instead.
    """
    from servobus.cli import SIGNALLED

    async def main() -> tuple[bool, T | None]:
        async with stop_on(signal.SIGTERM, signal.SIGINT, exit=False) as stop:
            token = _STOP.set(stop)
            try:
                return True, await coro
            finally:
                _STOP.reset(token)
                if stop.received not in (
                    None,
                    signal.SIGINT,
                ):  # (the list holds the others: Ctrl-C's is the default)
                    SIGNALLED.append(stop.received)
        return False, None  # (cancelled by the signal)

    try:
        finished, result = anyio.run(main, backend=backend)
    except BaseExceptionGroup as group:  # one error from a task group's task: say it as itself
        leaves = _leaves(group)
        if len(leaves) == 1:
            raise leaves[0] from None
        raise
    if not finished:
        raise KeyboardInterrupt
    return result  # type: ignore[return-value]


def _leaves(group: BaseExceptionGroup[BaseException]) -> list[BaseException]:
    """The exceptions in ``group`` and the groups inside it."""
    return [
        leaf
        for exc in group.exceptions
        for leaf in (_leaves(exc) if isinstance(exc, BaseExceptionGroup) else [exc])
    ]


def stop_scope() -> contextlib.AbstractContextManager[anyio.CancelScope]:
    """The block a Ctrl-C or SIGTERM cancels instead of the whole command: a loop whose summary is
    still printed after it (its ``cancelled_caught`` says the signal came). Outside :func:`run`, a
    plain cancel scope."""
    stop = _STOP.get(None)
    return stop.scope() if stop is not None else anyio.CancelScope()


class Asked(Protocol):
    """What the helpers here ask of a motor: a :class:`~servobus.bus.Motor`, or a bridge's
    (:class:`servobus.cli._remote.RemoteCliMotor`)."""

    @property
    def motor_id(self) -> int: ...

    @property
    def codec(self) -> Any: ...

    async def request(self, command: Command[T], *, timeout_s: float | None = None) -> T: ...


@dataclass(slots=True)
class Outcome:
    """One motor's result: the replies to what was sent (in order), or the error that ended it."""

    motor_id: int
    replies: list[Reply | None] = field(default_factory=list)
    error: str | None = None

    @property
    def reply(self) -> Reply | None:
        """The reply to the last command sent."""
        return self.replies[-1] if self.replies else None


def codecs(conn: Connection) -> list[Any]:
    """The bound codecs of the motors ``conn`` names (no bus needed: for checks before opening one).

    Raises:
        click.UsageError: a bad id or revision for the family (exit 2).
    """
    family = get_family(conn.family)
    with refused():
        return [family.bind(i, **conn.bind_options()) for i in conn.motor_ids]


def plan(conn: Connection, op: Op, values: Mapping[str, Any]) -> list[Sequence[Command]]:
    """Every motor's commands, in ``conn.motor_ids`` order, built and encoded now (nothing is sent).

    Raises:
        click.UsageError: a value out of range, a command the motor's revision or link lacks, or a
            combination the family does not support (exit 2).
    """
    return plan_codecs(codecs(conn), op, values, conn.limits)


def plan_codecs(
    bound: Sequence[Any], op: Op, values: Mapping[str, Any], limits: LimitBook | None = None
) -> list[Sequence[Command]]:
    """:func:`plan` for motors' bound codecs (a bridge's motors: bound here after connecting), each
    command within the motor's ``limits`` (``--limits``: refused, or clamped with a line saying so).

    Raises:
        click.UsageError: as :func:`plan` (exit 2).
    """
    planned = []
    for codec in bound:
        with refused():
            commands = op.first(codec, values)
            own = None if limits is None else limits.of(codec.motor_id)
            if own is not None:
                commands = tuple(_within(codec, own, command) for command in commands)
            for command in commands:
                codec.encode(command)  # the revision and link checks, before anything is sent
        planned.append(commands)
    return planned


def _within(codec: Any, limits: Limits, command: Command) -> Command:
    """``command`` within ``limits`` (LimitExceeded: a ValueError), a line on stderr for each field
    clamped. A relative move is left to the Bus: its target is known once the motor's angle is."""
    if command.POSITION == "relative" or command in safe_commands(codec):  # (a stop: always allowed)
        return command
    try:
        checked = limits.apply(command)
    except LimitExceeded as exc:
        raise LimitExceeded(
            f"{codec.family} motor {codec.motor_id}: {exc}", exc.field, exc.value, exc.limit
        ) from None
    names = [f.name for f in dataclasses.fields(checked)] if checked is not command else []  # type: ignore[arg-type]
    for name in names:
        before, after = getattr(command, name), getattr(checked, name)
        if before != after:
            what = f"{codec.family} motor {codec.motor_id}: {type(command).__name__}.{name}"
            click.echo(f"servobus: {what} {_said(before)} clamped to {_said(after)} (--limits)", err=True)
    return checked


def _said(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, tuple):
        return "(" + ", ".join(_said(v) for v in value) + ")"
    return "none" if value is None else str(value)


def plan_motors(
    motors: Sequence[RemoteCliMotor],
    op_of: Callable[[str], Op],
    values: Mapping[str, Any],
    limits: LimitBook | None = None,
) -> list[Sequence[Command[Any]]]:
    """:func:`plan_codecs` for a bridge's motors, ``op_of(family)`` saying what each motor's family
    sends (a bridge's bus may mix families); built and checked before anything is sent.

    Raises:
        click.UsageError: a family without the command, a value out of range, a command the motor's
            revision lacks (exit 2).
    """
    ops: dict[str, Op] = {}
    planned = []
    for motor in motors:
        family = motor.codec.family
        if family not in ops:
            ops[family] = op_of(family)
        planned.extend(plan_codecs([motor.codec], ops[family], values, limits))
    return planned


async def ask_all(
    motors: Sequence[Asked], planned: Sequence[Sequence[Command]], *, timeout_s: float | None = None
) -> list[Outcome]:
    """Send each motor its commands in order (the motors one after the other); collect the replies.
    ``timeout_s``: each reply's timeout (None: the library's)."""
    outcomes = []
    for motor, commands in zip(motors, planned, strict=True):
        outcome = Outcome(motor.motor_id)
        for command in commands:
            try:
                outcome.replies.append(await motor.request(command, timeout_s=timeout_s))
            except ServobusError as exc:
                outcome.error = str(exc)
                break
        outcomes.append(outcome)
    return outcomes


async def remote_ask(
    conn: Connection,
    remote: Remote,
    op_of: Callable[[str], Op],
    values: Mapping[str, Any],
    *,
    read_only: bool = False,
    rom: tuple[str, bool] | None = None,
) -> tuple[list[Sequence[Command]], list[Outcome], list[str]]:
    """:func:`ask` through a bridge: each motor's commands (``op_of(family)``)
    built once the bridge said the motors' families, sent as requests, their replies collected.
    ``rom``: (the command's name, ``--yes``), to ask first where it writes the ROM.

    Returns:
        The commands sent, each motor's outcome, and the motors' families.
    """
    async with open_remote(conn.ids, remote, read_only=read_only) as (_, motors):
        planned = plan_motors(motors, op_of, values, conn.limits)
        families = sorted({motor.codec.family for motor in motors})
        if rom is not None and any(op_of(family).rom for family in families):
            ids = ", ".join(str(m.motor_id) for m in motors)
            confirm(f"{rom[0]} writes the ROM of motor(s) {ids} of {remote.target}. Continue?", rom[1])
        return planned, await ask_all(motors, planned, timeout_s=conn.timeout_s), families


def ask(conn: Connection, planned: Sequence[Sequence[Command]]) -> list[Outcome]:
    """Open ``conn``'s bus, send each motor its planned commands (:func:`ask_all`), collect the
    outcomes. No safe command on the way out: what was asked is all that is sent."""

    async def go() -> list[Outcome]:
        async with open_bus(conn, safe=None) as (_, motors):
            return await ask_all(motors, planned, timeout_s=conn.timeout_s)

    return run(go())


#: the columns of a status (where the replies keep them: :data:`servobus.cli.plugin.STATUS_SOURCES`)
STATUS_COLUMNS = ("angle_deg", "speed_dps", "current_a", "torque_nm", "temperature_c", "voltage_v", "errors")


def status_of(replies: Sequence[Reply | None]) -> dict[str, Any]:
    """The status columns found in ``replies`` (a later reply fills only what earlier ones left), in
    the columns' units (radians converted to degrees).

    ``errors`` is the reply's own fault field (``Reply.FAULTS`` or ``FAULT_CODE``), as a list of names.
    """
    out: dict[str, Any] = dict.fromkeys(STATUS_COLUMNS)
    for reply in replies:
        if reply is None:
            continue
        for column, sources in STATUS_SOURCES.items():
            if out[column] is not None:
                continue
            for name, factor in sources:
                value = getattr(reply, name, None)
                if isinstance(value, int | float) and not isinstance(value, bool):
                    out[column] = value * factor if factor != 1.0 else value
                    break
        if out["errors"] is None:  # its flags, or its fault code (Reply.FAULTS, FAULT_CODE)
            out["errors"] = fault_names(reply)
    return out


def fail_if_any(outcomes: Sequence[Outcome]) -> None:
    """Raise one line for the motors that failed (exit 1), after the output was printed.

    Raises:
        click.ClickException: at least one motor failed.
    """
    failed = [o for o in outcomes if o.error is not None]
    if not failed:
        return
    first = failed[0].error
    more = f" (and {len(failed) - 1} more)" if len(failed) > 1 else ""
    raise click.ClickException(f"{len(failed)} of {len(outcomes)} motors failed: {first}{more}")
