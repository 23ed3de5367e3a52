"""What every command shares for output: the rich consoles, ``--json``, tables, replies as plain data.

Tables and progress go through rich; ``--json`` output is plain JSON on stdout (one document, or one
line per sample for live commands), so scripts never parse a table. Errors are not printed here: they
are raised (``click.ClickException``, ``click.UsageError``) and ``servobus.cli.main`` prints one line.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any, TypeVar

import click
from rich.console import Console
from rich.table import Table

from servobus.protocols._message import Command

__all__ = [
    "confirm",
    "console",
    "emit_json",
    "fmt",
    "json_option",
    "jsonable",
    "reply_fields",
    "table",
    "yes_option",
]

F = TypeVar("F", bound=Callable[..., Any])


def console(*, stderr: bool = False) -> Console:
    """A rich console on stdout (or stderr, for progress and live views that are not the output).

    Made per call, so it writes to whatever ``sys.stdout`` is now (tests capture it).
    """
    return Console(stderr=stderr, highlight=False, soft_wrap=False)


def json_option(func: F) -> F:
    """``--json``: machine-readable output on stdout; the command receives ``as_json``."""
    return click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")(func)


def yes_option(func: F) -> F:
    """``--yes``/``-y``: skip the confirmation of a ROM write or an id change."""
    return click.option("--yes", "-y", is_flag=True, help="Do not ask for confirmation.")(func)


def confirm(question: str, yes: bool) -> None:
    """Ask ``question`` on the terminal unless ``yes``.

    Raises:
        click.ClickException: declined, or no answer (stdin closed): nothing is sent (exit 1).
    """
    if yes:
        return
    try:
        answer = click.confirm(question, default=False, err=True)
    except (click.Abort, OSError):  # stdin closed or unreadable: no answer
        answer = False
    if not answer:
        raise click.ClickException("not confirmed (give --yes to skip the question): nothing was sent")


def jsonable(value: Any) -> Any:
    """``value`` as JSON data: enums by name, flags as a list of names, dataclasses as dicts."""
    if isinstance(value, enum.Flag):
        return [member.name for member in type(value) if member.value and member in value and member.name]
    if isinstance(value, enum.Enum):
        return value.name
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, Command):  # an echo's command: its name says it
        return type(value).__name__
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return reply_fields(value)
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, Iterable) and not isinstance(value, bytes | bytearray):
        return [jsonable(v) for v in value]
    if isinstance(value, bytes | bytearray):
        return value.hex(" ")
    return str(value)


def reply_fields(reply: Any) -> dict[str, Any]:
    """A reply's (or command's) shown fields as JSON data; fields hidden from its repr are left out."""
    if not (dataclasses.is_dataclass(reply) and not isinstance(reply, type)):
        return {}
    return {f.name: jsonable(getattr(reply, f.name)) for f in dataclasses.fields(reply) if f.repr}


def emit_json(data: Any) -> None:
    """``data`` as one JSON document on stdout."""
    click.echo(json.dumps(jsonable(data), ensure_ascii=False))


def fmt(value: Any, digits: int = 2) -> str:
    """A cell: numbers rounded, flags joined, nothing as an empty cell."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    if isinstance(value, list):
        return ",".join(str(v) for v in value) or "none"
    if isinstance(value, dict):
        return ",".join(f"{k}={v}" for k, v in value.items())
    return str(value)


def table(title: str | None, columns: Sequence[str], rows: Iterable[Sequence[Any]]) -> Table:
    """A rich table; numeric-looking columns (``*_deg``, ``*_a``, ...) are right-aligned by the caller's
    formatting, every cell through :func:`fmt`."""
    out = Table(title=title, title_justify="left", header_style="bold")
    for column in columns:
        out.add_column(column, justify="left" if column in _LEFT else "right")
    for row in rows:
        out.add_row(*(fmt(cell) for cell in row))
    return out


_LEFT = frozenset(
    {"family", "revision", "model", "state", "errors", "error", "key", "figure", "benchmark", "sent", "reply"}
)
