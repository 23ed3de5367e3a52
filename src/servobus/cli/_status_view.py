"""What a motor command shows of its motors: the status rows and table (printed at the end, redrawn
live on a terminal while it runs), and each tick's results taken into the motors' outcomes.

Shared by the reading commands (:mod:`servobus.cli.status`) and the set-points
(:mod:`servobus.cli.setpoints`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from rich.live import Live

from servobus.cli._motors import STATUS_COLUMNS, Asked, Outcome, status_of
from servobus.cli._output import console, table
from servobus.errors import ServobusError
from servobus.protocols import Command, Reply

__all__ = ["Items", "LiveStatus", "status_rows", "status_table", "take", "tick_items"]

#: one tick's (motor, command) pairs
Items = list[tuple[Any, Command]]


def status_rows(outcomes: Sequence[Outcome]) -> list[dict[str, Any]]:
    """One row per motor: its id, its status columns (:func:`~servobus.cli._motors.status_of`), its
    error."""
    rows = []
    for o in outcomes:
        row: dict[str, Any] = {"id": o.motor_id, **status_of(o.replies)}
        row["error"] = o.error
        rows.append(row)
    return rows


def status_table(rows: Sequence[Mapping[str, Any]], title: str | None = None) -> Any:
    """The rows as a table of the columns some motor has (the error column only if one failed)."""
    columns = ("id", *STATUS_COLUMNS, "error")
    shown = [c for c in columns if c in ("id", "error") or any(r.get(c) is not None for r in rows)]
    if not any(r.get("error") for r in rows):
        shown.remove("error")
    return table(title, shown, ([r.get(c) for c in shown] for r in rows))


def tick_items(motors: Sequence[Asked], commands: Sequence[Sequence[Command]]) -> Items:
    """One tick's (motor, command) pairs: each motor's commands, in order."""
    return [(motor, command) for motor, each in zip(motors, commands, strict=True) for command in each]


def take(
    outcomes: Sequence[Outcome], items: Sequence[tuple[Asked, Command]], results: Sequence[Any]
) -> dict[int, list[Reply | None]]:
    """One tick's results into each motor's outcome: its error, or its replies of this tick (a motor
    that failed keeps the replies of the last tick it answered). Returns this tick's replies by id.

    Raises:
        BaseException: a result that is not a motor's or the bus's failure (a bug, a refused frame).
    """
    fresh: dict[int, list[Reply | None]] = {o.motor_id: [] for o in outcomes}
    errors: dict[int, str] = {}
    for (motor, _), result in zip(items, results, strict=True):
        if isinstance(result, ServobusError):
            errors.setdefault(motor.motor_id, str(result))
        elif isinstance(result, BaseException):
            raise result
        else:
            fresh[motor.motor_id].append(result)
    for outcome in outcomes:
        outcome.error = errors.get(outcome.motor_id)
        if fresh[outcome.motor_id]:
            outcome.replies = fresh[outcome.motor_id]
    return fresh


class LiveStatus:
    """The live status table on stderr (a terminal only), redrawn about four times a second."""

    def __init__(self, live: bool, rate_hz: float) -> None:
        self._view = Live(console=console(stderr=True), auto_refresh=False) if live else None
        self._every = max(1, round(rate_hz / 4))

    def __enter__(self) -> LiveStatus:
        if self._view is not None:
            self._view.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._view is not None:
            self._view.stop()

    def show(self, tick: int, outcomes: Sequence[Outcome], title: str) -> None:
        if self._view is not None and tick % self._every == 0:
            self._view.update(status_table(status_rows(outcomes), title), refresh=True)
